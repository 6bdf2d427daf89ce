//! Replicas that share nothing but a PostgreSQL database survive each
//! other (issue 22 item 4): three `terraplan serve` replicas and a
//! `terraplan worker`, each with its own port and data directory, on a
//! database of their own in the cluster `TERRAPLAN_TEST_DATABASE_URL`
//! names (skipped, saying so, without it).
//!
//! - What one replica makes (DEM, costmap, survey, route) the others
//!   serve, download and replan.
//! - The replica running a costmap is killed (SIGKILL) mid-run: another
//!   takes the job over once its lease (2 s here) runs out and finishes it.
//! - A replica stopped with SIGTERM mid-run gives its job back at once
//!   and exits 0; another finishes the job. The last server stopped so,
//!   the worker alone finishes its job.
//! - The progress of a job reaches event-stream clients of every replica,
//!   wherever it runs.
//! - No job is lost or finished twice: every job ends done, once (one
//!   "costmap job done" over all the logs), its runs counted in the job
//!   table (a killed run counts, a run given back does not), and the
//!   three costmaps of one DEM, however often interrupted, are the same
//!   file byte for byte.
//!
//! No timing is asserted: every wait is for a condition, with generous
//! bounds.

use std::time::Duration;

use serde_json::{Value, json};
use terraplan_e2e::replicas::{
    EventClient, Replica, Role, TestDatabase, first_token, logged_anywhere, wait_until,
};
use terraplan_e2e::{dtm, example_survey_request, get, post, post_json};

/// The replicas' lease on a job (`--job-lease-s`): short, so a killed
/// replica's job is taken over soon.
const LEASE_S: &str = "2";
/// The longest wait for anything.
const WAIT: Duration = Duration::from_secs(180);
/// Options that make a costmap of the DTM take seconds (PCA
/// neighbourhoods of 30 cells' radius: about 6 s on a loaded 2-core
/// machine, 30 times the default), so that it is still running when its
/// replica is stopped; the test waits only for it to be under way.
fn slow_options() -> Value {
    json!({"pca_radius_m": 60})
}

fn start(name: &str, role: Role, db: &TestDatabase, token: Option<&str>) -> Replica {
    let r = Replica::start(
        name,
        role,
        &db.url,
        &[
            "--job-lease-s",
            LEASE_S,
            "--costmap-jobs",
            "1",
            "--planning-per-minute",
            "0",
        ],
    );
    if let Some(token) = token {
        r.use_token(token);
    }
    r
}

fn job(r: &Replica, id: &str) -> Value {
    let reply = get(&r.url(&format!("/api/v1/costmaps/{id}")));
    assert_eq!(reply.status, 200, "{}: {}", r.name, reply.text());
    reply.json()
}

fn wait_job(r: &Replica, id: &str, what: &str, done: impl Fn(&Value) -> bool) -> Value {
    wait_until(
        WAIT,
        &format!("costmap {id} {what} (asking {})", r.name),
        || {
            let j = job(r, id);
            done(&j).then_some(j)
        },
    )
}

fn wait_finished(r: &Replica, id: &str) -> Value {
    wait_job(r, id, "to finish", |j| {
        j["status"] == "done" || j["status"] == "failed"
    })
}

/// Running, with a stage recorded in the job table (so its build is
/// under way, not just claimed).
fn is_under_way(j: &Value) -> bool {
    j["status"] == "running" && !j["stage"].is_null()
}

fn post_costmap(r: &Replica, dem: &str, options: Value) -> String {
    let reply = post_json(
        &r.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "options": options}),
    );
    assert_eq!(reply.status, 202, "{}: {}", r.name, reply.text());
    reply.json()["id"].as_str().unwrap().to_string()
}

fn upload(r: &Replica, path: &std::path::Path) -> String {
    let reply = post(
        &r.url("/api/v1/dems"),
        "image/tiff",
        &std::fs::read(path).unwrap(),
    );
    assert_eq!(reply.status, 201, "{}: {}", r.name, reply.text());
    reply.json()["id"].as_str().unwrap().to_string()
}

/// A file's bytes through `r` (200 required).
fn download(r: &Replica, path: &str) -> Vec<u8> {
    let reply = get(&r.url(path));
    assert_eq!(reply.status, 200, "{} GET {path}: {}", r.name, reply.text());
    reply.body
}

fn events(r: &Replica, id: &str, token: &str) -> EventClient {
    EventClient::connect(
        &r.url(&format!("/api/v1/costmaps/{id}/events")),
        token,
        WAIT,
    )
}

/// A client has seen the job running with a stage: its progress reached
/// that replica.
fn saw_progress(client: &EventClient) -> bool {
    client.events().iter().any(|(name, data)| {
        name == "progress" && data["status"] == "running" && !data["stage"].is_null()
    })
}

/// The stream ended cleanly with a `done` event after progress events.
fn assert_followed_to_done(client: EventClient, who: &str) {
    let (ended, events) = client.finish();
    assert_eq!(ended, Ok(()), "{who}: the stream was cut: {events:?}");
    let (last, before) = events.split_last().expect("events");
    assert_eq!(last.0, "done", "{who}: {events:?}");
    assert_eq!(last.1["progress"], 1.0, "{who}");
    assert!(
        before.iter().any(|(n, d)| n == "progress"
            && d["status"] == "running"
            && d["progress"].as_f64().is_some_and(|p| p > 0.0)),
        "{who}: no progress under way: {events:?}"
    );
    // Progress never goes back within one run.
    for pair in before.windows(2) {
        let (a, b) = (&pair[0].1, &pair[1].1);
        if a["status"] == "running" && b["status"] == "running" {
            assert!(
                b["progress"].as_f64() >= a["progress"].as_f64() || b["progress"] == 0.0,
                "{who}: progress went back: {a} then {b}"
            );
        }
    }
}

/// A route across `map` (a done costmap's answer) through `r`: the first
/// pair of candidate points, mirrored about the map's centre, that lie in
/// one traversable region.
fn route_across(r: &Replica, map: &Value) -> Value {
    let b: Vec<f64> = map["bounds_wgs84"]
        .as_array()
        .expect("bounds_wgs84")
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let at = |fx: f64, fy: f64| json!([b[0] + fx * (b[2] - b[0]), b[1] + fy * (b[3] - b[1])]);
    let url = r.url(&format!(
        "/api/v1/costmaps/{}/routes",
        map["id"].as_str().unwrap()
    ));
    let steps = [0.2, 0.3, 0.4];
    for fx in steps {
        for fy in steps {
            let reply = post_json(
                &url,
                &json!({"start": at(fx, fy), "goal": at(1.0 - fx, 1.0 - fy)}),
            );
            match reply.status {
                201 => return reply.json(),
                // An end on an obstacle, or the two apart.
                422 => continue,
                s => panic!("route through {}: {s} {}", r.name, reply.text()),
            }
        }
    }
    panic!("no candidate route across the costmap")
}

/// The job table's row of `id`: (status, attempts, owner is null).
fn table_row(db: &TestDatabase, id: &str) -> (String, i64, bool) {
    let rows = db.query(&format!(
        "SELECT status, attempts, owner IS NULL FROM costmaps WHERE id = '{id}'"
    ));
    assert_eq!(rows.len(), 1, "{rows:?}");
    let r = &rows[0];
    (r[0].clone(), r[1].parse().unwrap(), r[2] == "t")
}

#[test]
fn replicas_survive_each_other() {
    let Some(db) = TestDatabase::create("replicas") else {
        return;
    };
    let mut r1 = start("r1", Role::Serve, &db, None);
    let token = first_token(WAIT, &r1);
    r1.use_token(&token);
    let mut r2 = start("r2", Role::Serve, &db, Some(&token));
    let mut r3 = start("r3", Role::Serve, &db, Some(&token));
    let mut worker = start("worker", Role::Worker, &db, None);

    // ---- What one makes, the others serve, download and replan.
    let dem = upload(&r1, &dtm());
    let via_r1 = get(&r1.url(&format!("/api/v1/dems/{dem}"))).json();
    let via_r2 = get(&r2.url(&format!("/api/v1/dems/{dem}")));
    assert_eq!(via_r2.status, 200, "{}", via_r2.text());
    assert_eq!(via_r2.json(), via_r1);
    let map_id = post_costmap(&r1, &dem, json!({}));
    let map = wait_finished(&r2, &map_id);
    assert_eq!(map["status"], "done", "{map}");
    let tif = map["urls"]["costmap_tif"].as_str().unwrap();
    let tif_r2 = download(&r2, tif);
    assert!(tif_r2.starts_with(b"II*\0"), "a little-endian TIFF");
    assert_eq!(download(&r3, tif), tif_r2);
    assert_eq!(job(&r3, &map_id), map);

    let survey = post_json(&r1.url("/api/v1/surveys"), &example_survey_request());
    assert_eq!(survey.status, 201, "{}", survey.text());
    let survey = survey.json();
    let survey_id = survey["id"].as_str().unwrap();
    let served = get(&r3.url(&format!("/api/v1/surveys/{survey_id}")));
    assert_eq!(served.status, 200, "{}", served.text());
    assert_eq!(served.json(), survey);
    let files = survey["uavs"][0]["sorties"][0]["files"]
        .as_object()
        .expect("a sortie's files");
    let urls: Vec<&str> = files.values().filter_map(Value::as_str).collect();
    assert!(urls.len() >= 3, "{files:?}");
    for url in urls {
        assert_eq!(download(&r2, url), download(&r3, url), "{url}");
    }

    let route = route_across(&r1, &map);
    let route_id = route["id"].as_str().unwrap();
    let served = get(&r2.url(&format!("/api/v1/routes/{route_id}")));
    assert_eq!(served.status, 200, "{}", served.text());
    assert_eq!(served.json()["waypoints"], route["waypoints"]);
    let geojson = route["urls"]["geojson"].as_str().unwrap();
    assert_eq!(download(&r3, geojson), download(&r1, geojson));
    // Replanned through r2 (r1 holds the route's search in memory; r2
    // searches afresh).
    let replan = post_json(
        &r2.url(route["urls"]["replan"].as_str().unwrap()),
        &json!({"position": route["start"]}),
    );
    assert_eq!(replan.status, 201, "{}", replan.text());
    let replanned = replan.json();
    assert_eq!(replanned["parent_id"], route_id);
    assert_eq!(
        replanned["waypoints"].as_array().unwrap().last(),
        route["waypoints"].as_array().unwrap().last()
    );

    // ---- The replica running a costmap is killed: another finishes it.
    let killed = post_costmap(&r1, &dem, slow_options());
    // Clients of every replica follow it.
    let clients: Vec<(String, EventClient)> = [&r1, &r2, &r3]
        .iter()
        .map(|r| (r.name.clone(), events(r, &killed, &token)))
        .collect();
    // Posted to r1, run by r1.
    r1.wait_for_log(&["costmap job started", &killed], WAIT);
    wait_job(&r2, &killed, "under way", is_under_way);
    // Its progress reaches the clients of the replicas not running it.
    for (name, client) in &clients {
        wait_until(WAIT, &format!("progress at {name}'s client"), || {
            saw_progress(client).then_some(())
        });
    }
    r1.kill();
    let done = wait_finished(&r3, &killed);
    assert_eq!(done["status"], "done", "{done}");
    let finished_by = logged_anywhere([&r1, &r2, &r3, &worker], &["costmap job done", &killed]);
    assert_eq!(finished_by.len(), 1, "{finished_by:?}");
    assert_ne!(finished_by[0].0, "r1");
    assert!(
        finished_by[0].1.contains("attempt=2"),
        "the second run: {finished_by:?}"
    );
    assert!(r1.logged(&["costmap job done", &killed]).is_empty());
    assert_eq!(table_row(&db, &killed), ("done".into(), 2, true));
    for (name, client) in clients {
        if name == "r1" {
            // Its server is gone: the stream was cut, after progress.
            let (ended, events) = client.finish();
            assert!(ended.is_err(), "{events:?}");
            assert!(events.iter().any(|(n, _)| n == "progress"), "{events:?}");
        } else {
            assert_followed_to_done(client, &name);
        }
    }
    let first_tif = download(&r2, done["urls"]["costmap_tif"].as_str().unwrap());

    // ---- SIGTERM: r2 gives its running job back and exits 0; another
    // replica finishes the job.
    let handed = post_costmap(&r2, &dem, slow_options());
    r2.wait_for_log(&["costmap job started", &handed], WAIT);
    let client = events(&r3, &handed, &token);
    wait_job(&r3, &handed, "under way", is_under_way);
    let status = r2.terminate(WAIT).expect("r2 exits after SIGTERM");
    assert!(status.success(), "r2: {status}");
    assert_eq!(r2.logged(&["given back", &handed]).len(), 1);
    assert_eq!(r2.logged(&["shut down cleanly"]).len(), 1);
    let done = wait_finished(&r3, &handed);
    assert_eq!(done["status"], "done", "{done}");
    let finished_by = logged_anywhere([&r2, &r3, &worker], &["costmap job done", &handed]);
    assert_eq!(finished_by.len(), 1, "{finished_by:?}");
    assert_ne!(finished_by[0].0, "r2");
    // A run given back is not counted.
    assert_eq!(table_row(&db, &handed), ("done".into(), 1, true));
    assert_followed_to_done(client, "r3");
    assert_eq!(
        download(&r3, done["urls"]["costmap_tif"].as_str().unwrap()),
        first_tif
    );

    // ---- The last server stopped mid-run: the worker alone finishes it.
    let last = post_costmap(&r3, &dem, slow_options());
    r3.wait_for_log(&["costmap job started", &last], WAIT);
    wait_job(&r3, &last, "under way", is_under_way);
    let status = r3.terminate(WAIT).expect("r3 exits after SIGTERM");
    assert!(status.success(), "r3: {status}");
    assert_eq!(r3.logged(&["given back", &last]).len(), 1);
    worker.wait_for_log(&["costmap job done", &last], WAIT);
    // A new replica serves it, and replans the route of the first.
    let mut r4 = start("r4", Role::Serve, &db, Some(&token));
    let done = job(&r4, &last);
    assert_eq!(done["status"], "done", "{done}");
    assert_eq!(
        download(&r4, done["urls"]["costmap_tif"].as_str().unwrap()),
        first_tif
    );
    let replan = post_json(
        &r4.url(route["urls"]["replan"].as_str().unwrap()),
        &json!({"position": route["start"]}),
    );
    assert_eq!(replan.status, 201, "{}", replan.text());
    assert_eq!(table_row(&db, &last), ("done".into(), 1, true));

    let status = worker
        .terminate(WAIT)
        .expect("the worker exits after SIGTERM");
    assert!(status.success(), "worker: {status}");
    assert_eq!(worker.logged(&["shut down cleanly"]).len(), 1);
    let status = r4.terminate(WAIT).expect("r4 exits after SIGTERM");
    assert!(status.success(), "r4: {status}");

    // ---- No job lost, none finished twice.
    let all = [&r1, &r2, &r3, &r4, &worker];
    let rows = db.query("SELECT id, status, owner IS NULL FROM costmaps ORDER BY created_at");
    assert_eq!(rows.len(), 4, "{rows:?}");
    for row in &rows {
        assert_eq!(
            (row[1].as_str(), row[2].as_str()),
            ("done", "t"),
            "{rows:?}"
        );
        let done = logged_anywhere(all, &["costmap job done", &row[0]]);
        assert_eq!(done.len(), 1, "{done:?}");
    }
    let discarded = logged_anywhere(all, &["discarded"]);
    assert!(discarded.is_empty(), "{discarded:?}");
    assert_eq!(table_row(&db, &map_id), ("done".into(), 1, true));
}

/// `terraplan worker` without PostgreSQL, or with a lease out of range:
/// exit status 2 and a message naming the fault.
#[test]
fn worker_faults() {
    let dir = std::env::temp_dir().join(format!("terraplan-worker-faults-{}", std::process::id()));
    let run = |args: &[&str]| {
        std::process::Command::new(terraplan_e2e::terraplan_bin())
            .arg("worker")
            .arg("--data-dir")
            .arg(&dir)
            .args(args)
            .env_remove("DATABASE_URL")
            .output()
            .expect("run terraplan worker")
    };
    let out = run(&[]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = terraplan_e2e::text(&out.stderr);
    assert!(
        err.contains("PostgreSQL") && err.contains("DATABASE_URL"),
        "{err}"
    );
    let out = run(&[
        "--database-url",
        "postgres://127.0.0.1:1/x",
        "--job-lease-s",
        "0.5",
    ]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = terraplan_e2e::text(&out.stderr);
    assert!(
        err.contains("--job-lease-s") && err.contains("[1, 3600]"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
