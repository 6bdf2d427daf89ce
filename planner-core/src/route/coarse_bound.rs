//! A lower bound, per block, on the cost of any fine path from any cell of
//! the block to the goal, computed on the coarse level alone (block minima
//! and maxima): the proof that a route found inside a corridor is optimal
//! compares it with what leaving the corridor must cost.
//!
//! The argument (R = K·B cells, K the reach in blocks, B the block side):
//! cut a fine path x = p₀ … t at milestones, p_{i+1} being the first cell
//! after p_i at Chebyshev distance R from it (each step moves the distance
//! by at most one, so it is exactly R). Then
//!
//! - every cell from p_i to p_{i+1} lies within R cells of p_i, so in the
//!   (2K+1)² blocks around p_i's block X_i: each step there costs at least
//!   its length × φ(X_i), the least arc factor any two costs of that square
//!   can give (`integrated`: its least cost; `thesis`: the factor of its
//!   least cost minus its largest, the rule growing with the difference);
//! - p_{i+1} is R cells from p_i along one axis, so its block is exactly K
//!   blocks away along that axis and at most K along the other; a block
//!   offset (a, b) needs at least (|a|−1)·B + 1 cells along an axis where
//!   a ≠ 0, and R along the axis of the milestone: the segment is at least
//!   as long as the octile distance of those cell counts (with the
//!   narrowest cells, as the A* heuristic measures);
//! - after the last milestone the path stays within R cells, so its block
//!   is within K blocks of the goal's: those blocks start at 0.
//!
//! So the milestones' blocks are a walk of offsets of Chebyshev length K
//! over traversable blocks whose weights never exceed the fine costs, and
//! the cheapest such walk (Dijkstra from the goal's blocks) is a lower
//! bound for every cell of its first block. Diagonal and lethal cells need
//! no special case: corner cutting only removes fine paths, lethal cells
//! only remove steps, and a lethal block holds no milestone. The bound
//! loses a fraction of about 1/K on diagonal runs (the offset (K, K) may
//! be realised with (K−1)·B + 1 cells along one axis) and what the square's
//! least cost is below the costs actually crossed.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use super::arc_model::ArcModel;
use super::block_minima::BlockMinima;

/// Octile distances in metres with the narrowest cells: a lower bound on
/// the length of any 8-connected path with those row and column counts
/// (as `Neighbourhood::octile`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Octile {
    pub(crate) dx_min: f64,
    pub(crate) dy: f64,
    pub(crate) diagonal_min: f64,
}

impl Octile {
    pub(crate) fn new(dx_per_row: &[f64], dy: f64) -> Octile {
        let dx_min = dx_per_row.iter().copied().fold(f64::INFINITY, f64::min);
        Octile {
            dx_min,
            dy,
            diagonal_min: dx_min.hypot(dy),
        }
    }

    #[inline]
    pub(crate) fn distance(&self, rows: usize, cols: usize) -> f64 {
        if cols >= rows {
            rows as f64 * self.diagonal_min + (cols - rows) as f64 * self.dx_min
        } else {
            cols as f64 * self.diagonal_min + (rows - cols) as f64 * self.dy
        }
    }
}

/// The per-block lower bound on the cost to the goal.
pub(crate) struct CoarseBound {
    across: usize,
    to_goal: Vec<f64>,
}

impl CoarseBound {
    /// The bound for the goal cell `goal` = (row, col), with reach `reach`
    /// (K ≥ 1) blocks.
    pub(crate) fn new(
        minima: &BlockMinima,
        model: &ArcModel,
        octile: &Octile,
        reach: usize,
        goal: (usize, usize),
    ) -> CoarseBound {
        let k = reach.max(1);
        let (across, down, b) = (minima.across, minima.down, minima.block);
        let factor = square_factors(minima, model, k);
        // The offsets of Chebyshev length K and the least length of a
        // milestone segment realising each.
        let cells = |blocks: usize| if blocks == 0 { 0 } else { (blocks - 1) * b + 1 };
        let moves: Vec<(isize, isize, f64)> = (-(k as isize)..=k as isize)
            .flat_map(|a| (-(k as isize)..=k as isize).map(move |c| (a, c)))
            .filter(|&(a, c)| a.unsigned_abs().max(c.unsigned_abs()) == k)
            .map(|(a, c)| {
                let (ua, uc) = (a.unsigned_abs(), c.unsigned_abs());
                let mut len = f64::INFINITY;
                if ua == k {
                    len = len.min(octile.distance(k * b, cells(uc)));
                }
                if uc == k {
                    len = len.min(octile.distance(cells(ua), k * b));
                }
                (a, c, len)
            })
            .collect();
        let mut to_goal = vec![f64::INFINITY; across * down];
        let mut open = BinaryHeap::new();
        let (gr, gc) = (goal.0 / b, goal.1 / b);
        for r in gr.saturating_sub(k)..(gr + k + 1).min(down) {
            for c in gc.saturating_sub(k)..(gc + k + 1).min(across) {
                let i = r * across + c;
                if !minima.is_lethal(i) {
                    to_goal[i] = 0.0;
                    open.push(Reverse((0u64, i as u32)));
                }
            }
        }
        while let Some(Reverse((bits, y))) = open.pop() {
            let dy = f64::from_bits(bits);
            let y = y as usize;
            if dy > to_goal[y] {
                continue;
            }
            let (yr, yc) = ((y / across) as isize, (y % across) as isize);
            for &(a, c, len) in &moves {
                let (xr, xc) = (yr - a, yc - c);
                if xr < 0 || xc < 0 || xr >= down as isize || xc >= across as isize {
                    continue;
                }
                let x = xr as usize * across + xc as usize;
                if minima.is_lethal(x) {
                    continue;
                }
                let candidate = dy + len * factor[x];
                if candidate < to_goal[x] {
                    to_goal[x] = candidate;
                    open.push(Reverse((candidate.to_bits(), x as u32)));
                }
            }
        }
        CoarseBound { across, to_goal }
    }

    /// The bound for any cell of block (row, col) (∞: the goal cannot be
    /// reached from it).
    #[inline]
    pub(crate) fn at_block(&self, row: usize, col: usize) -> f64 {
        self.to_goal[row * self.across + col]
    }

    pub(crate) fn bytes(&self) -> usize {
        8 * self.to_goal.len()
    }
}

/// φ per block: the least arc cost per metre of a step between any two
/// cells of the (2K+1)² blocks around it (separable running min and max;
/// lethal blocks count for nothing).
fn square_factors(minima: &BlockMinima, model: &ArcModel, k: usize) -> Vec<f64> {
    let (across, down) = (minima.across, minima.down);
    let lo: Vec<f32> = minima
        .min
        .iter()
        .map(|&v| if v.is_nan() { f32::INFINITY } else { v })
        .collect();
    let hi: Vec<f32> = minima
        .max
        .iter()
        .map(|&v| if v.is_nan() { f32::NEG_INFINITY } else { v })
        .collect();
    let lo = window(
        &window(&lo, across, down, k, f32::min, true),
        across,
        down,
        k,
        f32::min,
        false,
    );
    let hi = window(
        &window(&hi, across, down, k, f32::max, true),
        across,
        down,
        k,
        f32::max,
        false,
    );
    lo.iter()
        .zip(&hi)
        .map(|(&l, &h)| {
            if !l.is_finite() {
                f64::INFINITY
            } else if model.is_thesis() {
                model.arc(1.0, h, l)
            } else {
                f64::from(l)
            }
        })
        .collect()
}

/// A running `op` over 2k+1 blocks along rows (`along_rows`) or columns.
fn window(
    values: &[f32],
    across: usize,
    down: usize,
    k: usize,
    op: fn(f32, f32) -> f32,
    along_rows: bool,
) -> Vec<f32> {
    let mut out = values.to_vec();
    for r in 0..down {
        for c in 0..across {
            let acc = if along_rows {
                (c.saturating_sub(k)..(c + k + 1).min(across))
                    .map(|j| values[r * across + j])
                    .reduce(op)
            } else {
                (r.saturating_sub(k)..(r + k + 1).min(down))
                    .map(|i| values[i * across + c])
                    .reduce(op)
            };
            out[r * across + c] = acc.expect("the window holds the block itself");
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::route::neighbourhood::Neighbourhood;
    use crate::route::testing::{Rng, random_arc, random_grid};
    use crate::route::{ArcCost, CostGrid};

    /// The exact cost from every cell to `goal` (Dijkstra over reversed
    /// arcs, the search graph of every planner): the reference the bounds
    /// are checked against.
    pub(crate) fn exact_cost_to_goal(grid: &CostGrid, goal: usize, model: &ArcModel) -> Vec<f64> {
        let hood = Neighbourhood::new(grid);
        let costs = grid.costs();
        let w = grid.width();
        let mut dist = vec![f64::INFINITY; costs.len()];
        let mut open = BinaryHeap::new();
        dist[goal] = 0.0;
        open.push(Reverse((0u64, goal)));
        while let Some(Reverse((bits, y))) = open.pop() {
            let d = f64::from_bits(bits);
            if d > dist[y] {
                continue;
            }
            // x → y is a move iff y → x is (the rules are symmetric).
            let mut moves = hood.moves(costs, y, y / w, y % w);
            while moves != 0 {
                let m = moves.trailing_zeros() as usize;
                moves &= moves - 1;
                let x = hood.neighbour(y, m);
                let len = hood.step_len(y / w, m);
                let candidate = d + model.arc(len, costs[x], costs[y]);
                if candidate < dist[x] {
                    dist[x] = candidate;
                    open.push(Reverse((candidate.to_bits(), x)));
                }
            }
        }
        dist
    }

    #[test]
    fn the_bound_never_exceeds_the_exact_cost_to_the_goal() {
        let mut rng = Rng::new(21);
        let mut checked = 0usize;
        let mut useful = 0usize;
        for trial in 0..160 {
            let w = 8 + rng.below(70) as usize;
            let h = 8 + rng.below(70) as usize;
            let density = [0.0, 0.1, 0.3][trial % 3];
            let grid = random_grid(&mut rng, w, h, density, trial % 2 == 0);
            let arc = random_arc(&mut rng, trial % 4 == 3);
            let model = ArcModel::new(arc, grid.finite_cost_range());
            let goal = (rng.below(h as u64) as usize, rng.below(w as u64) as usize);
            if !grid.is_traversable(goal) {
                continue;
            }
            let block = [1, 2, 4, 8][trial % 4];
            let reach = 1 + trial % 3;
            let minima = BlockMinima::build(&grid, block).unwrap();
            let octile = Octile::new(grid.dx_per_row(), grid.dy());
            let bound = CoarseBound::new(&minima, &model, &octile, reach, goal);
            let exact = exact_cost_to_goal(&grid, goal.0 * w + goal.1, &model);
            for (i, &e) in exact.iter().enumerate() {
                let (r, c) = (i / w, i % w);
                if !grid.is_traversable((r, c)) {
                    continue;
                }
                let lb = bound.at_block(r / block, c / block);
                assert!(
                    lb <= e * (1.0 + 1e-12),
                    "trial {trial}: cell ({r}, {c}) bound {lb} > exact {e} (block {block}, K {reach})"
                );
                if e.is_finite() {
                    checked += 1;
                    if lb > 0.5 * e && e > 0.0 {
                        useful += 1;
                    }
                }
            }
        }
        assert!(checked > 50_000, "{checked}");
        // Not a trivial bound, even on these small maps whose costs often
        // vary cell by cell (so a square's least cost is far below what a
        // path pays): about a tenth of the cells get over half their cost.
        assert!(useful * 20 > checked, "{useful} of {checked}");
    }

    #[test]
    fn on_open_uniform_ground_the_bound_grows_with_distance() {
        let (w, h) = (256, 256);
        let grid = CostGrid::with_cell_size(w, h, vec![2.0; w * h], 1.0, 1.0).unwrap();
        let model = ArcModel::new(ArcCost::Integrated, grid.finite_cost_range());
        let minima = BlockMinima::build(&grid, 8).unwrap();
        let octile = Octile::new(grid.dx_per_row(), grid.dy());
        let bound = CoarseBound::new(&minima, &model, &octile, 4, (0, 0));
        // Straight along a row: exact 2 × 255 from the far end; the bound
        // loses at most the goal's reach (K blocks) and a cell per segment.
        let far = bound.at_block(0, 31);
        assert!((2.0 * (255.0 - 40.0)..=510.0).contains(&far), "{far}");
        // Diagonal: exact 2 × 255·√2 ≈ 721; the bound keeps ≥ 3/4 of it.
        let diagonal = bound.at_block(31, 31);
        assert!(diagonal <= 721.3 && diagonal > 0.75 * 721.0, "{diagonal}");
        // Blocks near the goal start at 0.
        assert_eq!(bound.at_block(4, 4), 0.0);
    }
}
