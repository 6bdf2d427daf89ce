//! SRTM `.hgt` tiles: a square grid of big-endian Int16 heights, 1201²
//! (3″) or 3601² (1″) samples, -32768 for voids, WGS84 lon/lat. The tile's
//! south-west corner is only in the file name (`N45E006.hgt`). Sample
//! centres sit on whole degrees and on the 1/1200° (1/3600°) grid: the first
//! sample's centre is the tile's north-west corner, so the raster's outer
//! edge is half a sample outside the 1°×1° square (as GDAL's SRTMHGT
//! driver reads it).

use super::common::{check_limits, resolve_crs};
use super::{Dem, DemFormat, DemLimits, GeoTransform, TerrainError};

/// The void marker of SRTM tiles.
const VOID: i16 = -32768;

pub(super) fn has_hgt_extension(name: &str) -> bool {
    base_name(name).to_ascii_lowercase().ends_with(".hgt")
}

/// Samples per side if `len` bytes is the size of an SRTM tile.
fn side_for_len(len: usize) -> Option<usize> {
    [1201usize, 3601]
        .into_iter()
        .find(|&n| n.checked_mul(n).and_then(|n| n.checked_mul(2)) == Some(len))
}

pub(super) fn is_hgt_size(len: usize) -> bool {
    side_for_len(len).is_some()
}

/// The last component of a path (either separator).
fn base_name(name: &str) -> &str {
    name.rsplit(['/', '\\']).next().unwrap_or(name)
}

/// The south-west corner (lat, lon) from a name like `N45E006.hgt` or
/// `s12w077.SRTMGL1.hgt`.
fn corner_from_name(name: &str) -> Option<(i32, i32)> {
    let b = base_name(name).as_bytes();
    let ns = *b.first()?;
    let lat_digits = b.get(1..3)?;
    let ew = *b.get(3)?;
    let lon_digits = b.get(4..7)?;
    if !lat_digits.iter().chain(lon_digits).all(u8::is_ascii_digit) {
        return None;
    }
    if b.get(7).is_some_and(u8::is_ascii_alphanumeric) {
        return None;
    }
    let num = |d: &[u8]| d.iter().fold(0i32, |a, &c| a * 10 + i32::from(c - b'0'));
    let lat = match ns.to_ascii_uppercase() {
        b'N' => num(lat_digits),
        b'S' => -num(lat_digits),
        _ => return None,
    };
    let lon = match ew.to_ascii_uppercase() {
        b'E' => num(lon_digits),
        b'W' => -num(lon_digits),
        _ => return None,
    };
    ((-90..=89).contains(&lat) && (-180..=179).contains(&lon)).then_some((lat, lon))
}

pub(super) fn read(
    bytes: &[u8],
    name: &str,
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    let Some(n) = side_for_len(bytes.len()) else {
        return Err(TerrainError::Invalid(format!(
            "{name:?} is {} bytes; an SRTM .hgt tile is 1201×1201 (2884802 bytes) or \
             3601×3601 (25934402 bytes) big-endian 16-bit samples",
            bytes.len()
        )));
    };
    let Some((lat, lon)) = corner_from_name(name) else {
        return Err(TerrainError::Invalid(format!(
            "cannot read the tile's position from the file name {:?}: an SRTM .hgt \
             file must be named like N45E006.hgt (latitude N/S 0-90, longitude E/W 0-180 \
             of its south-west corner)",
            base_name(name)
        )));
    };
    check_limits(n as u64, n as u64, limits)?;
    let crs = resolve_crs(Ok(4326), crs)?;
    if !crs.geographic {
        return Err(TerrainError::Crs(format!(
            "an SRTM .hgt tile's positions are degrees; EPSG:{} is projected (metres)",
            crs.epsg
        )));
    }

    let step = 1.0 / (n - 1) as f64;
    let transform = GeoTransform {
        origin_x: f64::from(lon) - 0.5 * step,
        pixel_width: step,
        row_rotation: 0.0,
        origin_y: f64::from(lat) + 1.0 + 0.5 * step,
        col_rotation: 0.0,
        pixel_height: -step,
    };
    let values = bytes
        .chunks_exact(2)
        .map(|c| {
            let v = i16::from_be_bytes([
                c.first().copied().unwrap_or(0),
                c.get(1).copied().unwrap_or(0),
            ]);
            if v == VOID { f64::NAN } else { f64::from(v) }
        })
        .collect();
    Ok(Dem {
        width: n,
        height: n,
        values,
        nodata: Some(f64::from(VOID)),
        transform,
        crs,
        format: DemFormat::Hgt,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::read_dem;

    #[test]
    fn names() {
        assert_eq!(corner_from_name("N45E006.hgt"), Some((45, 6)));
        assert_eq!(corner_from_name("/data/s12w077.hgt"), Some((-12, -77)));
        assert_eq!(
            corner_from_name("C:\\x\\N00W180.SRTMGL1.hgt"),
            Some((0, -180))
        );
        assert_eq!(corner_from_name("N45E006"), Some((45, 6)));
        assert_eq!(corner_from_name("N45E0061.hgt"), None);
        assert_eq!(corner_from_name("N91E006.hgt"), None);
        assert_eq!(corner_from_name("N45E180.hgt"), None);
        assert_eq!(corner_from_name("X45E006.hgt"), None);
        assert_eq!(corner_from_name("N4"), None);
        assert_eq!(corner_from_name("Né5E006.hgt"), None);
        assert!(has_hgt_extension("dir/N45E006.HGT"));
        assert!(!has_hgt_extension("N45E006.hgt.zip"));
    }

    #[test]
    fn reads_a_tile() {
        let n = 1201usize;
        let mut bytes = vec![0u8; n * n * 2];
        // (col 0, row 0) = 1000, (col 1200, row 1200) = -5, (col 3, row 2) void.
        bytes[0..2].copy_from_slice(&1000i16.to_be_bytes());
        let last = (n * n - 1) * 2;
        bytes[last..last + 2].copy_from_slice(&(-5i16).to_be_bytes());
        let i = (2 * n + 3) * 2;
        bytes[i..i + 2].copy_from_slice(&VOID.to_be_bytes());
        let dem = read_dem(&bytes, Some("N45E006.hgt"), None, &DemLimits::default()).unwrap();
        assert_eq!((dem.width, dem.height), (n, n));
        assert_eq!(dem.crs.epsg, 4326);
        assert_eq!(dem.format, DemFormat::Hgt);
        assert_eq!(dem.value(0, 0), Some(1000.0));
        assert_eq!(dem.value(1200, 1200), Some(-5.0));
        assert_eq!(dem.value(3, 2), None);
        assert_eq!(dem.value(4, 2), Some(0.0));
        assert_eq!(dem.nodata, Some(-32768.0));
        // The first sample's centre is the NW corner, the last one the SE corner.
        let (x, y) = dem.transform.apply(0.5, 0.5);
        assert!((x - 6.0).abs() < 1e-12 && (y - 46.0).abs() < 1e-12);
        let (x, y) = dem.transform.apply(1200.5, 1200.5);
        assert!((x - 7.0).abs() < 1e-12 && (y - 45.0).abs() < 1e-12);
        // Override.
        let dem = read_dem(
            &bytes,
            Some("N45E006.hgt"),
            Some(4258),
            &DemLimits::default(),
        )
        .unwrap();
        assert_eq!(dem.crs.epsg, 4258);
        // A projected override would read the degrees as metres.
        let e = read_dem(
            &bytes,
            Some("N45E006.hgt"),
            Some(32632),
            &DemLimits::default(),
        )
        .unwrap_err();
        assert!(
            matches!(e, TerrainError::Crs(ref m) if m.contains("projected")),
            "{e}"
        );
    }

    #[test]
    fn rejects_bad_tiles() {
        let l = DemLimits::default();
        let e = read_dem(&[0u8; 100], Some("N45E006.hgt"), None, &l).unwrap_err();
        assert!(
            matches!(e, TerrainError::Invalid(_)) && e.to_string().contains("100 bytes"),
            "{e}"
        );
        let bytes = vec![0u8; 1201 * 1201 * 2];
        let e = read_dem(&bytes, Some("tile.hgt"), None, &l).unwrap_err();
        assert!(e.to_string().contains("N45E006"), "{e}");
        let small = DemLimits {
            max_pixels: 1000,
            max_side: 1000,
        };
        let e = read_dem(&bytes, Some("N45E006.hgt"), None, &small).unwrap_err();
        assert!(matches!(e, TerrainError::TooLarge { .. }), "{e}");
    }
}
