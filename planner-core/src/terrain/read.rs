//! Reading a DEM: format detection, dispatch to the format's reader and
//! the checks every DEM passes (its corners in degrees when geographic).

use super::geotiff::TiffPage;
use super::{Crs, Dem, DemLimits, GeoTransform, TerrainError, asc, geotiff, hgt};

/// Read a DEM from the bytes of a file. The format is detected from the
/// content (TIFF magic, ASCII grid header); `file_name` is used for SRTM
/// `.hgt`, whose extent is only in its name (`N45E006.hgt`). `crs`
/// (an EPSG code) overrides or supplies the CRS.
///
/// The header is checked against `limits` before any pixel is allocated.
/// Any input ends in `Ok` or `Err`: corrupt, truncated or hostile files are
/// [`TerrainError`]s, never a panic.
pub fn read_dem(
    bytes: &[u8],
    file_name: Option<&str>,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    let dem = read_any(bytes, file_name, crs, limits)?;
    check_degrees(&dem)?;
    Ok(dem)
}

/// Read band `band` (numbered from 1) of a GeoTIFF with one or more bands
/// (`SamplesPerPixel`) into a [`Dem`], e.g. the cost or class band of a
/// costmap. Everything else is as [`read_dem`] reads a single-band
/// GeoTIFF: georeferencing, CRS (`crs` overrides or supplies it),
/// `GDAL_NODATA` (one value for every band, as GDAL writes it) and `NaN`
/// cells, vertical units, the `limits` checked before any pixel is
/// allocated, and no panic on any input.
///
/// Bands may be interleaved per pixel (`PlanarConfiguration` 1) or
/// separate (2), in strips or tiles, uncompressed, LZW, Deflate or
/// PackBits, with or without a predictor; all bands must have one sample
/// type (8-, 16- and 32-bit integers, Float32, Float64) and be MinIsBlack.
///
/// # Errors
///
/// A [`TerrainError`] for everything [`read_dem`] refuses (but several
/// bands), for a band number of 0 or above the file's band count (the
/// message names both), bands of different sample types, and bytes that
/// are not a TIFF.
pub fn read_geotiff_band(
    bytes: &[u8],
    band: usize,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    read_geotiff_page_band(bytes, 1, band, crs, limits)
}

/// Read band `band` of page `page` (both numbered from 1) of a GeoTIFF, as
/// [`read_geotiff_band`] reads the first page's. A page is an image of
/// the file (an IFD of its main chain), GDAL's subdataset
/// `GTIFF_DIR:page:file`; each has its own size, sample type, nodata and
/// georeferencing, e.g. a costmap's Byte class page after its Float32 cost
/// page.
///
/// # Errors
///
/// As [`read_geotiff_band`], and for a page number of 0 or above the
/// file's page count (the message names both).
pub fn read_geotiff_page_band(
    bytes: &[u8],
    page: usize,
    band: usize,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    check_tiff(bytes)?;
    let dem = geotiff::read_band(bytes, page, band, crs, limits)?;
    check_degrees(&dem)?;
    Ok(dem)
}

/// The first `limit` pages (images: IFDs of the main chain, GDAL's
/// `GTIFF_DIR:n`) of a GeoTIFF, with their sizes, band counts and whether
/// each is an image of its own or an overview or mask of another; nothing
/// else is read.
///
/// # Errors
///
/// Bytes that are not a TIFF, or whose chain of images is truncated,
/// points outside the file or loops, or a page without its size.
pub fn geotiff_pages(bytes: &[u8], limit: usize) -> Result<Vec<TiffPage>, TerrainError> {
    check_tiff(bytes)?;
    geotiff::pages(bytes, limit)
}

fn check_tiff(bytes: &[u8]) -> Result<(), TerrainError> {
    if geotiff::is_tiff(bytes) {
        return Ok(());
    }
    Err(TerrainError::Invalid(format!(
        "not a TIFF file: the file starts with {}",
        if bytes.is_empty() {
            "nothing (it is empty)".to_string()
        } else {
            describe_start(bytes)
        }
    )))
}

/// A geographic CRS whose coordinates are not degrees (e.g. a UTM raster
/// uploaded with `crs=EPSG:4326`) would put the DEM somewhere absurd.
fn check_degrees(dem: &Dem) -> Result<(), TerrainError> {
    check_corners_in_degrees(&dem.transform, &dem.crs, dem.width, dem.height)
}

/// [`check_degrees`] from a raster's header alone (for readers that never
/// hold the raster, e.g. [`super::geotiff::GeoTiffWindows`]).
pub(crate) fn check_corners_in_degrees(
    t: &GeoTransform,
    crs: &Crs,
    width: usize,
    height: usize,
) -> Result<(), TerrainError> {
    if !crs.geographic {
        return Ok(());
    }
    let (w, h) = (width as f64, height as f64);
    for (c, r) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        let (x, y) = t.apply(c, r);
        // Half-pixel borders may reach a little past the poles or ±180°.
        if !(x.is_finite()
            && y.is_finite()
            && (-181.0..=361.0).contains(&x)
            && (-91.0..=91.0).contains(&y))
        {
            return Err(TerrainError::Crs(format!(
                "the raster's corner ({x}, {y}) is not a longitude/latitude in degrees, yet \
                 its CRS EPSG:{} is geographic: check the crs",
                crs.epsg
            )));
        }
    }
    Ok(())
}

fn read_any(
    bytes: &[u8],
    file_name: Option<&str>,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    if geotiff::is_tiff(bytes) {
        return geotiff::read(bytes, crs, limits);
    }
    if let Some(name) = file_name
        && hgt::has_hgt_extension(name)
    {
        return hgt::read(bytes, name, crs, limits);
    }
    if asc::is_asc(bytes) {
        return asc::read(bytes, crs, limits);
    }
    if bytes.is_empty() {
        return Err(TerrainError::Invalid("the DEM file is empty".into()));
    }
    if hgt::is_hgt_size(bytes.len()) {
        return Err(TerrainError::Invalid(format!(
            "the file has the size of an SRTM .hgt tile ({} bytes) but {}; an .hgt \
             file's extent is only in its name, e.g. N45E006.hgt",
            bytes.len(),
            match file_name {
                Some(n) => format!("its name {n:?} does not end in .hgt"),
                None => "no file name was given".to_string(),
            }
        )));
    }
    Err(TerrainError::Invalid(format!(
        "not a DEM format terraplan reads (GeoTIFF, ESRI ASCII grid .asc, SRTM .hgt): \
         the file starts with {}",
        describe_start(bytes)
    )))
}

/// The first bytes of a file, for an error message.
pub(crate) fn describe_start(bytes: &[u8]) -> String {
    let head = bytes.get(..bytes.len().min(8)).unwrap_or(&[]);
    if head
        .iter()
        .all(|&b| b.is_ascii_graphic() || b == b' ' || b == b'\t' || b == b'\n' || b == b'\r')
    {
        format!("{:?}", String::from_utf8_lossy(head))
    } else {
        let hex: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
        format!("bytes {}", hex.join(" "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn geographic_crs_needs_degrees() {
        // A 2×2 ASCII grid at UTM-like coordinates declared EPSG:4326.
        let asc = b"ncols 2\nnrows 2\nxllcorner 500000\nyllcorner 4000000\ncellsize 10\n1 2\n3 4\n";
        let e = read_dem(asc, Some("x.asc"), Some(4326), &DemLimits::default()).unwrap_err();
        assert!(
            matches!(e, TerrainError::Crs(ref m) if m.contains("not a longitude/latitude")),
            "{e}"
        );
        assert!(read_dem(asc, Some("x.asc"), Some(32633), &DemLimits::default()).is_ok());
        let deg = b"ncols 2\nnrows 2\nxllcorner 6\nyllcorner 45\ncellsize 0.001\n1 2\n3 4\n";
        assert!(read_dem(deg, Some("x.asc"), Some(4326), &DemLimits::default()).is_ok());
    }
    #[test]
    fn unknown_formats_are_named() {
        let l = DemLimits::default();
        let e = read_dem(b"", None, None, &l).unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e = read_dem(b"\x89PNG\r\n\x1a\n....", Some("x.png"), None, &l).unwrap_err();
        assert!(matches!(e, TerrainError::Invalid(_)));
        assert!(e.to_string().contains("89 50 4e 47"), "{e}");
        let e = read_dem(b"hello world", None, None, &l).unwrap_err();
        assert!(e.to_string().contains("hello wo"), "{e}");
        let e = read_dem(&vec![0u8; 1201 * 1201 * 2], Some("dem.bin"), None, &l).unwrap_err();
        assert!(e.to_string().contains(".hgt"), "{e}");
    }
}
