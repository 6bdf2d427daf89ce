//! Planes (issue 20, aircraft part) end to end: `terraplan survey` and the
//! service with `aircraft` fixed_wing and vtol on real fields with NFZs,
//! each mission checked independently by tests/validators/check_aircraft.py
//! (turn rule at every waypoint, the rounded path's NFZ clearance and
//! fence containment, climb angles, camera off outside straight lanes,
//! photo footprint coverage) and loaded by pymavlink, MAVProxy and MAVSDK
//! (check_missions.py); a multirotor given explicitly plans byte for byte
//! as without the member.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, SurveyArea, SurveyFiles, assert_invalid_at, check_missions, post_json, shared_data,
    survey_cli, terraplan, text, validator, workspace, write_json,
};

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

/// Two NFZs inside the Illinois fields of Fields2Cover's two-cell test
/// (one straddling the cells' shared edge region, one in the south-east).
fn illinois_nfz(dir: &Path) -> PathBuf {
    write_json(
        dir,
        "nfz.geojson",
        &json!({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1375, 41.4710, -90.1365, 41.4717)},
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1315, 41.4650, -90.1280, 41.4660)}
        ]}),
    )
}

/// Plans with the CLI into `dir/out`; returns plan.json.
fn plan_cli(dir: &Path, roi: &Path, nfz: &[&Path], params: &Value) -> (PathBuf, Value) {
    let params_path = write_json(dir, "params.json", params);
    let out = dir.join("out");
    let _ = std::fs::remove_dir_all(&out);
    let files = SurveyFiles {
        area: SurveyArea::Roi(roi),
        no_fly: nfz,
        dem: None,
        params: &params_path,
    };
    let plan = survey_cli(&files, &out, "plan_cli");
    (out, plan)
}

/// check_aircraft.py on `out`; its summary.
#[allow(clippy::too_many_arguments)]
fn check_aircraft(
    out: &Path,
    roi: &Path,
    nfz: &[&Path],
    kind: &str,
    radius: f64,
    climb: f64,
    altitude: f64,
) -> Value {
    let flags = [
        ("--type", kind.to_string()),
        ("--radius", radius.to_string()),
        ("--climb", climb.to_string()),
        ("--clearance", "5".to_string()),
        ("--lead-in", radius.to_string()),
        ("--altitude", altitude.to_string()),
    ];
    check_aircraft_flags(out, roi, nfz, &flags)
}

/// check_aircraft.py on `out` with these flags; its summary.
fn check_aircraft_flags(out: &Path, roi: &Path, nfz: &[&Path], flags: &[(&str, String)]) -> Value {
    let mut args: Vec<PathBuf> = vec![out.to_path_buf(), roi.to_path_buf()];
    args.extend(nfz.iter().map(|p| p.to_path_buf()));
    for (k, v) in flags {
        args.push(PathBuf::from(k));
        args.push(PathBuf::from(v));
    }
    let refs: Vec<&Path> = args.iter().map(PathBuf::as_path).collect();
    let v = validator("check_aircraft.py", &refs);
    assert!(
        v.status.success(),
        "check_aircraft: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).unwrap()
}

/// What every plane's plan must show: the flight time is the flown 3D
/// length at the cruise speed (no turn penalty), the flown length is
/// longer than the lanes, and the camera is on for exactly the lanes.
fn check_figures(plan: &Value, summary: &Value, speed: f64) {
    let uav = &plan["uavs"][0];
    let s = &uav["sorties"][0]["stats"];
    let (len, len3, time) = (
        s["length_m"].as_f64().unwrap(),
        s["length_3d_m"].as_f64().unwrap(),
        s["flight_time_s"].as_f64().unwrap(),
    );
    assert!(
        (time - len3 / speed).abs() < 1e-6,
        "{time} vs {len3}/{speed}"
    );
    assert!(len > s["survey_length_m"].as_f64().unwrap() * 1.05);
    assert_eq!(uav["speed_m_s"], json!(speed));
    let lanes = summary["lanes"].as_u64().unwrap();
    assert!(lanes >= 8, "{summary}");
    // Lead-ins and overshoots are shortened only by no-fly zones.
    for m in summary["missions"].as_object().unwrap().values() {
        let (full, runs) = (
            m["full_runs"].as_f64().unwrap(),
            m["runs"].as_f64().unwrap(),
        );
        assert!(full >= 0.75 * runs, "{m}");
    }
}

#[test]
fn fixed_wing_on_the_illinois_fields_with_nfzs() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test_2_cell.json");
    let nfz = illinois_nfz(dir.path());
    let params = json!({"altitude_m": 100, "side_overlap": 0.6,
                        "aircraft": {"type": "fixed_wing", "turn_radius_m": 40}});
    let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], &params);
    let summary = check_aircraft(&out, &roi, &[&nfz], "fixed_wing", 40.0, 10.0, 100.0);
    assert!(summary["footprint_coverage"].as_f64().unwrap() >= 0.995);
    check_figures(&plan, &summary, 16.0);
    check_missions(&out);
    // The same survey flown by a multirotor: shorter, no arcs.
    let multi = json!({"altitude_m": 100, "side_overlap": 0.6});
    let (_, mplan) = plan_cli(dir.path(), &roi, &[&nfz], &multi);
    let fw_len = plan["stats"]["length_m"].as_f64().unwrap();
    let mr_len = mplan["stats"]["length_m"].as_f64().unwrap();
    assert!(fw_len > mr_len, "{fw_len} vs {mr_len}");
}

/// A wide turn against a narrow footprint: lane ends facing the zones are
/// pulled back so far that the footprints miss part of the free area.
/// plan.json's coverage_ratio and lane_count are those of the lanes flown
/// (check_aircraft.py recomputes both from the mission: within 0.001), not
/// of the lanes planned before (which cover it all), and a warning says so.
#[test]
fn plane_coverage_is_that_of_the_lanes_flown() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test_2_cell.json");
    let nfz = illinois_nfz(dir.path());
    let params = json!({"altitude_m": 40,
                        "aircraft": {"type": "fixed_wing", "turn_radius_m": 60}});
    let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], &params);
    let flags = [
        ("--type", "fixed_wing".to_string()),
        ("--radius", "60".to_string()),
        ("--climb", "10".to_string()),
        ("--clearance", "5".to_string()),
        ("--lead-in", "60".to_string()),
        ("--altitude", "40".to_string()),
        ("--min-coverage", "0.95".to_string()),
    ];
    let summary = check_aircraft_flags(&out, &roi, &[&nfz], &flags);
    let ratio = plan["stats"]["coverage_ratio"].as_f64().unwrap();
    assert!(
        (summary["swath_coverage"].as_f64().unwrap() - ratio).abs() <= 1e-3,
        "{summary}"
    );
    // Measured: 98.2 % flown (the lanes planned cover 100 %).
    assert!(ratio < 0.995 && ratio > 0.95, "{ratio}");
    let warnings = plan["warnings"].to_string();
    assert!(
        warnings.contains("pulled back") && warnings.contains("turn_radius_m = 60 m"),
        "{warnings}"
    );
    // The multirotor's figure is of its lanes as planned: all covered.
    let (_, mplan) = plan_cli(dir.path(), &roi, &[&nfz], &json!({"altitude_m": 40}));
    assert!(mplan["stats"]["coverage_ratio"].as_f64().unwrap() > 0.995);
}

/// Planes fly a crosshatch: both lane sets, each with the plane's
/// lead-ins, overshoots and Dubins turns (set by set, part by part of the
/// second). Every mission passes check_aircraft.py; check_patterns.py
/// finds each set alone covering >= 99.5 % of the free area and the sets
/// 90° ± 1° apart; a VTOL flock in battery sorties too; the service plans
/// the same as the CLI.
#[test]
fn planes_fly_a_crosshatch() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test_2_cell.json");
    let nfz = illinois_nfz(dir.path());
    let cases = [
        (
            "fixed_wing",
            40.0,
            10.0,
            json!({"altitude_m": 100, "side_overlap": 0.6, "pattern": "crosshatch",
                   "aircraft": {"type": "fixed_wing"}}),
        ),
        (
            "vtol",
            60.0,
            8.0,
            json!({"altitude_m": 100, "side_overlap": 0.6, "pattern": "crosshatch",
                   "uavs": [{"id": "a", "start": [-90.1350, 41.4690], "max_flight_time_s": 900},
                            {"id": "b", "start": [-90.1300, 41.4640], "max_flight_time_s": 900}],
                   "aircraft": {"type": "vtol"}}),
        ),
    ];
    for (kind, radius, climb, params) in &cases {
        let (kind, radius, climb) = (*kind, *radius, *climb);
        let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], params);
        let summary = check_aircraft(&out, &roi, &[&nfz], kind, radius, climb, 100.0);
        assert!(
            summary["footprint_coverage"].as_f64().unwrap() >= 0.995,
            "{kind}: {summary}"
        );
        let params_path = write_json(dir.path(), "checked.params.json", params);
        let v = validator(
            "check_patterns.py",
            &[&out, &params_path, &roi, nfz.as_path()],
        );
        assert!(
            v.status.success(),
            "{kind}: check_patterns: {}{}",
            text(&v.stdout),
            text(&v.stderr)
        );
        let p: Value = serde_json::from_slice(&v.stdout).unwrap();
        for set in ["set1", "set2"] {
            assert!(
                p[format!("{set}_lanes")].as_u64().unwrap() >= 5,
                "{kind}: {p}"
            );
            assert!(p[format!("{set}_coverage")].as_f64().unwrap() >= 0.995);
        }
        assert!(p["worst_right_angle_error_deg"].as_f64().unwrap() <= 1.0);
        assert_eq!(p["photos"], plan["stats"]["photos"], "{kind}");
        check_missions(&out);
        if kind == "vtol" {
            assert!(
                plan["stats"]["sorties"].as_u64().unwrap() >= 3,
                "{}",
                plan["stats"]
            );
        }
    }
    // The service plans the fixed wing's crosshatch as the CLI does.
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let mut body = cases[0].3.clone();
    body["roi"] = serde_json::from_str(&std::fs::read_to_string(&roi).unwrap()).unwrap();
    body["no_fly_zones"] = serde_json::from_str::<Value>(&std::fs::read_to_string(&nfz).unwrap())
        .unwrap()["features"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["geometry"].clone())
        .collect();
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let (_, cli) = plan_cli(dir.path(), &roi, &[&nfz], &cases[0].3);
    for k in ["lane_count", "photos", "length_m", "coverage_ratio"] {
        assert_eq!(r.json()["stats"][k], cli["stats"][k], "{k}");
    }
}

/// Battery sorties priced with the plane's turns, climb-out and final:
/// every sortie as flown fits the battery, and each is checked like a
/// whole mission.
#[test]
fn plane_sorties_fit_their_battery() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test_2_cell.json");
    let nfz = illinois_nfz(dir.path());
    let battery = 400.0;
    let params = json!({"altitude_m": 100, "side_overlap": 0.6,
                        "uavs": [{"id": "a", "start": [-90.1350, 41.4690], "max_flight_time_s": battery}],
                        "aircraft": {"type": "fixed_wing"}});
    let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], &params);
    let sorties = plan["uavs"][0]["sorties"].as_array().unwrap();
    assert!(sorties.len() >= 2, "{}", sorties.len());
    for s in sorties {
        let t = s["stats"]["flight_time_s"].as_f64().unwrap();
        assert!(t <= battery, "{}: {t} s", s["file_stem"]);
    }
    // No sortie over its battery. (The lanes flown, pulled back at the
    // zones and cut between sorties, sweep 99.25 % of the free area with
    // flat-ended strips, which a warning says; the photos' footprints,
    // reaching past the lane ends, still see 99.5 %.)
    let warnings = plan["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .all(|w| w.as_str().unwrap().contains("lanes the plane flies sweep")),
        "{warnings:?}"
    );
    let summary = check_aircraft(&out, &roi, &[&nfz], "fixed_wing", 40.0, 10.0, 100.0);
    assert_eq!(
        summary["missions"].as_object().unwrap().len(),
        sorties.len()
    );
    assert!(summary["footprint_coverage"].as_f64().unwrap() >= 0.995);
}

#[test]
fn vtol_on_the_dutch_field_with_its_nfzs() {
    let dir = tempfile::tempdir().unwrap();
    let ex = workspace().join("examples");
    let (roi, nfz) = (ex.join("field.geojson"), ex.join("field-nfz.geojson"));
    let params = json!({"altitude_m": 70, "side_overlap": 0.6,
                        "uavs": [{"id": "q", "start": [6.0620, 51.5110]}],
                        "aircraft": {"type": "vtol", "turn_radius_m": 30, "max_climb_angle_deg": 6}});
    let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], &params);
    let summary = check_aircraft(&out, &roi, &[&nfz], "vtol", 30.0, 6.0, 70.0);
    assert!(summary["footprint_coverage"].as_f64().unwrap() >= 0.995);
    check_figures(&plan, &summary, 20.0);
    check_missions(&out);
}

/// Racetrack order where lanes are closer than two turn radii: fewer
/// metres than flying them in turn with loop turns, and every lane still
/// flown once (the checker sees each lane bracketed by the camera).
#[test]
fn close_lanes_are_flown_skipping() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test.json");
    let params = json!({"altitude_m": 60, "line_spacing_m": 25,
                        "aircraft": {"type": "fixed_wing", "turn_radius_m": 35}});
    let (out, plan) = plan_cli(dir.path(), &roi, &[], &params);
    let summary = check_aircraft(&out, &roi, &[], "fixed_wing", 35.0, 10.0, 60.0);
    assert!(summary["footprint_coverage"].as_f64().unwrap() >= 0.995);
    assert_eq!(
        summary["lanes"].as_u64().unwrap(),
        plan["stats"]["lane_count"].as_u64().unwrap()
    );
}

/// Both planes over the Copernicus DSM (rolling hills west of Grenoble,
/// ~150 m of relief) with an NFZ: climbs and descents within the climb
/// angle along the whole track (relative frame), lanes split into
/// collinear legs that follow the ground, every other check as flat.
#[test]
fn planes_over_a_real_dem() {
    let dir = tempfile::tempdir().unwrap();
    let roi = write_json(
        dir.path(),
        "roi.geojson",
        &rect(5.2950, 45.2960, 5.3080, 45.3030),
    );
    let nfz = write_json(
        dir.path(),
        "nfz.geojson",
        &rect(5.3000, 45.2985, 5.3015, 45.2995),
    );
    let dem = shared_data("dems/demcompare__Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    for (kind, climb) in [("fixed_wing", 10.0), ("vtol", 8.0)] {
        let params = json!({"altitude_m": 100, "side_overlap": 0.6,
                            "uavs": [{"id": "d", "start": [5.2945, 45.2955]}],
                            "aircraft": {"type": kind, "turn_radius_m": 35}});
        let params_path = write_json(dir.path(), "params.json", &params);
        let out = dir.path().join(kind);
        let files = SurveyFiles {
            area: SurveyArea::Roi(&roi),
            no_fly: &[&nfz],
            dem: Some(&dem),
            params: &params_path,
        };
        survey_cli(&files, &out, kind);
        let summary = check_aircraft(&out, &roi, &[&nfz], kind, 35.0, climb, 100.0);
        assert!(summary["footprint_coverage"].as_f64().unwrap() >= 0.995);
        let m = &summary["missions"]["d.waypoints"];
        // The hills make it climb and descend, up to the limit.
        let steepest = m["steepest_deg"].as_f64().unwrap();
        assert!(
            steepest > climb * 0.5 && steepest <= climb + 0.01,
            "{kind}: {steepest}"
        );
        let plan: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
        let s = &plan["uavs"][0]["sorties"][0]["stats"];
        assert!(s["length_3d_m"].as_f64().unwrap() > s["length_m"].as_f64().unwrap());
        check_missions(&out);
    }
}

/// A field as dense with small NFZs as bench-survey-aircraft.sh's 1 000-NFZ
/// input (one zone of 1-4 m every ~57 m, a 5 m clearance), on a 600 m
/// square: no single Dubins path reaches many lane ends, so transits come
/// from the pose-lattice search. Both planes plan, and every mission passes
/// check_aircraft.py (turn rule, rounded path's clearance, lanes entered
/// straight, footprint coverage ≥ 99.5 %).
#[test]
fn planes_on_a_field_dense_with_nfzs() {
    let dir = tempfile::tempdir().unwrap();
    let (lat0, lon0) = (47.0f64, 8.5f64);
    let m_lat = 111_320.0;
    let m_lon = m_lat * lat0.to_radians().cos();
    let ll = |x: f64, y: f64| json!([lon0 + x / m_lon, lat0 + y / m_lat]);
    let roi = write_json(
        dir.path(),
        "roi.geojson",
        &json!({"type": "Polygon", "coordinates": [[ll(-300., -300.), ll(300., -300.),
                 ll(300., 300.), ll(-300., 300.), ll(-300., -300.)]]}),
    );
    // A fixed linear congruential sequence: the same zones every run.
    let mut rng = terraplan_e2e::Lcg(20);
    let mut next = || rng.next_unit();
    let features: Vec<Value> = (0..110)
        .map(|_| {
            let (cx, cy, r) = (
                next() * 540.0 - 270.0,
                next() * 540.0 - 270.0,
                1.0 + 3.0 * next(),
            );
            let ring: Vec<Value> = (0..=6)
                .map(|k| {
                    let a = std::f64::consts::PI * f64::from(k % 6) / 3.0;
                    ll(cx + r * a.cos(), cy + r * a.sin())
                })
                .collect();
            json!({"type": "Feature", "properties": {},
                   "geometry": {"type": "Polygon", "coordinates": [ring]}})
        })
        .collect();
    let nfz = write_json(
        dir.path(),
        "nfz.geojson",
        &json!({"type": "FeatureCollection", "features": features}),
    );
    for (kind, radius, climb) in [("fixed_wing", 40.0, 10.0), ("vtol", 60.0, 8.0)] {
        let params = json!({"altitude_m": 100,
                            "uavs": [{"id": "d", "start": [lon0, lat0 - 400.0 / m_lat]}],
                            "aircraft": {"type": kind}});
        let (out, plan) = plan_cli(dir.path(), &roi, &[&nfz], &params);
        let summary = check_aircraft(&out, &roi, &[&nfz], kind, radius, climb, 100.0);
        assert!(
            summary["footprint_coverage"].as_f64().unwrap() >= 0.995,
            "{kind}: {summary}"
        );
        assert!(
            plan["stats"]["lane_count"].as_u64().unwrap() >= 40,
            "{plan}"
        );
        check_missions(&out);
    }
}

#[test]
fn an_explicit_multirotor_plans_byte_for_byte_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let ex = workspace().join("examples");
    let (roi, nfz) = (ex.join("field.geojson"), ex.join("field-nfz.geojson"));
    let base = json!({"altitude_m": 60, "uavs": [{"id": "m", "start": [6.0620, 51.5110]}]});
    let (out_a, _) = plan_cli(dir.path(), &roi, &[&nfz], &base);
    let kept = dir.path().join("before");
    std::fs::rename(&out_a, &kept).unwrap();
    let mut with = base.clone();
    with["aircraft"] = json!({"type": "multirotor"});
    let (out_b, _) = plan_cli(dir.path(), &roi, &[&nfz], &with);
    let mut names: Vec<_> = std::fs::read_dir(&kept)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert!(names.len() >= 5);
    for n in names {
        let (a, b) = (
            std::fs::read(kept.join(&n)).unwrap(),
            std::fs::read(out_b.join(&n)).unwrap(),
        );
        assert!(a == b, "{n:?} differs");
    }
}

#[test]
fn service_plans_a_fixed_wing_and_names_the_faults() {
    let dir = tempfile::tempdir().unwrap();
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let url = server.url("/api/v1/surveys");
    let field = shared_data("polygons/fields2cover__test.json");
    let roi: Value = serde_json::from_str(&std::fs::read_to_string(&field).unwrap()).unwrap();
    let params = json!({"altitude_m": 80, "aircraft": {"type": "fixed_wing"}});
    let mut body = params.clone();
    body["roi"] = roi.clone();
    let r = post_json(&url, &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let survey = r.json();
    let (_, cli) = plan_cli(dir.path(), &field, &[], &params);
    for k in ["lane_count", "photos", "length_m", "flight_time_s"] {
        assert_eq!(survey["stats"][k], cli["stats"][k], "{k}");
    }
    // Out of range, and plane-only members on a multirotor.
    let cases = [
        (
            json!({"aircraft": {"type": "fixed_wing", "turn_radius_m": 2}}),
            "/aircraft/turn_radius_m",
            "[5, 1000]",
        ),
        (
            json!({"aircraft": {"type": "vtol", "max_climb_angle_deg": 60}}),
            "/aircraft/max_climb_angle_deg",
            "(0, 45]",
        ),
        (
            json!({"aircraft": {"type": "fixed_wing", "cruise_speed_m_s": 0}}),
            "/aircraft/cruise_speed_m_s",
            "(0, 50]",
        ),
        (
            json!({"aircraft": {"type": "multirotor", "turn_radius_m": 30}}),
            "/aircraft/turn_radius_m",
            "only planes",
        ),
        (
            json!({"aircraft": {"type": "glider"}}),
            "/aircraft/type",
            "glider",
        ),
    ];
    for (mut body, pointer, says) in cases {
        body["roi"] = roi.clone();
        let r = post_json(&url, &body);
        assert_invalid_at(&r, &body.to_string(), pointer, says);
    }
    // The CLI refuses the same with exit status 2.
    let bad = write_json(
        dir.path(),
        "bad.json",
        &json!({"aircraft": {"type": "fixed_wing", "turn_radius_m": 2}}),
    );
    let o = terraplan(&[
        "survey",
        "--roi",
        field.to_str().unwrap(),
        "--params",
        bad.to_str().unwrap(),
        "--out",
        dir.path().join("bad").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("/aircraft/turn_radius_m"));
}
