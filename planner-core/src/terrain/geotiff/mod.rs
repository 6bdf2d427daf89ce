//! GeoTIFF in one place: the reader of elevation (and costmap) rasters and
//! the writer of Float32 and Byte rasters, sharing one tag table.
//!
//! Reading: a page's IFD is parsed by hand (bounds-checked, allocation
//! bounded by the file size) to check the size limits, the sample layout,
//! the georeferencing (ModelPixelScale + ModelTiepoint or
//! ModelTransformation, PixelIsArea/PixelIsPoint), the GeoKeys' CRS and
//! `GDAL_NODATA` — all before any pixel is allocated. Strips and tiles are
//! then decompressed and un-predicted by the `tiff` crate, one chunk at a
//! time, into `f64`s.
//!
//! The rules follow GDAL's GTiff driver so that values, nodata and corner
//! coordinates equal `gdalinfo`'s / `gdallocationinfo`'s:
//! - a PixelIsPoint raster's transform is shifted by half a pixel up-left
//!   (GDAL's default, `GTIFF_POINT_GEO_IGNORE=NO`);
//! - the nodata text is read like `atof`, then compared in the sample type:
//!   truncated to an integer for integer samples (and ignored when out of the
//!   type's range), rounded to f32 for Float32; NaN samples are always nodata,
//!   and so are infinite ones (GDAL reads them as heights; no ground is
//!   infinitely high, and an infinite height would poison every slope,
//!   mean and hillshade computed over it);
//! - sparse chunks (byte count 0, whatever the offset) read as nodata (0
//!   if none);
//! - a Deflate chunk must be one whole zlib stream within its byte count,
//!   with a valid checksum, inflating to the chunk's size (`deflate_check`);
//! - an IFD of more than 4096 entries is refused (libtiff's sanity check),
//!   and a `GDAL_NODATA` tag of a type other than ASCII (or bytes) ignored.
//!
//! A DEM has one band; `read_geotiff_band` reads one band of a file with
//! several through the same path: PlanarConfiguration 1 chunks hold every
//! band of their pixels (the decoder undoes the predictor across pixels,
//! SamplesPerPixel samples apart), PlanarConfiguration 2 stores band b's
//! chunks after all of band b−1's.
//!
//! A file on disk can also be read a window at a time ([`GeoTiffWindows`]):
//! its header pieces read with bounded positioned reads, then only the
//! strips or tiles a window touches decoded, through the same decoder.
//!
//! Writing: see [`write_geotiff`].
//!
//! Modules, lowest first: `tags` (numbers and names), `ifd` (reading IFDs),
//! `geokeys` (CRS from and to GeoKeys), `header` (a page's header, read),
//! `read` (its pixels), `windows` (its pixels a window at a time), `raster` (what the writer is given), `write_ifd`
//! (the writer's IFDs), `write` (the writer).

mod deflate_check;
mod geokeys;
mod header;
mod ifd;
mod raster;
mod read;
mod tags;
mod windows;
mod write;
mod write_ifd;

pub use geokeys::geokey_directory;
pub use ifd::TiffPage;
pub(super) use ifd::pages;
pub use raster::{Band, BandData, Page, SampleType};
pub(super) use read::{read, read_band};
pub use windows::{GeoTiffWindows, MAX_CHUNK_BYTES, ReadAt};
pub use write::{TiledGeoTiffWriter, write_geotiff};

use super::TerrainError;

/// Whether `bytes` start with a TIFF or BigTIFF header, either byte order.
pub(super) fn is_tiff(bytes: &[u8]) -> bool {
    matches!(
        bytes.get(..4),
        Some(b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+")
    )
}

fn invalid(msg: impl Into<String>) -> TerrainError {
    TerrainError::Invalid(msg.into())
}

fn unsupported(msg: impl Into<String>) -> TerrainError {
    TerrainError::Unsupported(msg.into())
}
