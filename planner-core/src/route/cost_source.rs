//! Where a big-map search reads its costs from ([`CostSource`]): a
//! [`CostGrid`] in memory, or any [`RasterWindows`] (a costmap GeoTIFF on
//! disk, stored tiles) read a window at a time ([`WindowCosts`]), so that
//! no search needs every cell in memory at once.

use super::CostGrid;
use crate::terrain::{RasterWindows, cell_size_m};

/// Why costs could not be read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CostSourceError {
    #[error("the costmap cannot be read: {0}")]
    Read(String),
    #[error(
        "the cost at row {row}, column {col} is {value}; a traversable cell needs a cost > 0 \
         (mark obstacles and unknown cells with a non-finite value)"
    )]
    NonPositiveCost { row: usize, col: usize, value: f64 },
    #[error("the costmap's grid is rotated or sheared; only north-up grids can be planned on")]
    RotatedGrid,
    #[error("the costmap is empty ({width} columns × {height} rows)")]
    Empty { width: usize, height: usize },
    #[error("the costmap has {cells} cells; at most {max} are supported")]
    TooLarge { cells: u64, max: u64 },
}

/// A cost raster read a window at a time: finite costs (> 0) are
/// traversable, non-finite ones obstacles, as in [`CostGrid`].
pub trait CostSource: Sync {
    fn width(&self) -> usize;
    fn height(&self) -> usize;
    /// Cell width in metres of each row.
    fn dx_per_row(&self) -> &[f64];
    /// Cell height in metres.
    fn dy(&self) -> f64;
    /// Fills `out` (row-major, `width × height`) with the costs of the
    /// window whose top-left cell is (`row0`, `col0`); the window lies
    /// inside the raster. Non-finite costs read as NaN; a finite cost ≤ 0
    /// is an error naming its cell.
    fn read_costs(
        &self,
        row0: usize,
        col0: usize,
        width: usize,
        height: usize,
        out: &mut [f32],
    ) -> Result<(), CostSourceError>;
}

impl CostSource for CostGrid {
    fn width(&self) -> usize {
        CostGrid::width(self)
    }

    fn height(&self) -> usize {
        CostGrid::height(self)
    }

    fn dx_per_row(&self) -> &[f64] {
        CostGrid::dx_per_row(self)
    }

    fn dy(&self) -> f64 {
        CostGrid::dy(self)
    }

    fn read_costs(
        &self,
        row0: usize,
        col0: usize,
        width: usize,
        height: usize,
        out: &mut [f32],
    ) -> Result<(), CostSourceError> {
        let w = CostGrid::width(self);
        for (r, dst) in out.chunks_exact_mut(width.max(1)).take(height).enumerate() {
            let start = (row0 + r) * w + col0;
            dst.copy_from_slice(&self.costs()[start..start + width]);
        }
        // CostGrid::new already refused non-positive finite costs.
        Ok(())
    }
}

/// Band 1 of a costmap raster read through [`RasterWindows`], as costs.
pub struct WindowCosts<'a> {
    windows: &'a dyn RasterWindows,
    dx: Vec<f64>,
    dy: f64,
}

impl<'a> WindowCosts<'a> {
    /// The costs of `windows`, with cell sizes in metres from its
    /// geotransform (local metres for a geographic CRS, as [`RouteMap`]
    /// computes them).
    ///
    /// [`RouteMap`]: super::RouteMap
    pub fn new(windows: &'a dyn RasterWindows) -> Result<WindowCosts<'a>, CostSourceError> {
        let grid = windows.grid();
        let t = &grid.transform;
        if t.col_rotation != 0.0 || t.row_rotation != 0.0 {
            return Err(CostSourceError::RotatedGrid);
        }
        if grid.width == 0 || grid.height == 0 {
            return Err(CostSourceError::Empty {
                width: grid.width,
                height: grid.height,
            });
        }
        let sizes: Vec<[f64; 2]> = (0..grid.height)
            .map(|r| {
                cell_size_m(
                    t,
                    grid.crs.geographic,
                    grid.width as f64 / 2.0,
                    r as f64 + 0.5,
                )
            })
            .collect();
        let dy = sizes[grid.height / 2][1];
        Ok(WindowCosts {
            windows,
            dx: sizes.iter().map(|s| s[0]).collect(),
            dy,
        })
    }
}

impl CostSource for WindowCosts<'_> {
    fn width(&self) -> usize {
        self.windows.grid().width
    }

    fn height(&self) -> usize {
        self.windows.grid().height
    }

    fn dx_per_row(&self) -> &[f64] {
        &self.dx
    }

    fn dy(&self) -> f64 {
        self.dy
    }

    fn read_costs(
        &self,
        row0: usize,
        col0: usize,
        width: usize,
        height: usize,
        out: &mut [f32],
    ) -> Result<(), CostSourceError> {
        let mut values = vec![0.0f64; width * height];
        self.windows
            .read_window(col0, row0, width, height, &mut values)
            .map_err(|e| CostSourceError::Read(e.to_string()))?;
        for (i, (&v, o)) in values.iter().zip(out.iter_mut()).enumerate() {
            if v.is_finite() && v <= 0.0 {
                return Err(CostSourceError::NonPositiveCost {
                    row: row0 + i / width,
                    col: col0 + i % width,
                    value: v,
                });
            }
            // f32 as the costmap stores it (and as RouteMap narrows it).
            *o = if v.is_finite() { v as f32 } else { f32::NAN };
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::test_support::{dem, north_up};
    use crate::terrain::{Crs, Dem, DemWindows};

    /// A north-up raster in UTM 18N with cells `dx` × `dy` metres.
    fn utm_dem(w: usize, h: usize, values: Vec<f64>, [dx, dy]: [f64; 2]) -> Dem {
        let mut d = dem(
            w,
            h,
            values,
            north_up(500_000.0, 4_000_000.0, dx, dy),
            false,
        );
        d.crs = Crs::from_epsg(32618).unwrap();
        d
    }

    #[test]
    fn window_costs_read_the_band_as_f32_with_metre_cells() {
        let (w, h) = (6, 4);
        let values = (0..w * h)
            .map(|i| if i == 7 { f64::NAN } else { 1.0 + i as f64 })
            .collect();
        let d = utm_dem(w, h, values, [2.0, 3.0]);
        let windows = DemWindows::new(&d);
        let src = WindowCosts::new(&windows).unwrap();
        assert_eq!((src.width(), src.height(), src.dy()), (6, 4, 3.0));
        assert_eq!(src.dx_per_row(), &[2.0; 4]);
        let mut out = vec![0.0f32; 4];
        src.read_costs(1, 0, 2, 2, &mut out).unwrap();
        assert_eq!(out[0], 7.0);
        assert!(out[1].is_nan());
        assert_eq!(out[2..], [13.0, 14.0]);
    }

    #[test]
    fn a_non_positive_cost_is_named_and_a_bad_window_is_an_error() {
        let values = vec![1.0, 2.0, 0.0, 4.0];
        let d = utm_dem(2, 2, values, [1.0, 1.0]);
        let windows = DemWindows::new(&d);
        let src = WindowCosts::new(&windows).unwrap();
        let mut out = vec![0.0f32; 4];
        assert_eq!(
            src.read_costs(0, 0, 2, 2, &mut out),
            Err(CostSourceError::NonPositiveCost {
                row: 1,
                col: 0,
                value: 0.0
            })
        );
        assert!(matches!(
            src.read_costs(1, 1, 2, 2, &mut out),
            Err(CostSourceError::Read(_))
        ));
    }
}
