//! DJI WPML (`.kmz`) and Litchi (`.litchi.csv`) missions of `terraplan
//! survey` and the service, checked by independent validators against DJI's
//! WPML reference and Litchi's CSV columns (tests/validators/check_wpml.py
//! with zipfile, xml.etree, PROJ's EGM96 grid and GDAL's osr;
//! check_litchi.py with Python's csv) and against the plan's `.waypoints`.

use std::path::Path;
use std::process::Command;

use serde_json::{Value, json};
use terraplan_e2e::{
    GDAL_PYTHON, Server, SurveyArea, SurveyFiles, get, post_json, shared_data, survey_cli,
    terraplan, text, validator, workspace, write_json,
};

/// check_wpml.py (Debian's Python, for GDAL) on a survey's output; its summary.
fn check_wpml(out: &Path) -> Value {
    let o = Command::new(GDAL_PYTHON)
        .arg(workspace().join("tests/validators/check_wpml.py"))
        .arg(out)
        .output()
        .expect("run check_wpml.py");
    assert!(
        o.status.success(),
        "check_wpml.py {}: {}{}",
        out.display(),
        text(&o.stdout),
        text(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("check_wpml.py summary")
}

/// check_litchi.py on a survey's output; its summary.
fn check_litchi(out: &Path) -> Value {
    let o = validator("check_litchi.py", &[out]);
    assert!(
        o.status.success(),
        "check_litchi.py {}: {}{}",
        out.display(),
        text(&o.stdout),
        text(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("check_litchi.py summary")
}

/// `terraplan survey` of the example field and its mast into `dir/name`.
fn plan_example(dir: &Path, name: &str, params: &Value) -> (Value, std::path::PathBuf) {
    let ex = workspace().join("examples");
    let params = write_json(dir, &format!("{name}.json"), params);
    let out = dir.join(name);
    let nfz = ex.join("field-nfz.geojson");
    let files = SurveyFiles {
        area: SurveyArea::Roi(&ex.join("field.geojson")),
        no_fly: &[&nfz],
        dem: None,
        params: &params,
    };
    (survey_cli(&files, &out, name), out)
}

fn photos_of(plan: &Value) -> u64 {
    plan["uavs"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|u| u["sorties"].as_array().unwrap())
        .map(|s| s["stats"]["photos"].as_u64().unwrap())
        .sum()
}

#[test]
fn example_field_in_every_trigger_mode() {
    let dir = tempfile::tempdir().unwrap();
    let start = json!([6.0620, 51.5110]);
    let cases = [
        ("distance", json!({}), "m3e"),
        (
            "hover",
            json!({"trigger": {"mode": "hover", "hold_s": 1.5}, "camera_pitch_deg": -60, "dji_aircraft": "m30t"}),
            "m30t",
        ),
        (
            "time",
            json!({"trigger": {"mode": "time", "interval_s": 2}, "dji_aircraft": "m350_h20t"}),
            "m350_h20t",
        ),
    ];
    for (name, extra, aircraft) in cases {
        let mut params =
            json!({"altitude_m": 60, "speed_m_s": 8, "uavs": [{"id": "u1", "start": start}]});
        for (k, v) in extra.as_object().unwrap() {
            params[k] = v.clone();
        }
        let (plan, out) = plan_example(dir.path(), name, &params);
        assert_eq!(plan["dji_aircraft"].as_str().unwrap_or("m3e"), aircraft);
        let names: Vec<&str> = plan["files"]
            .as_array()
            .unwrap()
            .iter()
            .map(|f| f["name"].as_str().unwrap())
            .collect();
        assert!(names.contains(&"u1.kmz"), "{name}: {names:?}");
        let wpml = check_wpml(&out);
        let f = &wpml["files"][0];
        assert_eq!(f["execute_height_mode"], "relativeToStartPoint", "{name}");
        // Every photo of the plan, by the DJI actions (a plan of a
        // mapping survey takes dozens).
        assert_eq!(f["photos"].as_u64(), Some(photos_of(&plan)), "{name}: {f}");
        assert!(photos_of(&plan) > 50, "{name}: {}", photos_of(&plan));
        assert!(f["max_position_diff_deg"].as_f64().unwrap() < 1e-7);
        let litchi = check_litchi(&out);
        let m = &litchi["missions"][0];
        assert_eq!(m["waypoints"], f["waypoints"], "{name}");
        if name == "hover" {
            // One photo action per hover station.
            assert_eq!(m["photo_actions"].as_u64(), Some(photos_of(&plan)));
        }
    }
}

/// Many lanes: more than 99 waypoints, so Litchi's mission comes in parts,
/// each a complete mission of at most 99; the KMZ holds them all.
#[test]
fn long_missions_split_for_litchi() {
    let dir = tempfile::tempdir().unwrap();
    let params = json!({"altitude_m": 40, "line_spacing_m": 3, "speed_m_s": 12,
                        "uavs": [{"id": "u1", "start": [6.0620, 51.5110]}]});
    let (plan, out) = plan_example(dir.path(), "long", &params);
    let names: Vec<String> = plan["files"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["name"].as_str().unwrap().to_string())
        .collect();
    let parts: Vec<&String> = names
        .iter()
        .filter(|n| n.ends_with(".litchi.csv"))
        .collect();
    // 3 m lanes over the example field: a few hundred waypoints, so
    // several files (how many depends on the plan: checked below).
    assert!(parts.len() >= 2, "{parts:?}");
    assert_eq!(parts[0], "u1.part1.litchi.csv");
    assert!(!out.join("u1.litchi.csv").exists());
    let litchi = check_litchi(&out);
    let m = &litchi["missions"][0];
    assert_eq!(m["files"].as_u64(), Some(parts.len() as u64));
    let wpml = check_wpml(&out);
    assert_eq!(m["waypoints"], wpml["files"][0]["waypoints"]);
    let waypoints = m["waypoints"].as_u64().unwrap();
    assert!(waypoints > 99, "{m}");
    // Each part starts where the one before ended: 98 legs a file.
    assert_eq!(parts.len() as u64, (waypoints - 1).div_ceil(98), "{m}");
    assert_eq!(wpml["files"][0]["photos"].as_u64(), Some(photos_of(&plan)));
}

/// Over a DEM in the AMSL frame the waylines fly WGS84 ellipsoidal heights
/// (checked against PROJ's EGM96 grid within 0.5 m); in the terrain frame
/// a Mavic 3 enterprise follows the terrain in real time, and an aircraft
/// that cannot is refused naming `dji_aircraft`.
#[test]
fn heights_over_a_dem_in_each_frame() {
    let dir = tempfile::tempdir().unwrap();
    let dem = shared_data("dems/opengeos_data__elevation_dsm.tif");
    let info = terraplan(&["dem-info", dem.to_str().unwrap()]);
    assert!(info.status.success(), "{}", text(&info.stderr));
    let info: Value = serde_json::from_slice(&info.stdout).unwrap();
    let b: Vec<f64> = serde_json::from_value(info["bounds_wgs84"].clone()).unwrap();
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let (hx, hy) = ((b[2] - b[0]) / 4.0, (b[3] - b[1]) / 4.0);
    let roi = write_json(
        dir.path(),
        "roi.json",
        &json!({"type": "Polygon", "coordinates": [[[cx - hx, cy - hy], [cx + hx, cy - hy],
               [cx + hx, cy + hy], [cx - hx, cy + hy], [cx - hx, cy - hy]]]}),
    );
    for (frame, aircraft, mode) in [
        ("amsl", "m4e", "WGS84"),
        ("terrain", "m3e", "realTimeFollowSurface"),
        ("relative", "m350_h30", "relativeToStartPoint"),
    ] {
        let params = write_json(
            dir.path(),
            &format!("{frame}.json"),
            &json!({"altitude_m": 40, "altitude_frame": frame, "dji_aircraft": aircraft,
                    "uavs": [{"id": "t1", "start": [cx - hx, cy - hy]}]}),
        );
        let out = dir.path().join(frame);
        let files = SurveyFiles {
            area: SurveyArea::Roi(&roi),
            no_fly: &[],
            dem: Some(&dem),
            params: &params,
        };
        let plan = survey_cli(&files, &out, frame);
        let wpml = check_wpml(&out);
        let f = &wpml["files"][0];
        assert_eq!(f["execute_height_mode"], mode, "{frame}");
        assert_eq!(f["photos"].as_u64(), Some(photos_of(&plan)), "{frame}");
        if frame == "amsl" {
            // Ellipsoidal: the geoid here lies about 33 m below the ellipsoid.
            assert!(f["max_height_diff_m"].as_f64().unwrap() < 0.5, "{f}");
        }
        check_litchi(&out);
    }
    let params = write_json(
        dir.path(),
        "m30.json",
        &json!({"altitude_frame": "terrain", "dji_aircraft": "m30",
                "uavs": [{"id": "t1", "start": [cx - hx, cy - hy]}]}),
    );
    let o = terraplan(&[
        "survey",
        "--roi",
        roi.to_str().unwrap(),
        "--dem",
        dem.to_str().unwrap(),
        "--params",
        params.to_str().unwrap(),
        "--out",
        dir.path().join("m30").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("dji_aircraft") && err.contains("m30 cannot follow the terrain"),
        "{err}"
    );
}

/// Rally points: the `.plan`'s fence returns to the first (`breachReturn`,
/// as QGroundControl stores it), and the DJI mission returns home at their
/// altitude (WPML has no rally points).
#[test]
fn rally_altitude_is_the_return_height() {
    let dir = tempfile::tempdir().unwrap();
    let params = json!({"altitude_m": 55, "rally_points": [[6.0615, 51.5105]],
                        "uavs": [{"id": "u1", "start": [6.0620, 51.5110]}]});
    let (_, out) = plan_example(dir.path(), "rally", &params);
    let plan: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("u1.plan")).unwrap()).unwrap();
    let rally = &plan["rallyPoints"]["points"][0];
    assert_eq!(rally, &json!([51.5105, 6.0615, 55.0]));
    assert_eq!(&plan["geoFence"]["breachReturn"], rally);
    let wpml = check_wpml(&out);
    assert_eq!(wpml["files"][0]["rth_height_m"], 55.0);
    assert_eq!(wpml["files"][0]["finish_action"], "goHome");
}

/// The service serves both as downloads of the UAV, with their media types,
/// and links them from the survey; a plane's sortie has none.
#[test]
fn service_downloads() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let mut body = terraplan_e2e::example_survey_request();
    body["uavs"] = json!([{"id": "u1", "start": [6.0620, 51.5110]}]);
    body["dji_aircraft"] = json!("m3t");
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let created = r.json();
    let files = &created["uavs"][0]["sorties"][0]["files"];
    let id = created["id"].as_str().unwrap();
    assert_eq!(
        files["dji_kmz"],
        format!("/api/v1/surveys/{id}/uavs/u1/mission.kmz")
    );
    assert_eq!(
        files["litchi"],
        json!([format!("/api/v1/surveys/{id}/uavs/u1/mission.litchi.csv")])
    );
    let kmz = get(&server.url(files["dji_kmz"].as_str().unwrap()));
    assert_eq!(kmz.status, 200);
    assert_eq!(
        kmz.header("content-type"),
        Some("application/vnd.google-earth.kmz")
    );
    assert!(
        kmz.header("content-disposition")
            .unwrap()
            .ends_with("-u1.kmz\""),
        "{:?}",
        kmz.header("content-disposition")
    );
    assert_eq!(&kmz.body[..4], b"PK\x03\x04");
    let csv = get(&server.url(files["litchi"][0].as_str().unwrap()));
    assert_eq!(csv.header("content-type"), Some("text/csv; charset=utf-8"));
    assert!(
        csv.text()
            .starts_with("latitude,longitude,altitude(m),heading(deg),")
    );
    let missing = get(&server.url(&format!(
        "/api/v1/surveys/{id}/uavs/u1/mission.part2.litchi.csv"
    )));
    assert_eq!(missing.status, 404);
    assert!(
        missing.text().contains("mission.part1.litchi.csv"),
        "{}",
        missing.text()
    );
    // The downloads, validated as the CLI's files are.
    let out = dir.path().join("dl");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("u1.kmz"), &kmz.body).unwrap();
    std::fs::write(out.join("u1.litchi.csv"), &csv.body).unwrap();
    let wpl = get(&server.url(files["waypoints"].as_str().unwrap()));
    std::fs::write(out.join("u1.waypoints"), &wpl.body).unwrap();
    let mut plan = created.clone();
    plan["dji_aircraft"] = json!("m3t");
    for s in plan["uavs"][0]["sorties"].as_array_mut().unwrap() {
        s["file_stem"] = json!("u1");
    }
    write_json(&out, "plan.json", &plan);
    let wpml = check_wpml(&out);
    assert_eq!(
        wpml["files"][0]["photos"].as_u64(),
        created["uavs"][0]["stats"]["photos"].as_u64()
    );
    check_litchi(&out);

    // Documented: the KMZ as binary, the CSV as text.
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let content = &doc["paths"]["/api/v1/surveys/{id}/uavs/{uav}/{file}"]["get"]["responses"]["200"]
        ["content"];
    let kmz_schema = &content["application/vnd.google-earth.kmz"]["schema"]["$ref"];
    assert_eq!(kmz_schema, "#/components/schemas/BinaryFile", "{content}");
    assert_eq!(
        doc["components"]["schemas"]["BinaryFile"]["format"],
        "binary"
    );
    assert_eq!(content["text/csv"]["schema"]["type"], "string", "{content}");

    // A fixed-wing survey: no DJI files, no links.
    body["aircraft"] = json!({"type": "fixed_wing"});
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let plane = r.json();
    let files = &plane["uavs"][0]["sorties"][0]["files"];
    assert!(
        files.get("dji_kmz").is_none() && files.get("litchi").is_none(),
        "{files}"
    );
    let pid = plane["id"].as_str().unwrap();
    let r = get(&server.url(&format!("/api/v1/surveys/{pid}/uavs/u1/mission.kmz")));
    assert_eq!(r.status, 404);
    assert!(r.text().contains("multirotor"), "{}", r.text());
}
