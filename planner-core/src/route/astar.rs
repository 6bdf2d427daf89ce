//! A* on dense arrays.
//!
//! Memory, 16 bytes per cell in all: the caller's f32 costs (4), a tiled
//! copy of them (4, see `tiles`: neighbours share a tile and a page, which
//! halves the time on large maps) and one 64-bit label per cell (8): g as
//! an f64 whose 4 lowest mantissa bits hold the move back to the parent (3
//! bits) and a closed bit. The open list (`bucket_queue`) only holds the
//! frontier. g keeps 48 significant bits (relative 4·10⁻¹⁵ per step), far
//! inside the 1e-9 that results must match an independent Dijkstra to; the
//! reported cost is summed again in full f64 along the path. One label
//! instead of a g array and a state array halves the cache lines an
//! expansion touches outside the costs. The search waits on memory more
//! than it computes: the labels and the tiled copy are mapped on huge pages
//! by the worker threads before it starts (`pages`), and it prefetches the
//! cells it will pop next.
//!
//! The heuristic is the octile distance in metres times the smallest arc
//! cost per metre (the least finite cost for `integrated`, 1 for `thesis`):
//! admissible and consistent, so with `epsilon` = 1 every cell is closed
//! once with its optimal g and the route is optimal. With `epsilon` > 1 the
//! heuristic is inflated (weighted A* without re-opening), which bounds the
//! route's cost by `epsilon` × the optimum. Ties in f go to the smaller h
//! (the deeper cell), which keeps A* from flooding open ground.
//!
//! Unreachable goals: before searching, the goal's region is flood-filled
//! for a small budget (1/32 of the grid, 4096 to 262144 cells); a goal in a pocket that does not
//! hold the start is reported at once. Otherwise the search ends when its
//! open list empties, after the start's whole region — it never hangs, and
//! `max_expansions` and the cancellation hook bound it further. (Labelling
//! connected components up front would cost 4 more bytes per cell and a
//! pass over the whole grid for every query.)

use super::arc_model::{ArcModel, ArcRule, Heuristic, Rule};
use super::bucket_queue::BucketQueue;
use super::neighbourhood::{Marks, Neighbourhood, flood_budget, opposite};
use super::pages::fresh_zeroed;
use super::tiles::{TILE, TileLayout, Tiles, padded_cells};
use super::{CANCEL_CHECK_INTERVAL, Cell, CostGrid, End, Route, RouteError, RouteOptions};

/// Bit pattern of +∞. Labels are stored XOR-ed with it so that a zeroed
/// allocation (the kernel's fresh pages, see `pages`) reads as g = ∞ with
/// no flags, and no fill pass is needed.
const INFINITY_BITS: u64 = 0x7ff0_0000_0000_0000;
const PARENT: u64 = 0b0111;
const CLOSED: u64 = 0b1000;
const FLAGS: u64 = PARENT | CLOSED;

/// The per-cell labels (see the module docs).
struct Labels {
    words: Vec<u64>,
}

impl Labels {
    /// All at g = ∞, mapped up front by the worker threads (`pages`).
    fn new(len: usize) -> Labels {
        Labels {
            words: fresh_zeroed(len),
        }
    }

    #[inline]
    fn g(word: u64) -> f64 {
        f64::from_bits((word & !FLAGS) ^ INFINITY_BITS)
    }

    /// g and the parent move of an open cell.
    #[inline]
    fn open_word(g: f64, parent: usize) -> u64 {
        ((g.to_bits() ^ INFINITY_BITS) & !FLAGS) | parent as u64
    }
}

/// Most buckets the open list may use (see [`open_list`]).
const MAX_BUCKETS: usize = 1 << 12;

/// The cheapest route from `start` to `goal` (see the module docs).
///
/// `cancel` is asked every [`CANCEL_CHECK_INTERVAL`] expansions; returning
/// true stops the search with [`RouteError::Cancelled`].
pub fn astar(
    grid: &CostGrid,
    start: Cell,
    goal: Cell,
    options: &RouteOptions,
    cancel: &dyn Fn() -> bool,
) -> Result<Route, RouteError> {
    options.validate()?;
    let s = grid.endpoint(start, End::Start)?;
    let t = grid.endpoint(goal, End::Goal)?;
    let hood = Neighbourhood::new(grid);
    let model = ArcModel::new(options.arc_cost, grid.finite_cost_range());
    let (path, expanded) = search(grid, &hood, &model, s, t, options, cancel)?;
    Ok(super::finish_route(
        grid,
        &hood,
        &model,
        &path,
        expanded,
        options.smooth,
    ))
}

/// The search itself: the cell path (row-major indices, start to goal) and
/// the number of expanded cells.
fn search(
    grid: &CostGrid,
    hood: &Neighbourhood,
    model: &ArcModel,
    start: usize,
    goal: usize,
    options: &RouteOptions,
    cancel: &dyn Fn() -> bool,
) -> Result<(Vec<usize>, u64), RouteError> {
    if start == goal {
        return Ok((vec![start], 0));
    }
    let (path, expanded, _) = search_tree(grid, hood, model, (start, goal), options, cancel)?;
    Ok((path, expanded))
}

/// A finished search from a start to a goal (≠ the start): every cell's
/// label in tiled order, so that D* Lite can read the optimal cost from
/// the start of each closed cell (`landmark`).
pub(crate) struct SearchTree {
    words: Vec<u64>,
    layout: TileLayout,
    goal_g: f64,
}

impl SearchTree {
    /// The cost from the start of cell (r, c) if the search closed it
    /// (optimal with `epsilon` = 1), else `None`.
    #[inline]
    pub(crate) fn closed_g(&self, r: usize, c: usize) -> Option<f64> {
        let word = self.words[self.layout.index(r, c)];
        (word & CLOSED != 0).then(|| Labels::g(word))
    }

    /// The cost found from the start to the goal, as the labels hold it.
    pub(crate) fn goal_cost(&self) -> f64 {
        self.goal_g
    }

    /// Bytes held per (padded) cell.
    pub(crate) const BYTES_PER_CELL: usize = 8;
}

/// A* from `ends` = (start, goal), start ≠ goal: the cell path, the number
/// of expanded cells and the labels.
pub(crate) fn search_tree(
    grid: &CostGrid,
    hood: &Neighbourhood,
    model: &ArcModel,
    (start, goal): (usize, usize),
    options: &RouteOptions,
    cancel: &dyn Fn() -> bool,
) -> Result<(Vec<usize>, u64, SearchTree), RouteError> {
    let width = grid.width();
    // The tiled copy and the labels' pages, side by side on two threads.
    let (tiles, mut labels) = rayon::join(|| Tiles::new(grid), || Labels::new(padded_cells(grid)));
    let mut marks = TiledMarks {
        labels: &mut labels,
        tiles: &tiles,
        width,
    };
    let n = grid.cell_count();
    if hood.region_excludes(grid.costs(), &mut marks, goal, start, flood_budget(n)) {
        return Err(RouteError::Unreachable);
    }
    let search = Search {
        tiles: &tiles,
        hood,
        heuristic: Heuristic::new(hood, goal, model.heuristic_factor() * options.epsilon),
        limit: options.max_expansions.unwrap_or(u64::MAX),
        cancel,
    };
    let open = open_list(hood, model, options.epsilon);
    let (start_rc, goal_rc) = ((start / width, start % width), (goal / width, goal % width));
    // One copy of the inner loop per arc rule, without a branch on it.
    let expanded = match model.rule() {
        Rule::Integrated(rule) => search.run(rule, &mut labels.words, open, start_rc, goal_rc)?,
        Rule::Thesis(rule) => search.run(rule, &mut labels.words, open, start_rc, goal_rc)?,
    };
    // Walk the parent moves back from the goal.
    let mut path = vec![goal];
    let (mut r, mut c) = goal_rc;
    while (r, c) != start_rc {
        let parent = (labels.words[tiles.index(r, c)] & PARENT) as usize;
        (r, c) = tiles.step(r, c, parent);
        path.push(r * width + c);
        assert!(path.len() <= n, "the parent chain must reach the start");
    }
    path.reverse();
    let tree = SearchTree {
        goal_g: Labels::g(labels.words[tiles.index(goal_rc.0, goal_rc.1)]),
        words: labels.words,
        layout: tiles.layout(),
    };
    Ok((path, expanded, tree))
}

/// The goal flood marks cells with the closed bit (before the search).
struct TiledMarks<'a> {
    labels: &'a mut Labels,
    tiles: &'a Tiles,
    width: usize,
}

impl Marks for TiledMarks<'_> {
    fn mark(&mut self, i: usize) -> bool {
        let t = self.tiles.index(i / self.width, i % self.width);
        let new = self.labels.words[t] & CLOSED == 0;
        self.labels.words[t] |= CLOSED;
        new
    }

    fn unmark(&mut self, i: usize) {
        let t = self.tiles.index(i / self.width, i % self.width);
        self.labels.words[t] &= !CLOSED;
    }
}

struct Search<'a> {
    tiles: &'a Tiles,
    hood: &'a Neighbourhood,
    heuristic: Heuristic,
    limit: u64,
    cancel: &'a dyn Fn() -> bool,
}

impl Search<'_> {
    /// Expands cells until the goal is popped; the number expanded. Works
    /// in tiled indices; `start` and `goal` are (row, col).
    fn run(
        &self,
        rule: impl ArcRule,
        words: &mut [u64],
        mut open: BucketQueue,
        start: (usize, usize),
        goal: (usize, usize),
    ) -> Result<u64, RouteError> {
        let (tiles, hood, heuristic) = (self.tiles, self.hood, &self.heuristic);
        let start_index = tiles.index(start.0, start.1);
        let goal_index = tiles.index(goal.0, goal.1);
        words[start_index] = Labels::open_word(0.0, 0);
        let h = heuristic.at(hood, start.0, start.1);
        open.push(entry(h, h, start_index));
        let mut expanded = 0u64;
        while let Some(top) = open.pop_live(|e| words[e as u32 as usize] & CLOSED == 0) {
            // The search waits on memory: the labels and costs of a cell
            // popped a few steps from now are fetched while it works.
            if let Some(next) = open.ahead(PREFETCH_AHEAD) {
                prefetch_cell(words, tiles, next as u32 as usize);
            }
            let u = top as u32 as usize;
            let word_u = words[u];
            if word_u & CLOSED != 0 {
                continue; // a stale duplicate: u was closed from a cheaper entry
            }
            if u == goal_index {
                return Ok(expanded);
            }
            if expanded >= self.limit {
                return Err(RouteError::TooManyExpansions { limit: self.limit });
            }
            if expanded.is_multiple_of(CANCEL_CHECK_INTERVAL) && (self.cancel)() {
                return Err(RouteError::Cancelled);
            }
            words[u] = word_u | CLOSED;
            expanded += 1;
            let (r, c) = tiles.row_col(u);
            let gu = Labels::g(word_u);
            let cost_u = tiles.cost(u);
            let steps = hood.row_steps(r);
            let (neighbours, mut moves) = tiles.moves(u, r, c);
            while moves != 0 {
                let d = moves.trailing_zeros() as usize & 7;
                moves &= moves - 1;
                let v = neighbours[d];
                let word_v = words[v];
                if word_v & CLOSED != 0 {
                    continue;
                }
                let gv = gu + rule.arc(steps[d], cost_u, tiles.cost(v));
                if gv < Labels::g(word_v) {
                    words[v] = Labels::open_word(gv, opposite(d));
                    let (vr, vc) = tiles.step(r, c, d);
                    let hv = heuristic.at(hood, vr, vc);
                    open.push(entry(gv + hv, hv, v));
                }
            }
        }
        Err(RouteError::Unreachable)
    }
}

/// How many pops ahead the search prefetches (on the 4000² benchmark 16
/// took 5–7 % off the search loop, more than 4 or 32).
const PREFETCH_AHEAD: usize = 16;

/// Asks the caches for the label and cost lines of tiled cell `t` and of
/// the cells above and below it (its neighbours' rows in the tile).
#[inline(always)]
fn prefetch_cell(words: &[u64], tiles: &Tiles, t: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let last = words.len() - 1;
        for i in [t.saturating_sub(TILE), t, (t + TILE).min(last)] {
            // SAFETY: SSE is part of x86-64; a prefetch only hints the
            // caches (and the addresses are inside the two slices anyway).
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>((&raw const words[i]).cast());
                _mm_prefetch::<_MM_HINT_T0>(tiles.cost_ptr(i).cast());
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (words, tiles, t);
}

/// An open-list entry: f (its bit pattern: f ≥ 0 orders like the number),
/// then the smaller h (deeper cells first on ties), then the cell index.
#[inline]
fn entry(f: f64, h: f64, cell: usize) -> u128 {
    (u128::from(f.to_bits()) << 64) | (u128::from((h as f32).to_bits()) << 32) | cell as u128
}

/// The open list, with buckets a sixteenth of the cheapest arc wide (a
/// quarter made buckets of a thousand entries on the 4000² benchmark, and
/// sorting them took a sixth of the search): open f
/// values lie within (1 + epsilon) × the dearest arc of the smallest (an
/// arc plus the inflated heuristic's change along it), which sets the
/// number of buckets (capped).
pub(crate) fn open_list(hood: &Neighbourhood, model: &ArcModel, epsilon: f64) -> BucketQueue {
    let cheapest = hood.shortest_step() * model.heuristic_factor();
    let dearest = hood.longest_step() * model.largest_factor();
    let spread = (1.0 + epsilon) * dearest;
    let mut width = cheapest / 16.0;
    let mut buckets = (spread / width).ceil();
    if !(buckets.is_finite() && buckets < MAX_BUCKETS as f64 - 2.0) {
        buckets = MAX_BUCKETS as f64 - 2.0;
        width = spread / buckets;
    }
    if !(width.is_finite() && width > 0.0) {
        width = 1.0;
    }
    BucketQueue::new(width, buckets as usize + 2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::{
        Rng, assert_path_valid, dijkstra, random_arc, random_endpoints, random_grid,
    };
    use crate::route::{ArcCost, polyline_cost};
    use std::cell::Cell as Counter;

    const X: f32 = f32::NAN;

    fn opts(arc_cost: ArcCost) -> RouteOptions {
        RouteOptions {
            arc_cost,
            ..RouteOptions::default()
        }
    }

    fn path_cost(grid: &CostGrid, model_arc: ArcCost, cells: &[Cell]) -> f64 {
        let hood = Neighbourhood::new(grid);
        let model = ArcModel::new(model_arc, grid.finite_cost_range());
        let idx: Vec<usize> = cells.iter().map(|&c| grid.index(c).unwrap()).collect();
        idx.windows(2)
            .map(|p| {
                let d = hood.direction(p[0], p[1]).unwrap();
                model.arc(
                    hood.step_len(p[0] / grid.width(), d),
                    grid.costs()[p[0]],
                    grid.costs()[p[1]],
                )
            })
            .sum()
    }

    #[test]
    fn matches_an_independent_dijkstra_on_random_grids() {
        let mut rng = Rng::new(7);
        let (mut found, mut unreachable) = (0, 0);
        for trial in 0..600 {
            let w = 1 + rng.below(40) as usize;
            let h = 1 + rng.below(40) as usize;
            let density = [0.0, 0.1, 0.25, 0.4][trial % 4];
            let grid = random_grid(&mut rng, w, h, density, trial % 2 == 0);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let arc = random_arc(&mut rng, trial % 3 == 0);
            let expected = dijkstra(&grid, start, goal, arc);
            match (astar(&grid, start, goal, &opts(arc), &|| false), expected) {
                (Ok(route), Some(best)) => {
                    found += 1;
                    assert!(
                        (route.cost - best).abs() <= 1e-9 * best.max(1e-300),
                        "trial {trial}: A* {} vs Dijkstra {best}",
                        route.cost
                    );
                    assert_eq!(route.cells[0], start);
                    assert_eq!(*route.cells.last().unwrap(), goal);
                    assert_path_valid(&grid, &route.cells);
                    assert!(
                        (path_cost(&grid, arc, &route.cells) - route.cost).abs() <= 1e-9 * best
                    );
                    assert!(route.expanded as usize <= w * h);
                }
                (Err(RouteError::Unreachable), None) => unreachable += 1,
                (got, want) => panic!("trial {trial}: A* {got:?}, Dijkstra {want:?}"),
            }
        }
        assert!(found > 400 && unreachable > 20, "{found} {unreachable}");
    }

    #[test]
    fn integrated_route_cost_is_its_line_integral() {
        // With one dx for every row, the integrated cost of a cell path is
        // exactly the line integral of the cost along it.
        let mut rng = Rng::new(11);
        for _ in 0..100 {
            let grid = random_grid(&mut rng, 30, 25, 0.2, false);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let no_smooth = RouteOptions {
                smooth: false,
                ..RouteOptions::default()
            };
            if let Ok(route) = astar(&grid, start, goal, &no_smooth, &|| false) {
                let line = polyline_cost(&grid, &route.cells).unwrap();
                assert!((line.cost - route.cost).abs() <= 1e-9 * route.cost.max(1.0));
                assert!((route.waypoints_cost - route.cost).abs() <= 1e-9 * route.cost.max(1.0));
                assert!((line.length_m - route.length_m).abs() <= 1e-9 * route.length_m.max(1.0));
            }
        }
    }

    #[test]
    fn weighted_search_stays_within_epsilon() {
        let mut rng = Rng::new(8);
        let mut fewer = 0;
        let mut trials = 0;
        for trial in 0..300 {
            let grid = random_grid(&mut rng, 45, 45, 0.15, trial % 2 == 1);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let Some(best) = dijkstra(&grid, start, goal, ArcCost::Integrated) else {
                continue;
            };
            let optimal = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
            for epsilon in [1.2, 2.0, 5.0] {
                let o = RouteOptions {
                    epsilon,
                    ..RouteOptions::default()
                };
                let route = astar(&grid, start, goal, &o, &|| false).unwrap();
                assert!(
                    route.cost <= epsilon * best * (1.0 + 1e-12),
                    "trial {trial}"
                );
                assert!(route.cost >= best * (1.0 - 1e-12));
                assert_path_valid(&grid, &route.cells);
                trials += 1;
                if route.expanded < optimal.expanded {
                    fewer += 1;
                }
            }
        }
        assert!(
            fewer * 2 > trials,
            "weighting should usually expand fewer cells"
        );
    }

    #[test]
    fn never_cuts_corners() {
        // Two diagonal obstacles: the diagonal between them is closed.
        let grid = CostGrid::with_cell_size(2, 2, vec![1.0, X, X, 1.0], 1.0, 1.0).unwrap();
        assert_eq!(
            astar(&grid, (0, 0), (1, 1), &RouteOptions::default(), &|| false),
            Err(RouteError::Unreachable)
        );
        // One obstacle at the corner: go around it (two orthogonal steps).
        #[rustfmt::skip]
        let grid = CostGrid::with_cell_size(3, 3, vec![
            1.0, X,   1.0,
            1.0, 1.0, 1.0,
            1.0, 1.0, 1.0,
        ], 1.0, 1.0).unwrap();
        let route = astar(&grid, (0, 0), (0, 2), &RouteOptions::default(), &|| false).unwrap();
        assert_path_valid(&grid, &route.cells);
        assert_eq!(route.cells, vec![(0, 0), (1, 0), (1, 1), (1, 2), (0, 2)]);
        // (0,0)→(1,1) and (1,1)→(0,2) would pass the obstacle's corner, so
        // the route is S, E, E, N rather than SE, NE.
        assert!((route.cost - 4.0).abs() < 1e-12);
    }

    #[test]
    fn endpoint_errors() {
        let grid =
            CostGrid::with_cell_size(3, 2, vec![1.0, X, 1.0, 1.0, 1.0, 1.0], 1.0, 1.0).unwrap();
        let o = RouteOptions::default();
        let never = || false;
        assert_eq!(
            astar(&grid, (2, 0), (0, 0), &o, &never),
            Err(RouteError::StartOutside {
                row: 2,
                col: 0,
                width: 3,
                height: 2
            })
        );
        assert_eq!(
            astar(&grid, (0, 0), (0, 3), &o, &never),
            Err(RouteError::GoalOutside {
                row: 0,
                col: 3,
                width: 3,
                height: 2
            })
        );
        assert_eq!(
            astar(&grid, (0, 1), (0, 0), &o, &never),
            Err(RouteError::StartBlocked { row: 0, col: 1 })
        );
        assert_eq!(
            astar(&grid, (0, 0), (0, 1), &o, &never),
            Err(RouteError::GoalBlocked { row: 0, col: 1 })
        );
        let bad = RouteOptions {
            epsilon: 0.5,
            ..RouteOptions::default()
        };
        assert!(matches!(
            astar(&grid, (0, 0), (1, 2), &bad, &never),
            Err(RouteError::InvalidOptions(_))
        ));
        // Start = goal: a one-cell route.
        let route = astar(&grid, (1, 1), (1, 1), &o, &never).unwrap();
        assert_eq!(route.cells, vec![(1, 1)]);
        assert_eq!(route.waypoints, vec![(1, 1)]);
        assert_eq!(
            (route.cost, route.length_m, route.waypoints_cost),
            (0.0, 0.0, 0.0)
        );
    }

    #[test]
    fn unreachable_goal_in_a_pocket_is_found_without_searching() {
        // A big open map with the goal walled in.
        let (w, h) = (300, 300);
        let mut costs = vec![1.0f32; w * h];
        for r in 200..=210 {
            for c in 200..=210 {
                if r == 200 || r == 210 || c == 200 || c == 210 {
                    costs[r * w + c] = X;
                }
            }
        }
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        let calls = Counter::new(0);
        let cancel = || {
            calls.set(calls.get() + 1);
            false
        };
        assert_eq!(
            astar(&grid, (0, 0), (205, 205), &RouteOptions::default(), &cancel),
            Err(RouteError::Unreachable)
        );
        assert_eq!(calls.get(), 0, "answered before the search started");
        // The start in the pocket: the search exhausts the pocket quickly.
        assert_eq!(
            astar(&grid, (205, 205), (0, 0), &RouteOptions::default(), &cancel),
            Err(RouteError::Unreachable)
        );
        // Two halves split by a wall: the open list empties.
        let mut costs = vec![1.0f32; w * h];
        for r in 0..h {
            costs[r * w + 150] = X;
        }
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        assert_eq!(
            astar(&grid, (0, 0), (5, 299), &RouteOptions::default(), &|| false),
            Err(RouteError::Unreachable)
        );
    }

    #[test]
    fn cancellation_and_expansion_limit() {
        // Varied costs so that A* cannot walk straight to the goal.
        let mut rng = Rng::new(5);
        let grid = random_grid(&mut rng, 200, 200, 0.0, false);
        let calls = Counter::new(0);
        let cancel_on_third = || {
            calls.set(calls.get() + 1);
            calls.get() >= 3
        };
        let o = RouteOptions::default();
        assert_eq!(
            astar(&grid, (0, 0), (199, 199), &o, &cancel_on_third),
            Err(RouteError::Cancelled)
        );
        assert_eq!(calls.get(), 3);
        let limited = RouteOptions {
            max_expansions: Some(50),
            ..RouteOptions::default()
        };
        assert_eq!(
            astar(&grid, (0, 0), (199, 199), &limited, &|| false),
            Err(RouteError::TooManyExpansions { limit: 50 })
        );
        // A limit that is enough.
        let route = astar(&grid, (0, 0), (0, 3), &limited, &|| false).unwrap();
        assert!(route.expanded <= 50);
        assert_eq!(route.cells.len(), 4);
    }

    #[test]
    fn open_ground_expands_only_the_straight_line() {
        // Equal f everywhere along the diagonal: the h tie-break keeps A*
        // from flooding the map.
        let grid = CostGrid::with_cell_size(500, 500, vec![1.0; 250_000], 1.0, 1.0).unwrap();
        let route = astar(&grid, (0, 0), (499, 499), &RouteOptions::default(), &|| {
            false
        })
        .unwrap();
        assert!(route.expanded < 2_000, "{}", route.expanded);
        assert!((route.cost - 499.0 * 2f64.sqrt()).abs() < 1e-9);
        assert_eq!(route.waypoints, vec![(0, 0), (499, 499)]);
    }

    /// Release-mode timing on a large smooth costmap, corner to corner (run
    /// with `cargo test --release -p planner-core --lib route::astar::tests::timing
    /// -- --ignored --nocapture`; sizes from `ROUTE_SIZES`, default 2000,4000).
    #[test]
    #[ignore]
    fn timing_large_grid() {
        use crate::route::testing::{far_corners, thread_cpu_seconds, timing_costmaps};
        for (size, kind, grid) in timing_costmaps() {
            let (start, goal) = far_corners(&grid);
            if let Ok(dir) = std::env::var("ROUTE_DUMP") {
                // Raw little-endian f32 rows, for comparing with other tools.
                let bytes: Vec<u8> = grid.costs().iter().flat_map(|c| c.to_le_bytes()).collect();
                std::fs::write(format!("{dir}/{kind}{size}.f32"), bytes).unwrap();
                println!("{kind} {size}²: start {start:?} goal {goal:?}");
            }
            let mut route = None;
            for _ in 0..3 {
                let (t0, c0) = (std::time::Instant::now(), thread_cpu_seconds());
                let r = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
                println!(
                    "{kind} {size}²: A* {:.3} s wall, {:.3} s CPU, {} expanded, cost {:.4}, \
                     {} cells, {} waypoints",
                    t0.elapsed().as_secs_f64(),
                    thread_cpu_seconds() - c0,
                    r.expanded,
                    r.cost,
                    r.cells.len(),
                    r.waypoints.len()
                );
                route = Some(r);
            }
            let route = route.unwrap();
            let weighted = RouteOptions {
                epsilon: 1.5,
                ..RouteOptions::default()
            };
            let (t0, c0) = (std::time::Instant::now(), thread_cpu_seconds());
            let fast = astar(&grid, start, goal, &weighted, &|| false).unwrap();
            println!(
                "{kind} {size}²: ε = 1.5: {:.3} s wall, {:.3} s CPU, {} expanded, cost +{:.3}%",
                t0.elapsed().as_secs_f64(),
                thread_cpu_seconds() - c0,
                fast.expanded,
                100.0 * (fast.cost / route.cost - 1.0)
            );
            if size <= 2000 {
                let (t0, c0) = (std::time::Instant::now(), thread_cpu_seconds());
                let best = dijkstra(&grid, start, goal, ArcCost::Integrated).unwrap();
                println!(
                    "{kind} {size}²: reference Dijkstra {:.3} s wall, {:.3} s CPU, cost {best:.3}",
                    t0.elapsed().as_secs_f64(),
                    thread_cpu_seconds() - c0
                );
                assert!((route.cost - best).abs() <= 1e-9 * best);
            }
        }
    }
}
