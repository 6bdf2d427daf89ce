//! Large grid buffers.
//!
//! A 4000 × 4000 grid of `f32` is 64 MB: 16 000 pages of 4 KiB, each
//! faulted in and zeroed by the kernel on first touch. That cost alone
//! rivalled the costmap's own arithmetic. Where the kernel offers
//! transparent huge pages on request (Linux's default `madvise` mode),
//! asking for them makes it 32 faults of 2 MiB; and the first touch is
//! spread over the worker threads.

use rayon::prelude::*;

/// Buffers smaller than this keep the ordinary pages.
const HUGE_FROM_BYTES: usize = 4 << 20;

/// Elements per parallel task of the fill.
const FILL_CHUNK: usize = 1 << 16;

/// A `Vec` of `n` copies of `value`, backed by huge pages where the
/// kernel grants them and filled in parallel.
pub fn filled<T: Copy + Send + Sync>(n: usize, value: T) -> Vec<T> {
    let mut v: Vec<T> = Vec::with_capacity(n);
    let bytes = n.saturating_mul(std::mem::size_of::<T>());
    if bytes >= HUGE_FROM_BYTES {
        advise_huge_pages(v.as_mut_ptr().cast(), bytes);
    }
    v.spare_capacity_mut()[..n]
        .par_chunks_mut(FILL_CHUNK)
        .for_each(|chunk| {
            for x in chunk {
                x.write(value);
            }
        });
    // SAFETY: the first `n` elements were all written just above.
    unsafe { v.set_len(n) };
    v
}

/// Asks for huge pages over the whole 2 MiB pages inside `len` bytes from
/// `start` (advice only: refused or unsupported, nothing changes).
#[cfg(target_os = "linux")]
pub(crate) fn advise_huge_pages(start: *mut u8, len: usize) {
    const HUGE: usize = 2 << 20;
    let first = (start as usize).next_multiple_of(HUGE);
    let end = (start as usize + len) / HUGE * HUGE;
    if end > first {
        // SAFETY: [first, end) lies inside the allocation just made and
        // owned by the caller; MADV_HUGEPAGE changes no contents.
        unsafe {
            libc::madvise(first as *mut libc::c_void, end - first, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn advise_huge_pages(_start: *mut u8, _len: usize) {}

/// For a short-lived process that builds one large grid product (the
/// CLI): large blocks freed by one stage are kept by the allocator for the
/// next stage's grids, instead of going back to the kernel and coming
/// back as fresh pages it must zero again. A long-running service should
/// not call this: its memory would never shrink after a job.
pub fn keep_freed_grids() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes glibc's allocation thresholds.
    unsafe {
        // No block of its own mapped for each large grid (so none is
        // unmapped on free), and the heap never trimmed.
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filled_holds_n_copies_small_and_large() {
        for n in [0, 1, 1000, 3 << 20] {
            let v = filled(n, 2.5f32);
            assert_eq!(v.len(), n);
            assert!(v.iter().all(|&x| x == 2.5));
        }
        let v = filled(5 << 20, f64::NAN);
        assert!(v.iter().all(|x| x.is_nan()));
    }
}
