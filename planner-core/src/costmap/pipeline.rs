//! The whole costmap pipeline (SPEC §4.2 steps 1–8), from a DEM to costs
//! and classes, with progress and cancellation.

use std::borrow::Cow;
use std::io::{Seek, Write};

use rayon::prelude::*;

use super::bands::{Holes, Limits, Surface, surface};
use super::grid::{WorkGrid, work_grid};
use super::inflate::inflation;
use super::landcover::landcover_costs;
use super::normals::NormalsJob;
pub use super::params::check_against_dem;
use super::params::{negative_radius, resolve};
use super::progress::{Monotone, Ticker};
use super::regions::fill_enclosed;
use super::smooth::Smoother;
use super::stats::{CostmapStats, costmap_stats};
use super::steps::depth_below_plane;
use super::{
    Class, Costmap, CostmapError, CostmapOptions, Layer, Progress, ResolvedParams, Stage, StepMode,
    Vehicle,
};
use crate::geo::Issue;
use crate::terrain::Dem;
use crate::terrain::geotiff::{Band, BandData, Page, write_geotiff};

/// Cells per parallel task of the whole-grid passes.
const CHUNK: usize = 1 << 14;

/// The nodata value of the GeoTIFF's class band: unknown cells (no
/// height, or not judged), which `preview.png` leaves transparent too.
pub const CLASS_NODATA: u8 = Class::Unknown as u8;

/// Slope costs span [1, SLOPE_COST_MAX] (thesis §3.6.3: Zcomp remapped
/// from [cos(max_slope), 1] to [10, 1]).
pub const SLOPE_COST_MAX: f64 = 10.0;

/// Builds the costmap of `dem` for `vehicle`. `landcover`: the class
/// raster when `options.landcover` is set.
pub fn build_costmap(
    dem: &Dem,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
    progress: &dyn Progress,
) -> Result<Costmap, CostmapError> {
    run(Cow::Borrowed(dem), vehicle, options, landcover, progress)
}

/// [`build_costmap`] taking the DEM by value, so its heights become the
/// working grid without a copy (for the largest DEMs).
pub fn build_costmap_owned(
    dem: Dem,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
    progress: &dyn Progress,
) -> Result<Costmap, CostmapError> {
    run(Cow::Owned(dem), vehicle, options, landcover, progress)
}

fn run(
    dem: Cow<'_, Dem>,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
    progress: &dyn Progress,
) -> Result<Costmap, CostmapError> {
    let progress = &Monotone::new(progress);
    check_request(&dem, vehicle, options, landcover)?;
    let params = resolve(&dem, vehicle, options);
    let crs = dem.crs.clone();
    let mut warnings = Vec::new();

    let grid = resample(dem, vehicle, options, &params, progress, &mut warnings)?;
    let (w, h) = (grid.width, grid.height);
    let cell = grid.centre_size_m();
    // Steps are judged on the heights before smoothing (smoothing would
    // shave them), normals after; both band by band in one pass.
    let surface = surface_and_classes(&grid, vehicle, options, &params, progress)?;
    let negative = negative_steps(&grid, vehicle, options, progress)?;
    let transform = grid.transform;
    // Later grids take the heights' place.
    drop(grid);
    let landcover_cost = match (&options.landcover, landcover) {
        (Some(table), Some(raster)) => {
            Ticker::new(progress, Stage::Layers, 1).check()?;
            Some(landcover_costs(raster, table, w, h, &transform, crs.epsg)?)
        }
        _ => None,
    };
    let layers = CellLayers {
        step: surface.step,
        negative,
        zcomp: surface.zcomp,
        roughness: surface.roughness,
        landcover_cost,
    };
    let mut class = surface.class;
    add_layer_obstacles(&mut class, &layers);
    fill_pockets(&mut class, [w, h], cell, &params, progress)?;
    let obstacle = obstacles(&class, &surface.holes, w);
    let inflated = inflate(obstacle, [w, h], cell, &params, progress)?;
    let (cost, inflation_layer) = costs(inflated, &class, &layers, vehicle, options, progress)?;

    let stats = statistics(&cost, &class, [w, h], cell, vehicle, options);
    if stats.class_fractions.traversable == 0.0 {
        warnings.push(
            "no cell is traversable for this vehicle: every cell is an obstacle or unknown"
                .to_string(),
        );
    }
    let layers = layer_rasters(&layers, inflation_layer, options);
    Ok(Costmap {
        width: w,
        height: h,
        transform,
        crs,
        vehicle: vehicle.clone(),
        params,
        cost,
        class,
        layers,
        stats,
        warnings,
    })
}

/// The options' own checks, then those against the DEM, and a land-cover
/// raster when the options ask for one; every fault at once.
pub(super) fn check_request(
    dem: &Dem,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
) -> Result<(), CostmapError> {
    let mut issues = options.validate("/options");
    if issues.is_empty() {
        issues = check_against_dem(dem, vehicle, options, "/options");
    }
    if options.landcover.is_some() && landcover.is_none() {
        issues.push(Issue::new(
            "/options/landcover/source",
            "no land-cover raster was given",
        ));
    }
    if issues.is_empty() {
        Ok(())
    } else {
        Err(CostmapError::Invalid(issues))
    }
}

/// The per-cell grids of the working grid that classes and costs are
/// made of (row-major).
pub(super) struct CellLayers {
    /// Step height (SPEC §4.2 step 4), when kept as a layer.
    pub step: Option<Vec<f32>>,
    /// Depth below the local plane, and the deepest allowed (negative
    /// steps, optional).
    pub negative: Option<(Vec<f32>, f64)>,
    /// |n_z| of the surface normal (step 2).
    pub zcomp: Vec<f32>,
    /// Plane-fit residual (optional).
    pub roughness: Option<Vec<f32>>,
    /// Land-cover class costs, `INFINITY` where lethal (optional).
    pub landcover_cost: Option<Vec<f32>>,
}

/// SPEC §4.2 step 1: the working grid, DEM cells averaged in blocks of the
/// resample factor; warnings for a grid too coarse for the vehicle or a
/// resolution taken other than asked.
fn resample(
    dem: Cow<'_, Dem>,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    params: &ResolvedParams,
    progress: &dyn Progress,
    warnings: &mut Vec<String>,
) -> Result<WorkGrid, CostmapError> {
    Ticker::new(progress, Stage::Resample, 1).check()?;
    let grid = work_grid(dem, params.resample_factor);
    resample_warnings(vehicle, options, params, grid.centre_size_m(), warnings);
    Ok(grid)
}

/// The warnings of step 1: a grid too coarse for the vehicle (cells of
/// `centre_m` at its centre), a resolution taken other than asked.
pub(super) fn resample_warnings(
    vehicle: &Vehicle,
    options: &CostmapOptions,
    params: &ResolvedParams,
    centre_m: [f64; 2],
    warnings: &mut Vec<String>,
) {
    coarse_warnings(params, vehicle, centre_m, warnings);
    if let Some(r) = options.resolution_m {
        let [ax, ay] = params.resolution_m;
        if (ax - r).abs() > 0.01 * r || (ay - r).abs() > 0.01 * r {
            let [fx, fy] = params.resample_factor;
            warnings.push(format!(
                "resolution_m {r} m was taken as {ax:.3} × {ay:.3} m: whole blocks of {fx} × {fy} \
                 DEM cells are averaged"
            ));
        }
    }
}

/// SPEC §4.2 steps 2–4 and the union of step 5 for the step and slope
/// grids (and the roughness when asked for): one pass over the heights.
fn surface_and_classes(
    grid: &WorkGrid,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    params: &ResolvedParams,
    progress: &dyn Progress,
) -> Result<Surface, CostmapError> {
    let heights = Heights {
        z: &grid.z,
        width: grid.width,
        height: grid.height,
        row_size_m: &grid.row_size_m,
        centre_m: grid.centre_size_m(),
    };
    surface_of(&heights, vehicle, options, params, progress)
}

/// Heights of the working grid or of a window of it: `row_size_m` holds
/// the window's rows, `centre_m` the whole grid's centre cell (what the
/// kernels in cells are derived from).
pub(super) struct Heights<'a> {
    pub z: &'a [f64],
    pub width: usize,
    pub height: usize,
    pub row_size_m: &'a [[f64; 2]],
    pub centre_m: [f64; 2],
}

/// [`surface_and_classes`] of any heights.
pub(super) fn surface_of(
    grid: &Heights<'_>,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    params: &ResolvedParams,
    progress: &dyn Progress,
) -> Result<Surface, CostmapError> {
    let [sx, sy] = grid.centre_m;
    // Stage::Steps is reported as begun; the pass ticks as the normals.
    Ticker::new(progress, Stage::Steps, 1).check()?;
    let ticker = Ticker::new(progress, Stage::Normals, grid.height);
    let smoother = Smoother::new(
        params.smoothing_sigma_m / sx,
        params.smoothing_sigma_m / sy,
        3.0,
    );
    let normals = NormalsJob::new(
        grid.z,
        grid.width,
        grid.height,
        grid.row_size_m,
        params.pca_radius_m,
        smoother.as_ref(),
    );
    let limits = Limits {
        max_step_m: vehicle.max_step_m,
        cos_max: vehicle.max_slope_deg.to_radians().cos(),
        max_roughness_m: options.roughness.as_ref().map(|o| o.max_m),
    };
    let keep_step = options.layers.contains(&Layer::Step);
    surface(&normals, params.step_mode, limits, keep_step, &ticker)
}

/// The depth below the local plane and the deepest allowed, when negative
/// steps are asked for.
fn negative_steps(
    grid: &WorkGrid,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    progress: &dyn Progress,
) -> Result<Option<(Vec<f32>, f64)>, CostmapError> {
    let heights = Heights {
        z: &grid.z,
        width: grid.width,
        height: grid.height,
        row_size_m: &grid.row_size_m,
        centre_m: grid.centre_size_m(),
    };
    negative_steps_of(&heights, vehicle, options, progress)
}

/// [`negative_steps`] of any heights.
pub(super) fn negative_steps_of(
    grid: &Heights<'_>,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    progress: &dyn Progress,
) -> Result<Option<(Vec<f32>, f64)>, CostmapError> {
    let Some(n) = &options.negative_steps else {
        return Ok(None);
    };
    let (w, h) = (grid.width, grid.height);
    let ticker = Ticker::new(progress, Stage::Layers, h);
    let r = negative_radius(vehicle, n.radius_m);
    Ok(Some((
        depth_below_plane(grid.z, w, h, grid.row_size_m, r, &ticker)?,
        n.max_depth_m.unwrap_or(vehicle.max_step_m),
    )))
}

/// SPEC §4.2 step 5 (first part), the optional obstacle layers: ditches
/// deeper than allowed are steps, lethal land cover an "other" obstacle
/// where the cell would be traversable (precedence step > slope > other;
/// unknown cells stay unknown).
pub(super) fn add_layer_obstacles(class: &mut [u8], layers: &CellLayers) {
    let (unknown, trav) = (Class::Unknown as u8, Class::Traversable as u8);
    if let Some((depth, max)) = &layers.negative {
        class
            .par_chunks_mut(CHUNK)
            .zip(depth.par_chunks(CHUNK))
            .for_each(|(ks, ds)| {
                for (k, &d) in ks.iter_mut().zip(ds) {
                    if *k != unknown && f64::from(d) > *max {
                        *k = Class::Step as u8;
                    }
                }
            });
    }
    if let Some(l) = &layers.landcover_cost {
        class
            .par_chunks_mut(CHUNK)
            .zip(l.par_chunks(CHUNK))
            .for_each(|(ks, ls)| {
                for (k, &c) in ks.iter_mut().zip(ls) {
                    if *k == trav && c == f32::INFINITY {
                        *k = Class::Other as u8;
                    }
                }
            });
    }
}

/// SPEC §4.2 step 5 (second part): traversable pockets enclosed by
/// obstacles and smaller than the minimum region become obstacles.
fn fill_pockets(
    class: &mut [u8],
    [w, h]: [usize; 2],
    [sx, sy]: [f64; 2],
    params: &ResolvedParams,
    progress: &dyn Progress,
) -> Result<(), CostmapError> {
    let ticker = Ticker::new(progress, Stage::Regions, 1);
    fill_enclosed(class, w, h, params.min_region_area_m2 / (sx * sy));
    ticker.check()
}

/// The cells inflation grows from: obstacles and cells without a height
/// (`holes`: unknown ground is no safer than an obstacle), not the border
/// ring, which is unknown only because it cannot be judged.
fn obstacles(class: &[u8], holes: &Holes, width: usize) -> Vec<bool> {
    let mut obstacle = crate::buffer::filled(class.len(), false);
    obstacle
        .par_chunks_mut(width.max(1))
        .zip(class.par_chunks(width.max(1)))
        .enumerate()
        .for_each(|(r, (os, ks))| {
            holes.row_into(r, os);
            for (o, &k) in os.iter_mut().zip(ks) {
                *o |= Class::from_code(k).is_some_and(Class::is_obstacle);
            }
        });
    obstacle
}

/// SPEC §4.2 step 6: inflation from the `obstacle` cells.
fn inflate(
    obstacle: Vec<bool>,
    [w, h]: [usize; 2],
    cell: [f64; 2],
    params: &ResolvedParams,
    progress: &dyn Progress,
) -> Result<Vec<f32>, CostmapError> {
    let ticker = Ticker::new(progress, Stage::Inflate, 1);
    let inflated = inflation(
        &obstacle,
        w,
        h,
        cell,
        params.inflation_sigma_m,
        params.inflation,
    );
    drop(obstacle);
    ticker.check()?;
    Ok(inflated)
}

/// SPEC §4.2 steps 7–8: the slope cost and the weighted sum with the
/// inflation (plus the optional costs) on traversable cells, NaN
/// elsewhere; in place of the inflation, which is also returned when kept
/// as a layer.
pub(super) fn costs(
    inflated: Vec<f32>,
    class: &[u8],
    layers: &CellLayers,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    progress: &dyn Progress,
) -> Result<(Vec<f32>, Option<Vec<f32>>), CostmapError> {
    let ticker = Ticker::new(progress, Stage::Cost, 1);
    let cos_max = vehicle.max_slope_deg.to_radians().cos();
    let slope_span = 1.0 - cos_max;
    let rough_opts = options.roughness.as_ref();
    let CellLayers {
        zcomp,
        roughness,
        landcover_cost,
        ..
    } = layers;
    // The costs take the inflation's place (one grid less to allocate).
    let inflation_layer = options
        .layers
        .contains(&Layer::Inflation)
        .then(|| inflated.clone());
    let mut cost = inflated;
    let weights = [cos_max, slope_span, vehicle.w_infl, vehicle.w_slope];
    if roughness.is_none() && landcover_cost.is_none() {
        // No optional cost: a loop without per-cell option checks.
        cost.par_chunks_mut(CHUNK)
            .zip(class.par_chunks(CHUNK))
            .zip(zcomp.par_chunks(CHUNK))
            .for_each(|((cs, ks), zs)| plain_costs(cs, ks, zs, weights));
    } else {
        cost.par_iter_mut().enumerate().for_each(|(i, c)| {
            if class[i] != Class::Traversable as u8 {
                *c = f32::NAN;
                return;
            }
            let mut v = traversing_cost(zcomp[i], *c, weights);
            if let (Some(r), Some(o)) = (roughness, rough_opts) {
                v += o.weight * (f64::from(r[i]) / o.max_m).min(1.0);
            }
            if let Some(l) = landcover_cost {
                let lc = l[i];
                if lc.is_finite() {
                    v += f64::from(lc);
                }
            }
            *c = v as f32;
        });
    }
    ticker.check()?;
    Ok((cost, inflation_layer))
}

/// The statistics, over costs spanning [w_slope, the highest cost the
/// weights allow].
fn statistics(
    cost: &[f32],
    class: &[u8],
    [w, h]: [usize; 2],
    [sx, sy]: [f64; 2],
    vehicle: &Vehicle,
    options: &CostmapOptions,
) -> CostmapStats {
    costmap_stats(w, h, cost, class, sx * sy, cost_range(vehicle, options))
}

/// The range of costs the weights allow: [w_slope, the highest].
pub(super) fn cost_range(vehicle: &Vehicle, options: &CostmapOptions) -> [f64; 2] {
    let mut cost_hi = vehicle.w_infl + vehicle.w_slope * SLOPE_COST_MAX;
    if let Some(o) = &options.roughness {
        cost_hi += o.weight;
    }
    if let Some(l) = &options.landcover {
        let most = l.classes.iter().filter(|c| !c.lethal).map(|c| c.cost).fold(
            if l.unlisted_lethal {
                0.0
            } else {
                l.unlisted_cost
            },
            f64::max,
        );
        cost_hi += most;
    }
    [vehicle.w_slope, cost_hi]
}

/// The per-layer rasters asked for, in [`Layer::ALL`] order.
pub(super) fn layer_rasters(
    layers: &CellLayers,
    inflation_layer: Option<Vec<f32>>,
    options: &CostmapOptions,
) -> Vec<(Layer, Vec<f32>)> {
    let wanted = |l: Layer| options.layers.contains(&l);
    let mut out = Vec::new();
    for layer in Layer::ALL {
        if !wanted(layer) {
            continue;
        }
        let data = match layer {
            Layer::Slope => layers
                .zcomp
                .par_iter()
                .map(|&z| f64::from(z).min(1.0).acos().to_degrees() as f32)
                .collect(),
            Layer::Zcomp => layers.zcomp.clone(),
            Layer::Step => layers.step.clone().unwrap_or_default(),
            Layer::Inflation => inflation_layer.clone().unwrap_or_default(),
            Layer::Roughness => layers.roughness.clone().unwrap_or_default(),
            Layer::NegativeStep => layers
                .negative
                .as_ref()
                .map(|n| n.0.clone())
                .unwrap_or_default(),
            Layer::Landcover => layers
                .landcover_cost
                .as_ref()
                .map(|l| {
                    l.iter()
                        .map(|&v| if v.is_finite() { v } else { f32::NAN })
                        .collect()
                })
                .unwrap_or_default(),
        };
        out.push((layer, data));
    }
    out
}

/// SPEC §4.2 steps 7–8 before the optional layers: w_infl·inflation +
/// w_slope·(Zcomp remapped from [cos max_slope, 1] to [10, 1]).
#[inline(always)]
fn traversing_cost(zcomp: f32, inflation: f32, weights: [f64; 4]) -> f64 {
    let [cos_max, slope_span, w_infl, w_slope] = weights;
    let zc = f64::from(zcomp);
    let slope_cost = SLOPE_COST_MAX - (SLOPE_COST_MAX - 1.0) * (zc - cos_max) / slope_span;
    w_infl * f64::from(inflation) + w_slope * slope_cost
}

/// Costs without optional layers, in place of the inflation in `cost`
/// (NaN off the traversable cells), compiled also for AVX2 and picked at
/// run time.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx512bw+avx512dq+avx2+fma",
    "x86_64+avx2+fma",
    "x86_64+avx"
))]
fn plain_costs(cost: &mut [f32], class: &[u8], zcomp: &[f32], weights: [f64; 4]) {
    for ((c, &k), &zc) in cost.iter_mut().zip(class).zip(zcomp) {
        let v = traversing_cost(zc, *c, weights) as f32;
        *c = if k == Class::Traversable as u8 {
            v
        } else {
            f32::NAN
        };
    }
}

/// Warnings for a DEM too coarse to judge the vehicle on.
fn coarse_warnings(
    p: &ResolvedParams,
    vehicle: &Vehicle,
    [sx, sy]: [f64; 2],
    out: &mut Vec<String>,
) {
    let diagonal = sx.hypot(sy);
    let tan_max = vehicle.max_slope_deg.to_radians().tan();
    if p.step_mode == StepMode::Neighbours && diagonal * tan_max > vehicle.max_step_m {
        let limit = (vehicle.max_step_m / diagonal).atan().to_degrees();
        out.push(format!(
            "with step_mode neighbours on {sx:.3} × {sy:.3} m cells, every slope steeper than \
             {limit:.1}° (of the {}° allowed) is marked as a step: diagonal neighbours differ \
             by more than max_step {} m. step_mode residual judges steps against the local \
             slope instead",
            vehicle.max_slope_deg, vehicle.max_step_m
        ));
    }
    let size = vehicle.width_m.min(vehicle.length_m);
    if sx.max(sy) > size {
        out.push(format!(
            "the cells ({sx:.3} × {sy:.3} m) are larger than the vehicle ({} × {} m): \
             obstacles smaller than a cell are not seen, steps are heights {:.3} m apart \
             and slopes are averaged over {:.3} m; resample a finer DEM for a reliable map",
            vehicle.width_m,
            vehicle.length_m,
            sx.min(sy),
            2.0 * p.pca_radius_m
        ));
    }
}

/// The class band's metadata: `CLASS_<code>` and each class's name.
pub(super) fn class_names() -> Vec<(String, &'static str)> {
    Class::ALL
        .iter()
        .map(|c| (format!("CLASS_{}", *c as u8), c.name()))
        .collect()
}

impl Costmap {
    /// The costmap as a GeoTIFF in the DEM's CRS, in two pages (images; a
    /// TIFF image has one sample type and GDAL one nodata value per image):
    /// page 1, what GDAL opens as the file, the cost (Float32, unit `cost`,
    /// NaN = nodata on obstacles and unknown cells); page 2 (GDAL's
    /// `GTIFF_DIR:2:costmap.tif`) the class codes (Byte, no unit, nodata 0 =
    /// unknown, the codes' names in the band's metadata as `CLASS_<code>`).
    pub fn write_geotiff<W: Write + Seek>(&self, out: W) -> std::io::Result<()> {
        let names = class_names();
        let names: Vec<(&str, &str)> = names.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        write_geotiff(
            out,
            self.width,
            self.height,
            &self.transform,
            &self.crs,
            &[
                Page {
                    bands: &[Band::new("cost", "cost", BandData::F32(&self.cost))],
                    nodata: Some(f64::NAN),
                },
                Page {
                    bands: &[Band {
                        description: "class",
                        unit: "",
                        metadata: &names,
                        data: BandData::U8(&self.class),
                    }],
                    nodata: Some(f64::from(CLASS_NODATA)),
                },
            ],
        )
    }

    /// One kept layer as a single-band Float32 GeoTIFF (NaN nodata, the
    /// layer's name and unit on the band); `Ok(false)` (and nothing
    /// written) when that layer was not kept.
    pub fn write_layer_geotiff<W: Write + Seek>(
        &self,
        layer: Layer,
        out: W,
    ) -> std::io::Result<bool> {
        let Some((_, data)) = self.layers.iter().find(|(l, _)| *l == layer) else {
            return Ok(false);
        };
        write_geotiff(
            out,
            self.width,
            self.height,
            &self.transform,
            &self.crs,
            &[Page {
                bands: &[Band::new(layer.name(), layer.unit(), BandData::F32(data))],
                nodata: Some(f64::NAN),
            }],
        )?;
        Ok(true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{InflationMode, VehiclePreset};
    use crate::terrain::test_support::{dem, north_up};

    fn quiet() -> impl Progress {
        |_: Stage, _: f64| true
    }

    fn ugo() -> Vehicle {
        VehiclePreset::UGo.vehicle()
    }

    /// A `w`×`h` DEM of `cell` m cells in UTM with heights `f(x, y)`
    /// (metres east and north of the top-left cell centre).
    fn surface(w: usize, h: usize, cell: f64, f: impl Fn(f64, f64) -> f64) -> Dem {
        let values = (0..w * h)
            .map(|i| f((i % w) as f64 * cell, -((i / w) as f64) * cell))
            .collect();
        dem(
            w,
            h,
            values,
            north_up(400_000.0, 4_500_000.0, cell, cell),
            false,
        )
    }

    fn build(d: &Dem, v: &Vehicle, o: &CostmapOptions) -> Costmap {
        build_costmap(d, v, o, None, &quiet()).unwrap()
    }

    fn class_at(m: &Costmap, c: usize, r: usize) -> Class {
        Class::from_code(m.class[r * m.width + c]).unwrap()
    }

    /// Cells away from the border ring and the smoothing's reach.
    fn interior(m: &Costmap, margin: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
        (margin..m.height - margin)
            .flat_map(move |r| (margin..m.width - margin).map(move |c| (c, r)))
    }

    #[test]
    fn tilted_planes_on_both_sides_of_the_slope_limit() {
        let options = CostmapOptions {
            layers: vec![Layer::Zcomp, Layer::Slope],
            ..Default::default()
        };
        for (slope, want) in [
            (24.9, Class::Traversable),
            (25.1, Class::Slope),
            (5.0, Class::Traversable),
        ] {
            let g = f64::to_radians(slope).tan();
            let d = surface(16, 14, 0.5, |x, y| 300.0 + g * (0.6 * x + 0.8 * y));
            let m = build(&d, &ugo(), &options);
            let zc = &m.layers.iter().find(|l| l.0 == Layer::Zcomp).unwrap().1;
            for (c, r) in interior(&m, 3) {
                let i = r * m.width + c;
                assert!((f64::from(zc[i]) - f64::to_radians(slope).cos()).abs() < 1e-6);
                assert_eq!(class_at(&m, c, r), want, "{slope}° at {c},{r}");
            }
            // Border ring unknown.
            assert_eq!(class_at(&m, 0, 5), Class::Unknown);
            if want == Class::Traversable {
                // Slope cost: Zcomp remapped from [cos 25°, 1] to [10, 1];
                // no obstacle anywhere, so no inflation.
                let zc = f64::to_radians(slope).cos();
                let cos_max = f64::to_radians(25.0).cos();
                let expect = 10.0 - 9.0 * (zc - cos_max) / (1.0 - cos_max);
                let got = f64::from(m.cost[7 * m.width + 8]);
                assert!((got - expect).abs() < 1e-4, "{got} vs {expect}");
            } else {
                assert!(m.cost[7 * m.width + 8].is_nan());
            }
        }
    }

    #[test]
    fn a_step_is_an_obstacle_only_above_max_step() {
        for (rise, is_step) in [(0.14, false), (0.16, true)] {
            let d = surface(20, 12, 0.1, |x, y| {
                50.0 + 0.05 * y + if x > 0.95 { rise } else { 0.0 }
            });
            let m = build(&d, &ugo(), &CostmapOptions::default());
            for r in 2..10 {
                let classes: Vec<Class> = (1..19).map(|c| class_at(&m, c, r)).collect();
                let steps = classes.iter().filter(|&&k| k == Class::Step).count();
                assert_eq!(
                    steps,
                    if is_step { 2 } else { 0 },
                    "rise {rise}: {classes:?}"
                );
                if is_step {
                    assert_eq!(class_at(&m, 9, r), Class::Step);
                    assert_eq!(class_at(&m, 10, r), Class::Step);
                }
            }
        }
    }

    #[test]
    fn a_pit_is_a_step_obstacle_and_inflates_its_surroundings() {
        let d = surface(21, 21, 0.1, |x, y| {
            if (x - 1.0).abs() < 0.01 && (y + 1.0).abs() < 0.01 {
                9.5
            } else {
                10.0
            }
        });
        let m = build(&d, &ugo(), &CostmapOptions::default());
        assert_eq!(class_at(&m, 10, 10), Class::Step);
        assert_eq!(class_at(&m, 9, 10), Class::Step);
        assert_eq!(class_at(&m, 12, 10), Class::Traversable);
        // Inflation falls with the distance: nearer is dearer.
        let c = |col: usize| m.cost[10 * m.width + col];
        assert!(
            c(12) > c(14) && c(14) > c(17),
            "{} {} {}",
            c(12),
            c(14),
            c(17)
        );
    }

    #[test]
    fn a_one_cell_wall_costs_like_a_thick_one_in_distance_mode_only() {
        let thin = surface(40, 15, 0.1, |x, _| {
            if (x - 2.0).abs() < 0.01 { 11.0 } else { 10.0 }
        });
        // Thick: five cells of alternating height, so every one is a step
        // (a flat-topped wall would be traversable on top).
        let thick = surface(40, 15, 0.1, |x, _| {
            let col = (x / 0.1).round() as usize;
            if (16..=20).contains(&col) {
                11.0 + 0.5 * (col % 2) as f64
            } else {
                10.0
            }
        });
        for mode in [InflationMode::Distance, InflationMode::Blur] {
            let o = CostmapOptions {
                inflation: mode,
                smoothing_sigma_m: Some(0.0),
                ..Default::default()
            };
            let (a, b) = (build(&thin, &ugo(), &o), build(&thick, &ugo(), &o));
            // Wall (and step cells beside it) end at column 21; compare
            // traversable cells beyond.
            for col in 23..35 {
                let (x, y) = (a.cost[7 * 40 + col], b.cost[7 * 40 + col]);
                if mode == InflationMode::Distance {
                    assert!((x - y).abs() < 1e-5, "{mode:?} col {col}: {x} vs {y}");
                } else if col < 28 {
                    assert!(x < y - 0.1, "{mode:?} col {col}: {x} vs {y}");
                }
            }
        }
    }

    #[test]
    fn enclosed_plateaus_below_the_minimum_area_become_obstacles() {
        // A plateau 1 m high whose rim cells are steps; its inner 4 × 4 or
        // 12 × 12 cells of 0.5 m (4 m², 36 m²) are enclosed.
        for (side, min_area, want) in [
            (6, 10.0, Class::Enclosed),
            (14, 10.0, Class::Traversable),
            (6, 3.0, Class::Traversable),
        ] {
            let d = surface(30, 30, 0.5, |x, y| {
                let (c, r) = ((x / 0.5).round() as usize, (-y / 0.5).round() as usize);
                if (8..8 + side).contains(&c) && (8..8 + side).contains(&r) {
                    21.0
                } else {
                    20.0
                }
            });
            let o = CostmapOptions {
                min_region_area_m2: Some(min_area),
                ..Default::default()
            };
            let m = build(&d, &ugo(), &o);
            let mid = 8 + side / 2;
            assert_eq!(class_at(&m, mid, mid), want, "side {side}, min {min_area}");
            assert_eq!(class_at(&m, 8, mid), Class::Step);
            assert_eq!(class_at(&m, 3, 3), Class::Traversable);
        }
    }

    #[test]
    fn a_20_degree_plane_has_no_steps_at_any_resolution_in_residual_mode() {
        for cell in [0.1, 1.0, 5.0] {
            let g = f64::to_radians(20.0).tan();
            let d = surface(15, 15, cell, |x, y| 100.0 + g * (0.8 * x - 0.6 * y));
            let m = build(&d, &ugo(), &CostmapOptions::default());
            assert_eq!(m.stats.class_fractions.step, 0.0, "{cell} m");
            assert!(m.stats.class_fractions.traversable > 0.7, "{cell} m");
            // The literal test turns the whole plane into steps beyond
            // 0.15 / (cell·√2·tan 20°) … i.e. from ~0.3 m cells, and warns.
            let literal = CostmapOptions {
                step_mode: StepMode::Neighbours,
                ..Default::default()
            };
            let n = build(&d, &ugo(), &literal);
            if cell >= 1.0 {
                assert!(n.stats.class_fractions.step > 0.7);
                assert!(
                    n.warnings
                        .iter()
                        .any(|w| w.contains("step_mode neighbours"))
                );
            } else {
                assert_eq!(n.stats.class_fractions.step, 0.0);
            }
        }
    }

    #[test]
    fn geographic_dems_are_judged_in_metres() {
        // A plane rising 20 m per 92.6 m northwards (≈ 12.2°) on 3″ cells
        // at 45° N, where a degree of latitude is ≈ 111 132 m.
        let s = 3.0 / 3600.0;
        let (w, h) = (12, 12);
        let values = (0..w * h).map(|i| 1000.0 - 20.0 * (i / w) as f64).collect();
        let d = dem(w, h, values, north_up(6.0, 45.005, s, s), true);
        let o = CostmapOptions {
            layers: vec![Layer::Slope],
            smoothing_sigma_m: Some(0.0),
            ..Default::default()
        };
        let m = build(&d, &VehiclePreset::LargeSkidSteer.vehicle(), &o);
        let slope = &m.layers[0].1;
        let dy = m.params.resolution_m[1];
        let want = (20.0 / dy).atan().to_degrees();
        assert!(
            (f64::from(slope[6 * w + 6]) - want).abs() < 0.05,
            "{} vs {want}",
            slope[6 * w + 6]
        );
        assert!((want - 12.2).abs() < 0.1);
    }

    #[test]
    fn roughness_adds_cost_and_rejects_rough_ground() {
        // Flat ground with a patch of ±1 cm (mild) and ±6 cm (rough)
        // chequerboard noise (the rough one would trip the step test, so
        // max_step is raised for this test).
        let d = surface(40, 20, 0.1, |x, y| {
            let (c, r) = ((x / 0.1).round() as i64, (-y / 0.1).round() as i64);
            let sign = if (c + r) % 2 == 0 { 1.0 } else { -1.0 };
            match c {
                5..=14 => 10.0 + 0.01 * sign,
                25..=34 => 10.0 + 0.06 * sign,
                _ => 10.0,
            }
        });
        let mut v = ugo();
        v.max_step_m = 1.0;
        let o = CostmapOptions {
            roughness: Some(crate::costmap::RoughnessOptions {
                max_m: 0.03,
                weight: 5.0,
            }),
            smoothing_sigma_m: Some(0.0),
            layers: vec![Layer::Roughness],
            ..Default::default()
        };
        let m = build(&d, &v, &o);
        assert_eq!(class_at(&m, 30, 10), Class::Other, "rough patch");
        assert_eq!(class_at(&m, 10, 10), Class::Traversable, "mild patch");
        let rough = &m.layers[0].1;
        let mild = f64::from(rough[10 * 40 + 10]);
        assert!(mild > 0.005 && mild < 0.03, "{mild}");
        // The mild patch costs more than flat ground far from obstacles
        // by up to weight × roughness / max_m.
        let flat_far = f64::from(m.cost[10 * 40 + 2]);
        let patch = f64::from(m.cost[10 * 40 + 10]);
        assert!(patch > flat_far + 0.5, "{patch} vs {flat_far}");
    }

    #[test]
    fn negative_steps_find_a_ditch_the_step_test_misses() {
        // A ditch 0.25 m deep with 15° banks (1.9 m wide): no step and no
        // slope beyond the U-Go's limits, but its bottom lies well below
        // the plane of its surroundings.
        let tan15 = f64::to_radians(15.0).tan();
        let d = surface(40, 12, 0.1, |x, _| {
            let off = (x - 2.0).abs() * tan15;
            10.0 - (0.25 - off).clamp(0.0, 0.25)
        });
        let base = build(&d, &ugo(), &CostmapOptions::default());
        assert_eq!(base.stats.class_fractions.step, 0.0);
        assert_eq!(base.stats.class_fractions.slope, 0.0);
        let o = CostmapOptions {
            negative_steps: Some(crate::costmap::NegativeStepOptions {
                max_depth_m: Some(0.1),
                radius_m: Some(1.5),
            }),
            layers: vec![Layer::NegativeStep],
            ..Default::default()
        };
        let m = build(&d, &ugo(), &o);
        assert_eq!(class_at(&m, 20, 6), Class::Step, "ditch bottom");
        assert_eq!(class_at(&m, 5, 6), Class::Traversable);
        assert!(f64::from(m.layers[0].1[6 * 40 + 20]) > 0.1);
    }

    #[test]
    fn landcover_costs_and_lethal_classes() {
        use crate::costmap::{LandcoverClass, LandcoverOptions};
        let d = surface(20, 10, 1.0, |_, _| 5.0);
        // Class raster in the same CRS: left half 1 (grass, +2), right
        // half 7 (water, lethal), 2 m cells.
        let raster = dem(
            10,
            5,
            (0..50)
                .map(|i| if i % 10 < 5 { 1.0 } else { 7.0 })
                .collect(),
            north_up(400_000.0, 4_500_000.0, 2.0, 2.0),
            false,
        );
        let o = CostmapOptions {
            landcover: Some(LandcoverOptions {
                source: "classes.tif".into(),
                classes: vec![
                    LandcoverClass {
                        code: 1,
                        cost: 2.0,
                        lethal: false,
                        name: Some("grass".into()),
                    },
                    LandcoverClass {
                        code: 7,
                        cost: 0.0,
                        lethal: true,
                        name: Some("water".into()),
                    },
                ],
                unlisted_cost: 0.0,
                unlisted_lethal: false,
            }),
            layers: vec![Layer::Landcover],
            ..Default::default()
        };
        let m = build_costmap(&d, &ugo(), &o, Some(&raster), &quiet()).unwrap();
        assert_eq!(class_at(&m, 15, 5), Class::Other);
        assert_eq!(class_at(&m, 3, 5), Class::Traversable);
        let plain = build(&d, &ugo(), &CostmapOptions::default());
        let extra = m.cost[5 * 20 + 3] - plain.cost[5 * 20 + 3];
        assert!((extra - 2.0).abs() < 1e-4, "{extra}");
        assert_eq!(m.layers[0].1[5 * 20 + 3], 2.0);
        // Without the raster the run is refused, naming the source.
        match build_costmap(&d, &ugo(), &o, None, &quiet()) {
            Err(CostmapError::Invalid(i)) => assert_eq!(i[0].pointer, "/options/landcover/source"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn resampling_averages_blocks_and_keeps_the_georeferencing() {
        let d = surface(40, 30, 0.1, |x, _| 5.0 + 0.1 * x);
        let o = CostmapOptions {
            resolution_m: Some(0.5),
            ..Default::default()
        };
        let m = build(&d, &ugo(), &o);
        assert_eq!((m.width, m.height), (8, 6));
        assert_eq!(m.params.resample_factor, [5, 5]);
        assert!((m.transform.pixel_width - 0.5).abs() < 1e-12);
        assert_eq!(m.transform.origin_x, d.transform.origin_x);
        // Finer than the DEM is refused, naming the option.
        let bad = CostmapOptions {
            resolution_m: Some(0.01),
            ..Default::default()
        };
        match build_costmap(&d, &ugo(), &bad, None, &quiet()) {
            Err(CostmapError::Invalid(issues)) => {
                assert_eq!(issues[0].pointer, "/options/resolution_m");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_kerb_inside_a_resampled_block_is_still_a_step() {
        // The thesis' workflow: a 0.1 m DEM resampled to 0.5 m. A 0.3 m
        // kerb between DEM columns 51 and 52 falls inside block 10, whose
        // mean is in between: 0, 0.12, 0.3.
        for kerb_col in [50, 52, 54] {
            let d = surface(100, 40, 0.1, |x, _| {
                if (x / 0.1).round() as usize >= kerb_col {
                    0.3
                } else {
                    0.0
                }
            });
            let o = CostmapOptions {
                resolution_m: Some(0.5),
                ..Default::default()
            };
            let m = build(&d, &ugo(), &o);
            assert_eq!((m.width, m.height), (20, 8));
            for r in 2..6 {
                let steps = (2..18)
                    .filter(|&c| class_at(&m, c, r) == Class::Step)
                    .count();
                assert!(
                    (1..=3).contains(&steps),
                    "kerb at {kerb_col}, row {r}: {steps} step cells"
                );
                assert_eq!(class_at(&m, 3, r), Class::Traversable);
                assert_eq!(class_at(&m, 16, r), Class::Traversable);
            }
        }
    }

    #[test]
    fn dem_faults_name_the_dem_or_the_option() {
        let p = quiet();
        // Too small: the DEM itself, or the resolution that shrank it.
        let tiny = surface(2, 2, 1.0, |_, _| 0.0);
        match build_costmap(&tiny, &ugo(), &CostmapOptions::default(), None, &p) {
            Err(CostmapError::Invalid(i)) => assert_eq!(i[0].pointer, "/dem_id"),
            other => panic!("{other:?}"),
        }
        let small = surface(8, 8, 1.0, |_, _| 0.0);
        let coarse = CostmapOptions {
            resolution_m: Some(4.0),
            ..Default::default()
        };
        match build_costmap(&small, &ugo(), &coarse, None, &p) {
            Err(CostmapError::Invalid(i)) => assert_eq!(i[0].pointer, "/options/resolution_m"),
            other => panic!("{other:?}"),
        }
        // A geographic DEM reaching the pole: cells without width.
        let pole = dem(20, 11, vec![0.0; 220], north_up(0.0, 91.0, 1.0, 1.0), true);
        match build_costmap(&pole, &ugo(), &CostmapOptions::default(), None, &p) {
            Err(CostmapError::Invalid(i)) => {
                assert_eq!(i[0].pointer, "/dem_id");
                assert!(i[0].message.contains("pole"), "{}", i[0].message);
            }
            other => panic!("{other:?}"),
        }
        // A blur wider than 50 cells is refused; the distance mode is not.
        let flat = surface(10, 10, 1.0, |_, _| 0.0);
        let wide = |inflation| CostmapOptions {
            inflation,
            inflation_sigma_m: Some(500.0),
            ..Default::default()
        };
        match build_costmap(&flat, &ugo(), &wide(InflationMode::Blur), None, &p) {
            Err(CostmapError::Invalid(i)) => assert_eq!(i[0].pointer, "/options/inflation_sigma_m"),
            other => panic!("{other:?}"),
        }
        assert!(build_costmap(&flat, &ugo(), &wide(InflationMode::Distance), None, &p).is_ok());
        // A resolution rounded to whole blocks is said so.
        let m = build(
            &small,
            &ugo(),
            &CostmapOptions {
                resolution_m: Some(1.4),
                ..Default::default()
            },
        );
        assert!(
            m.warnings.iter().any(|w| w.contains("was taken as 1.000")),
            "{:?}",
            m.warnings
        );
    }

    #[test]
    fn progress_rises_and_cancelling_stops_the_run() {
        let d = surface(30, 30, 0.2, |x, y| x * 0.1 + y * 0.05);
        let last = std::sync::Mutex::new(Vec::new());
        let record = |stage: Stage, done: f64| {
            last.lock().unwrap().push((stage, done));
            true
        };
        // With the ditch layer too, whose stage runs between the others.
        let ditches = CostmapOptions {
            negative_steps: Some(crate::costmap::NegativeStepOptions {
                max_depth_m: None,
                radius_m: None,
            }),
            ..Default::default()
        };
        for options in [CostmapOptions::default(), ditches] {
            last.lock().unwrap().clear();
            build_costmap(&d, &ugo(), &options, None, &record).unwrap();
            let seen = last.lock().unwrap().clone();
            assert!(seen.iter().all(|&(_, f)| (0.0..=1.0).contains(&f)));
            assert!(seen.windows(2).all(|w| w[0].1 <= w[1].1), "{seen:?}");
            assert!(seen.iter().any(|&(s, _)| s == Stage::Cost));
        }
        let stop = |stage: Stage, _: f64| stage != Stage::Normals;
        assert!(matches!(
            build_costmap(&d, &ugo(), &CostmapOptions::default(), None, &stop),
            Err(CostmapError::Cancelled)
        ));
    }

    /// Tag `tag` of page `page` (0-based) of a TIFF, as text.
    fn ascii_tag(bytes: &[u8], page: usize, tag: u16) -> Option<String> {
        let mut d = tiff::decoder::Decoder::new(std::io::Cursor::new(bytes)).unwrap();
        d.seek_to_image(page).unwrap();
        d.find_tag(tiff::tags::Tag::Unknown(tag))
            .unwrap()
            .map(|v| v.into_string().unwrap())
    }

    #[test]
    fn writes_cost_and_class_pages_our_reader_reads_back() {
        use crate::terrain::{geotiff_pages, read_geotiff_page_band};
        let d = surface(12, 10, 1.0, |x, _| if x > 5.5 { 3.0 } else { 1.0 });
        let m = build(
            &d,
            &ugo(),
            &CostmapOptions {
                layers: vec![Layer::Step],
                ..Default::default()
            },
        );
        let mut buf = std::io::Cursor::new(Vec::new());
        m.write_geotiff(&mut buf).unwrap();
        let tif = buf.into_inner();
        // Float32 cost + Byte class, and the head.
        assert!(tif.len() > 12 * 10 * 5);
        assert_eq!(geotiff_pages(&tif, 10).unwrap().len(), 2);
        let limits = Default::default();
        let cost = read_geotiff_page_band(&tif, 1, 1, None, &limits).unwrap();
        let class = read_geotiff_page_band(&tif, 2, 1, None, &limits).unwrap();
        for page in [&cost, &class] {
            assert_eq!((page.width, page.height), (12, 10));
            assert_eq!(page.transform, d.transform);
            assert_eq!(page.crs.epsg, 32633);
        }
        assert!(cost.nodata.is_some_and(f64::is_nan));
        assert_eq!(class.nodata, Some(0.0));
        let mut seen = [0usize; 6];
        for i in 0..m.cost.len() {
            let (c, k) = (m.cost[i], m.class[i]);
            assert!(c.is_nan() == cost.values[i].is_nan(), "cost {i}");
            if !c.is_nan() {
                assert_eq!(cost.values[i], f64::from(c), "cost {i}");
            }
            // Unknown is the class page's nodata: read as NaN.
            if k == Class::Unknown as u8 {
                assert!(class.values[i].is_nan(), "class {i}");
            } else {
                assert_eq!(class.values[i], f64::from(k), "class {i}");
            }
            seen[usize::from(k)] += 1;
        }
        // The border ring is unknown, the wall a step, the rest traversable.
        assert!(seen[0] > 0 && seen[1] > 0 && seen[3] > 0, "{seen:?}");
        let cost_meta = ascii_tag(&tif, 0, 42112).unwrap();
        assert!(
            cost_meta.contains(r#"role="unittype">cost</Item>"#),
            "{cost_meta}"
        );
        let class_meta = ascii_tag(&tif, 1, 42112).unwrap();
        assert!(!class_meta.contains("unittype"), "{class_meta}");
        for c in Class::ALL {
            let item = format!(
                r#"<Item name="CLASS_{}" sample="0">{}</Item>"#,
                c as u8,
                c.name()
            );
            assert!(class_meta.contains(&item), "{class_meta}");
        }
        assert_eq!(ascii_tag(&tif, 0, 42113).as_deref(), Some("nan"));
        assert_eq!(ascii_tag(&tif, 1, 42113).as_deref(), Some("0"));

        // terraplan's DEM reader takes single-band files: read a layer.
        let mut layer = std::io::Cursor::new(Vec::new());
        assert!(m.write_layer_geotiff(Layer::Step, &mut layer).unwrap());
        let layer = layer.into_inner();
        let back = crate::terrain::read_dem(&layer, Some("s.tif"), None, &limits).unwrap();
        assert_eq!((back.width, back.height), (12, 10));
        assert_eq!(back.transform, d.transform);
        assert_eq!(back.crs.epsg, 32633);
        let step = &m.layers[0].1;
        for (a, b) in back.values.iter().zip(step) {
            assert!(a.is_nan() == b.is_nan() && (a.is_nan() || (*a - f64::from(*b)).abs() < 1e-6));
        }
        assert_eq!(
            ascii_tag(&layer, 0, 42112).as_deref(),
            Some(
                "<GDALMetadata>\n  <Item name=\"DESCRIPTION\" sample=\"0\" \
                 role=\"description\">step</Item>\n  <Item name=\"UNITTYPE\" sample=\"0\" \
                 role=\"unittype\">m</Item>\n</GDALMetadata>"
            )
        );
        assert!(
            !m.write_layer_geotiff(Layer::Slope, std::io::Cursor::new(Vec::new()))
                .unwrap()
        );
        let png = super::super::preview_png(&m, 8);
        assert_eq!(&png[1..4], b"PNG");
        assert!(super::super::legend_svg(&m).contains("step"));
    }
}
