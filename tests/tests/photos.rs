//! Planned photos (issue 20 item 5): `photos.geojson` per UAV and each
//! cell's achieved overlap and GSD, through `terraplan survey` and the
//! service, checked by tests/validators/check_photos.py (shapely, pyproj,
//! numpy, pymavlink: counts, cameras where the missions take the photos,
//! footprints recast from the camera, coverage of the free area, overlaps
//! recomputed) and, over a real DEM, check_photos_dem.py
//! (GDAL reads the DEM, numpy casts the rays).

use std::path::{Path, PathBuf};

use serde_json::{Value, json};
use terraplan_e2e::{
    GDAL_PYTHON, Server, SurveyArea, SurveyFiles, get, post_json, shared_data, survey_cli, text,
    validator, workspace, write_json,
};

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

/// Fields2Cover's two Illinois fields.
fn field() -> PathBuf {
    shared_data("polygons/fields2cover__test_2_cell.json")
}

/// NFZs inside the fields and across a border.
fn nfzs() -> Value {
    json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": rect(-90.1375, 41.4710, -90.1365, 41.4717)},
        {"type": "Feature", "properties": {}, "geometry": rect(-90.1315, 41.4650, -90.1280, 41.4660)}
    ]})
}

/// check_photos.py on `out` (planned with `params` over `roi` and `nfz`),
/// with the independent ground points of `ground` over a DEM; asserts it
/// passes and returns its summary.
fn check_photos(out: &Path, params: &Path, roi: &Path, nfz: &Path, ground: Option<&Path>) -> Value {
    let mut args: Vec<&Path> = vec![out, params, roi, nfz];
    if let Some(g) = ground {
        args.extend([Path::new("--ground"), g]);
    }
    let v = validator("check_photos.py", &args);
    assert!(
        v.status.success(),
        "check_photos on {}: {}{}",
        out.display(),
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).unwrap()
}

/// Plans the Illinois fields with `params` through the CLI into
/// `dir/name` and checks its photos; returns the plan and the summary.
fn plan_and_check(dir: &Path, name: &str, params: &Value) -> (Value, Value) {
    let params_path = write_json(dir, &format!("{name}.params.json"), params);
    let nfz = write_json(dir, "nfz.geojson", &nfzs());
    let out = dir.join(name);
    let files = SurveyFiles {
        area: SurveyArea::Roi(&field()),
        no_fly: &[&nfz],
        dem: None,
        params: &params_path,
    };
    let plan = survey_cli(&files, &out, name);
    let summary = check_photos(&out, &params_path, &field(), &nfz, None);
    assert_eq!(summary["photos"], plan["stats"]["photos"], "{name}");
    // Every photo where its sortie's .waypoints takes it.
    assert_eq!(
        summary["photos_matched_to_missions"], plan["stats"]["photos"],
        "{name}"
    );
    assert!(
        summary["coverage"].as_f64().unwrap() >= 0.995,
        "{name}: {summary}"
    );
    (plan, summary)
}

/// Every trigger mode and both patterns on a real field with NFZs, a flock
/// in battery sorties among them, and a VTOL: one footprint per photo the plan counts,
/// covering the free area, each where the camera's rays meet the ground,
/// the cells' overlaps as recomputed from them — on level ground the
/// requested 80 % front overlap exactly, and the side overlap at least
/// the requested 70 % less the 1 % the rounding of the lanes may give.
#[test]
fn footprints_cover_the_field_in_every_trigger_mode_and_pattern() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, grid) = plan_and_check(d, "grid", &json!({"altitude_m": 80}));
    assert_eq!(grid["min_front_overlap"].as_f64(), Some(0.8), "{grid}");
    assert!(grid["min_side_overlap"].as_f64().unwrap() >= 0.69, "{grid}");
    assert!(
        grid["worst_corner_error"].as_f64().unwrap() < 1e-3,
        "{grid}"
    );

    let uavs = json!([
        {"id": "a", "start": [-90.1347, 41.4692], "max_flight_time_s": 900},
        {"id": "b", "start": [-90.1400, 41.4740], "speed_m_s": 8, "max_flight_time_s": 900}
    ]);
    let (time_plan, time) = plan_and_check(
        d,
        "time",
        &json!({"altitude_m": 100, "side_overlap": 0.5, "pattern": "crosshatch",
                "trigger": {"mode": "time", "interval_s": 2.5}, "uavs": uavs}),
    );
    assert!(time_plan["stats"]["sorties"].as_u64().unwrap() > 2);
    // 2.5 s at 8 and 10 m/s: 20 and 25 m between photos of a 100 m
    // footprint: at least 75 % front overlap.
    assert!(
        time["min_front_overlap"].as_f64().unwrap() >= 0.75 - 1e-9,
        "{time}"
    );
    // Planes: the photos of the lanes they lay themselves (a VTOL in
    // battery sorties).
    plan_and_check(
        d,
        "vtol",
        &json!({"altitude_m": 100, "side_overlap": 0.6, "aircraft": {"type": "vtol"},
                "uavs": [{"id": "v", "start": [-90.1347, 41.4692], "max_flight_time_s": 600}]}),
    );
    let (hover_plan, _) = plan_and_check(
        d,
        "hover",
        &json!({"altitude_m": 100, "trigger": {"mode": "hover", "hold_s": 1.5}, "uavs": uavs}),
    );
    // Each UAV's file holds its sorties' photos, numbered by sortie.
    let file: Value = serde_json::from_str(
        &std::fs::read_to_string(d.join("hover").join("a.photos.geojson")).unwrap(),
    )
    .unwrap();
    let a = &hover_plan["uavs"][0];
    let sorties: Vec<u64> = a["sorties"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["stats"]["photos"].as_u64().unwrap())
        .collect();
    assert!(sorties.len() > 1, "{sorties:?}");
    for (k, want) in sorties.iter().enumerate() {
        let got = file["features"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["properties"]["sortie"] == json!(k + 1))
            .count() as u64;
        assert_eq!(got, *want, "sortie {}", k + 1);
    }
}

/// An oblique camera: footprints recast within 1 % (checked in
/// check_photos.py), and the lanes lengthened by the footprint's offset
/// ahead of the camera so that the ground just behind a lane's start is
/// seen: a strip one lane wide (its lane flown away from one end) is
/// covered; without the lengthening its first 14 m were not (96.4 %).
#[test]
fn oblique_footprints_reach_behind_the_lane_start() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, oblique) = plan_and_check(
        d,
        "oblique",
        &json!({"altitude_m": 80, "camera_pitch_deg": -50, "side_overlap": 0.6}),
    );
    assert!(oblique["worst_corner_error"].as_f64().unwrap() < 0.01);

    // A strip 400 × 25 m near Zürich, one lane wide at 60 m and −50°.
    let (lon0, lat0) = (8.5, 47.0);
    let (m_lat, m_lon) = (111_320.0, 111_320.0 * 47f64.to_radians().cos());
    let strip = rect(lon0, lat0, lon0 + 400.0 / m_lon, lat0 + 25.0 / m_lat);
    let roi = write_json(d, "strip.geojson", &strip);
    let none = write_json(
        d,
        "none.geojson",
        &json!({"type": "FeatureCollection", "features": []}),
    );
    let params = json!({"altitude_m": 60, "camera_pitch_deg": -50, "side_overlap": 0.6,
                        "slice_angle_deg": 0,
                        "uavs": [{"id": "s", "start": [lon0 - 0.0003, lat0 - 0.0002]}]});
    let params_path = write_json(d, "strip.params.json", &params);
    let out = d.join("strip");
    let plan = survey_cli(
        &SurveyFiles {
            area: SurveyArea::Roi(&roi),
            no_fly: &[&none],
            dem: None,
            params: &params_path,
        },
        &out,
        "strip",
    );
    assert_eq!(plan["stats"]["lane_count"], json!(1));
    let summary = check_photos(&out, &params_path, &roi, &none, None);
    assert!(summary["coverage"].as_f64().unwrap() >= 0.995, "{summary}");
    // The lane runs 2 × 60 · tan(40° − 26.57°) = 28.6 m past the strip
    // (400 m give or take the UTM scale and this test's metres per degree).
    let lane = plan["cells"][0]["lane_length_m"].as_f64().unwrap();
    assert!((lane - 428.6).abs() < 1.0, "{lane}");
}

/// Over the Copernicus DSM west of Grenoble (hills of ~150 m; in WGS 84,
/// so no datum shift between the planner's and GDAL's transformations)
/// with an NFZ, nadir, oblique and by a fixed wing: every corner of every footprint where
/// GDAL's ray casting puts it (within 1 % of the range plus 5 cm), the
/// overlaps recomputed from those within 0.02, the GSD within 1 %, and the
/// footprints cover the free area; the slopes make the achieved overlap
/// drop below the requested 80 % / 70 % somewhere.
#[test]
fn footprints_and_overlaps_over_a_real_dem() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let dem = shared_data("dems/demcompare__Copernicus_DSM_10_N45_00_E005_00_DEM.tif");
    let roi = write_json(d, "roi.geojson", &rect(5.2950, 45.2960, 5.3080, 45.3030));
    let nfz = write_json(d, "nfz.geojson", &rect(5.3000, 45.2985, 5.3015, 45.2995));
    let camera = write_json(d, "camera.json", &json!({}));
    let uav = json!([{"id": "d", "start": [5.2945, 45.2955]}]);
    for (name, params) in [
        ("nadir", json!({"altitude_m": 80, "uavs": uav})),
        (
            "oblique",
            json!({"altitude_m": 80, "camera_pitch_deg": -60, "uavs": uav}),
        ),
        // A plane lays its own lanes: its photos are read off its mission.
        (
            "fixed_wing",
            json!({"altitude_m": 100, "side_overlap": 0.6, "altitude_frame": "terrain", "uavs": uav,
                   "aircraft": {"type": "fixed_wing", "turn_radius_m": 35}}),
        ),
    ] {
        let params_path = write_json(d, &format!("{name}.params.json"), &params);
        let out = d.join(name);
        let plan = survey_cli(
            &SurveyFiles {
                area: SurveyArea::Roi(&roi),
                no_fly: &[&nfz],
                dem: Some(&dem),
                params: &params_path,
            },
            &out,
            name,
        );
        let ground = d.join(format!("{name}.ground.json"));
        let rays = std::process::Command::new(GDAL_PYTHON)
            .arg(workspace().join("tests/validators/check_photos_dem.py"))
            .args([&dem, &camera, &ground, &out.join("d.photos.geojson")])
            .output()
            .expect("run check_photos_dem.py");
        assert!(rays.status.success(), "{}", text(&rays.stderr));
        let summary = check_photos(&out, &params_path, &roi, &nfz, Some(&ground));
        assert_eq!(summary["photos"], plan["stats"]["photos"]);
        assert_eq!(
            summary["photos_matched_to_missions"],
            plan["stats"]["photos"]
        );
        assert!(
            summary["worst_corner_error"].as_f64().unwrap() < 0.01,
            "{summary}"
        );
        assert!(
            summary["coverage"].as_f64().unwrap() >= 0.995,
            "{name}: {summary}"
        );
        assert!(
            summary["min_front_overlap"].as_f64().unwrap() < 0.8
                || summary["min_side_overlap"].as_f64().unwrap() < 0.7,
            "{name}: {summary}"
        );
    }
}

/// The service: each sortie's answer links its photos, the UAV's file
/// holds every sortie's, `?sortie=k` one sortie's; the files and the
/// answer's cells pass check_photos.py; unknown UAVs are 404s.
#[test]
fn service_serves_photos_geojson() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let roi: Value = serde_json::from_str(&std::fs::read_to_string(field()).unwrap()).unwrap();
    let params = json!({"altitude_m": 90, "camera_pitch_deg": -60,
                        "uavs": [{"id": "a", "start": [-90.1347, 41.4692], "max_flight_time_s": 600}]});
    let mut body = params.clone();
    body["roi"] = roi;
    body["no_fly_zones"] = json!([nfzs()]);
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let mut survey = r.json();
    let out = d.join("service");
    std::fs::create_dir_all(&out).unwrap();
    let sorties = survey["uavs"][0]["sorties"].as_array_mut().unwrap();
    assert!(sorties.len() > 1, "{}", sorties.len());
    for (k, s) in sorties.iter_mut().enumerate() {
        let f = get(&server.url(s["files"]["photos"].as_str().unwrap()));
        assert_eq!(f.status, 200);
        let doc: Value = serde_json::from_slice(&f.body).unwrap();
        assert_eq!(
            doc["features"].as_array().unwrap().len() as u64,
            s["stats"]["photos"].as_u64().unwrap()
        );
        // Each sortie's mission, saved under a stem the checker reads.
        let wp = get(&server.url(s["files"]["waypoints"].as_str().unwrap()));
        assert_eq!(wp.status, 200);
        let stem = format!("a.s{}", k + 1);
        std::fs::write(out.join(format!("{stem}.waypoints")), &wp.body).unwrap();
        s["file_stem"] = json!(stem);
    }
    let id = survey["id"].as_str().unwrap();
    let all = get(&server.url(&format!("/api/v1/surveys/{id}/uavs/a/photos.geojson")));
    assert_eq!(all.status, 200);
    assert!(
        all.header("content-type")
            .unwrap_or_default()
            .contains("geo+json"),
        "{:?}",
        all.header("content-type")
    );
    std::fs::write(out.join("a.photos.geojson"), &all.body).unwrap();
    std::fs::write(out.join("plan.json"), survey.to_string()).unwrap();
    let params_path = write_json(d, "params.json", &params);
    let nfz = write_json(d, "nfz.geojson", &nfzs());
    let summary = check_photos(&out, &params_path, &field(), &nfz, None);
    assert_eq!(summary["photos"], survey["stats"]["photos"]);
    assert_eq!(
        summary["photos_matched_to_missions"],
        survey["stats"]["photos"]
    );
    let missing = get(&server.url(&format!("/api/v1/surveys/{id}/uavs/zz/photos.geojson")));
    assert_eq!(missing.status, 404);
}

/// The photos file is bounded (`--max-photo-features`, the service's
/// `--max-photo-features` / TERRAPLAN_MAX_PHOTO_FEATURES, default 50 000):
/// over the limit it holds every k-th photo and says so in its properties
/// (the plan's photo count, the features written, k, the limit); under it
/// the file is as before. A limit of 0 is refused (exit 2).
#[test]
fn photos_files_are_capped_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let nfz = write_json(dir.path(), "nfz.geojson", &nfzs());
    let params = write_json(dir.path(), "params.json", &json!({"altitude_m": 40}));
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let paths = [field(), nfz.clone(), params.clone(), out.clone()];
        let [roi, zones, params, out_dir] = paths.each_ref().map(|p| p.to_str().unwrap());
        let mut args = vec![
            "survey", "--roi", roi, "--no-fly", zones, "--params", params, "--out", out_dir,
        ];
        args.extend_from_slice(extra);
        (terraplan_e2e::terraplan(&args), out)
    };
    let read = |p: PathBuf| -> Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (o, full) = run("full", &[]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let plan = read(full.join("plan.json"));
    let photos = plan["stats"]["photos"].as_u64().unwrap();
    assert!(photos > 1000, "{photos}");
    let all = read(full.join("uav1.photos.geojson"));
    assert_eq!(all["features"].as_array().unwrap().len() as u64, photos);
    assert!(
        all["properties"].get("truncated").is_none(),
        "{}",
        all["properties"]
    );

    let (o, capped) = run("capped", &["--max-photo-features", "100"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let file = read(capped.join("uav1.photos.geojson"));
    let p = &file["properties"];
    let features = file["features"].as_array().unwrap();
    let k = p["every_kth_photo"].as_u64().unwrap();
    assert_eq!(p["truncated"], json!(true));
    assert_eq!(p["photos"].as_u64().unwrap(), photos);
    assert_eq!(p["max_photo_features"], json!(100));
    assert_eq!(k, photos.div_ceil(100));
    assert_eq!(p["features"].as_u64().unwrap(), features.len() as u64);
    assert!(features.len() <= 100 && features.len() as u64 == photos.div_ceil(k));
    assert!(p["note"].as_str().unwrap().contains(&photos.to_string()));
    // Every k-th photo, as in the whole file.
    let whole = all["features"].as_array().unwrap();
    for (n, f) in features.iter().enumerate() {
        assert_eq!(f, &whole[n * k as usize], "feature {n}");
    }
    // The other files are those of the plan without the limit.
    for name in ["plan.json", "uav1.waypoints", "cells.geojson"] {
        assert_eq!(
            std::fs::read(full.join(name)).unwrap(),
            std::fs::read(capped.join(name)).unwrap(),
            "{name}"
        );
    }
    let (o, _) = run("zero", &["--max-photo-features", "0"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--max-photo-features"));

    // The service's limit applies to every download of the file.
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &["--max-photo-features", "50"]);
    let mut body = json!({"altitude_m": 40, "no_fly_zones": nfzs()["features"]
        .as_array().unwrap().iter().map(|f| f["geometry"].clone()).collect::<Vec<_>>()});
    body["roi"] = read(field());
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let got = get(&server.url(&format!("/api/v1/surveys/{id}/uavs/uav1/photos.geojson")));
    assert_eq!(got.status, 200);
    let file: Value = serde_json::from_slice(&got.body).unwrap();
    assert_eq!(file["properties"]["photos"].as_u64().unwrap(), photos);
    assert_eq!(file["properties"]["max_photo_features"], json!(50));
    assert!(file["features"].as_array().unwrap().len() <= 50);
}
