//! Costmaps built as tile jobs by the service (issue 22 item 2), against
//! the real binary on SQLite: a server whose `--costmap-tile-cells` is
//! below the DTM's 283 × 259 working cells builds its costmap as 5 × 5
//! tiles of 64 (`--costmap-tile-side`), in the five stages (classify,
//! join, fill, cost, finish: 77 jobs), and
//!
//! - its answer (parameters, statistics, warnings, size, CRS, bounds,
//!   layers) is the same as a server with the default threshold gives for
//!   the same request, built whole; GDAL reads both files' cost and class
//!   pages and every layer equal value for value, the tiled files in blocks
//!   of 64; preview.png and legend.svg are the same bytes;
//! - every job is logged done once, none twice; a route across it is the
//!   route across the whole build;
//! - its progress reaches the event stream, rising through the stages, up
//!   to `done`;
//! - deleted mid-build, its tile jobs stop: its stream says it was deleted,
//!   nothing of it is left in the tables, and the next costmap is built;
//! - a tile side that is not a multiple of 16 from 16 to 8192, or a
//!   threshold of 0 cells, is refused at start-up naming the flag.

use std::collections::BTreeSet;
use std::time::Duration;

use serde_json::{Value, json};
use terraplan_e2e::replicas::{
    assert_same_costmap_files, costmap_content, download_costmap_files, wait_until,
};
use terraplan_e2e::{
    JOB_DEADLINE, Server, delete, dtm, get, get_streaming, post_json, sse_events, terraplan, text,
    upload_dem, wait_costmap_finished,
};

/// The DTM's 73 297 working cells are over this: built as tiles.
const TILED: [&str; 4] = ["--costmap-tile-cells", "10000", "--costmap-tile-side", "64"];
/// 5 × 5 tiles: three per-tile stages, a join and a finish.
const JOBS: usize = 3 * 25 + 2;
const LOG: &str = "info,sqlx=warn";

/// The layers asked for.
fn options() -> Value {
    json!({"layers": ["slope", "step", "inflation"], "pca_radius_m": 8})
}

fn post_costmap(server: &Server, dem: &str, options: Value) -> String {
    let r = post_json(
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "options": options}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

/// The (stage, tile) of a "costmap tile job done" log line.
fn job_of(line: &str) -> (String, u64) {
    let field = |name: &str| {
        line.split(&format!(" {name}="))
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .unwrap_or_else(|| panic!("no {name} in {line}"))
            .trim_matches('"')
            .to_string()
    };
    (field("stage"), field("tile").parse().unwrap())
}

#[test]
fn a_costmap_built_as_tiles_equals_the_whole_build() {
    let dir = tempfile::tempdir().unwrap();
    let whole = Server::start(&dir.path().join("whole"), &[]);
    let tiled = Server::start_logging(&dir.path().join("tiled"), &TILED, LOG);

    let whole_id = post_costmap(&whole, &upload_dem(&whole, &dtm()), options());
    let id = post_costmap(&tiled, &upload_dem(&tiled, &dtm()), options());
    let stream = get_streaming(
        &tiled.url(&format!("/api/v1/costmaps/{id}/events")),
        JOB_DEADLINE,
    );
    tiled.wait_for_log(&["costmap planned as tiles", &id, "tiles=25"], JOB_DEADLINE);

    // Progress through the event stream, up to done.
    let r = stream.finish();
    assert_eq!(r.status, 200);
    let events = sse_events(&r.text());
    let (last, before) = events.split_last().expect("events");
    assert_eq!(last.0, "done", "{events:?}");
    assert_eq!(last.1["progress"], 1.0);
    let running: Vec<f64> = before
        .iter()
        .filter(|(n, d)| n == "progress" && d["status"] == "running")
        .map(|(_, d)| d["progress"].as_f64().unwrap())
        .collect();
    let under_way: BTreeSet<u64> = running
        .iter()
        .filter(|p| **p > 0.0 && **p < 1.0)
        .map(|p| p.to_bits())
        .collect();
    assert!(under_way.len() >= 3, "{events:?}");
    assert!(
        running.windows(2).all(|w| w[1] >= w[0]),
        "progress went back: {running:?}"
    );
    assert!(
        before.iter().any(|(_, d)| d["stage"] == "cost"),
        "{events:?}"
    );

    // Every job done once.
    let mut done = BTreeSet::new();
    for _ in 0..JOBS {
        let line = tiled.wait_for_log(&["costmap tile job done", &id], JOB_DEADLINE);
        assert!(done.insert(job_of(&line)), "done twice: {line}");
    }
    let per_stage = |s: &str| done.iter().filter(|(stage, _)| stage == s).count();
    for (stage, n) in [
        ("classify", 25),
        ("join", 1),
        ("fill", 25),
        ("cost", 25),
        ("finish", 1),
    ] {
        assert_eq!(per_stage(stage), n, "{stage}: {done:?}");
    }

    // The same costmap as the whole build.
    let map = wait_costmap_finished(&tiled, &id);
    assert_eq!(map["status"], "done", "{map}");
    let reference = wait_costmap_finished(&whole, &whole_id);
    assert_eq!(reference["status"], "done", "{reference}");
    assert_eq!(costmap_content(&map), costmap_content(&reference));
    let a = download_costmap_files(&whole.base, &reference, &dir.path().join("a"));
    let b = download_costmap_files(&tiled.base, &map, &dir.path().join("b"));
    assert_eq!(b.layers, ["inflation", "slope", "step"]);
    let cells = assert_same_costmap_files(&a, &b, 64);
    assert_eq!(cells, 5 * 283 * 259);

    // Routes see no difference: the same route across both.
    let route = |server: &Server, map: &Value| {
        let b: Vec<f64> = map["bounds_wgs84"]
            .as_array()
            .expect("bounds_wgs84")
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let at = |fx: f64, fy: f64| json!([b[0] + fx * (b[2] - b[0]), b[1] + fy * (b[3] - b[1])]);
        let url = server.url(&format!(
            "/api/v1/costmaps/{}/routes",
            map["id"].as_str().unwrap()
        ));
        let r = post_json(&url, &json!({"start": at(0.3, 0.3), "goal": at(0.7, 0.7)}));
        assert_eq!(r.status, 201, "{}", r.text());
        let body = r.json();
        let route: Vec<&Value> = ["waypoints", "path_cells", "path_cost", "cost", "expanded"]
            .iter()
            .map(|k| &body[*k])
            .collect();
        assert!(route[0].as_array().is_some_and(|w| w.len() > 10), "{body}");
        json!(route)
    };
    assert_eq!(route(&tiled, &map), route(&whole, &reference));
}

/// The rows of `table` that belong to costmap `id`, in the server's
/// SQLite database (read with Python's sqlite3 while the server runs).
fn rows_of(server: &Server, table: &str, id: &str) -> u64 {
    let db = server.data_dir.join("terraplan.sqlite3");
    let script = "import sqlite3, sys\n\
                  c = sqlite3.connect(sys.argv[1])\n\
                  print(c.execute('SELECT COUNT(*) FROM ' + sys.argv[2] + \
                  ' WHERE costmap_id = ?', (sys.argv[3],)).fetchone()[0])";
    let out = std::process::Command::new("python3")
        .args(["-c", script, db.to_str().unwrap(), table, id])
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().parse().unwrap()
}

#[test]
fn deleting_a_tiled_costmap_mid_build_stops_its_tiles() {
    let dir = tempfile::tempdir().unwrap();
    // 9 × 9 tiles of 32 and wide neighbourhoods (a PCA radius of 50
    // cells, the most allowed): a minute of work in all, deleted after its
    // first tile.
    let server = Server::start_logging(
        dir.path(),
        &["--costmap-tile-cells", "10000", "--costmap-tile-side", "32"],
        LOG,
    );
    let dem = upload_dem(&server, &dtm());
    let id = post_costmap(&server, &dem, json!({"pca_radius_m": 100}));
    let url = server.url(&format!("/api/v1/costmaps/{id}"));
    wait_until(JOB_DEADLINE, "a tile done", || {
        let j = get(&url).json();
        assert_eq!(j["status"], "running", "{j}");
        (j["progress"].as_f64().unwrap() > 0.0).then_some(())
    });
    let stream = get_streaming(&format!("{url}/events"), JOB_DEADLINE);
    assert!(rows_of(&server, "costmap_tile_jobs", &id) > 0);
    assert_eq!(delete(&url).status, 204);

    let r = stream.finish();
    let events = sse_events(&r.text());
    let last = events.last().expect("events");
    assert_eq!(last.0, "failed", "{events:?}");
    assert_eq!(last.1["error"], "the costmap was deleted");
    assert_eq!(get(&url).status, 404);
    for table in [
        "costmap_tile_jobs",
        "costmap_tiles",
        "costmap_files",
        "costmap_file_chunks",
    ] {
        assert_eq!(rows_of(&server, table, &id), 0, "{table}");
    }
    // The tile jobs running then stop, or end discarded: the slot is free
    // again and the next costmap (built as tiles too) is done.
    let next = post_costmap(&server, &dem, json!({}));
    let map = wait_costmap_finished(&server, &next);
    assert_eq!(map["status"], "done", "{map}");
    server.wait_for_log(&["tiled costmap done", &next], Duration::from_secs(30));
    // Nothing of the deleted costmap came back (a run that ended after the
    // delete stored nothing), and the finished one left no intermediates.
    for table in ["costmap_tile_jobs", "costmap_tiles", "costmap_files"] {
        assert_eq!(rows_of(&server, table, &id), 0, "{table}");
    }
    for table in ["costmap_tile_jobs", "costmap_tiles"] {
        assert_eq!(rows_of(&server, table, &next), 0, "{table}");
    }
}

#[test]
fn bad_tile_flags_are_refused_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().to_str().unwrap();
    for (flag, value, says) in [
        ("--costmap-tile-side", "100", "multiple of 16"),
        ("--costmap-tile-side", "8208", "from 16 to 8192"),
        ("--costmap-tile-side", "x", "not a number"),
        ("--costmap-tile-cells", "0", "0"),
    ] {
        let out = terraplan(&["serve", "--port", "0", "--data-dir", data, flag, value]);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            err.contains(flag) && err.contains(says),
            "{flag} {value}: {err}"
        );
    }
}
