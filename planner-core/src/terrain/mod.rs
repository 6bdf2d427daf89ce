//! Digital elevation models (SPEC §4.1): reading GeoTIFF, ESRI ASCII grids
//! and SRTM `.hgt` into one [`Dem`] type, sampling heights, grey-scale
//! dilation and hillshade; writing georeferenced Float32 and Byte rasters
//! (costmaps) as GeoTIFF ([`geotiff`]).
//!
//! A DEM keeps its own CRS; points are transformed into it to be sampled
//! ([`TerrainSampler`]). Nodata is never a height: nodata cells hold `NaN`
//! in [`Dem::values`] and every sample that touches one is `None`.

mod asc;
mod cell_cache;
mod cell_size;
mod common;
mod crs;
mod dilate;
mod follow;
pub mod geotiff;
mod hgt;
mod hillshade;
mod info;
mod read;
mod sample;
mod windows;

pub use cell_cache::CellCache;
pub(crate) use cell_size::cell_size_m;
pub use crs::Crs;
pub use dilate::dilate;
pub use follow::{HeightRule, Point3, TerrainModel, length_3d};
pub use geotiff::{GeoTiffWindows, ReadAt, TiffPage};
pub use hillshade::hillshade_png;
pub use info::raster_bounds;
pub use read::{geotiff_pages, read_dem, read_geotiff_band, read_geotiff_page_band};
pub use sample::TerrainSampler;
pub use windows::{DemWindows, RasterGrid, RasterWindows, check_window};

use serde::{Deserialize, Serialize};

/// Limits checked from a raster's header before any pixel is allocated.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DemLimits {
    /// Most pixels (width × height) accepted.
    pub max_pixels: u64,
    /// Largest width or height accepted.
    pub max_side: u32,
}

impl Default for DemLimits {
    fn default() -> Self {
        DemLimits {
            max_pixels: 64_000_000,
            max_side: 65_535,
        }
    }
}

/// File formats terraplan reads.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DemFormat {
    GeoTiff,
    /// ESRI ASCII grid.
    Asc,
    /// SRTM `.hgt`.
    Hgt,
}

/// Affine georeferencing, GDAL's geotransform convention: the corner of
/// pixel (col, row) — not its centre — is at
/// `x = origin_x + col·pixel_width + row·row_rotation`,
/// `y = origin_y + col·col_rotation + row·pixel_height`.
/// For a north-up raster the rotations are 0 and `pixel_height` < 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeoTransform {
    pub origin_x: f64,
    pub pixel_width: f64,
    pub row_rotation: f64,
    pub origin_y: f64,
    pub col_rotation: f64,
    pub pixel_height: f64,
}

impl GeoTransform {
    /// CRS coordinates of fractional pixel position (col, row); (0.5, 0.5)
    /// is the centre of the first pixel.
    pub fn apply(&self, col: f64, row: f64) -> (f64, f64) {
        (
            self.origin_x + col * self.pixel_width + row * self.row_rotation,
            self.origin_y + col * self.col_rotation + row * self.pixel_height,
        )
    }

    /// The six coefficients in GDAL's order.
    pub fn coefficients(&self) -> [f64; 6] {
        [
            self.origin_x,
            self.pixel_width,
            self.row_rotation,
            self.origin_y,
            self.col_rotation,
            self.pixel_height,
        ]
    }

    /// Every coefficient finite and the transform invertible: a usable
    /// georeferencing.
    pub fn is_regular(&self) -> bool {
        self.coefficients().iter().all(|v| v.is_finite())
            && self.invert(self.origin_x, self.origin_y).is_some()
    }

    /// Fractional pixel position of CRS coordinates (the inverse of
    /// [`GeoTransform::apply`]); `None` when the transform is singular.
    pub fn invert(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let det = self.pixel_width * self.pixel_height - self.row_rotation * self.col_rotation;
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let dx = x - self.origin_x;
        let dy = y - self.origin_y;
        let col = (dx * self.pixel_height - dy * self.row_rotation) / det;
        let row = (dy * self.pixel_width - dx * self.col_rotation) / det;
        Some((col, row))
    }
}

/// An elevation raster in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Dem {
    pub width: usize,
    pub height: usize,
    /// Row-major, row 0 first (the top row of a north-up raster). Nodata
    /// cells are `NaN`, and so are infinite samples (no ground is
    /// infinitely high); every other value is the file's value converted
    /// exactly to f64 (all supported sample types fit).
    pub values: Vec<f64>,
    /// The file's nodata value, if it declares one (reported, not used:
    /// those cells are already `NaN`).
    pub nodata: Option<f64>,
    pub transform: GeoTransform,
    pub crs: Crs,
    pub format: DemFormat,
}

/// What `dem-info` prints and `POST /api/v1/dems` answers.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DemInfo {
    pub format: DemFormat,
    pub width: usize,
    pub height: usize,
    pub crs: Crs,
    /// Cell size in metres [x, y] (converted with the local metres per
    /// degree for a geographic DEM).
    pub resolution_m: [f64; 2],
    /// Cell size in CRS units [x, y] (degrees for a geographic DEM).
    pub resolution: [f64; 2],
    /// [min_x, min_y, max_x, max_y] in the DEM's CRS (outer pixel edges).
    pub bounds: [f64; 4],
    /// [west, south, east, north], degrees.
    pub bounds_wgs84: [f64; 4],
    /// Lowest and highest valid height; `None` when every cell is nodata.
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub nodata_value: Option<f64>,
    /// Fraction of cells without a height, [0, 1].
    pub nodata_fraction: f64,
}

/// Why a raster could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TerrainError {
    /// The bytes are not a raster of a supported format, or are corrupt.
    #[error("{0}")]
    Invalid(String),
    /// A valid raster using a feature terraplan does not read (e.g. JPEG
    /// compression, 3 bands).
    #[error("{0}")]
    Unsupported(String),
    /// The header declares more pixels than the limits allow.
    #[error("the raster is {width}×{height} pixels, over the limit of {limit}")]
    TooLarge {
        width: u64,
        height: u64,
        limit: String,
    },
    /// The CRS cannot be determined and none was given.
    #[error(
        "the raster's coordinate reference system cannot be determined ({0}); give one, e.g. crs=EPSG:32633"
    )]
    UnknownCrs(String),
    /// A CRS was given or found that PROJ does not know, or a
    /// transformation failed.
    #[error("{0}")]
    Crs(String),
    /// Stopped by its cancellation token (see [`crate::cancel`]).
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
}

impl Dem {
    /// Height of pixel (col, row); `None` on nodata or outside.
    pub fn value(&self, col: usize, row: usize) -> Option<f64> {
        if col >= self.width || row >= self.height {
            return None;
        }
        let v = self.values[row * self.width + col];
        (!v.is_nan()).then_some(v)
    }

    /// Bilinear height at CRS coordinates (x, y), between cell centres
    /// (GDAL's convention: a cell's value sits at its centre). `None` if
    /// any of the (up to four) cells it touches is nodata, or outside the
    /// raster. Within half a cell of the outer edge the nearest row or
    /// column is used (no extrapolation).
    pub fn sample(&self, x: f64, y: f64) -> Option<f64> {
        sample::bilinear(self, x, y)
    }

    /// Metadata (bounds, resolution, statistics).
    pub fn info(&self) -> Result<DemInfo, TerrainError> {
        info::dem_info(self)
    }

    /// Cell size in metres [x, y], from the CRS units (local metres per
    /// degree at the raster's centre for a geographic DEM).
    pub fn resolution_m(&self) -> [f64; 2] {
        info::resolution_m(self)
    }

    /// The sub-raster of `width`×`height` pixels whose top-left pixel is
    /// (`col0`, `row0`), clipped to the raster; same CRS, shifted transform.
    pub fn window(&self, col0: usize, row0: usize, width: usize, height: usize) -> Dem {
        let col0 = col0.min(self.width);
        let row0 = row0.min(self.height);
        let width = width.min(self.width - col0);
        let height = height.min(self.height - row0);
        let mut values = Vec::with_capacity(width * height);
        for r in row0..row0 + height {
            let start = r * self.width + col0;
            values.extend_from_slice(&self.values[start..start + width]);
        }
        let (origin_x, origin_y) = self.transform.apply(col0 as f64, row0 as f64);
        Dem {
            width,
            height,
            values,
            nodata: self.nodata,
            transform: GeoTransform {
                origin_x,
                origin_y,
                ..self.transform
            },
            crs: self.crs.clone(),
            format: self.format,
        }
    }
}

/// Small rasters for the stages' unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::{Crs, Dem, DemFormat, GeoTransform};

    /// A `w`×`h` DEM (row-major `values`) in EPSG:4326 or EPSG:32633.
    pub fn dem(w: usize, h: usize, values: Vec<f64>, t: GeoTransform, geographic: bool) -> Dem {
        assert_eq!(values.len(), w * h);
        Dem {
            width: w,
            height: h,
            values,
            nodata: None,
            transform: t,
            crs: Crs {
                epsg: if geographic { 4326 } else { 32633 },
                name: String::new(),
                geographic,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    /// A north-up transform with its top-left corner at (x0, y0) and
    /// cells `sx` wide and `sy` tall.
    pub fn north_up(x0: f64, y0: f64, sx: f64, sy: f64) -> GeoTransform {
        GeoTransform {
            origin_x: x0,
            pixel_width: sx,
            row_rotation: 0.0,
            origin_y: y0,
            col_rotation: 0.0,
            pixel_height: -sy,
        }
    }
}
