//! The coarse level of a big-map search: the least and largest finite
//! cost of every B × B block of cells, in one pass over the map read in
//! bands of whole rows (a strip-organised GeoTIFF decodes each strip
//! once). A block with no traversable cell is lethal.
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

/// Cells read per band at most (a band is whole rows: its f32 costs and,
/// for a raster source, the f64 window it converts from).
const BAND_CELLS: usize = 1 << 20;

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
    /// One pass over `source` in bands of whole block rows, two bands at
    /// a time on the rayon pool.
    pub(crate) fn build(
        source: &dyn CostSource,
        block: usize,
    ) -> Result<BlockMinima, CostSourceError> {
        let (width, height) = (source.width(), source.height());
        let across = width.div_ceil(block);
        let down = height.div_ceil(block);
        let block_rows_per_band = (BAND_CELLS / (width * block)).max(1);
        let bands: Vec<usize> = (0..down).step_by(block_rows_per_band).collect();
        let rows: Vec<(Vec<f32>, Vec<f32>)> = bands
            .par_iter()
            .map(|&first| {
                let block_rows = block_rows_per_band.min(down - first);
                let r0 = first * block;
                let h = (block_rows * block).min(height - r0);
                let mut costs = vec![0.0f32; width * h];
                source.read_costs(r0, 0, width, h, &mut costs)?;
                let mut min = vec![f32::INFINITY; block_rows * across];
                let mut max = vec![f32::NEG_INFINITY; block_rows * across];
                for (r, row) in costs.chunks_exact(width).enumerate() {
                    let base = (r / block) * across;
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
            min: Vec::with_capacity(across * down),
            max: Vec::with_capacity(across * down),
        };
        for (min, max) in rows {
            minima.min.extend(min);
            minima.max.extend(max);
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
    fn bands_split_tall_maps_without_changing_the_result() {
        // 2^20 cells per band: a 3000-wide map of 16-blocks reads 21 block
        // rows per band, so 2000 rows take several bands.
        let (w, h) = (3000, 2000);
        let costs = (0..w * h)
            .map(|i| {
                if i % 7919 == 0 {
                    f32::NAN
                } else {
                    1.0 + (i % 101) as f32
                }
            })
            .collect();
        let grid = CostGrid::with_cell_size(w, h, costs, 1.0, 1.0).unwrap();
        let m = BlockMinima::build(&grid, 16).unwrap();
        assert!((BAND_CELLS / (w * 16)) * 16 < h);
        let b = m.block_of(1999, 2999);
        assert_eq!(b, m.min.len() - 1);
        assert_eq!(m.min[m.block_of(1500, 40)], 1.0);
        assert_eq!(m.max[m.block_of(1500, 40)], 101.0);
        assert_eq!(m.cost_range(), Some((1.0, 101.0)));
    }
}
