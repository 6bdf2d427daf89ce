//! The costmap's parameters for one DEM: what the options leave open
//! filled in, and the checks of the options that need the DEM.

use super::grid::resample_factor;
use super::{CostmapOptions, InflationMode, MAX_RADIUS_CELLS, ResolvedParams, Vehicle};
use crate::geo::Issue;
use crate::terrain::Dem;

/// Everything `options` leaves open, filled in for `dem` and `vehicle`.
pub(crate) fn resolve(dem: &Dem, vehicle: &Vehicle, options: &CostmapOptions) -> ResolvedParams {
    let res = dem.resolution_m();
    let factor = options
        .resolution_m
        .map_or([1, 1], |r| resample_factor(res, r));
    let cell = [res[0] * factor[0] as f64, res[1] * factor[1] as f64];
    let (small, large) = (cell[0].min(cell[1]), cell[0].max(cell[1]));
    let longer = vehicle.width_m.max(vehicle.length_m);
    ResolvedParams {
        resolution_m: cell,
        resample_factor: factor,
        smoothing_sigma_m: options.smoothing_sigma_m.unwrap_or(0.5 * small),
        pca_radius_m: options.pca_radius_m.unwrap_or(1.5 * large),
        step_mode: options.step_mode,
        inflation: options.inflation,
        inflation_sigma_m: options
            .inflation_sigma_m
            .unwrap_or((longer / 2.0).max(large)),
        min_region_area_m2: options
            .min_region_area_m2
            .unwrap_or(10.0 * vehicle.width_m * vehicle.length_m),
    }
}

/// Checks of `options` that need the DEM (pointers under `prefix`): a
/// working resolution finer than the DEM, neighbourhoods of too many
/// cells, a grid too small to judge.
pub fn check_against_dem(
    dem: &Dem,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    prefix: &str,
) -> Vec<Issue> {
    let mut issues = Vec::new();
    let res = dem.resolution_m();
    let finest = res[0].min(res[1]);
    // A geographic DEM's cells narrow towards the poles; where they are far
    // longer than wide no neighbourhood in metres makes sense (and at 90°
    // they have no width at all).
    let [narrowest, widest] = cell_extremes_m(dem);
    if narrowest.is_nan() || narrowest <= 0.0 || widest / narrowest > MAX_CELL_ASPECT {
        issues.push(Issue::new(
            "/dem_id",
            &format!(
                "the DEM's cells range from {narrowest:.3e} to {widest:.3e} m across (it reaches \
                 too near a pole); costmaps need cells at most {MAX_CELL_ASPECT} times longer \
                 than wide"
            ),
        ));
        return issues;
    }
    if let Some(r) = options.resolution_m {
        // 0.1 % of slack for rounding in the cell size.
        if r < finest * 0.999 || !r.is_finite() {
            issues.push(Issue::new(
                &format!("{prefix}/resolution_m"),
                &format!(
                    "{} m is finer than the DEM's {:.4} × {:.4} m cells; the working \
                     resolution can only be coarser (cells are averaged, never invented)",
                    crate::num::readable(r),
                    res[0],
                    res[1]
                ),
            ));
            return issues;
        }
    }
    let p = resolve(dem, vehicle, options);
    // Limits in cells count the narrowest row's cells.
    let cell = narrowest * (p.resample_factor[0].min(p.resample_factor[1]) as f64);
    let (w, h) = (
        dem.width / p.resample_factor[0],
        dem.height / p.resample_factor[1],
    );
    if w < 3 || h < 3 {
        let pointer = if options.resolution_m.is_some() {
            format!("{prefix}/resolution_m")
        } else {
            "/dem_id".to_string()
        };
        issues.push(Issue::new(
            &pointer,
            &format!(
                "the working grid would be {w} × {h} cells; at least 3 × 3 are needed \
                 (the DEM is {} × {})",
                dem.width, dem.height
            ),
        ));
    }
    if p.pca_radius_m / cell > MAX_RADIUS_CELLS {
        issues.push(Issue::new(
            &format!("{prefix}/pca_radius_m"),
            &format!(
                "{} m spans {:.0} cells of {cell:.3} m; at most {MAX_RADIUS_CELLS} are allowed",
                crate::num::readable(p.pca_radius_m),
                p.pca_radius_m / cell
            ),
        ));
    }
    if p.pca_radius_m < cell {
        issues.push(Issue::new(
            &format!("{prefix}/pca_radius_m"),
            &format!(
                "{} m reaches no neighbour of the {cell:.3} m cells; a plane needs at least \
                 the 4 nearest",
                crate::num::readable(p.pca_radius_m)
            ),
        ));
    }
    if let Some(n) = &options.negative_steps {
        let r = negative_radius(vehicle, n.radius_m);
        if r / cell > MAX_NEGATIVE_RADIUS_CELLS || r < cell {
            issues.push(Issue::new(
                &format!("{prefix}/negative_steps/radius_m"),
                &format!(
                    "{} m spans {:.1} cells of {cell:.3} m; give 1 to \
                     {MAX_NEGATIVE_RADIUS_CELLS} cells",
                    crate::num::readable(r),
                    crate::num::readable(r / cell)
                ),
            ));
        }
    }
    if p.inflation == InflationMode::Blur && p.inflation_sigma_m / cell > MAX_RADIUS_CELLS {
        // The blur costs a kernel of 4σ cells per cell; the distance mode
        // is linear whatever σ.
        issues.push(Issue::new(
            &format!("{prefix}/inflation_sigma_m"),
            &format!(
                "{} m spans {:.0} cells of {cell:.3} m; with inflation blur at most \
                 {MAX_RADIUS_CELLS} are allowed (inflation distance has no such limit)",
                crate::num::readable(p.inflation_sigma_m),
                p.inflation_sigma_m / cell
            ),
        ));
    }
    if p.smoothing_sigma_m / cell > MAX_RADIUS_CELLS {
        issues.push(Issue::new(
            &format!("{prefix}/smoothing_sigma_m"),
            &format!("spans more than {MAX_RADIUS_CELLS} cells of {cell:.3} m"),
        ));
    }
    issues
}

/// Longest a cell may be relative to its width (geographic DEMs near the
/// poles).
pub const MAX_CELL_ASPECT: f64 = 20.0;

/// The smallest and largest side, in metres, of the DEM's cells over all
/// its rows (a geographic DEM's cells narrow towards the poles: the
/// extremes are on the first, middle or last row).
fn cell_extremes_m(dem: &Dem) -> [f64; 2] {
    if !dem.crs.geographic {
        let r = dem.resolution_m();
        return [r[0].min(r[1]), r[0].max(r[1])];
    }
    let rows = [0.5, dem.height as f64 / 2.0, dem.height as f64 - 0.5];
    let sizes =
        rows.map(|r| crate::terrain::cell_size_m(&dem.transform, true, dem.width as f64 / 2.0, r));
    let lo = sizes
        .iter()
        .flatten()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let hi = sizes.iter().flatten().copied().fold(0.0, f64::max);
    [lo, hi]
}

/// Most cells the negative-step plane's radius may span (each cell fits
/// a plane to every cell within it).
pub const MAX_NEGATIVE_RADIUS_CELLS: f64 = 25.0;

pub(crate) fn negative_radius(vehicle: &Vehicle, given: Option<f64>) -> f64 {
    given.unwrap_or(1.5 * vehicle.width_m.max(vehicle.length_m))
}
