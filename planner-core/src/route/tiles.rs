//! A tiled copy of a cost grid, for searches over large maps.
//!
//! A search's working set is its frontier, a band of cells across the
//! whole map. In row-major order each expanded cell touches three rows
//! that lie a full row apart in memory (32 kB of f64 labels on a 4000-wide
//! grid), so the band spans tens of thousands of pages and every expansion
//! misses the TLB several times. Stored as 16 × 16 tiles, a cell and its
//! neighbours share one tile (and page) three times out of four, and the
//! band fits the TLB: on a 4000² costmap A* runs about twice as fast.
//!
//! Tiles past the grid's right and bottom edges are padded with blocked
//! cells, so a grid whose sides are multiples of 16 needs no padding.

use rayon::prelude::*;

use super::CostGrid;
use super::neighbourhood::DIRECTIONS;

const TILE_BITS: usize = 4;
/// Tile side, in cells.
pub(crate) const TILE: usize = 1 << TILE_BITS;
const TILE_MASK: usize = TILE - 1;
/// Index offsets of the 8 moves for a cell inside its tile.
const INNER_OFFSETS: [isize; 8] = {
    let mut offsets = [0isize; 8];
    let mut d = 0;
    while d < 8 {
        offsets[d] = DIRECTIONS[d].0 * TILE as isize + DIRECTIONS[d].1;
        d += 1;
    }
    offsets
};
/// A neighbour outside the padded grid.
const OUTSIDE: usize = usize::MAX;

/// Where each cell sits in the tiled order: enough to index a search's
/// tiled labels after its cost copy is gone.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TileLayout {
    tiles_per_row: usize,
}

impl TileLayout {
    /// Tiled index of cell (r, c) of the padded grid.
    #[inline]
    pub(crate) fn index(self, r: usize, c: usize) -> usize {
        (((r >> TILE_BITS) * self.tiles_per_row + (c >> TILE_BITS)) << (2 * TILE_BITS))
            | ((r & TILE_MASK) << TILE_BITS)
            | (c & TILE_MASK)
    }
}

/// Number of cells of `grid` padded to whole tiles.
pub(crate) fn padded_cells(grid: &CostGrid) -> usize {
    grid.width().div_ceil(TILE) * TILE * grid.height().div_ceil(TILE) * TILE
}

pub(crate) struct Tiles {
    tiles_per_row: usize,
    /// ⌊2⁶⁴ / tiles_per_row⌋ + 1: exact division of tile numbers (< 2³²)
    /// by a multiply (Lemire's fastdiv).
    tiles_per_row_reciprocal: u128,
    padded_rows: usize,
    padded_cols: usize,
    costs: Vec<f32>,
}

impl Tiles {
    /// The tiled copy of `grid`'s costs (4 bytes per padded cell).
    pub(crate) fn new(grid: &CostGrid) -> Tiles {
        let (width, height) = (grid.width(), grid.height());
        let tiles_per_row = width.div_ceil(TILE);
        let padded_rows = height.div_ceil(TILE) * TILE;
        let mut tiles = Tiles {
            tiles_per_row,
            tiles_per_row_reciprocal: (1u128 << 64) / tiles_per_row as u128 + 1,
            padded_rows,
            padded_cols: tiles_per_row * TILE,
            costs: Vec::new(),
        };
        // Fresh pages (calloc), on huge pages where granted, written band
        // by band in parallel: a band of tiles is 16 whole grid rows.
        let mut costs = vec![0.0f32; padded_cells(grid)];
        crate::buffer::advise_huge_pages(costs.as_mut_ptr().cast(), costs.len() * 4);
        let src = grid.costs();
        costs
            .par_chunks_mut(TILE * tiles.padded_cols)
            .enumerate()
            .for_each(|(band_index, band)| {
                for (tile_col, tile) in band.chunks_exact_mut(TILE * TILE).enumerate() {
                    let c0 = tile_col * TILE;
                    for (tile_row, out) in tile.chunks_exact_mut(TILE).enumerate() {
                        let r = band_index * TILE + tile_row;
                        if r < height && c0 + TILE <= width {
                            out.copy_from_slice(&src[r * width + c0..][..TILE]);
                        } else {
                            // Padding past the grid's edges: blocked.
                            for (c, x) in (c0..).zip(out.iter_mut()) {
                                *x = if r < height && c < width {
                                    src[r * width + c]
                                } else {
                                    f32::NAN
                                };
                            }
                        }
                    }
                }
            });
        tiles.costs = costs;
        tiles
    }

    /// Number of (padded) cells.
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.costs.len()
    }

    /// Where cell `t`'s cost is stored (for prefetching).
    #[inline(always)]
    pub(crate) fn cost_ptr(&self, t: usize) -> *const f32 {
        &raw const self.costs[t]
    }

    #[inline]
    pub(crate) fn cost(&self, t: usize) -> f32 {
        self.costs[t]
    }

    /// Tiled index of cell (r, c) of the padded grid.
    #[inline]
    pub(crate) fn index(&self, r: usize, c: usize) -> usize {
        self.layout().index(r, c)
    }

    pub(crate) fn layout(&self) -> TileLayout {
        TileLayout {
            tiles_per_row: self.tiles_per_row,
        }
    }

    /// (row, col) of tiled index `t`.
    #[inline]
    pub(crate) fn row_col(&self, t: usize) -> (usize, usize) {
        let tile = t >> (2 * TILE_BITS);
        let tile_row = ((self.tiles_per_row_reciprocal * tile as u128) >> 64) as usize;
        let tile_col = tile - tile_row * self.tiles_per_row;
        (
            (tile_row << TILE_BITS) | ((t >> TILE_BITS) & TILE_MASK),
            (tile_col << TILE_BITS) | (t & TILE_MASK),
        )
    }

    /// The cell reached from (r, c) by move `d` (it must stay inside).
    #[inline]
    pub(crate) fn step(&self, r: usize, c: usize, d: usize) -> (usize, usize) {
        let (dr, dc) = DIRECTIONS[d];
        (r.wrapping_add_signed(dr), c.wrapping_add_signed(dc))
    }

    /// The neighbours of cell `t` = (`r`, `c`) and the moves to them (bit
    /// d = move d), with the searches' rules: onto traversable cells,
    /// diagonals only past two traversable orthogonal cells.
    #[inline(always)]
    pub(crate) fn moves(&self, t: usize, r: usize, c: usize) -> ([usize; 8], u8) {
        let mut neighbours = [OUTSIDE; 8];
        if (r & TILE_MASK).wrapping_sub(1) < TILE - 2 && (c & TILE_MASK).wrapping_sub(1) < TILE - 2
        {
            for (n, offset) in neighbours.iter_mut().zip(INNER_OFFSETS) {
                *n = t.wrapping_add_signed(offset);
            }
        } else {
            for (n, (dr, dc)) in neighbours.iter_mut().zip(DIRECTIONS) {
                let (nr, nc) = (r.wrapping_add_signed(dr), c.wrapping_add_signed(dc));
                if nr < self.padded_rows && nc < self.padded_cols {
                    *n = self.index(nr, nc);
                }
            }
        }
        let free = |d: usize| neighbours[d] != OUTSIDE && self.costs[neighbours[d]].is_finite();
        let (east, west, south, north) = (free(0), free(1), free(2), free(3));
        let moves = (east as u8)
            | (west as u8) << 1
            | (south as u8) << 2
            | (north as u8) << 3
            | ((south && east && free(4)) as u8) << 4
            | ((north && west && free(5)) as u8) << 5
            | ((south && west && free(6)) as u8) << 6
            | ((north && east && free(7)) as u8) << 7;
        (neighbours, moves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::neighbourhood::Neighbourhood;
    use crate::route::testing::{Rng, random_grid};

    #[test]
    fn indices_round_trip_and_cover_the_grid_once() {
        for (w, h) in [(1, 1), (16, 16), (17, 5), (40, 33), (3, 70)] {
            let grid = CostGrid::with_cell_size(w, h, vec![1.0; w * h], 1.0, 1.0).unwrap();
            let tiles = Tiles::new(&grid);
            assert_eq!(tiles.len() % (TILE * TILE), 0);
            let mut seen = vec![false; tiles.len()];
            for r in 0..tiles.padded_rows {
                for c in 0..tiles.padded_cols {
                    let t = tiles.index(r, c);
                    assert!(!seen[t]);
                    seen[t] = true;
                    assert_eq!(tiles.row_col(t), (r, c));
                    assert_eq!(tiles.cost(t).is_finite(), r < h && c < w);
                }
            }
            assert!(seen.iter().all(|&s| s));
        }
    }

    #[test]
    fn row_col_divides_exactly_for_any_width() {
        let mut rng = Rng::new(2);
        for tiles_per_row in [1usize, 2, 3, 7, 250, 4097, 65_535, 65_536, 1 << 20] {
            let tiles = Tiles {
                tiles_per_row,
                tiles_per_row_reciprocal: (1u128 << 64) / tiles_per_row as u128 + 1,
                padded_rows: 0,
                padded_cols: tiles_per_row * TILE,
                costs: Vec::new(),
            };
            let cells = u64::from(u32::MAX);
            for t in
                (0..2000)
                    .map(|_| rng.below(cells) as usize)
                    .chain([0, 255, 256, u32::MAX as usize])
            {
                let tile = t >> 8;
                let (r, c) = tiles.row_col(t);
                assert_eq!(r, (tile / tiles_per_row) * TILE + (t >> 4 & 15), "{t}");
                assert_eq!(c, (tile % tiles_per_row) * TILE + (t & 15), "{t}");
                assert_eq!(tiles.index(r, c), t);
            }
        }
    }

    #[test]
    fn moves_match_the_row_major_neighbourhood() {
        let mut rng = Rng::new(6);
        for trial in 0..40 {
            let (w, h) = (1 + rng.below(50) as usize, 1 + rng.below(50) as usize);
            let grid = random_grid(&mut rng, w, h, 0.3, trial % 2 == 0);
            let tiles = Tiles::new(&grid);
            let hood = Neighbourhood::new(&grid);
            for r in 0..h {
                for c in 0..w {
                    let t = tiles.index(r, c);
                    let (neighbours, moves) = tiles.moves(t, r, c);
                    let moves = if grid.is_traversable((r, c)) {
                        moves
                    } else {
                        0
                    };
                    assert_eq!(
                        moves,
                        hood.moves(grid.costs(), r * w + c, r, c),
                        "({r}, {c})"
                    );
                    for (d, &n) in neighbours.iter().enumerate() {
                        if moves & (1 << d) != 0 {
                            let (nr, nc) = tiles.step(r, c, d);
                            assert_eq!(n, tiles.index(nr, nc));
                        }
                    }
                }
            }
        }
    }
}
