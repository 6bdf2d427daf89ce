//! The working grid (SPEC §4.2 step 1): the DEM's heights, optionally
//! resampled to a coarser cell by averaging whole blocks of cells, with
//! the size of every row's cells in metres.
//!
//! A geographic DEM's cells are converted with the local metres per degree
//! of each row, so slopes and steps are judged in metres, never degrees.

use std::borrow::Cow;

use crate::terrain::cell_size_m;
use crate::terrain::{Dem, GeoTransform};

/// Heights on the working grid.
#[derive(Clone, Debug)]
pub struct WorkGrid {
    pub width: usize,
    pub height: usize,
    /// Row-major heights; `NaN` where unknown.
    pub z: Vec<f64>,
    pub transform: GeoTransform,
    /// Cell size [x, y] in metres of each row (all equal for a projected
    /// CRS).
    pub row_size_m: Vec<[f64; 2]>,
    /// DEM cells per working cell [x, y].
    pub factor: [usize; 2],
}

impl WorkGrid {
    /// Cell size at the grid's middle row, metres: what the stages that
    /// need one size for the whole grid (distance, areas, kernels) use.
    pub fn centre_size_m(&self) -> [f64; 2] {
        self.row_size_m[self.height / 2]
    }
}

/// Block factors [x, y] that bring the DEM's cells (`res_m`) to
/// `target_m`: the nearest whole numbers, at least 1.
pub fn resample_factor(res_m: [f64; 2], target_m: f64) -> [usize; 2] {
    let f = |r: f64| ((target_m / r).round().max(1.0)) as usize;
    [f(res_m[0]), f(res_m[1])]
}

/// The working grid of `dem`: its own cells when `factor` is [1, 1]
/// (taking the heights without a copy when the DEM is owned), else the
/// mean of each full `fx`×`fy` block's valid heights (a block with fewer
/// than half its cells valid is unknown). Rows and columns left over at
/// the right and bottom edges, less than a block, are dropped.
pub fn work_grid(dem: Cow<'_, Dem>, factor: [usize; 2]) -> WorkGrid {
    let geometry = work_geometry(&dem, factor);
    let z = if factor == [1, 1] {
        dem.into_owned().values
    } else {
        average_blocks(
            &dem.values,
            dem.width,
            geometry.width,
            geometry.height,
            factor,
        )
    };
    WorkGrid {
        width: geometry.width,
        height: geometry.height,
        z,
        transform: geometry.transform,
        row_size_m: geometry.row_size_m,
        factor,
    }
}

/// The working grid's size, georeferencing and row sizes, without its
/// heights: what a tiled run needs before reading any tile. `dem` needs
/// no values (only its size, transform and CRS are read).
pub struct WorkGeometry {
    pub width: usize,
    pub height: usize,
    pub transform: GeoTransform,
    pub row_size_m: Vec<[f64; 2]>,
}

/// The [`WorkGeometry`] of `dem` resampled by `factor`.
pub fn work_geometry(dem: &Dem, factor: [usize; 2]) -> WorkGeometry {
    let [fx, fy] = factor;
    let t = dem.transform;
    let width = dem.width / fx;
    let height = dem.height / fy;
    let transform = GeoTransform {
        pixel_width: t.pixel_width * fx as f64,
        col_rotation: t.col_rotation * fx as f64,
        row_rotation: t.row_rotation * fy as f64,
        pixel_height: t.pixel_height * fy as f64,
        ..t
    };
    let projected_m = (!dem.crs.geographic).then(|| {
        let [sx, sy] = dem.resolution_m();
        [sx * fx as f64, sy * fy as f64]
    });
    let row_size_m = (0..height)
        .map(|r| {
            projected_m.unwrap_or_else(|| {
                cell_size_m(&transform, true, width as f64 / 2.0, r as f64 + 0.5)
            })
        })
        .collect();
    WorkGeometry {
        width,
        height,
        transform,
        row_size_m,
    }
}

/// `width` × `height` working cells, each the mean of the valid heights
/// of its `fx`×`fy` block of `values` (row-major, `src_width` cells wide,
/// the first block at its top-left); a block with fewer than half its
/// cells valid is unknown. A window of a DEM whose corner is on a block
/// corner gives the same bits as the whole DEM there.
pub fn average_blocks(
    values: &[f64],
    src_width: usize,
    width: usize,
    height: usize,
    [fx, fy]: [usize; 2],
) -> Vec<f64> {
    let mut z = vec![f64::NAN; width * height];
    let need = (fx * fy).div_ceil(2);
    let mut sums = vec![(0.0f64, 0usize); width];
    for (r, out) in z.chunks_mut(width.max(1)).enumerate().take(height) {
        sums.fill((0.0, 0));
        for src_row in r * fy..(r + 1) * fy {
            let row = &values[src_row * src_width..src_row * src_width + width * fx];
            for (c, block) in row.chunks_exact(fx).enumerate() {
                for &v in block {
                    if !v.is_nan() {
                        sums[c].0 += v;
                        sums[c].1 += 1;
                    }
                }
            }
        }
        for (o, &(s, n)) in out.iter_mut().zip(&sums) {
            if n >= need {
                *o = s / n as f64;
            }
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::test_support::{dem, north_up};

    #[test]
    fn block_means_ignore_nodata_and_drop_partial_blocks() {
        // 5×4 DEM, 2 m cells, blocks of 2×2 → 2×2 grid (last column dropped).
        #[rustfmt::skip]
        let values = vec![
            1.0, 3.0, 10.0, 10.0, 99.0,
            1.0, 3.0, f64::NAN, 14.0, 99.0,
            0.0, f64::NAN, f64::NAN, f64::NAN, 99.0,
            0.0, 4.0, 5.0, f64::NAN, 99.0,
        ];
        let d = dem(5, 4, values, north_up(500.0, 1000.0, 2.0, 2.0), false);
        let g = work_grid(Cow::Owned(d), resample_factor([2.0, 2.0], 4.2));
        assert_eq!((g.width, g.height, g.factor), (2, 2, [2, 2]));
        assert_eq!(g.z[0], 2.0);
        assert!((g.z[1] - 34.0 / 3.0).abs() < 1e-12);
        assert!((g.z[2] - 4.0 / 3.0).abs() < 1e-12);
        assert!(g.z[3].is_nan(), "one valid cell of four is not enough");
        assert_eq!(g.row_size_m, vec![[4.0, 4.0]; 2]);
        assert_eq!(g.transform.apply(1.0, 1.0), (504.0, 996.0));
    }

    #[test]
    fn geographic_rows_are_in_local_metres() {
        // 3″ cells at 45° N: ≈ 65.7 m east-west, ≈ 92.6 m north-south.
        let s = 3.0 / 3600.0;
        let d = dem(
            4,
            4,
            vec![0.0; 16],
            north_up(6.0, 45.0 + 2.0 * s, s, s),
            true,
        );
        let g = work_grid(Cow::Borrowed(&d), [1, 1]);
        let [x, y] = g.row_size_m[2];
        assert!(
            (x - 65.70).abs() < 0.05 && (y - 92.61).abs() < 0.05,
            "{x} {y}"
        );
        // Rows further north are narrower.
        assert!(g.row_size_m[0][0] < g.row_size_m[3][0]);
    }
}
