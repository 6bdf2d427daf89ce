//! `terraplan upload`: missions, fences and rally points sent over MAVLink
//! on 127.0.0.1 to vehicles nobody here wrote the protocol engine of —
//! MAVSDK's MissionRawServer (tests/validators/mavsdk_vehicle.py, the C++
//! library in the `mavsdk` wheel) and a pymavlink vehicle that loses and
//! repeats messages (seeded), refuses on demand or stores a wrong item
//! (tests/validators/mavlink_vehicle.py) — and what each vehicle stored
//! compared here with the files, read independently of the CLI.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use terraplan_e2e::vehicles::{
    assert_fence_and_rally, assert_items_equal, free_udp_port, items, mavsdk_vehicle,
    pymavlink_vehicle, wpl_items,
};
use terraplan_e2e::{
    SurveyArea, SurveyFiles, survey_cli, terraplan_bin, text, workspace, write_json,
};

/// Run `terraplan upload`, killed if it has not ended within 120 s (a
/// bound on a hang, not a timing check).
fn upload(args: &[&str]) -> Output {
    let mut child = Command::new(terraplan_bin())
        .arg("upload")
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run terraplan upload");
    let limit = Instant::now() + Duration::from_secs(120);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > limit {
            let _ = child.kill();
            panic!("terraplan upload {args:?} did not end");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// The example field surveyed with rally points: u1.waypoints, u1.plan,
/// u1.fence.waypoints, u1.rally.waypoints.
fn survey(dir: &Path) -> PathBuf {
    let ex = workspace().join("examples");
    let params = write_json(
        dir,
        "params.json",
        &json!({"altitude_m": 70, "rally_points": [[6.0605, 51.5105], [6.0635, 51.5118]],
                "uavs": [{"id": "u1", "start": [6.0620, 51.5110]}]}),
    );
    let out = dir.join("out");
    let nfz = ex.join("field-nfz.geojson");
    survey_cli(
        &SurveyFiles {
            area: SurveyArea::Roi(&ex.join("field.geojson")),
            no_fly: &[&nfz],
            dem: None,
            params: &params,
        },
        &out,
        "upload survey",
    );
    out
}

/// The rows of a QGC WPL 110 file as MISSION_ITEM_INT fields.
fn wpl_rows(path: &Path) -> Vec<Value> {
    wpl_items(&std::fs::read_to_string(path).unwrap())
}

fn summary(o: &Output) -> Value {
    assert!(
        o.status.success(),
        "upload failed ({:?}): {}",
        o.status.code(),
        text(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).expect("upload's JSON summary")
}

#[test]
fn mavsdk_mission_raw_server_receives_the_waypoints_and_the_plan() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let rows = wpl_rows(&out.join("u1.waypoints"));
    assert!(rows.len() > 20, "{}", rows.len());
    let vehicle = mavsdk_vehicle(dir.path());
    let to = vehicle.address();
    let s = summary(&upload(&[
        out.join("u1.waypoints").to_str().unwrap(),
        "--to",
        &to,
    ]));
    assert_eq!(s["verified"], true);
    assert_eq!(s["sent"], json!([{"kind": "mission", "items": rows.len()}]));
    // The .plan (mission only: MissionRawServer keeps missions) sends the
    // same items: home first, as for ArduPilot.
    let s = summary(&upload(&[
        out.join("u1.plan").to_str().unwrap(),
        "--to",
        &to,
        "--mission-only",
    ]));
    assert_eq!(s["sent"][0]["items"].as_u64(), Some(rows.len() as u64));
    let stored = vehicle.stored_when(|v| v["missions"].as_array().is_some_and(|m| m.len() == 2));
    let missions = stored["missions"].as_array().unwrap();
    assert_eq!(missions.len(), 2, "{stored}");
    for (k, m) in missions.iter().enumerate() {
        assert_eq!(m["result"], "SUCCESS", "{m}");
        // The first from the .waypoints, the second from the .plan.
        let tol = if k == 0 { 0.0 } else { 1.0 };
        assert_items_equal(
            &format!("MAVSDK mission {k}"),
            &items(&m["items"]),
            &rows,
            tol,
        );
    }
}

#[test]
fn lossy_vehicle_gets_mission_fence_and_rally_equal_to_the_files() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let rows = wpl_rows(&out.join("u1.waypoints"));
    let fence = wpl_rows(&out.join("u1.fence.waypoints"));
    let rally = wpl_rows(&out.join("u1.rally.waypoints"));
    assert_eq!(rally.len(), 2);
    for seed in ["1", "2", "3"] {
        let vehicle = pymavlink_vehicle(
            dir.path(),
            &["--seed", seed, "--drop", "0.15", "--repeat", "0.15"],
        );
        let s = summary(&upload(&[
            out.join("u1.plan").to_str().unwrap(),
            "--to",
            &vehicle.address(),
            "--timeout",
            "150ms",
            "--retries",
            "8",
        ]));
        assert_eq!(s["verified"], true, "seed {seed}");
        let stored = vehicle.stored();
        // The losses happened, and were recovered.
        assert!(
            stored["dropped"].as_u64().unwrap() > 0,
            "seed {seed}: {stored}"
        );
        assert!(stored["repeated"].as_u64().unwrap() > 0, "seed {seed}");
        assert_items_equal(
            &format!("seed {seed} mission"),
            &items(&stored["mission"]),
            &rows,
            1.0,
        );
        // The .plan's fence, with its breach return point, and the rally points.
        assert_fence_and_rally(&format!("seed {seed}"), &stored, &fence, &rally);
    }
}

#[test]
fn separate_fence_and_rally_files_and_legacy_requests() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let vehicle = pymavlink_vehicle(dir.path(), &["--legacy"]);
    let s = summary(&upload(&[
        out.join("u1.waypoints").to_str().unwrap(),
        "--fence",
        out.join("u1.fence.waypoints").to_str().unwrap(),
        "--rally",
        out.join("u1.rally.waypoints").to_str().unwrap(),
        "--to",
        &vehicle.address(),
    ]));
    let kinds: Vec<&str> = s["sent"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["mission", "fence", "rally"]);
    let stored = vehicle.stored();
    for (kind, file) in [
        ("mission", "u1.waypoints"),
        ("fence", "u1.fence.waypoints"),
        ("rally", "u1.rally.waypoints"),
    ] {
        let got = items(&stored[kind]);
        assert_items_equal(kind, &got, &wpl_rows(&out.join(file)), 0.0);
        // Asked with MISSION_REQUEST, answered with MISSION_ITEM_INT.
        assert!(
            got.iter().all(|i| i["wire"] == "MISSION_ITEM_INT"),
            "{kind}"
        );
    }
}

#[test]
fn a_refusal_names_the_mission_result() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let vehicle = pymavlink_vehicle(dir.path(), &["--nack", "fence:MAV_MISSION_NO_SPACE"]);
    let o = upload(&[
        out.join("u1.plan").to_str().unwrap(),
        "--to",
        &vehicle.address(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("fence upload: the vehicle answered MAV_MISSION_NO_SPACE"),
        "{err}"
    );
    // The mission before it arrived.
    assert!(!items(&vehicle.stored()["mission"]).is_empty());
}

#[test]
fn a_wrong_read_back_is_a_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let vehicle = pymavlink_vehicle(dir.path(), &["--corrupt", "mission:5"]);
    let o = upload(&[
        out.join("u1.waypoints").to_str().unwrap(),
        "--to",
        &vehicle.address(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("mission read-back differs from what was sent: item 5: x/y"),
        "{err}"
    );
}

#[test]
fn a_dead_link_times_out() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    // Nothing listens on this port.
    let to = format!("udpout:127.0.0.1:{}", free_udp_port());
    let o = upload(&[
        out.join("u1.waypoints").to_str().unwrap(),
        "--to",
        &to,
        "--timeout",
        "200ms",
        "--retries",
        "2",
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o.stderr));
    let err = text(&o.stderr);
    assert!(
        err.contains("mission upload: timed out waiting for MISSION_REQUEST_INT for item 0 (or MISSION_ACK) (3 tries, 200ms each)"),
        "{err}"
    );
}

#[test]
fn bad_input_exits_2_naming_the_fault() {
    let dir = tempfile::tempdir().unwrap();
    let out = survey(dir.path());
    let wp = out.join("u1.waypoints");
    let wp = wp.to_str().unwrap();
    let plan_json = out.join("plan.json");
    let cases: [(Vec<&str>, &str); 6] = [
        (
            vec!["/nonexistent/m.waypoints", "--to", "udpout:127.0.0.1:14550"],
            "cannot read /nonexistent/m.waypoints",
        ),
        (
            vec![wp, "--to", "udp:127.0.0.1:14550"],
            "unknown link kind \"udp\"",
        ),
        (
            vec![wp, "--to", "udpout:127.0.0.1:99999"],
            "the port must be a number from 1 to 65535",
        ),
        (
            vec![wp, "--to", "udpout:127.0.0.1:14550", "--fence", wp],
            "fence file has command 16 at item 0",
        ),
        (
            vec![
                plan_json.to_str().unwrap(),
                "--to",
                "udpout:127.0.0.1:14550",
            ],
            "not a QGC WPL 110 file",
        ),
        (
            vec![wp, "--to", "udpout:127.0.0.1:14550", "--timeout", "0s"],
            "time-out must be from 10ms to 60s",
        ),
    ];
    for (args, want) in cases {
        let o = upload(&args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o.stderr));
        assert!(
            text(&o.stderr).contains(want),
            "{args:?}: {}",
            text(&o.stderr)
        );
    }
}
