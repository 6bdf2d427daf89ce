//! Project quotas: the bytes of a project's DEM and costmap files
//! (`--project-quota-mb`, 413 past it, refused before the body is read
//! when its declared size already is) and its costmap jobs queued or
//! running (`--project-queued-jobs`, 429 with Retry-After), reported in
//! the project.

use serde_json::json;
use terraplan_e2e::{
    Server, assert_problem, dtm, get, post, post_json, shared_data, slow_costmap_options,
    upload_dem, wait_costmap_finished,
};

fn personal_project(server: &Server) -> String {
    let s = get(&server.url("/api/v1/session")).json();
    s["personal_project_id"]
        .as_str()
        .expect("personal project")
        .to_string()
}

#[test]
fn uploads_past_the_storage_quota_are_refused_and_usage_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    // 1 MiB: the 214 kB DTM fits, then 1.6 MB more does not.
    let server = Server::start(dir.path(), &["--project-quota-mb", "1"]);
    let project = personal_project(&server);
    let usage = |server: &Server| {
        get(&server.url(&format!("/api/v1/projects/{project}"))).json()["usage"].clone()
    };
    let before = usage(&server);
    assert_eq!(before["stored_bytes"], 0, "{before}");
    assert_eq!(before["quota_bytes"], 1024 * 1024, "{before}");

    upload_dem(&server, &dtm());
    let after = usage(&server);
    // Its tiles, compressed (a GeoTIFF's file is not kept; what counts is
    // checked in dem_tile_quota.rs).
    let dtm_bytes = after["stored_bytes"].as_u64().unwrap();
    assert!(dtm_bytes > 0, "{after}");

    let big = std::fs::read(shared_data("dems/codem__AOI-DigitalSurfaceModel.tif")).unwrap();
    let r = post(&server.url("/api/v1/dems"), "image/tiff", &big);
    let p = assert_problem(&r, 413, "--project-quota-mb");
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains(&project), "{detail}");
    assert!(detail.contains("1.0 MiB quota"), "{detail}");
    // Nothing was stored.
    assert_eq!(usage(&server)["stored_bytes"], dtm_bytes);
    let list = get(&server.url("/api/v1/dems")).json();
    assert_eq!(list["total"], 1, "{list}");
}

#[test]
fn a_costmap_whose_files_would_pass_the_quota_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--project-quota-mb", "1"]);
    let dem = upload_dem(&server, &dtm());
    // 283 × 259 cells: 0.6 MiB of cost, class and preview fit in what is
    // left of 1 MiB beside the DEM; with four layers more (1.7 MiB) not.
    let layers = ["slope", "zcomp", "step", "inflation"];
    let r = post_json(
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "options": {"layers": layers}}),
    );
    assert_problem(&r, 413, "--project-quota-mb");
    let r = post_json(&server.url("/api/v1/costmaps"), &json!({"dem_id": dem}));
    assert_eq!(r.status, 202, "{}", r.text());
    // The estimate bounds what the costmap then stores.
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_costmap_finished(&server, &id);
    assert_eq!(job["status"], "done", "{job}");
    let project = personal_project(&server);
    let stored =
        get(&server.url(&format!("/api/v1/projects/{project}"))).json()["usage"]["stored_bytes"]
            .as_u64()
            .unwrap();
    let dem_bytes = std::fs::metadata(dtm()).unwrap().len();
    let cells = job["width"].as_u64().unwrap() * job["height"].as_u64().unwrap();
    assert!(
        stored - dem_bytes <= cells * 9,
        "the costmap's files take {} bytes, over the estimate of {}",
        stored - dem_bytes,
        cells * 9
    );
}

#[test]
fn too_many_queued_costmap_jobs_get_429() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        dir.path(),
        &["--project-queued-jobs", "1", "--costmap-jobs", "1"],
    );
    let dem = upload_dem(&server, &dtm());
    let body = json!({"dem_id": dem, "options": slow_costmap_options()});
    let first = post_json(&server.url("/api/v1/costmaps"), &body);
    assert_eq!(first.status, 202, "{}", first.text());
    let second = post_json(&server.url("/api/v1/costmaps"), &body);
    let p = assert_problem(&second, 429, "--project-queued-jobs");
    assert!(second.header("retry-after").is_some(), "{p}");
    let project = personal_project(&server);
    let usage = get(&server.url(&format!("/api/v1/projects/{project}"))).json()["usage"].clone();
    assert_eq!(usage["queued_jobs"], 1, "{usage}");
    assert_eq!(usage["max_queued_jobs"], 1, "{usage}");
}
