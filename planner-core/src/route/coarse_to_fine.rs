//! Routes on costmaps too big for [`astar()`]'s 16 bytes per cell: plan on
//! the coarse level (block minima, `block_minima`), search the fine cells
//! of a corridor of blocks around the coarse route (`corridor_search`),
//! and prove the result optimal for the whole grid with the coarse lower
//! bound on any path that leaves the corridor (`coarse_bound`); when the
//! proof fails the corridor is widened (its half-width doubled) and the
//! search repeated, until it succeeds or a limit (widenings, corridor
//! cells) stops it — then the answer says how far from optimal it can be
//! at most.
//!
//! Memory: the fine costs are read through an LRU of tiles
//! (`tile_cache`), never held whole; the search keeps 13 bytes for each
//! cell of the corridor blocks it touches, and the coarse level 8 + 8
//! bytes per block (minima and maxima, the bound) plus the coarse A*'s 16
//! per block: with 16 × 16 blocks, 1/8 byte per cell of the map.

use std::time::Instant;

use super::arc_model::ArcModel;
use super::block_minima::BlockMinima;
use super::coarse_bound::{CoarseBound, Octile};
use super::coarse_route::{coarse_route, corridor};
use super::corridor_search::{BYTES_PER_CELL, BYTES_PER_OPEN, CorridorSearch, SearchFault};
use super::cost_source::{CostSource, CostSourceError};
use super::neighbourhood::Neighbourhood;
use super::tile_cache::{DEFAULT_TILE, TileCache};
use super::{Cell, CostGrid, Route, RouteError, RouteOptions};
use crate::geo::Issue;

/// How a coarse-to-fine search works (all have defaults).
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseToFineOptions {
    /// Block side of the coarse level in cells (a power of two, 4 to 256).
    pub block: usize,
    /// Reach K of the coarse bound in blocks (1 to 16): larger is tighter
    /// on diagonal runs (it loses about 1/K there) but takes the least
    /// cost over a wider square.
    pub reach: usize,
    /// Half-width of the first corridor, in blocks (≥ 1).
    pub initial_halfwidth: usize,
    /// Most times the corridor is widened (its half-width doubled).
    pub max_widenings: u32,
    /// Most cells a corridor may cover: a wider one is not searched, and
    /// the last result is reported with its bound.
    pub max_corridor_cells: u64,
    /// Tile side of the cost cache in cells (a multiple of `block`).
    pub tile: usize,
    /// Tiles the cost cache holds at most.
    pub cache_tiles: usize,
}

impl Default for CoarseToFineOptions {
    fn default() -> Self {
        CoarseToFineOptions {
            block: 16,
            reach: 4,
            initial_halfwidth: 4,
            max_widenings: 16,
            max_corridor_cells: u64::MAX,
            tile: DEFAULT_TILE,
            cache_tiles: 64,
        }
    }
}

impl CoarseToFineOptions {
    /// Every out-of-range option.
    pub fn issues(&self) -> Vec<Issue> {
        let mut issues = Vec::new();
        if !(self.block.is_power_of_two() && (4..=256).contains(&self.block)) {
            issues.push(Issue::new(
                "/block",
                &format!(
                    "block must be a power of two from 4 to 256, got {}",
                    self.block
                ),
            ));
        }
        if !(1..=16).contains(&self.reach) {
            issues.push(Issue::new(
                "/reach",
                &format!("reach must be 1 to 16 blocks, got {}", self.reach),
            ));
        }
        if self.initial_halfwidth == 0 {
            issues.push(Issue::new(
                "/initial_halfwidth",
                "initial_halfwidth must be at least 1 block",
            ));
        }
        if self.tile == 0 || self.block == 0 || !self.tile.is_multiple_of(self.block) {
            issues.push(Issue::new(
                "/tile",
                &format!(
                    "tile ({}) must be a multiple of block ({})",
                    self.tile, self.block
                ),
            ));
        }
        if self.cache_tiles == 0 {
            issues.push(Issue::new("/cache_tiles", "cache_tiles must be at least 1"));
        }
        issues
    }
}

impl CoarseToFineOptions {
    /// Bytes of search state for each corridor cell, as estimated ahead:
    /// the corridor search's 13 and an open list of about half an entry
    /// (16 bytes) per cell (the 4000² benchmark's last corridor: 0.2).
    pub const CORRIDOR_BYTES_PER_CELL: u64 = (BYTES_PER_CELL + BYTES_PER_OPEN / 2) as u64;

    /// An estimate of the peak memory of a search on a `width` × `height`
    /// map, ahead of it (a reservation): the coarse level (minima and
    /// maxima, the bound, the coarse A* and the corridor marks: 40 bytes a
    /// block), the coarse pass's windows (two at a time, f32 costs and
    /// their f64 reads), the tile cache, and the largest corridor allowed
    /// ([`CORRIDOR_BYTES_PER_CELL`](Self::CORRIDOR_BYTES_PER_CELL) a cell,
    /// at most the map's cells). What the cost source holds is its own.
    pub fn estimated_bytes(&self, width: usize, height: usize) -> u64 {
        let block = self.block.max(1) as u64;
        let (w, h) = (width as u64, height as u64);
        let blocks = w.div_ceil(block).saturating_mul(h.div_ceil(block));
        // Windows of whole blocks about 1024 cells a side, two at a time.
        let side = (1024 / block).max(1) * block;
        let windows = w.div_ceil(side).saturating_mul(h.div_ceil(side)).min(2);
        let coarse_windows = windows * side.min(w) * side.min(h) * (4 + 8);
        let tile = self.tile.max(1) as u64;
        let tiles = w.div_ceil(tile).saturating_mul(h.div_ceil(tile));
        let cache = (self.cache_tiles as u64)
            .min(tiles)
            .saturating_mul(tile * tile * 4)
            .saturating_add(tile * tile * 8);
        let corridor = self
            .max_corridor_cells
            .min(w.saturating_mul(h))
            .saturating_mul(Self::CORRIDOR_BYTES_PER_CELL);
        blocks
            .saturating_mul(40)
            .saturating_add(coarse_windows)
            .saturating_add(cache)
            .saturating_add(corridor)
    }
}

/// Why a coarse-to-fine search gave no route.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BigRouteError {
    #[error(transparent)]
    Route(#[from] RouteError),
    #[error(transparent)]
    Source(#[from] CostSourceError),
    #[error(
        "no route was found within the largest corridor allowed ({halfwidth} blocks each side, \
         {cells} cells); any route costs at least {lower_bound}"
    )]
    CorridorLimit {
        halfwidth: usize,
        cells: u64,
        lower_bound: f64,
    },
}

impl From<SearchFault> for BigRouteError {
    fn from(f: SearchFault) -> Self {
        match f {
            SearchFault::Route(e) => BigRouteError::Route(e),
            SearchFault::Source(e) => BigRouteError::Source(e),
        }
    }
}

/// How the search went: the figures behind its memory and time.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CoarseToFineStats {
    pub block: usize,
    pub blocks_across: usize,
    pub blocks_down: usize,
    /// Corridors searched (1 + widenings).
    pub corridors: u32,
    /// Half-width in blocks of the last corridor.
    pub halfwidth: usize,
    /// Cells of the last corridor.
    pub corridor_cells: u64,
    /// Cells given search state in the last corridor search.
    pub cells_touched: u64,
    /// Cells expanded over all corridor searches.
    pub expanded: u64,
    /// Tiles read from the source (the coarse pass reads every cell once
    /// besides).
    pub tiles_read: u64,
    /// Largest bytes of search state of one corridor search (cells
    /// touched × 13 + open list) plus the cache and the coarse level.
    pub peak_bytes: u64,
    pub coarse_ms: f64,
    pub bound_ms: f64,
    pub fine_ms: f64,
}

/// A route found coarse to fine.
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseToFine {
    /// Every cell from start to goal.
    pub cells: Vec<Cell>,
    /// Cost of `cells` under the arc rule.
    pub cost: f64,
    /// Length of `cells` in metres.
    pub length_m: f64,
    /// True when `cost` is proven the optimum of the whole grid (within
    /// 1e-12 relative, floating-point rounding).
    pub proven_optimal: bool,
    /// A lower bound on the optimum of the whole grid: `cost` when proven,
    /// else how far below `cost` the optimum could be.
    pub lower_bound: f64,
    pub stats: CoarseToFineStats,
}

impl CoarseToFine {
    /// cost − lower bound, relative to the cost (0 when proven).
    pub fn gap(&self) -> f64 {
        if self.cost > 0.0 {
            ((self.cost - self.lower_bound) / self.cost).max(0.0)
        } else {
            0.0
        }
    }
}

/// Most cells of a map searched coarse to fine.
pub const MAX_CELLS: u64 = 1 << 32;

/// Relative slack of the optimality test: floating-point rounding only.
const PROOF_TOLERANCE: f64 = 1e-12;

/// The cheapest route from `start` to `goal` on `source`, coarse to fine
/// (see the module docs). `options.epsilon` must be 1 (the search is
/// optimal or says how far it may be from it); `smooth` is not used here
/// (see [`coarse_to_fine_route`] for a grid in memory).
pub fn coarse_to_fine(
    source: &dyn CostSource,
    start: Cell,
    goal: Cell,
    options: &RouteOptions,
    c2f: &CoarseToFineOptions,
    cancel: &dyn Fn() -> bool,
) -> Result<CoarseToFine, BigRouteError> {
    options.validate()?;
    let mut issues = c2f.issues();
    if options.epsilon != 1.0 {
        issues.push(Issue::new(
            "/epsilon",
            "coarse-to-fine searches prove their route optimal: epsilon must be 1",
        ));
    }
    if !issues.is_empty() {
        return Err(RouteError::InvalidOptions(issues).into());
    }
    let (width, height) = (source.width(), source.height());
    // The corridor search numbers cells with u32.
    let cells = width as u64 * height as u64;
    if cells > MAX_CELLS {
        return Err(CostSourceError::TooLarge {
            cells,
            max: MAX_CELLS,
        }
        .into());
    }
    let mut cache = TileCache::new(source, c2f.tile, c2f.cache_tiles);
    for (cell, is_start) in [(start, true), (goal, false)] {
        let (row, col) = cell;
        if row >= height || col >= width {
            return Err(if is_start {
                RouteError::StartOutside {
                    row,
                    col,
                    width,
                    height,
                }
            } else {
                RouteError::GoalOutside {
                    row,
                    col,
                    width,
                    height,
                }
            }
            .into());
        }
        if !cache.cost(row, col)?.is_finite() {
            return Err(if is_start {
                RouteError::StartBlocked { row, col }
            } else {
                RouteError::GoalBlocked { row, col }
            }
            .into());
        }
    }
    let mut stats = CoarseToFineStats {
        block: c2f.block,
        ..CoarseToFineStats::default()
    };
    if start == goal {
        return Ok(CoarseToFine {
            cells: vec![start],
            cost: 0.0,
            length_m: 0.0,
            proven_optimal: true,
            lower_bound: 0.0,
            stats,
        });
    }
    let t = Instant::now();
    let minima = BlockMinima::build(source, c2f.block)?;
    stats.blocks_across = minima.across;
    stats.blocks_down = minima.down;
    let model = ArcModel::new(options.arc_cost, minima.cost_range());
    let octile = Octile::new(source.dx_per_row(), source.dy());
    let route = coarse_route(
        &minima,
        source.dx_per_row(),
        source.dy(),
        start,
        goal,
        cancel,
    )?;
    stats.coarse_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let bound = CoarseBound::new(&minima, &model, &octile, c2f.reach, goal);
    stats.bound_ms = t.elapsed().as_secs_f64() * 1e3;
    let fixed_bytes = (minima.bytes() + bound.bytes() + cache.capacity_bytes()) as u64;

    let cells_per_block = (c2f.block * c2f.block) as u64;
    let mut halfwidth = c2f.initial_halfwidth;
    let mut best: Option<(Vec<Cell>, f64)> = None;
    let mut lower_bound = 0.0f64;
    let t = Instant::now();
    loop {
        let in_corridor = corridor(&minima, &route, halfwidth);
        let corridor_blocks = in_corridor.iter().filter(|&&b| b).count() as u64;
        let corridor_cells = corridor_blocks * cells_per_block;
        let remaining = options
            .max_expansions
            .map_or(u64::MAX, |m| m.saturating_sub(stats.expanded));
        let outcome = CorridorSearch {
            cache: &mut cache,
            minima: &minima,
            in_corridor: &in_corridor,
            bound: &bound,
            model: &model,
            octile,
            factor: model.heuristic_factor(),
            limit: remaining,
            cancel,
        }
        .run(start, goal)
        .map_err(|e| match e {
            SearchFault::Route(RouteError::TooManyExpansions { .. }) => {
                BigRouteError::Route(RouteError::TooManyExpansions {
                    limit: options.max_expansions.unwrap_or(u64::MAX),
                })
            }
            other => other.into(),
        })?;
        stats.corridors += 1;
        stats.halfwidth = halfwidth;
        stats.corridor_cells = corridor_cells;
        stats.cells_touched = outcome.blocks_touched as u64 * cells_per_block;
        stats.expanded += outcome.expanded;
        let search_bytes = stats.cells_touched * BYTES_PER_CELL as u64
            + (outcome.open_peak * BYTES_PER_OPEN) as u64
            + (minima.across * minima.down * 5) as u64;
        stats.peak_bytes = stats.peak_bytes.max(fixed_bytes + search_bytes);
        lower_bound = lower_bound.max(outcome.cost.min(outcome.leak));
        if let Some(path) = outcome.path {
            best = Some((path, outcome.cost));
        }
        let proven =
            outcome.cost.is_finite() && outcome.leak >= outcome.cost * (1.0 - PROOF_TOLERANCE);
        if proven {
            break;
        }
        if !outcome.cost.is_finite() && !outcome.leak.is_finite() {
            // Nothing leaves the corridor and the goal is not in reach.
            return Err(RouteError::Unreachable.into());
        }
        let next = halfwidth.saturating_mul(2);
        let next_cells = corridor(&minima, &route, next)
            .iter()
            .filter(|&&b| b)
            .count() as u64
            * cells_per_block;
        if stats.corridors > c2f.max_widenings
            || next_cells > c2f.max_corridor_cells
            || next_cells == corridor_cells
        {
            // (A corridor that cannot grow has no exits: every block a
            // step could leave to is within the wider one. So the loop
            // already ended above for it.)
            break;
        }
        halfwidth = next;
    }
    stats.fine_ms = t.elapsed().as_secs_f64() * 1e3;
    stats.tiles_read = cache.stats().tiles_read;
    let Some((cells, cost)) = best else {
        return Err(BigRouteError::CorridorLimit {
            halfwidth,
            cells: stats.corridor_cells,
            lower_bound,
        });
    };
    let proven_optimal = lower_bound >= cost * (1.0 - PROOF_TOLERANCE);
    let length_m = path_length(source, &cells);
    Ok(CoarseToFine {
        cells,
        cost,
        length_m,
        proven_optimal,
        lower_bound: if proven_optimal {
            cost
        } else {
            lower_bound.min(cost)
        },
        stats,
    })
}

/// Length in metres of an 8-connected cell path.
fn path_length(source: &dyn CostSource, cells: &[Cell]) -> f64 {
    let dx = source.dx_per_row();
    let dy = source.dy();
    cells
        .windows(2)
        .map(|p| {
            let ((ar, ac), (br, bc)) = (p[0], p[1]);
            match (ar != br, ac != bc) {
                (false, _) => dx[ar],
                (true, false) => dy,
                (true, true) => (0.5 * (dx[ar] + dx[br])).hypot(dy),
            }
        })
        .sum()
}

/// [`coarse_to_fine`] on a grid in memory, completed as [`astar()`]
/// completes its routes (cost summed again, waypoints smoothed or the
/// turning points): the same [`Route`] plain A* gives, with the proof.
pub fn coarse_to_fine_route(
    grid: &CostGrid,
    start: Cell,
    goal: Cell,
    options: &RouteOptions,
    c2f: &CoarseToFineOptions,
    cancel: &dyn Fn() -> bool,
) -> Result<(Route, CoarseToFine), BigRouteError> {
    let found = coarse_to_fine(grid, start, goal, options, c2f, cancel)?;
    let hood = Neighbourhood::new(grid);
    let model = ArcModel::new(options.arc_cost, grid.finite_cost_range());
    let path: Vec<usize> = found
        .cells
        .iter()
        .map(|&c| grid.index(c).expect("route cells are inside"))
        .collect();
    let route = super::finish_route(
        grid,
        &hood,
        &model,
        &path,
        found.stats.expanded,
        options.smooth,
    );
    Ok((route, found))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::{
        Rng, assert_path_valid, random_arc, random_endpoints, random_grid,
    };
    use crate::route::{ArcCost, astar};

    fn small_blocks() -> CoarseToFineOptions {
        CoarseToFineOptions {
            block: 4,
            reach: 2,
            initial_halfwidth: 1,
            tile: 16,
            cache_tiles: 4,
            ..CoarseToFineOptions::default()
        }
    }

    fn opts(arc_cost: ArcCost) -> RouteOptions {
        RouteOptions {
            arc_cost,
            ..RouteOptions::default()
        }
    }

    /// Plain A* and coarse-to-fine agree on the cost (1e-9 relative) and
    /// on unreachable goals, and every coarse-to-fine answer is proven.
    fn agree(grid: &CostGrid, start: Cell, goal: Cell, arc: ArcCost, c2f: &CoarseToFineOptions) {
        let plain = astar(grid, start, goal, &opts(arc), &|| false);
        let ours = coarse_to_fine_route(grid, start, goal, &opts(arc), c2f, &|| false);
        match (plain, ours) {
            (Ok(a), Ok((route, found))) => {
                assert!(
                    (route.cost - a.cost).abs() <= 1e-9 * a.cost.max(1e-300),
                    "coarse-to-fine {} vs A* {} ({start:?} → {goal:?})",
                    route.cost,
                    a.cost
                );
                assert!((found.cost - route.cost).abs() <= 1e-9 * route.cost.max(1e-300));
                assert!(found.proven_optimal, "{found:?}");
                assert_eq!(found.lower_bound, found.cost);
                assert_eq!(route.cells[0], start);
                assert_eq!(*route.cells.last().unwrap(), goal);
                assert_path_valid(grid, &route.cells);
            }
            (Err(RouteError::Unreachable), Err(BigRouteError::Route(RouteError::Unreachable))) => {}
            (a, b) => panic!("A* {a:?}, coarse-to-fine {b:?}"),
        }
    }

    /// The estimate made ahead covers what the searches held at their
    /// peak, on open and obstacle-strewn maps, the corridor capped or not.
    #[test]
    fn the_memory_estimate_covers_the_peak() {
        let mut rng = Rng::new(5);
        for trial in 0..40 {
            let (w, h) = (200 + rng.below(300) as usize, 150 + rng.below(300) as usize);
            let grid = random_grid(&mut rng, w, h, [0.0, 0.2][trial % 2], true);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let c2f = CoarseToFineOptions {
                block: 8,
                tile: 64,
                max_corridor_cells: [u64::MAX, 20_000][trial % 2],
                ..CoarseToFineOptions::default()
            };
            let opts = opts(ArcCost::Integrated);
            match coarse_to_fine(&grid, start, goal, &opts, &c2f, &|| false) {
                Ok(found) => {
                    let estimate = c2f.estimated_bytes(w, h);
                    assert!(
                        found.stats.peak_bytes <= estimate,
                        "{w}×{h}: peak {} > estimate {estimate}",
                        found.stats.peak_bytes
                    );
                }
                Err(BigRouteError::Route(RouteError::Unreachable))
                | Err(BigRouteError::CorridorLimit { .. }) => {}
                Err(e) => panic!("{e}"),
            }
        }
        // The corridor term grows with the cap, up to the map's cells.
        let c2f = CoarseToFineOptions {
            max_corridor_cells: 1000,
            ..CoarseToFineOptions::default()
        };
        let uncapped = CoarseToFineOptions::default();
        assert_eq!(
            uncapped.estimated_bytes(100, 100) - c2f.estimated_bytes(100, 100),
            9000 * CoarseToFineOptions::CORRIDOR_BYTES_PER_CELL
        );
    }

    #[test]
    fn equals_plain_a_star_on_random_costmaps_with_obstacles() {
        let mut rng = Rng::new(77);
        let mut compared = 0;
        for trial in 0..400 {
            let w = 5 + rng.below(80) as usize;
            let h = 5 + rng.below(80) as usize;
            let density = [0.0, 0.1, 0.25, 0.4][trial % 4];
            let grid = random_grid(&mut rng, w, h, density, trial % 2 == 0);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let arc = random_arc(&mut rng, trial % 3 == 0);
            let c2f = CoarseToFineOptions {
                block: [4, 8, 16][trial % 3],
                reach: 1 + trial % 4,
                initial_halfwidth: 1 + trial % 2,
                tile: 32,
                cache_tiles: 1 + trial % 5,
                ..CoarseToFineOptions::default()
            };
            agree(&grid, start, goal, arc, &c2f);
            compared += 1;
        }
        assert!(compared > 300, "{compared}");
    }

    /// A serpentine maze: walls across the map, open at alternate ends.
    /// The coarse route is forced round the walls too, but the first
    /// narrow corridor around a straight coarse route on a map whose
    /// cheap ground lies far to the side must widen.
    /// 160 × 120 cells: expensive ground (cost 20) between start and goal
    /// at (50, 2) and (50, 157), a cheap lane (cost 1) along the far bottom
    /// (rows 100..110) that the fine optimum takes. Single cheap cells
    /// sprinkled on the expensive ground lower its block minima, so the
    /// coarse route heads straight across.
    fn lure_grid() -> CostGrid {
        let (w, h) = (160, 120);
        let mut costs = vec![20.0f32; w * h];
        for r in 100..110 {
            for c in 0..w {
                costs[r * w + c] = 1.0;
            }
        }
        for r in (0..100).step_by(4) {
            for c in (0..w).step_by(4) {
                costs[r * w + c] = 1.0;
            }
        }
        CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap()
    }

    #[test]
    fn mazes_and_cheap_detours_outside_the_first_corridor() {
        let (w, h) = (120, 100);
        let mut costs = vec![2.0f32; w * h];
        for (k, wall_row) in (10..h).step_by(12).enumerate() {
            for c in 0..w {
                let gap = if k % 2 == 0 { c >= w - 4 } else { c < 4 };
                if !gap {
                    costs[wall_row * w + c] = f32::NAN;
                }
            }
        }
        let maze = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        agree(
            &maze,
            (0, 60),
            (99, 60),
            ArcCost::Integrated,
            &small_blocks(),
        );
        agree(&maze, (99, 0), (0, 119), ArcCost::thesis(), &small_blocks());

        // The coarse route heads straight across the lure's expensive
        // ground: the corridor around it must widen until the proof holds.
        let lure = lure_grid();
        let (start, goal) = ((50, 2), (50, 157));
        let a = astar(&lure, start, goal, &RouteOptions::default(), &|| false).unwrap();
        assert!(
            a.cells.iter().any(|&(r, _)| r >= 100),
            "the optimum takes the lane"
        );
        let (route, found) = coarse_to_fine_route(
            &lure,
            start,
            goal,
            &RouteOptions::default(),
            &small_blocks(),
            &|| false,
        )
        .unwrap();
        assert!((route.cost - a.cost).abs() <= 1e-9 * a.cost);
        assert!(found.proven_optimal);
        assert!(found.stats.corridors > 1, "the first corridor had to widen");
    }

    #[test]
    fn a_limit_reports_the_bound_achieved() {
        // The lure map again, with no widening allowed.
        let grid = lure_grid();
        let c2f = CoarseToFineOptions {
            max_widenings: 0,
            ..small_blocks()
        };
        let (start, goal) = ((50, 2), (50, 157));
        let exact = astar(&grid, start, goal, &RouteOptions::default(), &|| false)
            .unwrap()
            .cost;
        let found = coarse_to_fine(&grid, start, goal, &RouteOptions::default(), &c2f, &|| {
            false
        })
        .unwrap();
        assert!(!found.proven_optimal);
        assert!(
            found.lower_bound <= exact * (1.0 + 1e-12),
            "the bound is sound"
        );
        assert!(found.cost >= exact * (1.0 - 1e-12));
        assert!(found.gap() > 0.0 && found.gap() < 1.0, "{}", found.gap());
    }

    #[test]
    fn endpoints_on_borders_blocked_or_walled_in() {
        const X: f32 = f32::NAN;
        let (w, h) = (64, 48);
        let mut costs = vec![1.5f32; w * h];
        // A pocket round (20, 30): a ring of obstacles.
        for r in 18..=22 {
            for c in 28..=32 {
                if r == 18 || r == 22 || c == 28 || c == 32 {
                    costs[r * w + c] = X;
                }
            }
        }
        costs[5 * w + 5] = X;
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        let o = RouteOptions::default();
        let c2f = small_blocks();
        let run = |s, g| coarse_to_fine(&grid, s, g, &o, &c2f, &|| false).map(|f| f.cost);
        // Corners and borders.
        agree(&grid, (0, 0), (47, 63), ArcCost::Integrated, &c2f);
        agree(&grid, (47, 0), (0, 63), ArcCost::Integrated, &c2f);
        agree(&grid, (0, 31), (47, 31), ArcCost::Integrated, &c2f);
        // Walled in: unreachable either way, a clear error.
        assert_eq!(
            run((20, 30), (0, 0)),
            Err(BigRouteError::Route(RouteError::Unreachable))
        );
        assert_eq!(
            run((0, 0), (20, 30)),
            Err(BigRouteError::Route(RouteError::Unreachable))
        );
        assert_eq!(
            run((5, 5), (0, 0)),
            Err(BigRouteError::Route(RouteError::StartBlocked {
                row: 5,
                col: 5
            }))
        );
        assert_eq!(
            run((0, 0), (48, 0)),
            Err(BigRouteError::Route(RouteError::GoalOutside {
                row: 48,
                col: 0,
                width: 64,
                height: 48
            }))
        );
        assert_eq!(run((3, 3), (3, 3)), Ok(0.0));
        let bad = CoarseToFineOptions {
            block: 6,
            ..c2f.clone()
        };
        let e = coarse_to_fine(&grid, (0, 0), (1, 1), &o, &bad, &|| false).unwrap_err();
        assert!(e.to_string().contains("power of two"), "{e}");
        let weighted = RouteOptions {
            epsilon: 2.0,
            ..RouteOptions::default()
        };
        let e = coarse_to_fine(&grid, (0, 0), (1, 1), &weighted, &c2f, &|| false).unwrap_err();
        assert!(e.to_string().contains("epsilon must be 1"), "{e}");
    }

    #[test]
    fn the_shared_costmap_shapes_agree_and_stay_narrow() {
        // The benchmark's costmap styles at 400²: the same cost as A*, and
        // the last corridor well under the whole map.
        use crate::route::testing::{far_corners, smooth_costmap, terrain_costmap};
        let mut rng = Rng::new(1);
        for grid in [
            terrain_costmap(&mut rng, 400, 400, 0.05),
            smooth_costmap(&mut rng, 400, 400, 0.05),
        ] {
            let (start, goal) = far_corners(&grid);
            let c2f = CoarseToFineOptions::default();
            agree(&grid, start, goal, ArcCost::Integrated, &c2f);
            agree(&grid, start, goal, ArcCost::thesis(), &c2f);
        }
    }

    /// Release-mode figures next to plain A* on the benchmark's costmap
    /// styles, corner to corner (run with `cargo test --release -p
    /// planner-core --lib route::coarse_to_fine::tests::timing -- --ignored
    /// --nocapture`; sizes from `ROUTE_SIZES`, default 2000,4000).
    #[test]
    #[ignore]
    fn timing_against_plain_a_star() {
        use crate::route::testing::{far_corners, timing_costmaps};
        for (size, kind, grid) in timing_costmaps() {
            let (start, goal) = far_corners(&grid);
            let t = Instant::now();
            let plain = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
            let plain_s = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let found = coarse_to_fine(
                &grid,
                start,
                goal,
                &RouteOptions::default(),
                &CoarseToFineOptions::default(),
                &|| false,
            )
            .unwrap();
            let ours_s = t.elapsed().as_secs_f64();
            println!(
                "{kind} {size}²: A* {plain_s:.3} s cost {:.4} ({} expanded); coarse-to-fine \
                 {ours_s:.3} s cost {:.4} proven {} bound {:.4}, {:?}",
                plain.cost,
                plain.expanded,
                found.cost,
                found.proven_optimal,
                found.lower_bound,
                found.stats
            );
            assert!((found.cost - plain.cost).abs() <= 1e-9 * plain.cost);
        }
    }
}
