//! The replanning rules (SPEC §4.3): how blocked areas and cost changes
//! change the cells of a costmap, which ends of a route they may not
//! block, and how a D* Lite search is repaired for them.
//!
//! Blocked areas make their cells obstacles; a cost change sets the cost
//! of its cells that are still traversable. A cost change never makes an
//! obstacle (of the costmap or a blocked area) traversable, and among cost
//! changes the later one wins.

use std::collections::BTreeMap;

use geo_types::Polygon;

use super::{Cell, CostGrid, DStarLite, GridError, MapRouteError, Route, RouteError, RouteMap};

/// Which area of the changes, by its index in the list it was given in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChangedArea {
    /// The cost change at this index.
    Cost(usize),
    /// The blocked area at this index.
    Blocked(usize),
}

/// An area that cannot be put on the map, and why.
#[derive(Clone, Debug, PartialEq)]
pub struct AreaFault {
    pub area: ChangedArea,
    pub reason: String,
}

/// Why changes could not be put on a map.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ChangeError {
    /// Areas at fault: for each run of cost changes of equal cost, and
    /// for the blocked areas, the first one that does not fit.
    #[error("{} area(s) cannot be put on the costmap", .0.len())]
    Areas(Vec<AreaFault>),
    #[error(transparent)]
    Map(MapRouteError),
}

/// An end of the route that a replan's changes would block: a replan
/// starts where the vehicle is and keeps the goal.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BlockedEnd {
    /// The start, by a blocked area of these changes.
    #[error("the position is inside an area this replan blocks")]
    Start,
    /// The start, already blocked before these changes.
    #[error("the position is inside an area an earlier replan blocked")]
    StartEarlier,
    /// The goal, by the blocked area at index `area` (the first covering
    /// it; `None` when none alone does).
    #[error("this area covers the route's goal: a replan keeps the goal, which cannot be blocked")]
    Goal { area: Option<usize> },
}

/// Changes rasterised to cells: cost changes in runs of equal cost (one
/// pass over the grid per run), then the blocked cells.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CellChanges {
    costs: Vec<(Vec<usize>, f32)>,
    blocked: Vec<usize>,
}

impl CellChanges {
    /// The cells of `cost_changes` (in order, each area with its new
    /// cost) and of `blocked`, by [`RouteMap::cells_in_areas`].
    pub fn rasterise(
        map: &RouteMap,
        cost_changes: &[(&Polygon<f64>, f64)],
        blocked: &[&Polygon<f64>],
    ) -> Result<CellChanges, ChangeError> {
        let mut faults = Vec::new();
        let mut costs = Vec::new();
        let mut first = 0;
        for run in cost_changes.chunk_by(|a, b| a.1 == b.1) {
            let areas: Vec<&Polygon<f64>> = run.iter().map(|(a, _)| *a).collect();
            let offset = first;
            let cells = area_cells(map, &areas, |i| ChangedArea::Cost(offset + i), &mut faults)?;
            costs.push((cells, run[0].1 as f32));
            first += run.len();
        }
        let blocked = if blocked.is_empty() {
            Vec::new()
        } else {
            area_cells(map, blocked, ChangedArea::Blocked, &mut faults)?
        };
        if faults.is_empty() {
            Ok(CellChanges { costs, blocked })
        } else {
            Err(ChangeError::Areas(faults))
        }
    }

    /// The cells the blocked areas cover (obstacles already or not):
    /// row-major indices, sorted, no repeats.
    pub fn blocked(&self) -> &[usize] {
        &self.blocked
    }

    /// The new value of every cell these change on a grid of `costs`: a
    /// cost change sets traversable cells (the later wins), blocking makes
    /// them obstacles (NaN); obstacles stay as they are.
    pub fn on(&self, costs: &[f32]) -> BTreeMap<usize, f32> {
        let mut out = BTreeMap::new();
        for (cells, cost) in &self.costs {
            for &i in cells {
                if costs[i].is_finite() {
                    out.insert(i, *cost);
                }
            }
        }
        for &i in &self.blocked {
            if costs[i].is_finite() {
                out.insert(i, f32::NAN);
            }
        }
        out
    }

    /// `grid` with these changes made.
    pub fn apply_to(&self, grid: CostGrid) -> Result<CostGrid, GridError> {
        let changed = self.on(grid.costs());
        with_changes(grid, &changed)
    }
}

/// The cells of `areas` (their union). An area that does not fit is a
/// fault, named by `name` from its index, and contributes no cell.
fn area_cells(
    map: &RouteMap,
    areas: &[&Polygon<f64>],
    name: impl Fn(usize) -> ChangedArea,
    faults: &mut Vec<AreaFault>,
) -> Result<Vec<usize>, ChangeError> {
    let polygons: Vec<Polygon<f64>> = areas.iter().map(|&a| a.clone()).collect();
    match map.cells_in_areas(&polygons) {
        Ok(cells) => Ok(cells),
        Err(MapRouteError::InvalidArea { index, reason }) => {
            faults.push(AreaFault {
                area: name(index),
                reason,
            });
            Ok(Vec::new())
        }
        Err(e) => Err(ChangeError::Map(e)),
    }
}

/// `grid` with the cells of `changed` set to their new values.
pub fn with_changes(grid: CostGrid, changed: &BTreeMap<usize, f32>) -> Result<CostGrid, GridError> {
    let (width, height, dy) = (grid.width(), grid.height(), grid.dy());
    let dx = grid.dx_per_row().to_vec();
    let mut costs = grid.into_costs();
    for (&i, &c) in changed {
        costs[i] = c;
    }
    CostGrid::new(width, height, costs, dx, dy)
}

/// Neither end of a replan may end up blocked: `costs` are the grid's
/// before these changes, `changed` what they make of it, `blocked` the
/// changes' blocked areas (to name the one covering the goal).
pub fn check_ends(
    map: &RouteMap,
    blocked: &[&Polygon<f64>],
    costs: &[f32],
    changed: &BTreeMap<usize, f32>,
    start: Cell,
    goal: Cell,
) -> Result<(), BlockedEnd> {
    let width = map.grid().width();
    let after = |i: usize| changed.get(&i).copied().unwrap_or(costs[i]);
    let (s, g) = (start.0 * width + start.1, goal.0 * width + goal.1);
    if !after(s).is_finite() {
        return Err(if costs[s].is_finite() {
            BlockedEnd::Start
        } else {
            BlockedEnd::StartEarlier
        });
    }
    if !after(g).is_finite() {
        // Only blocked areas make obstacles, and the goal was on
        // traversable ground before: one of these areas covers it.
        let area = blocked.iter().position(|&a| {
            map.cells_in_areas(std::slice::from_ref(a))
                .is_ok_and(|c| c.binary_search(&g).is_ok())
        });
        return Err(BlockedEnd::Goal { area });
    }
    Ok(())
}

/// Whether `search` can be repaired for a replan to `goal` on a map of
/// `cells` cells (else it is rebuilt).
pub fn can_repair(search: &DStarLite, goal: Cell, cells: usize) -> bool {
    search.goal() == goal && search.grid().cell_count() == cells
}

/// A search that could not be repaired.
#[derive(Debug)]
pub struct RepairFailure {
    pub error: RouteError,
    /// Whether the changes were undone, leaving the search as it was
    /// (D* Lite repairs it on its next plan): worth keeping.
    pub restored: bool,
}

/// Repair `search` for `changed` (as [`CellChanges::on`] gives them) and
/// the vehicle now at `start`, and plan. When that fails (unreachable,
/// cancelled, over its limit), the changes are undone.
pub fn repair(
    search: &mut DStarLite,
    changed: &BTreeMap<usize, f32>,
    start: Cell,
    cancel: &dyn Fn() -> bool,
) -> Result<Route, RepairFailure> {
    let costs = search.grid().costs();
    let undo: Vec<(usize, f32)> = changed.keys().map(|&i| (i, costs[i])).collect();
    let changed: Vec<(usize, f32)> = changed.iter().map(|(&i, &c)| (i, c)).collect();
    let planned = search
        .update_cells(&changed)
        .and_then(|()| search.move_start(start))
        .and_then(|()| search.plan(cancel));
    planned.map_err(|error| RepairFailure {
        error,
        restored: search.update_cells(&undo).is_ok(),
    })
}

#[cfg(test)]
mod tests {
    use geo_types::{Coord, LineString};

    use super::*;
    use crate::route::{RouteOptions, astar};
    use crate::terrain::{Crs, GeoTransform};

    /// Degrees per cell of the test map.
    const CELL: f64 = 0.001;

    /// A `w` × `h` map in WGS84 with its north-west corner at 10°E 45°N,
    /// cost 1 except where `blocked` says.
    fn map(w: usize, h: usize, blocked: impl Fn(usize, usize) -> bool) -> RouteMap {
        let costs = (0..w * h)
            .map(|i| if blocked(i / w, i % w) { f32::NAN } else { 1.0 })
            .collect();
        let t = GeoTransform {
            origin_x: 10.0,
            pixel_width: CELL,
            col_rotation: 0.0,
            origin_y: 45.0,
            row_rotation: 0.0,
            pixel_height: -CELL,
        };
        RouteMap::new(w, h, t, Crs::from_epsg(4326).unwrap(), costs, None, None).unwrap()
    }

    /// A rectangle covering the cells of rows `rows` and columns `cols`
    /// (and no other: its edges run through those cells, a quarter cell
    /// in from their sides).
    fn cells(rows: [usize; 2], cols: [usize; 2]) -> Polygon<f64> {
        let lon = |c: f64| 10.0 + c * CELL;
        let lat = |r: f64| 45.0 - r * CELL;
        let (w, e) = (lon(cols[0] as f64 + 0.25), lon(cols[1] as f64 + 0.75));
        let (n, s) = (lat(rows[0] as f64 + 0.25), lat(rows[1] as f64 + 0.75));
        Polygon::new(
            LineString(vec![
                Coord { x: w, y: s },
                Coord { x: e, y: s },
                Coord { x: e, y: n },
                Coord { x: w, y: n },
                Coord { x: w, y: s },
            ]),
            vec![],
        )
    }

    /// Equal costs, NaN (an obstacle) equal to NaN.
    fn same_costs(a: &CostGrid, b: &CostGrid) -> bool {
        a.cell_count() == b.cell_count()
            && a.costs()
                .iter()
                .zip(b.costs())
                .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
    }

    fn not_finite() -> Polygon<f64> {
        let mut p = cells([0, 0], [0, 0]);
        p.exterior_mut(|r| r.0[1].x = f64::NAN);
        p
    }

    #[test]
    fn cell_changes_keep_obstacles_and_let_blocking_win() {
        let changes = CellChanges {
            costs: vec![(vec![0, 1, 2], 5.0), (vec![1], 7.0)],
            blocked: vec![2, 3],
        };
        let costs = [1.0, 1.0, 1.0, 1.0, f32::NAN];
        let on = changes.on(&costs);
        assert_eq!(on.get(&0), Some(&5.0));
        assert_eq!(on.get(&1), Some(&7.0), "the later cost change wins");
        assert!(on[&2].is_nan() && on[&3].is_nan(), "blocking wins");
        assert!(!on.contains_key(&4), "obstacles stay");
    }

    #[test]
    fn areas_become_cells_and_later_cost_changes_win() {
        // Column 2 of a 5 × 4 map is an obstacle.
        let m = map(5, 4, |_, c| c == 2);
        let (wide, corner) = (cells([0, 1], [0, 3]), cells([0, 0], [0, 0]));
        let changes = CellChanges::rasterise(&m, &[(&wide, 4.0), (&corner, 9.0)], &[]).unwrap();
        assert!(changes.blocked().is_empty());
        let grid = changes.apply_to(m.grid().clone()).unwrap();
        let c = grid.costs();
        assert_eq!(c[0], 9.0, "the later change wins");
        assert_eq!([c[1], c[3], c[5], c[6], c[8]], [4.0; 5]);
        assert!(c[2].is_nan() && c[7].is_nan(), "obstacles stay obstacles");
        assert_eq!(c[4], 1.0, "column 4 is outside both areas");
        assert_eq!(c[10], 1.0, "row 2 is outside both areas");

        let block = cells([1, 2], [3, 3]);
        let both = CellChanges::rasterise(&m, &[(&wide, 4.0)], &[&block]).unwrap();
        assert_eq!(both.blocked(), [8, 13]);
        let c = both.apply_to(m.grid().clone()).unwrap().into_costs();
        assert_eq!(c[3], 4.0);
        assert!(c[8].is_nan(), "blocking wins over a cost change");
        assert!(c[13].is_nan());
    }

    #[test]
    fn areas_at_fault_are_named_by_list_and_index() {
        let m = map(5, 4, |_, _| false);
        let ok = cells([0, 0], [0, 0]);
        let bad = not_finite();
        let Err(ChangeError::Areas(faults)) = CellChanges::rasterise(
            &m,
            &[(&ok, 2.0), (&bad, 2.0), (&ok, 3.0), (&bad, 4.0)],
            &[&ok, &bad],
        ) else {
            panic!("accepted an area with a NaN vertex");
        };
        let named: Vec<ChangedArea> = faults.iter().map(|f| f.area).collect();
        assert_eq!(
            named,
            [
                ChangedArea::Cost(1),
                ChangedArea::Cost(3),
                ChangedArea::Blocked(1)
            ]
        );
        assert_eq!(faults[0].reason, "a vertex is not a finite number");
    }

    #[test]
    fn blocked_ends_are_refused() {
        // Cell (1, 1) was blocked by an earlier replan.
        let m = map(6, 3, |r, c| (r, c) == (1, 1));
        let costs = m.grid().costs();
        let (start, goal) = ((1, 0), (1, 5));
        let (near_goal, over_goal) = (cells([0, 0], [3, 3]), cells([0, 2], [4, 5]));
        let changes = CellChanges::rasterise(&m, &[], &[&near_goal, &over_goal]).unwrap();
        let changed = changes.on(costs);
        let blocked = [&near_goal, &over_goal];
        assert_eq!(
            check_ends(&m, &blocked, costs, &changed, start, goal),
            Err(BlockedEnd::Goal { area: Some(1) })
        );
        let changes = CellChanges::rasterise(&m, &[], &[&near_goal]).unwrap();
        let changed = changes.on(costs);
        assert_eq!(
            check_ends(&m, &[&near_goal], costs, &changed, start, goal),
            Ok(())
        );
        assert_eq!(
            check_ends(&m, &[&near_goal], costs, &changed, (0, 3), goal),
            Err(BlockedEnd::Start)
        );
        assert_eq!(
            check_ends(&m, &[&near_goal], costs, &changed, (1, 1), goal),
            Err(BlockedEnd::StartEarlier)
        );
    }

    #[test]
    fn repairs_match_a_search_from_scratch_and_failures_are_undone() {
        let m = map(12, 9, |_, _| false);
        let options = RouteOptions::default();
        let (start, goal) = ((4, 0), (4, 11));
        let mut search = DStarLite::new(m.grid().clone(), start, goal, options.clone()).unwrap();
        let first = search.plan(&|| false).unwrap();
        let open = astar(m.grid(), start, goal, &options, &|| false).unwrap();
        assert!((first.cost - open.cost).abs() <= 1e-9 * open.cost);
        let straight = astar(m.grid(), (4, 2), goal, &options, &|| false).unwrap();
        assert!(can_repair(&search, goal, m.grid().cell_count()));
        assert!(!can_repair(&search, (0, 0), m.grid().cell_count()));

        // A wall across column 6 but for row 0, and the vehicle at (4, 2).
        let wall = cells([1, 8], [6, 6]);
        let changes = CellChanges::rasterise(&m, &[], &[&wall]).unwrap();
        let changed = changes.on(search.grid().costs());
        let mut scratch_grid = changes.apply_to(m.grid().clone()).unwrap();
        let repaired = repair(&mut search, &changed, (4, 2), &|| false).unwrap();
        let scratch = astar(&scratch_grid, (4, 2), goal, &options, &|| false).unwrap();
        assert!(
            (repaired.cost - scratch.cost).abs() <= 1e-9 * scratch.cost,
            "{} against {}",
            repaired.cost,
            scratch.cost
        );
        assert!(
            repaired.cost > straight.cost * (1.0 + 1e-6),
            "the wall is not gone round"
        );
        assert!(same_costs(search.grid(), &scratch_grid));

        // Closing the gap cuts the goal off: the failure leaves the search
        // as it was, and it plans the same route again.
        let gap = cells([0, 0], [6, 6]);
        let changes = CellChanges::rasterise(&m, &[], &[&gap]).unwrap();
        let changed = changes.on(search.grid().costs());
        let failed = repair(&mut search, &changed, (4, 2), &|| false).unwrap_err();
        assert_eq!(failed.error, RouteError::Unreachable);
        assert!(failed.restored);
        assert!(same_costs(search.grid(), &scratch_grid));
        let again = search.plan(&|| false).unwrap();
        assert!((again.cost - repaired.cost).abs() <= 1e-9 * repaired.cost);

        // The same closure from scratch.
        scratch_grid = with_changes(scratch_grid, &changed).unwrap();
        assert_eq!(
            astar(&scratch_grid, (4, 2), goal, &options, &|| false).unwrap_err(),
            RouteError::Unreachable
        );
    }
}
