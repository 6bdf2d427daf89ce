//! The cells of a survey: the free space, its decomposition at the slice
//! angle (or the angle `auto` finds) with a lawnmower plan per cell, and
//! the cells and coverage as planned.

use geo::{Area, Euclidean, Length};
use geo_types::{Coord, MultiPolygon, Polygon};
use rayon::prelude::*;

use super::request::{NO_FLY_POINTER, PlanError, ROI_POINTER, SliceAngle};
use super::result::CellOut;
use crate::coverage::{self, CellPlan};
use crate::decompose;
use crate::export::geojson as gj;
use crate::geo::{GeoError, Issue, SurveyArea, UtmProjection};

/// Free space smaller than this (m²) is treated as nothing left to survey.
pub(super) const MIN_FREE_AREA_M2: f64 = 1.0;
/// How many slice angles `auto` tries at most: every 15° plus the bearings
/// of the longest boundary edges, where the fewest turns usually are.
const AUTO_EDGE_CANDIDATES: usize = 12;
const AUTO_STEP_DEG: f64 = 15.0;

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
    pub plans: Vec<CellPlan>,
    /// Lanes laid along a corridor's line: kept as laid (not re-planned).
    pub along_line: bool,
}

/// The cells of one slice angle, their lane layouts and the turns these
/// need in all.
struct Laid {
    angle: f64,
    cells: Vec<Polygon<f64>>,
    layouts: Vec<Layouts>,
    turns: usize,
}

/// A cell's lane layouts, or not yet: a cell one lane wide needs no turn
/// whatever its layout, and is only laid out if its angle contends (boxed:
/// most cells of thousands are one lane).
enum Layouts {
    Laid(Option<Box<coverage::CellLayouts>>),
    OneLane,
}

impl Layouts {
    fn turns(&self) -> usize {
        match self {
            Layouts::Laid(l) => l.as_ref().map_or(0, |l| l.turns()),
            Layouts::OneLane => 0,
        }
    }
}

/// Decompose at the requested angle, or at every candidate angle for
/// `auto`, and plan the lanes of every cell. `auto` keeps the angle with
/// the fewest turns in total, then the shortest lanes-and-links length.
/// The turns of an angle are known from its cells' lane layouts alone, so
/// the lanes are only extended and linked for the angles that tie on the
/// fewest (most of the work among thousands of NFZs).
pub(super) fn decompose_and_cover(
    free: &MultiPolygon<f64>,
    angle: SliceAngle,
    spacing: f64,
) -> Result<Decomposition, PlanError> {
    let candidates = match angle {
        SliceAngle::Degrees(d) => vec![d],
        SliceAngle::Auto => auto_candidates(free),
    };
    let token = crate::cancel::current();
    let prepared = decompose::PreparedFree::new(free).map_err(decompose_error)?;
    // One decomposition per core at a time (each can hold tens of
    // thousands of cells), the token taken along to the worker threads.
    let decomposed = |a: f64| -> Result<Laid, PlanError> {
        token.scope(|| {
            crate::cancel::check()?;
            let cells = prepared.decompose(a).map_err(decompose_error)?;
            let layouts: Vec<Layouts> = cells
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    if coverage::is_one_lane(c, spacing, a) {
                        Layouts::OneLane
                    } else {
                        Layouts::Laid(coverage::CellLayouts::new(i, c, spacing, a).map(Box::new))
                    }
                })
                .collect();
            // The cells stop early when cancelled, with layouts to throw away.
            crate::cancel::check()?;
            let turns = layouts.iter().map(Layouts::turns).sum();
            Ok(Laid {
                angle: a,
                cells,
                layouts,
                turns,
            })
        })
    };
    let mut fewest = usize::MAX;
    let mut contenders: Vec<Laid> = Vec::new();
    for batch in candidates.chunks(rayon::current_num_threads().max(1)) {
        let results: Vec<_> = batch.par_iter().map(|&a| decomposed(a)).collect();
        for result in results {
            let laid = result?;
            if laid.turns < fewest {
                fewest = laid.turns;
                contenders.clear();
            }
            if laid.turns == fewest {
                contenders.push(laid);
            }
        }
    }
    // The contenders all need the fewest turns: the shortest flight wins,
    // the first in candidate order on a tie.
    let mut best: Option<(f64, Decomposition)> = None;
    // Index the free space once for every cell of every contending angle.
    let free_space = coverage::FreeSpace::new(free);
    for Laid {
        angle: a,
        cells,
        layouts,
        ..
    } in contenders
    {
        let plans: Vec<CellPlan> = layouts
            .par_iter()
            .zip(&cells)
            .enumerate()
            .filter_map(|(i, (l, c))| {
                token.scope(|| match l {
                    Layouts::Laid(l) => l.as_ref()?.best_plan(c, &free_space),
                    Layouts::OneLane => {
                        coverage::CellLayouts::new(i, c, spacing, a)?.best_plan(c, &free_space)
                    }
                })
            })
            .collect();
        crate::cancel::check()?;
        let length_m: f64 = plans.iter().map(CellPlan::length_m).sum();
        if best.as_ref().is_none_or(|(b, _)| length_m < b - 1e-6) {
            best = Some((
                length_m,
                Decomposition {
                    slice_angle_deg: a,
                    cells,
                    plans,
                    along_line: false,
                },
            ));
        }
    }
    let (_, best) = best.ok_or_else(|| PlanError::Internal("no slice angle tried".into()))?;
    if best.plans.is_empty() {
        return Err(PlanError::Invalid(vec![Issue::new(
            ROI_POINTER,
            "the free area is too small or too thin for a single survey lane",
        )]));
    }
    Ok(best)
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

/// A decomposition's fault as the survey reports it.
fn decompose_error(e: decompose::DecomposeError) -> PlanError {
    match e {
        decompose::DecomposeError::EmptyFreeSpace => PlanError::Invalid(vec![Issue::new(
            NO_FLY_POINTER,
            "the no-fly zones cover the whole region of interest: nothing is left to survey",
        )]),
        decompose::DecomposeError::Cancelled(c) => PlanError::Cancelled(c),
        other => PlanError::Internal(other.to_string()),
    }
}

/// Candidate slice angles for `auto`: every 15°, and the bearings of the
/// longest boundary edges (a lane or slice along a long edge saves turns).
fn auto_candidates(free: &MultiPolygon<f64>) -> Vec<f64> {
    let mut edges: Vec<(f64, f64)> = free
        .0
        .iter()
        .flat_map(|p| std::iter::once(p.exterior()).chain(p.interiors()))
        .flat_map(|r| r.lines())
        .map(|l| (Euclidean.length(&l), bearing_mod_180(l.start, l.end)))
        .collect();
    edges.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut out: Vec<f64> = (0..(180.0 / AUTO_STEP_DEG) as usize)
        .map(|i| i as f64 * AUTO_STEP_DEG)
        .collect();
    for (_, b) in edges.into_iter().take(AUTO_EDGE_CANDIDATES) {
        for c in [b, (b + 90.0) % 180.0] {
            if out.iter().all(|o| angle_gap(*o, c) > 0.5) {
                out.push(c);
            }
        }
    }
    out
}

fn bearing_mod_180(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let deg = (b.x - a.x).atan2(b.y - a.y).to_degrees();
    let m = deg.rem_euclid(180.0);
    if m >= 180.0 - 1e-9 { 0.0 } else { m }
}

fn angle_gap(a: f64, b: f64) -> f64 {
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

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::polygon;

    #[test]
    fn auto_candidates_include_edge_bearings() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 100.0, y: 100.0), (x: 90.0, y: 110.0), (x: -10.0, y: 10.0)];
        let c = auto_candidates(&MultiPolygon(vec![p]));
        assert!(c.iter().any(|a| angle_gap(*a, 45.0) < 1e-9));
        assert!(c.iter().any(|a| angle_gap(*a, 135.0) < 1e-9));
    }
}
