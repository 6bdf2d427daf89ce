//! The costmap pipeline (SPEC §4.2) run tile by tile over a raster read a
//! window at a time ([`RasterWindows`]), so a DEM larger than memory can
//! be mapped: memory is bounded by the tile size, never the map's.
//!
//! Every neighbourhood operation reaches a bounded distance ([`Halos`]),
//! so each tile is read with a halo that wide and its core comes out as
//! the whole-grid run's ([`super::build_costmap`]), bit for bit. The
//! enclosed-pocket fill is global, so the run makes three passes over the
//! tiles:
//!
//! 1. per tile, the surface (resampling, steps, normals, optional
//!    obstacle layers) and the classes before the fill, written to a
//!    scratch file ([`ClassStore`], a byte per cell); the tile's
//!    traversable regions are labelled and the labels on its edges kept
//!    ([`RegionJoin`]); then the edges are joined (union–find);
//! 2. per tile, the labels again, and the pockets to fill are filled in
//!    the scratch file;
//! 3. per tile, the surface again (cheaper than keeping it on disk), the
//!    inflation from the final classes of the tile and its inflation halo,
//!    the costs; the tile goes to a [`TileSink`] (e.g. a tiled GeoTIFF)
//!    and into the statistics and the preview.
//!
//! Resampling is tiled exactly (a working cell is a whole block of DEM
//! cells), geographic DEMs too (each row's cell size is the whole grid's);
//! the land-cover layer samples each cell from the grid's own transform.

use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use super::bands::Surface;
use super::class_store::{ClassStore, HOLE_BIT};
use super::grid::{WorkGeometry, average_blocks, work_geometry};
use super::halo::{Halos, Padded, TileLayout, TileWindow, crop, halos};
use super::inflate::inflation;
use super::landcover::landcover_costs_window;
use super::params::resolve;
use super::pipeline::{
    CellLayers, Heights, add_layer_obstacles, check_request, cost_range, costs, layer_rasters,
    negative_steps_of, resample_warnings, surface_of,
};
use super::preview_tiles::PreviewTiles;
use super::progress::Monotone;
use super::region_join::{JoinError, RegionJoin, TileLabels, label_tile};
use super::stats::StatsTally;
use super::{
    Class, CostmapError, CostmapOptions, CostmapStats, Layer, Progress, ResolvedParams, Stage,
    Vehicle,
};
use crate::terrain::{Crs, Dem, DemFormat, GeoTransform, RasterWindows, TerrainError};

/// How a tiled run cuts and where it keeps its scratch file.
#[derive(Clone, Debug)]
pub struct TiledOptions {
    /// Core tile side, working cells (the last tiles are narrower).
    pub tile: usize,
    /// Where the scratch file of classes goes (a byte per working cell).
    pub scratch_dir: PathBuf,
    /// The preview's longer side, pixels.
    pub preview_max_side: usize,
}

/// One finished tile of a costmap: its core, row-major.
pub struct CostmapTile<'a> {
    /// Tile column and row, and its top-left cell and size on the grid.
    pub tx: usize,
    pub ty: usize,
    pub col0: usize,
    pub row0: usize,
    pub width: usize,
    pub height: usize,
    pub cost: &'a [f32],
    pub class: &'a [u8],
    /// The layers asked for, in [`Layer::ALL`] order.
    pub layers: &'a [(Layer, Vec<f32>)],
}

/// The map a tiled run is about to make, told to its sink first.
#[derive(Clone, Debug)]
pub struct MapHeader {
    pub width: usize,
    pub height: usize,
    pub transform: GeoTransform,
    pub crs: Crs,
    /// The tile side: every tile but the last column's and row's is this
    /// wide and high.
    pub tile: usize,
    /// The layers every tile holds, in [`Layer::ALL`] order.
    pub layers: Vec<Layer>,
}

/// Where a tiled run's tiles go: [`TileSink::begin`] once the map's size
/// is known (after the checks), then every tile in row-major tile order.
pub trait TileSink {
    fn begin(&mut self, map: &MapHeader) -> io::Result<()>;
    fn tile(&mut self, tile: &CostmapTile<'_>) -> io::Result<()>;
}

/// What a tiled run knows of its costmap once every tile went out.
#[derive(Clone, Debug)]
pub struct TiledCostmap {
    pub width: usize,
    pub height: usize,
    pub transform: GeoTransform,
    pub crs: Crs,
    pub vehicle: Vehicle,
    pub params: ResolvedParams,
    pub stats: CostmapStats,
    pub warnings: Vec<String>,
    /// The preview PNG (as [`super::preview_png`] draws it).
    pub preview_png: Vec<u8>,
    /// The tile side and the halos the run used.
    pub tile: usize,
    pub halos: Halos,
}

/// Why a tiled run failed.
#[derive(Debug, thiserror::Error)]
pub enum TiledError {
    #[error(transparent)]
    Costmap(#[from] CostmapError),
    #[error("reading the DEM: {0}")]
    Read(#[from] TerrainError),
    #[error("writing the costmap: {0}")]
    Write(#[source] io::Error),
    #[error("the scratch file of classes: {0}")]
    Scratch(#[source] io::Error),
    #[error("joining regions across tiles: {0}")]
    Join(#[from] JoinError),
}

/// The grid's size and georeferencing as a [`Dem`] without heights: what
/// the checks and the parameters read.
fn shell_dem(src: &dyn RasterWindows) -> Dem {
    let g = src.grid();
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
/// report nothing, the run reports its tiles.
struct Silent<'a>(&'a AtomicBool);

impl Progress for Silent<'_> {
    fn report(&self, _: Stage, _: f64) -> bool {
        !self.0.load(Ordering::Relaxed)
    }
}

/// Everything a tile's computation reads.
struct Run<'a> {
    src: &'a dyn RasterWindows,
    vehicle: &'a Vehicle,
    options: &'a CostmapOptions,
    landcover: Option<&'a Dem>,
    params: ResolvedParams,
    geometry: WorkGeometry,
    centre_m: [f64; 2],
    epsg: u32,
    cancel: AtomicBool,
}

/// A window's surface: classes before the fill (with the optional
/// obstacle layers), and the per-cell grids the costs are made of.
struct WindowSurface {
    class: Vec<u8>,
    layers: CellLayers,
    holes: Vec<bool>,
}

impl Run<'_> {
    /// The working heights of window `p`.
    fn heights(&self, p: &Padded) -> Result<Vec<f64>, TiledError> {
        let [fx, fy] = self.params.resample_factor;
        let mut dem = vec![0.0; p.width * fx * p.height * fy];
        self.src.read_window(
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

    fn surface(&self, p: &Padded) -> Result<WindowSurface, TiledError> {
        let z = self.heights(p)?;
        let heights = Heights {
            z: &z,
            width: p.width,
            height: p.height,
            row_size_m: &self.geometry.row_size_m[p.row0..p.row0 + p.height],
            centre_m: self.centre_m,
        };
        let silent = Silent(&self.cancel);
        let Surface {
            zcomp,
            roughness,
            step,
            mut class,
            holes,
        } = surface_of(&heights, self.vehicle, self.options, &self.params, &silent)?;
        let negative = negative_steps_of(&heights, self.vehicle, self.options, &silent)?;
        let landcover_cost = match (&self.options.landcover, self.landcover) {
            (Some(table), Some(raster)) => Some(landcover_costs_window(
                raster,
                table,
                [p.col0, p.row0],
                p.width,
                p.height,
                &self.geometry.transform,
                self.epsg,
            )?),
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

    fn cancelled(&self) -> Result<(), TiledError> {
        if self.cancel.load(Ordering::Relaxed) {
            Err(CostmapError::Cancelled.into())
        } else {
            Ok(())
        }
    }
}

/// Builds the costmap of the DEM `src` tile by tile, giving each finished
/// tile to `sink` in row-major tile order; the same costs, classes and
/// layers as [`super::build_costmap`] of the whole DEM, and the same
/// statistics but for the order the mean's sum is added in.
pub fn build_costmap_tiled(
    src: &dyn RasterWindows,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
    tiled: &TiledOptions,
    progress: &dyn Progress,
    sink: &mut dyn TileSink,
) -> Result<TiledCostmap, TiledError> {
    let progress = &Monotone::new(progress);
    let shell = shell_dem(src);
    check_request(&shell, vehicle, options, landcover)?;
    let params = resolve(&shell, vehicle, options);
    let geometry = work_geometry(&shell, params.resample_factor);
    let (w, h) = (geometry.width, geometry.height);
    let centre_m = geometry.row_size_m[h / 2];
    let mut warnings = Vec::new();
    resample_warnings(vehicle, options, &params, centre_m, &mut warnings);
    let halos = halos(&params, options, vehicle, &geometry.row_size_m, centre_m);
    let layout = TileLayout::new(w, h, tiled.tile);
    let run = Run {
        src,
        vehicle,
        options,
        landcover,
        params: params.clone(),
        epsg: shell.crs.epsg,
        geometry,
        centre_m,
        cancel: AtomicBool::new(false),
    };
    let report = |stage: Stage, done: f64| {
        if !progress.report(stage, done) {
            run.cancel.store(true, Ordering::Relaxed);
        }
    };
    let n = layout.count();
    let mut store = ClassStore::create(&tiled.scratch_dir, w, h).map_err(TiledError::Scratch)?;
    // The surface's halo, plus the ring of cells beside the core whose
    // classes say whether a region is open.
    let ring_halo = halos.surface.map(|v| v + 1);
    let min_cells = params.min_region_area_m2 / (centre_m[0] * centre_m[1]);
    let mut join = RegionJoin::new(layout, min_cells);

    // Pass 1: classes before the fill, the regions' edges.
    let mut buf = Vec::new();
    for k in 0..n {
        report(Stage::Normals, 0.5 * k as f64 / n as f64);
        run.cancelled()?;
        let t = layout.tile(k);
        let p = t.padded(ring_halo, w, h);
        let s = run.surface(&p)?;
        let ring = t.padded([1, 1], w, h);
        let offset = [ring.col0 - p.col0, ring.row0 - p.row0];
        crop(
            &s.class,
            p.width,
            offset,
            [ring.width, ring.height],
            &mut buf,
        );
        join.add(
            k,
            &label_tile(&buf, ring.width, [ring.dx, ring.dy], &t, [w, h]),
        )?;
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
        write_core(&mut store, &t, &core)?;
    }
    join.join()?;

    // Pass 2: the pockets filled.
    let mut raw = Vec::new();
    for k in 0..n {
        report(Stage::Regions, 0.5 + 0.1 * k as f64 / n as f64);
        run.cancelled()?;
        let t = layout.tile(k);
        let ring = t.padded([1, 1], w, h);
        let labels = labelled(&mut store, &t, &ring, [w, h], &mut raw)?;
        let mut core = Vec::new();
        crop(
            &raw,
            ring.width,
            [ring.dx, ring.dy],
            [t.width, t.height],
            &mut core,
        );
        let mut plain: Vec<u8> = core.iter().map(|&c| c & !HOLE_BIT).collect();
        if join.apply(k, &labels, &mut plain) > 0 {
            for (c, p) in core.iter_mut().zip(&plain) {
                *c = (*c & HOLE_BIT) | p;
            }
            write_core(&mut store, &t, &core)?;
        }
    }
    drop(join);

    // Pass 3: inflation and costs.
    sink.begin(&MapHeader {
        width: w,
        height: h,
        transform: run.geometry.transform,
        crs: shell.crs.clone(),
        tile: layout.tile,
        layers: Layer::ALL
            .into_iter()
            .filter(|l| options.layers.contains(l))
            .collect(),
    })
    .map_err(TiledError::Write)?;
    let range = cost_range(vehicle, options);
    let mut tally = StatsTally::new(range);
    let mut preview = PreviewTiles::new(w, h, tiled.preview_max_side);
    for k in 0..n {
        report(Stage::Cost, 0.6 + 0.4 * k as f64 / n as f64);
        run.cancelled()?;
        let t = layout.tile(k);
        let p = t.padded(halos.surface, w, h);
        let s = run.surface(&p)?;
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
        let inflated = inflate_tile(&run, &mut store, &t, halos.inflation, [w, h], &mut raw)?;
        let pi = t.padded(halos.inflation, w, h);
        let mut class = Vec::new();
        crop(
            &raw,
            pi.width,
            [pi.dx, pi.dy],
            [t.width, t.height],
            &mut class,
        );
        class.iter_mut().for_each(|c| *c &= !HOLE_BIT);
        let silent = Silent(&run.cancel);
        let (cost, inflation_layer) = costs(inflated, &class, &layers, vehicle, options, &silent)?;
        let layer_out = layer_rasters(&layers, inflation_layer, options);
        tally.add(&cost, &class);
        preview.add(t.col0, t.row0, t.width, &cost, &class);
        sink.tile(&CostmapTile {
            tx: t.tx,
            ty: t.ty,
            col0: t.col0,
            row0: t.row0,
            width: t.width,
            height: t.height,
            cost: &cost,
            class: &class,
            layers: &layer_out,
        })
        .map_err(TiledError::Write)?;
    }
    report(Stage::Cost, 1.0);
    run.cancelled()?;
    let stats = tally.finish(w, h, centre_m[0] * centre_m[1], range);
    if stats.class_fractions.traversable == 0.0 {
        warnings.push(
            "no cell is traversable for this vehicle: every cell is an obstacle or unknown"
                .to_string(),
        );
    }
    Ok(TiledCostmap {
        width: w,
        height: h,
        transform: run.geometry.transform,
        crs: shell.crs,
        vehicle: vehicle.clone(),
        params,
        stats,
        warnings,
        preview_png: preview.finish(range),
        tile: layout.tile,
        halos,
    })
}

fn write_core(store: &mut ClassStore, t: &TileWindow, core: &[u8]) -> Result<(), TiledError> {
    store
        .write(t.col0, t.row0, t.width, t.height, core)
        .map_err(TiledError::Scratch)
}

/// Tile `t`'s regions, labelled from the stored classes of its core and
/// the ring around it (`ring`), which are left in `raw`.
fn labelled(
    store: &mut ClassStore,
    t: &TileWindow,
    ring: &Padded,
    grid: [usize; 2],
    raw: &mut Vec<u8>,
) -> Result<TileLabels, TiledError> {
    store
        .read(ring.col0, ring.row0, ring.width, ring.height, raw)
        .map_err(TiledError::Scratch)?;
    let plain: Vec<u8> = raw.iter().map(|&c| c & !HOLE_BIT).collect();
    Ok(label_tile(&plain, ring.width, [ring.dx, ring.dy], t, grid))
}

/// The inflation of tile `t`'s core, from the final classes (and holes)
/// of the tile and its inflation halo, which are left in `raw`.
fn inflate_tile(
    run: &Run<'_>,
    store: &mut ClassStore,
    t: &TileWindow,
    halo: [usize; 2],
    [w, h]: [usize; 2],
    raw: &mut Vec<u8>,
) -> Result<Vec<f32>, TiledError> {
    let pi = t.padded(halo, w, h);
    store
        .read(pi.col0, pi.row0, pi.width, pi.height, raw)
        .map_err(TiledError::Scratch)?;
    // As the whole-grid run: obstacles and cells without a height.
    let obstacle: Vec<bool> = raw
        .iter()
        .map(|&c| c & HOLE_BIT != 0 || Class::from_code(c).is_some_and(Class::is_obstacle))
        .collect();
    let window = inflation(
        &obstacle,
        pi.width,
        pi.height,
        run.centre_m,
        run.params.inflation_sigma_m,
        run.params.inflation,
    );
    let mut core = Vec::new();
    crop(
        &window,
        pi.width,
        [pi.dx, pi.dy],
        [t.width, t.height],
        &mut core,
    );
    Ok(core)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{Costmap, InflationMode, StepMode, VehiclePreset, build_costmap};
    use crate::terrain::DemWindows;
    use crate::terrain::test_support::{dem, north_up};
    use crate::test_rng::Lcg;

    /// Collects the tiles into whole grids.
    struct Assemble {
        width: usize,
        cost: Vec<f32>,
        class: Vec<u8>,
        layers: Vec<(Layer, Vec<f32>)>,
        order: Vec<(usize, usize)>,
    }

    impl TileSink for Assemble {
        fn begin(&mut self, map: &MapHeader) -> io::Result<()> {
            assert_eq!(map.width, self.width);
            Ok(())
        }

        fn tile(&mut self, t: &CostmapTile<'_>) -> io::Result<()> {
            self.order.push((t.tx, t.ty));
            if self.layers.is_empty() {
                let n = self.cost.len();
                self.layers = t.layers.iter().map(|(l, _)| (*l, vec![0.0; n])).collect();
            }
            for r in 0..t.height {
                let at = (t.row0 + r) * self.width + t.col0;
                let from = r * t.width..(r + 1) * t.width;
                self.cost[at..at + t.width].copy_from_slice(&t.cost[from.clone()]);
                self.class[at..at + t.width].copy_from_slice(&t.class[from.clone()]);
                for ((_, all), (_, part)) in self.layers.iter_mut().zip(t.layers) {
                    all[at..at + t.width].copy_from_slice(&part[from.clone()]);
                }
            }
            Ok(())
        }
    }

    fn quiet() -> impl Progress {
        |_: Stage, _: f64| true
    }

    fn tiled(d: &Dem, v: &Vehicle, o: &CostmapOptions, tile: usize) -> (TiledCostmap, Assemble) {
        let whole = build_costmap(d, v, o, None, &quiet()).unwrap();
        let mut sink = Assemble {
            width: whole.width,
            cost: vec![0.0; whole.width * whole.height],
            class: vec![0; whole.width * whole.height],
            layers: Vec::new(),
            order: Vec::new(),
        };
        let opts = TiledOptions {
            tile,
            scratch_dir: std::env::temp_dir(),
            preview_max_side: 64,
        };
        let m = build_costmap_tiled(&DemWindows::new(d), v, o, None, &opts, &quiet(), &mut sink)
            .unwrap();
        (m, sink)
    }

    /// The tiled run equals the whole-grid run: costs, classes and layers
    /// bit for bit, the statistics (the mean within 1e-9 relative) and the
    /// preview.
    fn assert_same(d: &Dem, v: &Vehicle, o: &CostmapOptions, tile: usize) -> Costmap {
        let whole = build_costmap(d, v, o, None, &quiet()).unwrap();
        let (m, got) = tiled(d, v, o, tile);
        assert_eq!((m.width, m.height), (whole.width, whole.height));
        assert_eq!(m.transform, whole.transform);
        let label = format!("{}×{} tile {tile}", whole.width, whole.height);
        for (i, (a, b)) in got.cost.iter().zip(&whole.cost).enumerate() {
            assert_eq!(
                a.to_bits(),
                b.to_bits(),
                "{label}: cost of cell {i}: {a} vs {b}"
            );
        }
        for (i, (a, b)) in got.class.iter().zip(&whole.class).enumerate() {
            assert_eq!(a, b, "{label}: class of cell {i}");
        }
        assert_eq!(got.layers.len(), whole.layers.len());
        for ((la, a), (lb, b)) in got.layers.iter().zip(&whole.layers) {
            assert_eq!(la, lb);
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert_eq!(x.to_bits(), y.to_bits(), "{label}: {la:?} of cell {i}");
            }
        }
        let (s, t) = (&m.stats, &whole.stats);
        assert_eq!(s.class_fractions, t.class_fractions, "{label}");
        assert_eq!(s.histogram, t.histogram, "{label}");
        assert_eq!(
            (s.cost_min, s.cost_max),
            (t.cost_min, t.cost_max),
            "{label}"
        );
        match (s.cost_mean, t.cost_mean) {
            (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-9 * b.abs(), "{label}: {a} vs {b}"),
            (a, b) => assert_eq!(a, b),
        }
        assert_eq!(m.warnings, whole.warnings, "{label}");
        assert_eq!(
            m.preview_png,
            crate::costmap::preview_png(&whole, 64),
            "{label}"
        );
        // Tiles went out in row-major order, each once.
        let nx = whole.width.div_ceil(tile);
        let want: Vec<(usize, usize)> = (0..got.order.len()).map(|k| (k % nx, k / nx)).collect();
        assert_eq!(got.order, want);
        whole
    }

    /// Rough ground with kerbs, pits, walled pockets crossing tile
    /// borders and nodata holes (some on tile borders).
    fn terrain(w: usize, h: usize, cell: f64, seed: u64) -> Dem {
        let mut s = Lcg(seed);
        let noise: Vec<f64> = (0..w * h).map(|_| s.next()).collect();
        let values = (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                let (x, y) = (c as f64 * cell, r as f64 * cell);
                let mut z = 100.0 + 0.08 * x + 0.05 * y + 0.6 * (x * 0.3).sin() * (y * 0.2).cos();
                z += 0.02 * noise[i];
                // Square walls 0.5 m high around pockets of several sizes.
                for (c0, r0, side) in [(5, 5, 9), (14, 9, 6), (30, 3, 14), (2, 28, 5)] {
                    let inside = |v: usize, o: usize| v >= o && v <= o + side;
                    if inside(c, c0)
                        && inside(r, r0)
                        && (c == c0 || c == c0 + side || r == r0 || r == r0 + side)
                    {
                        z += 0.5;
                    }
                }
                if (noise[i] > 0.995 && c > 22)
                    || (c == 16 && r % 7 == 3)
                    || (r == 16 && c % 5 == 1)
                {
                    f64::NAN
                } else {
                    z
                }
            })
            .collect();
        dem(
            w,
            h,
            values,
            north_up(400_000.0, 4_500_000.0, cell, cell),
            false,
        )
    }

    #[test]
    fn tiles_equal_the_whole_grid_on_rough_ground_with_pockets_and_holes() {
        let v = VehiclePreset::UGo.vehicle();
        let d = terrain(47, 39, 0.1, 7);
        let o = CostmapOptions {
            layers: Layer::ALL
                .into_iter()
                .filter(|&l| l != Layer::Landcover)
                .collect(),
            roughness: Some(crate::costmap::RoughnessOptions {
                max_m: 0.05,
                weight: 2.0,
            }),
            negative_steps: Some(crate::costmap::NegativeStepOptions {
                max_depth_m: Some(0.1),
                radius_m: Some(0.3),
            }),
            min_region_area_m2: Some(1.0),
            ..Default::default()
        };
        // Tiles of 1 cell, smaller than every halo, of odd sizes, of the
        // whole grid and beyond.
        for tile in [1, 3, 7, 16, 23, 47, 100] {
            let whole = assert_same(&d, &v, &o, tile);
            assert!(
                whole.stats.class_fractions.enclosed > 0.0,
                "{:?}",
                whole.stats.class_fractions
            );
            assert!(whole.stats.class_fractions.step > 0.0);
        }
    }

    #[test]
    fn tiles_equal_the_whole_grid_in_every_mode_and_resampled() {
        let v = VehiclePreset::UGo.vehicle();
        let d = terrain(60, 44, 0.05, 11);
        let modes = [
            CostmapOptions::default(),
            CostmapOptions {
                inflation: InflationMode::Blur,
                step_mode: StepMode::Neighbours,
                min_region_area_m2: Some(0.3),
                ..Default::default()
            },
            CostmapOptions {
                resolution_m: Some(0.1),
                smoothing_sigma_m: Some(0.0),
                layers: vec![Layer::Slope, Layer::Inflation],
                ..Default::default()
            },
            CostmapOptions {
                resolution_m: Some(0.15),
                inflation_sigma_m: Some(0.05),
                ..Default::default()
            },
        ];
        for o in &modes {
            for tile in [4, 9, 17] {
                assert_same(&d, &v, o, tile);
            }
        }
    }

    #[test]
    fn a_geographic_dem_tiles_like_the_whole_grid() {
        let v = VehiclePreset::UGo.vehicle();
        let mut d = terrain(40, 36, 1.0, 3);
        // ~0.1 m cells at 60° N.
        d = dem(40, 36, d.values, north_up(10.0, 60.0, 1.8e-6, 0.9e-6), true);
        for tile in [5, 12] {
            assert_same(&d, &v, &CostmapOptions::default(), tile);
        }
    }

    #[test]
    fn random_dems_and_tile_sizes() {
        let v = VehiclePreset::UGo.vehicle();
        let mut s = Lcg(0x7117ed);
        for case in 0..16 {
            let w = 3 + (s.next() * 70.0) as usize;
            let h = 3 + (s.next() * 70.0) as usize;
            let cell = 0.05 + 0.1 * s.next();
            let d = terrain(w, h, cell, case);
            let tile = 1 + (s.next() * 30.0) as usize;
            // Inflation reaching from 1 to ~20 cells, so that halos are
            // both wider and narrower than the grid.
            let o = CostmapOptions {
                min_region_area_m2: Some(0.5 + 3.0 * s.next()),
                inflation_sigma_m: Some(cell * (0.2 + 2.0 * s.next())),
                inflation: [InflationMode::Distance, InflationMode::Blur][case as usize % 2],
                pca_radius_m: Some(cell * (1.0 + 2.0 * s.next())),
                smoothing_sigma_m: Some(cell * s.next()),
                ..Default::default()
            };
            assert_same(&d, &v, &o, tile);
        }
    }

    #[test]
    fn cancelling_stops_the_run_and_bad_options_are_refused() {
        let v = VehiclePreset::UGo.vehicle();
        let d = terrain(30, 30, 0.1, 5);
        let opts = TiledOptions {
            tile: 8,
            scratch_dir: std::env::temp_dir(),
            preview_max_side: 16,
        };
        struct Nothing;
        impl TileSink for Nothing {
            fn begin(&mut self, _: &MapHeader) -> io::Result<()> {
                Ok(())
            }

            fn tile(&mut self, _: &CostmapTile<'_>) -> io::Result<()> {
                Ok(())
            }
        }
        let stop = |stage: Stage, _: f64| stage != Stage::Regions;
        let src = DemWindows::new(&d);
        let r = build_costmap_tiled(
            &src,
            &v,
            &CostmapOptions::default(),
            None,
            &opts,
            &stop,
            &mut Nothing,
        );
        assert!(
            matches!(r, Err(TiledError::Costmap(CostmapError::Cancelled))),
            "{r:?}"
        );
        let bad = CostmapOptions {
            resolution_m: Some(0.01),
            ..Default::default()
        };
        let r = build_costmap_tiled(&src, &v, &bad, None, &opts, &quiet(), &mut Nothing);
        match r {
            Err(TiledError::Costmap(CostmapError::Invalid(i))) => {
                assert_eq!(i[0].pointer, "/options/resolution_m")
            }
            other => panic!("{other:?}"),
        }
        // A sink that fails: the error says so.
        struct Full;
        impl TileSink for Full {
            fn begin(&mut self, _: &MapHeader) -> io::Result<()> {
                Ok(())
            }

            fn tile(&mut self, _: &CostmapTile<'_>) -> io::Result<()> {
                Err(io::Error::other("disk full"))
            }
        }
        let r = build_costmap_tiled(
            &src,
            &v,
            &CostmapOptions::default(),
            None,
            &opts,
            &quiet(),
            &mut Full,
        );
        assert!(
            matches!(&r, Err(TiledError::Write(e)) if e.to_string() == "disk full"),
            "{r:?}"
        );
    }
}
