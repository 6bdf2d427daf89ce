//! A stored file (its chunks in the database) as a source of positioned
//! reads ([`ReadAt`]), so that a costmap's GeoTIFF is read a window at a
//! time ([`planner_core::terrain::GeoTiffWindows`]) without the whole file
//! in memory: the chunks a read needs are fetched in one query, blocking
//! the calling thread (a planner thread, never an async worker), and the
//! last few kept in a small LRU.

use std::io;
use std::sync::{Arc, Mutex};

use planner_core::terrain::ReadAt;

use crate::db::{Db, StoredFile};

/// Chunks kept (1 MiB each at most): a tile of the costmap spans one or
/// two, and a window of tiles a few.
pub const CACHED_CHUNKS: usize = 8;

/// Most chunks fetched by one query (a large read is served in parts).
const CHUNKS_PER_QUERY: usize = 4;

/// A stored file read by byte ranges.
pub struct StoredFileReader {
    db: Db,
    runtime: tokio::runtime::Handle,
    file: StoredFile,
    /// Where each chunk starts in the file (chunk `i` has seq `i`), and
    /// the file's length last.
    starts: Vec<u64>,
    /// Most recently used first: (chunk index, bytes).
    cache: Mutex<Vec<(usize, Arc<Vec<u8>>)>>,
    capacity: usize,
}

/// Why a stored file cannot be read by ranges.
#[derive(Debug, thiserror::Error)]
pub enum StoredFileError {
    #[error(transparent)]
    Db(#[from] sqlx::Error),
    #[error("the stored file is damaged: {0}")]
    Damaged(String),
}

impl StoredFileReader {
    /// The stored `file` of `size` bytes (its owner's record), read by
    /// ranges; keeps `capacity` chunks (at least one). Reads must come from
    /// threads that may block (see [`tokio::runtime::Handle::block_on`]).
    ///
    /// # Errors
    ///
    /// The database's, and chunks that do not make up `size` bytes in
    /// order from seq 0 (the file was deleted or is being rewritten).
    pub async fn open(
        db: Db,
        file: StoredFile,
        size: u64,
        capacity: usize,
    ) -> Result<StoredFileReader, StoredFileError> {
        let lengths = db.file_chunk_lengths(&file).await?;
        let mut starts = Vec::with_capacity(lengths.len() + 1);
        let mut at = 0u64;
        for (i, &(seq, len)) in lengths.iter().enumerate() {
            if seq != i as i64 || len <= 0 {
                return Err(StoredFileError::Damaged(format!(
                    "chunk {i} is seq {seq} of {len} bytes"
                )));
            }
            starts.push(at);
            at += len as u64;
        }
        if at != size {
            return Err(StoredFileError::Damaged(format!(
                "its chunks hold {at} bytes, its record says {size}"
            )));
        }
        starts.push(at);
        Ok(StoredFileReader {
            db,
            runtime: tokio::runtime::Handle::current(),
            file,
            starts,
            cache: Mutex::new(Vec::new()),
            capacity: capacity.max(1),
        })
    }

    fn len(&self) -> u64 {
        self.starts.last().copied().unwrap_or(0)
    }

    fn chunks(&self) -> usize {
        self.starts.len() - 1
    }

    fn cached(&self, i: usize) -> Option<Arc<Vec<u8>>> {
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        let at = cache.iter().position(|(k, _)| *k == i)?;
        let entry = cache.remove(at);
        let bytes = Arc::clone(&entry.1);
        cache.insert(0, entry);
        Some(bytes)
    }

    fn keep(&self, i: usize, bytes: Arc<Vec<u8>>) {
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        cache.retain(|(k, _)| *k != i);
        cache.insert(0, (i, bytes));
        cache.truncate(self.capacity);
    }

    /// Chunk `i`, from the cache or fetched with the chunks after it that
    /// the read up to file offset `end` needs.
    fn chunk(&self, i: usize, end: u64) -> io::Result<Arc<Vec<u8>>> {
        if let Some(bytes) = self.cached(i) {
            return Ok(bytes);
        }
        let last = self
            .starts
            .partition_point(|&s| s < end)
            .saturating_sub(1)
            .clamp(
                i,
                (i + CHUNKS_PER_QUERY.min(self.capacity) - 1).min(self.chunks() - 1),
            );
        let fetched = self
            .runtime
            .block_on(
                self.db
                    .file_chunks_between(&self.file, i as i64, last as i64),
            )
            .map_err(|e| io::Error::other(format!("reading the stored file: {e}")))?;
        let mut wanted = None;
        for (k, (seq, data)) in fetched.into_iter().enumerate() {
            let index = i + k;
            let expected = self.starts[index + 1] - self.starts[index];
            if seq != index as i64 || data.len() as u64 != expected {
                return Err(io::Error::other(format!(
                    "the stored file changed while it was read (chunk {index})"
                )));
            }
            let bytes = Arc::new(data);
            if index == i {
                wanted = Some(Arc::clone(&bytes));
            }
            self.keep(index, bytes);
        }
        wanted.ok_or_else(|| {
            io::Error::other(format!(
                "chunk {i} of the stored file is missing (deleted meanwhile?)"
            ))
        })
    }
}

impl ReadAt for StoredFileReader {
    /// The bytes at `offset` up to the end of its chunk (a short read:
    /// callers read on).
    fn read_at(&self, offset: u64, buf: &mut [u8]) -> io::Result<usize> {
        if buf.is_empty() || offset >= self.len() {
            return Ok(0);
        }
        let i = self.starts.partition_point(|&s| s <= offset) - 1;
        let end = offset.saturating_add(buf.len() as u64).min(self.len());
        let bytes = self.chunk(i, end)?;
        let from = (offset - self.starts[i]) as usize;
        let n = buf.len().min(bytes.len() - from);
        buf[..n].copy_from_slice(&bytes[from..from + n]);
        Ok(n)
    }

    fn size(&self) -> io::Result<u64> {
        Ok(self.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use planner_core::terrain::{DemLimits, GeoTiffWindows, RasterWindows};
    use std::path::PathBuf;

    fn shared_dem(name: &str) -> PathBuf {
        std::env::var("TERRAPLAN_SHARED_DATA")
            .map_or_else(
                |_| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
                PathBuf::from,
            )
            .join("dems")
            .join(name)
    }

    /// A DEM row whose file is `data` in chunks of the `sizes` given
    /// (repeated), written as the upload writes chunks.
    async fn store(db: &Db, id: &str, data: &[u8], sizes: &[usize]) {
        let row = crate::db::DemMetaRow {
            id: id.into(),
            name: None,
            created_at: 1,
            file_name: Some("x.tif".into()),
            crs_override: None,
            info: "{}".into(),
            size_bytes: data.len() as i64,
            read_bytes: None,
            project_id: None,
        };
        db.insert_dem(&row, &[]).await.unwrap();
        let Db::Sqlite(pool) = db else {
            unreachable!("tests run on SQLite")
        };
        let (mut at, mut seq) = (0, 0);
        while at < data.len() {
            let n = sizes[seq % sizes.len()].min(data.len() - at);
            sqlx::query("INSERT INTO dem_chunks (dem_id, seq, data) VALUES ($1, $2, $3)")
                .bind(id)
                .bind(seq as i64)
                .bind(&data[at..at + n])
                .execute(pool)
                .await
                .unwrap();
            at += n;
            seq += 1;
        }
    }

    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// A GeoTIFF stored in uneven chunks reads a window at a time through
    /// the chunk reader bit for bit as from the file, with a cache of one
    /// chunk and of several; every byte range reads as the bytes.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn windows_over_stored_chunks_equal_the_file() {
        let dir = std::env::temp_dir().join(format!("terraplan-chunks-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = Db::connect(None, &dir).await.unwrap();
        let path = shared_dem("demcompare__srtm_ref.tif");
        let bytes = std::fs::read(&path).unwrap();
        // Chunks of odd sizes, so headers, tiles and strips straddle them.
        store(&db, "odd", &bytes, &[100_003, 7, 65_536, 333_333]).await;
        store(&db, "mib", &bytes, &[crate::db::CHUNK_BYTES]).await;
        for (id, capacity) in [("odd", 1), ("odd", CACHED_CHUNKS), ("mib", 2)] {
            let reader = StoredFileReader::open(
                db.clone(),
                StoredFile::Dem(id.into()),
                bytes.len() as u64,
                capacity,
            )
            .await
            .unwrap();
            let want = bytes.clone();
            let file = std::fs::File::open(&path).unwrap();
            tokio::task::spawn_blocking(move || {
                // Byte ranges, across chunk borders and past the end.
                for (at, len) in [(0, 10), (99_990, 30), (100_003, 7), (0, 400_000)]
                    .into_iter()
                    .chain([(want.len() - 5, 20), (want.len() + 3, 4)])
                {
                    let mut buf = vec![0u8; len];
                    let mut done = 0;
                    while done < len {
                        let n = reader
                            .read_at((at + done) as u64, &mut buf[done..])
                            .unwrap();
                        if n == 0 {
                            break;
                        }
                        done += n;
                    }
                    let expect = &want[at.min(want.len())..(at + len).min(want.len())];
                    assert_eq!(&buf[..done], expect, "{id}: {len} bytes at {at}");
                }
                let limits = DemLimits::default();
                let stored = GeoTiffWindows::open(reader, None, &limits).unwrap();
                let disk = GeoTiffWindows::open(file, None, &limits).unwrap();
                let g = disk.grid().clone();
                assert_eq!(
                    (
                        stored.grid().width,
                        stored.grid().height,
                        stored.grid().transform
                    ),
                    (g.width, g.height, g.transform)
                );
                let (w, h) = (g.width, g.height);
                for (c0, r0, ww, hh) in [
                    (0, 0, w, h),
                    (w / 3, h / 5, w / 2, 7),
                    (w - 1, h - 1, 1, 1),
                    (5, h / 2, 300.min(w - 5), h / 2),
                ] {
                    let mut a = vec![0.0; ww * hh];
                    let mut b = vec![1.0; ww * hh];
                    stored.read_window(c0, r0, ww, hh, &mut a).unwrap();
                    disk.read_window(c0, r0, ww, hh, &mut b).unwrap();
                    assert!(
                        a.iter().zip(&b).all(|(x, y)| same(*x, *y)),
                        "{id}: window {c0},{r0} {ww}×{hh}"
                    );
                }
            })
            .await
            .unwrap();
        }
        // A record longer than the chunks is refused at once.
        let long = StoredFileReader::open(
            db.clone(),
            StoredFile::Dem("odd".into()),
            bytes.len() as u64 + 1,
            1,
        )
        .await;
        assert!(matches!(long, Err(StoredFileError::Damaged(_))));
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
