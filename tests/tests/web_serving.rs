//! `terraplan serve` serves the built web page outside `/api`: its files,
//! `index.html` for the page's own paths, hashed assets cached for good;
//! and, when the page is not built, a page saying how to build it.

use serde_json::Value;
use terraplan_e2e::{Server, get, post};

#[test]
fn serves_the_built_page_outside_the_api() {
    let dir = tempfile::tempdir().unwrap();
    let web = dir.path().join("dist");
    std::fs::create_dir_all(web.join("assets")).unwrap();
    std::fs::write(
        web.join("index.html"),
        "<!doctype html><title>t</title><p>the page",
    )
    .unwrap();
    std::fs::write(web.join("assets/app-1a2b3c.js"), "console.log(1)").unwrap();
    let server = Server::start(
        &dir.path().join("data"),
        &["--web-dir", web.to_str().unwrap()],
    );

    let r = get(&server.url("/"));
    assert_eq!(r.status, 200);
    assert!(r.text().contains("the page"));
    assert_eq!(r.header("cache-control"), Some("no-cache"));
    let r = get(&server.url("/assets/app-1a2b3c.js"));
    assert_eq!(r.status, 200);
    assert!(r.header("content-type").unwrap().contains("javascript"));
    assert!(r.header("cache-control").unwrap().contains("immutable"));
    // The page's own paths load the page.
    let r = get(&server.url("/surveys/0190"));
    assert_eq!(r.status, 200);
    assert!(r.text().contains("the page"));
    // The API keeps its problem+json 404s and its routes.
    let r = get(&server.url("/api/v1/nothing"));
    assert_eq!(r.status, 404);
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    let body: Value = r.json();
    assert_eq!(body["status"], 404);
    assert_eq!(get(&server.url("/healthz")).status, 200);
    assert_eq!(post(&server.url("/"), "text/plain", b"x").status, 405);
}

#[test]
fn says_how_to_build_a_missing_page() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        &dir.path().join("data"),
        &["--web-dir", dir.path().join("none").to_str().unwrap()],
    );
    let r = get(&server.url("/"));
    assert_eq!(r.status, 503);
    assert!(r.text().contains("scripts/run.sh"), "{}", r.text());
    assert_eq!(get(&server.url("/api/v1/vehicles")).status, 200);
}
