//! ESRI ASCII grids (`.asc`, GDAL's AAIGrid): a header of `keyword value`
//! lines (`ncols`, `nrows`, `xllcorner`/`xllcenter`, `yllcorner`/`yllcenter`,
//! `cellsize` or `dx`+`dy`, optional `NODATA_value`) followed by `nrows`
//! rows of `ncols` numbers, top row first.
//!
//! Values are read the way GDAL reads them, so that they compare bit for
//! bit: the grid is Int32 unless the nodata value or any data value has a
//! decimal point, comma or exponent, in which case it is Float32 (each value
//! rounded to the nearest f32, clamped to ±f32::MAX), or Float64 when the
//! nodata value does not fit a float. Cells equal to the nodata value are
//! nodata, and so are infinite ones (`inf`, `1e999`: GDAL clamps them to
//! ±f32::MAX, a height no ground has). The CRS lives in a `.prj` side file, which a single file's bytes
//! do not have: an ASCII grid needs the caller's CRS.

use super::common::{c_atof, check_limits, resolve_crs};
use super::{Dem, DemFormat, DemLimits, GeoTransform, TerrainError};

/// Header keywords a grid may start with (GDAL's identification rule).
const START_KEYWORDS: [&str; 9] = [
    "ncols",
    "nrows",
    "xllcorner",
    "yllcorner",
    "xllcenter",
    "yllcenter",
    "dx",
    "dy",
    "cellsize",
];

/// Longest header accepted before the data must start.
const MAX_HEADER_BYTES: usize = 64 * 1024;

fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes)
}

pub(super) fn is_asc(bytes: &[u8]) -> bool {
    let b = strip_bom(bytes);
    let start = b
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(b.len());
    let head = b.get(start..b.len().min(start + 16)).unwrap_or(&[]);
    START_KEYWORDS.iter().any(|k| {
        head.len() > k.len()
            && head
                .get(..k.len())
                .is_some_and(|h| h.eq_ignore_ascii_case(k.as_bytes()))
            && head.get(k.len()).is_some_and(|c| c.is_ascii_whitespace())
    })
}

/// GDAL's `isspace` (C locale): space, \t, \n, \v, \f, \r.
fn is_space(c: u8) -> bool {
    matches!(c, b' ' | b'\t' | b'\n' | 0x0b | 0x0c | b'\r')
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum CellType {
    Int32,
    Float32,
    Float64,
}

/// The header's `keyword value` pairs (keywords lower-cased; the first
/// occurrence wins) and the offset where the data starts.
fn parse_header(b: &[u8]) -> Result<(Vec<(String, String)>, usize), TerrainError> {
    let mut pairs: Vec<(String, String)> = Vec::new();
    let mut pos = 0usize;
    loop {
        if pos >= b.len() {
            return Err(TerrainError::Invalid(
                "the ASCII grid has a header but no data values".into(),
            ));
        }
        if pos > MAX_HEADER_BYTES {
            return Err(TerrainError::Invalid(format!(
                "the ASCII grid's header is longer than {MAX_HEADER_BYTES} bytes"
            )));
        }
        let rest = b.get(pos..).unwrap_or(&[]);
        let line_len = rest
            .iter()
            .position(|&c| c == b'\n')
            .map_or(rest.len(), |p| p + 1);
        let line = rest.get(..line_len).unwrap_or(&[]);
        let first = line.iter().position(|&c| !is_space(c));
        let Some(first) = first else {
            pos += line_len; // blank line
            continue;
        };
        let lead = line.get(first..).unwrap_or(&[]);
        let is_null_value = lead.len() > 4 && lead.get(..4).is_some_and(|n| n == b"null");
        if !lead.first().is_some_and(u8::is_ascii_alphabetic) || is_null_value {
            return Ok((pairs, pos + first));
        }
        let text = String::from_utf8_lossy(line);
        let mut tokens = text
            .split(|c: char| c.is_ascii() && is_space(c as u8))
            .filter(|t| !t.is_empty());
        while let Some(key) = tokens.next() {
            let key = key.to_ascii_lowercase();
            let Some(value) = tokens.next() else {
                return Err(TerrainError::Invalid(format!(
                    "the ASCII grid header keyword {key:?} has no value"
                )));
            };
            if !pairs.iter().any(|(k, _)| *k == key) {
                pairs.push((key, value.to_string()));
            }
        }
        pos += line_len;
    }
}

fn get<'a>(pairs: &'a [(String, String)], key: &str) -> Option<&'a str> {
    pairs
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.as_str())
}

/// A header number; `what` names it in the error.
fn number(pairs: &[(String, String)], key: &str) -> Result<Option<f64>, TerrainError> {
    let Some(text) = get(pairs, key) else {
        return Ok(None);
    };
    let (v, whole) = c_atof(text);
    if !whole || !v.is_finite() {
        return Err(TerrainError::Invalid(format!(
            "the ASCII grid header's {key} {text:?} is not a finite number"
        )));
    }
    Ok(Some(v))
}

fn dimension(pairs: &[(String, String)], key: &str) -> Result<u64, TerrainError> {
    let text = get(pairs, key)
        .ok_or_else(|| TerrainError::Invalid(format!("the ASCII grid header has no {key}")))?;
    match text.parse::<u64>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(TerrainError::Invalid(format!(
            "the ASCII grid header's {key} {text:?} is not a positive whole number"
        ))),
    }
}

/// GDAL's `MapNoDataToFloat`.
fn nodata_to_float(v: f64) -> f64 {
    if v.is_nan() || v.is_infinite() {
        v
    } else if v >= f64::from(f32::MAX) {
        f64::from(f32::MAX)
    } else if v <= -f64::from(f32::MAX) {
        -f64::from(f32::MAX)
    } else {
        f64::from(v as f32)
    }
}

/// GDAL's `DoubleToFloatClamp`, back to f64.
fn clamp_to_f32(v: f64) -> f64 {
    if v <= f64::from(f32::MIN) {
        f64::from(f32::MIN)
    } else if v >= f64::from(f32::MAX) {
        f64::from(f32::MAX)
    } else {
        f64::from(v as f32)
    }
}

pub(super) fn read(
    bytes: &[u8],
    crs: Option<u32>,
    limits: &DemLimits,
) -> Result<Dem, TerrainError> {
    let b = strip_bom(bytes);
    let (pairs, data_start) = parse_header(b)?;
    let ncols = dimension(&pairs, "ncols")?;
    let nrows = dimension(&pairs, "nrows")?;
    check_limits(ncols, nrows, limits)?;
    let data = b.get(data_start..).unwrap_or(&[]);
    let n_cells = ncols * nrows; // fits: checked against the limits
    // Every value takes at least one character and one separator.
    if n_cells.saturating_mul(2).saturating_sub(1) > data.len() as u64 {
        return Err(TerrainError::Invalid(format!(
            "the ASCII grid is short: it declares {ncols}×{nrows} cells but has only {} bytes \
             of data",
            data.len()
        )));
    }

    let transform = georeferencing(&pairs, ncols, nrows)?;
    let crs = resolve_crs(
        Err(
            "an ESRI ASCII grid has no CRS of its own (it is in a .prj side file, \
             which is not read)"
                .into(),
        ),
        crs,
    )?;

    let (cell_type, nodata) = cell_type_and_nodata(&pairs, data)?;
    let values = read_values(data, [ncols, nrows], cell_type, nodata)?;

    Ok(Dem {
        width: ncols as usize,
        height: nrows as usize,
        values,
        nodata,
        transform,
        crs,
        format: DemFormat::Asc,
    })
}

/// The grid's transform from its cell size and lower-left corner (or
/// centre), as GDAL computes it.
fn georeferencing(
    pairs: &[(String, String)],
    ncols: u64,
    nrows: u64,
) -> Result<GeoTransform, TerrainError> {
    let (dx, dy) = match number(pairs, "cellsize")? {
        Some(c) => (c, c),
        None => match (number(pairs, "dx")?, number(pairs, "dy")?) {
            (Some(dx), Some(dy)) => (dx, dy),
            _ => {
                return Err(TerrainError::Invalid(
                    "the ASCII grid header has no cellsize (nor dx and dy)".into(),
                ));
            }
        },
    };
    if !(dx > 0.0 && dy > 0.0) {
        return Err(TerrainError::Invalid(format!(
            "the ASCII grid's cell size ({dx} × {dy}) must be positive"
        )));
    }
    let (mut dx, mut dy) = (dx, dy);
    let rows_f = nrows as f64;
    let (origin_x, origin_y) = match (
        number(pairs, "xllcorner")?,
        number(pairs, "yllcorner")?,
        number(pairs, "xllcenter")?,
        number(pairs, "yllcenter")?,
    ) {
        (Some(x), Some(y), _, _) => {
            // GDAL's fix for grids whose cellsize lost precision (global
            // grids of 360·k columns starting at -180).
            if ncols.is_multiple_of(360)
                && (x + 180.0).abs() < 1e-12
                && dx == dy
                && (dx - 360.0 / ncols as f64).abs() < 1e-9
            {
                dx = 360.0 / ncols as f64;
                dy = dx;
            }
            (x, y + rows_f * dy)
        }
        (_, _, Some(x), Some(y)) => (x - 0.5 * dx, y - 0.5 * dy + rows_f * dy),
        _ => {
            return Err(TerrainError::Invalid(
                "the ASCII grid header needs xllcorner and yllcorner (or xllcenter and \
                 yllcenter)"
                    .into(),
            ));
        }
    };
    let transform = GeoTransform {
        origin_x,
        pixel_width: dx,
        row_rotation: 0.0,
        origin_y,
        col_rotation: 0.0,
        pixel_height: -dy,
    };
    if !(origin_x.is_finite() && origin_y.is_finite()) {
        return Err(TerrainError::Invalid(
            "the ASCII grid's origin is not finite".into(),
        ));
    }
    Ok(transform)
}

/// The cell type and nodata value, as GDAL decides them: Int32 unless the
/// nodata value or any data value has a decimal point, comma or exponent.
fn cell_type_and_nodata(
    pairs: &[(String, String)],
    data: &[u8],
) -> Result<(CellType, Option<f64>), TerrainError> {
    let mut cell_type = CellType::Int32;
    let mut nodata: Option<f64> = None;
    if let Some(text) = get(pairs, "nodata_value") {
        if text == "null" {
            cell_type = CellType::Float32;
            nodata = Some(-f64::from(f32::MAX));
        } else {
            let (v, whole) = c_atof(text);
            if !whole {
                return Err(TerrainError::Invalid(format!(
                    "the ASCII grid's NODATA_value {text:?} is not a number"
                )));
            }
            if text.contains(['.', ',']) || v < f64::from(i32::MIN) || v > f64::from(i32::MAX) {
                cell_type = CellType::Float32;
                if !v.is_infinite()
                    && (v.abs() < f64::from(f32::MIN_POSITIVE) || v.abs() > f64::from(f32::MAX))
                {
                    cell_type = CellType::Float64;
                }
            }
            nodata = Some(if cell_type == CellType::Float32 {
                nodata_to_float(v)
            } else {
                v
            });
        }
    }
    if cell_type == CellType::Int32 && data.iter().any(|c| matches!(c, b'.' | b',' | b'e' | b'E')) {
        cell_type = CellType::Float32;
        nodata = nodata.map(nodata_to_float);
    }
    Ok((cell_type, nodata))
}

/// The `ncols`×`nrows` values of `data`, nodata and infinite ones `NaN`.
fn read_values(
    data: &[u8],
    [ncols, nrows]: [u64; 2],
    cell_type: CellType,
    nodata: Option<f64>,
) -> Result<Vec<f64>, TerrainError> {
    let n_cells = ncols * nrows; // fits: checked against the limits
    let nodata_int = nodata
        .filter(|v| *v >= f64::from(i32::MIN) && *v <= f64::from(i32::MAX))
        .map(|v| v.trunc());

    let capacity = usize::try_from(n_cells).map_err(|_| TerrainError::TooLarge {
        width: ncols,
        height: nrows,
        limit: "the address space".into(),
    })?;
    let mut values = Vec::with_capacity(capacity);
    let mut tokens = data.split(|&c| is_space(c)).filter(|t| !t.is_empty());
    for i in 0..n_cells {
        let Some(tok) = tokens.next() else {
            return Err(TerrainError::Invalid(format!(
                "the ASCII grid is short: it declares {ncols}×{nrows} = {n_cells} values but \
                 has {i}"
            )));
        };
        let bad = || {
            TerrainError::Invalid(format!(
                "the ASCII grid's value at row {}, column {} ({:?}) is not a number",
                i / ncols,
                i % ncols,
                String::from_utf8_lossy(tok.get(..tok.len().min(40)).unwrap_or(&[]))
            ))
        };
        let text = std::str::from_utf8(tok).map_err(|_| bad())?;
        let v = match cell_type {
            CellType::Int32 => {
                let v: i64 = text.parse().map_err(|_| bad())?;
                if v < i64::from(i32::MIN) || v > i64::from(i32::MAX) {
                    return Err(TerrainError::Invalid(format!(
                        "the ASCII grid's value at row {}, column {} ({v}) does not fit a \
                         32-bit integer",
                        i / ncols,
                        i % ncols
                    )));
                }
                let v = v as f64;
                if nodata_int == Some(v) { f64::NAN } else { v }
            }
            CellType::Float32 | CellType::Float64 => {
                let raw = if text == "null" {
                    if cell_type == CellType::Float32 {
                        -f64::from(f32::MAX)
                    } else {
                        -f64::MAX
                    }
                } else {
                    match text.parse::<f64>() {
                        Ok(v) => v,
                        Err(_) => {
                            let (v, whole) = c_atof(text);
                            if !whole {
                                return Err(bad());
                            }
                            v
                        }
                    }
                };
                let v = if !raw.is_finite() {
                    f64::NAN
                } else if cell_type == CellType::Float32 {
                    clamp_to_f32(raw)
                } else {
                    raw
                };
                if v.is_nan() || nodata == Some(v) {
                    f64::NAN
                } else {
                    v
                }
            }
        };
        values.push(v);
    }
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::read_dem;

    fn read(text: &str, crs: Option<u32>) -> Result<Dem, TerrainError> {
        read_dem(text.as_bytes(), Some("x.asc"), crs, &DemLimits::default())
    }

    #[test]
    fn detects() {
        assert!(is_asc(b"ncols 3\nnrows 2\n"));
        assert!(is_asc(b"\xEF\xBB\xBF  NCOLS\t3\n"));
        assert!(is_asc(b"cellsize 3\n"));
        assert!(!is_asc(b"ncolsx 3\n"));
        assert!(!is_asc(b"hello"));
    }

    #[test]
    fn integer_grid_with_corner() {
        let text = "ncols 3\nnrows 2\nxllcorner 100\nyllcorner 200\ncellsize 10\n\
                    NODATA_value -9999\n1 2 3\n4 -9999 6\n";
        let e = read(text, None).unwrap_err();
        assert!(matches!(e, TerrainError::UnknownCrs(_)), "{e}");
        let dem = read(text, Some(32633)).unwrap();
        assert_eq!((dem.width, dem.height), (3, 2));
        assert_eq!(dem.crs.epsg, 32633);
        assert_eq!(dem.format, DemFormat::Asc);
        assert_eq!(dem.value(0, 0), Some(1.0));
        assert_eq!(dem.value(1, 1), None);
        assert_eq!(dem.value(2, 1), Some(6.0));
        assert_eq!(dem.nodata, Some(-9999.0));
        let t = dem.transform;
        assert_eq!(
            (t.origin_x, t.origin_y, t.pixel_width, t.pixel_height),
            (100.0, 220.0, 10.0, -10.0)
        );
    }

    #[test]
    fn float_grid_with_centre_is_rounded_to_f32() {
        let text = "NCOLS 2\r\nNROWS 2\r\nXLLCENTER 0.5\r\nYLLCENTER 0.5\r\nDX 1\r\nDY 2\r\n\
                    0.1 2\r\n3 1e2\r\n";
        let dem = read(text, Some(4326)).unwrap();
        assert_eq!(dem.value(0, 0), Some(f64::from(0.1f32)));
        assert_eq!(dem.value(1, 1), Some(100.0));
        assert_eq!(dem.nodata, None);
        let t = dem.transform;
        assert_eq!(
            (t.origin_x, t.origin_y, t.pixel_width, t.pixel_height),
            (0.0, 3.5, 1.0, -2.0)
        );
    }

    #[test]
    fn nodata_zero_with_float_data() {
        // As in landlab's west_bijou_gully.asc: 0 is nodata, GDAL reads Float32.
        let text =
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value 0\n0 1.5\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.value(0, 0), None);
        assert_eq!(dem.value(1, 0), Some(1.5));
        assert_eq!(dem.nodata, Some(0.0));
        // A nodata value below f32's smallest normal makes GDAL pick Float64.
        let text =
            "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\nNODATA_value 0.0\n0 0.1\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.value(0, 0), None);
        assert_eq!(dem.value(1, 0), Some(0.1));
    }

    /// Values beyond f64 (`1e999`) are infinite: nodata, not the
    /// ±f32::MAX GDAL clamps them to, in Float32 and Float64 grids.
    #[test]
    fn infinite_values_are_nodata() {
        let text = "ncols 3\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1e999 -1e999 2.5\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.value(0, 0), None);
        assert_eq!(dem.value(1, 0), None);
        assert_eq!(dem.value(2, 0), Some(2.5));
        // Finite values over f32's range are still clamped, as GDAL does.
        let text = "ncols 1\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1e39\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.value(0, 0), Some(f64::from(f32::MAX)));
        // A nodata value below f32's smallest normal: a Float64 grid.
        let text = "ncols 2\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n\
                    NODATA_value 0.0\n1e999 0.1\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.value(0, 0), None);
        assert_eq!(dem.value(1, 0), Some(0.1));
    }

    #[test]
    fn values_may_wrap_lines() {
        let text = "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2\n3 4 5\n6 7 8\n";
        let dem = read(text, Some(32613)).unwrap();
        assert_eq!(dem.values, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }

    #[test]
    fn rejects_broken_grids() {
        let cases = [
            (
                "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4 5",
                "short",
            ),
            (
                "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 x 4 5 6",
                "column 2",
            ),
            (
                "ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\n1 2 3 4 5 6",
                "cellsize",
            ),
            ("ncols 3\nnrows 2\ncellsize 1\n1 2 3 4 5 6", "xllcorner"),
            (
                "ncols -3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3",
                "ncols",
            ),
            (
                "ncols 3\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3",
                "nrows",
            ),
            (
                "ncols 3\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 0\n1 2 3",
                "positive",
            ),
            (
                "ncols 3\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 99999999999",
                "32-bit",
            ),
            (
                "ncols 3\nnrows 1\nxllcorner zero\nyllcorner 0\ncellsize 1\n1 2 3",
                "xllcorner",
            ),
            (
                "ncols 3\nnrows 1\nxllcorner 0\nyllcorner 0\ncellsize\n",
                "no value",
            ),
            ("ncols 3\nnrows 1\n", "no data"),
        ];
        for (text, needle) in cases {
            let e = read(text, Some(32613)).unwrap_err();
            assert!(matches!(e, TerrainError::Invalid(_)), "{text:?}: {e}");
            assert!(e.to_string().contains(needle), "{text:?}: {e}");
        }
    }

    #[test]
    fn huge_header_is_too_large_without_allocating() {
        let text = "ncols 1000000\nnrows 1000000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n";
        let e = read(text, Some(32613)).unwrap_err();
        assert!(matches!(e, TerrainError::TooLarge { .. }), "{e}");
        let text = "ncols 1000\nnrows 1000\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n";
        let e = read(text, Some(32613)).unwrap_err();
        assert!(matches!(e, TerrainError::Invalid(_)), "{e}");
    }
}
