//! A* restricted to a corridor of blocks, with its per-cell state held only
//! for the corridor blocks it touches (costs, g and flags: 13 bytes a
//! cell, allocated a block at a time), its costs read on demand through
//! the tile LRU, and every step out of the corridor kept as an *exit*.
//!
//! The heuristic inside is plain A*'s (octile distance × the least arc
//! factor): admissible and consistent. An exit from a closed cell b to a
//! cell x outside is valued g(b) + arc(b, x) + max(h(x), L(x)), L the coarse
//! bound of x's block (`coarse_bound`); `leak` is the least exit value.
//! When the goal is closed at cost C:
//!
//! - a path that stays in the corridor costs ≥ C (A* is exact there);
//! - a path that leaves it first leaves from some cell b by a step to x,
//!   and its part up to b lies in the corridor, so it costs
//!   ≥ g*(b) + arc(b, x) + cost(x → goal). If b was closed, that is
//!   ≥ the exit's value ≥ `leak`; if not, consistency gives
//!   g*(b) + arc + h(x) ≥ g*(b) + h(b) ≥ C, A* closing every cell with
//!   g* + h < C.
//!
//! So min(C, leak) bounds the optimum of the whole grid from below, and
//! C is optimal for the whole grid when leak ≥ C.

use super::arc_model::ArcModel;
use super::block_minima::BlockMinima;
use super::bucket_queue::BucketQueue;
use super::coarse_bound::{CoarseBound, Octile};
use super::cost_source::CostSourceError;
use super::neighbourhood::{DIRECTIONS, opposite};
use super::tile_cache::TileCache;
use super::{CANCEL_CHECK_INTERVAL, Cell, RouteError};

const PARENT: u8 = 0b0111;
const CLOSED: u8 = 0b1000;

/// Why a corridor search stopped without an answer.
#[derive(Debug)]
pub(crate) enum SearchFault {
    Route(RouteError),
    Source(CostSourceError),
}

impl From<CostSourceError> for SearchFault {
    fn from(e: CostSourceError) -> Self {
        SearchFault::Source(e)
    }
}

/// What a corridor search found.
#[derive(Debug)]
pub(crate) struct CorridorOutcome {
    /// The cheapest path inside the corridor, start to goal, if any.
    pub(crate) path: Option<Vec<Cell>>,
    /// Its cost (∞ without a path).
    pub(crate) cost: f64,
    /// The least value of a step out of the corridor (∞ without one).
    pub(crate) leak: f64,
    pub(crate) expanded: u64,
    /// Corridor blocks given state.
    pub(crate) blocks_touched: usize,
    /// Most open-list entries at once.
    pub(crate) open_peak: usize,
}

/// Per-cell state of one touched corridor block.
struct BlockState {
    costs: Vec<f32>,
    g: Vec<f64>,
    flags: Vec<u8>,
}

/// Bytes of state per touched cell.
pub(crate) const BYTES_PER_CELL: usize = 4 + 8 + 1;
/// Bytes per open-list entry.
pub(crate) const BYTES_PER_OPEN: usize = 16;

pub(crate) struct CorridorSearch<'c, 'a> {
    pub(crate) cache: &'c mut TileCache<'a>,
    pub(crate) minima: &'c BlockMinima,
    pub(crate) in_corridor: &'c [bool],
    pub(crate) bound: &'c CoarseBound,
    pub(crate) model: &'c ArcModel,
    pub(crate) octile: Octile,
    /// The least arc cost per metre (the heuristic's factor).
    pub(crate) factor: f64,
    pub(crate) limit: u64,
    pub(crate) cancel: &'c dyn Fn() -> bool,
}

struct State {
    slots: Vec<u32>,
    blocks: Vec<BlockState>,
}

const NO_SLOT: u32 = u32::MAX;

impl CorridorSearch<'_, '_> {
    /// A* from `start` to `goal` (both traversable, both in the corridor).
    pub(crate) fn run(&mut self, start: Cell, goal: Cell) -> Result<CorridorOutcome, SearchFault> {
        let source = self.cache.source();
        let (width, height) = (source.width(), source.height());
        let dx = source.dx_per_row().to_vec();
        let dy = source.dy();
        // Diagonal between rows r and r+1, as `Neighbourhood` measures it.
        let diagonal: Vec<f64> = (0..height)
            .map(|r| {
                if r + 1 < height {
                    (0.5 * (dx[r] + dx[r + 1])).hypot(dy)
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        let b = self.minima.block;
        let mut state = State {
            slots: vec![NO_SLOT; self.minima.across * self.minima.down],
            blocks: Vec::new(),
        };
        let (factor, octile) = (self.factor, self.octile);
        let h = move |r: usize, c: usize| {
            factor * octile.distance(r.abs_diff(goal.0), c.abs_diff(goal.1))
        };
        let mut open = open_list(self.model, &self.octile, &dx, dy, &diagonal);
        let mut pushed = 0usize;
        let mut popped = 0usize;
        let mut open_peak = 0;
        let (slot, local) = self.locate(&mut state, start.0, start.1)?;
        state.blocks[slot].g[local] = 0.0;
        let h0 = h(start.0, start.1);
        open.push(entry(h0, h0, id(start, width)));
        let mut leak = f64::INFINITY;
        let mut expanded = 0u64;
        let mut found = None;
        while let Some(top) = open.pop() {
            popped += 1;
            let cell = top as u32 as usize;
            let (r, c) = (cell / width, cell % width);
            let (slot, local) = self.locate(&mut state, r, c)?;
            if state.blocks[slot].flags[local] & CLOSED != 0 {
                continue;
            }
            if (r, c) == goal {
                found = Some(state.blocks[slot].g[local]);
                break;
            }
            if expanded >= self.limit {
                return Err(SearchFault::Route(RouteError::TooManyExpansions {
                    limit: self.limit,
                }));
            }
            if expanded.is_multiple_of(CANCEL_CHECK_INTERVAL) && (self.cancel)() {
                return Err(SearchFault::Route(RouteError::Cancelled));
            }
            state.blocks[slot].flags[local] |= CLOSED;
            expanded += 1;
            let gu = state.blocks[slot].g[local];
            let cost_u = state.blocks[slot].costs[local];
            // E, W, S, N first: the diagonals need both cells they pass.
            let mut near = [f32::NAN; 8];
            for (d, cost) in near.iter_mut().enumerate().take(4) {
                if let Some((vr, vc)) = step((r, c), d, width, height) {
                    *cost = self.cost(&mut state, vr, vc)?;
                }
            }
            for (d, (a, b)) in [(4, (2, 0)), (5, (3, 1)), (6, (2, 1)), (7, (3, 0))] {
                if near[a].is_finite() && near[b].is_finite() {
                    let (vr, vc) = step((r, c), d, width, height).expect("both sides inside");
                    near[d] = self.cost(&mut state, vr, vc)?;
                }
            }
            for (d, &cost_v) in near.iter().enumerate() {
                if !cost_v.is_finite() {
                    continue;
                }
                let (vr, vc) = step((r, c), d, width, height).expect("a finite cost is inside");
                let len = match d {
                    0 | 1 => dx[r],
                    2 | 3 => dy,
                    4 | 6 => diagonal[r],
                    _ => diagonal[r - 1],
                };
                let gv = gu + self.model.arc(len, cost_u, cost_v);
                let vb = self.minima.block_of(vr, vc);
                if !self.in_corridor[vb] {
                    let outside = self.bound.at_block(vr / b, vc / b).max(h(vr, vc));
                    leak = leak.min(gv + outside);
                    continue;
                }
                let (vs, vl) = self.locate(&mut state, vr, vc)?;
                let v = &mut state.blocks[vs];
                if v.flags[vl] & CLOSED != 0 || gv >= v.g[vl] {
                    continue;
                }
                v.g[vl] = gv;
                v.flags[vl] = opposite(d) as u8;
                let hv = h(vr, vc);
                open.push(entry(gv + hv, hv, id((vr, vc), width)));
                pushed += 1;
                open_peak = open_peak.max(pushed - popped);
            }
        }
        let blocks_touched = state.blocks.len();
        let Some(cost) = found else {
            return Ok(CorridorOutcome {
                path: None,
                cost: f64::INFINITY,
                leak,
                expanded,
                blocks_touched,
                open_peak,
            });
        };
        let mut path = vec![goal];
        let mut at = goal;
        while at != start {
            let (slot, local) = self.locate(&mut state, at.0, at.1)?;
            let parent = (state.blocks[slot].flags[local] & PARENT) as usize;
            at = step(at, parent, width, height).expect("parents are inside");
            path.push(at);
            assert!(
                path.len() <= blocks_touched * b * b,
                "the parent chain must reach the start"
            );
        }
        path.reverse();
        Ok(CorridorOutcome {
            path: Some(path),
            cost,
            leak,
            expanded,
            blocks_touched,
            open_peak,
        })
    }

    /// The cost of cell (r, c): from its corridor block's state, NaN in a
    /// lethal block, else through the tile cache (cells just outside).
    fn cost(&mut self, state: &mut State, r: usize, c: usize) -> Result<f32, SearchFault> {
        let block = self.minima.block_of(r, c);
        if self.in_corridor[block] {
            let (slot, local) = self.locate(state, r, c)?;
            Ok(state.blocks[slot].costs[local])
        } else if self.minima.is_lethal(block) {
            Ok(f32::NAN)
        } else {
            Ok(self.cache.cost(r, c)?)
        }
    }

    /// The state slot and index in it of corridor cell (r, c), its block
    /// given state (costs read, g = ∞) on first use.
    fn locate(
        &mut self,
        state: &mut State,
        r: usize,
        c: usize,
    ) -> Result<(usize, usize), SearchFault> {
        let b = self.minima.block;
        let block = self.minima.block_of(r, c);
        let local = (r % b) * b + c % b;
        let slot = state.slots[block];
        if slot != NO_SLOT {
            return Ok((slot as usize, local));
        }
        let source = self.cache.source();
        let (r0, c0) = ((r / b) * b, (c / b) * b);
        let h = b.min(source.height() - r0);
        let w = b.min(source.width() - c0);
        let mut window = vec![0.0f32; w * h];
        self.cache.copy_window(r0, c0, h, w, &mut window)?;
        // Cells past the raster's edge stay blocked.
        let mut costs = vec![f32::NAN; b * b];
        for (i, row) in window.chunks_exact(w).enumerate() {
            costs[i * b..i * b + w].copy_from_slice(row);
        }
        state.blocks.push(BlockState {
            costs,
            g: vec![f64::INFINITY; b * b],
            flags: vec![0; b * b],
        });
        let slot = state.blocks.len() - 1;
        state.slots[block] = slot as u32;
        Ok((slot, local))
    }
}

/// Row-major cell number (the caller checked that the map has at most
/// 2³² cells).
#[inline]
fn id((r, c): Cell, width: usize) -> u32 {
    (r * width + c) as u32
}

/// An open-list entry: f, then the smaller h, then the cell (as A*'s).
#[inline]
fn entry(f: f64, h: f64, cell: u32) -> u128 {
    (u128::from(f.to_bits()) << 64) | (u128::from((h as f32).to_bits()) << 32) | u128::from(cell)
}

/// The open list, its buckets sized as A*'s (`astar::open_list`): a
/// sixteenth of the cheapest arc wide, over twice the dearest arc.
fn open_list(
    model: &ArcModel,
    octile: &Octile,
    dx: &[f64],
    dy: f64,
    diagonal: &[f64],
) -> BucketQueue {
    const MAX_BUCKETS: f64 = 4094.0;
    let cheapest = octile.dx_min.min(dy) * model.heuristic_factor();
    let longest = diagonal
        .iter()
        .chain(dx)
        .copied()
        .filter(|l| l.is_finite())
        .fold(dy, f64::max);
    let spread = 2.0 * longest * model.largest_factor();
    let mut width = cheapest / 16.0;
    let mut buckets = (spread / width).ceil();
    if !(buckets.is_finite() && buckets < MAX_BUCKETS) {
        buckets = MAX_BUCKETS;
        width = spread / buckets;
    }
    if !(width.is_finite() && width > 0.0) {
        width = 1.0;
    }
    BucketQueue::new(width, buckets as usize + 2)
}

/// The cell reached from (r, c) by move `d`, `None` outside the grid.
#[inline]
fn step((r, c): Cell, d: usize, width: usize, height: usize) -> Option<Cell> {
    let (dr, dc) = DIRECTIONS[d];
    let vr = r.checked_add_signed(dr)?;
    let vc = c.checked_add_signed(dc)?;
    (vr < height && vc < width).then_some((vr, vc))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::coarse_route::corridor;
    use crate::route::{ArcCost, CostGrid, RouteOptions, astar};

    fn search(
        grid: &CostGrid,
        block: usize,
        in_corridor: &[bool],
        start: Cell,
        goal: Cell,
    ) -> CorridorOutcome {
        let minima = BlockMinima::build(grid, block).unwrap();
        let model = ArcModel::new(ArcCost::Integrated, minima.cost_range());
        let octile = Octile::new(grid.dx_per_row(), grid.dy());
        let bound = CoarseBound::new(&minima, &model, &octile, 2, goal);
        let mut cache = TileCache::new(grid, 32, 4);
        CorridorSearch {
            cache: &mut cache,
            minima: &minima,
            in_corridor,
            bound: &bound,
            model: &model,
            octile,
            factor: model.heuristic_factor(),
            limit: u64::MAX,
            cancel: &|| false,
        }
        .run(start, goal)
        .unwrap()
    }

    #[test]
    fn a_corridor_of_every_block_is_plain_a_star() {
        let mut rng = crate::route::testing::Rng::new(3);
        let grid = crate::route::testing::random_grid(&mut rng, 50, 40, 0.2, true);
        let (start, goal) = crate::route::testing::random_endpoints(&mut rng, &grid).unwrap();
        let all = vec![true; 13 * 10];
        let out = search(&grid, 4, &all, start, goal);
        let plain = astar(&grid, start, goal, &RouteOptions::default(), &|| false);
        match plain {
            Ok(route) => {
                assert!((out.cost - route.cost).abs() <= 1e-9 * route.cost);
                let path = out.path.unwrap();
                assert_eq!((path[0], *path.last().unwrap()), (start, goal));
            }
            Err(_) => assert!(out.path.is_none()),
        }
        assert_eq!(out.leak, f64::INFINITY, "no cell is outside");
    }

    #[test]
    fn a_wall_across_the_corridor_leaks_round_it() {
        // Open ground, a wall across rows 0..28 at column 20: the straight
        // corridor along row 2 is closed, the way round leaves it.
        let (w, h) = (40, 32);
        let costs = (0..w * h)
            .map(|i| {
                if i % w == 20 && i / w < 28 {
                    f32::NAN
                } else {
                    1.0
                }
            })
            .collect();
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        let minima = BlockMinima::build(&grid, 4).unwrap();
        let route: Vec<usize> = (0..10).map(|c| minima.index(0, c)).collect();
        let narrow = corridor(&minima, &route, 1);
        let out = search(&grid, 4, &narrow, (2, 2), (2, 37));
        assert!(out.path.is_none());
        assert!(out.leak.is_finite());
        let exact = astar(&grid, (2, 2), (2, 37), &RouteOptions::default(), &|| false)
            .unwrap()
            .cost;
        assert!(out.leak <= exact * (1.0 + 1e-12), "{} {exact}", out.leak);
    }
}
