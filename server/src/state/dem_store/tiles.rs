//! DEMs as tiles (issue 22 item 1): a raster cut into 512² tiles with
//! overviews (each level the 2×2 mean of the one below, down to one tile),
//! each tile compressed with zlib; and [`StoredTiles`], a
//! [`RasterWindows`] over the tiles in the database, with an LRU of
//! decoded tiles, so any window of a stored DEM is read without the rest.
//!
//! Cutting reads the source a band of 512 rows at a time (a strip-organised
//! GeoTIFF is then decoded strip by strip), and the overviews are made as
//! the bands pass (each level keeps at most one band of its rows): memory
//! is a few bands of the raster's width, whatever its height.

use std::io::{Read, Write};
use std::sync::{Arc, Mutex};

use planner_core::terrain::{
    CellCache, Dem, DemFormat, GeoTransform, RasterGrid, RasterWindows, TerrainError, check_window,
};

use crate::db::{Db, DemTileRow, DemTileSetRow};
use crate::error::ApiError;
use crate::state::dem_store::uploads::{UploadLease, swept_error};
use crate::state::{Planners, Work};

/// Tiles written per transaction.
const TILES_PER_INSERT: usize = 16;

/// Cells per tile side.
pub const TILE_SIDE: usize = 512;

/// Decoded tiles a [`StoredTiles`] keeps, bytes (as f64 cells).
pub const TILE_CACHE_BYTES: usize = 64 << 20;

/// How a tile's samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileSample {
    F32,
    F64,
}

impl TileSample {
    pub fn name(self) -> &'static str {
        match self {
            TileSample::F32 => "f32",
            TileSample::F64 => "f64",
        }
    }

    pub fn from_name(name: &str) -> Option<TileSample> {
        match name {
            "f32" => Some(TileSample::F32),
            "f64" => Some(TileSample::F64),
            _ => None,
        }
    }

    pub fn bytes(self) -> usize {
        match self {
            TileSample::F32 => 4,
            TileSample::F64 => 8,
        }
    }
}

/// The tiles of one DEM: their size, sample type and levels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileSet {
    pub width: usize,
    pub height: usize,
    pub tile_side: usize,
    pub sample: TileSample,
    pub levels: usize,
}

impl TileSet {
    /// The tile set of a `width` × `height` raster, its levels down to the
    /// first that fits one tile.
    pub fn new(width: usize, height: usize, sample: TileSample) -> TileSet {
        let (mut w, mut h, mut levels) = (width, height, 1);
        while w > TILE_SIDE || h > TILE_SIDE {
            w = w.div_ceil(2);
            h = h.div_ceil(2);
            levels += 1;
        }
        TileSet {
            width,
            height,
            tile_side: TILE_SIDE,
            sample,
            levels,
        }
    }

    /// Width and height of level `level` (0: the DEM itself).
    pub fn level_size(&self, level: usize) -> (usize, usize) {
        let (mut w, mut h) = (self.width, self.height);
        for _ in 0..level {
            w = w.div_ceil(2);
            h = h.div_ceil(2);
        }
        (w, h)
    }

    /// Tiles across and down at `level`.
    pub fn tiles(&self, level: usize) -> (usize, usize) {
        let (w, h) = self.level_size(level);
        (w.div_ceil(self.tile_side), h.div_ceil(self.tile_side))
    }

    /// Width and height of tile (`col`, `row`) of `level` (cut at the edges).
    pub fn tile_size(&self, level: usize, col: usize, row: usize) -> (usize, usize) {
        let (w, h) = self.level_size(level);
        let s = self.tile_side;
        (s.min(w - col * s), s.min(h - row * s))
    }

    /// The tiles of every level.
    #[cfg(test)]
    pub fn tile_count(&self) -> u64 {
        (0..self.levels)
            .map(|l| {
                let (a, d) = self.tiles(l);
                (a * d) as u64
            })
            .sum()
    }
}

/// One compressed tile.
pub struct Tile {
    pub level: usize,
    pub col: usize,
    pub row: usize,
    pub data: Vec<u8>,
}

/// What cutting found of the level-0 cells: for the DEM's info.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellStats {
    pub min: f64,
    pub max: f64,
    pub nodata: u64,
    pub cells: u64,
}

impl Default for CellStats {
    fn default() -> Self {
        CellStats {
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            nodata: 0,
            cells: 0,
        }
    }
}

impl CellStats {
    fn add(&mut self, cells: &[f64]) {
        for &v in cells {
            if v.is_nan() {
                self.nodata += 1;
            } else {
                self.min = self.min.min(v);
                self.max = self.max.max(v);
            }
        }
        self.cells += cells.len() as u64;
    }
}

/// Why cutting stopped.
#[derive(Debug, thiserror::Error)]
pub enum CutError {
    #[error(transparent)]
    Terrain(#[from] TerrainError),
    /// The receiver of the tiles gave up (its own error says why).
    #[error("the tiles were not taken: {0}")]
    Stopped(String),
}

/// The statistics of `src`'s cells, read a band of 512 rows at a time.
pub fn cell_stats(src: &dyn RasterWindows) -> Result<CellStats, TerrainError> {
    let g = src.grid();
    let mut stats = CellStats::default();
    let mut band = Vec::new();
    for row0 in (0..g.height).step_by(TILE_SIDE) {
        let rows = TILE_SIDE.min(g.height - row0);
        band.resize(rows * g.width, 0.0);
        src.read_window(0, row0, g.width, rows, &mut band)?;
        stats.add(&band);
    }
    Ok(stats)
}

/// The info of a raster of grid `g` read a window at a time (as
/// [`Dem::info`] gives it for the raster in memory), its cells'
/// statistics `stats`.
pub fn windows_info(
    g: &RasterGrid,
    format: DemFormat,
    stats: &CellStats,
) -> Result<planner_core::terrain::DemInfo, TerrainError> {
    // Its geometry, from an empty DEM of its size.
    let empty = Dem {
        width: g.width,
        height: g.height,
        values: Vec::new(),
        nodata: g.nodata,
        transform: g.transform,
        crs: g.crs.clone(),
        format,
    };
    let mut info = empty.info()?;
    let has_values = stats.nodata < stats.cells;
    info.min = has_values.then_some(stats.min);
    info.max = has_values.then_some(stats.max);
    info.nodata_fraction = if stats.cells == 0 {
        1.0
    } else {
        stats.nodata as f64 / stats.cells as f64
    };
    Ok(info)
}

/// Memory cutting a raster `width` cells wide takes at most, bytes: the
/// band read, one band per overview level (halving), the tiles in hand.
pub fn cut_bytes(width: u64) -> u64 {
    let band = width.saturating_mul(TILE_SIDE as u64).saturating_mul(8);
    band.saturating_mul(3) + (32 << 20)
}

/// Every value of `src` converts exactly to f32 (so f32 tiles lose
/// nothing), read a band at a time.
pub fn exact_in_f32(src: &dyn RasterWindows) -> Result<bool, TerrainError> {
    let g = src.grid();
    let mut band = Vec::new();
    for row0 in (0..g.height).step_by(TILE_SIDE) {
        let rows = TILE_SIDE.min(g.height - row0);
        band.resize(rows * g.width, 0.0);
        src.read_window(0, row0, g.width, rows, &mut band)?;
        if band
            .iter()
            .any(|&v| !v.is_nan() && f64::from(v as f32) != v)
        {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Cut `src` into the tiles of `set` (level 0, then each overview as its
/// rows are complete), handing each compressed tile to `emit`; the cells'
/// statistics at the end.
pub fn cut_tiles(
    src: &dyn RasterWindows,
    set: &TileSet,
    emit: &mut dyn FnMut(Tile) -> Result<(), String>,
) -> Result<CellStats, CutError> {
    let g = src.grid();
    let mut levels: Vec<LevelRows> = (0..set.levels)
        .map(|l| {
            let (width, height) = set.level_size(l);
            LevelRows {
                level: l,
                width,
                height,
                rows: Vec::new(),
                first_row: 0,
            }
        })
        .collect();
    let mut stats = CellStats::default();
    for row0 in (0..g.height).step_by(set.tile_side) {
        let rows = set.tile_side.min(g.height - row0);
        // A band of its own, handed on without a copy.
        let mut band = vec![0.0; rows * g.width];
        src.read_window(0, row0, g.width, rows, &mut band)?;
        stats.add(&band);
        push_rows(&mut levels, 0, band, set, emit)?;
    }
    Ok(stats)
}

/// The rows of one level not yet cut into tiles.
struct LevelRows {
    level: usize,
    width: usize,
    height: usize,
    /// Row-major, `width` wide, starting at row `first_row`.
    rows: Vec<f64>,
    first_row: usize,
}

/// Add `new` (whole rows) to level `l`: each complete row of tiles is cut
/// and emitted, and its 2×2 means passed to the next level.
fn push_rows(
    levels: &mut [LevelRows],
    l: usize,
    new: Vec<f64>,
    set: &TileSet,
    emit: &mut dyn FnMut(Tile) -> Result<(), String>,
) -> Result<(), CutError> {
    let Some(level) = levels.get_mut(l) else {
        return Ok(());
    };
    if level.rows.is_empty() {
        level.rows = new;
    } else {
        level.rows.extend_from_slice(&new);
    }
    let side = set.tile_side;
    loop {
        let level = &mut levels[l];
        let have = level.rows.len() / level.width.max(1);
        let last = level.first_row + have == level.height;
        if have == 0 || (have < side && !last) {
            return Ok(());
        }
        let take = have.min(side);
        let block: Vec<f64> = if take == have {
            std::mem::take(&mut level.rows)
        } else {
            level.rows.drain(..take * level.width).collect()
        };
        let tile_row = level.first_row / side;
        let width = level.width;
        level.first_row += take;
        for col in 0..width.div_ceil(side) {
            let x0 = col * side;
            let cw = side.min(width - x0);
            let data = encode_tile(&block, width, x0, cw, take, set.sample)
                .map_err(|e| CutError::Stopped(format!("cannot compress a tile: {e}")))?;
            emit(Tile {
                level: level.level,
                col,
                row: tile_row,
                data,
            })
            .map_err(CutError::Stopped)?;
        }
        if l + 1 < levels.len() {
            let half = halve(&block, width, take);
            drop(block);
            push_rows(levels, l + 1, half, set, emit)?;
        }
    }
}

/// The 2×2 means of the non-NaN cells of `rows` (`width` wide, `height`
/// high), NaN where all four are; the last row and column of an odd size
/// average what there is.
fn halve(rows: &[f64], width: usize, height: usize) -> Vec<f64> {
    let (w2, h2) = (width.div_ceil(2), height.div_ceil(2));
    let mut out = Vec::with_capacity(w2 * h2);
    for r in 0..h2 {
        for c in 0..w2 {
            let (mut sum, mut n) = (0.0, 0u32);
            for y in 2 * r..(2 * r + 2).min(height) {
                for x in 2 * c..(2 * c + 2).min(width) {
                    let v = rows[y * width + x];
                    if !v.is_nan() {
                        sum += v;
                        n += 1;
                    }
                }
            }
            out.push(if n == 0 { f64::NAN } else { sum / f64::from(n) });
        }
    }
    out
}

/// Columns `x0..x0+cw` of `rows` (`width` wide, `ch` high) as
/// little-endian samples, zlib-compressed.
fn encode_tile(
    rows: &[f64],
    width: usize,
    x0: usize,
    cw: usize,
    ch: usize,
    sample: TileSample,
) -> std::io::Result<Vec<u8>> {
    let mut raw = Vec::with_capacity(cw * ch * sample.bytes());
    for r in 0..ch {
        let row = &rows[r * width + x0..r * width + x0 + cw];
        match sample {
            TileSample::F32 => {
                for &v in row {
                    raw.extend_from_slice(&(v as f32).to_le_bytes());
                }
            }
            TileSample::F64 => {
                for &v in row {
                    raw.extend_from_slice(&v.to_le_bytes());
                }
            }
        }
    }
    let mut z = flate2::write::ZlibEncoder::new(
        Vec::with_capacity(raw.len() / 2),
        flate2::Compression::fast(),
    );
    z.write_all(&raw)?;
    z.finish()
}

/// A tile's cells (`cw × ch`), from its compressed bytes; an error when
/// they do not inflate to exactly that many samples.
pub fn decode_tile(
    data: &[u8],
    cw: usize,
    ch: usize,
    sample: TileSample,
) -> Result<Vec<f64>, TerrainError> {
    let want = cw * ch * sample.bytes();
    let mut raw = Vec::with_capacity(want);
    flate2::read::ZlibDecoder::new(data)
        .take(want as u64 + 1)
        .read_to_end(&mut raw)
        .map_err(|e| TerrainError::Invalid(format!("a stored DEM tile is corrupt: {e}")))?;
    if raw.len() != want {
        return Err(TerrainError::Invalid(format!(
            "a stored DEM tile holds {} bytes, {want} expected",
            raw.len()
        )));
    }
    Ok(match sample {
        TileSample::F32 => raw
            .chunks_exact(4)
            .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            .collect(),
        TileSample::F64 => raw
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
            .collect(),
    })
}

/// The georeferencing of level `level` of `set` over a DEM of `grid`:
/// the same corner, cells as much larger as the level is smaller.
pub fn level_grid(grid: &RasterGrid, set: &TileSet, level: usize) -> RasterGrid {
    let (w, h) = set.level_size(level);
    let sx = grid.width as f64 / w as f64;
    let sy = grid.height as f64 / h as f64;
    let t = grid.transform;
    RasterGrid {
        width: w,
        height: h,
        transform: GeoTransform {
            origin_x: t.origin_x,
            pixel_width: t.pixel_width * sx,
            row_rotation: t.row_rotation * sy,
            origin_y: t.origin_y,
            col_rotation: t.col_rotation * sx,
            pixel_height: t.pixel_height * sy,
        },
        crs: grid.crs.clone(),
        nodata: grid.nodata,
    }
}

/// A DEM in memory, shared, read through [`RasterWindows`] (to cut an
/// ESRI grid or `.hgt` file, read whole, into tiles).
pub struct SharedDem {
    dem: Arc<Dem>,
    grid: RasterGrid,
}

impl SharedDem {
    pub fn new(dem: Arc<Dem>) -> SharedDem {
        let grid = planner_core::terrain::DemWindows::new(&dem).grid().clone();
        SharedDem { dem, grid }
    }
}

impl RasterWindows for SharedDem {
    fn grid(&self) -> &RasterGrid {
        &self.grid
    }

    fn read_window(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut [f64],
    ) -> Result<(), TerrainError> {
        planner_core::terrain::DemWindows::new(&self.dem)
            .read_window(col0, row0, width, height, out)
    }
}

/// What storing a DEM's tiles made: the tile set (as stored) and the
/// level-0 cells' statistics.
pub struct StoredSet {
    pub row: DemTileSetRow,
    pub stats: CellStats,
}

/// Cut `src` into tiles (f32 when `f32_exact` says every value fits,
/// `None`: checked by a first pass) on a DEM planner slot and store them
/// under upload `upload` as they come, a few per transaction, each batch
/// checked against the project's storage quota first. On a fault the
/// caller abandons the upload (its tiles go with it).
pub async fn store_tiles<S: RasterWindows + Send + 'static>(
    db: &Db,
    planner: &Planners,
    upload: &UploadLease,
    src: S,
    f32_exact: Option<bool>,
) -> Result<StoredSet, ApiError> {
    let (send, mut take) = tokio::sync::mpsc::channel::<Tile>(TILES_PER_INSERT);
    let cutting = planner.run(Work::Dem, move |_| {
        let exact = match f32_exact {
            Some(e) => e,
            None => exact_in_f32(&src)?,
        };
        let g = src.grid();
        let sample = if exact {
            TileSample::F32
        } else {
            TileSample::F64
        };
        let set = TileSet::new(g.width, g.height, sample);
        let transform = g.transform;
        let stats = cut_tiles(&src, &set, &mut |t| {
            send.blocking_send(t)
                .map_err(|_| "the database stopped taking them".to_string())
        })?;
        Ok::<_, CutError>((set, stats, transform))
    });
    // Moves `take` in: a fault drops it, and the cutting stops at its
    // next tile (instead of waiting for room in the channel).
    let storing = async move {
        let mut batch = Vec::with_capacity(TILES_PER_INSERT);
        let mut bytes = 0u64;
        loop {
            let tile = take.recv().await;
            let done = tile.is_none();
            if let Some(t) = tile {
                batch.push(DemTileRow {
                    level: t.level as i64,
                    row: t.row as i64,
                    col: t.col as i64,
                    data: t.data,
                });
            }
            if batch.len() >= TILES_PER_INSERT || (done && !batch.is_empty()) {
                let adding: u64 = batch.iter().map(|t| t.data.len() as u64).sum();
                upload.check_held()?;
                upload.check_quota(bytes, adding).await?;
                let held = db
                    .insert_dem_tiles(
                        upload.dem_id(),
                        upload.owner(),
                        &batch,
                        upload.lease_until(),
                    )
                    .await?;
                if !held {
                    return Err(swept_error());
                }
                bytes += adding;
                batch.clear();
            }
            if done {
                return Ok::<_, ApiError>(bytes);
            }
        }
    };
    let (cut, stored) = tokio::join!(cutting, storing);
    // The storing's fault first: it is why the cutting stopped.
    let bytes = stored?;
    let (set, stats, transform) = cut?.map_err(|e| match e {
        CutError::Terrain(t) => ApiError::from(t),
        CutError::Stopped(m) => ApiError::Internal(format!("cannot store the DEM's tiles: {m}")),
    })?;
    let row = DemTileSetRow {
        tile_size: set.tile_side as i64,
        sample: set.sample.name().to_string(),
        levels: set.levels as i64,
        transform: serde_json::to_string(&transform)
            .map_err(|e| ApiError::Internal(e.to_string()))?,
        size_bytes: i64::try_from(bytes).unwrap_or(i64::MAX),
    };
    Ok(StoredSet { row, stats })
}

/// A stored DEM's tile set and level-0 grid, from its rows; `None` for a
/// DEM stored before tiles.
pub async fn stored_set(
    db: &Db,
    id: &str,
    info: &planner_core::terrain::DemInfo,
) -> Result<Option<(TileSet, RasterGrid)>, ApiError> {
    let Some(row) = db.dem_tile_set(id).await? else {
        return Ok(None);
    };
    let bad =
        |what: &str| ApiError::Internal(format!("the tile set of DEM {id} is unreadable: {what}"));
    let sample = TileSample::from_name(&row.sample).ok_or_else(|| bad(&row.sample))?;
    let transform: GeoTransform =
        serde_json::from_str(&row.transform).map_err(|e| bad(&e.to_string()))?;
    let mut set = TileSet::new(info.width, info.height, sample);
    if set.levels as i64 != row.levels || row.tile_size != TILE_SIDE as i64 {
        return Err(bad("its levels or tile size differ from the DEM's size"));
    }
    set.sample = sample;
    let grid = RasterGrid {
        width: info.width,
        height: info.height,
        transform,
        crs: info.crs.clone(),
        nodata: info.nodata_value,
    };
    Ok(Some((set, grid)))
}

/// One level of a stored DEM's tiles, read a window at a time: tiles are
/// fetched from the database as windows need them (blocking the calling
/// thread, which must not be an async worker) and kept decoded in an LRU.
pub struct StoredTiles {
    db: Db,
    runtime: tokio::runtime::Handle,
    dem_id: String,
    set: TileSet,
    level: usize,
    grid: RasterGrid,
    cache: Mutex<CellCache<(usize, usize)>>,
}

impl StoredTiles {
    /// Level `level` of DEM `dem_id`'s tiles, whose level 0 is `grid`.
    pub fn new(
        db: Db,
        runtime: tokio::runtime::Handle,
        dem_id: &str,
        set: TileSet,
        level: usize,
        grid: &RasterGrid,
    ) -> StoredTiles {
        StoredTiles {
            db,
            runtime,
            dem_id: dem_id.to_string(),
            set,
            level,
            grid: level_grid(grid, &set, level),
            cache: Mutex::new(CellCache::new(TILE_CACHE_BYTES)),
        }
    }

    fn tile(&self, col: usize, row: usize) -> Result<Arc<Vec<f64>>, TerrainError> {
        let key = (col, row);
        if let Some(t) = self.cache.lock().ok().and_then(|mut c| c.get(key)) {
            return Ok(t);
        }
        let cells = Arc::new(self.fetch(col, row)?);
        if let Ok(mut c) = self.cache.lock() {
            c.put(key, Arc::clone(&cells));
        }
        Ok(cells)
    }

    /// Tile (`col`, `row`) read from the database and decoded.
    fn fetch(&self, col: usize, row: usize) -> Result<Vec<f64>, TerrainError> {
        let data = self
            .runtime
            .block_on(
                self.db
                    .dem_tile(&self.dem_id, self.level as i64, row as i64, col as i64),
            )
            .map_err(|e| {
                TerrainError::Invalid(format!(
                    "tile ({col}, {row}) of level {} of DEM {} cannot be read: {e}",
                    self.level, self.dem_id
                ))
            })?
            .ok_or_else(|| {
                TerrainError::Invalid(format!(
                    "tile ({col}, {row}) of level {} of DEM {} is missing",
                    self.level, self.dem_id
                ))
            })?;
        let (cw, ch) = self.set.tile_size(self.level, col, row);
        decode_tile(&data, cw, ch, self.set.sample)
    }

    /// The whole level as a [`Dem`] (`format` is the DEM's), read tile by
    /// tile into one grid of heights (past the cache: each tile is read
    /// once).
    pub fn read_whole(&self, format: DemFormat) -> Result<Dem, TerrainError> {
        let g = &self.grid;
        let mut values = vec![0.0; g.width * g.height];
        let s = self.set.tile_side;
        let (across, down) = self.set.tiles(self.level);
        for row in 0..down {
            for col in 0..across {
                let cells = self.fetch(col, row)?;
                let (cw, ch) = self.set.tile_size(self.level, col, row);
                for y in 0..ch {
                    let dst = (row * s + y) * g.width + col * s;
                    values[dst..dst + cw].copy_from_slice(&cells[y * cw..(y + 1) * cw]);
                }
            }
        }
        Ok(Dem {
            width: g.width,
            height: g.height,
            values,
            nodata: g.nodata,
            transform: g.transform,
            crs: g.crs.clone(),
            format,
        })
    }
}

impl RasterWindows for StoredTiles {
    fn grid(&self) -> &RasterGrid {
        &self.grid
    }

    fn read_window(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut [f64],
    ) -> Result<(), TerrainError> {
        check_window(&self.grid, col0, row0, width, height, out.len())?;
        if width == 0 || height == 0 {
            return Ok(());
        }
        let s = self.set.tile_side;
        for ty in row0 / s..=(row0 + height - 1) / s {
            for tx in col0 / s..=(col0 + width - 1) / s {
                let cells = self.tile(tx, ty)?;
                let (x0, y0) = (tx * s, ty * s);
                let (cw, _) = self.set.tile_size(self.level, tx, ty);
                let (xa, xb) = (col0.max(x0), (col0 + width).min(x0 + cw));
                let (ya, yb) = (row0.max(y0), (row0 + height).min(y0 + s));
                for y in ya..yb {
                    let src = (y - y0) * cw + (xa - x0);
                    let dst = (y - row0) * width + (xa - col0);
                    let (Some(from), Some(to)) = (
                        cells.get(src..src + (xb - xa)),
                        out.get_mut(dst..dst + (xb - xa)),
                    ) else {
                        return Err(TerrainError::Invalid(
                            "a stored DEM tile is smaller than its place".into(),
                        ));
                    };
                    to.copy_from_slice(from);
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use planner_core::terrain::{Crs, DemWindows};

    use super::*;

    fn dem(w: usize, h: usize, f: impl Fn(usize, usize) -> f64) -> Dem {
        let mut values = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                values.push(f(x, y));
            }
        }
        Dem {
            width: w,
            height: h,
            values,
            nodata: Some(-9999.0),
            transform: GeoTransform {
                origin_x: 500_000.0,
                pixel_width: 2.0,
                row_rotation: 0.0,
                origin_y: 4_000_000.0,
                col_rotation: 0.0,
                pixel_height: -2.0,
            },
            crs: Crs {
                epsg: 32633,
                name: "WGS 84 / UTM zone 33N".into(),
                geographic: false,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    /// Cut `d` into tiles kept in a map by (level, col, row).
    /// Compressed tiles by (level, col, row).
    type Tiles = HashMap<(usize, usize, usize), Vec<u8>>;

    fn cut(d: &Dem, sample: TileSample) -> (TileSet, Tiles) {
        let set = TileSet::new(d.width, d.height, sample);
        let mut tiles = HashMap::new();
        let stats = cut_tiles(&DemWindows::new(d), &set, &mut |t: Tile| {
            assert!(
                tiles.insert((t.level, t.col, t.row), t.data).is_none(),
                "a tile emitted twice"
            );
            Ok(())
        })
        .unwrap();
        let nan = d.values.iter().filter(|v| v.is_nan()).count() as u64;
        assert_eq!(stats.nodata, nan);
        assert_eq!(stats.cells, d.values.len() as u64);
        (set, tiles)
    }

    fn level(set: &TileSet, tiles: &HashMap<(usize, usize, usize), Vec<u8>>, l: usize) -> Vec<f64> {
        let (w, h) = set.level_size(l);
        let mut out = vec![0.0; w * h];
        let (across, down) = set.tiles(l);
        for row in 0..down {
            for col in 0..across {
                let (cw, ch) = set.tile_size(l, col, row);
                let cells = decode_tile(&tiles[&(l, col, row)], cw, ch, set.sample).unwrap();
                for y in 0..ch {
                    for x in 0..cw {
                        out[(row * 512 + y) * w + col * 512 + x] = cells[y * cw + x];
                    }
                }
            }
        }
        out
    }

    #[test]
    fn tiles_hold_the_cells_and_overviews_the_means() {
        // 1300 × 1100: three levels (1300, 650, 325 wide), edge tiles cut.
        let d = dem(1300, 1100, |x, y| {
            if (x * 7 + y * 3) % 101 == 0 {
                f64::NAN
            } else {
                (x as f64) * 0.5 - (y as f64) * 0.25 + 1000.0
            }
        });
        let (set, tiles) = cut(&d, TileSample::F64);
        assert_eq!(set.levels, 3);
        assert_eq!(tiles.len() as u64, set.tile_count());
        assert_eq!(tiles.len(), 3 * 3 + 2 * 2 + 1);
        let l0 = level(&set, &tiles, 0);
        assert_same(&l0, &d.values);
        let l1 = level(&set, &tiles, 1);
        assert_same(&l1, &halve(&d.values, 1300, 1100));
        let l2 = level(&set, &tiles, 2);
        assert_eq!(set.level_size(2), (325, 275));
        assert_same(&l2, &halve(&l1, 650, 550));
    }

    fn assert_same(a: &[f64], b: &[f64]) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()));
        }
    }

    #[test]
    fn halving_averages_what_is_not_nodata_and_odd_edges() {
        let v = [1.0, 3.0, 5.0, f64::NAN, 7.0, 9.0];
        // 3 wide, 2 high → 2 × 1.
        let h = halve(&v, 3, 2);
        assert_eq!(h[0], (1.0 + 3.0 + 7.0) / 3.0);
        assert_eq!(h[1], (5.0 + 9.0) / 2.0);
        assert!(halve(&[f64::NAN; 4], 2, 2)[0].is_nan());
    }

    #[test]
    fn f32_tiles_round_trip_and_exactness_is_checked() {
        let d = dem(600, 40, |x, y| (x + y) as f64 * 0.5);
        assert!(exact_in_f32(&DemWindows::new(&d)).unwrap());
        let (set, tiles) = cut(&d, TileSample::F32);
        assert_eq!(level(&set, &tiles, 0), d.values);
        let inexact = dem(10, 10, |x, _| 0.1 * x as f64);
        assert!(!exact_in_f32(&DemWindows::new(&inexact)).unwrap());
    }

    #[test]
    fn corrupt_tiles_are_errors() {
        let d = dem(20, 10, |x, _| x as f64);
        let (_, tiles) = cut(&d, TileSample::F32);
        let t = &tiles[&(0, 0, 0)];
        assert!(decode_tile(t, 20, 10, TileSample::F32).is_ok());
        assert!(decode_tile(t, 20, 9, TileSample::F32).is_err());
        assert!(decode_tile(t, 20, 11, TileSample::F32).is_err());
        assert!(decode_tile(&t[..t.len() / 2], 20, 10, TileSample::F32).is_err());
        assert!(decode_tile(b"garbage", 20, 10, TileSample::F32).is_err());
    }

    #[test]
    fn level_grids_keep_the_corner_and_scale_the_cells() {
        let d = dem(1300, 1100, |_, _| 0.0);
        let set = TileSet::new(1300, 1100, TileSample::F32);
        let g = DemWindows::new(&d).grid().clone();
        let l1 = level_grid(&g, &set, 1);
        assert_eq!((l1.width, l1.height), (650, 550));
        assert_eq!(l1.transform.pixel_width, 4.0);
        assert_eq!(l1.transform.origin_x, 500_000.0);
        assert_eq!(TileSet::new(512, 512, TileSample::F32).levels, 1);
        assert_eq!(TileSet::new(513, 10, TileSample::F32).levels, 2);
    }

    /// xorshift64*: the same cases every run.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
        }

        fn below(&mut self, n: usize) -> usize {
            (self.next() % n.max(1) as u64) as usize
        }

        fn bytes(&mut self, n: usize) -> Vec<u8> {
            (0..n).map(|_| self.next() as u8).collect()
        }
    }

    /// This process' peak resident memory, bytes, after resetting it (the
    /// tests run one per process under nextest).
    fn reset_peak() {
        let _ = std::fs::write("/proc/self/clear_refs", "5");
    }

    fn peak() -> u64 {
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        status
            .lines()
            .find_map(|l| l.strip_prefix("VmHWM:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .unwrap_or(0)
            * 1024
    }

    /// Property test of the stored tiles' decoding: random bytes, zlib
    /// streams of the wrong length and a zlib bomb (16 MiB of zeros in a
    /// few KiB) are errors, never a panic, and the memory taken stays that
    /// of one tile whatever the bytes claim.
    #[test]
    fn decoding_random_and_hostile_tiles_is_an_error_within_bounded_memory() {
        let mut rng = Rng(0x5EED_0001);
        let mut bomb = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        bomb.write_all(&vec![0u8; 16 << 20]).unwrap();
        let bomb = bomb.finish().unwrap();
        reset_peak();
        let before = peak();
        let mut decoded = 0;
        for case in 0..600 {
            let (cw, ch) = (1 + rng.below(512), 1 + rng.below(512));
            let sample = if rng.below(2) == 0 {
                TileSample::F32
            } else {
                TileSample::F64
            };
            let want = cw * ch * sample.bytes();
            let data = match case % 4 {
                0 => {
                    let n = rng.below(4096);
                    rng.bytes(n)
                }
                1 => {
                    // A valid stream of a random length, sometimes right.
                    let n = if rng.below(4) == 0 {
                        want
                    } else {
                        rng.below(2 * want + 2)
                    };
                    let raw = rng.bytes(n);
                    let mut z =
                        flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                    z.write_all(&raw).unwrap();
                    z.finish().unwrap()
                }
                2 => {
                    // A valid tile with bytes flipped or cut.
                    let d = dem(cw, ch, |x, y| (x * 3 + y) as f64);
                    let mut t = encode_tile(&d.values, cw, 0, cw, ch, sample).unwrap();
                    if rng.below(2) == 0 {
                        let cut = rng.below(t.len());
                        t.truncate(cut);
                    } else {
                        for _ in 0..1 + rng.below(8) {
                            let i = rng.below(t.len());
                            t[i] ^= 1 << rng.below(8);
                        }
                    }
                    t
                }
                _ => bomb.clone(),
            };
            match decode_tile(&data, cw, ch, sample) {
                Ok(cells) => {
                    assert_eq!(cells.len(), cw * ch, "case {case}");
                    decoded += 1;
                }
                Err(e) => assert!(
                    e.to_string().contains("stored DEM tile"),
                    "case {case}: {e}"
                ),
            }
        }
        // Streams of exactly a tile's bytes decode (a quarter of case 1).
        assert!(decoded > 10, "{decoded}");
        // One tile of 512² f64 is 2 MiB: a bomb never inflates past it.
        let grown = peak().saturating_sub(before);
        assert!(grown < 64 << 20, "decoding grew the peak by {grown} bytes");
    }

    /// Property test of the windows over stored tiles: with some tiles
    /// garbage, cut short or missing, random windows (some outside the
    /// raster) read the cells cut from the source exactly when every tile
    /// they touch is intact, and are errors otherwise; never a panic.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn windows_over_corrupt_stored_tiles_are_errors_or_the_cells() {
        let dir = std::env::temp_dir().join(format!("terraplan-tilefuzz-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = Db::connect(None, &dir).await.unwrap();
        let mut rng = Rng(0x5EED_0002);
        let d = dem(1300, 1100, |x, y| ((x * 7 + y * 13) % 1000) as f64 * 0.5);
        let (set, tiles) = cut(&d, TileSample::F32);
        db.begin_dem_upload("d", None, "me", 0, i64::MAX)
            .await
            .unwrap();
        let mut broken = std::collections::HashSet::new();
        let mut rows = Vec::new();
        for (&(level, col, row), data) in &tiles {
            let data = match rng.below(6) {
                0 => {
                    let n = rng.below(3000);
                    rng.bytes(n)
                }
                1 => data[..rng.below(data.len())].to_vec(),
                2 if level == 0 => {
                    broken.insert((level, col, row));
                    continue; // missing
                }
                _ => data.clone(),
            };
            if &data != data_of(&tiles, level, col, row) {
                broken.insert((level, col, row));
            }
            rows.push(DemTileRow {
                level: level as i64,
                row: row as i64,
                col: col as i64,
                data,
            });
        }
        assert!(
            db.insert_dem_tiles("d", "me", &rows, i64::MAX)
                .await
                .unwrap()
        );
        let grid = DemWindows::new(&d).grid().clone();
        let runtime = tokio::runtime::Handle::current();
        let reader = db.clone();
        let outcome = tokio::task::spawn_blocking(move || {
            let windows = StoredTiles::new(reader, runtime, "d", set, 0, &grid);
            let (mut good, mut bad) = (0, 0);
            for case in 0..300 {
                let (c0, r0) = (rng.below(1400), rng.below(1200));
                let (w, h) = (1 + rng.below(700), 1 + rng.below(700));
                let mut out = vec![0.0; w * h];
                let got = windows.read_window(c0, r0, w, h, &mut out);
                let inside = c0 + w <= 1300 && r0 + h <= 1100;
                let intact = inside
                    && (r0 / 512..=(r0 + h - 1) / 512).all(|ty| {
                        (c0 / 512..=(c0 + w - 1) / 512).all(|tx| !broken.contains(&(0, tx, ty)))
                    });
                match got {
                    Ok(()) => {
                        assert!(intact, "case {case}: a window over broken tiles read");
                        for y in 0..h {
                            for x in 0..w {
                                let want = d.values[(r0 + y) * 1300 + c0 + x];
                                assert_eq!(out[y * w + x], want, "case {case} ({x}, {y})");
                            }
                        }
                        good += 1;
                    }
                    Err(e) => {
                        assert!(!intact, "case {case}: intact window refused: {e}");
                        bad += 1;
                    }
                }
            }
            (good, bad)
        })
        .await
        .unwrap();
        assert!(outcome.0 > 5 && outcome.1 > 5, "{outcome:?}");
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    fn data_of(tiles: &Tiles, level: usize, col: usize, row: usize) -> &Vec<u8> {
        &tiles[&(level, col, row)]
    }
}
