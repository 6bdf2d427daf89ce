//! The search graph shared by every planner: 8-connected moves without
//! corner cutting, step lengths in metres per row, and a bounded flood fill
//! that answers "unreachable" early when an endpoint sits in a small pocket.

use super::CostGrid;

/// Moves as (row delta, column delta): E, W, S, N, SE, NW, SW, NE. Paired so
/// that `d ^ 1` is the opposite move, which lets a search keep "where I came
/// from" in 3 bits.
pub(crate) const DIRECTIONS: [(isize, isize); 8] = [
    (0, 1),
    (0, -1),
    (1, 0),
    (-1, 0),
    (1, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
];

pub(crate) const fn opposite(d: usize) -> usize {
    d ^ 1
}

/// Neighbour offsets and step lengths of one grid, precomputed once per
/// search so that the inner loop only adds and looks up.
#[derive(Clone)]
pub(crate) struct Neighbourhood {
    width: usize,
    height: usize,
    /// Row-major index offset of each move.
    offsets: [isize; 8],
    /// Step length (metres) per row and move; moves that would leave the
    /// grid are never taken, their entry is ∞.
    steps: Vec<[f64; 8]>,
    dx_min: f64,
    dy: f64,
    diagonal_min: f64,
}

impl Neighbourhood {
    pub(crate) fn new(grid: &CostGrid) -> Neighbourhood {
        let (width, height) = (grid.width(), grid.height());
        let w = width as isize;
        let mut offsets = [0isize; 8];
        for (o, (dr, dc)) in offsets.iter_mut().zip(DIRECTIONS) {
            *o = dr * w + dc;
        }
        let dy = grid.dy();
        // A diagonal between rows r and r+1 uses the mean of their widths,
        // the same from either end.
        let diagonal = |r: usize| {
            if r + 1 < height {
                (0.5 * (grid.dx(r) + grid.dx(r + 1))).hypot(dy)
            } else {
                f64::INFINITY
            }
        };
        let steps = (0..height)
            .map(|r| {
                let dx = grid.dx(r);
                let down = diagonal(r);
                let up = if r > 0 {
                    diagonal(r - 1)
                } else {
                    f64::INFINITY
                };
                [dx, dx, dy, dy, down, up, down, up]
            })
            .collect();
        let dx_min = grid
            .dx_per_row()
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        Neighbourhood {
            width,
            height,
            offsets,
            steps,
            dx_min,
            dy,
            diagonal_min: dx_min.hypot(dy),
        }
    }

    pub(crate) fn width(&self) -> usize {
        self.width
    }

    /// The shortest step in the grid (metres).
    pub(crate) fn shortest_step(&self) -> f64 {
        self.dx_min.min(self.dy)
    }

    /// The longest step in the grid (metres).
    pub(crate) fn longest_step(&self) -> f64 {
        self.steps
            .iter()
            .flatten()
            .copied()
            .filter(|l| l.is_finite())
            .fold(0.0, f64::max)
    }

    /// The moves out of cell `i` = (`r`, `c`) as a bit set (bit d = move d):
    /// onto traversable cells inside the grid, diagonals only when both
    /// orthogonal cells they pass are traversable. Empty for a blocked cell.
    #[inline]
    pub(crate) fn moves(&self, costs: &[f32], i: usize, r: usize, c: usize) -> u8 {
        if !costs[i].is_finite() {
            return 0;
        }
        let w = self.width;
        let east = c + 1 < self.width && costs[i + 1].is_finite();
        let west = c > 0 && costs[i - 1].is_finite();
        let south = r + 1 < self.height && costs[i + w].is_finite();
        let north = r > 0 && costs[i - w].is_finite();
        let south_east = south && east && costs[i + w + 1].is_finite();
        let north_west = north && west && costs[i - w - 1].is_finite();
        let south_west = south && west && costs[i + w - 1].is_finite();
        let north_east = north && east && costs[i - w + 1].is_finite();
        (east as u8)
            | (west as u8) << 1
            | (south as u8) << 2
            | (north as u8) << 3
            | (south_east as u8) << 4
            | (north_west as u8) << 5
            | (south_west as u8) << 6
            | (north_east as u8) << 7
    }

    /// The cell reached from `i` by move `d` (which must stay inside).
    #[inline]
    pub(crate) fn neighbour(&self, i: usize, d: usize) -> usize {
        i.wrapping_add_signed(self.offsets[d])
    }

    /// Lengths in metres of the 8 moves from a cell in `row`.
    #[inline]
    pub(crate) fn row_steps(&self, row: usize) -> &[f64; 8] {
        &self.steps[row]
    }

    /// Length in metres of move `d` from a cell in `row`.
    #[inline]
    pub(crate) fn step_len(&self, row: usize, d: usize) -> f64 {
        self.steps[row][d]
    }

    /// The move from `a` to its 8-neighbour `b`, `None` if not neighbours.
    pub(crate) fn direction(&self, a: usize, b: usize) -> Option<usize> {
        let (ar, ac) = ((a / self.width) as isize, (a % self.width) as isize);
        let (br, bc) = ((b / self.width) as isize, (b % self.width) as isize);
        DIRECTIONS.iter().position(|&d| d == (br - ar, bc - ac))
    }

    /// Octile distance in metres, a lower bound on the length of any path
    /// between the two cells: it is the exact shortest path on an open grid
    /// whose cells are all `dx_min` wide, and wider cells only lengthen steps.
    #[inline]
    pub(crate) fn octile(&self, rows: usize, cols: usize) -> f64 {
        if cols >= rows {
            rows as f64 * self.diagonal_min + (cols - rows) as f64 * self.dx_min
        } else {
            cols as f64 * self.diagonal_min + (rows - cols) as f64 * self.dy
        }
    }

    /// Flood-fills the traversable region of `from` (same moves as the
    /// searches) for at most `budget` cells. True when the whole region was
    /// seen and `other` is not in it: the two are certainly disconnected.
    /// The marks are cleared again before returning.
    pub(crate) fn region_excludes(
        &self,
        costs: &[f32],
        marks: &mut impl Marks,
        from: usize,
        other: usize,
        budget: usize,
    ) -> bool {
        let mut seen: Vec<u32> = vec![from as u32];
        marks.mark(from);
        let mut head = 0;
        let mut verdict = true;
        'flood: while head < seen.len() {
            let u = seen[head] as usize;
            head += 1;
            let mut moves = self.moves(costs, u, u / self.width, u % self.width);
            while moves != 0 {
                let d = moves.trailing_zeros() as usize;
                moves &= moves - 1;
                let v = self.neighbour(u, d);
                if v == other || seen.len() >= budget {
                    verdict = false;
                    break 'flood;
                }
                if marks.mark(v) {
                    seen.push(v as u32);
                }
            }
        }
        for &v in &seen {
            marks.unmark(v as usize);
        }
        verdict
    }
}

/// Scratch marks for [`Neighbourhood::region_excludes`], kept in a search's
/// own per-cell state.
pub(crate) trait Marks {
    /// Marks cell i; true if it was not marked before.
    fn mark(&mut self, i: usize) -> bool;
    fn unmark(&mut self, i: usize);
}

/// One bit of a byte per cell.
pub(crate) struct ByteMarks<'a> {
    pub(crate) bytes: &'a mut [u8],
    pub(crate) bit: u8,
}

impl Marks for ByteMarks<'_> {
    fn mark(&mut self, i: usize) -> bool {
        let new = self.bytes[i] & self.bit == 0;
        self.bytes[i] |= self.bit;
        new
    }

    fn unmark(&mut self, i: usize) {
        self.bytes[i] &= !self.bit;
    }
}

/// Cells the early unreachability flood may visit: a small fraction of the
/// grid, so it costs little next to the search it can save.
pub(crate) fn flood_budget(cells: usize) -> usize {
    (cells / 32).clamp(1 << 12, 1 << 18)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(width: usize, height: usize, costs: Vec<f32>) -> CostGrid {
        CostGrid::with_cell_size(width, height, costs, 1.0, 1.0).unwrap()
    }

    #[test]
    fn directions_pair_with_their_opposites() {
        for d in 0..8 {
            let (dr, dc) = DIRECTIONS[d];
            assert_eq!(DIRECTIONS[opposite(d)], (-dr, -dc));
        }
    }

    #[test]
    fn moves_respect_borders_obstacles_and_corners() {
        const X: f32 = f32::NAN;
        // 3×3, centre free; blocked north and east → no N, E, NE, and also
        // no NW (passes north) and no SE (passes east).
        let g = grid(3, 3, vec![1.0, X, 1.0, 1.0, 1.0, X, 1.0, 1.0, 1.0]);
        let hood = Neighbourhood::new(&g);
        let m = hood.moves(g.costs(), 4, 1, 1);
        let allowed: Vec<(isize, isize)> = (0..8)
            .filter(|d| m & (1 << d) != 0)
            .map(|d| DIRECTIONS[d])
            .collect();
        assert_eq!(allowed, vec![(0, -1), (1, 0), (1, -1)]);
        // Corner cell: only inward moves.
        let open = grid(3, 3, vec![1.0; 9]);
        let hood = Neighbourhood::new(&open);
        let m = hood.moves(open.costs(), 0, 0, 0);
        assert_eq!(m.count_ones(), 3);
        assert_eq!(hood.moves(open.costs(), 4, 1, 1), 0xff);
        // A blocked cell has no moves.
        assert_eq!(hood.moves(g.costs(), 1, 0, 1), 0);
    }

    #[test]
    fn step_lengths_follow_row_widths() {
        let g = CostGrid::new(2, 3, vec![1.0; 6], vec![1.0, 3.0, 5.0], 2.0).unwrap();
        let hood = Neighbourhood::new(&g);
        assert_eq!(hood.step_len(1, 0), 3.0);
        assert_eq!(hood.step_len(1, 2), 2.0);
        // Diagonal between rows 1 and 2: mean width 4.
        assert!((hood.step_len(1, 4) - 20f64.sqrt()).abs() < 1e-12);
        assert_eq!(hood.step_len(1, 4), hood.step_len(2, 5));
        assert_eq!(hood.step_len(0, 4), hood.step_len(1, 7));
        assert_eq!(hood.direction(0, 3), Some(4));
        assert_eq!(hood.direction(3, 0), Some(5));
        assert_eq!(hood.direction(0, 5), None);
        // Octile with the narrowest row.
        assert!((hood.octile(2, 3) - (2.0 * 5f64.sqrt() + 1.0)).abs() < 1e-12);
        assert!((hood.octile(3, 1) - (5f64.sqrt() + 4.0)).abs() < 1e-12);
    }

    #[test]
    fn flood_detects_pockets_only_when_complete() {
        const X: f32 = f32::NAN;
        #[rustfmt::skip]
        let g = grid(5, 5, vec![
            1.0, 1.0, 1.0, 1.0, 1.0,
            1.0, X,   X,   X,   1.0,
            1.0, X,   1.0, X,   1.0,
            1.0, X,   X,   X,   1.0,
            1.0, 1.0, 1.0, 1.0, 1.0,
        ]);
        let hood = Neighbourhood::new(&g);
        let mut state = vec![0u8; 25];
        let mut marks = ByteMarks {
            bytes: &mut state,
            bit: 0x80,
        };
        assert!(hood.region_excludes(g.costs(), &mut marks, 12, 0, 100));
        assert!(hood.region_excludes(g.costs(), &mut marks, 0, 12, 100));
        assert!(!hood.region_excludes(g.costs(), &mut marks, 0, 24, 100));
        // Budget too small to see the whole ring: no verdict.
        assert!(!hood.region_excludes(g.costs(), &mut marks, 0, 12, 5));
        assert!(state.iter().all(|&s| s == 0), "scratch bit cleared");
    }
}
