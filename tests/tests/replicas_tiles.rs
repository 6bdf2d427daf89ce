//! One costmap built as tiles by every process on a PostgreSQL database
//! (issue 22 item 2): three `terraplan serve` replicas and a `terraplan
//! worker`, each with its own data directory, on a database of their own
//! in the cluster `TERRAPLAN_TEST_DATABASE_URL` names (skipped, saying so,
//! without it), with `--costmap-tile-cells` below the DTM's 283 × 259
//! working cells: its costmap is 5 × 5 tiles of 64, 77 tile jobs.
//!
//! - Every process runs some of its tile jobs (its log says so).
//! - A replica running a tile job is killed (SIGKILL): the job is taken
//!   over once its lease (2 s) runs out, run again (its second attempt)
//!   elsewhere. Another is stopped with SIGTERM while it runs one: it gives
//!   the job back (unless it finished it just before), run again elsewhere
//!   as the same attempt, and exits 0.
//! - The costmap still finishes, every job logged done once over all the
//!   logs (none twice), and it is the costmap a server on another database
//!   builds whole: the same answer, preview and legend, GDAL reads the same
//!   values on every page and layer.
//! - Its progress reaches an event stream on a replica that ran none of
//!   the stages it reports.
//!
//! No timing is asserted: every wait is for a condition, with generous
//! bounds.

use std::collections::BTreeSet;
use std::time::Duration;

use serde_json::{Value, json};
use terraplan_e2e::replicas::{
    EventClient, Replica, Role, TestDatabase, assert_same_costmap_files, costmap_content,
    download_costmap_files, first_token, logged_anywhere, wait_until,
};
use terraplan_e2e::{dtm, get, post, post_json};

const LEASE_S: &str = "2";
const WAIT: Duration = Duration::from_secs(300);
const JOBS: usize = 3 * 25 + 2;

/// Wide neighbourhoods (a PCA radius of 15 cells): each tile takes a
/// while, so that jobs are running when a replica is stopped.
fn options() -> Value {
    json!({"pca_radius_m": 30, "layers": ["slope", "step"]})
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
            "--costmap-tile-cells",
            "10000",
            "--costmap-tile-side",
            "64",
        ],
    );
    if let Some(token) = token {
        r.use_token(token);
    }
    r
}

fn upload(r: &Replica) -> String {
    let reply = post(
        &r.url("/api/v1/dems"),
        "image/tiff",
        &std::fs::read(dtm()).unwrap(),
    );
    assert_eq!(reply.status, 201, "{}: {}", r.name, reply.text());
    reply.json()["id"].as_str().unwrap().to_string()
}

fn post_costmap(r: &Replica, dem: &str) -> String {
    let reply = post_json(
        &r.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "options": options()}),
    );
    assert_eq!(reply.status, 202, "{}: {}", r.name, reply.text());
    reply.json()["id"].as_str().unwrap().to_string()
}

fn wait_finished(r: &Replica, id: &str) -> Value {
    wait_until(WAIT, &format!("costmap {id} to finish"), || {
        let reply = get(&r.url(&format!("/api/v1/costmaps/{id}")));
        assert_eq!(reply.status, 200, "{}", reply.text());
        let j = reply.json();
        (j["status"] == "done" || j["status"] == "failed").then_some(j)
    })
}

/// A log line's field `name` (`name=value` or `name="value"`).
fn field(line: &str, name: &str) -> String {
    line.split(&format!(" {name}="))
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("no {name} in {line}"))
        .trim_matches('"')
        .to_string()
}

/// (stage, tile) of a tile job's log line.
fn job_of(line: &str) -> (String, String) {
    (field(line, "stage"), field(line, "tile"))
}

/// A tile job of costmap `id` that `r` runs now (by the job table and
/// the holder `r` logs), once there is one.
fn running_on(r: &Replica, db: &TestDatabase, id: &str) -> (String, String) {
    wait_until(WAIT, &format!("{} to run a tile job", r.name), || {
        let rows = db.query(&format!(
            "SELECT owner, stage, tile FROM costmap_tile_jobs \
             WHERE costmap_id = '{id}' AND status = 'running'"
        ));
        let held = rows.iter().find(|row| {
            !r.logged(&[
                "costmap tile job started",
                id,
                &format!("holder={}", row[0]),
            ])
            .is_empty()
        })?;
        let stage = match held[1].as_str() {
            "1" => "classify",
            "2" => "join",
            "3" => "fill",
            "4" => "cost",
            _ => "finish",
        };
        Some((stage.to_string(), held[2].clone()))
    })
}

#[test]
fn replicas_and_a_worker_build_one_tiled_costmap_together() {
    let Some(db) = TestDatabase::create("replicas_tiles") else {
        return;
    };
    let Some(whole_db) = TestDatabase::create("replicas_tiles_whole") else {
        return;
    };
    // The reference: the same request built whole, on another database.
    let whole = Replica::start("whole", Role::Serve, &whole_db.url, &[]);
    whole.use_token(&first_token(WAIT, &whole));
    let whole_id = post_costmap(&whole, &upload(&whole));

    let r1 = start("r1", Role::Serve, &db, None);
    let token = first_token(WAIT, &r1);
    r1.use_token(&token);
    let mut r2 = start("r2", Role::Serve, &db, Some(&token));
    let mut r3 = start("r3", Role::Serve, &db, Some(&token));
    let mut worker = start("worker", Role::Worker, &db, None);

    let dem = upload(&r1);
    let id = post_costmap(&r1, &dem);
    let client = EventClient::connect(
        &r1.url(&format!("/api/v1/costmaps/{id}/events")),
        &token,
        WAIT,
    );

    // r2 is killed while it runs a tile job, after it did one.
    r2.wait_for_log(&["costmap tile job done", &id], WAIT);
    let killed = running_on(&r2, &db, &id);
    r2.kill();
    // r3 is stopped while it runs one, after it did one: it gives it back.
    r3.wait_for_log(&["costmap tile job done", &id], WAIT);
    let handed = running_on(&r3, &db, &id);
    let status = r3
        .terminate(Duration::from_secs(30))
        .expect("r3 exits after SIGTERM");
    assert!(status.success(), "r3: {status}");

    let map = wait_finished(&r1, &id);
    assert_eq!(map["status"], "done", "{map}");
    let all = [&r1, &r2, &r3, &worker];
    for r in all {
        assert!(
            !r.logged(&["costmap tile job done", &id]).is_empty(),
            "{} ran no tile job",
            r.name
        );
    }
    assert_eq!(r1.logged(&["costmap planned as tiles", &id]).len(), 1);
    assert_eq!(logged_anywhere(all, &["tiled costmap done", &id]).len(), 1);

    // Every job done once over all the logs.
    let mut done = BTreeSet::new();
    for (who, line) in logged_anywhere(all, &["costmap tile job done", &id]) {
        assert!(done.insert(job_of(&line)), "{who}: done twice: {line}");
    }
    assert_eq!(done.len(), JOBS, "{done:?}");
    // The killed replica's job was run again elsewhere as one more
    // attempt, unless it was done just before the kill; the job given back
    // was run again by another without counting the interrupted run.
    let attempt = |r: &Replica, job: &(String, String)| -> u32 {
        let started = r.logged(&["costmap tile job started", &id]);
        let line = started
            .iter()
            .rev()
            .find(|l| job_of(l) == *job)
            .unwrap_or_else(|| panic!("{} did not start {job:?}", r.name));
        field(line, "attempt").parse().unwrap()
    };
    let again = |job: &(String, String), want: u32| {
        logged_anywhere([&r1, &worker], &["costmap tile job started", &id])
            .into_iter()
            .any(|(_, l)| job_of(&l) == *job && field(&l, "attempt") == want.to_string())
    };
    let done_by = |r: &Replica, job: &(String, String)| {
        r.logged(&["costmap tile job done", &id])
            .iter()
            .any(|l| job_of(l) == *job)
    };
    let killed_attempt = attempt(&r2, &killed);
    assert!(
        done_by(&r2, &killed) || again(&killed, killed_attempt + 1),
        "{killed:?}"
    );
    // Unless r3 had done it just before the SIGTERM, it gave it back.
    let handed_attempt = attempt(&r3, &handed);
    let given_back = r3.logged(&["costmap tile jobs given back", &id]);
    assert!(
        done_by(&r3, &handed) || (given_back.len() == 1 && again(&handed, handed_attempt)),
        "{handed:?}: {given_back:?}"
    );

    // Its progress reached r1's event stream, up to done.
    let (ended, events) = client.finish();
    assert_eq!(ended, Ok(()), "{events:?}");
    let (last, before) = events.split_last().expect("events");
    assert_eq!(last.0, "done", "{events:?}");
    assert!(
        before
            .iter()
            .any(|(_, d)| d["status"] == "running" && d["progress"].as_f64() > Some(0.5)),
        "{events:?}"
    );

    // The costmap a single server builds whole.
    let reference = wait_finished(&whole, &whole_id);
    assert_eq!(reference["status"], "done", "{reference}");
    assert_eq!(costmap_content(&map), costmap_content(&reference));
    let dir = tempfile::tempdir().unwrap();
    let a = download_costmap_files(&whole.base, &reference, &dir.path().join("whole"));
    let b = download_costmap_files(&r1.base, &map, &dir.path().join("tiled"));
    assert_eq!(
        assert_same_costmap_files(&a, &b, 64),
        4 * 283 * 259,
        "cost, class and two layers"
    );
    // Nothing is left of its tile jobs and tiles.
    for table in ["costmap_tile_jobs", "costmap_tiles"] {
        let rows = db.query(&format!(
            "SELECT COUNT(*) FROM {table} WHERE costmap_id = '{id}'"
        ));
        assert_eq!(rows[0][0], "0", "{table}");
    }
    let status = worker
        .terminate(Duration::from_secs(30))
        .expect("the worker exits after SIGTERM");
    assert!(status.success(), "worker: {status}");
}
