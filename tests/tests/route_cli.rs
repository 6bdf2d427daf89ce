//! `terraplan route` against the real binary: optimality against
//! scikit-image's MCP_Geometric, the files a rover takes (checked by
//! pymavlink), D* Lite replanning after blocking an area, and exit status 2
//! naming each fault.

use std::path::{Path, PathBuf};
use std::process::Command;

use geo::Intersects;
use geo_types::{Coord, LineString, Polygon};
use serde_json::{Value, json};
use terraplan_e2e::{
    dtm, egm96_undulations, shared_data, terraplan, text, validator, venv_python, workspace,
};

fn mcp(args: &[&str]) -> Value {
    let out = Command::new(venv_python())
        .arg(workspace().join("tests/validators/mcp_route.py"))
        .args(args)
        .output()
        .expect("run mcp_route.py");
    assert!(out.status.success(), "{}", text(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap_or(Value::Null)
}

fn read_json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn utm_arg(v: &Value) -> String {
    format!("utm:{},{}", v[0], v[1])
}

/// Routes on random cost arrays, with and without obstacles, against
/// MCP_Geometric (fully connected, geometric: the `integrated` rule): the
/// same cost to 1e-6 relative without obstacles, never cheaper with them
/// (MCP cuts corners between two obstacle cells; terraplan does not), and
/// there the optimum of an independent Dijkstra with terraplan's rules.
#[test]
fn costs_match_scikit_image_mcp() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    let out = Command::new(venv_python())
        .arg(workspace().join("tests/validators/mcp_route.py"))
        .args([
            "random", d, "--seed", "7", "--count", "12", "--size", "150x110",
        ])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let cases = read_json(&dir.path().join("cases.json"));
    let cases = cases.as_array().unwrap();
    assert_eq!(cases.len(), 12);
    let mut worst_equal: f64 = 0.0;
    let mut dearer = 0;
    for (k, c) in cases.iter().enumerate() {
        let out_dir = dir.path().join(format!("out{k}"));
        let o = terraplan(&[
            "route",
            c["file"].as_str().unwrap(),
            "--from",
            &utm_arg(&c["start_utm"]),
            "--to",
            &utm_arg(&c["goal_utm"]),
            "--no-smooth",
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "case {k}: {}", text(&o.stderr));
        let r = read_json(&out_dir.join("route.json"));
        // The route starts and ends on the requested cells.
        let first = &r["waypoints"][0];
        let last = r["waypoints"].as_array().unwrap().last().unwrap();
        assert_eq!(json!([first["row"], first["col"]]), c["start"], "case {k}");
        assert_eq!(json!([last["row"], last["col"]]), c["goal"], "case {k}");
        let ours = r["path_cost"].as_f64().unwrap();
        let theirs = c["mcp_cost"].as_f64().unwrap();
        let rel = (ours - theirs) / theirs;
        if c["obstacles"].as_bool().unwrap() {
            assert!(rel >= -1e-9, "case {k}: {ours} cheaper than MCP's {theirs}");
            dearer += usize::from(rel > 1e-6);
            // Around obstacles, the optimum of the same rules.
            let cell = |v: &Value| format!("{},{}", v[0], v[1]);
            let file = c["file"].as_str().unwrap();
            let d = mcp(&["dijkstra", file, &cell(&c["start"]), &cell(&c["goal"])]);
            let d = d["cost"].as_f64().unwrap();
            assert!(
                (ours - d).abs() <= 1e-9 * d,
                "case {k}: {ours} vs Dijkstra's {d}"
            );
        } else {
            assert!(rel.abs() <= 1e-6, "case {k}: {ours} vs MCP's {theirs}");
            worst_equal = worst_equal.max(rel.abs());
        }
        // Smoothing (the default) never raises the integrated cost.
        assert!(r["cost"].as_f64().unwrap() <= ours * (1.0 + 1e-9));
    }
    eprintln!(
        "MCP comparison: worst relative difference without obstacles {worst_equal:.2e}; \
         {dearer} of 6 routes with obstacles dearer than MCP's corner-cutting ones"
    );
}

struct DtmCostmap {
    _dir: tempfile::TempDir,
    dir: PathBuf,
    tif: PathBuf,
}

fn dtm_costmap() -> DtmCostmap {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_path_buf();
    let cm = path.join("cm");
    let o = terraplan(&[
        "costmap",
        dtm().to_str().unwrap(),
        "--out",
        cm.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    DtmCostmap {
        _dir: dir,
        dir: path,
        tif: cm.join("costmap.tif"),
    }
}

/// The UTM 18N centre of a cell of the DTM's grid (EPSG:26918, 2 m cells
/// from (321498, 4298018)); NAD83 and WGS84 UTM agree here to PROJ's
/// ballpark transformation.
fn dtm_cell_utm(cell: &Value) -> String {
    let (r, c) = (cell[0].as_f64().unwrap(), cell[1].as_f64().unwrap());
    format!(
        "utm:{},{}",
        321_498.0 + (c + 0.5) * 2.0,
        4_298_018.0 - (r + 0.5) * 2.0
    )
}

/// Corner to corner of the DTM's largest traversable region: the files,
/// the figures, pymavlink reading the rover mission, the optimum of an
/// independent Dijkstra (Python), MCP never dearer, and
/// a D* Lite replan after blocking 20 m of the route equal to a search
/// from scratch and clear of the blocked area.
#[test]
fn dtm_route_files_and_replan() {
    let cm = dtm_costmap();
    let picked = mcp(&["pick", cm.tif.to_str().unwrap()]);
    let out = cm.dir.join("route");
    let from = dtm_cell_utm(&picked["start"]);
    let to = dtm_cell_utm(&picked["goal"]);
    let o = terraplan(&[
        "route",
        cm.tif.to_str().unwrap(),
        "--from",
        &from,
        "--to",
        &to,
        "--dem",
        dtm().to_str().unwrap(),
        "--speed",
        "1.5",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).starts_with("route "), "{}", text(&o.stdout));
    let r = read_json(&out.join("route.json"));
    let wps = r["waypoints"].as_array().unwrap();
    assert!(wps.len() >= 2);
    assert_eq!(r["utm_zone"], "18N");
    assert_eq!(r["utm_epsg"], 32618);
    let (l2, l3) = (
        r["length_2d_m"].as_f64().unwrap(),
        r["length_3d_m"].as_f64().unwrap(),
    );
    let (s, g) = (&wps[0], wps.last().unwrap());
    let straight = (g["easting"].as_f64().unwrap() - s["easting"].as_f64().unwrap())
        .hypot(g["northing"].as_f64().unwrap() - s["northing"].as_f64().unwrap());
    assert!(l2 >= straight - 1e-6 && l3 >= l2, "{straight} {l2} {l3}");
    // Costs are ≥ 1 per metre; the smoothed line is not dearer than the
    // cell path.
    let (cost, path_cost) = (
        r["cost"].as_f64().unwrap(),
        r["path_cost"].as_f64().unwrap(),
    );
    assert!(cost >= l2 * (1.0 - 1e-9) && cost <= path_cost * (1.0 + 1e-9));
    let max_slope = r["max_slope_deg"].as_f64().unwrap();
    let mean_slope = r["mean_slope_deg"].as_f64().unwrap();
    assert!((0.0..90.0).contains(&max_slope) && mean_slope <= max_slope);
    assert!(wps.iter().all(|w| w["height_m"].is_number()));

    // MCP on the same band: never dearer than terraplan's optimum.
    let cell = |v: &Value| format!("{},{}", v[0], v[1]);
    let theirs = mcp(&[
        "cost",
        cm.tif.to_str().unwrap(),
        &cell(&picked["start"]),
        &cell(&picked["goal"]),
    ]);
    let theirs = theirs["cost"].as_f64().unwrap();
    assert!(
        theirs <= path_cost * (1.0 + 1e-9),
        "{theirs} vs {path_cost}"
    );
    assert!(path_cost <= theirs * 1.10, "{path_cost} vs MCP {theirs}");
    // An independent Dijkstra with terraplan's rules: the same optimum.
    let dijkstra = mcp(&[
        "dijkstra",
        cm.tif.to_str().unwrap(),
        &cell(&picked["start"]),
        &cell(&picked["goal"]),
    ]);
    let dijkstra = dijkstra["cost"].as_f64().unwrap();
    assert!(
        (path_cost - dijkstra).abs() <= 1e-9 * dijkstra,
        "{path_cost} vs Dijkstra's {dijkstra}"
    );

    // GeoJSON: a FeatureCollection, heights above the WGS 84 ellipsoid (the
    // terrain's plus the EGM96 undulation, which PROJ gives independently).
    let gj = read_json(&out.join("route.geojson"));
    assert_eq!(gj["type"], "FeatureCollection");
    let feature = &gj["features"][0];
    assert_eq!(feature["geometry"]["type"], "LineString");
    let coords = feature["geometry"]["coordinates"].as_array().unwrap();
    assert_eq!(coords.len(), wps.len());
    let points: Vec<[f64; 2]> = wps
        .iter()
        .map(|p| [p["lon"].as_f64().unwrap(), p["lat"].as_f64().unwrap()])
        .collect();
    for ((c, p), n) in coords.iter().zip(wps).zip(egm96_undulations(&points)) {
        assert_eq!(c.as_array().unwrap().len(), 3, "{c}");
        let above = c[2].as_f64().unwrap() - p["height_m"].as_f64().unwrap();
        assert!((above - n).abs() <= 0.5, "{c}: {above} vs EGM96 (PROJ) {n}");
    }
    // CSV of UTM waypoints.
    let csv = std::fs::read_to_string(out.join("route.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], "index,easting,northing,zone,height");
    assert_eq!(rows.len(), wps.len() + 1);
    let cols: Vec<&str> = rows[1].split(',').collect();
    assert_eq!(cols[3], "18N");
    assert!((cols[1].parse::<f64>().unwrap() - s["easting"].as_f64().unwrap()).abs() < 1e-3);

    // pymavlink: home at the start, a speed change, then the waypoints to
    // the goal.
    let wp = validator("load_waypoints.py", &[&out.join("mission.waypoints")]);
    assert!(wp.status.success(), "{}", text(&wp.stderr));
    let loaded: Value = serde_json::from_slice(&wp.stdout).unwrap();
    let items = loaded["items"].as_array().unwrap();
    assert_eq!(loaded["count"].as_u64().unwrap() as usize, wps.len() + 1);
    assert_eq!(items[1]["command"], 178);
    assert!((items[1]["params"][1].as_f64().unwrap() - 1.5).abs() < 1e-6);
    let near = |item: &Value, w: &Value| {
        (item["lat"].as_f64().unwrap() - w["lat"].as_f64().unwrap()).abs() < 1e-7
            && (item["lon"].as_f64().unwrap() - w["lon"].as_f64().unwrap()).abs() < 1e-7
    };
    assert!(near(&items[0], s) && near(items.last().unwrap(), g));
    assert!(items[2..].iter().all(|i| i["command"] == 16));

    // Block 20 m of the route around its middle waypoint segment: a
    // 20 m × 6 m box across the line.
    let mid = wps.len() / 2;
    let (a, b) = (&wps[mid - 1], &wps[mid]);
    let (lon, lat) = (
        (a["lon"].as_f64().unwrap() + b["lon"].as_f64().unwrap()) / 2.0,
        (a["lat"].as_f64().unwrap() + b["lat"].as_f64().unwrap()) / 2.0,
    );
    // About 10 m in degrees at 38.8°N.
    let (dlon, dlat) = (10.0 / 86_800.0, 10.0 / 111_000.0);
    let ring = vec![
        Coord {
            x: lon - dlon,
            y: lat - dlat,
        },
        Coord {
            x: lon + dlon,
            y: lat - dlat,
        },
        Coord {
            x: lon + dlon,
            y: lat + dlat,
        },
        Coord {
            x: lon - dlon,
            y: lat + dlat,
        },
        Coord {
            x: lon - dlon,
            y: lat - dlat,
        },
    ];
    let area = Polygon::new(LineString(ring.clone()), vec![]);
    let coords: Vec<[f64; 2]> = ring.iter().map(|c| [c.x, c.y]).collect();
    let block = cm.dir.join("block.geojson");
    std::fs::write(
        &block,
        json!({"type": "Polygon", "coordinates": [coords]}).to_string(),
    )
    .unwrap();
    let o = terraplan(&[
        "route",
        cm.tif.to_str().unwrap(),
        "--from",
        &from,
        "--to",
        &to,
        "--dem",
        dtm().to_str().unwrap(),
        "--block",
        block.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    if !o.status.success() {
        // Blocking may cut the region in two: then it says so, exit 2.
        assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
        assert!(
            text(&o.stderr).contains("cannot be reached"),
            "{}",
            text(&o.stderr)
        );
        eprintln!("the block cut the region in two: {}", text(&o.stderr));
        return;
    }
    let t = read_json(&out.join("replanned/timing.json"));
    eprintln!("replan after blocking 20 m: {t}");
    assert!(t["blocked_cells"].as_u64().unwrap() >= 50, "{t}");
    let replan = t["dstar_lite"]["replan_cost"].as_f64().unwrap();
    let scratch = t["astar_from_scratch"]["cost"].as_f64().unwrap();
    assert!((replan - scratch).abs() <= 1e-9 * scratch, "{t}");
    assert!(replan >= path_cost * (1.0 - 1e-9), "{t}");
    let nr = read_json(&out.join("replanned/route.json"));
    let line: LineString<f64> = nr["waypoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| Coord {
            x: w["lon"].as_f64().unwrap(),
            y: w["lat"].as_f64().unwrap(),
        })
        .collect();
    assert!(
        !line.intersects(&area),
        "the replanned route crosses the blocked area"
    );
    let old: LineString<f64> = wps
        .iter()
        .map(|w| Coord {
            x: w["lon"].as_f64().unwrap(),
            y: w["lat"].as_f64().unwrap(),
        })
        .collect();
    assert!(
        old.intersects(&area),
        "the block did not cut the first route"
    );
}

/// Faults exit with status 2 and a message naming them.
#[test]
fn route_faults_exit_2() {
    let cm = dtm_costmap();
    let tif = cm.tif.to_str().unwrap();
    let out = cm.dir.join("bad");
    let out = out.to_str().unwrap();
    let picked = mcp(&["pick", tif]);
    let (from, to) = (
        dtm_cell_utm(&picked["start"]),
        dtm_cell_utm(&picked["goal"]),
    );
    let fails = |args: &[String], says: &str| {
        let o = terraplan(&args.iter().map(String::as_str).collect::<Vec<_>>());
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
        let err = text(&o.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    };
    let route = |from: &str, to: &str| -> Vec<String> {
        ["route", tif, "--from", from, "--to", to, "--out", out]
            .map(String::from)
            .to_vec()
    };
    fails(&route("utm:300000,4298000", &to), "--from: the start");
    fails(&route(&from, "-77.2,38.81"), "--to: the goal");
    fails(&route("1,2,3", &to), "two numbers");
    fails(&route("abc,1", &to), "not a finite number");
    fails(&route(&from, "-77,95"), "[-180, 180]");
    // A step cell of the costmap (class 3).
    fails(&route(&dtm_cell_utm(&picked["step"]), &to), "a step higher");
    let mut a = route(&from, &to);
    a.extend(["--epsilon".into(), "0.5".into()]);
    fails(&a, "epsilon");
    let mut a = route(&from, &to);
    a.extend(["--arc-cost".into(), "cheapest".into()]);
    fails(&a, "--arc-cost");
    // A DEM is not a costmap (one band).
    let dem = dtm();
    let mut a = route(&from, &to);
    a[1] = dem.to_str().unwrap().into();
    fails(&a, "band");
    // Another DEM is not the costmap's.
    let other = shared_data("dems/demcompare__srtm_ref.tif");
    let mut a = route(&from, &to);
    a.extend(["--dem".into(), other.to_str().unwrap().into()]);
    fails(&a, "--dem");
    // Unreachable: from a traversable cell outside the goal's region.
    fails(
        &route(&dtm_cell_utm(&picked["island"]), &to),
        "cannot be reached",
    );
}

/// `--block` with an area over the replan's start or over the goal: the
/// service's replanning rules refuse it, exit 2 naming the flag or file.
#[test]
fn blocking_an_end_exits_2() {
    let cm = dtm_costmap();
    let tif = cm.tif.to_str().unwrap();
    let picked = mcp(&["pick", tif]);
    let (from, to) = (
        dtm_cell_utm(&picked["start"]),
        dtm_cell_utm(&picked["goal"]),
    );
    let out = cm.dir.join("ends");
    let out = out.to_str().unwrap();
    let o = terraplan(&["route", tif, "--from", &from, "--to", &to, "--out", out]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let r = read_json(&Path::new(out).join("route.json"));
    let wps = r["waypoints"].as_array().unwrap();
    let lonlat = |w: &Value| [w["lon"].as_f64().unwrap(), w["lat"].as_f64().unwrap()];
    // A square of about 6 m around a point, at 38.8°N.
    let square = |name: &str, [lon, lat]: [f64; 2]| -> PathBuf {
        let (dlon, dlat) = (3.0 / 86_800.0, 3.0 / 111_000.0);
        let ring = [
            [lon - dlon, lat - dlat],
            [lon + dlon, lat - dlat],
            [lon + dlon, lat + dlat],
            [lon - dlon, lat + dlat],
            [lon - dlon, lat - dlat],
        ];
        let path = cm.dir.join(name);
        std::fs::write(
            &path,
            json!({"type": "Polygon", "coordinates": [ring]}).to_string(),
        )
        .unwrap();
        path
    };
    let at_start = square("start.geojson", lonlat(&wps[0]));
    let at_goal = square("goal.geojson", lonlat(wps.last().unwrap()));
    let fails = |block: &Path, says: &str| {
        let b = block.to_str().unwrap();
        let args = [
            "route", tif, "--from", &from, "--to", &to, "--block", b, "--out", out,
        ];
        let o = terraplan(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
        let err = text(&o.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    };
    fails(
        &at_start,
        "--from: the position is inside an area this replan blocks",
    );
    fails(
        &at_goal,
        &format!(
            "--block {}: this area covers the route's goal",
            at_goal.display()
        ),
    );
    assert!(
        !Path::new(out).join("replanned").exists(),
        "a refused replan wrote files"
    );
}
