//! The slice angle of a survey and the cells and lanes it gives: the
//! requested angle, or for `auto` the best of a set of candidates.
//!
//! Multirotors fly the cells of [`decompose::PreparedFree::decompose_merged`]
//! (chains of cells one sweep of lanes flies whole are one cell) and `auto`
//! compares whole plans: lanes, the links between them and the tour over
//! the cells from the first UAV's start, as flown (issue 21: fewer metres
//! than Fields2Cover). Angles are planned whole in order of an estimate
//! (the lanes' lower bound plus a link per lane change) while their cells
//! fit [`WHOLE_PLAN_CELL_BUDGET`], skipping those whose lanes alone already
//! outlast the best plan. Planes, and surveys too big for that budget, keep
//! the angle with the fewest turns (a plane's turn is long and slow), then
//! the shortest lanes and links.

use geo_types::{Coord, MultiPolygon, Polygon};
use rayon::prelude::*;

use super::cells::{Decomposition, angle_gap, bearing_mod_180};
use super::request::{NO_FLY_POINTER, PlanError, ROI_POINTER, SliceAngle};
use crate::coverage::{self, CellPlan};
use crate::decompose;
use crate::flock::{ObstacleMap, TransitError, plan_tour_in};
use crate::geo::Issue;

/// How many slice angles `auto` tries at most: every 15° plus the bearings
/// of the longest boundary edges, where the fewest turns usually are.
const AUTO_EDGE_CANDIDATES: usize = 12;
const AUTO_STEP_DEG: f64 = 15.0;
/// Cells planned whole (lanes, links and a tour) over all angles `auto`
/// compares: a tour of 2000 cells takes about 0.25 s. Beyond it the angle
/// with the fewest turns is kept, as for planes.
const WHOLE_PLAN_CELL_BUDGET: usize = 2000;
/// Footprint coverage every plan should reach (SPEC §3): a shorter plan
/// that covers less only wins when no angle reaches it.
const COVERAGE_TARGET: f64 = 0.995;

/// Where the lines of a lane grid are tried, as fractions of a spacing
/// back from half a spacing inside the free space (see
/// [`coverage::LaneGrid::shifted`]).
const GRID_PHASES: [f64; 4] = [0.0, 0.25, 0.5, 0.75];

/// How much more of the surveyed space (a share) a grid plan's lane strips
/// must cover than the plan it would replace: a grid plan leaves slivers
/// of cells to neighbours' lines, and a measure of its strips made apart
/// from the planner's (other rounding, the lanes read back from a mission
/// file) may find a few millionths less; with this margin it never finds
/// less than the plan replaced.
const GRID_STRIP_MARGIN: f64 = 1e-5;

/// How `auto` compares the candidate angles.
pub(super) enum Compare<'a> {
    /// Fewest turns, then the shortest lanes and links (planes).
    FewestTurns,
    /// The shortest whole flight of a multirotor: lanes, links and the tour
    /// from `start` over the cells and back, around `obstacles`; among plans
    /// whose footprints (`footprint_side_m`) cover [`COVERAGE_TARGET`] of
    /// `free` where there are any.
    WholePlan {
        start: Coord<f64>,
        obstacles: &'a ObstacleMap,
        free: &'a MultiPolygon<f64>,
        footprint_side_m: f64,
    },
}

/// The cells of one slice angle, their lane layouts and the turns these
/// need in all.
struct Laid {
    angle: f64,
    cells: Vec<Polygon<f64>>,
    joined: Vec<bool>,
    layouts: Vec<Layouts>,
    turns: usize,
    /// Every cell's layouts are laid (none left as [`Layouts::OneLane`]),
    /// so the angle can be planned whole.
    all_laid: bool,
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

impl Laid {
    /// No plan of this angle is shorter: its cells' lanes alone.
    fn lane_lower_bound(&self) -> f64 {
        self.layouts
            .iter()
            .map(|l| match l {
                Layouts::Laid(Some(l)) => l.length_lower_bound(),
                _ => 0.0,
            })
            .sum()
    }

    /// What the whole plan is expected to fly: the lanes' lower bound and a
    /// link of `spacing` per lane change.
    fn estimate(&self, spacing: f64) -> f64 {
        self.lane_lower_bound() + (self.turns / 2) as f64 * spacing
    }

    /// Every cell's shortest plan (lanes and links).
    fn plans(&self, spacing: f64, free_space: &coverage::FreeSpace) -> Vec<CellPlan> {
        let token = crate::cancel::current();
        self.layouts
            .par_iter()
            .zip(&self.cells)
            .enumerate()
            .filter_map(|(i, (l, c))| {
                token.scope(|| match l {
                    Layouts::Laid(l) => l.as_ref()?.best_plan(c, free_space),
                    Layouts::OneLane => coverage::CellLayouts::new(i, c, spacing, self.angle)?
                        .best_plan(c, free_space),
                })
            })
            .collect()
    }

    fn into_decomposition(self, plans: Vec<CellPlan>) -> Decomposition {
        Decomposition {
            slice_angle_deg: self.angle,
            cells: self.cells,
            joined: self.joined,
            plans,
            along_line: false,
            on_grid: false,
        }
    }
}

/// Decompose at the requested angle, or at every candidate angle for
/// `auto` and keep the best by `compare`, and plan the lanes of every cell.
pub(super) fn decompose_and_cover(
    free: &MultiPolygon<f64>,
    angle: SliceAngle,
    spacing: f64,
    compare: &Compare,
) -> Result<Decomposition, PlanError> {
    let candidates = match angle {
        SliceAngle::Degrees(d) => vec![d],
        SliceAngle::Auto => auto_candidates(free),
    };
    let merged = matches!(compare, Compare::WholePlan { .. });
    let whole = merged && candidates.len() > 1;
    let token = crate::cancel::current();
    let prepared = decompose::PreparedFree::new(free).map_err(decompose_error)?;
    // One decomposition per core at a time (each can hold tens of
    // thousands of cells), the token taken along to the worker threads.
    let decomposed = |a: f64| -> Result<Laid, PlanError> {
        token.scope(|| {
            crate::cancel::check()?;
            let (cells, joined): (Vec<Polygon<f64>>, Vec<bool>) = if merged {
                let cells = prepared
                    .decompose_merged(a, spacing)
                    .map_err(decompose_error)?;
                cells.into_iter().map(|c| (c.polygon, c.joined)).unzip()
            } else {
                let cells = prepared.decompose(a).map_err(decompose_error)?;
                let n = cells.len();
                (cells, vec![false; n])
            };
            // Small enough to be planned whole: every cell laid out now,
            // for the lower bound of its lanes.
            let all_laid = whole && cells.len() <= WHOLE_PLAN_CELL_BUDGET;
            let layouts: Vec<Layouts> = cells
                .iter()
                .zip(&joined)
                .enumerate()
                .map(|(i, (c, &j))| {
                    if j {
                        // Joined cells are flown across the slice, whole.
                        let along = coverage::CellLayouts::along(i, c, spacing, a + 90.0);
                        Layouts::Laid(along.map(Box::new))
                    } else if !all_laid && coverage::is_one_lane(c, spacing, a) {
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
                joined,
                layouts,
                turns,
                all_laid,
            })
        })
    };
    // Fewest turns among all angles; the angles small enough to be planned
    // whole are kept for that too.
    let mut fewest = usize::MAX;
    let mut contenders: Vec<Laid> = Vec::new();
    let mut small: Vec<Laid> = Vec::new();
    for batch in candidates.chunks(rayon::current_num_threads().max(1)) {
        let results: Vec<_> = batch.par_iter().map(|&a| decomposed(a)).collect();
        for result in results {
            let laid = result?;
            if laid.all_laid {
                small.push(laid);
                continue;
            }
            if laid.turns < fewest {
                fewest = laid.turns;
                contenders.clear();
            }
            if laid.turns == fewest {
                contenders.push(laid);
            }
        }
    }
    let free_space = coverage::FreeSpace::new(free);
    let best = match compare {
        Compare::WholePlan {
            start,
            obstacles,
            free: surveyed,
            footprint_side_m,
        } if !small.is_empty() => {
            let judge = Judge {
                start: *start,
                obstacles,
                flyable: &free_space,
                surveyed,
                footprint_side_m: *footprint_side_m,
                spacing,
            };
            // A plain decomposition of more than one cell: its cells side
            // by side may share lane lines. Cells smaller than a spacing
            // squared (rounding slivers along a curved outline) do not
            // count: their lanes are too short to be worth a grid.
            let several: Vec<f64> = small
                .iter()
                .filter(|l| {
                    let big = l
                        .cells
                        .iter()
                        .filter(|c| geo::Area::unsigned_area(*c) >= spacing * spacing);
                    big.count() > 1 || l.joined.iter().any(|&j| j)
                })
                .map(|l| l.angle)
                .collect();
            let (best, length_m, planned_cells) = shortest_whole_plan(small, &judge, &free_space)?;
            let grid = GridSearch {
                prepared: &prepared,
                free,
                judge: &judge,
                free_space: &free_space,
            };
            grid.shorter(best, length_m, &several, planned_cells)?
        }
        _ => {
            // Too big to be planned whole (or a plane's): small angles
            // contend on turns too.
            for laid in small {
                if laid.turns < fewest {
                    fewest = laid.turns;
                    contenders.clear();
                }
                if laid.turns == fewest {
                    contenders.push(laid);
                }
            }
            shortest_of_fewest_turns(contenders, spacing, &free_space)?
        }
    };
    if best.plans.is_empty() {
        return Err(PlanError::Invalid(vec![Issue::new(
            ROI_POINTER,
            "the free area is too small or too thin for a single survey lane",
        )]));
    }
    Ok(best)
}

/// The contenders all need the fewest turns: the shortest lanes and links
/// win, the first in candidate order on a tie.
fn shortest_of_fewest_turns(
    contenders: Vec<Laid>,
    spacing: f64,
    free_space: &coverage::FreeSpace,
) -> Result<Decomposition, PlanError> {
    let mut best: Option<(f64, Decomposition)> = None;
    for laid in contenders {
        let plans = laid.plans(spacing, free_space);
        crate::cancel::check()?;
        let length_m: f64 = plans.iter().map(CellPlan::length_m).sum();
        if best.as_ref().is_none_or(|(b, _)| length_m < b - 1e-6) {
            best = Some((length_m, laid.into_decomposition(plans)));
        }
    }
    best.map(|(_, d)| d)
        .ok_or_else(|| PlanError::Internal("no slice angle tried".into()))
}

/// What a whole plan is judged by (see [`Compare::WholePlan`]).
struct Judge<'a> {
    start: Coord<f64>,
    obstacles: &'a ObstacleMap,
    /// Where the lanes, links and transits run.
    flyable: &'a coverage::FreeSpace,
    /// Where the footprints must cover.
    surveyed: &'a MultiPolygon<f64>,
    footprint_side_m: f64,
    spacing: f64,
}

impl Judge<'_> {
    /// The length of the tour over `plans` from the start and back, or
    /// `None` if some cell cannot be reached (another angle may do).
    fn flown_length(
        &self,
        plans: &[CellPlan],
        cells: &[Polygon<f64>],
    ) -> Result<Option<f64>, PlanError> {
        match plan_tour_in(self.start, plans, cells, self.flyable, self.obstacles) {
            Ok(tour) => Ok(Some(tour.length_m())),
            Err(TransitError::Cancelled(c)) => Err(PlanError::Cancelled(c)),
            Err(_) => Ok(None),
        }
    }

    fn covers(&self, plans: &[CellPlan]) -> bool {
        let (_, ratio) = super::cells::coverage(plans, self.footprint_side_m, self.surveyed);
        ratio >= COVERAGE_TARGET
    }

    /// The share of the surveyed space the lanes' strips, one line spacing
    /// wide, cover: what a lane adds, and a plan with fewer lanes leaves out.
    fn strip_coverage(&self, plans: &[CellPlan]) -> f64 {
        super::cells::coverage(plans, self.spacing, self.surveyed).1
    }
}

/// How a whole plan fares, best first when compared (see
/// [`shortest_whole_plan`]).
#[derive(Clone, Copy, Debug)]
struct Fare {
    /// Footprints cover [`COVERAGE_TARGET`].
    covers: bool,
    /// Lane strips (one line spacing wide) cover at least what the plan
    /// with the fewest turns covers: a shorter plan must not leave more out.
    keeps_coverage: bool,
    length_m: f64,
}

impl Fare {
    fn beats(&self, other: &Fare) -> bool {
        let rank = |f: &Fare| (f.covers, f.keeps_coverage);
        match rank(self).cmp(&rank(other)) {
            std::cmp::Ordering::Greater => true,
            std::cmp::Ordering::Less => false,
            std::cmp::Ordering::Equal => self.length_m < other.length_m - 1e-6,
        }
    }
}

/// The plan with the fewest turns (the shortest lanes and links among
/// them) is planned first: the reference whose strip coverage the others
/// must keep. Then the other angles are planned whole in order of their
/// estimate, within the cell budget; the best [`Fare`] wins, the first in
/// that order on a tie.
/// Returns the plan, its flown length and how many cells were planned.
fn shortest_whole_plan(
    small: Vec<Laid>,
    judge: &Judge,
    free_space: &coverage::FreeSpace,
) -> Result<(Decomposition, f64, usize), PlanError> {
    let fewest = small.iter().map(|l| l.turns).min().unwrap_or(0);
    let mut reference: Option<(f64, usize, Vec<CellPlan>)> = None;
    let mut planned: Vec<Option<Vec<CellPlan>>> = vec![None; small.len()];
    let mut planned_cells = 0;
    for (i, laid) in small.iter().enumerate() {
        if laid.turns != fewest {
            continue;
        }
        let plans = laid.plans(judge.spacing, free_space);
        crate::cancel::check()?;
        planned_cells += laid.cells.len();
        let length: f64 = plans.iter().map(CellPlan::length_m).sum();
        if !plans.is_empty() && reference.as_ref().is_none_or(|(b, _, _)| length < b - 1e-6) {
            reference = Some((length, i, plans.clone()));
        }
        planned[i] = Some(plans);
    }
    let reference_strips = reference
        .as_ref()
        .map_or(0.0, |(_, _, plans)| judge.strip_coverage(plans));
    let mut order: Vec<(f64, f64, usize)> = small
        .iter()
        .enumerate()
        .map(|(i, l)| (l.estimate(judge.spacing), l.lane_lower_bound(), i))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The reference first: it is planned, and every other must beat it.
    if let Some((_, r, _)) = &reference {
        let r = *r;
        order.sort_by_key(|&(_, _, i)| i != r);
    }
    let mut best: Option<(Fare, usize, Vec<CellPlan>)> = None;
    for (_, lower_bound, i) in order {
        crate::cancel::check()?;
        let laid = &small[i];
        let plans = match planned[i].take() {
            Some(plans) => plans,
            None => {
                if let Some((fare, _, _)) = &best {
                    // The budget is spent once something is planned; an
                    // angle whose lanes alone outlast the best plan, when
                    // that covers, cannot beat it.
                    if planned_cells + laid.cells.len() > WHOLE_PLAN_CELL_BUDGET
                        || (fare.covers && fare.keeps_coverage && lower_bound >= fare.length_m)
                    {
                        continue;
                    }
                }
                planned_cells += laid.cells.len();
                laid.plans(judge.spacing, free_space)
            }
        };
        crate::cancel::check()?;
        if plans.is_empty() {
            continue;
        }
        let Some(length_m) = judge.flown_length(&plans, &laid.cells)? else {
            continue;
        };
        // Coverage is the dear part of a fare (strips unioned over the
        // field): a plan no shorter than a best that covers cannot win.
        if best
            .as_ref()
            .is_some_and(|(b, _, _)| b.covers && b.keeps_coverage && length_m >= b.length_m - 1e-6)
        {
            continue;
        }
        let fare = Fare {
            covers: judge.covers(&plans),
            keeps_coverage: judge.strip_coverage(&plans) >= reference_strips - 1e-6,
            length_m,
        };
        if best.as_ref().is_none_or(|(b, _, _)| fare.beats(b)) {
            best = Some((fare, i, plans));
        }
    }
    let (fare, i, plans) =
        best.ok_or_else(|| PlanError::Internal("no slice angle could be planned".into()))?;
    let laid = small
        .into_iter()
        .nth(i)
        .ok_or_else(|| PlanError::Internal("lost the best slice angle".into()))?;
    Ok((laid.into_decomposition(plans), fare.length_m, planned_cells))
}

/// The angles planned whole, planned again on one lane grid each
/// ([`coverage::LaneGrid`]): the plain cells of the angle (none joined),
/// every one flown along the slice on the grid's lines, so cells side by
/// side share lines instead of each rounding its lane count up.
struct GridSearch<'a> {
    prepared: &'a decompose::PreparedFree<'a>,
    /// The space decomposed, over which the grid is laid.
    free: &'a MultiPolygon<f64>,
    judge: &'a Judge<'a>,
    free_space: &'a coverage::FreeSpace,
}

impl GridSearch<'_> {
    /// `best` (flown `best_m` long), or the plan on a grid of one of
    /// `angles` that flies shorter while its footprints cover as the
    /// best's do and its lane strips cover more (by [`GRID_STRIP_MARGIN`]):
    /// so a grid plan never leaves out more than the plan it replaces. Within the cell budget
    /// (`planned_cells` spent already).
    fn shorter(
        &self,
        best: Decomposition,
        best_m: f64,
        angles: &[f64],
        mut planned_cells: usize,
    ) -> Result<Decomposition, PlanError> {
        if angles.is_empty() {
            return Ok(best);
        }
        let spacing = self.judge.spacing;
        let best_covers = self.judge.covers(&best.plans);
        let best_strips = self.judge.strip_coverage(&best.plans);
        let mut best = (best, best_m);
        let token = crate::cancel::current();
        for &a in angles {
            crate::cancel::check()?;
            let cells = self.prepared.decompose(a).map_err(decompose_error)?;
            if cells.len() < 2 {
                continue;
            }
            let Some(grid) = coverage::LaneGrid::new(self.free, spacing, a) else {
                continue;
            };
            let boxes = CellBoxes::new(&cells);
            // Each cell's layouts on its own, laid when first needed.
            let mut own: Vec<Option<Option<coverage::CellLayouts>>> =
                (0..cells.len()).map(|_| None).collect();
            for phase in GRID_PHASES {
                if planned_cells + cells.len() > WHOLE_PLAN_CELL_BUDGET {
                    break;
                }
                planned_cells += cells.len();
                let grid = grid.shifted(phase);
                let layouts = self.layouts_on(&grid, &cells, &boxes, &mut own)?;
                crate::cancel::check()?;
                let lower_bound: f64 = layouts
                    .iter()
                    .flatten()
                    .map(coverage::CellLayouts::length_lower_bound)
                    .sum();
                if lower_bound >= best.1 {
                    continue;
                }
                let plans: Vec<CellPlan> = layouts
                    .par_iter()
                    .zip(&cells)
                    .filter_map(|(l, c)| token.scope(|| l.as_ref()?.best_plan(c, self.free_space)))
                    .collect();
                crate::cancel::check()?;
                let Some(length_m) = self.judge.flown_length(&plans, &cells)? else {
                    continue;
                };
                if length_m >= best.1 - 1e-6
                    || (best_covers && !self.judge.covers(&plans))
                    || self.judge.strip_coverage(&plans) < best_strips + GRID_STRIP_MARGIN
                {
                    continue;
                }
                let n = cells.len();
                best = (
                    Decomposition {
                        slice_angle_deg: a,
                        cells: cells.clone(),
                        joined: vec![false; n],
                        plans,
                        along_line: false,
                        on_grid: true,
                    },
                    length_m,
                );
            }
        }
        Ok(best.0)
    }

    /// Every cell's layout on `grid`, or on its own where that needs fewer
    /// lanes (a cell whose strips reach past its sides into cells whose
    /// lines do not cover them flies lanes of its own there): a cell's
    /// sliver is left to a neighbour's line only while that neighbour
    /// flies the grid, so cells leave the grid one round after another
    /// until none does. `own[i]` caches cell `i`'s own layouts.
    fn layouts_on(
        &self,
        grid: &coverage::LaneGrid,
        cells: &[Polygon<f64>],
        boxes: &CellBoxes,
        own: &mut [Option<Option<coverage::CellLayouts>>],
    ) -> Result<Vec<Option<coverage::CellLayouts>>, PlanError> {
        let token = crate::cancel::current();
        let spacing = self.judge.spacing;
        let mut on_grid = vec![true; cells.len()];
        loop {
            let flown = |p: Coord<f64>| boxes.cell_at(cells, p).is_some_and(|j| on_grid[j]);
            let laid: Vec<Option<coverage::CellLayouts>> = cells
                .par_iter()
                .enumerate()
                .map(|(i, c)| {
                    if !on_grid[i] {
                        return None;
                    }
                    token.scope(|| {
                        coverage::CellLayouts::on_grid(i, c, grid, self.free_space, &flown)
                    })
                })
                .collect();
            crate::cancel::check()?;
            let mut left = false;
            for (i, l) in laid.iter().enumerate() {
                if !on_grid[i] {
                    continue;
                }
                let own_lanes = own[i]
                    .get_or_insert_with(|| {
                        coverage::CellLayouts::new(i, &cells[i], spacing, grid.bearing())
                    })
                    .as_ref()
                    .map_or(usize::MAX, coverage::CellLayouts::lanes);
                if l.as_ref().is_none_or(|l| l.lanes() > own_lanes) {
                    on_grid[i] = false;
                    left = true;
                }
            }
            if !left {
                return Ok(laid
                    .into_iter()
                    .enumerate()
                    .map(|(i, l)| {
                        if on_grid[i] {
                            l
                        } else {
                            own[i].take().flatten()
                        }
                    })
                    .collect());
            }
        }
    }
}

/// The cells' bounding boxes, to find the cell holding a point.
struct CellBoxes {
    tree: rstar::RTree<
        rstar::primitives::GeomWithData<rstar::primitives::Rectangle<[f64; 2]>, usize>,
    >,
}

impl CellBoxes {
    fn new(cells: &[Polygon<f64>]) -> CellBoxes {
        use geo::BoundingRect;
        let boxes = cells
            .iter()
            .enumerate()
            .filter_map(|(i, c)| {
                let r = c.bounding_rect()?;
                let rect = rstar::primitives::Rectangle::from_corners(
                    [r.min().x, r.min().y],
                    [r.max().x, r.max().y],
                );
                Some(rstar::primitives::GeomWithData::new(rect, i))
            })
            .collect();
        CellBoxes {
            tree: rstar::RTree::bulk_load(boxes),
        }
    }

    /// The first cell (by index) that holds `p`, its boundary included.
    fn cell_at(&self, cells: &[Polygon<f64>], p: Coord<f64>) -> Option<usize> {
        use geo::Intersects;
        self.tree
            .locate_all_at_point(&[p.x, p.y])
            .map(|g| g.data)
            .filter(|&i| cells[i].intersects(&p))
            .min()
    }
}

/// A decomposition's fault as the survey reports it.
pub(super) fn decompose_error(e: decompose::DecomposeError) -> PlanError {
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
    use geo::{Euclidean, Length};
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

#[cfg(test)]
mod tests {
    use super::*;
    use geo::Area;
    use geo_types::polygon;

    #[test]
    fn auto_candidates_include_edge_bearings() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 100.0, y: 100.0), (x: 90.0, y: 110.0), (x: -10.0, y: 10.0)];
        let c = auto_candidates(&MultiPolygon(vec![p]));
        assert!(c.iter().any(|a| angle_gap(*a, 45.0) < 1e-9));
        assert!(c.iter().any(|a| angle_gap(*a, 135.0) < 1e-9));
    }

    /// An L-shaped field with a square hole near its corner.
    /// A cell between two no-fly zones whose lines on the grid miss it by
    /// a few metres on both sides would fly two sliver lanes of its own
    /// (4 in all) where it needs 3 laid on its own: it leaves the grid, the
    /// others keep it, and the field is still covered.
    #[test]
    fn a_cell_leaves_the_grid_when_its_slivers_cost_a_lane() {
        let hole = |x0: f64, x1: f64| {
            geo_types::LineString::from(vec![
                (x0, 30.0),
                (x1, 30.0),
                (x1, 70.0),
                (x0, 70.0),
                (x0, 30.0),
            ])
        };
        let field = Polygon::new(
            geo_types::LineString::from(vec![
                (0.0, 0.0),
                (200.0, 0.0),
                (200.0, 100.0),
                (0.0, 100.0),
                (0.0, 0.0),
            ]),
            vec![hole(45.0, 75.0), hole(125.0, 155.0)],
        );
        let free = MultiPolygon(vec![field]);
        let holes = MultiPolygon(vec![
            Polygon::new(hole(45.0, 75.0), vec![]),
            Polygon::new(hole(125.0, 155.0), vec![]),
        ]);
        let spacing = 20.0;
        let obstacles = ObstacleMap::new(&holes, 0.0);
        let free_space = coverage::FreeSpace::new(&free);
        let prepared = decompose::PreparedFree::new(&free).unwrap();
        let judge = Judge {
            start: Coord { x: 0.0, y: -50.0 },
            obstacles: &obstacles,
            flyable: &free_space,
            surveyed: &free,
            footprint_side_m: spacing / 0.7,
            spacing,
        };
        let search = GridSearch {
            prepared: &prepared,
            free: &free,
            judge: &judge,
            free_space: &free_space,
        };
        let cells = prepared.decompose(0.0).unwrap();
        assert_eq!(cells.len(), 7);
        let grid = coverage::LaneGrid::new(&free, spacing, 0.0).unwrap();
        let boxes = CellBoxes::new(&cells);
        let mut own: Vec<Option<Option<coverage::CellLayouts>>> =
            (0..cells.len()).map(|_| None).collect();
        let layouts = search.layouts_on(&grid, &cells, &boxes, &mut own).unwrap();
        let plans: Vec<CellPlan> = layouts
            .iter()
            .zip(&cells)
            .map(|(l, c)| l.as_ref().unwrap().best_plan(c, &free_space).unwrap())
            .collect();
        let between = cells
            .iter()
            .position(|c| {
                let r = geo::BoundingRect::bounding_rect(c).unwrap();
                (r.min().x - 75.0).abs() < 1e-6 && (r.max().x - 125.0).abs() < 1e-6
            })
            .unwrap();
        // On the grid: lines 90 and 110, and slivers at 77.5 and 122.5
        // (lines 70 and 130 run into the zones there).
        assert_eq!(plans[between].lanes.len(), 3);
        let lanes: usize = plans.iter().map(|p| p.lanes.len()).sum();
        // 3 + 2 + 2 + 3 + 2 + 2 + 3: the outer cells fly their slivers
        // against the zones, 42.5 and 157.5 m.
        assert_eq!(lanes, 17);
        let strips = judge.strip_coverage(&plans);
        assert!(strips > 1.0 - 1e-5, "strips cover {strips}");
    }

    fn l_field() -> MultiPolygon<f64> {
        let outer = polygon![
            (x: 0.0, y: 0.0), (x: 600.0, y: 0.0), (x: 600.0, y: 250.0),
            (x: 250.0, y: 250.0), (x: 250.0, y: 500.0), (x: 0.0, y: 500.0),
        ];
        let hole = polygon![(x: 100.0, y: 100.0), (x: 160.0, y: 100.0), (x: 160.0, y: 160.0), (x: 100.0, y: 160.0)];
        MultiPolygon(vec![Polygon::new(
            outer.exterior().clone(),
            vec![hole.exterior().clone()],
        )])
    }

    fn whole_length(
        d: &Decomposition,
        start: Coord<f64>,
        free: &MultiPolygon<f64>,
        obstacles: &ObstacleMap,
    ) -> f64 {
        crate::flock::plan_tour(start, &d.plans, &d.cells, free, obstacles)
            .unwrap()
            .length_m()
    }

    /// `auto` over whole plans flies no more than any single candidate
    /// angle does (each planned whole the same way), covers the target and
    /// keeps every lane inside the field.
    #[test]
    fn whole_plan_auto_is_the_shortest_candidate() {
        let free = l_field();
        let hole = MultiPolygon(vec![
            polygon![(x: 100.0, y: 100.0), (x: 160.0, y: 100.0), (x: 160.0, y: 160.0), (x: 100.0, y: 160.0)],
        ]);
        let obstacles = ObstacleMap::new(&hole, 0.0);
        let start = Coord { x: -20.0, y: -20.0 };
        let compare = Compare::WholePlan {
            start,
            obstacles: &obstacles,
            free: &free,
            footprint_side_m: 30.0,
        };
        let spacing = 25.0;
        let auto = decompose_and_cover(&free, SliceAngle::Auto, spacing, &compare).unwrap();
        let auto_len = whole_length(&auto, start, &free, &obstacles);
        let cover =
            |plans: &[CellPlan], side: f64| super::super::cells::coverage(plans, side, &free).1;
        assert!(cover(&auto.plans, 30.0) >= COVERAGE_TARGET);
        let auto_strips = cover(&auto.plans, spacing);
        let mut rivals = 0;
        for a in auto_candidates(&free) {
            let one =
                decompose_and_cover(&free, SliceAngle::Degrees(a), spacing, &compare).unwrap();
            // Every angle covering as much as auto's plan was eligible.
            if cover(&one.plans, 30.0) >= COVERAGE_TARGET
                && cover(&one.plans, spacing) >= auto_strips - 1e-6
            {
                rivals += 1;
                let len = whole_length(&one, start, &free, &obstacles);
                assert!(
                    auto_len <= len + 1e-6,
                    "angle {a}: {len} < auto's {auto_len}"
                );
            }
        }
        assert!(rivals >= 1, "auto's own angle is among the candidates");
        // Merged cells cover the field exactly.
        let area: f64 = auto.cells.iter().map(|c| c.unsigned_area()).sum();
        assert!((area - free.unsigned_area()).abs() < 1e-6 * free.unsigned_area());
        assert_eq!(auto.joined.len(), auto.cells.len());
    }

    /// Property: on random fields (a jittered convex-ish outline with up to
    /// four rectangular no-fly holes) at random line spacings, the merged
    /// cells of the whole-plan `auto` tile the free space exactly, and its
    /// plan never covers less than the fewest-turns plan of unmerged cells:
    /// lane strips (one spacing wide) at least as much, and footprints at
    /// least the coverage target whenever the fewest-turns plan reaches it.
    #[test]
    fn merged_cells_never_lose_coverage() {
        let mut rng = crate::test_rng::Lcg(0x5eed_2101);
        let mut checked = 0;
        for case in 0..24 {
            let n = 6 + (rng.next() * 9.0) as usize;
            let (cx, cy) = (300.0, 250.0);
            let outline: Vec<Coord<f64>> = (0..n)
                .map(|k| {
                    let t = std::f64::consts::TAU * (k as f64 + 0.3 * rng.next()) / n as f64;
                    let r = 90.0 + 210.0 * rng.next();
                    Coord {
                        x: cx + r * t.cos(),
                        y: cy + r * t.sin(),
                    }
                })
                .collect();
            let mut holes = Vec::new();
            for _ in 0..(rng.next() * 40.0) as usize {
                let (x, y) = (
                    cx - 150.0 + 300.0 * rng.next(),
                    cy - 150.0 + 300.0 * rng.next(),
                );
                let (w, h) = (2.0 + 8.0 * rng.next(), 2.0 + 8.0 * rng.next());
                let hole = polygon![(x: x, y: y), (x: x + w, y: y), (x: x + w, y: y + h), (x: x, y: y + h)];
                if holes
                    .iter()
                    .all(|o: &Polygon<f64>| !geo::Intersects::intersects(o, &hole))
                {
                    holes.push(hole);
                }
            }
            // Holes may reach past a star-shaped outline: the free space is
            // the difference, as the survey computes it.
            let outline = Polygon::new(geo_types::LineString::from(outline), vec![]);
            let free = geo::BooleanOps::difference(&outline, &MultiPolygon(holes.clone()));
            let obstacles = ObstacleMap::new(&MultiPolygon(holes.clone()), 0.0);
            let spacing = 25.0 + 35.0 * rng.next();
            let footprint = spacing / 0.7;
            let compare = Compare::WholePlan {
                start: Coord { x: cx, y: -200.0 },
                obstacles: &obstacles,
                free: &free,
                footprint_side_m: footprint,
            };
            let whole = decompose_and_cover(&free, SliceAngle::Auto, spacing, &compare).unwrap();
            let fewest =
                decompose_and_cover(&free, SliceAngle::Auto, spacing, &Compare::FewestTurns)
                    .unwrap();
            let area: f64 = whole.cells.iter().map(|c| c.unsigned_area()).sum();
            let total = free.unsigned_area();
            assert!(
                (area - total).abs() < 1e-6 * total,
                "case {case}: {area} of {total}"
            );
            let cover =
                |plans: &[CellPlan], side: f64| super::super::cells::coverage(plans, side, &free).1;
            let (strips_whole, strips_fewest) =
                (cover(&whole.plans, spacing), cover(&fewest.plans, spacing));
            assert!(
                strips_whole >= strips_fewest - 1e-6,
                "case {case}: strips {strips_whole} < fewest turns' {strips_fewest}"
            );
            if cover(&fewest.plans, footprint) >= COVERAGE_TARGET {
                assert!(
                    cover(&whole.plans, footprint) >= COVERAGE_TARGET,
                    "case {case}: footprints below the target"
                );
            }
            checked += usize::from(whole.joined.iter().any(|&j| j));
            // At fixed angles too, where cells are joined whatever is
            // shortest: the joined lanes cover what the split cells' do.
            for angle in [0.0, 37.0, 90.0, 128.0] {
                let at = SliceAngle::Degrees(angle);
                let merged = decompose_and_cover(&free, at, spacing, &compare).unwrap();
                let split = decompose_and_cover(&free, at, spacing, &Compare::FewestTurns).unwrap();
                let area: f64 = merged.cells.iter().map(|c| c.unsigned_area()).sum();
                assert!(
                    (area - total).abs() < 1e-6 * total,
                    "case {case} at {angle}°"
                );
                let (m, u) = (cover(&merged.plans, spacing), cover(&split.plans, spacing));
                let (mf, uf) = (
                    cover(&merged.plans, footprint),
                    cover(&split.plans, footprint),
                );
                assert!(
                    m >= u - 1e-6 && mf >= uf - 1e-6,
                    "case {case} at {angle}°: merged strips {m}, footprints {mf}; split {u}, {uf}"
                );
                checked += usize::from(merged.joined.iter().any(|&j| j));
            }
        }
        // The property is about joined cells: some cases must have them.
        assert!(checked >= 3, "only {checked} cases with joined cells");
    }

    /// Fewer turns than the merged plan's, never: a plane's `auto` keeps
    /// the fewest turns.
    #[test]
    fn fewest_turns_keeps_the_fewest_turns() {
        let free = l_field();
        let spacing = 25.0;
        let d =
            decompose_and_cover(&free, SliceAngle::Auto, spacing, &Compare::FewestTurns).unwrap();
        let turns: usize = d.plans.iter().map(CellPlan::turns).sum();
        for a in auto_candidates(&free) {
            let one = decompose_and_cover(
                &free,
                SliceAngle::Degrees(a),
                spacing,
                &Compare::FewestTurns,
            )
            .unwrap();
            let t: usize = one.plans.iter().map(CellPlan::turns).sum();
            assert!(turns <= t, "angle {a}: {t} turns < auto's {turns}");
        }
        assert!(d.joined.iter().all(|j| !j));
    }
}
