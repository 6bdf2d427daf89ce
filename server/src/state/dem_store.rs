//! The stored DEMs, parsed: upload limits, the spool directory, the small
//! cache of parsed rasters and the loader that reads a stored DEM (once)
//! with room for it in the memory budget, for handlers and costmap jobs.

pub mod tiles;
pub mod uploads;

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use planner_core::terrain::{Dem, DemLimits, read_dem};
use serde::Deserialize;

use super::planners::{Planners, Work};
use crate::config::ServeConfig;
use crate::db::{Db, DemMetaRow};
use crate::error::{ApiError, not_found};
use crate::memory::{MemoryBudget, QUEUE_TIMEOUT, Reservation, dem_read_bytes};

/// Parsed DEMs kept at once, at most.
const DEM_CACHE_ENTRIES: usize = 4;
/// Spool files untouched for this long belong to no upload in progress
/// (the server stopped during it): removed at start-up.
const STALE_SPOOL: Duration = Duration::from_secs(3600);

/// DEM upload limits and the parsed DEMs kept ready for sampling.
pub struct DemStore {
    /// Pixel limits checked from a raster's header at upload.
    pub limits: DemLimits,
    /// Largest DEM file accepted, bytes.
    pub max_upload_bytes: usize,
    pub cache: DemCache,
    /// Where uploads are written as they arrive, before they are read.
    pub spool_dir: PathBuf,
}

impl DemStore {
    pub fn new(limits: DemLimits, max_upload_bytes: usize, cache_bytes: usize) -> DemStore {
        DemStore {
            limits,
            max_upload_bytes,
            cache: DemCache::new(DEM_CACHE_ENTRIES, cache_bytes),
            spool_dir: std::env::temp_dir(),
        }
    }

    pub fn from_config(config: &ServeConfig) -> DemStore {
        let cache_bytes = config.dem_cache_mb.saturating_mul(1024 * 1024);
        DemStore {
            spool_dir: spool_dir(&config.data_dir),
            ..DemStore::new(
                config.dem_limits(),
                config.max_dem_bytes(),
                usize::try_from(cache_bytes).unwrap_or(usize::MAX),
            )
        }
    }
}

/// Where uploads are spooled under `data_dir`, with the files left behind
/// by a server that stopped during an upload removed.
fn spool_dir(data_dir: &Path) -> PathBuf {
    let dir = data_dir.join("uploads");
    if let Ok(entries) = std::fs::read_dir(&dir) {
        for entry in entries.flatten() {
            let stale = entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t.elapsed().is_ok_and(|age| age > STALE_SPOOL));
            if stale && entry.path().extension().is_some_and(|e| e == "part") {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    dir
}

/// A small LRU of parsed DEMs, bounded by count and by the memory of
/// their heights.
pub struct DemCache {
    inner: Mutex<CacheInner>,
    max_entries: usize,
    max_bytes: usize,
}

struct CacheInner {
    /// Most recently used first.
    entries: Vec<(String, Arc<Dem>)>,
    /// Bumped by every eviction, so a load that raced a delete does not
    /// put the deleted DEM back.
    epoch: u64,
}

fn dem_bytes(dem: &Dem) -> usize {
    dem.values.len() * std::mem::size_of::<f64>()
}

impl DemCache {
    pub fn new(max_entries: usize, max_bytes: usize) -> DemCache {
        DemCache {
            inner: Mutex::new(CacheInner {
                entries: Vec::new(),
                epoch: 0,
            }),
            max_entries,
            max_bytes,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        // The lock guards no invariant a panic could break half-way.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn get(&self, id: &str) -> Option<Arc<Dem>> {
        let mut inner = self.lock();
        let i = inner.entries.iter().position(|(k, _)| k == id)?;
        let entry = inner.entries.remove(i);
        let dem = entry.1.clone();
        inner.entries.insert(0, entry);
        Some(dem)
    }

    /// The current eviction count, to pass to [`DemCache::insert`].
    pub fn epoch(&self) -> u64 {
        self.lock().epoch
    }

    /// Keep `dem` as the most recently used, unless something was evicted
    /// since `epoch` (when given) or it alone is over the memory budget.
    pub fn insert(&self, id: &str, dem: Arc<Dem>, epoch: Option<u64>) {
        let size = dem_bytes(&dem);
        let mut inner = self.lock();
        if epoch.is_some_and(|e| e != inner.epoch) || size > self.max_bytes || self.max_entries == 0
        {
            return;
        }
        inner.entries.retain(|(k, _)| k != id);
        inner.entries.insert(0, (id.to_string(), dem));
        let mut total = 0usize;
        let mut keep = 0;
        for (_, d) in &inner.entries {
            let next = total.saturating_add(dem_bytes(d));
            if keep == self.max_entries || next > self.max_bytes {
                break;
            }
            total = next;
            keep += 1;
        }
        inner.entries.truncate(keep);
    }

    pub fn evict(&self, id: &str) {
        let mut inner = self.lock();
        inner.entries.retain(|(k, _)| k != id);
        inner.epoch += 1;
    }
}

/// A stored DEM's width and height, from its stored info.
pub fn stored_size(row: &DemMetaRow) -> Result<(u64, u64), ApiError> {
    #[derive(Deserialize)]
    struct Size {
        width: u64,
        height: u64,
    }
    let size: Size = serde_json::from_str(&row.info).map_err(|e| {
        ApiError::Internal(format!("stored DEM info of {} unreadable: {e}", row.id))
    })?;
    Ok((size.width, size.height))
}

/// What reading a stored DEM needs: the database it is stored in, the
/// cache, the memory budget and the DEM planner slots.
#[derive(Clone)]
pub struct DemLoader {
    pub db: Db,
    pub store: Arc<DemStore>,
    pub memory: Arc<MemoryBudget>,
    pub planner: Arc<Planners>,
}

impl DemLoader {
    /// A stored DEM, parsed (from the cache when it is there); 404 when
    /// there is no DEM `id`.
    pub async fn load(&self, id: &str) -> Result<Arc<Dem>, ApiError> {
        Ok(self.load_for(id, "", |_, _| 0).await?.0)
    }

    /// [`DemLoader::load`], holding room in the memory budget for `work`
    /// bytes of work on the DEM (given its width and height) as well,
    /// and, when the DEM is not in the cache, for reading it; the room is
    /// held until the returned reservation is dropped. `what` names the
    /// work in a refusal (a 422 when it alone needs more than the budget).
    pub async fn load_for(
        &self,
        id: &str,
        what: &str,
        work: impl FnOnce(u64, u64) -> u64,
    ) -> Result<(Arc<Dem>, Reservation), ApiError> {
        self.load_within(id, what, work, Some(QUEUE_TIMEOUT)).await
    }

    /// [`DemLoader::load_for`] waiting for room in the budget at most
    /// `timeout` (`None`: as long as it takes, for background jobs).
    pub async fn load_within(
        &self,
        id: &str,
        what: &str,
        work: impl FnOnce(u64, u64) -> u64,
        timeout: Option<Duration>,
    ) -> Result<(Arc<Dem>, Reservation), ApiError> {
        let doing = |w: u64, h: u64| {
            let on = format!("DEM {id} ({w} × {h} pixels)");
            if what.is_empty() {
                format!("reading {on}")
            } else {
                format!("{what} on {on}")
            }
        };
        let cache = &self.store.cache;
        if let Some(dem) = cache.get(id) {
            let (w, h) = (dem.width as u64, dem.height as u64);
            let room = self
                .memory
                .reserve_within(work(w, h), &doing(w, h), timeout)
                .await?;
            return Ok((dem, room));
        }
        let epoch = cache.epoch();
        let meta = self
            .db
            .get_dem_meta(id)
            .await?
            .ok_or_else(|| not_found("DEM", id))?;
        let (w, h) = stored_size(&meta)?;
        let size = u64::try_from(meta.size_bytes).unwrap_or(0);
        let read = match meta.read_bytes.and_then(|b| u64::try_from(b).ok()) {
            Some(b) => b,
            // Stored before the estimate was kept: the whole image as one
            // Float64 chunk at worst.
            None => {
                let pixels = w.saturating_mul(h);
                dem_read_bytes(pixels, pixels.saturating_mul(8), size)
            }
        };
        let work_bytes = work(w, h);
        let need = read.saturating_add(work_bytes);
        let mut room = self
            .memory
            .reserve_within(need, &doing(w, h), timeout)
            .await?;
        let dem = Arc::new(self.read(&meta).await?);
        cache.insert(id, dem.clone(), Some(epoch));
        if cache.get(id).is_some_and(|d| Arc::ptr_eq(&d, &dem)) {
            // Kept in the cache, whose memory is its own: only the work's
            // room is still needed.
            room.shrink_to(work_bytes);
        }
        Ok((dem, room))
    }

    /// Read stored DEM `meta` again, on a DEM planner slot: from its tiles
    /// when it has them, else from its file.
    async fn read(&self, meta: &DemMetaRow) -> Result<Dem, ApiError> {
        let id = meta.id.as_str();
        let info = crate::api::dems::stored_dem_info(meta)?;
        if let Some((set, grid)) = tiles::stored_set(&self.db, id, &info).await? {
            let src = tiles::StoredTiles::new(
                self.db.clone(),
                tokio::runtime::Handle::current(),
                id,
                set,
                0,
                &grid,
            );
            let format = info.format;
            return self
                .planner
                .run(Work::Dem, move |_| src.read_whole(format))
                .await?
                .map_err(|e| {
                    ApiError::Internal(format!("stored DEM {id} does not read again: {e}"))
                });
        }
        let row = self
            .db
            .get_dem_data(id)
            .await?
            .ok_or_else(|| not_found("DEM", id))?;
        let crs = row
            .crs_override
            .map(u32::try_from)
            .transpose()
            .map_err(|e| ApiError::Internal(format!("stored CRS of DEM {id}: {e}")))?;
        // It was read once at upload: the limits of the day need not hold again.
        let limits = DemLimits {
            max_pixels: u64::MAX,
            max_side: u32::MAX,
        };
        self.planner
            .run(Work::Dem, move |_| {
                read_dem(&row.data, row.file_name.as_deref(), crs, &limits)
            })
            .await?
            .map_err(|e| ApiError::Internal(format!("stored DEM {id} does not read again: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use planner_core::terrain::{Crs, DemFormat, GeoTransform};

    use super::*;

    fn dem(pixels: usize) -> Arc<Dem> {
        Arc::new(Dem {
            width: pixels,
            height: 1,
            values: vec![1.0; pixels],
            nodata: None,
            transform: GeoTransform {
                origin_x: 0.0,
                pixel_width: 1.0,
                row_rotation: 0.0,
                origin_y: 0.0,
                col_rotation: 0.0,
                pixel_height: -1.0,
            },
            crs: Crs {
                epsg: 32633,
                name: "WGS 84 / UTM zone 33N".into(),
                geographic: false,
                proj4: String::new(),
            },
            format: DemFormat::Asc,
        })
    }

    #[test]
    fn dem_cache_is_lru_by_count_and_bytes() {
        let cache = DemCache::new(2, 8 * 100);
        cache.insert("a", dem(10), None);
        cache.insert("b", dem(10), None);
        assert!(cache.get("a").is_some()); // a is now the most recent
        cache.insert("c", dem(10), None);
        assert!(cache.get("b").is_none(), "least recently used goes first");
        assert!(cache.get("a").is_some() && cache.get("c").is_some());
        // Bytes: 90 + 10 pixels fit, 91 + 10 do not.
        cache.insert("big", dem(90), None);
        assert!(cache.get("big").is_some() && cache.get("c").is_some());
        cache.insert("bigger", dem(91), None);
        assert!(cache.get("bigger").is_some());
        assert!(cache.get("big").is_none());
        // Alone over the budget: not kept.
        cache.insert("huge", dem(101), None);
        assert!(cache.get("huge").is_none());
    }

    #[test]
    fn eviction_beats_a_racing_load() {
        let cache = DemCache::new(4, usize::MAX);
        let epoch = cache.epoch();
        cache.evict("a"); // deleted while being loaded
        cache.insert("a", dem(1), Some(epoch));
        assert!(cache.get("a").is_none());
        cache.insert("a", dem(1), Some(cache.epoch()));
        assert!(cache.get("a").is_some());
        cache.evict("a");
        assert!(cache.get("a").is_none());
    }
}
