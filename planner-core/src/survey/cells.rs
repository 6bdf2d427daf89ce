//! The cells of a survey: the free space, its decomposition at the slice
//! angle (or the angle `auto` finds) with a lawnmower plan per cell, and
//! the cells and coverage as planned.

use geo::Area;
use geo_types::{Coord, MultiPolygon, Polygon};

use super::request::{NO_FLY_POINTER, PlanError};
use super::result::CellOut;
use crate::coverage::{self, CellPlan};
use crate::decompose;
use crate::export::geojson as gj;
use crate::geo::{GeoError, Issue, SurveyArea, UtmProjection};

/// Free space smaller than this (m²) is treated as nothing left to survey.
pub(super) const MIN_FREE_AREA_M2: f64 = 1.0;

/// ROI minus `zones`, over every part of the ROI: the free space (minus
/// the NFZs), or the flyable space (minus their keep-out area, where lanes,
/// links and transits may run).
pub(super) fn roi_minus(area: &SurveyArea, zones: &[Polygon<f64>]) -> MultiPolygon<f64> {
    let mut parts = Vec::new();
    for roi in &area.roi.0 {
        parts.extend(decompose::free_space(roi, zones).0);
    }
    if area.roi.0.len() > 1 {
        // Overlapping ROI parts must not be surveyed twice.
        crate::overlay::unary_union(parts.iter())
    } else {
        MultiPolygon(parts)
    }
}

/// One pass over all zones: folding pairwise unions is quadratic.
pub(super) fn nfz_union(no_fly: &[Polygon<f64>]) -> MultiPolygon<f64> {
    crate::overlay::unary_union(no_fly.iter())
}

/// Cells at one slice angle and the lawnmower plan of each.
pub(super) struct Decomposition {
    pub slice_angle_deg: f64,
    pub cells: Vec<Polygon<f64>>,
    /// Per cell: joined from several by [`decompose::decompose_merged`],
    /// flown whole with lanes across the slice (which other layouts of its
    /// lane count may not cover).
    pub joined: Vec<bool>,
    pub plans: Vec<CellPlan>,
    /// Lanes laid along a corridor's line: kept as laid (not re-planned).
    pub along_line: bool,
    /// Every cell's lanes on one grid ([`coverage::LaneGrid`]): kept as
    /// laid (a cell may leave a sliver to its neighbour's lane).
    pub on_grid: bool,
}

/// Lays the request's pattern over every cell's plan: with `crosshatch`, a
/// second set of lanes across the first (after the terrain, if any, chose
/// each cell's first set), `spacing` apart in the flyable space `free`.
pub(super) fn lay_pattern(
    d: &mut Decomposition,
    pattern: coverage::Pattern,
    free: &MultiPolygon<f64>,
    spacing: f64,
) -> Result<(), PlanError> {
    if pattern == coverage::Pattern::Crosshatch {
        // Each cell cut into parts monotone across its lanes: every lane
        // of the second set is then one segment reaching its strip's ends.
        let split = |cell: &Polygon<f64>, bearing: f64| {
            decompose::decompose(&MultiPolygon(vec![cell.clone()]), bearing)
                .unwrap_or_else(|_| vec![cell.clone()])
        };
        d.plans = coverage::crosshatch_all(&d.plans, &d.cells, free, spacing, &split);
        crate::cancel::check()?;
    }
    Ok(())
}

pub(super) fn bearing_mod_180(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let deg = (b.x - a.x).atan2(b.y - a.y).to_degrees();
    let m = deg.rem_euclid(180.0);
    if m >= 180.0 - 1e-9 { 0.0 } else { m }
}

pub(super) fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(180.0);
    d.min(180.0 - d)
}

pub(super) fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// The free space: the ROI less the no-fly zones, refused when nothing is
/// left of it.
pub(super) fn free_space(area: &SurveyArea) -> Result<MultiPolygon<f64>, PlanError> {
    let free = roi_minus(area, &area.no_fly);
    crate::cancel::check()?;
    if free.unsigned_area() < MIN_FREE_AREA_M2 {
        return Err(PlanError::Invalid(vec![Issue::new(
            NO_FLY_POINTER,
            "the no-fly zones cover the whole region of interest: nothing is left to survey",
        )]));
    }
    Ok(free)
}

/// The lanes planned and the share of `free` their footprints
/// (`footprint_side_m` wide) cover.
pub(super) fn coverage(
    plans: &[CellPlan],
    footprint_side_m: f64,
    free: &MultiPolygon<f64>,
) -> (usize, f64) {
    let lanes: Vec<coverage::Lane> = plans.iter().flat_map(|p| p.lanes.iter().copied()).collect();
    let ratio = coverage::coverage_ratio(&lanes, footprint_side_m, free);
    (lanes.len(), ratio)
}

/// What is left out of the free area (`free_area_m2`): pockets enclosed
/// by the keep-out area (`enclosed_m2`) and what the footprints miss.
pub(super) fn left_out_warnings(
    enclosed_m2: f64,
    clearance: f64,
    coverage_ratio: f64,
    free_area_m2: f64,
) -> Vec<String> {
    let mut warnings = Vec::new();
    if enclosed_m2 > 0.0 {
        warnings.push(format!(
            "{:.0} m² of the free area are enclosed by no-fly zones with gaps narrower than twice \
             nfz_clearance_m ({clearance} m): no way in keeps the clearance, so they are not flown",
            enclosed_m2
        ));
    }
    if coverage_ratio < 0.995 {
        warnings.push(format!(
            "footprints cover {:.2} % of the free area: {:.0} m² are left out (narrow corners \
             between no-fly zones, or strips the lanes cannot reach while keeping \
             nfz_clearance_m = {clearance} m from them)",
            coverage_ratio * 100.0,
            (1.0 - coverage_ratio) * free_area_m2
        ));
    }
    warnings
}

/// The cells as planned: area, lane direction and lanes of each, and its
/// polygon in WGS84.
pub(super) fn cells_out(d: &Decomposition, proj: &UtmProjection) -> Result<Vec<CellOut>, GeoError> {
    // Each cell's (first) plan, found by index: there may be thousands.
    let mut plan_of: Vec<Option<&CellPlan>> = vec![None; d.cells.len()];
    for p in d.plans.iter().rev() {
        if let Some(slot) = plan_of.get_mut(p.cell_index) {
            *slot = Some(p);
        }
    }
    d.cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let plan = plan_of[i];
            Ok(CellOut {
                id: i,
                area_m2: c.unsigned_area(),
                lane_bearing_deg: plan.map_or(d.slice_angle_deg, |p| p.direction_deg),
                lanes: plan.map_or(0, |p| p.lanes.len()),
                lane_length_m: plan
                    .map_or(0.0, |p| p.lanes.iter().map(|l| dist(l.start, l.end)).sum()),
                polygon: gj::polygon_geometry(&proj.polygon_to_wgs84(c)?),
                photos: None,
            })
        })
        .collect()
}
