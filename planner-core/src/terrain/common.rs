//! The pieces every format reader (GeoTIFF, ASCII grid, `.hgt`) shares:
//! the size limits, the CRS decision and a C-like number parser.

use super::crs::crs_from_epsg;
use super::{Crs, DemLimits, TerrainError};

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
