//! `terraplan survey` end to end on real field boundaries, checked by
//! pymavlink, shapely and pyproj (tests/validators/check_survey.py), and
//! every `.plan` with its `.waypoints`, fence and rally files read by
//! pymavlink, MAVSDK and MAVProxy (tests/validators/check_missions.py).

use std::path::Path;

use serde_json::{Value, json};
use terraplan_e2e::{
    SurveyArea, SurveyFiles, check_missions, check_terrain, shared_data, survey_cli, terraplan,
    text, validator, workspace, write_json,
};

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

/// Plan, then run the independent validator; returns (plan.json, validator summary).
fn plan_and_validate(roi: &Path, nfz: &[&Path], params: &Value, dir: &Path) -> (Value, Value) {
    let params_path = write_json(dir, "params.json", params);
    let out = dir.join("out");
    let files = SurveyFiles {
        area: SurveyArea::Roi(roi),
        no_fly: nfz,
        dem: None,
        params: &params_path,
    };
    let plan = survey_cli(&files, &out, "plan_and_validate");
    let mut vargs: Vec<&Path> = vec![&out, roi];
    vargs.extend(nfz.iter().copied());
    let v = validator("check_survey.py", &vargs);
    assert!(
        v.status.success(),
        "validator: {}{}",
        text(&v.stdout),
        text(&v.stderr)
    );
    let summary: Value = serde_json::from_slice(&v.stdout).unwrap();
    check_missions(&out);
    (plan, summary)
}

#[test]
fn example_field_with_nfz_inside_and_across_border() {
    let dir = tempfile::tempdir().unwrap();
    let ex = workspace().join("examples");
    for angle in [json!(0), json!(90), json!(37.5), json!("auto")] {
        let params = json!({"altitude_m": 60, "slice_angle_deg": angle, "uavs": [{"id": "uav1", "start": [6.0620, 51.5110]}]});
        let (plan, summary) = plan_and_validate(
            &ex.join("field.geojson"),
            &[&ex.join("field-nfz.geojson")],
            &params,
            dir.path(),
        );
        // Flat-ended strips cannot reach into acute corners of the ROI or an
        // NFZ without leaving free space, so a forced slice angle may lose a
        // little; the default (auto) must reach 99.5 %.
        let ratio = summary["coverage_ratio"].as_f64().unwrap();
        let floor = if angle == json!("auto") { 0.995 } else { 0.99 };
        assert!(ratio >= floor, "angle {angle}: coverage {ratio}");
        let stats = &plan["stats"];
        assert!(
            stats["cell_count"].as_u64().unwrap() >= 2,
            "an NFZ inside the field splits it"
        );
        // Cells' union equals the flyable area (the free area less the band
        // within the clearance of the NFZs) within 1e-6 relative.
        let cell_area: f64 = plan["cells"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["area_m2"].as_f64().unwrap())
            .sum();
        let free = stats["free_area_m2"].as_f64().unwrap();
        let flyable = stats["flyable_area_m2"].as_f64().unwrap();
        assert!(
            (cell_area - flyable).abs() <= 1e-6 * flyable,
            "cells {cell_area} vs flyable {flyable}"
        );
        assert!(flyable < free, "flyable {flyable} vs free {free}");
        // Every flown segment kept the 5 m clearance (checked by
        // check_survey.py, which also reports the least distance).
        let least = summary["min_nfz_distance_m"].as_f64().unwrap();
        assert!((4.99..6.0).contains(&least), "least NFZ distance {least}");
        // Every cell is flown once.
        let mut flown: Vec<u64> = plan["uavs"][0]["cells"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_u64().unwrap())
            .collect();
        flown.sort();
        let with_lanes: Vec<u64> = plan["cells"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|c| c["lanes"].as_u64().unwrap() > 0)
            .map(|c| c["id"].as_u64().unwrap())
            .collect();
        assert_eq!(flown, with_lanes);
        for f in [
            "uav1.waypoints",
            "uav1.plan",
            "uav1.route.geojson",
            "uav1.fence.waypoints",
            "uav1.kml",
            "cells.geojson",
        ] {
            assert!(dir.path().join("out").join(f).exists(), "{f} missing");
        }
    }
}

#[test]
fn fields2cover_fields_with_generated_nfzs() {
    let dir = tempfile::tempdir().unwrap();
    // Two Illinois fields as one ROI; NFZs inside, across a border, overlapping
    // each other and one entirely outside.
    let roi = shared_data("polygons/fields2cover__test_2_cell.json");
    let nfz = write_json(
        dir.path(),
        "nfz.geojson",
        &json!({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1375, 41.4710, -90.1365, 41.4717)},
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1368, 41.4714, -90.1360, 41.4720)},
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1315, 41.4650, -90.1280, 41.4660)},
            {"type": "Feature", "properties": {}, "geometry": rect(-90.1500, 41.4800, -90.1490, 41.4810)}
        ]}),
    );
    for angle in [json!(0), json!(90), json!("auto")] {
        let params = json!({"altitude_m": 80, "side_overlap": 0.6, "slice_angle_deg": angle});
        let (plan, summary) = plan_and_validate(&roi, &[&nfz], &params, dir.path());
        let ratio = summary["coverage_ratio"].as_f64().unwrap();
        let floor = if angle == json!("auto") { 0.995 } else { 0.99 };
        assert!(ratio >= floor, "angle {angle}: coverage {ratio}");
        assert!(plan["uavs"][0]["stats"]["photos"].as_u64().unwrap() > 0);
    }
}

/// Rally points next to the fences: in every `.plan`, in a rally file per
/// UAV (sorties included), inside the inclusion fence, at the flight
/// altitude above home; MAVSDK and MAVProxy load them (check_missions.py).
#[test]
fn rally_points_in_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let ex = workspace().join("examples");
    // West of the field's start, and inside the field's south-west part.
    let rally = json!([[6.0605, 51.5105], [6.0635, 51.5118]]);
    let params = json!({"altitude_m": 70, "rally_points": rally,
                        "uavs": [{"id": "a", "start": [6.0620, 51.5110], "max_flight_time_s": 100},
                                 {"id": "b", "start": [6.0625, 51.5112]}]});
    let (plan, _) = plan_and_validate(
        &ex.join("field.geojson"),
        &[&ex.join("field-nfz.geojson")],
        &params,
        dir.path(),
    );
    let out = dir.path().join("out");
    assert!(
        plan["uavs"][0]["sorties"].as_array().unwrap().len() >= 2,
        "the battery splits a's mission"
    );
    let summary = check_missions(&out);
    let stems = summary["stems"].as_object().unwrap();
    assert_eq!(
        stems.len(),
        plan["uavs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|u| u["sorties"].as_array().unwrap().len())
            .sum::<usize>()
    );
    for (stem, s) in stems {
        assert_eq!(s["rally_items"], 2, "{stem}");
        assert_eq!(s["mavsdk"]["rally"], 2, "{stem}");
    }
    // The rally file: MAV_CMD_NAV_RALLY_POINT at 70 m above home, per UAV.
    for uav in ["a", "b"] {
        let loaded = validator(
            "load_waypoints.py",
            &[&out.join(format!("{uav}.rally.waypoints"))],
        );
        assert!(loaded.status.success(), "{}", text(&loaded.stderr));
        let loaded: Value = serde_json::from_slice(&loaded.stdout).unwrap();
        assert_eq!(loaded["count"], 2);
        for (item, p) in loaded["items"]
            .as_array()
            .unwrap()
            .iter()
            .zip(rally.as_array().unwrap())
        {
            assert_eq!(
                (item["command"].as_u64(), item["frame"].as_u64()),
                (Some(5100), Some(3))
            );
            assert!((item["lon"].as_f64().unwrap() - p[0].as_f64().unwrap()).abs() < 1e-8);
            assert!((item["lat"].as_f64().unwrap() - p[1].as_f64().unwrap()).abs() < 1e-8);
            assert!((item["alt"].as_f64().unwrap() - 70.0).abs() < 1e-6);
        }
    }
    // The inclusion fence holds both rally points.
    use geo::Contains;
    let ring: Vec<(f64, f64)> =
        serde_json::from_value::<Vec<[f64; 2]>>(plan["fences"][0]["vertices"].clone())
            .unwrap()
            .into_iter()
            .map(|v| (v[0], v[1]))
            .collect();
    assert_eq!(plan["fences"][0]["inclusion"], true);
    let fence = geo_types::Polygon::new(ring.into(), vec![]);
    for p in rally.as_array().unwrap() {
        let pt = geo_types::Point::new(p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
        assert!(
            fence.contains(&pt),
            "rally point {p} outside the inclusion fence"
        );
    }
}

#[test]
fn netherlands_field_default_params() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test.json");
    let (plan, summary) = plan_and_validate(&roi, &[], &json!({}), dir.path());
    assert!(summary["coverage_ratio"].as_f64().unwrap() >= 0.995);
    // Default camera at 60 m: GSD = 60·13.2·100/(5472·8.8) ≈ 1.645 cm/px.
    let gsd = plan["stats"]["gsd_cm_px"].as_f64().unwrap();
    assert!((gsd - 1.6447).abs() < 1e-3, "{gsd}");
    // Starts at the ROI's first vertex by default.
    let start = &plan["uavs"][0]["start"];
    assert!((start[0].as_f64().unwrap() - 6.062131843297665).abs() < 1e-12);
}

/// Defaults that never fail: an empty NFZ collection is no NFZ, and with no
/// UAV given the start skips ROI vertices within the clearance of an NFZ.
#[test]
fn defaults_with_an_empty_nfz_file_and_an_nfz_on_the_first_vertex() {
    let dir = tempfile::tempdir().unwrap();
    let roi = shared_data("polygons/fields2cover__test.json");
    let empty = write_json(
        dir.path(),
        "empty.geojson",
        &json!({"type": "FeatureCollection", "features": []}),
    );
    let (plan, summary) = plan_and_validate(&roi, &[&empty], &json!({}), dir.path());
    assert!(summary["coverage_ratio"].as_f64().unwrap() >= 0.995);
    assert_eq!(
        plan["stats"]["flyable_area_m2"],
        plan["stats"]["free_area_m2"]
    );
    let first = [6.062131843297665, 51.51238564279176];
    assert_eq!(plan["uavs"][0]["start"], json!(first));

    // An NFZ over the first vertex (and 3 m round it): the UAV takes off
    // at the next vertex that is 5 m clear, and the plan says where.
    let nfz = write_json(
        dir.path(),
        "corner.geojson",
        &rect(
            first[0] - 0.0002,
            first[1] - 0.0002,
            first[0] + 0.00005,
            first[1] + 0.00005,
        ),
    );
    let (plan, summary) = plan_and_validate(&roi, &[&nfz], &json!({}), dir.path());
    assert!(summary["coverage_ratio"].as_f64().unwrap() >= 0.99);
    let start = plan["uavs"][0]["start"].clone();
    assert_ne!(start, json!(first));
    let warned = plan["warnings"].as_array().unwrap().iter().any(|w| {
        w.as_str()
            .unwrap()
            .contains("takes off at the ROI's vertex")
    });
    assert!(warned, "{}", plan["warnings"]);
    // The start is a vertex of the ROI, 5 m or more from the NFZ (the
    // validator checked the clearance of the whole flight).
    let ring = std::fs::read_to_string(&roi).unwrap();
    let lon = start[0].as_f64().unwrap();
    assert!(ring.contains(&format!("{lon}")), "{start} is not a vertex");
}

/// Each bad input exits with status 2 and a message naming the fault.
#[test]
fn bad_input_names_its_fault() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cases: Vec<(&str, Value, Option<Value>, Value, &str)> = vec![
        (
            "self-intersecting ROI",
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 52.003], [5.005, 52.0], [5.0, 52.003], [5.0, 52.0]]]}),
            None,
            json!({}),
            "self-intersects",
        ),
        (
            "NFZ covering the ROI",
            rect(5.0, 52.0, 5.005, 52.003),
            Some(rect(4.99, 51.99, 5.01, 52.01)),
            json!({}),
            "cover the whole region",
        ),
        (
            "empty ring",
            json!({"type": "Polygon", "coordinates": [[]]}),
            None,
            json!({}),
            "ring is empty",
        ),
        (
            "unclosable ring",
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 52.003]]]}),
            None,
            json!({}),
            "too short",
        ),
        (
            "latitude 95",
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 95.0], [5.0, 52.003], [5.0, 52.0]]]}),
            None,
            json!({}),
            "latitude 95",
        ),
        (
            "NaN",
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, "NaN"], [5.0, 52.003], [5.0, 52.0]]]}),
            None,
            json!({}),
            "finite number",
        ),
        (
            "overlap 1",
            rect(5.0, 52.0, 5.005, 52.003),
            None,
            json!({"side_overlap": 1.0}),
            "side_overlap: 1 is outside",
        ),
        (
            "negative altitude",
            rect(5.0, 52.0, 5.005, 52.003),
            None,
            json!({"altitude_m": -10}),
            "altitude_m: -10 is outside",
        ),
        (
            "unknown geometry type",
            json!({"type": "Circle", "coordinates": [5.0, 52.0]}),
            None,
            json!({}),
            "unknown GeoJSON type",
        ),
        (
            "too large",
            rect(5.0, 52.0, 5.3, 52.3),
            None,
            json!({}),
            "too large",
        ),
        (
            "start inside an NFZ",
            rect(5.0, 52.0, 5.005, 52.003),
            Some(rect(5.001, 52.001, 5.002, 52.002)),
            json!({"uavs": [{"id": "mapper", "start": [5.0012, 52.0015]}]}),
            "UAV mapper's start position is inside a no-fly zone, 13.",
        ),
        (
            "clearance swallowing the field",
            rect(5.0, 52.0, 5.001, 52.0005),
            Some(rect(5.0005, 51.99, 5.0006, 52.01)),
            json!({"nfz_clearance_m": 40}),
            "leave nothing of the region of interest to fly over",
        ),
        (
            "UAV id twice",
            rect(5.0, 52.0, 5.005, 52.003),
            None,
            json!({"uavs": [{"id": "a", "start": [5.0, 52.0]}, {"id": "a", "start": [5.0, 52.0]}]}),
            "given twice",
        ),
        (
            "battery too small to reach the area",
            rect(5.0, 52.0, 5.005, 52.003),
            None,
            json!({"uavs": [{"id": "a", "start": [4.99, 52.0], "max_flight_time_s": 60}]}),
            "within its battery",
        ),
        (
            "start in NFZ",
            rect(5.0, 52.0, 5.005, 52.003),
            Some(rect(5.001, 52.001, 5.002, 52.002)),
            json!({"uavs": [{"id": "a", "start": [5.0015, 52.0015]}]}),
            "inside a no-fly zone",
        ),
        (
            "rally point in NFZ",
            rect(5.0, 52.0, 5.005, 52.003),
            Some(rect(5.001, 52.001, 5.002, 52.002)),
            json!({"rally_points": [[4.999, 52.0], [5.0015, 52.0015]]}),
            "/rally_points/1: rally point 2 (5.0015, 52.0015) is inside a no-fly zone",
        ),
        (
            "rally point with lon and lat swapped",
            rect(5.0, 52.0, 5.005, 52.003),
            None,
            json!({"rally_points": [[52.0, 5.0]]}),
            "/rally_points/0: rally point 1 (52, 5) is",
        ),
    ];
    for (name, roi, nfz, params, expect) in cases {
        let roi_p = write_json(d, "case-roi.json", &roi);
        let params_p = write_json(d, "case-params.json", &params);
        let mut args = vec![
            "survey".to_string(),
            "--roi".into(),
            roi_p.display().to_string(),
        ];
        if let Some(n) = nfz {
            args.extend([
                "--no-fly".into(),
                write_json(d, "case-nfz.json", &n).display().to_string(),
            ]);
        }
        args.extend([
            "--params".into(),
            params_p.display().to_string(),
            "--out".into(),
            d.join("o").display().to_string(),
        ]);
        let argv: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = terraplan(&argv);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {err}");
        assert!(
            err.contains(expect),
            "{name}: expected {expect:?} in {err:?}"
        );
    }
    // Unreadable and malformed files are input errors too.
    let o = terraplan(&[
        "survey",
        "--roi",
        "/nonexistent.geojson",
        "--out",
        d.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("cannot read ROI file"));
    std::fs::write(d.join("broken.json"), "{\"type\": ").unwrap();
    let o = terraplan(&[
        "survey",
        "--roi",
        d.join("broken.json").to_str().unwrap(),
        "--out",
        d.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("not valid JSON"));
}

/// `terraplan survey --dem`: the same terrain following as the service,
/// checked against GDAL; a DEM that misses the ROI is an input error naming
/// the DEM file.
#[test]
fn survey_over_a_dem_file() {
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
        &rect(cx - hx, cy - hy, cx + hx, cy + hy),
    );
    let params = write_json(
        dir.path(),
        "params.json",
        &json!({"altitude_m": 35, "agl_tolerance_m": 4, "altitude_frame": "terrain",
                "uavs": [{"id": "t1", "start": [cx - hx, cy - hy]}],
                "rally_points": [[cx + hx, cy + hy]]}),
    );
    let out = dir.path().join("out");
    let files = SurveyFiles {
        area: SurveyArea::Roi(&roi),
        no_fly: &[],
        dem: Some(&dem),
        params: &params,
    };
    survey_cli(&files, &out, "survey over a DEM file");
    check_terrain(
        &dem,
        &out.join("plan.json"),
        "t1",
        &[&out.join("t1.waypoints")],
    );
    let wp = validator("load_waypoints.py", &[&out.join("t1.waypoints")]);
    assert!(wp.status.success(), "{}", text(&wp.stderr));
    check_missions(&out);
    // The rally point is flown at least 35 m above the DEM under it, and
    // no lower than the mission's highest point (heights above home).
    let plan: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap();
    let ground = plan["rally_points"][0]["ground_amsl_m"].as_f64().unwrap();
    let terrain = &plan["uavs"][0]["sorties"][0]["terrain"];
    let home = terrain["home_amsl_m"].as_f64().unwrap();
    let highest = terrain["max_altitude_m"].as_f64().unwrap() - home;
    let rally = validator("load_waypoints.py", &[&out.join("t1.rally.waypoints")]);
    assert!(rally.status.success(), "{}", text(&rally.stderr));
    let rally: Value = serde_json::from_slice(&rally.stdout).unwrap();
    let alt = rally["items"][0]["alt"].as_f64().unwrap();
    assert!(
        (alt - (ground + 35.0 - home).max(highest)).abs() < 1e-5,
        "rally altitude {alt}, ground {ground}, home {home}, highest {highest}"
    );

    let far = write_json(dir.path(), "far.json", &rect(10.0, 50.0, 10.001, 50.001));
    let o = terraplan(&[
        "survey",
        "--roi",
        far.to_str().unwrap(),
        "--dem",
        dem.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = text(&o.stderr);
    assert!(err.contains("DEM ") && err.contains("no heights"), "{err}");
}
