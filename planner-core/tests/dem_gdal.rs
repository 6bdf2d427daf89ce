//! The DEM readers against GDAL (gdalinfo, gdallocationinfo, gdal_translate,
//! gdalwarp 3.x and Python's osgeo.gdal, which must be installed).
//!
//! For every raster in the shared data directory and for variants written
//! with GDAL (compressions, predictors, tiles, BigTIFF, big-endian, sample
//! types, PixelIsPoint, a rotated transform, SRTM .hgt, ASCII grids):
//! - the size, geotransform (1e-9 relative), EPSG code and nodata value
//!   equal `gdalinfo -json`'s;
//! - ≥ 1000 pixels (deterministic pseudo-random plus the corners) equal GDAL's
//!   bit for bit (dumped exactly by osgeo.gdal, with GDAL's own nodata
//!   mask), and `gdallocationinfo -valonly` agrees to the 15 significant
//!   digits it prints;
//! - a raster whose CRS GDAL cannot tell is `UnknownCrs` without a CRS.
//!
//! Data: `$TERRAPLAN_SHARED_DATA/dems` (or `$TERRAPLAN_SHARED_DATA` itself),
//! else `../../shared/data/dems` from this crate. Python: `$TERRAPLAN_GDAL_PYTHON`,
//! else `/usr/bin/python3`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use planner_core::terrain::{Dem, DemLimits, TerrainError, read_dem};
use serde_json::Value;

mod support;
use support::data_dir;

/// CRS given for rasters that carry none GDAL can name.
const FALLBACK_CRS: u32 = 32613;
/// Random pixels compared per raster (plus the four corners).
const POINTS: usize = 1200;

fn python() -> String {
    std::env::var("TERRAPLAN_GDAL_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into())
}

fn shared_dems() -> Vec<PathBuf> {
    let dir = data_dir();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("cannot list the shared DEMs in {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            matches!(
                p.extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase)
                    .as_deref(),
                Some("tif" | "tiff" | "asc" | "hgt")
            )
        })
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no DEMs in {}", dir.display());
    files
}

fn run(cmd: &mut Command) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?} (is GDAL installed?): {e}"));
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Run `cmd` with `input` on stdin, return stdout.
fn run_with_input(cmd: &mut Command, input: &str) -> String {
    let mut child = cmd
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {cmd:?}: {e}"));
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_string();
    let writer = std::thread::spawn(move || stdin.write_all(input.as_bytes()));
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap().unwrap();
    assert!(
        out.status.success(),
        "{cmd:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A temporary directory, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let dir =
            std::env::temp_dir().join(format!("terraplan-{tag}-{}-{nanos}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// splitmix64: deterministic, dependency-free.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Exact values and GDAL's nodata mask at (col, row) points: one line per
/// point, "<f64 bits> <mask 0|255>".
const DUMP_PY: &str = r#"
import struct, sys
from osgeo import gdal
gdal.UseExceptions()
ds = gdal.Open(sys.argv[1])
band = ds.GetRasterBand(1)
values = band.ReadAsArray()
mask = band.GetMaskBand().ReadAsArray()
out = []
for line in sys.stdin:
    if not line.strip():
        continue
    c, r = (int(t) for t in line.split())
    bits = struct.unpack('<Q', struct.pack('<d', float(values[r][c])))[0]
    out.append('%d %d' % (bits, int(mask[r][c])))
print('\n'.join(out))
"#;

/// The horizontal EPSG code GDAL gives a raster, `None` if it has none.
fn gdal_epsg(info: &Value) -> Option<u32> {
    if let Some(code) = info.pointer("/stac/proj:epsg").and_then(Value::as_u64) {
        return Some(code as u32);
    }
    let wkt = info.pointer("/coordinateSystem/wkt")?.as_str()?;
    // A compound CRS: its first component is the horizontal one.
    let node = match wkt.strip_prefix("COMPOUNDCRS[") {
        Some(inner) => &inner[inner.find(|c: char| c.is_ascii_uppercase())?..],
        None => wkt,
    };
    if !(node.starts_with("PROJCRS[") || node.starts_with("GEOGCRS[")) {
        return None;
    }
    // The CRS's own ID is an ID[...] directly inside its node (depth 1).
    let mut depth = 0i32;
    let mut in_string = false;
    for (i, ch) in node.char_indices() {
        match ch {
            '"' => in_string = !in_string,
            '[' if !in_string => depth += 1,
            ']' if !in_string => {
                depth -= 1;
                if depth == 0 {
                    return None;
                }
            }
            'I' if !in_string && depth == 1 && node[i..].starts_with("ID[\"EPSG\",") => {
                let rest = &node[i + 10..];
                return rest[..rest.find([']', ','])?].trim().parse().ok();
            }
            _ => {}
        }
    }
    None
}

fn rel_eq(a: f64, b: f64, tol: f64) -> bool {
    a == b || (a - b).abs() <= tol * a.abs().max(b.abs())
}

/// The nearest value with 15 significant digits (what GDAL's %.15g prints).
fn sig15(v: f64) -> f64 {
    format!("{v:.14e}").parse().unwrap()
}

/// Compare our reading of `path` with GDAL's. `crs` is the CRS to give when
/// GDAL knows none; `name` the file name passed to `read_dem`.
fn compare_with_gdal(path: &Path, crs_if_unknown: u32) -> Dem {
    let label = path.display().to_string();
    let bytes = std::fs::read(path).unwrap();
    let name = path.file_name().and_then(|n| n.to_str());
    let info: Value = serde_json::from_str(&run(Command::new("gdalinfo")
        .arg("-json")
        .arg(path)
        .stderr(Stdio::null())))
    .unwrap();
    let limits = DemLimits::default();

    // An ASCII grid's CRS is in its .prj, which read_dem does not see.
    let is_asc = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("asc"));
    let epsg = gdal_epsg(&info);
    let crs_if_unknown = if is_asc {
        epsg.unwrap_or(crs_if_unknown)
    } else {
        crs_if_unknown
    };
    let dem = match epsg.filter(|_| !is_asc) {
        Some(code) => {
            let dem =
                read_dem(&bytes, name, None, &limits).unwrap_or_else(|e| panic!("{label}: {e}"));
            assert_eq!(dem.crs.epsg, code, "{label}: EPSG code");
            dem
        }
        None => {
            let e = read_dem(&bytes, name, None, &limits).unwrap_err();
            assert!(
                matches!(e, TerrainError::UnknownCrs(_)),
                "{label}: GDAL knows no EPSG code, we gave {e:?}"
            );
            let dem = read_dem(&bytes, name, Some(crs_if_unknown), &limits)
                .unwrap_or_else(|e| panic!("{label}: {e}"));
            assert_eq!(dem.crs.epsg, crs_if_unknown);
            dem
        }
    };

    // Size, transform, nodata value.
    let size: Vec<u64> = info["size"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert_eq!(size, [dem.width as u64, dem.height as u64], "{label}: size");
    let gt: Vec<f64> = info["geoTransform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let t = dem.transform;
    let ours = [
        t.origin_x,
        t.pixel_width,
        t.row_rotation,
        t.origin_y,
        t.col_rotation,
        t.pixel_height,
    ];
    for (i, (a, b)) in ours.iter().zip(&gt).enumerate() {
        // Rotation terms are compared relative to the pixel size.
        let scale = if i % 3 == 0 {
            a.abs().max(b.abs())
        } else {
            gt[1].abs().max(gt[5].abs())
        };
        assert!(
            (a - b).abs() <= 1e-9 * scale,
            "{label}: geotransform[{i}] ours {a} GDAL {b} (ours {ours:?}, GDAL {gt:?})"
        );
    }
    for corner in ["upperLeft", "lowerRight"] {
        let c = &info["cornerCoordinates"][corner];
        let (col, row) = if corner == "upperLeft" {
            (0.0, 0.0)
        } else {
            (dem.width as f64, dem.height as f64)
        };
        let (x, y) = t.apply(col, row);
        // gdalinfo prints corners rounded (7 decimals for degrees).
        let printed = if dem.crs.geographic { 1e-7 } else { 1e-3 };
        let close = |a: f64, b: f64| rel_eq(a, b, 1e-9) || (a - b).abs() <= printed;
        assert!(
            close(x, c[0].as_f64().unwrap()) && close(y, c[1].as_f64().unwrap()),
            "{label}: {corner} ours ({x}, {y}) GDAL {c}"
        );
    }
    let band = &info["bands"][0];
    match band.get("noDataValue") {
        None => assert_eq!(dem.nodata, None, "{label}: nodata"),
        Some(Value::String(s)) if s.eq_ignore_ascii_case("nan") => {
            assert!(dem.nodata.is_some_and(f64::is_nan), "{label}: nodata")
        }
        Some(v) => {
            let g = v.as_f64().unwrap();
            let o = dem
                .nodata
                .unwrap_or_else(|| panic!("{label}: no nodata, GDAL {g}"));
            // GDAL reports a Float32 band's nodata rounded to f32.
            assert!(
                o == g || (o as f32) == (g as f32),
                "{label}: nodata ours {o} GDAL {g}"
            );
        }
    }

    // Pixels.
    let mut rng = Rng(0x7E22_A91A ^ bytes.len() as u64);
    let mut points = vec![
        (0, 0),
        (dem.width - 1, 0),
        (0, dem.height - 1),
        (dem.width - 1, dem.height - 1),
    ];
    for _ in 0..POINTS {
        points.push((rng.below(dem.width), rng.below(dem.height)));
    }
    let input: String = points.iter().map(|(c, r)| format!("{c} {r}\n")).collect();
    let exact = run_with_input(
        Command::new(python()).arg("-c").arg(DUMP_PY).arg(path),
        &input,
    );
    let exact: Vec<(u64, u32)> = exact
        .lines()
        .map(|l| {
            let mut it = l.split_whitespace();
            (
                it.next().unwrap().parse().unwrap(),
                it.next().unwrap().parse().unwrap(),
            )
        })
        .collect();
    assert_eq!(exact.len(), points.len(), "{label}: osgeo dump");
    let printed = run_with_input(
        Command::new("gdallocationinfo")
            .arg("-valonly")
            .arg(path)
            .stderr(Stdio::null()),
        &input,
    );
    let printed: Vec<&str> = printed.lines().collect();
    assert_eq!(
        printed.len(),
        points.len(),
        "{label}: gdallocationinfo output"
    );
    let (mut valid, mut nodata) = (0, 0);
    for (((c, r), (bits, mask)), text) in points.iter().zip(&exact).zip(&printed) {
        let ours = dem.values[r * dem.width + c];
        let gdal = f64::from_bits(*bits);
        if *mask == 0 || gdal.is_nan() {
            nodata += 1;
            assert!(
                ours.is_nan(),
                "{label}: ({c}, {r}) is nodata for GDAL ({gdal}), ours {ours}"
            );
            continue;
        }
        valid += 1;
        assert_eq!(
            ours.to_bits(),
            *bits,
            "{label}: ({c}, {r}) ours {ours:e} GDAL {gdal:e}"
        );
        let p: f64 = text
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("{label}: gdallocationinfo printed {text:?}"));
        assert_eq!(
            sig15(ours),
            sig15(p),
            "{label}: ({c}, {r}) ours {ours} gdallocationinfo {text}"
        );
    }
    eprintln!(
        "{label}: {}×{} EPSG:{} — {valid} values equal, {nodata} nodata",
        dem.width, dem.height, dem.crs.epsg
    );
    assert!(valid > 0, "{label}: no valid pixel compared");
    dem
}

#[test]
fn shared_dems_match_gdal() {
    for path in shared_dems() {
        compare_with_gdal(&path, FALLBACK_CRS);
    }
}

/// Write `out` from `src` with gdal_translate `args`.
fn translate(src: &Path, out: &Path, args: &[&str]) {
    run(Command::new("gdal_translate")
        .arg("-q")
        .args(args)
        .arg(src)
        .arg(out)
        .stderr(Stdio::null()));
}

fn shared(name_part: &str) -> PathBuf {
    shared_dems()
        .into_iter()
        .find(|p| p.to_string_lossy().contains(name_part))
        .unwrap_or_else(|| panic!("no shared DEM named like {name_part}"))
}

#[test]
fn gdal_translate_variants_match_gdal() {
    let tmp = TempDir::new("dem-variants");
    let int16 = shared("srtm_ref");
    let float32 = shared("elevation_dsm");
    let float64 = shared("codem");
    let variants: Vec<(&str, &Path, Vec<&str>)> = vec![
        (
            "lzw_pred2.tif",
            &int16,
            vec!["-co", "COMPRESS=LZW", "-co", "PREDICTOR=2"],
        ),
        (
            "deflate_tiled_pred2.tif",
            &int16,
            vec![
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "TILED=YES",
                "-co",
                "PREDICTOR=2",
                "-co",
                "BLOCKXSIZE=128",
                "-co",
                "BLOCKYSIZE=96",
            ],
        ),
        (
            "packbits_tiled.tif",
            &int16,
            vec!["-co", "COMPRESS=PACKBITS", "-co", "TILED=YES"],
        ),
        (
            "bigtiff_lzw_tiled.tif",
            &int16,
            vec![
                "-co",
                "BIGTIFF=YES",
                "-co",
                "TILED=YES",
                "-co",
                "COMPRESS=LZW",
            ],
        ),
        (
            "bigendian.tif",
            &int16,
            vec![
                "-co",
                "ENDIANNESS=BIG",
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "PREDICTOR=2",
            ],
        ),
        (
            "int32.tif",
            &int16,
            vec!["-ot", "Int32", "-co", "COMPRESS=LZW", "-co", "PREDICTOR=2"],
        ),
        ("uint16.tif", &int16, vec!["-ot", "UInt16"]),
        (
            "uint8.tif",
            &int16,
            vec![
                "-ot",
                "Byte",
                "-scale",
                "0",
                "4000",
                "1",
                "255",
                "-co",
                "COMPRESS=DEFLATE",
            ],
        ),
        (
            "float64_from_int16.tif",
            &int16,
            vec!["-ot", "Float64", "-co", "TILED=YES"],
        ),
        ("point.tif", &int16, vec!["-mo", "AREA_OR_POINT=Point"]),
        (
            "f32_lzw_pred3_tiled.tif",
            &float32,
            vec![
                "-co",
                "COMPRESS=LZW",
                "-co",
                "PREDICTOR=3",
                "-co",
                "TILED=YES",
            ],
        ),
        (
            "f32_deflate_pred2.tif",
            &float32,
            vec!["-co", "COMPRESS=DEFLATE", "-co", "PREDICTOR=2"],
        ),
        ("f32_nan_nodata.tif", &float32, vec!["-a_nodata", "nan"]),
        (
            "f32_big_pred3.tif",
            &float32,
            vec![
                "-co",
                "ENDIANNESS=BIG",
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "PREDICTOR=3",
            ],
        ),
        (
            "f32_point_tiled.tif",
            &float32,
            vec![
                "-mo",
                "AREA_OR_POINT=Point",
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=64",
                "-co",
                "BLOCKYSIZE=32",
            ],
        ),
        (
            "f64_deflate_pred3.tif",
            &float64,
            vec!["-co", "COMPRESS=DEFLATE", "-co", "PREDICTOR=3"],
        ),
        (
            "f64_packbits_bigtiff.tif",
            &float64,
            vec!["-co", "COMPRESS=PACKBITS", "-co", "BIGTIFF=YES"],
        ),
        (
            "f32_from_f64.tif",
            &float64,
            vec!["-ot", "Float32", "-a_nodata", "-3.4028234663852886e+38"],
        ),
        // Integer rasters where about one cell in ten is nodata.
        (
            "int16_nodata_hits.tif",
            &int16,
            vec![
                "-scale",
                "1111",
                "3270",
                "-5",
                "5",
                "-a_nodata",
                "0",
                "-co",
                "COMPRESS=LZW",
                "-co",
                "TILED=YES",
            ],
        ),
        (
            "uint8_nodata_hits.tif",
            &int16,
            vec![
                "-ot",
                "Byte",
                "-scale",
                "1111",
                "3270",
                "0",
                "20",
                "-a_nodata",
                "5",
            ],
        ),
        (
            "int_grid_nodata.asc",
            &int16,
            vec![
                "-of",
                "AAIGrid",
                "-scale",
                "1111",
                "3270",
                "-5",
                "5",
                "-a_nodata",
                "0",
                "-srcwin",
                "0",
                "0",
                "200",
                "150",
            ],
        ),
        (
            "int_grid.asc",
            &int16,
            vec!["-of", "AAIGrid", "-srcwin", "100", "200", "300", "250"],
        ),
        ("float_grid.asc", &float32, vec!["-of", "AAIGrid"]),
    ];
    for (name, src, args) in &variants {
        let out = tmp.path(name);
        translate(src, &out, args);
        // The CRS to give an ASCII grid: its source's.
        let crs = if *src == int16 {
            4326
        } else if *src == float32 {
            26918
        } else {
            32616
        };
        compare_with_gdal(&out, crs);
    }

    // SRTM .hgt: warp the Copernicus tile onto the 3" SRTM grid of N45E005.
    let warped = tmp.path("warped.tif");
    run(Command::new("gdalwarp")
        .args([
            "-q",
            "-overwrite",
            "-r",
            "near",
            "-ts",
            "1201",
            "1201",
            "-te",
        ])
        .args([
            "4.999583333333333",
            "44.99958333333333",
            "6.000416666666667",
            "46.00041666666667",
        ])
        .arg(shared("Copernicus"))
        .arg(&warped)
        .stderr(Stdio::null()));
    let hgt = tmp.path("N45E005.hgt");
    translate(&warped, &hgt, &["-of", "SRTMHGT"]);
    let dem = compare_with_gdal(&hgt, 4326);
    assert_eq!(dem.format, planner_core::terrain::DemFormat::Hgt);

    // A rotated ModelTransformation (GDAL writes one for a rotated
    // geotransform), as PixelIsArea and as PixelIsPoint (GDAL shifts the
    // matrix by half a pixel too).
    for raster_type in ["Area", "Point"] {
        let rotated = tmp.path(&format!("rotated_{raster_type}.tif"));
        run(Command::new(python())
            .arg("-c")
            .arg(
                r#"
import math, sys
from osgeo import gdal
gdal.UseExceptions()
src = gdal.Open(sys.argv[1])
ds = gdal.GetDriverByName('GTiff').CreateCopy(sys.argv[2], src, options=['COMPRESS=LZW'])
ds.SetMetadataItem('AREA_OR_POINT', sys.argv[3])
a = math.radians(20)
x, dx, _, y, _, dy = src.GetGeoTransform()
ds.SetGeoTransform([x, dx * math.cos(a), dx * math.sin(a), y, dx * math.sin(a), dy * math.cos(a)])
ds = None
"#,
            )
            .arg(&float32)
            .arg(&rotated)
            .arg(raster_type));
        let dem = compare_with_gdal(&rotated, 4326);
        assert!(dem.transform.row_rotation != 0.0 && dem.transform.col_rotation != 0.0);
    }
}

#[test]
fn non_dem_tiffs_are_rejected_by_name() {
    let tmp = TempDir::new("dem-rejects");
    let int16 = shared("srtm_ref");
    let cases: Vec<(&str, Vec<&str>, &str)> = vec![
        (
            "two_bands.tif",
            vec!["-b", "1", "-b", "1"],
            "SamplesPerPixel=2",
        ),
        (
            "jpeg.tif",
            vec!["-ot", "Byte", "-co", "COMPRESS=JPEG"],
            "JPEG",
        ),
        ("zstd.tif", vec!["-co", "COMPRESS=ZSTD"], "ZSTD"),
        (
            "lerc.tif",
            vec!["-ot", "Float32", "-co", "COMPRESS=LERC"],
            "LERC",
        ),
        ("cint16.tif", vec!["-ot", "CInt16"], "complex"),
    ];
    let limits = DemLimits::default();
    for (name, args, needle) in cases {
        let out = tmp.path(name);
        translate(&int16, &out, &args);
        let bytes = std::fs::read(&out).unwrap();
        let e = read_dem(&bytes, Some(name), None, &limits).unwrap_err();
        assert!(
            matches!(e, TerrainError::Unsupported(_)) && e.to_string().contains(needle),
            "{name}: {e:?}"
        );
    }
    // A truncated copy: an error that says so, not a panic.
    let bytes = std::fs::read(&int16).unwrap();
    for cut in [bytes.len() / 2, bytes.len() - 100] {
        let e = read_dem(&bytes[..cut], None, None, &limits).unwrap_err();
        assert!(e.to_string().contains("truncated"), "cut at {cut}: {e}");
    }
}
