//! The classes of a tiled costmap run between its passes, on disk: one
//! byte per working cell in a scratch file (row-major), read and written
//! a window at a time, so the run's memory stays bounded by its tiles
//! whatever the map's size. The file is removed when the store is
//! dropped (on Unix at once: it is unlinked as soon as it is open, so a
//! killed run leaves nothing behind).

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use super::tile_stages::ClassWindows;
use super::tiled::TiledError;

/// The bit set on cells without a height (class `Unknown` either way):
/// inflation grows from those, not from the border ring's unknown cells.
pub const HOLE_BIT: u8 = 0x80;

/// A `width`×`height` grid of bytes in a scratch file.
pub struct ClassStore {
    /// Locked for a read, so windows are read from several threads.
    file: Mutex<File>,
    path: PathBuf,
    /// Still to remove on drop (not unlinked at creation).
    remove_on_drop: bool,
    width: usize,
    height: usize,
}

impl ClassStore {
    /// A zeroed store in a new file in `dir`.
    pub fn create(dir: &Path, width: usize, height: usize) -> io::Result<ClassStore> {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let name = format!(
            "terraplan-costmap-classes-{}-{}.bin",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let path = dir.join(name);
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)?;
        let len = (width as u64)
            .checked_mul(height as u64)
            .ok_or_else(|| io::Error::other("the class store's size overflows"))?;
        let remove_now = cfg!(unix);
        file.set_len(len)?;
        let store = ClassStore {
            file: Mutex::new(file),
            path: path.clone(),
            remove_on_drop: !remove_now,
            width,
            height,
        };
        if remove_now {
            std::fs::remove_file(&path)?;
        }
        Ok(store)
    }

    /// Fails unless the window lies inside the store and `len` (when
    /// given) is its size; checked before anything is allocated.
    fn check(
        &self,
        col0: usize,
        row0: usize,
        w: usize,
        h: usize,
        len: Option<usize>,
    ) -> io::Result<()> {
        let inside = col0.checked_add(w).is_some_and(|c| c <= self.width)
            && row0.checked_add(h).is_some_and(|r| r <= self.height);
        if !inside || len.is_some_and(|n| n != w * h) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "window {w}×{h} at ({col0}, {row0}){} is not inside the {}×{} class store",
                    len.map_or(String::new(), |n| format!(" with {n} values")),
                    self.width,
                    self.height
                ),
            ));
        }
        Ok(())
    }

    /// Writes the `w`×`h` block `data` with its top-left at (`col0`, `row0`).
    pub fn write(
        &mut self,
        col0: usize,
        row0: usize,
        w: usize,
        h: usize,
        data: &[u8],
    ) -> io::Result<()> {
        self.check(col0, row0, w, h, Some(data.len()))?;
        let file = self.file.get_mut().unwrap_or_else(|p| p.into_inner());
        for (r, row) in data.chunks(w.max(1)).enumerate().take(h) {
            let at = ((row0 + r) * self.width + col0) as u64;
            file.seek(SeekFrom::Start(at))?;
            file.write_all(row)?;
        }
        Ok(())
    }

    /// Reads the `w`×`h` block with its top-left at (`col0`, `row0`) into
    /// `out` (resized to it).
    pub fn read(
        &self,
        col0: usize,
        row0: usize,
        w: usize,
        h: usize,
        out: &mut Vec<u8>,
    ) -> io::Result<()> {
        self.check(col0, row0, w, h, None)?;
        out.resize(w * h, 0);
        let mut file = self.file.lock().unwrap_or_else(|p| p.into_inner());
        for (r, row) in out.chunks_mut(w.max(1)).enumerate().take(h) {
            let at = ((row0 + r) * self.width + col0) as u64;
            file.seek(SeekFrom::Start(at))?;
            file.read_exact(row)?;
        }
        Ok(())
    }
}

impl ClassWindows for ClassStore {
    fn read_classes(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut Vec<u8>,
    ) -> Result<(), TiledError> {
        self.read(col0, row0, width, height, out)
            .map_err(TiledError::Scratch)
    }
}

impl Drop for ClassStore {
    fn drop(&mut self) {
        if self.remove_on_drop {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_read_back_what_was_written_and_nothing_is_left_behind() {
        let dir = std::env::temp_dir();
        let mut s = ClassStore::create(&dir, 7, 5).unwrap();
        s.write(2, 1, 3, 2, &[1, 2, 3, 4, 5, 6]).unwrap();
        let mut out = Vec::new();
        s.read(1, 0, 5, 3, &mut out).unwrap();
        assert_eq!(out, vec![0, 0, 0, 0, 0, 0, 1, 2, 3, 0, 0, 4, 5, 6, 0]);
        assert!(s.read(5, 0, 3, 1, &mut out).is_err());
        assert!(s.write(0, 4, 2, 2, &[0; 4]).is_err());
        let path = s.path.clone();
        drop(s);
        assert!(!path.exists(), "{}", path.display());
    }
}
