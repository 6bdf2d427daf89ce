//! Rasters read a window at a time ([`RasterWindows`]), so a DEM larger
//! than memory can be worked through tile by tile: a GeoTIFF on disk, the
//! tiles a server stored, or a [`Dem`] already in memory all answer the
//! same request "fill these cells".

use super::{Crs, Dem, GeoTransform, TerrainError};

/// The georeferencing and size of a raster, without its cells.
#[derive(Clone, Debug, PartialEq)]
pub struct RasterGrid {
    pub width: usize,
    pub height: usize,
    pub transform: GeoTransform,
    pub crs: Crs,
    /// The nodata value the source declares, if any (reported only: nodata
    /// cells read as `NaN`).
    pub nodata: Option<f64>,
}

/// A raster whose cells are read a window at a time. Implementations are
/// `Sync` so tiles can be read from several threads at once.
pub trait RasterWindows: Sync {
    /// Size and georeferencing.
    fn grid(&self) -> &RasterGrid;

    /// Fills `out` (row-major, `width × height`, row `row0` first) with
    /// the cells of the window whose top-left cell is (`col0`, `row0`).
    /// Nodata and infinite cells read as `NaN`, every other cell as its
    /// value converted exactly to f64 (as [`Dem::values`]). The window
    /// must lie inside the raster and `out` must have its size: anything
    /// else is [`TerrainError::Invalid`], never a panic.
    fn read_window(
        &self,
        col0: usize,
        row0: usize,
        width: usize,
        height: usize,
        out: &mut [f64],
    ) -> Result<(), TerrainError>;
}

/// Checks a window request against the raster's size and the buffer's
/// length: the one check every implementation makes first.
pub fn check_window(
    grid: &RasterGrid,
    col0: usize,
    row0: usize,
    width: usize,
    height: usize,
    out_len: usize,
) -> Result<(), TerrainError> {
    let inside = col0.checked_add(width).is_some_and(|end| end <= grid.width)
        && row0
            .checked_add(height)
            .is_some_and(|end| end <= grid.height);
    if !inside {
        return Err(TerrainError::Invalid(format!(
            "the window of {width}×{height} cells at column {col0}, row {row0} is not inside \
             the {}×{} raster",
            grid.width, grid.height
        )));
    }
    if width.checked_mul(height) != Some(out_len) {
        return Err(TerrainError::Invalid(format!(
            "a window of {width}×{height} cells needs a buffer of {} values, not {out_len}",
            width.saturating_mul(height)
        )));
    }
    Ok(())
}

/// A DEM in memory, read through [`RasterWindows`] (the reference every
/// tiled computation is tested against).
pub struct DemWindows<'a> {
    dem: &'a Dem,
    grid: RasterGrid,
}

impl<'a> DemWindows<'a> {
    pub fn new(dem: &'a Dem) -> DemWindows<'a> {
        DemWindows {
            dem,
            grid: RasterGrid {
                width: dem.width,
                height: dem.height,
                transform: dem.transform,
                crs: dem.crs.clone(),
                nodata: dem.nodata,
            },
        }
    }
}

impl RasterWindows for DemWindows<'_> {
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
        if width == 0 {
            return Ok(());
        }
        for (r, dst) in out.chunks_exact_mut(width).enumerate() {
            let start = (row0 + r) * self.dem.width + col0;
            dst.copy_from_slice(&self.dem.values[start..start + width]);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::test_support::{dem, north_up};

    fn ramp(w: usize, h: usize) -> Dem {
        let values = (0..w * h).map(|i| i as f64).collect();
        dem(
            w,
            h,
            values,
            north_up(500_000.0, 4_000_000.0, 1.0, 1.0),
            false,
        )
    }

    #[test]
    fn a_window_holds_the_cells_of_the_dem() {
        let d = ramp(7, 5);
        let src = DemWindows::new(&d);
        let mut out = vec![0.0; 3 * 2];
        src.read_window(2, 1, 3, 2, &mut out).unwrap();
        assert_eq!(out, vec![9.0, 10.0, 11.0, 16.0, 17.0, 18.0]);
        assert_eq!(src.grid().width, 7);
        assert_eq!(src.grid().height, 5);
    }

    #[test]
    fn a_window_outside_or_a_wrong_buffer_is_an_error_not_a_panic() {
        let d = ramp(4, 4);
        let src = DemWindows::new(&d);
        let mut out = vec![0.0; 4];
        assert!(src.read_window(3, 0, 2, 2, &mut out).is_err());
        assert!(src.read_window(usize::MAX, 0, 2, 2, &mut out).is_err());
        let mut short = vec![0.0; 3];
        let err = src.read_window(0, 0, 2, 2, &mut short).unwrap_err();
        assert!(err.to_string().contains("needs a buffer of 4"), "{err}");
        let mut empty: Vec<f64> = Vec::new();
        src.read_window(4, 4, 0, 0, &mut empty).unwrap();
    }
}
