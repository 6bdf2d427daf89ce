//! The costmap pipeline (SPEC §4.2) run tile by tile over a raster read a
//! window at a time ([`RasterWindows`]), so a DEM larger than memory can
//! be mapped: memory is bounded by the tile size, never the map's.
//!
//! Every neighbourhood operation reaches a bounded distance ([`Halos`]),
//! so each tile is read with a halo that wide and its core comes out as
//! the whole-grid run's ([`super::build_costmap`]), bit for bit. The
//! enclosed-pocket fill is global, so the run is the stages of
//! [`super::tile_stages`] one after the other, in one process:
//!
//! 1. per tile, the surface (resampling, steps, normals, optional
//!    obstacle layers) and the classes before the fill, written to a
//!    scratch file ([`ClassStore`], a byte per cell), and the edges of
//!    the tile's traversable regions; then the edges are joined
//!    (union–find, [`super::region_join`]);
//! 2. per tile, the labels again, and the pockets to fill are filled in
//!    the scratch file;
//! 3. per tile, the surface again (cheaper than keeping it on disk), the
//!    inflation from the final classes of the tile and its inflation halo,
//!    the costs; the tile goes to a [`TileSink`] (e.g. a tiled GeoTIFF)
//!    and its parts of the statistics and the preview are merged.
//!
//! Resampling is tiled exactly (a working cell is a whole block of DEM
//! cells), geographic DEMs too (each row's cell size is the whole grid's);
//! the land-cover layer samples each cell from the grid's own transform.

use std::io;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use super::class_store::ClassStore;
use super::halo::Halos;
use super::progress::Monotone;
use super::region_join::JoinError;
use super::tile_bytes::PieceError;
use super::tile_stages::TilePlan;
use super::{
    CostmapError, CostmapOptions, CostmapStats, Layer, Progress, ResolvedParams, Stage, Vehicle,
};
use crate::terrain::{Crs, Dem, GeoTransform, RasterWindows, TerrainError};

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

/// Why a tiled run (or one of its stages) failed.
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
    /// A stage's piece (edges, fill, tally, preview) whose bytes are
    /// damaged.
    #[error("a tile's piece is damaged: {0}")]
    Piece(#[from] PieceError),
    /// A tile index beyond the plan's tiles.
    #[error("tile {k} is not one of the costmap's {count} tiles")]
    NoSuchTile { k: usize, count: usize },
    /// Inputs of a stage that do not fit the plan (a DEM of another size,
    /// a class window or a part of another tile, parts out of order).
    #[error("a stage's input does not fit the costmap's plan: {0}")]
    Mismatch(String),
    /// Reading stored classes failed (a [`super::ClassWindows`] of the
    /// caller's).
    #[error("reading stored classes: {0}")]
    Stored(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl TiledCostmap {
    /// The legend of its preview (as [`super::legend_svg`] draws a whole
    /// costmap's).
    pub fn legend_svg(&self) -> String {
        super::legend_svg_of(&self.stats, &self.vehicle.name)
    }
}

/// Builds the costmap of the DEM `src` tile by tile, giving each finished
/// tile to `sink` in row-major tile order; the same costs, classes and
/// layers as [`super::build_costmap`] of the whole DEM, and the same
/// statistics but for the order the mean's sum is added in. The stages
/// of [`TilePlan`] in one process, so bit for bit what they give run as
/// jobs anywhere.
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
    let plan = TilePlan::new(src.grid(), vehicle, options, landcover, tiled.tile)?
        .with_preview_max_side(tiled.preview_max_side);
    let cancel = AtomicBool::new(false);
    // Reports each tile as it begins; a refusal stops the run there.
    let report = |stage: Stage, done: f64| {
        if !progress.report(stage, done) {
            cancel.store(true, Ordering::Relaxed);
        }
        if cancel.load(Ordering::Relaxed) {
            Err(TiledError::Costmap(CostmapError::Cancelled))
        } else {
            Ok(())
        }
    };
    let n = plan.tile_count();
    let header = plan.header();
    let mut store = ClassStore::create(&tiled.scratch_dir, header.width, header.height)
        .map_err(TiledError::Scratch)?;

    // Stage 1: classes before the fill, the regions' edges; stage 2, the
    // join.
    let mut join = plan.edge_join();
    for k in 0..n {
        report(Stage::Normals, 0.5 * k as f64 / n as f64)?;
        let c = plan.classify(src, landcover, k, &cancel)?;
        let t = plan.tile(k)?;
        store
            .write(t.col0, t.row0, t.width, t.height, &c.core)
            .map_err(TiledError::Scratch)?;
        join.add(k, c.edges)?;
    }
    let fill = join.join()?;

    // Stage 3: the pockets filled, in place: tile k reads the ring of
    // tiles already filled, which labels the same (see
    // [`TilePlan::fill`]).
    for k in 0..n {
        report(Stage::Regions, 0.5 + 0.1 * k as f64 / n as f64)?;
        let part = fill.tile(k).ok_or(JoinError::Missing(k))?;
        let (core, filled) = plan.fill_counted(k, &store, part)?;
        if filled > 0 {
            let t = plan.tile(k)?;
            store
                .write(t.col0, t.row0, t.width, t.height, &core)
                .map_err(TiledError::Scratch)?;
        }
    }
    drop(fill);

    // Stage 4: inflation and costs, the tiles out in order; stage 5, the
    // parts merged in the same order.
    sink.begin(&header).map_err(TiledError::Write)?;
    let mut merge = plan.merge();
    for k in 0..n {
        report(Stage::Cost, 0.6 + 0.4 * k as f64 / n as f64)?;
        let tile = plan.cost(src, landcover, &store, k, &cancel)?;
        sink.tile(&tile.view()).map_err(TiledError::Write)?;
        merge.add(k, &tile.tally, &tile.preview)?;
    }
    report(Stage::Cost, 1.0)?;
    merge.finish()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::costmap::{Costmap, InflationMode, StepMode, VehiclePreset, build_costmap};
    use crate::terrain::DemWindows;
    use crate::terrain::test_support::{dem, north_up};
    use crate::test_rng::Lcg;

    /// Collects the tiles into whole grids.
    pub(crate) struct Assemble {
        width: usize,
        pub(crate) cost: Vec<f32>,
        pub(crate) class: Vec<u8>,
        pub(crate) layers: Vec<(Layer, Vec<f32>)>,
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

    pub(crate) fn quiet() -> impl Progress {
        |_: Stage, _: f64| true
    }

    pub(crate) fn tiled(
        d: &Dem,
        v: &Vehicle,
        o: &CostmapOptions,
        tile: usize,
    ) -> (TiledCostmap, Assemble) {
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
    pub(crate) fn assert_same(d: &Dem, v: &Vehicle, o: &CostmapOptions, tile: usize) -> Costmap {
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
    pub(crate) fn terrain(w: usize, h: usize, cell: f64, seed: u64) -> Dem {
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
