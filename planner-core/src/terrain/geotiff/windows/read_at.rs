//! Where a [`GeoTiffWindows`](super::GeoTiffWindows) reads its bytes: any
//! source of positioned reads — a file on disk, a buffer, or (in the
//! server) a file stored in the database in chunks.

use std::fs::File;
use std::io;
use std::os::unix::fs::FileExt;

/// A byte source read at given positions, from several threads at once.
pub trait ReadAt: Send + Sync + 'static {
    /// Reads up to `buf.len()` bytes at `offset` into `buf`: how many it
    /// read, 0 at or past the end.
    ///
    /// # Errors
    ///
    /// Whatever the source fails with.
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize>;

    /// The source's length in bytes.
    ///
    /// # Errors
    ///
    /// Whatever the source fails with.
    fn size(&self) -> io::Result<u64>;
}

impl ReadAt for File {
    #[inline]
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize> {
        FileExt::read_at(self, buf, offset)
    }

    fn size(&self) -> io::Result<u64> {
        Ok(self.metadata()?.len())
    }
}

/// One source shared, e.g. by the windows of several pages of a file.
impl<T: ReadAt + ?Sized> ReadAt for std::sync::Arc<T> {
    #[inline]
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize> {
        (**self).read_at(offset, buf)
    }

    fn size(&self) -> io::Result<u64> {
        (**self).size()
    }
}

impl ReadAt for Vec<u8> {
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize> {
        let start = usize::try_from(offset)
            .unwrap_or(usize::MAX)
            .min(self.len());
        let n = buf.len().min(self.len() - start);
        buf[..n].copy_from_slice(&self[start..start + n]);
        Ok(n)
    }

    fn size(&self) -> io::Result<u64> {
        Ok(self.len() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// Every (offset, length) of a short source through `src`, against the
    /// bytes themselves: short reads only at the end, 0 past it.
    fn reads_like_the_bytes(src: &dyn ReadAt, bytes: &[u8]) {
        assert_eq!(src.size().unwrap(), bytes.len() as u64);
        for at in 0..=bytes.len() + 3 {
            for len in 0..=bytes.len() + 2 {
                let mut buf = vec![0xAAu8; len];
                let mut done = 0;
                while done < len {
                    let n = src.read_at((at + done) as u64, &mut buf[done..]).unwrap();
                    if n == 0 {
                        break;
                    }
                    done += n;
                }
                let want = &bytes[at.min(bytes.len())..(at + len).min(bytes.len())];
                assert_eq!(&buf[..done], want, "at {at}, {len} bytes");
            }
        }
    }

    #[test]
    fn a_file_and_a_buffer_read_their_bytes_at_any_offset() {
        let bytes: Vec<u8> = (0..97u32).map(|i| (i * 37 % 251) as u8).collect();
        let path =
            std::env::temp_dir().join(format!("terraplan-read-at-{}.bin", std::process::id()));
        std::fs::File::create(&path)
            .unwrap()
            .write_all(&bytes)
            .unwrap();
        let file = File::open(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        reads_like_the_bytes(&file, &bytes);
        reads_like_the_bytes(&bytes.clone(), &bytes);
        reads_like_the_bytes(&std::sync::Arc::new(file), &bytes);
        reads_like_the_bytes(&Vec::new(), &[]);
    }
}
