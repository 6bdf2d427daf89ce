//! `terraplan costmap` checked by GDAL over the real bare-earth DEMs of
//! `../shared/data/dems`: tests/validators/check_costmap_gdal.py compares
//! terraplan's slope layer with `gdaldem slope` (Horn; `-s 111120` for
//! geographic DEMs) — RMS, mean difference and agreement of the slope-only
//! obstacle mask — and reads costmap.tif back with GDAL (its two pages,
//! the Float32 cost and the Byte class; each band's description, data
//! type, unit type and nodata through osgeo.gdal and `gdalinfo -json`, also
//! the slope layer's; geotransform, CRS, `gdallocationinfo` against
//! ReadAsArray, cost NaN exactly where the class is not traversable). Run
//! with `--nocapture` to see the figures per DEM.

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use terraplan_e2e::{GDAL_PYTHON, shared_data, terraplan, text, workspace};

/// Build the costmap of `dem` with its slope layer, validate it with GDAL
/// and return the validator's figures.
fn costmap_against_gdaldem(dem: &str) -> Value {
    let dem_path = shared_data(dem);
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    let out = terraplan(&[
        "costmap",
        dem_path.to_str().unwrap(),
        "--layers",
        "slope",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "terraplan costmap {dem}: {}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    for f in [
        "costmap.tif",
        "preview.png",
        "legend.svg",
        "stats.json",
        "layers/slope.tif",
    ] {
        assert!(out_dir.join(f).is_file(), "{dem}: {f} was not written");
    }
    let figures = validate(&dem_path, &out_dir);
    println!(
        "{dem}: slope vs gdaldem over {} cells: RMS {:.2}°, mean difference {:+.2}°, \
         obstacle mask (≥ 25°) agreement {:.1} %; costmap.tif: {} gdallocationinfo \
         probes agree, traversable {:.1} %",
        figures["cells"],
        figures["rms_deg"].as_f64().unwrap(),
        figures["mean_diff_deg"].as_f64().unwrap(),
        figures["agree_pct"].as_f64().unwrap(),
        figures["locations_checked"],
        figures["traversable_pct"].as_f64().unwrap(),
    );
    println!("{dem}: {figures}");
    figures
}

/// Run check_costmap_gdal.py with its default thresholds (RMS ≤ 3°,
/// agreement ≥ 95 %, max slope 25°).
fn validate(dem: &Path, out_dir: &Path) -> Value {
    let out = Command::new(GDAL_PYTHON)
        .arg(workspace().join("tests/validators/check_costmap_gdal.py"))
        .arg(dem)
        .arg(out_dir)
        .output()
        .expect("run check_costmap_gdal.py");
    assert!(
        out.status.success(),
        "check_costmap_gdal.py on {}: {}{}",
        dem.display(),
        text(&out.stdout),
        text(&out.stderr)
    );
    let figures: Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("validator output is not JSON ({e}): {}", text(&out.stdout)));
    assert_eq!(figures["ok"], true, "{figures}");
    figures
}

/// The comparison covered most of the interior (a 2-cell border is left
/// out), so the figures are not those of a few stray cells.
fn assert_covers_interior(figures: &Value) {
    let size = figures["size"].as_array().unwrap();
    let (w, h) = (size[0].as_u64().unwrap(), size[1].as_u64().unwrap());
    let interior = (w - 4) * (h - 4);
    let cells = figures["cells"].as_u64().unwrap();
    assert!(
        cells * 10 >= interior * 9,
        "only {cells} of {interior} interior cells compared: {figures}"
    );
    assert_eq!(figures["locations_checked"], 10, "{figures}");
    assert_eq!(figures["nan_class_mismatches"], 0, "{figures}");
    // Every band was checked for its type and unit ("-": none).
    assert_eq!(
        figures["bands_checked"],
        serde_json::json!([
            "costmap.tif:1:Float32:cost",
            "costmap.tif page 2:1:Byte:-",
            "layers/slope.tif:1:Float32:deg"
        ]),
        "{figures}"
    );
}

/// Lidar DTM, 283 × 259 cells of 2 m, NAD83 / UTM 18N (projected).
#[test]
fn opengeos_dtm_slope_matches_gdaldem() {
    let f = costmap_against_gdaldem("dems/opengeos_data__elevation_dtm.tif");
    assert_eq!(f["geographic"], false);
    assert_covers_interior(&f);
}

/// SRTM, 1000 × 1000 cells of 3″, WGS 84 (geographic).
#[test]
fn srtm_slope_matches_gdaldem() {
    let f = costmap_against_gdaldem("dems/demcompare__srtm_ref.tif");
    assert_eq!(f["geographic"], true);
    assert_covers_interior(&f);
}

/// Copernicus DEM, 500 × 500 cells, WGS 84 (geographic, PixelIsPoint),
/// the Alps.
#[test]
fn copernicus_slope_matches_gdaldem() {
    let f = costmap_against_gdaldem("dems/demcompare__Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    assert_eq!(f["geographic"], true);
    assert_covers_interior(&f);
}
