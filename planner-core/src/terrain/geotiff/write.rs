//! Streaming writer of GeoTIFFs (SPEC §4.2 output: the costmap "in the
//! DEM's CRS, readable by GDAL/QGIS"), of Float32 and Byte bands.
//!
//! A file holds one or more *pages* (TIFF images, GDAL's subdatasets
//! `GTIFF_DIR:1:file.tif`, `GTIFF_DIR:2:file.tif`, …; opening the file
//! itself gives the first). All bands of a page share one sample type and
//! one nodata value, as GDAL's GTiff driver and libtiff require: a band
//! that needs another type or nodata goes on a page of its own. Every page
//! is a little-endian, uncompressed, stripped image with
//! `PlanarConfiguration = 2` (one plane per band, written one after the
//! other), `SampleFormat` 3 / `BitsPerSample` 32 (Float32) or 1 / 8 (Byte),
//! and the tags GDAL reads back:
//!
//! - georeferencing: `ModelPixelScale` + `ModelTiepoint` for a north-up
//!   raster (no rotation, `pixel_width > 0`, `pixel_height < 0`), otherwise
//!   `ModelTransformation`; `GTRasterTypeGeoKey = 1` (PixelIsArea), so the
//!   transform's origin is the outer corner of pixel (0, 0) as in GDAL;
//! - the CRS as an EPSG code in the `GeoKeyDirectory`
//!   (`GeographicTypeGeoKey` or `ProjectedCSTypeGeoKey`), with the CRS name
//!   as `GTCitationGeoKey`;
//! - the page's `GDAL_NODATA` (`"nan"` for NaN, as GDAL writes it), and in
//!   `GDAL_METADATA` each band's description, unit (GDAL's `GetUnitType`,
//!   e.g. `m`, `deg`) and further metadata items.
//!
//! Layout: header, the pages' IFDs and tag values first, then the image
//! data, page after page and band after band, in strips of about 256 KiB.
//! Everything is known before the first byte is written, so the output is
//! written strictly sequentially and without seeking. On a little-endian
//! machine a band's memory is its strips' bytes already: each band goes
//! out in one `write_all`, without a copy (a `BufWriter` passes so large a
//! write straight through); elsewhere one strip at a time is encoded and
//! written, and only that strip is held besides the caller's bands. A file larger than
//! 4 GiB is written as BigTIFF automatically (GDAL, QGIS and terraplan's own
//! reader read it).

use std::io::{self, Seek, Write};

use super::geokeys::epsg_code;
use super::raster::{
    Page, Raster, SampleType, Strips, invalid_input, len_u64, page_sample, too_large,
};
use super::write_ifd::{ifd_entries, serialize_ifd};
use crate::terrain::{Crs, GeoTransform};

/// Write `pages` (each band `width × height` cells, row-major) as a
/// GeoTIFF georeferenced by `transform` (GDAL's convention, corner of pixel
/// (0, 0) at the origin) in `crs`. The first page is what GDAL opens as
/// the file; page n is GDAL's `GTIFF_DIR:n:file` and terraplan's
/// `read_geotiff_page_band(bytes, n, …)`.
///
/// `out` must be positioned at the start of the file (a fresh `File`,
/// `BufWriter<File>` or `Cursor`); it is flushed before returning. The
/// values are not checked against the nodata value: NaN cells stay NaN
/// whatever it is.
///
/// # Errors
///
/// `io::ErrorKind::InvalidInput` (nothing written) when the width or height
/// is 0 or above `u32::MAX`, there are no pages, a page has no bands or
/// more than 65 535, mixes sample types, or has a nodata value its type
/// cannot hold, a band's length is not `width × height`, a metadata name is
/// not a plain identifier, the transform is not finite or not invertible,
/// the EPSG code does not fit a GeoKey (1..=65535, not 32767), or `out` is
/// not at position 0; any error of `out`.
pub fn write_geotiff<W: Write + Seek>(
    out: W,
    width: usize,
    height: usize,
    transform: &GeoTransform,
    crs: &Crs,
    pages: &[Page<'_>],
) -> io::Result<()> {
    let raster = Raster {
        width,
        height,
        transform,
        crs,
        pages,
    };
    write_raster(out, &raster, Options::default())
}

/// Bytes per strip aimed at (a strip holds at least one row).
const STRIP_TARGET_BYTES: usize = 256 * 1024;

/// Pages a file may hold (each IFD is written before any data).
const MAX_PAGES: usize = 1024;

/// Knobs the tests turn to exercise many strips and BigTIFF on small files.
#[derive(Clone, Copy, Debug)]
struct Options {
    strip_target_bytes: usize,
    force_bigtiff: bool,
    /// Encode and write strip by strip even where a band's memory could
    /// be written as it is (the big-endian path, tested everywhere).
    strip_by_strip: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            strip_target_bytes: STRIP_TARGET_BYTES,
            force_bigtiff: false,
            strip_by_strip: false,
        }
    }
}
/// Where everything goes: the head (header and IFDs) and the byte at
/// which each page's image data starts.
struct Layout {
    head: Vec<u8>,
    data_starts: Vec<u64>,
}

fn write_raster<W: Write + Seek>(mut out: W, r: &Raster<'_>, opts: Options) -> io::Result<()> {
    validate(r, true)?;
    let position = out.stream_position()?;
    if position != 0 {
        return Err(invalid_input(format!(
            "the GeoTIFF must be written at the start of the file, not at byte {position}"
        )));
    }
    let strips = r
        .pages
        .iter()
        .map(|p| Strips::new(r.width, r.height, page_sample(p), opts.strip_target_bytes))
        .collect::<io::Result<Vec<_>>>()?;
    let classic = if opts.force_bigtiff {
        None
    } else {
        layout(r, &strips, false)?
    };
    let laid = match classic {
        Some(l) => l,
        None => layout(r, &strips, true)?.ok_or_else(too_large)?,
    };
    out.write_all(&laid.head)?;
    let mut written = len_u64(laid.head.len())?;

    let largest = strips
        .iter()
        .map(|s| s.row_bytes.saturating_mul(s.rows_per_strip as u64))
        .max()
        .unwrap_or(0);
    let mut buf = Vec::with_capacity(usize::try_from(largest).unwrap_or(0));
    for ((page, st), &start) in r.pages.iter().zip(&strips).zip(&laid.data_starts) {
        // Padding to the page's 8-byte aligned start.
        let pad = start.checked_sub(written).ok_or_else(too_large)?;
        out.write_all(&vec![0; usize::try_from(pad).map_err(|_| too_large())?])?;
        written = start;
        for band in page.bands {
            // A band's strips follow each other in the file: on a
            // little-endian machine, its memory in one write (no copy).
            if let Some(bytes) = band.data.le_bytes().filter(|_| !opts.strip_by_strip) {
                out.write_all(bytes)?;
                written += len_u64(bytes.len())?;
                continue;
            }
            for s in 0..st.per_band {
                let rows = st.rows(s, r.height);
                band.data
                    .encode(rows.start * r.width..rows.end * r.width, &mut buf)?;
                out.write_all(&buf)?;
                written += len_u64(buf.len())?;
            }
        }
    }
    out.flush()
}

/// Everything that goes before the image data (header, the pages' IFDs
/// with their tag values, padding) and where each page's data starts.
/// `None` when a classic TIFF cannot hold the file (> 4 GiB).
fn layout(r: &Raster<'_>, strips: &[Strips], big: bool) -> io::Result<Option<Layout>> {
    let header_len: u64 = if big { 16 } else { 8 };
    let mut data_lens = Vec::with_capacity(r.pages.len());
    for (page, st) in r.pages.iter().zip(strips) {
        let n_bands = len_u64(page.bands.len())?;
        data_lens.push(st.band_bytes.checked_mul(n_bands).ok_or_else(too_large)?);
    }
    // A classic TIFF's offsets are 32-bit: check before laying out IFDs
    // that could not hold them.
    let total = data_lens
        .iter()
        .try_fold(0u64, |a, &l| a.checked_add(l))
        .ok_or_else(too_large)?;
    if !big && total > u64::from(u32::MAX) {
        return Ok(None);
    }
    // An IFD's size does not depend on the values of the strip offsets or
    // of the next-IFD pointer, nor (IFDs starting 8-byte aligned) on where
    // it starts: measure each with zeros, then lay them out for real.
    let mut ifd_starts = Vec::with_capacity(r.pages.len());
    let mut at = header_len;
    for (page, st) in r.pages.iter().zip(strips) {
        ifd_starts.push(at);
        let probe = serialize_ifd(&ifd_entries(r, page, st, 0, big)?, big, at, 0)?;
        at = align8(at.checked_add(len_u64(probe.len())?))?;
    }
    let mut data_starts = Vec::with_capacity(r.pages.len());
    for len in &data_lens {
        data_starts.push(at);
        at = align8(at.checked_add(*len))?;
    }
    // Where the last page's data ends (no padding after it).
    let end = data_starts[data_starts.len() - 1] + data_lens[data_lens.len() - 1];
    if !big && end > u64::from(u32::MAX) {
        return Ok(None);
    }

    let head_len = usize::try_from(data_starts[0]).map_err(|_| too_large())?;
    let mut head = Vec::with_capacity(head_len);
    if big {
        head.extend_from_slice(b"II");
        head.extend_from_slice(&43u16.to_le_bytes());
        head.extend_from_slice(&8u16.to_le_bytes());
        head.extend_from_slice(&0u16.to_le_bytes());
        head.extend_from_slice(&header_len.to_le_bytes());
    } else {
        head.extend_from_slice(b"II");
        head.extend_from_slice(&42u16.to_le_bytes());
        head.extend_from_slice(&8u32.to_le_bytes());
    }
    for (i, (page, st)) in r.pages.iter().zip(strips).enumerate() {
        let next = ifd_starts.get(i + 1).copied().unwrap_or(0);
        let entries = ifd_entries(r, page, st, data_starts[i], big)?;
        let ifd = serialize_ifd(&entries, big, ifd_starts[i], next)?;
        debug_assert_eq!(len_u64(head.len())?, ifd_starts[i]);
        head.extend_from_slice(&ifd);
        head.resize(head.len().next_multiple_of(8), 0);
    }
    debug_assert_eq!(head.len(), head_len);
    head.resize(head_len, 0);
    Ok(Some(Layout { head, data_starts }))
}

/// `v` rounded up to a multiple of 8; an error on overflow (of `v` too).
pub(super) fn align8(v: Option<u64>) -> io::Result<u64> {
    v.and_then(|v| v.checked_next_multiple_of(8))
        .ok_or_else(too_large)
}

/// A metadata item name GDAL's XML and `gdalinfo` show as is.
fn plain_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_alphabetic())
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Checks what the writer is given; the bands' lengths only with
/// `with_data` (a tiled file's bands come a tile at a time).
fn validate(r: &Raster<'_>, with_data: bool) -> io::Result<()> {
    if r.width == 0 || r.height == 0 {
        return Err(invalid_input(format!(
            "cannot write a {}×{} GeoTIFF: width and height must be positive",
            r.width, r.height
        )));
    }
    if u32::try_from(r.width).is_err() || u32::try_from(r.height).is_err() {
        return Err(invalid_input(format!(
            "cannot write a {}×{} GeoTIFF: a TIFF's width and height are at most {}",
            r.width,
            r.height,
            u32::MAX
        )));
    }
    if r.pages.is_empty() {
        return Err(invalid_input("cannot write a GeoTIFF without pages"));
    }
    if r.pages.len() > MAX_PAGES {
        return Err(invalid_input(format!(
            "cannot write {} pages: at most {MAX_PAGES}",
            r.pages.len()
        )));
    }
    let cells = r.width.checked_mul(r.height).ok_or_else(too_large)?;
    for (p, page) in r.pages.iter().enumerate() {
        let p = p + 1;
        if page.bands.is_empty() {
            return Err(invalid_input(format!(
                "page {p} has no bands: a TIFF image has at least one"
            )));
        }
        if page.bands.len() > usize::from(u16::MAX) {
            return Err(invalid_input(format!(
                "cannot write {} bands on page {p}: a TIFF has at most {} samples per pixel",
                page.bands.len(),
                u16::MAX
            )));
        }
        let sample = page_sample(page);
        for (i, band) in page.bands.iter().enumerate() {
            let b = i + 1;
            if with_data && band.data.len() != cells {
                return Err(invalid_input(format!(
                    "page {p} band {b} ({:?}) has {} values, expected {}×{} = {cells}",
                    band.description,
                    band.data.len(),
                    r.width,
                    r.height
                )));
            }
            let own = band.data.sample_type();
            if own != sample {
                return Err(invalid_input(format!(
                    "page {p} band {b} ({:?}) is {} but band 1 is {}: the bands of a TIFF \
                     image share one sample type; put it on a page of its own",
                    band.description,
                    own.name(),
                    sample.name()
                )));
            }
            if let Some((name, _)) = band.metadata.iter().find(|(n, _)| !plain_name(n)) {
                return Err(invalid_input(format!(
                    "page {p} band {b}: the metadata name {name:?} is not letters, digits and \
                     '_' starting with a letter"
                )));
            }
        }
        if let Some(v) = page.nodata {
            let fits = match sample {
                SampleType::Float32 => !v.is_finite() || (v as f32).is_finite(),
                SampleType::Byte => v.fract() == 0.0 && (0.0..=255.0).contains(&v),
            };
            if !fits {
                return Err(invalid_input(format!(
                    "page {p}: the nodata value {v} does not fit its {} samples",
                    sample.name()
                )));
            }
        }
    }
    let t = r.transform;
    let all = t.coefficients();
    if !t.is_regular() {
        return Err(invalid_input(format!(
            "the geotransform {all:?} is not finite and invertible"
        )));
    }
    if epsg_code(r.crs).is_none() {
        return Err(invalid_input(format!(
            "EPSG:{} cannot be written as a GeoTIFF CRS code (1..=65535, not 32767)",
            r.crs.epsg
        )));
    }
    Ok(())
}

mod tiled;
pub use tiled::TiledGeoTiffWriter;

#[cfg(test)]
mod tests;
