//! The tiled costmap ([`super::tiled`]) as stages whose jobs can run on
//! different processes, in any tile order: a costmap of N tiles
//! (row-major tile index k over its [`TileLayout`]) runs
//!
//! 1. [`TilePlan::classify`] (N jobs): tile k's surface on its padded
//!    window → its core classes before the pocket fill ([`HOLE_BIT`] on
//!    cells without a height) and its edge facts ([`TileEdges`]);
//! 2. [`TilePlan::join`] (1 job): every tile's edges → which regions are
//!    filled ([`RegionFill`], a [`TileFill`] per tile);
//! 3. [`TilePlan::fill`] (N jobs): tile k's pre-fill core and the ring of
//!    cells around it from its neighbours' pre-fill classes → its labels
//!    (exactly those of stage 1, so the join's decisions apply) → its
//!    final core classes;
//! 4. [`TilePlan::cost`] (N jobs): tile k's surface again and the final
//!    classes over its inflation halo → its costs, classes, layers, its
//!    [`TallyPart`] and its [`PreviewPart`];
//! 5. [`TilePlan::finish`] (1 job): the tallies and previews merged in
//!    tile order → statistics, warnings, preview ([`TiledCostmap`]).
//!
//! A stage starts when the previous one is complete. Every process
//! rebuilds the same [`TilePlan`] from the same request; the pieces
//! exchanged between stages have a byte form (`to_bytes`/`from_bytes`,
//! refusing damaged bytes with an error) or are plain class bytes.
//! A tile's work is bounded by the tile and its halos, never the grid.

use std::sync::atomic::{AtomicBool, Ordering};

use super::bands::Surface;
use super::class_store::HOLE_BIT;
use super::grid::{average_blocks, work_geometry};
use super::halo::{Halos, Padded, TileLayout, TileWindow, crop, halos};
use super::inflate::inflation;
use super::landcover::landcover_costs_window;
use super::params::resolve;
use super::pipeline::{
    CellLayers, Heights, add_layer_obstacles, check_request, cost_range, costs, layer_rasters,
    negative_steps_of, resample_warnings, surface_of,
};
use super::preview_tiles::{PreviewGrid, PreviewPart, PreviewTiles};
use super::region_join::{RegionFill, RegionJoin, TileEdges, TileFill, label_tile};
use super::stats::{StatsTally, TallyPart};
use super::tiled::{CostmapTile, MapHeader, TiledCostmap, TiledError};
use super::{Class, CostmapError, CostmapOptions, Layer, Progress, ResolvedParams, Stage, Vehicle};
use crate::terrain::{Crs, Dem, DemFormat, GeoTransform, RasterGrid, RasterWindows};

/// The preview's longer side when [`TilePlan::with_preview_max_side`]
/// is not called (the service's).
pub const DEFAULT_PREVIEW_MAX_SIDE: usize = 1024;

/// Windows of a class raster (before the fill or final) over the whole
/// working grid, any size: [`super::class_store::ClassStore`] on disk,
/// [`ClassTiles`] over stored tiles, or the server's own.
pub trait ClassWindows: Sync {
    /// Fills `out` (resized to `width × height`, row-major) with the
    /// classes of the window whose top-left cell is (`col0`, `row0`).
    fn read_classes(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut Vec<u8>,
    ) -> Result<(), TiledError>;
}

/// Class windows cut from the tiles of a layout, each fetched whole by
/// `fetch(k)` (a tile's core classes, row-major, as [`TilePlan::classify`]
/// or [`TilePlan::fill`] made them).
pub struct ClassTiles<F> {
    layout: TileLayout,
    fetch: F,
}

impl<F, T> ClassTiles<F>
where
    F: Fn(usize) -> Result<T, TiledError> + Sync,
    T: AsRef<[u8]>,
{
    pub fn new(layout: TileLayout, fetch: F) -> ClassTiles<F> {
        ClassTiles { layout, fetch }
    }
}

impl<F, T> ClassWindows for ClassTiles<F>
where
    F: Fn(usize) -> Result<T, TiledError> + Sync,
    T: AsRef<[u8]>,
{
    fn read_classes(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut Vec<u8>,
    ) -> Result<(), TiledError> {
        let l = &self.layout;
        let inside = col0.checked_add(width).is_some_and(|c| c <= l.width)
            && row0.checked_add(height).is_some_and(|r| r <= l.height);
        if !inside {
            return Err(TiledError::Mismatch(format!(
                "class window {width}×{height} at ({col0}, {row0}) is not inside the {}×{} grid",
                l.width, l.height
            )));
        }
        out.clear();
        out.resize(width * height, 0);
        if width == 0 || height == 0 {
            return Ok(());
        }
        for k in tiles_under(l, col0, row0, width, height) {
            let t = l.tile(k);
            let data = (self.fetch)(k)?;
            let data = data.as_ref();
            if data.len() != t.width * t.height {
                return Err(TiledError::Mismatch(format!(
                    "tile {k}'s classes are {} bytes, the tile has {} cells",
                    data.len(),
                    t.width * t.height
                )));
            }
            // The overlap of the tile and the window.
            let (c0, c1) = (t.col0.max(col0), (t.col0 + t.width).min(col0 + width));
            let (r0, r1) = (t.row0.max(row0), (t.row0 + t.height).min(row0 + height));
            for r in r0..r1 {
                let from = (r - t.row0) * t.width + (c0 - t.col0);
                let to = (r - row0) * width + (c0 - col0);
                out[to..to + c1 - c0].copy_from_slice(&data[from..from + c1 - c0]);
            }
        }
        Ok(())
    }
}

/// The tiles of `l` that the window (inside the grid) overlaps, ascending.
fn tiles_under(
    l: &TileLayout,
    col0: usize,
    row0: usize,
    width: usize,
    height: usize,
) -> Vec<usize> {
    if width == 0 || height == 0 {
        return Vec::new();
    }
    let nx = l.tiles()[0];
    let mut out = Vec::new();
    for ty in row0 / l.tile..=(row0 + height - 1) / l.tile {
        for tx in col0 / l.tile..=(col0 + width - 1) / l.tile {
            out.push(ty * nx + tx);
        }
    }
    out
}

/// What [`TilePlan::classify`] makes of a tile.
#[derive(Clone, Debug)]
pub struct Classified {
    /// The core's classes before the pocket fill, row-major, with
    /// [`HOLE_BIT`] on cells without a height.
    pub core: Vec<u8>,
    /// The core's edge facts, for the join.
    pub edges: TileEdges,
}

/// What [`TilePlan::cost`] makes of a tile: its part of the costmap.
#[derive(Clone, Debug)]
pub struct CostTile {
    /// The tile's place on the grid.
    pub window: TileWindow,
    /// Row-major costs, `NaN` on obstacles and unknown cells.
    pub cost: Vec<f32>,
    /// Row-major [`Class`] codes (no [`HOLE_BIT`]).
    pub class: Vec<u8>,
    /// The layers asked for, in [`Layer::ALL`] order.
    pub layers: Vec<(Layer, Vec<f32>)>,
    pub tally: TallyPart,
    pub preview: PreviewPart,
}

impl CostTile {
    /// The tile as a [`super::TileSink`] takes it.
    pub fn view(&self) -> CostmapTile<'_> {
        let t = &self.window;
        CostmapTile {
            tx: t.tx,
            ty: t.ty,
            col0: t.col0,
            row0: t.row0,
            width: t.width,
            height: t.height,
            cost: &self.cost,
            class: &self.class,
            layers: &self.layers,
        }
    }
}

/// Everything every stage of a tiled costmap needs: the checked request,
/// its resolved parameters, the working grid's geometry, the halos and
/// the tiles. The same on every process given the same inputs.
#[derive(Clone, Debug)]
pub struct TilePlan {
    vehicle: Vehicle,
    options: CostmapOptions,
    params: ResolvedParams,
    /// The DEM's size, which each stage's source must have.
    dem_size: [usize; 2],
    transform: GeoTransform,
    crs: Crs,
    row_size_m: Vec<[f64; 2]>,
    centre_m: [f64; 2],
    halos: Halos,
    layout: TileLayout,
    /// The warnings known before any tile (coarse DEM, resampling).
    warnings: Vec<String>,
    range: [f64; 2],
    min_cells: f64,
    preview: PreviewGrid,
}

/// The grid's size and georeferencing as a [`Dem`] without heights: what
/// the checks and the parameters read.
fn shell_dem(g: &RasterGrid) -> Dem {
    Dem {
        width: g.width,
        height: g.height,
        values: Vec::new(),
        nodata: g.nodata,
        transform: g.transform,
        crs: g.crs.clone(),
        format: DemFormat::GeoTiff,
    }
}

/// A progress that only passes on cancellation: the stages run per tile
/// report nothing, the caller reports its tiles.
struct Silent<'a>(&'a AtomicBool);

impl Progress for Silent<'_> {
    fn report(&self, _: Stage, _: f64) -> bool {
        !self.0.load(Ordering::Relaxed)
    }
}

fn cancelled(cancel: &AtomicBool) -> Result<(), TiledError> {
    if cancel.load(Ordering::Relaxed) {
        Err(CostmapError::Cancelled.into())
    } else {
        Ok(())
    }
}

/// A window's surface: classes before the fill (with the optional
/// obstacle layers), and the per-cell grids the costs are made of.
struct WindowSurface {
    class: Vec<u8>,
    layers: CellLayers,
    holes: Vec<bool>,
}

impl TilePlan {
    /// Checks the request (as the whole-raster run does), resolves its
    /// parameters and cuts the working grid of the DEM `grid` into tiles
    /// of `tile` × `tile` cells. Deterministic: every process rebuilding
    /// the plan from the same inputs gets the same plan.
    pub fn new(
        grid: &RasterGrid,
        vehicle: &Vehicle,
        options: &CostmapOptions,
        landcover: Option<&Dem>,
        tile: usize,
    ) -> Result<TilePlan, CostmapError> {
        let shell = shell_dem(grid);
        check_request(&shell, vehicle, options, landcover)?;
        let params = resolve(&shell, vehicle, options);
        let geometry = work_geometry(&shell, params.resample_factor);
        let (w, h) = (geometry.width, geometry.height);
        let centre_m = geometry.row_size_m[h / 2];
        let mut warnings = Vec::new();
        resample_warnings(vehicle, options, &params, centre_m, &mut warnings);
        let halos = halos(&params, options, vehicle, &geometry.row_size_m, centre_m);
        let min_cells = params.min_region_area_m2 / (centre_m[0] * centre_m[1]);
        Ok(TilePlan {
            vehicle: vehicle.clone(),
            options: options.clone(),
            dem_size: [grid.width, grid.height],
            transform: geometry.transform,
            crs: grid.crs.clone(),
            row_size_m: geometry.row_size_m,
            centre_m,
            halos,
            layout: TileLayout::new(w, h, tile),
            warnings,
            range: cost_range(vehicle, options),
            min_cells,
            preview: PreviewGrid::new(w, h, DEFAULT_PREVIEW_MAX_SIDE),
            params,
        })
    }

    /// The preview at most `max_side` pixels on its longer side (default
    /// [`DEFAULT_PREVIEW_MAX_SIDE`]); every process must use the same.
    pub fn with_preview_max_side(mut self, max_side: usize) -> TilePlan {
        self.preview = PreviewGrid::new(self.layout.width, self.layout.height, max_side);
        self
    }

    pub fn tile_count(&self) -> usize {
        self.layout.count()
    }

    pub fn layout(&self) -> TileLayout {
        self.layout
    }

    pub fn halos(&self) -> Halos {
        self.halos
    }

    pub fn params(&self) -> &ResolvedParams {
        &self.params
    }

    /// The layers every tile holds, in [`Layer::ALL`] order.
    pub fn layers(&self) -> Vec<Layer> {
        Layer::ALL
            .into_iter()
            .filter(|l| self.options.layers.contains(l))
            .collect()
    }

    /// The map's size, georeferencing, tile side and layers (what a
    /// [`super::TileSink`] is told first).
    pub fn header(&self) -> MapHeader {
        MapHeader {
            width: self.layout.width,
            height: self.layout.height,
            transform: self.transform,
            crs: self.crs.clone(),
            tile: self.layout.tile,
            layers: self.layers(),
        }
    }

    /// Tile `k`'s place on the working grid; an error unless `k` is below
    /// [`TilePlan::tile_count`].
    pub fn tile(&self, k: usize) -> Result<TileWindow, TiledError> {
        let count = self.tile_count();
        if k >= count {
            return Err(TiledError::NoSuchTile { k, count });
        }
        Ok(self.layout.tile(k))
    }

    /// The tiles whose classes before the fill [`TilePlan::fill`] reads
    /// for tile `k` (it and its neighbours), ascending: what to fetch
    /// before it runs.
    pub fn fill_reads(&self, k: usize) -> Result<Vec<usize>, TiledError> {
        let t = self.tile(k)?;
        let p = t.padded([1, 1], self.layout.width, self.layout.height);
        Ok(tiles_under(&self.layout, p.col0, p.row0, p.width, p.height))
    }

    /// The tiles whose final classes [`TilePlan::cost`] reads for tile
    /// `k` (those within its inflation halo), ascending.
    pub fn cost_reads(&self, k: usize) -> Result<Vec<usize>, TiledError> {
        let t = self.tile(k)?;
        let p = t.padded(self.halos.inflation, self.layout.width, self.layout.height);
        Ok(tiles_under(&self.layout, p.col0, p.row0, p.width, p.height))
    }

    fn check_source(&self, src: &dyn RasterWindows) -> Result<(), TiledError> {
        let g = src.grid();
        if [g.width, g.height] != self.dem_size {
            return Err(TiledError::Mismatch(format!(
                "the DEM is {}×{}, the plan's {}×{}",
                g.width, g.height, self.dem_size[0], self.dem_size[1]
            )));
        }
        Ok(())
    }

    /// The working heights of window `p`.
    fn heights(&self, src: &dyn RasterWindows, p: &Padded) -> Result<Vec<f64>, TiledError> {
        let [fx, fy] = self.params.resample_factor;
        let mut dem = vec![0.0; p.width * fx * p.height * fy];
        src.read_window(
            p.col0 * fx,
            p.row0 * fy,
            p.width * fx,
            p.height * fy,
            &mut dem,
        )?;
        if [fx, fy] == [1, 1] {
            return Ok(dem);
        }
        Ok(average_blocks(
            &dem,
            p.width * fx,
            p.width,
            p.height,
            [fx, fy],
        ))
    }

    fn surface(
        &self,
        src: &dyn RasterWindows,
        landcover: Option<&Dem>,
        p: &Padded,
        cancel: &AtomicBool,
    ) -> Result<WindowSurface, TiledError> {
        let z = self.heights(src, p)?;
        let heights = Heights {
            z: &z,
            width: p.width,
            height: p.height,
            row_size_m: &self.row_size_m[p.row0..p.row0 + p.height],
            centre_m: self.centre_m,
        };
        let silent = Silent(cancel);
        let (vehicle, options) = (&self.vehicle, &self.options);
        let Surface {
            zcomp,
            roughness,
            step,
            mut class,
            holes,
        } = surface_of(&heights, vehicle, options, &self.params, &silent)?;
        let negative = negative_steps_of(&heights, vehicle, options, &silent)?;
        let landcover_cost = match (&options.landcover, landcover) {
            (Some(table), Some(raster)) => Some(landcover_costs_window(
                raster,
                table,
                [p.col0, p.row0],
                p.width,
                p.height,
                &self.transform,
                self.crs.epsg,
            )?),
            (Some(_), None) => {
                return Err(CostmapError::invalid(
                    "/options/landcover/source",
                    "no land-cover raster was given".to_string(),
                )
                .into());
            }
            _ => None,
        };
        let layers = CellLayers {
            step,
            negative,
            zcomp,
            roughness,
            landcover_cost,
        };
        add_layer_obstacles(&mut class, &layers);
        let mut hole_cells = vec![false; p.width * p.height];
        for (r, row) in hole_cells.chunks_mut(p.width.max(1)).enumerate() {
            holes.row_into(r, row);
        }
        Ok(WindowSurface {
            class,
            layers,
            holes: hole_cells,
        })
    }

    /// Stage 1: tile `k`'s classes before the pocket fill, from its
    /// surface on a window wide enough for the ring of cells around the
    /// core too, and the edges of its regions (labelled with that ring).
    pub fn classify(
        &self,
        src: &dyn RasterWindows,
        landcover: Option<&Dem>,
        k: usize,
        cancel: &AtomicBool,
    ) -> Result<Classified, TiledError> {
        let t = self.tile(k)?;
        self.check_source(src)?;
        cancelled(cancel)?;
        let [w, h] = [self.layout.width, self.layout.height];
        // The surface's halo, plus the ring of cells beside the core whose
        // classes say whether a region is open.
        let p = t.padded(self.halos.surface.map(|v| v + 1), w, h);
        let s = self.surface(src, landcover, &p, cancel)?;
        let ring = t.padded([1, 1], w, h);
        let mut window = Vec::new();
        crop(
            &s.class,
            p.width,
            [ring.col0 - p.col0, ring.row0 - p.row0],
            [ring.width, ring.height],
            &mut window,
        );
        let labels = label_tile(&window, ring.width, [ring.dx, ring.dy], &t, [w, h]);
        let edges = TileEdges::of(&t, &labels);
        let mut core = Vec::new();
        crop(
            &s.class,
            p.width,
            [p.dx, p.dy],
            [t.width, t.height],
            &mut core,
        );
        let mut holes = Vec::new();
        crop(
            &s.holes,
            p.width,
            [p.dx, p.dy],
            [t.width, t.height],
            &mut holes,
        );
        for (c, &hole) in core.iter_mut().zip(&holes) {
            if hole {
                *c |= HOLE_BIT;
            }
        }
        Ok(Classified { core, edges })
    }

    /// A join of the tiles' edges, fed one tile at a time in any order
    /// (what [`TilePlan::join`] does with an iterator).
    pub fn edge_join(&self) -> RegionJoin {
        RegionJoin::new(self.layout, self.min_cells)
    }

    /// Stage 2: every tile's edges (in any order, each once) → which
    /// regions are filled.
    pub fn join(
        &self,
        edges: impl IntoIterator<Item = (usize, TileEdges)>,
    ) -> Result<RegionFill, TiledError> {
        let mut join = self.edge_join();
        for (k, e) in edges {
            join.add(k, e)?;
        }
        Ok(join.join()?)
    }

    /// Stage 3: tile `k`'s final classes (with [`HOLE_BIT`]): its core
    /// and the ring around it read from `prefill` (the classes stage 1
    /// made, of this tile and its neighbours), labelled as in stage 1,
    /// then the pockets `fill` (the join's part for tile `k`) says are
    /// enclosed filled.
    ///
    /// Only whether a ring cell is unknown counts in the labelling, and a
    /// fill turns traversable cells into enclosed ones only, so a ring
    /// read from neighbours already filled labels the same.
    pub fn fill(
        &self,
        k: usize,
        prefill: &dyn ClassWindows,
        fill: &TileFill,
    ) -> Result<Vec<u8>, TiledError> {
        self.fill_counted(k, prefill, fill).map(|(core, _)| core)
    }

    /// [`TilePlan::fill`] and how many cells it filled.
    pub(crate) fn fill_counted(
        &self,
        k: usize,
        prefill: &dyn ClassWindows,
        fill: &TileFill,
    ) -> Result<(Vec<u8>, usize), TiledError> {
        let t = self.tile(k)?;
        let [w, h] = [self.layout.width, self.layout.height];
        let ring = t.padded([1, 1], w, h);
        let mut raw = Vec::new();
        prefill.read_classes(ring.col0, ring.row0, ring.width, ring.height, &mut raw)?;
        if raw.len() != ring.width * ring.height {
            return Err(TiledError::Mismatch(format!(
                "a {}×{} class window read as {} bytes",
                ring.width,
                ring.height,
                raw.len()
            )));
        }
        let plain: Vec<u8> = raw.iter().map(|&c| c & !HOLE_BIT).collect();
        let labels = label_tile(&plain, ring.width, [ring.dx, ring.dy], &t, [w, h]);
        let mut core = Vec::new();
        crop(
            &raw,
            ring.width,
            [ring.dx, ring.dy],
            [t.width, t.height],
            &mut core,
        );
        let mut plain_core: Vec<u8> = core.iter().map(|&c| c & !HOLE_BIT).collect();
        let filled = fill.apply(&t, &labels, self.min_cells, &mut plain_core)?;
        if filled > 0 {
            for (c, p) in core.iter_mut().zip(&plain_core) {
                *c = (*c & HOLE_BIT) | p;
            }
        }
        Ok((core, filled))
    }

    /// Stage 4: tile `k`'s costs, classes and layers, from its surface
    /// (computed again: cheaper than keeping it) and the inflation of the
    /// final classes of the tile and its inflation halo (`classes`: what
    /// stage 3 made), with its parts of the statistics and the preview.
    pub fn cost(
        &self,
        src: &dyn RasterWindows,
        landcover: Option<&Dem>,
        classes: &dyn ClassWindows,
        k: usize,
        cancel: &AtomicBool,
    ) -> Result<CostTile, TiledError> {
        let t = self.tile(k)?;
        self.check_source(src)?;
        cancelled(cancel)?;
        let [w, h] = [self.layout.width, self.layout.height];
        let p = t.padded(self.halos.surface, w, h);
        let s = self.surface(src, landcover, &p, cancel)?;
        let core_of = |v: &[f32]| {
            let mut out = Vec::new();
            crop(v, p.width, [p.dx, p.dy], [t.width, t.height], &mut out);
            out
        };
        let layers = CellLayers {
            step: s.layers.step.as_deref().map(core_of),
            negative: s.layers.negative.as_ref().map(|(d, m)| (core_of(d), *m)),
            zcomp: core_of(&s.layers.zcomp),
            roughness: s.layers.roughness.as_deref().map(core_of),
            landcover_cost: s.layers.landcover_cost.as_deref().map(core_of),
        };
        drop(s);
        cancelled(cancel)?;
        let pi = t.padded(self.halos.inflation, w, h);
        let mut raw = Vec::new();
        classes.read_classes(pi.col0, pi.row0, pi.width, pi.height, &mut raw)?;
        if raw.len() != pi.width * pi.height {
            return Err(TiledError::Mismatch(format!(
                "a {}×{} class window read as {} bytes",
                pi.width,
                pi.height,
                raw.len()
            )));
        }
        // As the whole-grid run: obstacles and cells without a height.
        let obstacle: Vec<bool> = raw
            .iter()
            .map(|&c| c & HOLE_BIT != 0 || Class::from_code(c).is_some_and(Class::is_obstacle))
            .collect();
        let window = inflation(
            &obstacle,
            pi.width,
            pi.height,
            self.centre_m,
            self.params.inflation_sigma_m,
            self.params.inflation,
        );
        drop(obstacle);
        let mut inflated = Vec::new();
        crop(
            &window,
            pi.width,
            [pi.dx, pi.dy],
            [t.width, t.height],
            &mut inflated,
        );
        drop(window);
        let mut class = Vec::new();
        crop(
            &raw,
            pi.width,
            [pi.dx, pi.dy],
            [t.width, t.height],
            &mut class,
        );
        class.iter_mut().for_each(|c| *c &= !HOLE_BIT);
        let silent = Silent(cancel);
        let (cost, inflation_layer) = costs(
            inflated,
            &class,
            &layers,
            &self.vehicle,
            &self.options,
            &silent,
        )?;
        let layer_out = layer_rasters(&layers, inflation_layer, &self.options);
        let mut tally = StatsTally::new(self.range);
        tally.add(&cost, &class);
        let preview = self.preview.part(&t, &cost, &class);
        Ok(CostTile {
            window: t,
            cost,
            class,
            layers: layer_out,
            tally: tally.into_part(),
            preview,
        })
    }

    /// A merge of the tiles' statistics and previews, fed in tile order
    /// (what [`TilePlan::finish`] does with an iterator).
    pub fn merge(&self) -> FinishMerge<'_> {
        FinishMerge {
            plan: self,
            next: 0,
            tally: StatsTally::new(self.range),
            preview: PreviewTiles::new(self.preview),
        }
    }

    /// Stage 5: every tile's tally and preview part, in tile order (0, 1,
    /// …, each once) → the costmap's statistics, warnings and preview.
    pub fn finish(
        &self,
        parts: impl IntoIterator<Item = (usize, TallyPart, PreviewPart)>,
    ) -> Result<TiledCostmap, TiledError> {
        let mut merge = self.merge();
        for (k, tally, preview) in parts {
            merge.add(k, &tally, &preview)?;
        }
        merge.finish()
    }
}

/// The statistics and preview of a tiled costmap being merged from its
/// tiles' parts, in tile order: the same bits whatever process made each
/// part, in whatever order they were made.
pub struct FinishMerge<'a> {
    plan: &'a TilePlan,
    next: usize,
    tally: StatsTally,
    preview: PreviewTiles,
}

impl FinishMerge<'_> {
    /// Adds tile `k`'s parts; `k` must be the next tile.
    pub fn add(
        &mut self,
        k: usize,
        tally: &TallyPart,
        preview: &PreviewPart,
    ) -> Result<(), TiledError> {
        if k != self.next {
            return Err(TiledError::Mismatch(format!(
                "the parts of tile {k} came when those of tile {} were due (they merge in tile \
                 order)",
                self.next
            )));
        }
        let t = self.plan.tile(k)?;
        let cells = (t.width * t.height) as u64;
        if tally.cells() != cells {
            return Err(TiledError::Mismatch(format!(
                "the tally of tile {k} counts {} cells, the tile has {cells}",
                tally.cells()
            )));
        }
        self.preview.merge(&t, preview)?;
        self.tally.merge(tally);
        self.next += 1;
        Ok(())
    }

    /// The costmap once every tile's parts were added.
    pub fn finish(self) -> Result<TiledCostmap, TiledError> {
        let plan = self.plan;
        let n = plan.tile_count();
        if self.next != n {
            return Err(TiledError::Mismatch(format!(
                "the parts of {} tiles of {n} were merged",
                self.next
            )));
        }
        let (w, h) = (plan.layout.width, plan.layout.height);
        let [cx, cy] = plan.centre_m;
        let stats = self.tally.finish(w, h, cx * cy, plan.range);
        let mut warnings = plan.warnings.clone();
        if stats.class_fractions.traversable == 0.0 {
            warnings.push(
                "no cell is traversable for this vehicle: every cell is an obstacle or unknown"
                    .to_string(),
            );
        }
        Ok(TiledCostmap {
            width: w,
            height: h,
            transform: plan.transform,
            crs: plan.crs.clone(),
            vehicle: plan.vehicle.clone(),
            params: plan.params.clone(),
            stats,
            warnings,
            preview_png: self.preview.finish(plan.range),
            tile: plan.layout.tile,
            halos: plan.halos,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::JoinError;
    use crate::costmap::tiled::tests::{assert_same, terrain, tiled};
    use crate::costmap::{InflationMode, NegativeStepOptions, RoughnessOptions, VehiclePreset};
    use crate::terrain::DemWindows;
    use crate::test_rng::Lcg;

    /// 0..n in an order drawn from `s`.
    fn shuffled(n: usize, s: &mut Lcg) -> Vec<usize> {
        let mut order: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            let j = (s.next() * (i + 1) as f64) as usize;
            order.swap(i, j.min(i));
        }
        order
    }

    /// A costmap made by the stages as jobs would make it: each stage's
    /// tiles in a shuffled order, each on a plan rebuilt from the request
    /// (as every process does), every exchanged piece through its bytes;
    /// then the tiles assembled into whole grids.
    struct Staged {
        map: TiledCostmap,
        cost: Vec<f32>,
        class: Vec<u8>,
        layers: Vec<(Layer, Vec<f32>)>,
    }

    /// Class windows of only the tiles a stage says it reads.
    fn only<'a>(
        layout: TileLayout,
        tiles: &'a [Vec<u8>],
        reads: Vec<usize>,
    ) -> ClassTiles<impl Fn(usize) -> Result<&'a [u8], TiledError> + Sync> {
        ClassTiles::new(layout, move |j| {
            if reads.contains(&j) {
                Ok(tiles[j].as_slice())
            } else {
                Err(TiledError::Mismatch(format!(
                    "tile {j} read, not in {reads:?}"
                )))
            }
        })
    }

    fn staged(d: &Dem, v: &Vehicle, o: &CostmapOptions, tile: usize, seed: u64) -> Staged {
        let src = DemWindows::new(d);
        let plan_of = || {
            TilePlan::new(src.grid(), v, o, None, tile)
                .unwrap()
                .with_preview_max_side(64)
        };
        let plan = plan_of();
        let n = plan.tile_count();
        let mut s = Lcg(seed);
        let cancel = AtomicBool::new(false);

        // 1. classify
        let mut prefill = vec![Vec::new(); n];
        let mut edges = vec![Vec::new(); n];
        for k in shuffled(n, &mut s) {
            let c = plan_of().classify(&src, None, k, &cancel).unwrap();
            prefill[k] = c.core;
            edges[k] = c.edges.to_bytes();
        }
        // 2. join
        let order = shuffled(n, &mut s);
        let fill = plan_of()
            .join(
                order
                    .iter()
                    .map(|&k| (k, TileEdges::from_bytes(&edges[k]).unwrap())),
            )
            .unwrap();
        let fill = RegionFill::from_bytes(&fill.to_bytes()).unwrap();
        let fill: Vec<Vec<u8>> = fill.into_tiles().iter().map(TileFill::to_bytes).collect();
        // 3. fill, reading the classes before the fill only
        let mut classes = vec![Vec::new(); n];
        for k in shuffled(n, &mut s) {
            let part = TileFill::from_bytes(&fill[k]).unwrap();
            let prefill_windows = only(plan.layout(), &prefill, plan.fill_reads(k).unwrap());
            classes[k] = plan_of().fill(k, &prefill_windows, &part).unwrap();
        }
        // 4. cost
        let (w, h) = (plan.layout().width, plan.layout().height);
        let mut cost = vec![0.0; w * h];
        let mut class = vec![0; w * h];
        let mut layers: Vec<(Layer, Vec<f32>)> = plan
            .layers()
            .into_iter()
            .map(|l| (l, vec![0.0; w * h]))
            .collect();
        let mut parts = vec![(Vec::new(), Vec::new()); n];
        for k in shuffled(n, &mut s) {
            let final_windows = only(plan.layout(), &classes, plan.cost_reads(k).unwrap());
            let t = plan_of()
                .cost(&src, None, &final_windows, k, &cancel)
                .unwrap();
            let tw = &t.window;
            for r in 0..tw.height {
                let at = (tw.row0 + r) * w + tw.col0;
                let from = r * tw.width..(r + 1) * tw.width;
                cost[at..at + tw.width].copy_from_slice(&t.cost[from.clone()]);
                class[at..at + tw.width].copy_from_slice(&t.class[from.clone()]);
                assert_eq!(t.layers.len(), layers.len());
                for ((la, all), (lb, part)) in layers.iter_mut().zip(&t.layers) {
                    assert_eq!(la, lb);
                    all[at..at + tw.width].copy_from_slice(&part[from.clone()]);
                }
            }
            parts[k] = (t.tally.to_bytes(), t.preview.to_bytes());
        }
        // 5. finish, the parts read back in tile order
        let map = plan_of()
            .finish(parts.iter().enumerate().map(|(k, (t, p))| {
                (
                    k,
                    TallyPart::from_bytes(t).unwrap(),
                    PreviewPart::from_bytes(p).unwrap(),
                )
            }))
            .unwrap();
        Staged {
            map,
            cost,
            class,
            layers,
        }
    }

    /// The stages in shuffled order give what the sequential tiled run
    /// gives, bit for bit (statistics and preview included), and that is
    /// the whole-raster run's ([`assert_same`]).
    fn assert_stages_equal(d: &Dem, v: &Vehicle, o: &CostmapOptions, tile: usize, seed: u64) {
        assert_same(d, v, o, tile);
        let (m, seq) = tiled(d, v, o, tile);
        let st = staged(d, v, o, tile, seed);
        let label = format!("{}×{} tile {tile}", m.width, m.height);
        assert!(
            st.cost
                .iter()
                .zip(&seq.cost)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{label}: costs"
        );
        assert_eq!(st.class, seq.class, "{label}: classes");
        assert_eq!(st.layers.len(), seq.layers.len(), "{label}");
        for ((la, a), (lb, b)) in st.layers.iter().zip(&seq.layers) {
            assert_eq!(la, lb);
            assert!(
                a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()),
                "{label}: {la:?}"
            );
        }
        let sm = &st.map;
        assert_eq!(sm.stats, m.stats, "{label}: statistics");
        assert_eq!(
            sm.stats.cost_mean.map(f64::to_bits),
            m.stats.cost_mean.map(f64::to_bits),
            "{label}: mean"
        );
        assert_eq!(sm.warnings, m.warnings, "{label}");
        assert_eq!(sm.preview_png, m.preview_png, "{label}: preview");
        assert_eq!(
            (
                sm.width,
                sm.height,
                sm.transform,
                &sm.crs,
                sm.tile,
                sm.halos
            ),
            (m.width, m.height, m.transform, &m.crs, m.tile, m.halos),
            "{label}"
        );
        assert_eq!(sm.params, m.params);
        assert_eq!(sm.legend_svg(), m.legend_svg());
    }

    #[test]
    fn stages_in_any_order_equal_the_sequential_and_whole_runs() {
        let v = VehiclePreset::UGo.vehicle();
        // Walled pockets across tile borders, nodata on tile borders.
        let d = terrain(47, 39, 0.1, 7);
        let o = CostmapOptions {
            layers: Layer::ALL
                .into_iter()
                .filter(|&l| l != Layer::Landcover)
                .collect(),
            roughness: Some(RoughnessOptions {
                max_m: 0.05,
                weight: 2.0,
            }),
            negative_steps: Some(NegativeStepOptions {
                max_depth_m: Some(0.1),
                radius_m: Some(0.3),
            }),
            min_region_area_m2: Some(1.0),
            ..Default::default()
        };
        for (i, tile) in [1, 3, 7, 16, 23, 47, 100].into_iter().enumerate() {
            assert_stages_equal(&d, &v, &o, tile, 100 + i as u64);
        }
    }

    #[test]
    fn stages_equal_the_runs_on_random_dems_modes_and_tile_sizes() {
        let v = VehiclePreset::UGo.vehicle();
        let mut s = Lcg(0x57a9e5);
        for case in 0..10 {
            let w = 8 + (s.next() * 60.0) as usize;
            let h = 8 + (s.next() * 60.0) as usize;
            let cell = 0.05 + 0.1 * s.next();
            let d = terrain(w, h, cell, case);
            let tile = 1 + (s.next() * 30.0) as usize;
            // Every third case resampled to cells twice as large.
            let resampled = case % 3 == 2;
            let work = if resampled { 2.0 * cell } else { cell };
            let o = CostmapOptions {
                min_region_area_m2: Some(0.5 + 3.0 * s.next()),
                inflation_sigma_m: Some(work * (0.2 + 2.0 * s.next())),
                inflation: [InflationMode::Distance, InflationMode::Blur][case as usize % 2],
                pca_radius_m: Some(work * (1.5 + 1.5 * s.next())),
                resolution_m: resampled.then_some(work),
                layers: vec![Layer::Slope, Layer::Inflation],
                ..Default::default()
            };
            assert_stages_equal(&d, &v, &o, tile, case);
        }
    }

    #[test]
    fn the_plan_is_the_same_on_every_rebuild() {
        let v = VehiclePreset::UGo.vehicle();
        let d = terrain(40, 30, 0.1, 2);
        let src = DemWindows::new(&d);
        let o = CostmapOptions::default();
        let a = TilePlan::new(src.grid(), &v, &o, None, 16).unwrap();
        let b = TilePlan::new(src.grid(), &v, &o, None, 16).unwrap();
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert_eq!(a.tile_count(), 6);
        assert_eq!(a.header().tile, 16);
    }

    #[test]
    fn stage_inputs_that_do_not_fit_the_plan_are_errors() {
        let v = VehiclePreset::UGo.vehicle();
        let d = terrain(40, 30, 0.1, 2);
        let src = DemWindows::new(&d);
        let plan = TilePlan::new(src.grid(), &v, &CostmapOptions::default(), None, 16).unwrap();
        let cancel = AtomicBool::new(false);
        let n = plan.tile_count();
        assert!(matches!(
            plan.classify(&src, None, n, &cancel),
            Err(TiledError::NoSuchTile { k, count }) if k == n && count == n
        ));
        // Another DEM's source.
        let other = terrain(41, 30, 0.1, 2);
        assert!(matches!(
            plan.classify(&DemWindows::new(&other), None, 0, &cancel),
            Err(TiledError::Mismatch(_))
        ));
        // Cancelled before it starts.
        let stop = AtomicBool::new(true);
        assert!(matches!(
            plan.classify(&src, None, 0, &stop),
            Err(TiledError::Costmap(CostmapError::Cancelled))
        ));
        let classified: Vec<Classified> = (0..n)
            .map(|k| plan.classify(&src, None, k, &cancel).unwrap())
            .collect();
        // The join: a tile twice, one missing, another tile's edges.
        let edges = |k: usize| classified[k].edges.clone();
        let r = plan.join([(0, edges(0)), (0, edges(0))]);
        assert!(
            matches!(r, Err(TiledError::Join(JoinError::Twice(0)))),
            "{r:?}"
        );
        let r = plan.join((0..n - 1).map(|k| (k, edges(k))));
        assert!(
            matches!(r, Err(TiledError::Join(JoinError::Missing(k))) if k == n - 1),
            "{r:?}"
        );
        // Tile 2 is 8 cells wide, tile 0 16.
        let r = plan.join([(2, edges(0))]);
        assert!(
            matches!(r, Err(TiledError::Join(JoinError::WrongSize { k: 2, .. }))),
            "{r:?}"
        );
        let fill = plan.join((0..n).rev().map(|k| (k, edges(k)))).unwrap();
        // Class tiles of the wrong size.
        let short = ClassTiles::new(plan.layout(), |_| Ok(vec![1u8; 3]));
        let r = plan.fill(0, &short, fill.tile(0).unwrap());
        assert!(matches!(r, Err(TiledError::Mismatch(_))), "{r:?}");
        // A store that fails says so.
        let failing = ClassTiles::new(plan.layout(), |_| -> Result<Vec<u8>, TiledError> {
            Err(TiledError::Stored("the database is gone".into()))
        });
        let r = plan.cost(&src, None, &failing, 0, &cancel);
        assert!(
            matches!(&r, Err(e) if e.to_string().contains("the database is gone")),
            "{r:?}"
        );
        // Finish: out of order, wrong tile, incomplete.
        let prefill = ClassTiles::new(plan.layout(), |k| Ok(classified[k].core.as_slice()));
        let finals: Vec<Vec<u8>> = (0..n)
            .map(|k| plan.fill(k, &prefill, fill.tile(k).unwrap()).unwrap())
            .collect();
        // Another tile's fill, or classes that are not those joined.
        let r = plan.fill(0, &prefill, fill.tile(1).unwrap());
        assert!(
            matches!(r, Err(TiledError::Join(JoinError::Labels { tx: 0, ty: 0 }))),
            "{r:?}"
        );
        let changed = ClassTiles::new(plan.layout(), |k| {
            let mut c = classified[k].core.clone();
            c[0] = if c[0] == Class::Traversable as u8 {
                Class::Step as u8
            } else {
                Class::Traversable as u8
            };
            Ok(c)
        });
        let r = plan.fill(4, &changed, fill.tile(4).unwrap());
        assert!(
            matches!(r, Err(TiledError::Join(JoinError::Labels { tx: 1, ty: 1 }))),
            "{r:?}"
        );
        let classes = ClassTiles::new(plan.layout(), |k| Ok(finals[k].as_slice()));
        let tiles: Vec<CostTile> = (0..n)
            .map(|k| plan.cost(&src, None, &classes, k, &cancel).unwrap())
            .collect();
        let part = |k: usize| (k, tiles[k].tally.clone(), tiles[k].preview.clone());
        let r = plan.finish([part(1), part(0)]);
        assert!(matches!(r, Err(TiledError::Mismatch(_))), "{r:?}");
        let mut merge = plan.merge();
        merge.add(0, &tiles[0].tally, &tiles[0].preview).unwrap();
        // Tile 2's tally (fewer cells) given as tile 1's.
        let r = merge.add(1, &tiles[2].tally, &tiles[1].preview);
        assert!(matches!(r, Err(TiledError::Mismatch(_))), "{r:?}");
        assert!(matches!(merge.finish(), Err(TiledError::Mismatch(_))));
        plan.finish((0..n).map(part)).unwrap();
    }

    #[test]
    fn class_tiles_cut_windows_across_tiles() {
        let layout = TileLayout::new(10, 7, 4);
        // Each tile's cells hold their grid index mod 251.
        let tiles: Vec<Vec<u8>> = (0..layout.count())
            .map(|k| {
                let t = layout.tile(k);
                (0..t.width * t.height)
                    .map(|i| (((t.row0 + i / t.width) * 10 + t.col0 + i % t.width) % 251) as u8)
                    .collect()
            })
            .collect();
        let windows = ClassTiles::new(layout, |k| Ok(tiles[k].as_slice()));
        let mut out = Vec::new();
        for (c0, r0, w, h) in [(0, 0, 10, 7), (3, 2, 5, 4), (9, 6, 1, 1), (2, 3, 0, 2)] {
            windows.read_classes(c0, r0, w, h, &mut out).unwrap();
            let want: Vec<u8> = (0..w * h)
                .map(|i| (((r0 + i / w.max(1)) * 10 + c0 + i % w.max(1)) % 251) as u8)
                .collect();
            assert_eq!(out, want, "{c0} {r0} {w} {h}");
        }
        assert!(windows.read_classes(8, 0, 3, 1, &mut out).is_err());
        assert!(windows.read_classes(0, 0, usize::MAX, 1, &mut out).is_err());
    }
}
