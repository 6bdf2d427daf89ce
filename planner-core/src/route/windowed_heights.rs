//! Heights for a route on a costmap read by windows: the DEM it was built
//! from, itself read a window at a time, brought onto the costmap's grid
//! by the costmap's own block averaging — what
//! [`RouteMap::from_costmap_geotiff`](super::RouteMap::from_costmap_geotiff)
//! does to the whole DEM, done only to the windows a route's profile reads
//! (block averaging is local, so the heights are the same to the bit).

use super::on_map::{MapRouteError, averaging_factor};
use crate::costmap::grid::{average_blocks, work_geometry};
use crate::terrain::{Dem, DemFormat, RasterGrid, RasterWindows, TerrainError, check_window};

/// A DEM's heights on a costmap's grid, read a window at a time.
pub struct AveragedHeights<'a> {
    dem: &'a dyn RasterWindows,
    factor: [usize; 2],
    grid: RasterGrid,
}

/// A raster's size and georeferencing as a [`Dem`] without values.
fn shape(grid: &RasterGrid) -> Dem {
    Dem {
        width: grid.width,
        height: grid.height,
        values: Vec::new(),
        nodata: grid.nodata,
        transform: grid.transform,
        crs: grid.crs.clone(),
        format: DemFormat::GeoTiff,
    }
}

impl<'a> AveragedHeights<'a> {
    /// The heights of `dem` on `costmap`'s grid.
    ///
    /// # Errors
    ///
    /// [`MapRouteError::DemMismatch`] when the DEM is in another CRS or
    /// does not average onto exactly the costmap's cells.
    pub fn new(
        dem: &'a dyn RasterWindows,
        costmap: &RasterGrid,
    ) -> Result<AveragedHeights<'a>, MapRouteError> {
        let source = shape(dem.grid());
        let factor = averaging_factor(&source, &shape(costmap))?;
        let geometry = work_geometry(&source, factor);
        Ok(AveragedHeights {
            dem,
            factor,
            grid: RasterGrid {
                width: geometry.width,
                height: geometry.height,
                transform: geometry.transform,
                crs: source.crs,
                nodata: source.nodata,
            },
        })
    }
}

impl RasterWindows for AveragedHeights<'_> {
    fn grid(&self) -> &RasterGrid {
        &self.grid
    }

    fn read_window(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut [f64],
    ) -> Result<(), TerrainError> {
        check_window(&self.grid, col0, row0, width, height, out.len())?;
        let [fx, fy] = self.factor;
        if self.factor == [1, 1] {
            return self.dem.read_window(col0, row0, width, height, out);
        }
        let mut cells = vec![0.0; width * fx * height * fy];
        self.dem
            .read_window(col0 * fx, row0 * fy, width * fx, height * fy, &mut cells)?;
        out.copy_from_slice(&average_blocks(
            &cells,
            width * fx,
            width,
            height,
            self.factor,
        ));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::grid::work_grid;
    use crate::terrain::test_support::{dem, north_up};
    use crate::terrain::{Crs, DemWindows};
    use std::borrow::Cow;

    /// Windows of the averaged heights are the whole DEM's averaging, to
    /// the bit, for factors 1, 2 × 3 and 4 (with nodata and a cut-off
    /// remainder); a DEM in another CRS or grid is refused.
    #[test]
    fn windows_equal_the_whole_averaging() {
        let (w, h) = (47, 38);
        let values: Vec<f64> = (0..w * h)
            .map(|i| {
                if i % 17 == 3 {
                    f64::NAN
                } else {
                    100.0 + ((i * 37) % 101) as f64 * 0.37
                }
            })
            .collect();
        let mut d = dem(
            w,
            h,
            values,
            north_up(472_000.0, 4_295_000.0, 1.0, 1.0),
            false,
        );
        d.crs = Crs::from_epsg(32618).unwrap();
        let windows = DemWindows::new(&d);
        for factor in [[1, 1], [2, 3], [4, 4]] {
            let whole = work_grid(Cow::Borrowed(&d), factor);
            let costmap = RasterGrid {
                width: whole.width,
                height: whole.height,
                transform: whole.transform,
                crs: d.crs.clone(),
                nodata: None,
            };
            let heights = AveragedHeights::new(&windows, &costmap).unwrap();
            assert_eq!(
                (heights.grid().width, heights.grid().height),
                (whole.width, whole.height)
            );
            for (c0, r0, ww, hh) in [
                (0, 0, whole.width, whole.height),
                (1, 2, 3, 4),
                (whole.width - 1, whole.height - 1, 1, 1),
            ] {
                let mut out = vec![0.0; ww * hh];
                heights.read_window(c0, r0, ww, hh, &mut out).unwrap();
                for r in 0..hh {
                    for c in 0..ww {
                        let want = whole.z[(r0 + r) * whole.width + c0 + c];
                        let got = out[r * ww + c];
                        assert!(
                            got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                            "{factor:?} ({}, {}): {got} vs {want}",
                            r0 + r,
                            c0 + c
                        );
                    }
                }
            }
        }
        let other = RasterGrid {
            width: w,
            height: h,
            transform: d.transform,
            crs: Crs::from_epsg(32617).unwrap(),
            nodata: None,
        };
        assert!(matches!(
            AveragedHeights::new(&windows, &other),
            Err(MapRouteError::DemMismatch(_))
        ));
        let shifted = RasterGrid {
            transform: north_up(472_010.0, 4_295_000.0, 1.0, 1.0),
            crs: d.crs.clone(),
            ..other
        };
        assert!(matches!(
            AveragedHeights::new(&windows, &shifted),
            Err(MapRouteError::DemMismatch(_))
        ));
    }
}
