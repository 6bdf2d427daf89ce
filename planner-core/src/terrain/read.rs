//! Format detection and the pieces the three readers share: the size
//! limits, the CRS decision and a C-like number parser.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use super::geotiff::TiffPage;
use super::{Crs, Dem, DemLimits, TerrainError, asc, geotiff, hgt};

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
    if !dem.crs.geographic {
        return Ok(());
    }
    let corners = [
        (0.0, 0.0),
        (dem.width as f64, 0.0),
        (0.0, dem.height as f64),
        (dem.width as f64, dem.height as f64),
    ];
    for (c, r) in corners {
        let (x, y) = dem.transform.apply(c, r);
        // Half-pixel borders may reach a little past the poles or ±180°.
        if !(x.is_finite()
            && y.is_finite()
            && (-181.0..=361.0).contains(&x)
            && (-91.0..=91.0).contains(&y))
        {
            return Err(TerrainError::Crs(format!(
                "the raster's corner ({x}, {y}) is not a longitude/latitude in degrees, yet \
                 its CRS EPSG:{} is geographic: check the crs",
                dem.crs.epsg
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
fn describe_start(bytes: &[u8]) -> String {
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

/// `TooLarge` unless a `width`×`height` raster fits `limits`. Called with the
/// header's numbers before anything of that size is allocated.
pub(super) fn check_limits(
    width: u64,
    height: u64,
    limits: &DemLimits,
) -> Result<(), TerrainError> {
    let side = u64::from(limits.max_side);
    if width > side || height > side {
        return Err(TerrainError::TooLarge {
            width,
            height,
            limit: format!("{} pixels per side", limits.max_side),
        });
    }
    match width.checked_mul(height) {
        Some(n) if n <= limits.max_pixels => Ok(()),
        _ => Err(TerrainError::TooLarge {
            width,
            height,
            limit: format!("{} pixels", limits.max_pixels),
        }),
    }
}

/// The CRS of a DEM: the caller's EPSG code if given (validated with PROJ),
/// else the one the file declares. `from_file` is the file's EPSG code or
/// why none can be determined.
pub(super) fn resolve_crs(
    from_file: Result<u32, String>,
    given: Option<u32>,
) -> Result<Crs, TerrainError> {
    if let Some(code) = given {
        return crs_from_epsg(code);
    }
    match from_file {
        Ok(code) => crs_from_epsg(code).map_err(|e| {
            TerrainError::UnknownCrs(format!(
                "the file declares EPSG:{code}, which cannot be used: {e}"
            ))
        }),
        Err(reason) => Err(TerrainError::UnknownCrs(reason)),
    }
}

/// [`Crs::from_epsg`], remembered: asking PROJ costs milliseconds, about
/// as much as reading a DEM of a few megabytes.
pub(super) fn crs_from_epsg(code: u32) -> Result<Crs, TerrainError> {
    static CACHE: OnceLock<Mutex<HashMap<u32, Crs>>> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(crs) = cache.lock().ok().and_then(|c| c.get(&code).cloned()) {
        return Ok(crs);
    }
    let crs = Crs::from_epsg(code)?;
    if let Ok(mut c) = cache.lock()
        && c.len() < 4096
    {
        c.insert(code, crs.clone());
    }
    Ok(crs)
}

/// A number as C's `atof` (GDAL's `CPLAtofM`) reads it: leading white space
/// skipped, the longest numeric prefix taken (`nan`, `inf`, `infinity`
/// included, `,` accepted as the decimal separator), 0 when there is none.
/// Returns the value and whether the whole trimmed text was the number.
pub(super) fn c_atof(text: &str) -> (f64, bool) {
    let t = text.trim_matches(|c: char| c.is_ascii_whitespace() || c == '\0');
    let t = t.get(..t.len().min(400)).unwrap_or("");
    let b = t.as_bytes();
    let mut i = 0;
    if matches!(b.first(), Some(b'+' | b'-')) {
        i = 1;
    }
    let rest = t.get(i..).unwrap_or("").to_ascii_lowercase();
    for word in ["infinity", "inf", "nan"] {
        if rest.starts_with(word) {
            let v = if word == "nan" {
                f64::NAN
            } else {
                f64::INFINITY
            };
            let v = if b.first() == Some(&b'-') { -v } else { v };
            return (v, rest.len() == word.len());
        }
    }
    // Longest prefix of the form digits[.digits][e[+-]digits].
    let mut j = i;
    let digits = |j: &mut usize| {
        let s = *j;
        while b.get(*j).is_some_and(u8::is_ascii_digit) {
            *j += 1;
        }
        *j > s
    };
    let mut any = digits(&mut j);
    if matches!(b.get(j), Some(b'.' | b',')) {
        j += 1;
        any |= digits(&mut j);
    }
    if !any {
        return (0.0, false);
    }
    let mantissa_end = j;
    if matches!(b.get(j), Some(b'e' | b'E')) {
        let mut k = j + 1;
        if matches!(b.get(k), Some(b'+' | b'-')) {
            k += 1;
        }
        if digits(&mut k) {
            j = k;
        }
    }
    let _ = mantissa_end;
    let num = t.get(..j).unwrap_or("").replace(',', ".");
    let v = num.parse::<f64>().unwrap_or(0.0);
    (v, j == t.len())
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
    fn atof_like_c() {
        assert_eq!(c_atof("-9999"), (-9999.0, true));
        assert_eq!(c_atof(" -9999\0"), (-9999.0, true));
        assert_eq!(c_atof("1.5e3x"), (1500.0, false));
        assert_eq!(c_atof("1,5"), (1.5, true));
        assert_eq!(c_atof("abc"), (0.0, false));
        assert_eq!(c_atof(""), (0.0, false));
        assert_eq!(c_atof("1e"), (1.0, false));
        assert_eq!(c_atof(".5"), (0.5, true));
        assert!(c_atof("nan").0.is_nan());
        assert!(c_atof("-NaN").0.is_nan());
        assert_eq!(c_atof("-inf").0, f64::NEG_INFINITY);
        assert_eq!(
            c_atof("-3.4028234663852886e+38").0,
            -3.402_823_466_385_288_6e38
        );
        assert_eq!(c_atof("1e999").0, f64::INFINITY);
    }

    #[test]
    fn limits() {
        let l = DemLimits {
            max_pixels: 100,
            max_side: 20,
        };
        assert!(check_limits(10, 10, &l).is_ok());
        assert!(matches!(
            check_limits(11, 10, &l),
            Err(TerrainError::TooLarge { .. })
        ));
        assert!(matches!(
            check_limits(21, 1, &l),
            Err(TerrainError::TooLarge { .. })
        ));
        assert!(matches!(
            check_limits(
                u64::MAX,
                u64::MAX,
                &DemLimits {
                    max_pixels: u64::MAX,
                    max_side: u32::MAX
                }
            ),
            Err(TerrainError::TooLarge { .. })
        ));
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

    #[test]
    fn given_crs_is_validated() {
        assert!(matches!(
            resolve_crs(Ok(4326), Some(999_999)),
            Err(TerrainError::Crs(_))
        ));
        assert_eq!(
            resolve_crs(Err("x".into()), Some(32633)).unwrap().epsg,
            32633
        );
        assert!(matches!(
            resolve_crs(Err("x".into()), None),
            Err(TerrainError::UnknownCrs(_))
        ));
        assert!(matches!(
            resolve_crs(Ok(999_999), None),
            Err(TerrainError::UnknownCrs(_))
        ));
        assert_eq!(resolve_crs(Ok(4326), None).unwrap().epsg, 4326);
    }
}
