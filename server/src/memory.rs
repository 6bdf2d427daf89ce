//! The memory budget (`--memory-budget-mb`): work that needs much memory
//! (reading a DEM, a hillshade, a costmap build, a route search) reserves
//! an estimate of its peak before it starts, from the sizes it knows in
//! advance (a raster's declared width and height, a file's length). Work
//! that does not fit beside the work already running waits its turn
//! (first come, first served); work that alone needs more than the whole
//! budget is refused, with the numbers, before anything is allocated.
//!
//! Memory held apart from the budget: the parsed DEMs kept for sampling
//! (`--dem-cache-mb`), the route searches kept for replanning
//! (`--route-cache-mb`), and small per-request buffers (a download holds
//! one stored chunk at a time).
//!
//! Freed memory goes back to the operating system: glibc keeps what a
//! thread frees in that thread's arena, and raises its mmap threshold up to
//! 32 MiB after large frees, so the grids of finished work would stay in
//! the process (its idle RSS stayed at 2 GB). [`tune_allocator`] fixes the
//! threshold and caps the arenas; after large work the free pages are
//! trimmed.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::error::ApiError;

pub const MIB: u64 = 1024 * 1024;
/// Budget permits are KiB, so that a `u32` count spans 4 TiB.
const UNIT: u64 = 1024;
/// How long a request waits for room in the budget before a 503.
pub const QUEUE_TIMEOUT: Duration = Duration::from_secs(120);
/// Work at least this large trims the allocator when it ends.
const TRIM_FROM: u64 = 32 * MIB;
/// Trimming waits this long after the work, so that the buffers it
/// dropped last (a response body, a cached DEM's file) are freed too.
const TRIM_DELAY: Duration = Duration::from_millis(300);
/// Added to every estimate: allocator slack, small buffers, PROJ objects.
const SLACK: u64 = 16 * MIB;

/// The budget's default, MiB: half the memory of the machine (or of its
/// cgroup, when that is lower), at least 256 MiB; 2048 when neither can be
/// read.
pub fn default_budget_mb() -> u64 {
    let mem_total = std::fs::read_to_string("/proc/meminfo").ok().and_then(|s| {
        s.lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kib| kib * 1024)
    });
    // cgroup v2, then v1; "max" (no limit) does not parse.
    let cgroup = [
        "/sys/fs/cgroup/memory.max",
        "/sys/fs/cgroup/memory/memory.limit_in_bytes",
    ]
    .iter()
    .find_map(|p| std::fs::read_to_string(p).ok()?.trim().parse::<u64>().ok());
    match (mem_total, cgroup) {
        (None, None) => 2048,
        (a, b) => (a.unwrap_or(u64::MAX).min(b.unwrap_or(u64::MAX)) / 2 / MIB).max(256),
    }
}

/// `bytes` as MiB for messages, e.g. "1024.5 MiB".
pub fn mib(bytes: u64) -> String {
    let m = bytes as f64 / MIB as f64;
    if m >= 100.0 {
        format!("{m:.0} MiB")
    } else {
        format!("{m:.1} MiB")
    }
}

/// Peak memory of reading a raster of `pixels` (heights are held as f64)
/// from a file of `file_bytes` (held whole while it is read, plus a copy
/// some tiled files need), decoding `chunk_bytes` at a time (a strip or a
/// tile as stored; a whole single-strip image is one chunk).
pub fn dem_read_bytes(pixels: u64, chunk_bytes: u64, file_bytes: u64) -> u64 {
    pixels
        .saturating_mul(8)
        .saturating_add(chunk_bytes)
        .saturating_add(file_bytes.saturating_mul(2))
        .saturating_add(SLACK)
}

/// Peak memory of a hillshade of a `width`×`height` DEM at most `max_side`
/// pixels on its longer side: the reduced grid (f64), the grey + alpha
/// pixels and the PNG.
pub fn hillshade_bytes(width: u64, height: u64, max_side: u64) -> u64 {
    let f = width.max(height).div_ceil(max_side.max(1)).max(1);
    let out = width.div_ceil(f).saturating_mul(height.div_ceil(f));
    out.saturating_mul(8 + 2 + 2).saturating_add(SLACK)
}

/// Peak memory of building a costmap on a grid of at most `cells` cells
/// with `layers` layer files kept, beside its DEM: about 16 bytes a cell
/// while it is built (the README's benchmark: ≤ 5 × the Float32 grid),
/// then the files (cost and class, 5 bytes a cell; 4 a layer).
pub fn costmap_build_bytes(cells: u64, layers: u64) -> u64 {
    cells
        .saturating_mul(16 + 5 + 4 * layers)
        .saturating_add(2 * SLACK)
}

/// Peak memory of a route search on a costmap of `cells` cells stored in
/// `file_bytes`: the file, the cost band read as f64, the search's arrays
/// (A*: 16 bytes a cell with the costs; a D* Lite search built for
/// replanning: 17, its landmark's A* labels 8 and that A*'s tiled costs 4
/// while it runs).
pub fn route_search_bytes(cells: u64, file_bytes: u64) -> u64 {
    cells
        .saturating_mul(8 + 4 + 29)
        .saturating_add(file_bytes)
        .saturating_add(SLACK)
}

/// Peak memory of a route search coarse to fine, beside `search_bytes`
/// (the search's own estimate, `CoarseToFineOptions::estimated_bytes`):
/// what the sources it reads keep, each at most the data it caches — the
/// costmap's decoded chunks (`window_cache` bytes at most, f64 per cell of
/// its `cells`), the stored file's chunks (`file_cache` bytes at most, the
/// file's `file_bytes`), and the DEM's decoded tiles for the heights
/// (`dem_cache` bytes at most, f64 per cell of its `dem_cells`; 0
/// without heights).
pub fn route_coarse_to_fine_bytes(
    search_bytes: u64,
    (cells, window_cache): (u64, u64),
    (file_bytes, file_cache): (u64, u64),
    (dem_cells, dem_cache): (u64, u64),
) -> u64 {
    search_bytes
        .saturating_add(cells.saturating_mul(8).min(window_cache))
        .saturating_add(file_bytes.min(file_cache))
        .saturating_add(dem_cells.saturating_mul(8).min(dem_cache))
        .saturating_add(SLACK)
}

/// Why no room was made in the budget.
#[derive(Debug, thiserror::Error)]
pub enum BudgetError {
    /// The work alone needs more than the whole budget.
    #[error("{what} needs about {}, more than the server's memory budget of {} (--memory-budget-mb)", mib(*need), mib(*budget))]
    OverBudget {
        what: String,
        need: u64,
        budget: u64,
    },
    /// Other work held the budget for longer than a request waits.
    #[error(
        "the server's memory budget ({}) is taken by other work: retry in a moment",
        mib(*budget)
    )]
    Busy { budget: u64 },
    #[error("the service is shutting down")]
    Closed,
}

impl From<BudgetError> for ApiError {
    /// Over the budget: 422 (the request is valid but cannot be served
    /// here); waited too long: 503.
    fn from(e: BudgetError) -> Self {
        match e {
            BudgetError::OverBudget { .. } => {
                ApiError::Validation(vec![planner_core::geo::Issue::new("", &e.to_string())])
            }
            BudgetError::Busy { .. } | BudgetError::Closed => ApiError::Unavailable(e.to_string()),
        }
    }
}

/// The global budget of memory for heavy work.
pub struct MemoryBudget {
    total: u64,
    permits: Arc<Semaphore>,
    trimmer: Arc<Trimmer>,
}

/// Room held in the budget until dropped.
#[must_use = "the room is given back when the reservation is dropped"]
pub struct Reservation {
    permit: Option<OwnedSemaphorePermit>,
    bytes: u64,
    trimmer: Arc<Trimmer>,
}

impl Reservation {
    #[cfg(test)]
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Give back all but `keep` bytes of the room held.
    pub fn shrink_to(&mut self, keep: u64) {
        if keep >= self.bytes {
            return;
        }
        if let Some(permit) = self.permit.as_mut() {
            let held = permit.num_permits();
            let kept = usize::try_from(keep.div_ceil(UNIT))
                .unwrap_or(held)
                .min(held);
            if kept == 0 {
                self.permit = None;
            } else {
                drop(permit.split(held - kept));
            }
        }
        self.bytes = keep;
    }
}

impl Drop for Reservation {
    fn drop(&mut self) {
        self.permit.take();
        if self.bytes >= TRIM_FROM {
            self.trimmer.schedule();
        }
    }
}

impl MemoryBudget {
    /// A budget of `total_mb` MiB.
    pub fn new(total_mb: u64) -> MemoryBudget {
        let total = total_mb.saturating_mul(MIB);
        let units = usize::try_from((total / UNIT).min(u64::from(u32::MAX)))
            .unwrap_or(u32::MAX as usize)
            .min(Semaphore::MAX_PERMITS);
        MemoryBudget {
            total: units as u64 * UNIT,
            permits: Arc::new(Semaphore::new(units)),
            trimmer: Arc::new(Trimmer::default()),
        }
    }

    /// The whole budget, bytes.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// Bytes not reserved now.
    #[cfg(test)]
    pub fn available(&self) -> u64 {
        self.permits.available_permits() as u64 * UNIT
    }

    /// `OverBudget` when `need` bytes alone exceed the budget.
    pub fn check(&self, need: u64, what: &str) -> Result<(), BudgetError> {
        if need > self.total {
            return Err(BudgetError::OverBudget {
                what: what.to_string(),
                need,
                budget: self.total,
            });
        }
        Ok(())
    }

    /// Hold `need` bytes of the budget, waiting (up to two minutes) for
    /// work ahead to give back enough; `what` names the work in a refusal.
    pub async fn reserve(&self, need: u64, what: &str) -> Result<Reservation, BudgetError> {
        self.reserve_within(need, what, Some(QUEUE_TIMEOUT)).await
    }

    /// [`MemoryBudget::reserve`], waiting at most `timeout` (`None`: as
    /// long as it takes, for background jobs).
    pub async fn reserve_within(
        &self,
        need: u64,
        what: &str,
        timeout: Option<Duration>,
    ) -> Result<Reservation, BudgetError> {
        match timeout {
            None => self.reserve_waiting(need, what).await,
            Some(t) => match tokio::time::timeout(t, self.reserve_waiting(need, what)).await {
                Ok(r) => r,
                Err(_) => Err(BudgetError::Busy { budget: self.total }),
            },
        }
    }

    async fn reserve_waiting(&self, need: u64, what: &str) -> Result<Reservation, BudgetError> {
        self.check(need, what)?;
        if need == 0 {
            return Ok(Reservation {
                permit: None,
                bytes: 0,
                trimmer: self.trimmer.clone(),
            });
        }
        // `check` bounds it by the total, which fits a u32 of units.
        let units = u32::try_from(need.div_ceil(UNIT).max(1)).unwrap_or(u32::MAX);
        let permit = self
            .permits
            .clone()
            .acquire_many_owned(units)
            .await
            .map_err(|_| BudgetError::Closed)?;
        Ok(Reservation {
            permit: Some(permit),
            bytes: need,
            trimmer: self.trimmer.clone(),
        })
    }
}

/// Gives freed memory back to the operating system after large work.
#[derive(Default)]
struct Trimmer {
    pending: AtomicBool,
}

impl Trimmer {
    /// Trim soon (once for any number of calls meanwhile).
    fn schedule(self: &Arc<Self>) {
        let Ok(runtime) = tokio::runtime::Handle::try_current() else {
            trim();
            return;
        };
        if self.pending.swap(true, Ordering::AcqRel) {
            return;
        }
        let this = self.clone();
        runtime.spawn(async move {
            tokio::time::sleep(TRIM_DELAY).await;
            this.pending.store(false, Ordering::Release);
            // It walks every arena: off the runtime's threads.
            let _ = tokio::task::spawn_blocking(trim).await;
            if let Some((now, peak)) = rss() {
                tracing::debug!(rss_mib = now / MIB, peak_mib = peak / MIB, "memory trimmed");
            }
        });
    }
}

/// Hand the allocator's free pages back to the operating system.
pub fn trim() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only releases free memory of the allocator's own.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Set glibc's allocator up for a server of large, short-lived buffers:
/// blocks of 1 MiB and more are always mapped on their own (so freeing one
/// returns it at once; by default the threshold rises after each large
/// free, up to 32 MiB, and such blocks then stay in the heap), and at most
/// four arenas (by default eight per core, each keeping its own free
/// memory). Call once, before the worker threads start.
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes the allocator's parameters.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 1024 * 1024);
        libc::mallopt(libc::M_ARENA_MAX, 4);
    }
}

/// The process' resident set now and at its peak (VmRSS, VmHWM), bytes,
/// from `/proc/self/status`.
pub fn rss() -> Option<(u64, u64)> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let field = |name: &str| -> Option<u64> {
        let v = status.lines().find_map(|l| l.strip_prefix(name))?;
        Some(v.trim().trim_end_matches("kB").trim().parse::<u64>().ok()? * 1024)
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn work_waits_for_room_and_the_oversized_is_refused() {
        let budget = MemoryBudget::new(10);
        assert_eq!(budget.total(), 10 * MIB);
        let a = budget.reserve(6 * MIB, "a").await.unwrap();
        assert_eq!(budget.available(), 4 * MIB);
        // 5 MiB does not fit beside a's 6: it waits until a is dropped.
        let waiting = budget.reserve(5 * MIB, "b");
        tokio::pin!(waiting);
        assert!(
            tokio::time::timeout(Duration::from_millis(50), &mut waiting)
                .await
                .is_err()
        );
        drop(a);
        let b = waiting.await.unwrap();
        assert_eq!(b.bytes(), 5 * MIB);
        assert_eq!(budget.available(), 5 * MIB);
        drop(b);
        assert_eq!(budget.available(), 10 * MIB);
        let mut c = budget.reserve(8 * MIB, "c").await.unwrap();
        c.shrink_to(3 * MIB);
        assert_eq!((c.bytes(), budget.available()), (3 * MIB, 7 * MIB));
        c.shrink_to(0);
        assert_eq!(budget.available(), 10 * MIB);
        drop(c);
        assert_eq!(budget.available(), 10 * MIB);
        let none = budget.reserve(0, "nothing").await.unwrap();
        assert_eq!((none.bytes(), budget.available()), (0, 10 * MIB));

        let Err(e) = budget.reserve(10 * MIB + 1, "reading the DEM").await else {
            panic!("over the budget");
        };
        assert_eq!(
            e.to_string(),
            "reading the DEM needs about 10.0 MiB, more than the server's memory budget of \
             10.0 MiB (--memory-budget-mb)"
        );
        let api: ApiError = e.into();
        assert_eq!(api.status(), axum::http::StatusCode::UNPROCESSABLE_ENTITY);
        // The whole budget is allowed.
        drop(budget.reserve(10 * MIB, "all").await.unwrap());
    }

    #[test]
    fn estimates() {
        // A 8000 × 8000 Float64 single-strip TIFF of 486 KB.
        let px = 64_000_000;
        let need = dem_read_bytes(px, px * 8, 486_000);
        assert_eq!(need, 1_024_000_000 + 972_000 + SLACK);
        // Hillshade of it at 1024: reduced by 8 to 1000 × 1000.
        assert_eq!(hillshade_bytes(8000, 8000, 1024), 12_000_000 + SLACK);
        assert_eq!(hillshade_bytes(100, 50, 1024), 5000 * 12 + SLACK);
        assert_eq!(costmap_build_bytes(1000, 0), 21_000 + 2 * SLACK);
        assert_eq!(route_search_bytes(1000, 5000), 41_000 + 5000 + SLACK);
        // A costmap of 1 M cells (8 MB decoded, a 5 MB file) and a DEM of
        // 4 M cells: each source's cache bounded by its data or its cap.
        assert_eq!(
            route_coarse_to_fine_bytes(
                100,
                (1_000_000, 16 * MIB),
                (5_000_000, 8 * MIB),
                (4_000_000, 64 * MIB)
            ),
            100 + 8_000_000 + 5_000_000 + 32_000_000 + SLACK
        );
        assert_eq!(
            route_coarse_to_fine_bytes(0, (u64::MAX, 16 * MIB), (u64::MAX, 8 * MIB), (0, 64 * MIB)),
            24 * MIB + SLACK
        );
        assert_eq!(dem_read_bytes(u64::MAX, 1, 1), u64::MAX);
    }

    #[test]
    fn readable_sizes() {
        assert_eq!(mib(1536 * 1024), "1.5 MiB");
        assert_eq!(mib(1_024_000_000 + SLACK), "993 MiB");
        assert!(default_budget_mb() >= 256);
    }
}
