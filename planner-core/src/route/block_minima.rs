//! The coarse level of a big-map search: the least and largest finite
//! cost of every B × B block of cells, in one pass over the map read in
//! square windows of about 1024² cells, two at a time on the rayon pool. A
//! block with no traversable cell is lethal.
//!
//! Why the minima bound every fine path from below: both arc rules cost a
//! step by its length times a factor that depends only on the costs of its
//! two cells, and the factor of any step between cells of a set of blocks
//! is at least the factor computed from the least cost of those blocks
//! (`integrated`, the mean of two costs) or from their least minus their
//! largest cost (`thesis`, increasing in the cost difference). The coarse
//! bound (`coarse_bound`) combines this with the least length of any
//! step sequence between blocks.

use rayon::prelude::*;

use super::cost_source::{CostSource, CostSourceError};

/// Side in cells of the square windows the pass reads (rounded down to
/// whole blocks): 1 M cells, 12 MB with the f64 window a raster source
/// converts from; a tiled GeoTIFF decodes each of its tiles about once.
const WINDOW: usize = 1024;

/// Block minima and maxima of a cost raster.
#[derive(Clone, Debug)]
pub(crate) struct BlockMinima {
    /// Block side in cells.
    pub(crate) block: usize,
    /// Blocks across and down.
    pub(crate) across: usize,
    pub(crate) down: usize,
    /// Least finite cost per block, row-major; NaN for a lethal block.
    pub(crate) min: Vec<f32>,
    /// Largest finite cost per block; NaN for a lethal block.
    pub(crate) max: Vec<f32>,
}

impl BlockMinima {
    /// One pass over `source` in square windows of whole blocks.
    pub(crate) fn build(
        source: &dyn CostSource,
        block: usize,
    ) -> Result<BlockMinima, CostSourceError> {
        let (width, height) = (source.width(), source.height());
        let across = width.div_ceil(block);
        let down = height.div_ceil(block);
        // Square windows of whole blocks, about WINDOW cells a side.
        let side = (WINDOW / block).max(1) * block;
        let (windows_across, windows_down) = (width.div_ceil(side), height.div_ceil(side));
        let per_window: Vec<(Vec<f32>, Vec<f32>)> = (0..windows_across * windows_down)
            .into_par_iter()
            .map(|k| {
                let (r0, c0) = ((k / windows_across) * side, (k % windows_across) * side);
                let (h, w) = (side.min(height - r0), side.min(width - c0));
                let mut costs = vec![0.0f32; w * h];
                source.read_costs(r0, c0, w, h, &mut costs)?;
                let cols = w.div_ceil(block);
                let mut min = vec![f32::INFINITY; h.div_ceil(block) * cols];
                let mut max = vec![f32::NEG_INFINITY; min.len()];
                for (r, row) in costs.chunks_exact(w).enumerate() {
                    let base = (r / block) * cols;
                    for (j, chunk) in row.chunks(block).enumerate() {
                        let (lo, hi) =
                            chunk
                                .iter()
                                .fold((min[base + j], max[base + j]), |(lo, hi), &c| {
                                    if c.is_finite() {
                                        (lo.min(c), hi.max(c))
                                    } else {
                                        (lo, hi)
                                    }
                                });
                        min[base + j] = lo;
                        max[base + j] = hi;
                    }
                }
                Ok((min, max))
            })
            .collect::<Result<_, CostSourceError>>()?;
        let mut minima = BlockMinima {
            block,
            across,
            down,
            min: vec![f32::INFINITY; across * down],
            max: vec![f32::NEG_INFINITY; across * down],
        };
        let blocks_per_side = side / block;
        for (k, (min, max)) in per_window.into_iter().enumerate() {
            let br0 = (k / windows_across) * blocks_per_side;
            let bc0 = (k % windows_across) * blocks_per_side;
            let cols = blocks_per_side.min(across - bc0);
            for (i, (lo, hi)) in min
                .chunks_exact(cols)
                .zip(max.chunks_exact(cols))
                .enumerate()
            {
                let at = (br0 + i) * across + bc0;
                minima.min[at..at + cols].copy_from_slice(lo);
                minima.max[at..at + cols].copy_from_slice(hi);
            }
        }
        for (lo, hi) in minima.min.iter_mut().zip(minima.max.iter_mut()) {
            if *lo > *hi {
                (*lo, *hi) = (f32::NAN, f32::NAN);
            }
        }
        Ok(minima)
    }

    /// Index of block (row, col).
    #[inline]
    pub(crate) fn index(&self, row: usize, col: usize) -> usize {
        row * self.across + col
    }

    /// The block holding cell (r, c).
    #[inline]
    pub(crate) fn block_of(&self, r: usize, c: usize) -> usize {
        self.index(r / self.block, c / self.block)
    }

    pub(crate) fn is_lethal(&self, b: usize) -> bool {
        self.min[b].is_nan()
    }

    /// Least and largest finite cost of the whole raster, `None` when
    /// nothing is traversable (the range every arc model normalises with).
    pub(crate) fn cost_range(&self) -> Option<(f32, f32)> {
        let lo = self
            .min
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f32::INFINITY, f32::min);
        let hi = self
            .max
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(f32::NEG_INFINITY, f32::max);
        (lo <= hi).then_some((lo, hi))
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> usize {
        8 * self.min.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::CostGrid;
    use crate::route::testing::{Rng, random_grid};

    #[test]
    fn minima_and_maxima_of_every_block_lethal_when_blocked() {
        let mut rng = Rng::new(4);
        for trial in 0..40 {
            let (w, h) = (1 + rng.below(70) as usize, 1 + rng.below(70) as usize);
            let grid = random_grid(&mut rng, w, h, [0.0, 0.3, 0.8][trial % 3], false);
            let block = [1, 3, 4, 16][trial % 4];
            let m = BlockMinima::build(&grid, block).unwrap();
            assert_eq!((m.across, m.down), (w.div_ceil(block), h.div_ceil(block)));
            for br in 0..m.down {
                for bc in 0..m.across {
                    let cells: Vec<f32> = (br * block..((br + 1) * block).min(h))
                        .flat_map(|r| (bc * block..((bc + 1) * block).min(w)).map(move |c| (r, c)))
                        .map(|cell| grid.cost(cell).unwrap())
                        .filter(|c| c.is_finite())
                        .collect();
                    let b = m.index(br, bc);
                    if cells.is_empty() {
                        assert!(m.is_lethal(b) && m.max[b].is_nan());
                    } else {
                        let lo = cells.iter().copied().fold(f32::INFINITY, f32::min);
                        let hi = cells.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                        assert_eq!((m.min[b], m.max[b]), (lo, hi), "trial {trial}");
                    }
                }
            }
            assert_eq!(m.cost_range(), grid.finite_cost_range());
        }
    }

    #[test]
    fn windows_tile_big_maps_without_changing_the_result() {
        // 3000 × 2000 cells in windows of 1024²: partial windows and a
        // partial block (3000 = 187.5 blocks) on the right and bottom.
        let (w, h) = (3000, 2000);
        let costs: Vec<f32> = (0..w * h)
            .map(|i| {
                if i % 7919 == 0 {
                    f32::NAN
                } else {
                    1.0 + ((i * 7) % 101) as f32
                }
            })
            .collect();
        let grid = CostGrid::with_cell_size(w, h, costs.clone(), 1.0, 1.0).unwrap();
        let m = BlockMinima::build(&grid, 16).unwrap();
        assert!(w > 2 * WINDOW && h > WINDOW);
        let mut lo = vec![f32::INFINITY; m.min.len()];
        let mut hi = vec![f32::NEG_INFINITY; m.min.len()];
        for (i, &c) in costs.iter().enumerate() {
            let b = m.block_of(i / w, i % w);
            if c.is_finite() {
                lo[b] = lo[b].min(c);
                hi[b] = hi[b].max(c);
            }
        }
        assert_eq!(m.block_of(1999, 2999), 125 * 188 - 1);
        assert_eq!((m.min, m.max), (lo, hi));
    }
}
