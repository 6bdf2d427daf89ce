//! `POST /api/v1/surveys/{id}/uavs/{uav}/upload` against the real
//! `terraplan serve`: a stored survey's mission (and fence and rally
//! points) sent over MAVLink on 127.0.0.1 to MAVSDK's MissionRawServer
//! (tests/validators/mavsdk_vehicle.py) and to a pymavlink vehicle that
//! loses and repeats messages, refuses or stores a wrong item
//! (tests/validators/mavlink_vehicle.py); what each vehicle stored is
//! compared with the survey's files as the API serves them. Also: the
//! event stream's order, a dead address, the allow-list
//! (`serve --vehicle-links`), one upload per address, a client that goes
//! away, the endpoint switched off, and other users' surveys.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use terraplan_e2e::vehicles::{
    assert_fence_and_rally, assert_items_equal, free_udp_port, items, mavsdk_vehicle,
    pymavlink_vehicle, wpl_items,
};
use terraplan_e2e::{
    Auth, Reply, Server, assert_invalid_at, assert_problem, example_survey_request, get, get_as,
    last_line, post_json, post_json_as, sse_events, text, unique_user_name, user_command,
};

/// The allow-list of the servers here: any UDP port on 127.0.0.1.
const LINKS: &str = "udpout:127.0.0.1:*";

/// The example field planned through the API with rally points, for one
/// UAV: the survey's id.
fn stored_survey(server: &Server) -> String {
    let mut req = example_survey_request();
    req["altitude_m"] = json!(70);
    req["rally_points"] = json!([[6.0605, 51.5105], [6.0635, 51.5118]]);
    req["uavs"] = json!([{"id": "u1", "start": [6.0620, 51.5110]}]);
    let r = post_json(&server.url("/api/v1/surveys"), &req);
    assert_eq!(r.status, 201, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

/// The rows of a QGC WPL 110 file served by the API, as MISSION_ITEM_INT
/// fields.
fn wpl_rows(server: &Server, survey: &str, file: &str) -> Vec<Value> {
    let r = get(&server.url(&format!("/api/v1/surveys/{survey}/uavs/u1/{file}")));
    assert_eq!(r.status, 200, "{file}: {}", r.text());
    wpl_items(&r.text())
}

fn upload_url(server: &Server, survey: &str, uav: &str) -> String {
    server.url(&format!("/api/v1/surveys/{survey}/uavs/{uav}/upload"))
}

/// POST an upload and read its whole event stream.
fn upload(server: &Server, survey: &str, body: &Value) -> Vec<(String, Value)> {
    let r = post_json(&upload_url(server, survey, "u1"), body);
    events_of(&r)
}

fn events_of(r: &Reply) -> Vec<(String, Value)> {
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(
        r.header("content-type"),
        Some("text/event-stream"),
        "{}",
        r.text()
    );
    sse_events(&r.text())
}

/// The stream's rules: `started` first, naming the lists; per list its
/// upload progress up to its total, then its read-back up to its total,
/// then `verified`, in the order started named; each event's name is its
/// `event` member and its `to` the address; one last event, `done` or
/// `failed`. Returns the last event.
fn check_order(events: &[(String, Value)], to: &str) -> Value {
    assert!(events.len() >= 2, "{events:?}");
    for (name, data) in events {
        assert_eq!(data["event"], name.as_str(), "{data}");
        assert_eq!(data["to"], to, "{data}");
    }
    let (first, started) = &events[0];
    assert_eq!(first, "started", "{events:?}");
    let lists = items(&started["lists"]);
    let (last_name, last) = events.last().unwrap();
    assert!(last_name == "done" || last_name == "failed", "{events:?}");
    let mut list = 0;
    // (stage, done) of the current list: upload then read_back, never back.
    let mut at: (u8, u64) = (0, 0);
    for (name, data) in &events[1..events.len() - 1] {
        let want_kind = &lists[list]["kind"];
        let total = lists[list]["items"].as_u64().unwrap();
        assert_eq!(&data["kind"], want_kind, "{data} (lists {lists:?})");
        match name.as_str() {
            "progress" => {
                let stage = match data["stage"].as_str() {
                    Some("upload") => 0,
                    Some("read_back") => 1,
                    other => panic!("stage {other:?}"),
                };
                let done = data["done"].as_u64().unwrap();
                assert_eq!(data["total"].as_u64(), Some(total), "{data}");
                assert!(done <= total, "{data}");
                assert!((stage, done) >= at, "{data} after {at:?}");
                if stage > at.0 {
                    assert_eq!(at.1, total, "read-back before the upload ended: {data}");
                }
                at = (stage, done);
            }
            "verified" => {
                assert_eq!(at, (1, total), "verified before the read-back: {data}");
                assert_eq!(data["done"].as_u64(), Some(total));
                list += 1;
                at = (0, 0);
            }
            other => panic!("unexpected event {other}: {data}"),
        }
    }
    if last_name == "done" {
        assert_eq!(list, lists.len(), "done before every list: {events:?}");
        assert_eq!(last["sent"], started["lists"], "{last}");
    }
    last.clone()
}

#[test]
fn mavsdk_mission_raw_server_receives_the_stored_mission() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let survey = stored_survey(&server);
    let rows = wpl_rows(&server, &survey, "mission.waypoints");
    assert!(rows.len() > 20, "{}", rows.len());
    let vehicle = mavsdk_vehicle(dir.path());
    let events = upload(&server, &survey, &json!({"to": vehicle.address()}));
    let last = check_order(&events, &vehicle.address());
    assert_eq!(last["event"], "done", "{events:?}");
    assert_eq!(
        last["sent"],
        json!([{"kind": "mission", "items": rows.len()}])
    );
    // Progress reached the vehicle's side: every item of both stages.
    assert!(
        events.iter().any(
            |(_, d)| d["stage"] == "read_back" && d["done"].as_u64() == Some(rows.len() as u64)
        )
    );
    let stored = vehicle.stored_when(|v| v["missions"].as_array().is_some_and(|m| !m.is_empty()));
    let missions = items(&stored["missions"]);
    assert_eq!(missions.len(), 1, "{stored}");
    assert_eq!(missions[0]["result"], "SUCCESS", "{stored}");
    assert_items_equal("MAVSDK mission", &items(&missions[0]["items"]), &rows, 0.0);
}

#[test]
fn lossy_vehicle_gets_the_mission_fence_and_rally_points_of_the_stored_plan() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let survey = stored_survey(&server);
    let rows = wpl_rows(&server, &survey, "mission.waypoints");
    let fence = wpl_rows(&server, &survey, "fence.waypoints");
    let rally = wpl_rows(&server, &survey, "rally.waypoints");
    assert_eq!(rally.len(), 2);
    for seed in ["1", "2"] {
        let vehicle = pymavlink_vehicle(
            dir.path(),
            &["--seed", seed, "--drop", "0.15", "--repeat", "0.15"],
        );
        let events = upload(
            &server,
            &survey,
            &json!({"to": vehicle.address(), "fence": true, "rally": true,
                    "timeout_ms": 150, "retries": 8}),
        );
        let last = check_order(&events, &vehicle.address());
        assert_eq!(last["event"], "done", "seed {seed}: {events:?}");
        let kinds: Vec<Value> = items(&last["sent"])
            .iter()
            .map(|l| l["kind"].clone())
            .collect();
        assert_eq!(kinds, [json!("mission"), json!("fence"), json!("rally")]);
        let stored = vehicle.stored_when(|v| v["rally"].as_array().is_some_and(|r| !r.is_empty()));
        // The losses happened, and were recovered.
        assert!(stored["dropped"].as_u64().unwrap() > 0, "seed {seed}");
        assert!(stored["repeated"].as_u64().unwrap() > 0, "seed {seed}");
        assert_items_equal(
            &format!("seed {seed} mission"),
            &items(&stored["mission"]),
            &rows,
            0.0,
        );
        // The .plan's fence, with its breach return point, and the rally points.
        assert_fence_and_rally(&format!("seed {seed}"), &stored, &fence, &rally);
    }
}

#[test]
fn a_refusal_a_wrong_read_back_and_a_dead_address_end_in_a_failed_event() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let survey = stored_survey(&server);

    // A NACK of the fence, after the mission arrived.
    let vehicle = pymavlink_vehicle(dir.path(), &["--nack", "fence:MAV_MISSION_NO_SPACE"]);
    let events = upload(
        &server,
        &survey,
        &json!({"to": vehicle.address(), "fence": true}),
    );
    let last = check_order(&events, &vehicle.address());
    assert_eq!(last["event"], "failed", "{events:?}");
    assert_eq!(last["kind"], "fence", "{last}");
    let error = last["error"].as_str().unwrap();
    assert!(
        error.contains("fence upload: the vehicle answered MAV_MISSION_NO_SPACE"),
        "{error}"
    );
    assert!(
        events
            .iter()
            .any(|(n, d)| n == "verified" && d["kind"] == "mission"),
        "{events:?}"
    );

    // A vehicle storing another item than the one sent.
    let vehicle = pymavlink_vehicle(dir.path(), &["--corrupt", "mission:5"]);
    let events = upload(&server, &survey, &json!({"to": vehicle.address()}));
    let last = check_order(&events, &vehicle.address());
    assert_eq!(last["event"], "failed", "{events:?}");
    let error = last["error"].as_str().unwrap();
    assert!(
        error.contains("mission read-back differs from what was sent: item 5: x/y"),
        "{error}"
    );

    // Nothing listens there: the engine's time-out, then the address is
    // free again (a second try is not refused as busy).
    let dead = format!("udpout:127.0.0.1:{}", free_udp_port());
    for _ in 0..2 {
        let events = upload(
            &server,
            &survey,
            &json!({"to": dead, "timeout_ms": 200, "retries": 2}),
        );
        let last = check_order(&events, &dead);
        assert_eq!(last["event"], "failed", "{events:?}");
        let error = last["error"].as_str().unwrap();
        assert!(
            error.contains(
                "mission upload: timed out waiting for MISSION_REQUEST_INT for item 0 \
                 (or MISSION_ACK) (3 tries, 200ms each)"
            ),
            "{error}"
        );
    }
}

/// A POST whose answer's head and first event have arrived, its
/// connection kept open: dropping it is a client that goes away.
struct OpenUpload {
    stream: TcpStream,
    received: String,
}

/// POST an upload and wait for its `started` event; the status of an
/// answer that is not an event stream (a refusal) instead.
fn try_open(server: &Server, survey: &str, body: &Value) -> Result<OpenUpload, u16> {
    let url = upload_url(server, survey, "u1");
    let authority = server.base.trim_start_matches("http://").to_string();
    let path = &url[server.base.len()..];
    let mut stream = TcpStream::connect(&authority).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .unwrap();
    let body = body.to_string();
    write!(
        stream,
        "POST {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n{}\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        server.auth_line(),
        body.len()
    )
    .unwrap();
    let mut received = Vec::new();
    let mut chunk = [0u8; 4096];
    loop {
        let got = text(&received);
        if got.contains("\r\n\r\n") && !got.starts_with("HTTP/1.1 200") {
            let status = got.split(' ').nth(1).and_then(|s| s.parse().ok());
            return Err(status.unwrap_or_else(|| panic!("no status: {got}")));
        }
        if got.contains("event: started") {
            return Ok(OpenUpload {
                stream,
                received: got,
            });
        }
        match stream.read(&mut chunk) {
            Ok(0) => panic!("closed: {got}"),
            Ok(n) => received.extend_from_slice(&chunk[..n]),
            Err(e) => panic!("{e}: {got}"),
        }
    }
}

#[test]
fn only_listed_addresses_one_upload_each_and_a_client_that_goes_away_frees_it() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        &dir.path().join("data"),
        &[
            "--vehicle-links",
            "udpout:127.0.0.1:*,tcpout:127.0.0.1:5760",
        ],
    );
    let survey = stored_survey(&server);
    let url = upload_url(&server, &survey, "u1");

    // Not on the list: 403 naming the address and the list.
    for to in [
        "udpout:127.0.0.2:14550",
        "tcpout:127.0.0.1:5761",
        "udpin:127.0.0.1:14550",
        "serial:/dev/ttyS0:57600",
    ] {
        let p = assert_problem(
            &post_json(&url, &json!({"to": to})),
            403,
            "is not one of the vehicle links this service may reach",
        );
        let detail = p["detail"].as_str().unwrap();
        assert!(detail.contains(to), "{detail}");
        assert!(
            detail.contains("udpout:127.0.0.1:*, tcpout:127.0.0.1:5760"),
            "{detail}"
        );
    }
    // Bad bodies: 422 at the member at fault.
    assert_invalid_at(
        &post_json(&url, &json!({"to": "udp:127.0.0.1:14550"})),
        "link kind",
        "/to",
        "unknown link kind",
    );
    assert_invalid_at(
        &post_json(&url, &json!({"to": "udpout:127.0.0.1:14550", "sortie": 2})),
        "sortie",
        "/sortie",
        "there is no sortie 2",
    );
    assert_invalid_at(
        &post_json(
            &url,
            &json!({"to": "udpout:127.0.0.1:14550", "timeout_ms": 1}),
        ),
        "timeout",
        "/timeout_ms",
        "from 10 to 10000",
    );
    assert_problem(
        &post_json(
            &upload_url(&server, &survey, "u9"),
            &json!({"to": "udpout:127.0.0.1:14550"}),
        ),
        404,
        "has no UAV",
    );

    // The page's list.
    let links = get(&server.url("/api/v1/vehicle-links")).json();
    assert_eq!(
        links,
        json!({"enabled": true, "addresses": [
            {"address": "udpout:127.0.0.1:*", "exact": false},
            {"address": "tcpout:127.0.0.1:5760", "exact": true}]})
    );

    // An upload to a silent address holds it (2 s × 6 tries per step)…
    let dead = format!("udpout:127.0.0.1:{}", free_udp_port());
    let slow = json!({"to": dead, "timeout_ms": 2000, "retries": 5});
    let first = try_open(&server, &survey, &slow).expect("the first upload starts");
    assert!(
        first.received.starts_with("HTTP/1.1 200"),
        "{}",
        first.received
    );
    // …so a second one to it is refused, one elsewhere is not.
    assert_problem(&post_json(&url, &slow), 409, "is busy");
    let vehicle = pymavlink_vehicle(dir.path(), &[]);
    let events = upload(&server, &survey, &json!({"to": vehicle.address()}));
    assert_eq!(events.last().unwrap().0, "done", "{events:?}");
    // The client goes away: the upload stops and the address is free.
    drop(first.stream);
    let limit = Instant::now() + Duration::from_secs(30);
    let freed = loop {
        match try_open(&server, &survey, &slow) {
            Ok(open) => break open,
            Err(409) if Instant::now() < limit => std::thread::sleep(Duration::from_millis(50)),
            Err(status) => panic!("after the client went away: {status}"),
        }
    };
    drop(freed.stream);
}

#[test]
fn without_the_flag_the_endpoint_answers_404_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let survey = stored_survey(&server);
    assert_problem(
        &post_json(
            &upload_url(&server, &survey, "u1"),
            &json!({"to": "udpout:127.0.0.1:14550"}),
        ),
        404,
        "vehicle links are switched off on this service",
    );
    assert_eq!(
        get(&server.url("/api/v1/vehicle-links")).json(),
        json!({"enabled": false, "addresses": []})
    );
    // The document says so.
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let op = &doc["paths"]["/api/v1/surveys/{id}/uavs/{uav}/upload"]["post"];
    let why = op["responses"]["404"]["description"].as_str().unwrap();
    assert!(why.contains("--vehicle-links"), "{why}");
    assert!(
        op["responses"]["200"]["content"]["text/event-stream"].is_object(),
        "{op}"
    );
}

#[test]
fn another_users_survey_is_404_and_a_viewer_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let name = unique_user_name("upload-other");
    let out = user_command(&server.data_dir, &["create", &name], None);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let other = Auth::Bearer(last_line(&out));
    let body = json!({"to": format!("udpout:127.0.0.1:{}", free_udp_port()),
                      "timeout_ms": 10, "retries": 0});
    // The admin's survey, in the admin's personal project.
    let survey = stored_survey(&server);
    let url = upload_url(&server, &survey, "u1");
    let p = assert_problem(&post_json_as(&other, &url, &body), 404, "survey");
    assert!(p["detail"].as_str().unwrap().contains(&survey), "{p}");
    // The same user made a viewer of a shared project: 403.
    let r = post_json(&server.url("/api/v1/projects"), &json!({"name": "shared"}));
    assert_eq!(r.status, 201, "{}", r.text());
    let project = r.json()["id"].as_str().unwrap().to_string();
    let r = post_json(
        &server.url(&format!("/api/v1/projects/{project}/members")),
        &json!({"user": name, "role": "viewer"}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let mut req = example_survey_request();
    req["project_id"] = json!(project);
    let r = post_json(&server.url("/api/v1/surveys"), &req);
    assert_eq!(r.status, 201, "{}", r.text());
    let shared = r.json()["id"].as_str().unwrap().to_string();
    let uav = r.json()["uavs"][0]["id"].as_str().unwrap().to_string();
    // The viewer sees it…
    assert_eq!(
        get_as(&other, &server.url(&format!("/api/v1/surveys/{shared}"))).status,
        200
    );
    // …but may not send it.
    assert_problem(
        &post_json_as(&other, &upload_url(&server, &shared, &uav), &body),
        403,
        "needs the editor role",
    );
    // Without credentials: 401.
    let r = post_json_as(&Auth::None, &url, &body);
    assert_eq!(r.status, 401, "{}", r.text());
}

#[test]
fn a_server_stop_ends_an_upload_with_a_failed_event() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let survey = stored_survey(&server);
    // A silent address: the upload would wait 2 s × 6 tries per step.
    let dead = format!("udpout:127.0.0.1:{}", free_udp_port());
    let mut open = try_open(
        &server,
        &survey,
        &json!({"to": dead, "timeout_ms": 2000, "retries": 5}),
    )
    .expect("the upload starts");
    // SIGTERM: the graceful stop does not wait for the upload's time-outs.
    let status = server.stop();
    assert!(status.success(), "{status:?}");
    let mut rest = Vec::new();
    open.stream.read_to_end(&mut rest).unwrap();
    let body = format!("{}{}", open.received, text(&rest));
    // The chunked framing's size lines sit between the events' lines.
    let events: Vec<Value> = body
        .lines()
        .filter_map(|l| l.strip_prefix("data: "))
        .map(|d| serde_json::from_str(d).unwrap())
        .collect();
    let last = events.last().unwrap();
    assert_eq!(last["event"], "failed", "{body}");
    assert!(
        last["error"]
            .as_str()
            .unwrap()
            .contains("the service is shutting down"),
        "{last}"
    );
}

#[test]
fn a_client_that_goes_away_cancels_the_vehicles_transfer() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &["--vehicle-links", LINKS]);
    let survey = stored_survey(&server);
    // A vehicle that goes quiet when mission item 3 arrives. The engine's
    // own time-out (10 s × 6 tries) would cancel only after the 30 s the
    // test waits for the vehicle: a cancel seen comes from the disconnect.
    let vehicle = pymavlink_vehicle(dir.path(), &["--stall", "mission:3"]);
    let open = try_open(
        &server,
        &survey,
        &json!({"to": vehicle.address(), "timeout_ms": 10000, "retries": 5}),
    )
    .expect("the upload starts");
    let stalled = vehicle.stored_when(|v| v["stalled"] == true);
    assert_eq!(stalled["stalled"], true, "{stalled}");
    // The client goes away mid-transfer: the vehicle is told at once
    // (MISSION_ACK OPERATION_CANCELLED), not left waiting.
    drop(open.stream);
    let told = vehicle.stored_when(|v| v["cancelled_by_gcs"].as_u64() >= Some(1));
    assert_eq!(told["cancelled_by_gcs"], 1, "{told}");
    assert_eq!(told["mission"], json!([]), "nothing was stored");
}
