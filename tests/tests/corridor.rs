//! Corridor surveys (`corridor` + `corridor_width_m` instead of `roi`) end
//! to end, through the CLI and the service, along real lines made from the
//! shared data, checked by tests/validators/check_corridor.py (shapely's
//! own flat-capped buffer of the line, pymavlink, pyproj), check_missions.py
//! (pymavlink, MAVProxy, MAVSDK) and, over the DTM, check_terrain.py (GDAL).
//!
//! The lines (provenance):
//! - `field_edge_line`: the west and south edges of the Fields2Cover test
//!   parcel (`polygons/fields2cover__test.json`, boundary vertices 0–10, a
//!   field edge in the Netherlands with a bend of about 80°), with two
//!   rectangular no-fly zones drawn across it here;
//! - `building_line`: the line through the centroids of five buildings of
//!   `polygons/opengeos__elevation_buildings.geojson` (features 46, 29, 58,
//!   74, 26, west to east across Alexandria's DTM), with all 84 building
//!   footprints as no-fly zones, so the ones at the line's vertices cut the
//!   corridor across; flown over `dems/opengeos_data__elevation_dtm.tif`.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, SurveyArea, SurveyFiles, assert_invalid_at, check_missions, check_terrain, get,
    post_json, shared_data, survey_cli, terraplan, text, validator, write_json,
};

fn read(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn rect(cx: f64, cy: f64, hx: f64, hy: f64) -> Value {
    let (x0, y0, x1, y1) = (cx - hx, cy - hy, cx + hx, cy + hy);
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

/// The parcel's west and south edges, as a GeoJSON Feature.
fn field_edge_line() -> Value {
    let parcel = read(&shared_data("polygons/fields2cover__test.json"));
    let ring = parcel["features"][0]["geometry"]["coordinates"][0]
        .as_array()
        .unwrap();
    let line: Vec<Value> = ring[..=10].iter().map(|c| json!([c[0], c[1]])).collect();
    json!({"type": "Feature", "properties": {"source": "fields2cover__test.json, boundary vertices 0-10"},
           "geometry": {"type": "LineString", "coordinates": line}})
}

/// Two zones across the field edge: one across its west leg, one across
/// its south leg.
fn field_edge_zones() -> [Value; 2] {
    [
        rect(6.06225, 51.51190, 0.0005, 0.00006),
        rect(6.0640, 51.51137, 0.00012, 0.0004),
    ]
}

/// The line through the centroids of five buildings (see the module doc).
fn building_line() -> Value {
    let b = read(&shared_data(
        "polygons/opengeos__elevation_buildings.geojson",
    ));
    let line: Vec<Value> = [46usize, 29, 58, 74, 26]
        .iter()
        .map(|&i| {
            let ring = b["features"][i]["geometry"]["coordinates"][0][0]
                .as_array()
                .unwrap();
            // The vertex mean of the outer ring: inside these small convex
            // footprints, and close to their centroid.
            let n = (ring.len() - 1) as f64;
            let (sx, sy) = ring[..ring.len() - 1].iter().fold((0.0, 0.0), |(x, y), c| {
                (x + c[0].as_f64().unwrap(), y + c[1].as_f64().unwrap())
            });
            json!([sx / n, sy / n])
        })
        .collect();
    json!({"type": "LineString", "coordinates": line})
}

/// `terraplan survey --corridor`; returns (plan.json, check_corridor's summary).
fn plan_corridor(
    dir: &Path,
    line: &Value,
    zones: &[PathBuf],
    params: &Value,
    dem: Option<&Path>,
) -> (PathBuf, Value, Value) {
    let line_path = write_json(dir, "line.geojson", line);
    let params_path = write_json(dir, "params.json", params);
    let out = dir.join("out");
    let zones: Vec<&Path> = zones.iter().map(PathBuf::as_path).collect();
    let files = SurveyFiles {
        area: SurveyArea::Corridor(&line_path),
        no_fly: &zones,
        dem,
        params: &params_path,
    };
    let plan = survey_cli(&files, &out, "corridor");
    let width = params["corridor_width_m"].to_string();
    let mut vargs: Vec<&Path> = vec![&out, &line_path, Path::new(&width)];
    vargs.extend(zones);
    let v = validator("check_corridor.py", &vargs);
    assert!(
        v.status.success(),
        "check_corridor.py: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    (out, plan, serde_json::from_slice(&v.stdout).unwrap())
}

#[test]
fn cli_corridor_along_a_field_edge_across_two_zones() {
    let dir = tempfile::tempdir().unwrap();
    let zones: Vec<PathBuf> = field_edge_zones()
        .iter()
        .enumerate()
        .map(|(i, z)| write_json(dir.path(), &format!("nfz{i}.geojson"), z))
        .collect();
    let params = json!({"corridor_width_m": 120, "altitude_m": 35,
        "uavs": [{"id": "a", "start": [6.0619, 51.5124]}, {"id": "b", "start": [6.0655, 51.5116]}]});
    let (out, plan, summary) = plan_corridor(dir.path(), &field_edge_line(), &zones, &params, None);
    let s = &plan["stats"];
    // 120 m at a spacing of 15.75 m: 8 lanes, cut by both zones into more
    // than one cell each side.
    assert!(s["cell_count"].as_u64().unwrap() >= 3, "{s}");
    assert!(summary["photo_coverage"].as_f64().unwrap() >= 0.995);
    assert!(summary["min_nfz_distance_m"].as_f64().unwrap() >= 5.0 - 0.01);
    // The flock shares the corridor: both UAVs fly lanes.
    for uav in plan["uavs"].as_array().unwrap() {
        assert!(
            uav["stats"]["survey_length_m"].as_f64().unwrap() > 100.0,
            "{uav}"
        );
    }
    check_missions(&out);

    // No zones and three UAVs: one cell, cut into pieces for them.
    let dir = tempfile::tempdir().unwrap();
    let params = json!({"corridor_width_m": 60, "altitude_m": 40, "uavs": [
        {"id": "a", "start": [6.0619, 51.5124]}, {"id": "b", "start": [6.0655, 51.5116]},
        {"id": "c", "start": [6.0628, 51.5111]}]});
    let (_, plan, summary) = plan_corridor(dir.path(), &field_edge_line(), &[], &params, None);
    assert_eq!(plan["stats"]["cell_count"], 1);
    assert!(summary["photo_coverage"].as_f64().unwrap() >= 0.995);
    for uav in plan["uavs"].as_array().unwrap() {
        assert!(!uav["pieces"].as_array().unwrap().is_empty(), "{uav}");
    }
}

/// Planes along the field edge across its two zones: each bend of the
/// line rounded on an arc of the turn radius with the camera off (the
/// lanes' legs are entered and left straight), lane ends pulled back from
/// the zones so the plane can turn before them. check_corridor.py (lanes
/// in the corridor along the line, clearance, photos covering >= 99.5 %
/// of the corridor minus the zones, the plan's swath figure) and
/// check_aircraft.py (turn rule at every waypoint, the rounded path's
/// clearance and fence, climbs, camera on straight lanes only) pass for a
/// fixed wing through the CLI; the service plans a VTOL's as the CLI does.
#[test]
fn planes_along_the_field_edge_across_two_zones() {
    let dir = tempfile::tempdir().unwrap();
    let zones: Vec<PathBuf> = field_edge_zones()
        .iter()
        .enumerate()
        .map(|(i, z)| write_json(dir.path(), &format!("nfz{i}.geojson"), z))
        .collect();
    let params = json!({"corridor_width_m": 120, "altitude_m": 100,
        "aircraft": {"type": "fixed_wing", "turn_radius_m": 30}});
    let (out, plan, summary) = plan_corridor(dir.path(), &field_edge_line(), &zones, &params, None);
    assert!(
        summary["photo_coverage"].as_f64().unwrap() >= 0.995,
        "{summary}"
    );
    let line_path = dir.path().join("line.geojson");
    let mut args: Vec<PathBuf> = vec![out.clone(), line_path];
    args.extend(zones.iter().cloned());
    for (k, v) in [
        ("--corridor-width", "120"),
        ("--type", "fixed_wing"),
        ("--radius", "30"),
        ("--climb", "10"),
        ("--clearance", "5"),
        ("--lead-in", "30"),
        ("--altitude", "100"),
    ] {
        args.push(PathBuf::from(k));
        args.push(PathBuf::from(v));
    }
    let refs: Vec<&Path> = args.iter().map(PathBuf::as_path).collect();
    let v = validator("check_aircraft.py", &refs);
    assert!(
        v.status.success(),
        "check_aircraft.py: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    let checked: Value = serde_json::from_slice(&v.stdout).unwrap();
    assert!(
        checked["footprint_coverage"].as_f64().unwrap() >= 0.995,
        "{checked}"
    );
    // The lines' bends are flown round: more camera stretches than lanes
    // across (3), each cut by the zones and at the 80° bend.
    assert!(
        plan["stats"]["lane_count"].as_u64().unwrap() >= 9,
        "{}",
        plan["stats"]
    );
    // The lanes swept with flat ends leave the ends pulled back from the
    // zones and the bends out (measured: 72.6 %), which a warning says.
    let ratio = plan["stats"]["coverage_ratio"].as_f64().unwrap();
    assert!(ratio < 0.995 && ratio > 0.6, "{ratio}");
    assert!(
        plan["warnings"]
            .to_string()
            .contains("lanes the plane flies sweep")
    );
    check_missions(&out);

    // A VTOL through the service: the same plan as the CLI's.
    let mut vtol = params.clone();
    vtol["aircraft"] = json!({"type": "vtol", "turn_radius_m": 30});
    let (_, cli_plan, _) = plan_corridor(dir.path(), &field_edge_line(), &zones, &vtol, None);
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let mut body = vtol.clone();
    body["corridor"] = field_edge_line();
    body["no_fly_zones"] = json!(field_edge_zones());
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    for k in ["lane_count", "photos", "length_m", "coverage_ratio"] {
        assert_eq!(r.json()["stats"][k], cli_plan["stats"][k], "{k}");
    }
}

#[test]
fn cli_corridor_over_the_dtm_between_buildings() {
    let dir = tempfile::tempdir().unwrap();
    let buildings = shared_data("polygons/opengeos__elevation_buildings.geojson");
    let dtm = shared_data("dems/opengeos_data__elevation_dtm.tif");
    let params = json!({"corridor_width_m": 80, "altitude_m": 30, "agl_tolerance_m": 3,
        "transit_clearance_m": 35, "nfz_clearance_m": 3,
        "uavs": [{"id": "a", "start": [-77.0547, 38.8098]}]});
    let (out, plan, summary) = plan_corridor(
        dir.path(),
        &building_line(),
        &[buildings],
        &params,
        Some(&dtm),
    );
    // The buildings at the vertices cut the corridor into many cells.
    assert!(plan["stats"]["cell_count"].as_u64().unwrap() >= 5);
    assert!(summary["min_nfz_distance_m"].as_f64().unwrap() >= 3.0 - 0.01);
    let t = &plan["stats"]["terrain"];
    assert_eq!(t["dem_known_fraction"], 1.0, "{t}");
    let terrain = check_terrain(
        &dtm,
        &out.join("plan.json"),
        "a",
        &[&out.join("a.waypoints"), &out.join("a.route.geojson")],
    );
    // Lanes 30 m above the (dilated) ground, within the 3 m tolerance.
    assert!(
        terrain["lane_min_agl"].as_f64().unwrap() >= 27.0 - 0.01,
        "{terrain}"
    );
    assert_eq!(terrain["lane_within_fraction"], 1.0, "{terrain}");
    check_missions(&out);
}

#[test]
fn service_plans_the_same_corridor_and_names_its_faults() {
    let dir = tempfile::tempdir().unwrap();
    let zones = field_edge_zones();
    let zone_paths: Vec<PathBuf> = zones
        .iter()
        .enumerate()
        .map(|(i, z)| write_json(dir.path(), &format!("nfz{i}.geojson"), z))
        .collect();
    let params = json!({"corridor_width_m": 90, "altitude_m": 40,
        "uavs": [{"id": "a", "start": [6.0619, 51.5124]}]});
    let (_, cli_plan, _) =
        plan_corridor(dir.path(), &field_edge_line(), &zone_paths, &params, None);

    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let url = server.url("/api/v1/surveys");
    let mut body = params.clone();
    body["corridor"] = field_edge_line();
    body["no_fly_zones"] = json!(zones);
    let r = post_json(&url, &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let survey = r.json();
    // The same plan as the CLI's.
    for k in ["cell_count", "lane_count", "photos", "area_m2", "length_m"] {
        assert_eq!(survey["stats"][k], cli_plan["stats"][k], "{k}");
    }
    let sortie = &survey["uavs"][0]["sorties"][0];
    let wp = get(&server.url(sortie["files"]["waypoints"].as_str().unwrap()));
    assert_eq!(wp.status, 200);
    let wp_path = dir.path().join("a.waypoints");
    std::fs::write(&wp_path, &wp.body).unwrap();
    let loaded = validator("load_waypoints.py", &[&wp_path]);
    assert!(loaded.status.success(), "{}", text(&loaded.stderr));

    // The OpenAPI document offers the corridor.
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let text_doc = doc.to_string();
    assert!(text_doc.contains("\"corridor\"") && text_doc.contains("corridor_width_m"));

    // Faults, each at its pointer.
    let roi = rect(6.063, 51.512, 0.001, 0.001);
    let line = field_edge_line();
    let cases = [
        (
            json!({"roi": roi, "corridor": line, "corridor_width_m": 50}),
            "/roi",
            "not both",
        ),
        (
            json!({"roi": roi, "corridor": line, "corridor_width_m": 50}),
            "/corridor",
            "not both",
        ),
        (json!({"altitude_m": 50}), "/roi", "missing"),
        (json!({"altitude_m": 50}), "/corridor", "missing"),
        (json!({"corridor": line}), "/corridor_width_m", "missing"),
        (
            json!({"corridor": line, "corridor_width_m": 0.5}),
            "/corridor_width_m",
            "[1, 2000]",
        ),
        (
            json!({"corridor": line, "corridor_width_m": 3000}),
            "/corridor_width_m",
            "[1, 2000]",
        ),
        (
            json!({"corridor": {"type": "LineString", "coordinates": [[6.06, 51.51], [6.06, 51.51]]},
                   "corridor_width_m": 50}),
            "/corridor/coordinates",
            "1 distinct position",
        ),
        (
            json!({"corridor": {"type": "LineString", "coordinates": [[6.06, 51.51], [6.07, 51.52], [6.07, 51.51], [6.06, 51.52]]},
                   "corridor_width_m": 50}),
            "/corridor/coordinates",
            "crosses itself",
        ),
        (
            json!({"corridor": {"type": "LineString", "coordinates": [[6.06, 51.51], [6.07, 95.0]]},
                   "corridor_width_m": 50}),
            "/corridor/coordinates/1/1",
            "latitude",
        ),
        (
            json!({"corridor": roi, "corridor_width_m": 50}),
            "/corridor/type",
            "not a line",
        ),
        // 55 km long and 2 km wide: over the 100 km² limit.
        (
            json!({"corridor": {"type": "LineString", "coordinates": [[6.1, 51.5], [6.9, 51.5]]},
                   "corridor_width_m": 2000}),
            "/corridor/coordinates",
            "too large",
        ),
    ];
    for (body, pointer, says) in cases {
        let r = post_json(&url, &body);
        assert_invalid_at(&r, &body.to_string(), pointer, says);
    }
}

#[test]
fn cli_refuses_bad_corridors_with_status_2() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path();
    let line = write_json(p, "line.geojson", &field_edge_line());
    let point = write_json(
        p,
        "point.geojson",
        &json!({"type": "LineString", "coordinates": [[6.06, 51.51]]}),
    );
    let roi = write_json(p, "roi.geojson", &rect(6.063, 51.512, 0.001, 0.001));
    let with_width = write_json(p, "params.json", &json!({"corridor_width_m": 50}));
    let without = write_json(p, "bare.json", &json!({}));
    let out = p.join("out");
    let run = |args: &[&Path]| {
        let mut a: Vec<&str> = vec!["survey"];
        let strs: Vec<String> = args.iter().map(|x| x.display().to_string()).collect();
        a.extend(strs.iter().map(String::as_str));
        a.extend(["--out", out.to_str().unwrap()]);
        let o = terraplan(&a);
        (o.status.code(), text(&o.stderr))
    };
    let flag = |s: &'static str| Path::new(s);
    // Both an area and a line.
    let (code, err) = run(&[
        flag("--roi"),
        &roi,
        flag("--corridor"),
        &line,
        flag("--params"),
        &with_width,
    ]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("--corridor") && err.contains("--roi"), "{err}");
    // A line of one position: named in its file.
    let (code, err) = run(&[flag("--corridor"), &point, flag("--params"), &with_width]);
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("point.geojson#/coordinates") && err.contains("distinct position"),
        "{err}"
    );
    // No width.
    let (code, err) = run(&[flag("--corridor"), &line, flag("--params"), &without]);
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("corridor_width_m"), "{err}");
    assert!(!out.join("plan.json").exists());
}
