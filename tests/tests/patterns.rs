//! Survey patterns (issue 20): crosshatch, oblique camera pitch and the
//! trigger modes, through `terraplan survey` and the service, on a real
//! field (fields2cover's two Illinois fields) with no-fly zones inside and
//! across its border, checked by tests/validators/check_patterns.py
//! (shapely, pyproj, numpy ray casting, pymavlink), check_survey.py and
//! check_missions.py (pymavlink, MAVSDK, MAVProxy).

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, SurveyArea, SurveyFiles, check_missions, check_terrain, get, post_json, shared_data,
    survey_cli, terraplan, text, validator, write_json,
};

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

fn roi() -> PathBuf {
    shared_data("polygons/fields2cover__test_2_cell.json")
}

/// NFZs inside the fields and across a border.
fn nfzs() -> Value {
    json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": rect(-90.1375, 41.4710, -90.1365, 41.4717)},
        {"type": "Feature", "properties": {}, "geometry": rect(-90.1315, 41.4650, -90.1280, 41.4660)}
    ]})
}

/// Plans with `params` through the CLI into `dir/name`; returns its plan.json.
fn plan(dir: &Path, name: &str, params: &Value) -> (PathBuf, Value) {
    let params_path = write_json(dir, &format!("{name}.params.json"), params);
    let nfz = write_json(dir, "nfz.geojson", &nfzs());
    let out = dir.join(name);
    let files = SurveyFiles {
        area: SurveyArea::Roi(&roi()),
        no_fly: &[&nfz],
        dem: None,
        params: &params_path,
    };
    let plan = survey_cli(&files, &out, name);
    (out, plan)
}

/// check_patterns.py on an output directory; returns its summary.
fn check_patterns(dir: &Path, out: &Path, params: &Value) -> Value {
    let params_path = write_json(dir, "checked.params.json", params);
    let nfz = dir.join("nfz.geojson");
    let v = validator(
        "check_patterns.py",
        &[out, &params_path, &roi(), nfz.as_path()],
    );
    assert!(
        v.status.success(),
        "check_patterns: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).unwrap()
}

fn check_survey(dir: &Path, out: &Path) -> Value {
    let nfz = dir.join("nfz.geojson");
    let v = validator("check_survey.py", &[out, &roi(), nfz.as_path()]);
    assert!(
        v.status.success(),
        "check_survey: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).unwrap()
}

/// Crosshatch with an oblique camera: both lane sets cover the free area
/// alone and cross at right angles, the footprint matches ray casting, the
/// missions load everywhere; absent members plan exactly today's survey.
#[test]
fn crosshatch_oblique_on_a_field_with_nfzs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let params = json!({"altitude_m": 80, "side_overlap": 0.6,
                        "pattern": "crosshatch", "camera_pitch_deg": -55});
    let (out, cross) = plan(d, "cross", &params);
    let summary = check_patterns(d, &out, &params);
    assert!(summary["set1_coverage"].as_f64().unwrap() >= 0.995);
    assert!(summary["set2_coverage"].as_f64().unwrap() >= 0.995);
    assert!(summary["worst_right_angle_error_deg"].as_f64().unwrap() <= 1.0);
    check_survey(d, &out);
    check_missions(&out);

    // The grid of the same request: half the lanes or fewer, and the
    // explicit defaults plan it byte for byte as the bare request does.
    let (grid_out, grid) = plan(d, "grid", &json!({"altitude_m": 80, "side_overlap": 0.6}));
    let (same_out, _) = plan(
        d,
        "explicit",
        &json!({"altitude_m": 80, "side_overlap": 0.6,
                "pattern": "grid", "trigger": {"mode": "distance"}}),
    );
    for f in ["uav1.waypoints", "uav1.plan", "uav1.route.geojson"] {
        let (a, b) = (
            std::fs::read_to_string(grid_out.join(f)).unwrap(),
            std::fs::read_to_string(same_out.join(f)).unwrap(),
        );
        let first = a.lines().zip(b.lines()).find(|(x, y)| x != y);
        assert!(a == b, "{f} differs: {first:?}");
    }
    let explicit: Value =
        serde_json::from_str(&std::fs::read_to_string(same_out.join("plan.json")).unwrap())
            .unwrap();
    assert_eq!(explicit["stats"], grid["stats"]);
    assert_eq!(explicit["cells"], grid["cells"]);
    let lanes = |p: &Value| p["stats"]["lane_count"].as_u64().unwrap();
    assert!(
        lanes(&cross) > lanes(&grid),
        "{} {}",
        lanes(&cross),
        lanes(&grid)
    );
    // At −55° the near edge lies 8.4° off the nadir but on a longer ray
    // than the nadir image's edge: 80 · 13.2 / (8.8 cos 35° + 4.4 sin 35°)
    // = 108.5 m wide against 120 m, so the lanes lie closer.
    let spacing = |p: &Value| p["stats"]["line_spacing_m"].as_f64().unwrap();
    assert!(
        (spacing(&cross) - 108.5 * 0.4).abs() < 0.1,
        "{}",
        spacing(&cross)
    );
    assert!(
        (spacing(&grid) - 120.0 * 0.4).abs() < 1e-6,
        "{}",
        spacing(&grid)
    );
}

/// Time triggering over a crosshatch and hover triggering, with two UAVs
/// sharing the field in battery sorties: the photo counts of the missions
/// equal the plan's, each crosshatch set covers the free area alone, hover
/// holds at every photo and its flight time carries the holds.
#[test]
fn trigger_modes_with_a_flock_in_sorties() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let uavs = json!([
        {"id": "a", "start": [-90.1347, 41.4692], "max_flight_time_s": 900},
        {"id": "b", "start": [-90.1400, 41.4740], "speed_m_s": 8, "max_flight_time_s": 900}
    ]);
    let base = json!({"altitude_m": 100, "side_overlap": 0.5, "front_overlap": 0.6, "uavs": uavs});
    let with = |extra: Value| {
        let mut p = base.clone();
        for (k, v) in extra.as_object().unwrap() {
            p[k] = v.clone();
        }
        p
    };
    let (dist_out, dist) = plan(d, "distance", &base);
    check_patterns(d, &dist_out, &base);

    // Time triggering over a crosshatch: both sets shared by the flock and
    // cut into sorties, each set's photos alone seeing the free area.
    let time =
        with(json!({"trigger": {"mode": "time", "interval_s": 2.5}, "pattern": "crosshatch"}));
    let (time_out, time_plan) = plan(d, "time", &time);
    let summary = check_patterns(d, &time_out, &time);
    assert!(
        summary["set1_coverage"].as_f64().unwrap() >= 0.995,
        "{summary}"
    );
    assert!(
        summary["set2_coverage"].as_f64().unwrap() >= 0.995,
        "{summary}"
    );
    assert!(time_plan["stats"]["sorties"].as_u64().unwrap() > 2);
    check_missions(&time_out);
    // 2.5 s at 10 and at 8 m/s: 25 and 20 m between photos, against the
    // 40 m trigger distance (100 m footprint, 60 % front overlap): more.
    assert!(
        time_plan["stats"]["photos"].as_u64().unwrap() > dist["stats"]["photos"].as_u64().unwrap()
    );

    // Hover stops make the flight longer: shorter batteries (600 s) make
    // sure it is cut into several sorties whatever the lane layout.
    let short_uavs = json!([
        {"id": "a", "start": [-90.1347, 41.4692], "max_flight_time_s": 600},
        {"id": "b", "start": [-90.1400, 41.4740], "speed_m_s": 8, "max_flight_time_s": 600}
    ]);
    let hover = with(json!({"trigger": {"mode": "hover", "hold_s": 1.5}, "uavs": short_uavs}));
    let (hover_out, hover_plan) = plan(d, "hover", &hover);
    check_patterns(d, &hover_out, &hover);
    check_missions(&hover_out);
    // The same photos as by distance; every stop adds its hold and a
    // turn's penalty (2 s), and every sortie still fits its battery.
    let photos = hover_plan["stats"]["photos"].as_u64().unwrap();
    assert_eq!(photos, dist["stats"]["photos"].as_u64().unwrap());
    let flown = |p: &Value| -> f64 {
        p["uavs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|u| u["stats"]["flight_time_s"].as_f64().unwrap())
            .sum()
    };
    let extra = flown(&hover_plan) - flown(&dist);
    assert!(
        extra > photos as f64 * 3.5 * 0.9,
        "{extra} s more for {photos} stops"
    );
    for u in hover_plan["uavs"].as_array().unwrap() {
        for s in u["sorties"].as_array().unwrap() {
            let t = s["stats"]["flight_time_s"].as_f64().unwrap();
            assert!(t <= 600.0 + 1e-6, "{}: {t} s", s["file_stem"]);
        }
    }
    assert!(hover_plan["stats"]["sorties"].as_u64().unwrap() > 2);
}

/// Bad members are refused naming them: exit 2 on the CLI, 422 with the
/// member's pointer from the service; the service plans an oblique
/// crosshatch with time triggering whose missions pass the same checks.
#[test]
fn service_and_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (params, pointer) in [
        (json!({"camera_pitch_deg": -20}), "/camera_pitch_deg"),
        (json!({"camera_pitch_deg": -30}), "/camera_pitch_deg"),
        (json!({"trigger": {"interval_s": 3}}), "/trigger/interval_s"),
        (json!({"pattern": "zigzag"}), "/pattern"),
    ] {
        let p = write_json(d, "bad.json", &params);
        let o = terraplan(&[
            "survey",
            "--roi",
            roi().to_str().unwrap(),
            "--params",
            p.to_str().unwrap(),
            "--out",
            d.join("bad").to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{params}");
        assert!(
            text(&o.stderr).contains(pointer),
            "{params}: {}",
            text(&o.stderr)
        );
    }

    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let roi_doc: Value = serde_json::from_str(&std::fs::read_to_string(roi()).unwrap()).unwrap();
    let body = |extra: Value| {
        let mut b = json!({"roi": roi_doc, "no_fly_zones": [nfzs()],
                           "altitude_m": 90, "side_overlap": 0.5});
        for (k, v) in extra.as_object().unwrap() {
            b[k] = v.clone();
        }
        b
    };
    let r = post_json(
        &server.url("/api/v1/surveys"),
        &body(json!({"camera_pitch_deg": -30})),
    );
    assert_eq!(r.status, 422, "{}", r.text());
    let problem = r.json();
    assert!(
        problem.to_string().contains("/camera_pitch_deg"),
        "{problem}"
    );
    assert!(problem.to_string().contains("at most -31.6"), "{problem}");

    let params = json!({"pattern": "crosshatch", "camera_pitch_deg": -70,
                        "trigger": {"mode": "time"}});
    let r = post_json(&server.url("/api/v1/surveys"), &body(params.clone()));
    assert_eq!(r.status, 201, "{}", r.text());
    let mut survey = r.json();
    let out = d.join("service");
    std::fs::create_dir_all(&out).unwrap();
    // The answer names each sortie's files by URL: saved under stems of
    // their own, named in the plan.json the checker reads.
    for u in survey["uavs"].as_array_mut().unwrap() {
        let id = u["id"].as_str().unwrap().to_string();
        for (k, s) in u["sorties"].as_array_mut().unwrap().iter_mut().enumerate() {
            let stem = format!("{id}.s{k}");
            for (kind, ext) in [("waypoints", "waypoints"), ("plan", "plan")] {
                let f = get(&server.url(s["files"][kind].as_str().unwrap()));
                assert_eq!(f.status, 200);
                std::fs::write(out.join(format!("{stem}.{ext}")), &f.body).unwrap();
            }
            s["file_stem"] = json!(stem);
        }
    }
    std::fs::write(out.join("plan.json"), survey.to_string()).unwrap();
    write_json(d, "nfz.geojson", &nfzs());
    let mut checked = params;
    checked["altitude_m"] = json!(90);
    checked["side_overlap"] = json!(0.5);
    let summary = check_patterns(d, &out, &checked);
    assert_eq!(
        summary["photos"].as_u64(),
        survey["stats"]["photos"].as_u64()
    );
    assert!(summary["set2_coverage"].as_f64().unwrap() >= 0.995);
}

/// Terrain following with the patterns: an oblique crosshatch hovered for
/// each photo over the opengeos DSM; the heights above the DEM checked by
/// GDAL (check_terrain.py), the photos and the gimbal by check_patterns.py.
#[test]
fn crosshatch_hover_over_a_dem() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dem = shared_data("dems/opengeos_data__elevation_dsm.tif");
    let info = terraplan(&["dem-info", dem.to_str().unwrap()]);
    assert!(info.status.success(), "{}", text(&info.stderr));
    let info: Value = serde_json::from_slice(&info.stdout).unwrap();
    let b: Vec<f64> = serde_json::from_value(info["bounds_wgs84"].clone()).unwrap();
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let (hx, hy) = ((b[2] - b[0]) / 5.0, (b[3] - b[1]) / 5.0);
    let roi = write_json(d, "roi.json", &rect(cx - hx, cy - hy, cx + hx, cy + hy));
    let nfz = write_json(
        d,
        "nfz.geojson",
        &rect(cx - hx / 4.0, cy - hy / 4.0, cx + hx / 4.0, cy + hy / 4.0),
    );
    let params = json!({"altitude_m": 40, "agl_tolerance_m": 4, "altitude_frame": "terrain",
                        "pattern": "crosshatch", "camera_pitch_deg": -75,
                        "trigger": {"mode": "hover", "hold_s": 1},
                        "uavs": [{"id": "t1", "start": [cx - hx, cy - hy]}]});
    let params_path = write_json(d, "params.json", &params);
    let out = d.join("out");
    let files = SurveyFiles {
        area: SurveyArea::Roi(&roi),
        no_fly: &[&nfz],
        dem: Some(&dem),
        params: &params_path,
    };
    survey_cli(&files, &out, "hover crosshatch over a DEM");
    check_terrain(
        &dem,
        &out.join("plan.json"),
        "t1",
        &[&out.join("t1.waypoints")],
    );
    let params_checked = write_json(d, "checked.json", &params);
    let v = validator(
        "check_patterns.py",
        &[&out, &params_checked, &roi, nfz.as_path()],
    );
    assert!(v.status.success(), "{}{}", text(&v.stdout), text(&v.stderr));
    let summary: Value = serde_json::from_slice(&v.stdout).unwrap();
    assert!(summary["photos"].as_u64().unwrap() > 10, "{summary}");
    check_missions(&out);
}
