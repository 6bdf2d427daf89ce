//! `terraplan serve` end to end over HTTP: the surveys resource, its files
//! (checked by pymavlink), persistence across a restart, and problem+json
//! errors. Runs on SQLite, and on PostgreSQL when the test command sets
//! `TERRAPLAN_TEST_DATABASE_URL`.

use std::io::{Read, Write};

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, assert_invalid_at, assert_problem, delete, example_survey_request, get, post,
    post_json, validator,
};

fn example_request() -> Value {
    let mut req = example_survey_request();
    req["name"] = json!("field with a mast");
    req["altitude_m"] = json!(60);
    req["uavs"] = json!([{"id": "uav1", "start": [6.0620, 51.5110]}]);
    req
}

#[test]
fn create_get_list_download_delete() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let health = get(&server.url("/healthz"));
    assert_eq!(health.status, 200);
    assert_eq!(health.json()["status"], "ok");

    let r = post_json(&server.url("/api/v1/surveys"), &example_request());
    assert_eq!(r.status, 201, "{}", r.text());
    let created = r.json();
    let id = created["id"].as_str().unwrap().to_string();
    assert_eq!(
        r.header("location"),
        Some(format!("/api/v1/surveys/{id}").as_str())
    );
    assert_eq!(created["name"], "field with a mast");
    assert!(created["stats"]["coverage_ratio"].as_f64().unwrap() >= 0.995);
    assert_eq!(created["cells"]["type"], "FeatureCollection");
    let uav = &created["uavs"][0]["sorties"][0];
    assert_eq!(uav["route"]["type"], "LineString");
    // No DEM: the ground's height above the ellipsoid is unknown, so the
    // positions are 2D (RFC 7946) and the mission's altitudes stand beside.
    let route = uav["route"]["coordinates"].as_array().unwrap();
    assert_eq!(route[1].as_array().unwrap().len(), 2);
    let altitudes = uav["mission_altitudes_m"].as_array().unwrap();
    assert_eq!(altitudes.len(), route.len());
    assert_eq!(altitudes[0], 0.0);
    assert_eq!(altitudes[1], created["stats"]["altitude_m"]);

    let r = get(&server.url(&format!("/api/v1/surveys/{id}")));
    assert_eq!(r.status, 200);
    assert_eq!(r.json(), created);
    // The request comes back (without its name), so a client can reopen it.
    let mut asked = example_request();
    asked.as_object_mut().unwrap().remove("name");
    assert_eq!(created["request"], asked);

    let r = get(&server.url("/api/v1/surveys?limit=10"));
    assert_eq!(r.status, 200);
    let list = r.json();
    assert!(
        list["items"]
            .as_array()
            .unwrap()
            .iter()
            .any(|s| s["id"] == id.as_str())
    );

    // Every file, with its content type and download name.
    let files = &uav["files"];
    let wp = get(&server.url(files["waypoints"].as_str().unwrap()));
    assert_eq!(wp.status, 200);
    assert!(wp.header("content-type").unwrap().starts_with("text/plain"));
    let disposition = wp.header("content-disposition").unwrap();
    assert!(
        disposition.starts_with("attachment; filename=\"terraplan-")
            && disposition.ends_with("-uav1.waypoints\""),
        "{disposition}"
    );
    let wp_path = dir.path().join("m.waypoints");
    std::fs::write(&wp_path, &wp.body).unwrap();
    let loaded = validator("load_waypoints.py", &[&wp_path]);
    assert!(
        loaded.status.success(),
        "{}",
        terraplan_e2e::text(&loaded.stderr)
    );
    let loaded: Value = serde_json::from_slice(&loaded.stdout).unwrap();
    // pymavlink's waypoints equal the route's points (route = home, waypoints, home).
    let nav: Vec<&Value> = loaded["items"]
        .as_array()
        .unwrap()
        .iter()
        .skip(1)
        .filter(|i| i["command"] == 16)
        .collect();
    let route = uav["route"]["coordinates"].as_array().unwrap();
    assert_eq!(nav.len() + 2, route.len());
    for (w, c) in nav.iter().zip(&route[1..]) {
        assert!((w["lon"].as_f64().unwrap() - c[0].as_f64().unwrap()).abs() < 1e-6);
        assert!((w["lat"].as_f64().unwrap() - c[1].as_f64().unwrap()).abs() < 1e-6);
    }

    let plan = get(&server.url(files["plan"].as_str().unwrap()));
    assert_eq!(plan.header("content-type"), Some("application/json"));
    let plan_path = dir.path().join("m.plan");
    std::fs::write(&plan_path, &plan.body).unwrap();
    let clear = terraplan_e2e::assert_clearance(
        &created,
        &wp_path,
        &plan_path,
        &example_request()["no_fly_zones"],
    );
    assert!(
        clear["min_nfz_distance_m"].as_f64().unwrap() >= 4.99,
        "{clear}"
    );
    assert_eq!(plan.json()["fileType"], "Plan");
    assert_eq!(
        plan.json()["geoFence"]["polygons"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
    let route_file = get(&server.url(files["route"].as_str().unwrap()));
    assert_eq!(
        route_file.header("content-type"),
        Some("application/geo+json")
    );
    assert_eq!(route_file.json()["features"][0]["geometry"], uav["route"]);
    let props = &route_file.json()["features"][0]["properties"];
    assert_eq!(props["mission_altitudes_m"], uav["mission_altitudes_m"]);
    assert!(
        props["height_reference"]
            .as_str()
            .unwrap()
            .starts_with("none")
    );
    let kml = get(&server.url(files["kml"].as_str().unwrap()));
    assert_eq!(
        kml.header("content-type"),
        Some("application/vnd.google-earth.kml+xml")
    );
    assert!(kml.text().contains("<LineString>"));
    let fence = get(&server.url(files["fence"].as_str().unwrap()));
    assert!(fence.text().starts_with("QGC WPL 110\n"));
    let cells = get(&server.url(created["files"]["cells"].as_str().unwrap()));
    assert_eq!(cells.header("content-type"), Some("application/geo+json"));
    assert_eq!(cells.json(), created["cells"]);
    assert_eq!(
        get(&server.url(&format!("/api/v1/surveys/{id}/uavs/nope/mission.plan"))).status,
        404
    );
    assert_eq!(
        get(&server.url(&format!("/api/v1/surveys/{id}/uavs/uav1/mission.exe"))).status,
        404
    );

    let r = delete(&server.url(&format!("/api/v1/surveys/{id}")));
    assert_eq!(r.status, 204);
    assert_problem(
        &get(&server.url(&format!("/api/v1/surveys/{id}"))),
        404,
        "no survey",
    );
    assert_problem(
        &delete(&server.url(&format!("/api/v1/surveys/{id}"))),
        404,
        "no survey",
    );
    assert!(server.stop().success());
}

/// The camera presets a survey may name, with their numbers; each is
/// accepted by `POST /api/v1/surveys`.
#[test]
fn camera_presets_are_listed_and_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let r = get(&server.url("/api/v1/cameras"));
    assert_eq!(r.status, 200);
    let items = r.json()["items"].as_array().unwrap().clone();
    assert_eq!(items.len(), 7);
    assert_eq!(items[0]["name"], "dji_phantom4_pro");
    assert_eq!(items[0]["camera"]["sensor_width_mm"], 13.2);
    for item in &items {
        assert!(item["camera"]["focal_length_mm"].as_f64().unwrap() > 0.0);
        let mut req = example_request();
        req["camera_preset"] = item["name"].clone();
        let r = post_json(&server.url("/api/v1/surveys"), &req);
        assert_eq!(r.status, 201, "{}: {}", item["name"], r.text());
    }
}

#[test]
fn surveys_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let r = post_json(&server.url("/api/v1/surveys"), &example_request());
    assert_eq!(r.status, 201, "{}", r.text());
    let created = r.json();
    let id = created["id"].as_str().unwrap().to_string();
    assert!(server.stop().success(), "graceful shutdown exits 0");

    let server = Server::start(dir.path(), &[]);
    let r = get(&server.url(&format!("/api/v1/surveys/{id}")));
    assert_eq!(r.status, 200);
    assert_eq!(r.json(), created);
    // The request comes back (without its name), so a client can reopen it.
    let mut asked = example_request();
    asked.as_object_mut().unwrap().remove("name");
    assert_eq!(created["request"], asked);
    let wp = get(&server.url(
        created["uavs"][0]["sorties"][0]["files"]["waypoints"]
            .as_str()
            .unwrap(),
    ));
    assert_eq!(wp.status, 200);
}

#[test]
fn newest_first_pagination() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let mut ids = Vec::new();
    for i in 0..3 {
        let mut req = example_request();
        req["name"] = json!(format!("survey {i}"));
        let r = post_json(&server.url("/api/v1/surveys"), &req);
        assert_eq!(r.status, 201);
        ids.push(r.json()["id"].as_str().unwrap().to_string());
    }
    let page = get(&server.url("/api/v1/surveys?limit=2&offset=0")).json();
    let got: Vec<&str> = page["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    // Other tests may share a PostgreSQL database: check order among ours.
    let ours: Vec<&String> = ids.iter().rev().collect();
    let pos = |id: &str| ours.iter().position(|o| o.as_str() == id);
    let positions: Vec<usize> = got.iter().filter_map(|g| pos(g)).collect();
    assert!(positions.windows(2).all(|w| w[0] < w[1]), "{positions:?}");
    assert_eq!(page["limit"], 2);
    assert!(page["total"].as_i64().unwrap() >= 3);
    let bad = get(&server.url("/api/v1/surveys?limit=0"));
    assert_problem(&bad, 400, "limit 0");
    let bad = get(&server.url("/api/v1/surveys?limit=abc"));
    assert_problem(&bad, 400, "query");
}

#[test]
fn bad_input_is_a_problem_naming_the_fault() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let url = server.url("/api/v1/surveys");
    let rect = |x0: f64, y0: f64, x1: f64, y1: f64| json!({"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]});
    let small = rect(5.0, 52.0, 5.005, 52.003);
    let cases: Vec<(&str, Value, &str, &str)> = vec![
        (
            "self-intersecting ROI",
            json!({"roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 52.003], [5.005, 52.0], [5.0, 52.003], [5.0, 52.0]]]}}),
            "/roi/coordinates/0",
            "self-intersects",
        ),
        (
            "NFZ covering the ROI",
            json!({"roi": small, "no_fly_zones": [rect(4.99, 51.99, 5.01, 52.01)]}),
            "/no_fly_zones",
            "cover the whole",
        ),
        (
            "empty ring",
            json!({"roi": {"type": "Polygon", "coordinates": [[]]}}),
            "/roi/coordinates/0",
            "empty",
        ),
        (
            "unclosable ring",
            json!({"roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.1, 52.1]]]}}),
            "/roi/coordinates/0",
            "too short",
        ),
        (
            "latitude 95",
            json!({"roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 95.0], [5.0, 52.003], [5.0, 52.0]]]}}),
            "/roi/coordinates/0/1/1",
            "latitude 95",
        ),
        (
            "NaN",
            json!({"roi": {"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, "NaN"], [5.0, 52.003], [5.0, 52.0]]]}}),
            "/roi/coordinates/0/1/1",
            "finite number",
        ),
        (
            "overlap 1",
            json!({"roi": small, "side_overlap": 1.0}),
            "/side_overlap",
            "outside",
        ),
        (
            "negative altitude",
            json!({"roi": small, "altitude_m": -10}),
            "/altitude_m",
            "outside",
        ),
        (
            "unknown geometry type",
            json!({"roi": {"type": "Circle", "coordinates": [5.0, 52.0]}}),
            "/roi/type",
            "unknown GeoJSON type",
        ),
        ("missing ROI", json!({"altitude_m": 50}), "/roi", "required"),
        (
            "unknown field",
            json!({"roi": small, "altitud_m": 50}),
            "/altitud_m",
            "unknown field",
        ),
        (
            "wrong type",
            json!({"roi": small, "speed_m_s": "fast"}),
            "/speed_m_s",
            "invalid type",
        ),
        (
            "65 UAVs",
            json!({"roi": small, "uavs": (0..65).map(|i| json!({"id": format!("u{i}"), "start": [5.0, 52.0]})).collect::<Vec<_>>()}),
            "/uavs",
            "at most 64",
        ),
        (
            "UAV id twice",
            json!({"roi": small, "uavs": [{"id": "a", "start": [5.0, 52.0]}, {"id": "a", "start": [5.001, 52.0]}]}),
            "/uavs/1/id",
            "given twice",
        ),
        (
            "UAV speed 0",
            json!({"roi": small, "uavs": [{"id": "a", "start": [5.0, 52.0], "speed_m_s": 0}]}),
            "/uavs/0/speed_m_s",
            "outside the allowed range",
        ),
        (
            "battery of 5 s",
            json!({"roi": small, "uavs": [{"id": "a", "start": [5.0, 52.0], "max_flight_time_s": 5}]}),
            "/uavs/0/max_flight_time_s",
            "outside the allowed range",
        ),
        (
            "battery too small to reach the area",
            json!({"roi": small, "uavs": [{"id": "a", "start": [4.99, 52.0], "max_flight_time_s": 60}]}),
            "/uavs/0/max_flight_time_s",
            "within its battery",
        ),
        (
            "unknown policy",
            json!({"roi": small, "assignment": "fastest"}),
            "/assignment",
            "unknown variant",
        ),
        ("not an object", json!([1, 2]), "", "JSON object"),
    ];
    for (name, body, pointer, msg) in cases {
        assert_invalid_at(&post_json(&url, &body), name, pointer, msg);
    }
    assert_problem(
        &post(&url, "application/json", b"{\"roi\": "),
        400,
        "not valid JSON",
    );
    assert_problem(&post(&url, "application/json", b""), 400, "empty");
    assert_problem(&post(&url, "text/plain", b"{}"), 415, "Content-Type");
    assert_problem(
        &get(&server.url("/api/v1/nothing-here")),
        404,
        "no resource",
    );
    assert_problem(
        &get(&server.url("/api/v1/surveys/00000000-0000-0000-0000-000000000000")),
        404,
        "no survey",
    );
    assert_problem(&delete(&server.url("/healthz")), 405, "not allowed");

    // A 100 MB body is refused from its Content-Length, without reading it.
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut s = std::net::TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(std::time::Duration::from_secs(30)))
        .unwrap();
    let len = 100 * 1024 * 1024;
    write!(s, "POST /api/v1/surveys HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/json\r\nContent-Length: {len}\r\nConnection: close\r\n{}\r\n", server.auth_line()).unwrap();
    let _ = s.write_all(&vec![b' '; 1024 * 1024]);
    let mut resp = Vec::new();
    let _ = s.read_to_end(&mut resp);
    let resp = String::from_utf8_lossy(&resp);
    assert!(resp.starts_with("HTTP/1.1 413"), "{resp}");
    assert!(
        resp.contains("application/problem+json") && resp.contains("too large"),
        "{resp}"
    );

    // The server is still healthy after all that.
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

#[test]
fn openapi_document_and_docs_page() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let r = get(&server.url("/api/v1/openapi.json"));
    assert_eq!(r.status, 200);
    let doc = r.json();
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    let paths = doc["paths"].as_object().unwrap();
    for p in [
        "/healthz",
        "/api/v1/surveys",
        "/api/v1/surveys/{id}",
        "/api/v1/surveys/{id}/uavs/{uav}/{file}",
        "/api/v1/surveys/{id}/cells.geojson",
    ] {
        assert!(
            paths.contains_key(p),
            "{p} missing from the OpenAPI document"
        );
    }
    let params = &doc["components"]["schemas"]["CreateSurvey"]["properties"];
    // The area is `roi` or `corridor`: neither is required alone (the
    // planner answers 422 at both pointers when both or neither are given).
    assert_eq!(
        doc["components"]["schemas"]["CreateSurvey"]["required"],
        Value::Null
    );
    assert_eq!(params["roi"]["type"], "object");
    assert_eq!(params["corridor"]["type"], "object");
    assert_eq!(params["corridor_width_m"]["maximum"], 2000.0);
    assert_eq!(params["side_overlap"]["maximum"], 0.95);
    assert_eq!(params["side_overlap"]["default"], 0.7);
    // A DEM's CRS carries its PROJ.4 definition for the web page.
    let proj4 = &doc["components"]["schemas"]["Crs"]["properties"]["proj4"];
    assert_eq!(proj4["type"], "string", "{proj4}");
    assert!(
        proj4["description"]
            .as_str()
            .is_some_and(|d| d.contains("proj4js")),
        "{proj4}"
    );
    let page = get(&server.url("/api/docs/"));
    assert_eq!(page.status, 200);
    assert!(
        page.text().contains("swagger"),
        "docs page is served locally"
    );
}

/// SIGTERM while a heavy plan is being computed: the request still gets
/// its 201, the survey is stored, and the server exits cleanly.
#[test]
fn graceful_shutdown_finishes_in_flight_requests() {
    let dir = tempfile::tempdir().unwrap();
    // tower-http logs each request as it starts at DEBUG.
    let server = Server::start_logging(dir.path(), &[], "info,tower_http=debug");
    // ~90 km² at 25 m: about a second of planning (debug build).
    let body = json!({
        "roi": {"type": "Polygon", "coordinates": [[[8.50, 47.0], [8.62, 47.0], [8.62, 47.085], [8.50, 47.085], [8.50, 47.0]]]},
        "altitude_m": 25,
    });
    let url = server.url("/api/v1/surveys");
    let client = std::thread::spawn(move || post_json(&url, &body));
    // SIGTERM once the server has the request (a request it has not
    // accepted yet is refused at shutdown, rightly): planning takes ~0.5 s,
    // so it lands mid-plan.
    server.wait_for_log(
        &["started processing request", "uri=/api/v1/surveys"],
        std::time::Duration::from_secs(120),
    );
    let data_dir = server.data_dir.clone();
    let status = server.stop();
    let reply = client.join().unwrap();
    assert_eq!(reply.status, 201, "{}", reply.text());
    assert!(status.success(), "exit status {status:?}");
    let id = reply.json()["id"].as_str().unwrap().to_string();
    let server = Server::start(&data_dir, &[]);
    assert_eq!(
        get(&server.url(&format!("/api/v1/surveys/{id}"))).status,
        200
    );
}

/// Rally points through the API: each UAV's `mission.plan`,
/// `mission.waypoints`, `fence.waypoints` and `rally.waypoints`, downloaded,
/// agree item by item and load in pymavlink, MAVSDK and MAVProxy
/// (check_missions.py); a rally point in a no-fly zone is a 422 at its
/// pointer, and a survey without rally points has no rally file.
#[test]
fn rally_points_downloaded_load_in_mavsdk_and_mavproxy() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let mut req = example_request();
    req["rally_points"] = json!([[6.0605, 51.5105]]);
    req["uavs"] = json!([{"id": "uav1", "start": [6.0620, 51.5110]},
                         {"id": "uav2", "start": [6.0625, 51.5112]}]);
    let r = post_json(&server.url("/api/v1/surveys"), &req);
    assert_eq!(r.status, 201, "{}", r.text());
    let created = r.json();
    let out = dir.path().join("files");
    std::fs::create_dir(&out).unwrap();
    for uav in created["uavs"].as_array().unwrap() {
        let id = uav["id"].as_str().unwrap();
        let sorties = uav["sorties"].as_array().unwrap();
        assert_eq!(sorties.len(), 1);
        let files = &sorties[0]["files"];
        for (key, name) in [
            ("plan", format!("{id}.plan")),
            ("waypoints", format!("{id}.waypoints")),
            ("fence", format!("{id}.fence.waypoints")),
            ("rally", format!("{id}.rally.waypoints")),
        ] {
            let url = files[key]
                .as_str()
                .unwrap_or_else(|| panic!("no {key} link in {files}"));
            let f = get(&server.url(url));
            assert_eq!(f.status, 200, "{url}: {}", f.text());
            std::fs::write(out.join(name), &f.body).unwrap();
        }
    }
    let summary = terraplan_e2e::check_missions(&out);
    for id in ["uav1", "uav2"] {
        let s = &summary["stems"][id];
        assert_eq!(s["rally_items"], 1, "{summary}");
        assert_eq!(s["mavsdk"]["rally"], 1, "{summary}");
        assert!(s["items"].as_u64().unwrap() > 3, "{summary}");
    }

    // In the middle of the example's mast NFZ: refused at its pointer.
    let mut bad = req.clone();
    bad["rally_points"] = json!([[6.0605, 51.5105], [6.0635, 51.512125]]);
    let r = post_json(&server.url("/api/v1/surveys"), &bad);
    assert_invalid_at(
        &r,
        "rally point in an NFZ",
        "/rally_points/1",
        "inside a no-fly zone",
    );

    // Without rally points: no link, and the file is a 404 that says why.
    let r = post_json(&server.url("/api/v1/surveys"), &example_request());
    assert_eq!(r.status, 201, "{}", r.text());
    let plain = r.json();
    let files = &plain["uavs"][0]["sorties"][0]["files"];
    assert!(files.get("rally").is_none(), "{files}");
    let url = files["fence"]
        .as_str()
        .unwrap()
        .replace("fence.waypoints", "rally.waypoints");
    let r = get(&server.url(&url));
    assert_problem(&r, 404, "no rally points");
}

/// Issue 17, part 3: counts are refused before any per-member work, the
/// list of faults is capped, and the service stays responsive meanwhile.
#[test]
fn huge_lists_get_a_short_answer() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let url = server.url("/api/v1/surveys");
    let roi = json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.005, 52.0], [5.005, 52.003], [5.0, 52.0]]]});
    // 20 000 UAVs with one id: one fault, the count.
    let uavs: Vec<Value> = (0..20_000)
        .map(|_| json!({"id": "a", "start": [5.0, 52.0]}))
        .collect();
    let r = post_json(&url, &json!({"roi": roi, "uavs": uavs}));
    assert_eq!(r.status, 422, "{}", r.text());
    let errors = r.json()["errors"].as_array().unwrap().clone();
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert!(
        errors[0]["message"]
            .as_str()
            .unwrap()
            .starts_with("20000 UAVs given")
    );
    // 50 000 empty NFZs: at most 100 faults, the last says how many more.
    let empty = json!({"type": "Polygon", "coordinates": []});
    let r = post_json(
        &url,
        &json!({"roi": roi, "no_fly_zones": vec![empty; 50_000]}),
    );
    assert_eq!(r.status, 422);
    assert!(r.body.len() < 64 * 1024, "{} bytes", r.body.len());
    let errors = r.json()["errors"].as_array().unwrap().clone();
    assert_eq!(errors.len(), 100);
    assert!(
        errors[99]["message"]
            .as_str()
            .unwrap()
            .contains("more problems")
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);
    assert!(server.stop().success());
}
