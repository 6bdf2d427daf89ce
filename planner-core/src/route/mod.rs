//! UGV routes: the cheapest safe path across a traversability costmap
//! (SPEC §4.3, thesis §2.3 and §3.6.4), one algorithm per file:
//!
//! - [`astar()`]: A* on dense arrays (optionally weighted by `epsilon`),
//!   16 bytes per cell including the costs;
//! - [`DStarLite`]: incremental replanning when cells become blocked or
//!   change cost (Koenig & Likhachev 2002, optimised version), its first
//!   search guided by A*'s costs (`landmark`), 21 bytes per cell including
//!   the costs;
//! - [`coarse_to_fine()`]: routes on maps too big for A*'s arrays: A* on
//!   block minima places a corridor, A* inside it reads the costs on
//!   demand through an LRU of tiles (`tile_cache`, from a [`CostSource`])
//!   with state only for the corridor blocks it touches
//!   (`corridor_search`), and a coarse lower bound (`coarse_bound`)
//!   proves the route optimal for the whole grid or widens the corridor;
//! - [`smooth`]: post-smoothing of a cell path into a few waypoints;
//! - [`changes`]: the replanning rules, how blocked areas and cost
//!   changes change cells and how a D* Lite search is repaired for them;
//!
//! and their parts: the 8-neighbourhood and step lengths
//! (`neighbourhood`), the arc rules and heuristic (`arc_model`), a tiled
//! copy of the costs (`tiles`), the open list (`bucket_queue`), D* Lite's
//! landmark heuristic (`landmark`) and a lazily infinite f64 array
//! (`dist_array`).
//!
//! Searches never hang: they end when the goal is reached or the open list
//! is empty, `RouteOptions::max_expansions` bounds them, and the
//! cancellation hook (`&dyn Fn() -> bool`, true = stop) is asked every
//! [`CANCEL_CHECK_INTERVAL`] expansions. They allocate per call and share
//! nothing, so several may run on threads at once.
//!
//! The search graph, shared by all of them: every finite cost is a
//! traversable cell, 8-connected, and a diagonal move is allowed only when
//! both orthogonal cells it passes between are traversable (no corner
//! cutting). Step lengths come from the cell size in metres: `dx(row)`
//! horizontally, `dy` vertically, and for a diagonal between rows r and r+1
//! `√(((dx(r) + dx(r+1))/2)² + dy²)`. The arc cost of a step is given by
//! [`ArcCost`].
//!
//! Cells are `(row, col)`; row 0 is the first row of the cost array.

mod arc_model;
pub mod astar;
mod block_minima;
mod bucket_queue;
pub mod changes;
mod coarse_bound;
mod coarse_route;
pub mod coarse_to_fine;
mod corridor_search;
pub mod cost_source;
mod dist_array;
pub mod dstar_lite;
mod landmark;
pub mod map_route;
mod neighbourhood;
pub mod on_map;
mod pages;
pub mod smooth;
#[cfg(test)]
mod testing;
mod tile_cache;
mod tiles;
pub mod windowed_heights;
pub mod windowed_map;

pub use astar::astar;
pub use changes::{BlockedEnd, CellChanges, ChangeError, ChangedArea};
pub use coarse_to_fine::{
    BigRouteError, CoarseToFine, CoarseToFineOptions, CoarseToFineStats, coarse_to_fine,
    coarse_to_fine_route,
};
pub use cost_source::{CostSource, CostSourceError, WindowCosts};
pub use dstar_lite::DStarLite;
pub use map_route::{MapRoute, RoutePoint};
pub use on_map::{Endpoint, MapRouteError, Position, RouteMap};
pub use smooth::{SegmentCost, polyline_cost, segment_cost, smooth_path, turning_points};
pub use windowed_heights::AveragedHeights;
pub use windowed_map::{WindowedMap, WindowedRouteError};

use serde::{Deserialize, Serialize};

use crate::geo::Issue;
use arc_model::ArcModel;
use neighbourhood::Neighbourhood;

/// A grid cell as `(row, col)`.
pub type Cell = (usize, usize);

/// How often (in expanded cells) a search asks its cancellation hook.
pub const CANCEL_CHECK_INTERVAL: u64 = 1024;

/// A costmap to plan on: row-major costs with the cell size in metres.
///
/// A finite cost is a traversable cell (it must be > 0; costmaps use
/// [1, 20]); a non-finite cost (NaN, ±∞) is an obstacle or unknown terrain.
/// `dx` is given per row so that geographic grids, whose cells are narrower
/// towards the poles, keep true metres; a UTM grid has the same `dx` in
/// every row.
#[derive(Clone, Debug, PartialEq)]
pub struct CostGrid {
    width: usize,
    height: usize,
    costs: Vec<f32>,
    dx: Vec<f64>,
    dy: f64,
}

/// Why a [`CostGrid`] could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GridError {
    #[error("the cost grid is empty ({width} columns × {height} rows)")]
    Empty { width: usize, height: usize },
    #[error(
        "the cost grid has {cells} cells; at most {max} are supported \
         (with both sides rounded up to multiples of 16)"
    )]
    TooLarge { cells: u128, max: u64 },
    #[error("expected {expected} costs (columns × rows), got {got}")]
    CostCount { expected: usize, got: usize },
    #[error("expected one cell width (dx) per row, {expected} in all, got {got}")]
    DxCount { expected: usize, got: usize },
    #[error("the cell width dx of row {row} is {value}; it must be a finite number of metres > 0")]
    InvalidDx { row: usize, value: f64 },
    #[error("the cell height dy is {value}; it must be a finite number of metres > 0")]
    InvalidDy { value: f64 },
    #[error(
        "the cost at row {row}, column {col} is {value}; a traversable cell needs a cost > 0 \
         (mark obstacles and unknown cells with a non-finite value)"
    )]
    NonPositiveCost { row: usize, col: usize, value: f32 },
}

impl CostGrid {
    /// Largest supported grid, counted with its sides rounded up to
    /// multiples of 16: searches index cells with `u32`.
    pub const MAX_CELLS: u64 = u32::MAX as u64;

    /// A grid with one cell width `dx[row]` per row and a common cell
    /// height `dy` (metres).
    pub fn new(
        width: usize,
        height: usize,
        costs: Vec<f32>,
        dx: Vec<f64>,
        dy: f64,
    ) -> Result<CostGrid, GridError> {
        if width == 0 || height == 0 {
            return Err(GridError::Empty { width, height });
        }
        // Searches index the grid padded to whole 16 × 16 tiles with u32.
        let padded = (width as u128).div_ceil(16) * 16 * (height as u128).div_ceil(16) * 16;
        if padded > u128::from(Self::MAX_CELLS) {
            return Err(GridError::TooLarge {
                cells: width as u128 * height as u128,
                max: Self::MAX_CELLS,
            });
        }
        let expected = width * height;
        if costs.len() != expected {
            return Err(GridError::CostCount {
                expected,
                got: costs.len(),
            });
        }
        if dx.len() != height {
            return Err(GridError::DxCount {
                expected: height,
                got: dx.len(),
            });
        }
        if let Some((row, &value)) = dx
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v > 0.0))
        {
            return Err(GridError::InvalidDx { row, value });
        }
        if !(dy.is_finite() && dy > 0.0) {
            return Err(GridError::InvalidDy { value: dy });
        }
        if let Some((i, &value)) = costs
            .iter()
            .enumerate()
            .find(|(_, c)| c.is_finite() && **c <= 0.0)
        {
            return Err(GridError::NonPositiveCost {
                row: i / width,
                col: i % width,
                value,
            });
        }
        Ok(CostGrid {
            width,
            height,
            costs,
            dx,
            dy,
        })
    }

    /// A grid whose cells are all `dx` × `dy` metres (a projected grid).
    pub fn with_cell_size(
        width: usize,
        height: usize,
        costs: Vec<f32>,
        dx: f64,
        dy: f64,
    ) -> Result<CostGrid, GridError> {
        Self::new(width, height, costs, vec![dx; height], dy)
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Number of cells (width × height).
    pub fn cell_count(&self) -> usize {
        self.costs.len()
    }

    /// Row-major costs.
    pub fn costs(&self) -> &[f32] {
        &self.costs
    }

    pub fn into_costs(self) -> Vec<f32> {
        self.costs
    }

    /// Cell width in metres of `row`.
    pub fn dx(&self, row: usize) -> f64 {
        self.dx[row]
    }

    pub fn dx_per_row(&self) -> &[f64] {
        &self.dx
    }

    /// Cell height in metres.
    pub fn dy(&self) -> f64 {
        self.dy
    }

    pub fn contains(&self, (row, col): Cell) -> bool {
        row < self.height && col < self.width
    }

    /// Row-major index of a cell, `None` outside the grid.
    pub fn index(&self, cell: Cell) -> Option<usize> {
        self.contains(cell).then(|| cell.0 * self.width + cell.1)
    }

    /// The cell at a row-major index, `None` outside the grid.
    pub fn cell(&self, index: usize) -> Option<Cell> {
        (index < self.costs.len()).then(|| (index / self.width, index % self.width))
    }

    /// The cost of a cell, `None` outside the grid.
    pub fn cost(&self, cell: Cell) -> Option<f32> {
        self.index(cell).map(|i| self.costs[i])
    }

    /// Inside the grid and not an obstacle.
    pub fn is_traversable(&self, cell: Cell) -> bool {
        self.cost(cell).is_some_and(f32::is_finite)
    }

    /// Smallest and largest finite cost, `None` if every cell is blocked.
    pub fn finite_cost_range(&self) -> Option<(f32, f32)> {
        finite_range(&self.costs)
    }

    pub(crate) fn costs_mut(&mut self) -> &mut [f32] {
        &mut self.costs
    }

    /// The index of a search endpoint, checked: inside and traversable.
    fn endpoint(&self, cell: Cell, end: End) -> Result<usize, RouteError> {
        let (row, col) = cell;
        let (width, height) = (self.width, self.height);
        let Some(i) = self.index(cell) else {
            return Err(match end {
                End::Start => RouteError::StartOutside {
                    row,
                    col,
                    width,
                    height,
                },
                End::Goal => RouteError::GoalOutside {
                    row,
                    col,
                    width,
                    height,
                },
            });
        };
        if !self.costs[i].is_finite() {
            return Err(match end {
                End::Start => RouteError::StartBlocked { row, col },
                End::Goal => RouteError::GoalBlocked { row, col },
            });
        }
        Ok(i)
    }
}

pub(crate) fn finite_range(costs: &[f32]) -> Option<(f32, f32)> {
    use rayon::prelude::*;
    let fold = |(lo, hi): (f32, f32), &c: &f32| {
        if c.is_finite() {
            (lo.min(c), hi.max(c))
        } else {
            (lo, hi)
        }
    };
    let empty = (f32::INFINITY, f32::NEG_INFINITY);
    // In parallel: a search on a large map starts with this pass.
    let (lo, hi) = costs
        .par_chunks(1 << 16)
        .map(|chunk| chunk.iter().fold(empty, fold))
        .reduce(|| empty, |a, b| (a.0.min(b.0), a.1.max(b.1)));
    (lo <= hi).then_some((lo, hi))
}

#[derive(Clone, Copy)]
enum End {
    Start,
    Goal,
}

/// The cost of one step (arc) between neighbouring cells.
///
/// Both rules scale the step length in metres, so the octile distance times
/// the smallest factor is an admissible, consistent A* heuristic.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "mode", rename_all = "snake_case", deny_unknown_fields)]
pub enum ArcCost {
    /// Step length × (cost(a) + cost(b)) / 2: the line integral of the cost
    /// along the step, the rule of scikit-image's `MCP_Geometric`. A route's
    /// cost is then the cost-weighted distance, and expensive cells are
    /// avoided in proportion to their cost.
    #[default]
    Integrated,
    /// The thesis' Algorithm 1: step length × c, with
    /// c = 1 + (d_max − 1)·(δ + R)/(2R) ∈ [1, d_max], δ = cost(next) −
    /// cost(current) and R = max − min of the map's finite costs. The
    /// thesis shifts δ ∈ [−19, 19] by max = 20 to [1, 39] for its [1, 20]
    /// costs, normalises to [0, 1] and remaps to [1, d_max]; this is the
    /// same map written for any cost range (identical when min = 1). On a
    /// map of one uniform cost (R = 0) c is the midpoint (1 + d_max)/2.
    ///
    /// **Why it is not the default:** the cost-difference term nearly
    /// telescopes. Writing c = A + K·δ with A = (1 + d_max)/2 and
    /// K = (d_max − 1)/(2R), a path of steps L_i between cells
    /// q_0 … q_n costs A·Σ L_i + K·Σ L_i (q_i − q_{i−1}), and summation by
    /// parts gives Σ L_i (q_i − q_{i−1}) = L_n q_n − L_1 q_0 +
    /// Σ_{0<j<n} q_j (L_j − L_{j+1}). A cell's cost only counts where the
    /// step length changes (orthogonal ↔ diagonal turns, ±(√2 − 1)·cell),
    /// never along a straight run, so the route is close to the shortest
    /// traversable one and barely steers away from costly cells (tested in
    /// `arc_model`).
    Thesis {
        /// Largest magnification of a step, ≥ 1 (thesis: 10).
        #[serde(default = "default_d_max")]
        d_max: f64,
    },
}

fn default_d_max() -> f64 {
    ArcCost::DEFAULT_D_MAX
}

impl ArcCost {
    pub const DEFAULT_D_MAX: f64 = 10.0;
    /// Accepted range of `d_max`.
    pub const D_MAX_RANGE: (f64, f64) = (1.0, 1000.0);

    /// The thesis rule with its default d_max = 10.
    pub fn thesis() -> ArcCost {
        ArcCost::Thesis {
            d_max: Self::DEFAULT_D_MAX,
        }
    }
}

/// Search options (all have defaults; see [`RouteOptions::validate`] for
/// the ranges).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RouteOptions {
    /// Arc cost rule; `integrated` by default.
    pub arc_cost: ArcCost,
    /// Heuristic weight ≥ 1 (weighted A*): the route costs at most
    /// `epsilon` × the optimum and usually expands far fewer cells.
    /// 1 (default) gives the optimum. A* only; D* Lite requires 1.
    pub epsilon: f64,
    /// Smooth the waypoints (default true); otherwise the waypoints are the
    /// turning points of the cell path.
    pub smooth: bool,
    /// Stop with [`RouteError::TooManyExpansions`] after this many expanded
    /// cells (per `plan` call for D* Lite). None: no limit beyond the grid.
    pub max_expansions: Option<u64>,
}

impl Default for RouteOptions {
    fn default() -> Self {
        RouteOptions {
            arc_cost: ArcCost::Integrated,
            epsilon: 1.0,
            smooth: true,
            max_expansions: None,
        }
    }
}

impl RouteOptions {
    /// Accepted range of `epsilon`.
    pub const EPSILON_RANGE: (f64, f64) = (1.0, 10.0);

    /// Every out-of-range option, with its JSON pointer.
    pub fn issues(&self) -> Vec<Issue> {
        let mut issues = Vec::new();
        let (lo, hi) = Self::EPSILON_RANGE;
        if !(self.epsilon >= lo && self.epsilon <= hi) {
            issues.push(Issue::new(
                "/epsilon",
                &format!(
                    "epsilon must be in [{lo}, {hi}], got {}",
                    crate::num::readable(self.epsilon)
                ),
            ));
        }
        if let ArcCost::Thesis { d_max } = self.arc_cost {
            let (lo, hi) = ArcCost::D_MAX_RANGE;
            if !(d_max >= lo && d_max <= hi) {
                issues.push(Issue::new(
                    "/arc_cost/d_max",
                    &format!(
                        "d_max must be in [{lo}, {hi}], got {}",
                        crate::num::readable(d_max)
                    ),
                ));
            }
        }
        if self.max_expansions == Some(0) {
            issues.push(Issue::new(
                "/max_expansions",
                "max_expansions must be at least 1",
            ));
        }
        issues
    }

    pub fn validate(&self) -> Result<(), RouteError> {
        let issues = self.issues();
        if issues.is_empty() {
            Ok(())
        } else {
            Err(RouteError::InvalidOptions(issues))
        }
    }
}

/// A planned route.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Route {
    /// Every cell from start to goal; consecutive cells are 8-neighbours.
    pub cells: Vec<Cell>,
    /// The polyline to drive, a subsequence of `cells` from start to goal:
    /// smoothed, or the turning points of `cells` when smoothing is off.
    pub waypoints: Vec<Cell>,
    /// Cost of `cells` under the chosen arc rule: what the search
    /// minimised, equal to the optimum (or ≤ epsilon × it).
    pub cost: f64,
    /// Length of `cells` in metres (sum of step lengths).
    pub length_m: f64,
    /// Integrated cost of the `waypoints` polyline: the line integral of
    /// the cell cost along it ([`polyline_cost`]). With `integrated` arcs on
    /// a grid with one dx it equals `cost` for unsmoothed waypoints, and
    /// smoothing never makes it higher.
    pub waypoints_cost: f64,
    /// Length of the `waypoints` polyline in metres.
    pub waypoints_length_m: f64,
    /// Cells expanded by the search (for D* Lite: in this `plan` call).
    pub expanded: u64,
}

/// Why no route was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RouteError {
    #[error(
        "the start (row {row}, column {col}) is outside the costmap \
         ({width} columns × {height} rows)"
    )]
    StartOutside {
        row: usize,
        col: usize,
        width: usize,
        height: usize,
    },
    #[error(
        "the goal (row {row}, column {col}) is outside the costmap \
         ({width} columns × {height} rows)"
    )]
    GoalOutside {
        row: usize,
        col: usize,
        width: usize,
        height: usize,
    },
    #[error("the start (row {row}, column {col}) is on an obstacle or unknown terrain")]
    StartBlocked { row: usize, col: usize },
    #[error("the goal (row {row}, column {col}) is on an obstacle or unknown terrain")]
    GoalBlocked { row: usize, col: usize },
    #[error(
        "the goal cannot be reached from the start: obstacles separate them \
         (they are in different traversable regions)"
    )]
    Unreachable,
    #[error("the route search was cancelled")]
    Cancelled,
    #[error("the route search gave up after expanding {limit} cells (max_expansions)")]
    TooManyExpansions { limit: u64 },
    #[error("invalid route options: {}", join_issues(.0))]
    InvalidOptions(Vec<Issue>),
    #[error("cell index {index} is outside the costmap ({cells} cells)")]
    ChangeOutside { index: usize, cells: usize },
    #[error(
        "the new cost {cost} of cell index {index} is not positive \
         (use a non-finite cost to block a cell)"
    )]
    InvalidChangeCost { index: usize, cost: f32 },
}

fn join_issues(issues: &[Issue]) -> String {
    issues
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// Completes a search's cell path (row-major indices, start to goal) into a
/// [`Route`]: its cost under the arc rule (summed from the start, like the
/// searches' g values), its length, and the waypoints.
fn finish_route(
    grid: &CostGrid,
    hood: &Neighbourhood,
    model: &ArcModel,
    path: &[usize],
    expanded: u64,
    smooth: bool,
) -> Route {
    let costs = grid.costs();
    let (mut cost, mut length_m) = (0.0, 0.0);
    for pair in path.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let d = hood.direction(a, b).expect("search paths are 8-connected");
        let len = hood.step_len(a / grid.width, d);
        cost += model.arc(len, costs[a], costs[b]);
        length_m += len;
    }
    let cells: Vec<Cell> = path
        .iter()
        .map(|&i| (i / grid.width, i % grid.width))
        .collect();
    let waypoints = if smooth {
        smooth_path(grid, &cells)
    } else {
        turning_points(&cells)
    };
    let line = polyline_cost(grid, &waypoints).unwrap_or(SegmentCost {
        cost: f64::INFINITY,
        length_m: f64::INFINITY,
    });
    Route {
        cells,
        waypoints,
        cost,
        length_m,
        waypoints_cost: line.cost,
        waypoints_length_m: line.length_m,
        expanded,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_validation_names_the_fault() {
        assert!(matches!(
            CostGrid::with_cell_size(0, 3, vec![], 1.0, 1.0),
            Err(GridError::Empty { .. })
        ));
        assert_eq!(
            CostGrid::with_cell_size(2, 2, vec![1.0; 3], 1.0, 1.0),
            Err(GridError::CostCount {
                expected: 4,
                got: 3
            })
        );
        assert_eq!(
            CostGrid::new(2, 2, vec![1.0; 4], vec![1.0], 1.0),
            Err(GridError::DxCount {
                expected: 2,
                got: 1
            })
        );
        assert!(matches!(
            CostGrid::new(2, 2, vec![1.0; 4], vec![1.0, f64::NAN], 1.0),
            Err(GridError::InvalidDx { row: 1, .. })
        ));
        assert!(matches!(
            CostGrid::new(2, 2, vec![1.0; 4], vec![1.0, -1.0], 1.0),
            Err(GridError::InvalidDx { row: 1, .. })
        ));
        assert!(matches!(
            CostGrid::with_cell_size(2, 2, vec![1.0; 4], 1.0, 0.0),
            Err(GridError::InvalidDy { .. })
        ));
        let err = CostGrid::with_cell_size(2, 2, vec![1.0, 1.0, 1.0, 0.0], 1.0, 1.0).unwrap_err();
        assert_eq!(
            err,
            GridError::NonPositiveCost {
                row: 1,
                col: 1,
                value: 0.0
            }
        );
        assert!(err.to_string().contains("row 1, column 1"));
        assert!(
            CostGrid::with_cell_size(2, 2, vec![-3.0, 1.0, 1.0, 1.0], 1.0, 1.0).is_err(),
            "negative costs are rejected"
        );
        // Non-finite costs of any kind are obstacles, not errors.
        let grid = CostGrid::with_cell_size(
            2,
            2,
            vec![f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.5],
            1.0,
            1.0,
        )
        .unwrap();
        assert!(!grid.is_traversable((0, 0)));
        assert!(!grid.is_traversable((0, 1)));
        assert!(!grid.is_traversable((1, 0)));
        assert!(grid.is_traversable((1, 1)));
        assert!(!grid.is_traversable((2, 0)));
        assert_eq!(grid.finite_cost_range(), Some((0.5, 0.5)));
    }

    #[test]
    fn grid_size_limit() {
        // Checked before the costs: no need to allocate a huge grid.
        let err = CostGrid::with_cell_size(1 << 20, 1 << 13, vec![], 1.0, 1.0).unwrap_err();
        assert!(matches!(err, GridError::TooLarge { .. }), "{err}");
        let err = CostGrid::with_cell_size(1, 1 << 29, vec![], 1.0, 1.0).unwrap_err();
        assert!(
            matches!(err, GridError::TooLarge { .. }),
            "thin grids pad to 16 wide"
        );
    }

    #[test]
    fn grid_accessors() {
        let grid = CostGrid::new(
            3,
            2,
            vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            vec![2.0, 3.0],
            4.0,
        )
        .unwrap();
        assert_eq!((grid.width(), grid.height(), grid.cell_count()), (3, 2, 6));
        assert_eq!(grid.index((1, 2)), Some(5));
        assert_eq!(grid.index((2, 0)), None);
        assert_eq!(grid.index((0, 3)), None);
        assert_eq!(grid.cell(4), Some((1, 1)));
        assert_eq!(grid.cell(6), None);
        assert_eq!(grid.cost((1, 0)), Some(4.0));
        assert_eq!((grid.dx(1), grid.dy()), (3.0, 4.0));
        assert_eq!(grid.finite_cost_range(), Some((1.0, 6.0)));
        let blocked = CostGrid::with_cell_size(1, 1, vec![f32::NAN], 1.0, 1.0).unwrap();
        assert_eq!(blocked.finite_cost_range(), None);
    }

    #[test]
    fn options_validate_with_pointers() {
        assert!(RouteOptions::default().validate().is_ok());
        let bad = RouteOptions {
            arc_cost: ArcCost::Thesis { d_max: 0.5 },
            epsilon: 0.9,
            smooth: true,
            max_expansions: Some(0),
        };
        let Err(RouteError::InvalidOptions(issues)) = bad.validate() else {
            panic!("expected invalid options");
        };
        let pointers: Vec<&str> = issues.iter().map(|i| i.pointer.as_str()).collect();
        assert_eq!(pointers, ["/epsilon", "/arc_cost/d_max", "/max_expansions"]);
        for eps in [f64::NAN, f64::INFINITY, 10.5] {
            let o = RouteOptions {
                epsilon: eps,
                ..RouteOptions::default()
            };
            assert!(o.validate().is_err(), "epsilon {eps}");
        }
        let o = RouteOptions {
            arc_cost: ArcCost::Thesis { d_max: f64::NAN },
            ..RouteOptions::default()
        };
        assert!(o.validate().is_err());
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.contains("epsilon must be in [1, 10]"), "{msg}");
    }

    #[test]
    fn options_json() {
        let o: RouteOptions = serde_json::from_str("{}").unwrap();
        assert_eq!(o, RouteOptions::default());
        let o: RouteOptions =
            serde_json::from_str(r#"{"arc_cost": {"mode": "thesis"}, "epsilon": 1.5}"#).unwrap();
        assert_eq!(o.arc_cost, ArcCost::Thesis { d_max: 10.0 });
        assert_eq!(o.epsilon, 1.5);
        assert!(o.smooth);
        let o: RouteOptions = serde_json::from_str(
            r#"{"arc_cost": {"mode": "thesis", "d_max": 4}, "smooth": false, "max_expansions": 7}"#,
        )
        .unwrap();
        assert_eq!(o.arc_cost, ArcCost::Thesis { d_max: 4.0 });
        assert_eq!(o.max_expansions, Some(7));
        assert!(!o.smooth);
        let o: RouteOptions =
            serde_json::from_str(r#"{"arc_cost": {"mode": "integrated"}}"#).unwrap();
        assert_eq!(o.arc_cost, ArcCost::Integrated);
        assert_eq!(
            serde_json::to_value(ArcCost::thesis()).unwrap(),
            serde_json::json!({"mode": "thesis", "d_max": 10.0})
        );
        assert_eq!(
            serde_json::to_value(ArcCost::Integrated).unwrap(),
            serde_json::json!({"mode": "integrated"})
        );
        assert!(serde_json::from_str::<RouteOptions>(r#"{"epsilom": 2}"#).is_err());
        assert!(serde_json::from_str::<RouteOptions>(r#"{"arc_cost": {"mode": "mcp"}}"#).is_err());
        let back: RouteOptions = serde_json::from_value(serde_json::to_value(&o).unwrap()).unwrap();
        assert_eq!(back, o);
    }

    #[test]
    fn error_messages_name_start_and_goal() {
        let grid = CostGrid::with_cell_size(2, 2, vec![1.0; 4], 1.0, 1.0).unwrap();
        let e = grid.endpoint((5, 0), End::Start).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("the start (row 5, column 0) is outside")
        );
        let e = grid.endpoint((0, 9), End::Goal).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("the goal (row 0, column 9) is outside")
        );
        let grid = CostGrid::with_cell_size(2, 1, vec![f32::NAN, 1.0], 1.0, 1.0).unwrap();
        let e = grid.endpoint((0, 0), End::Goal).unwrap_err();
        assert_eq!(e, RouteError::GoalBlocked { row: 0, col: 0 });
        assert!(e.to_string().contains("goal"));
        assert_eq!(grid.endpoint((0, 1), End::Start), Ok(1));
    }
}
