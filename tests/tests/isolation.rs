//! Isolation between users and projects (issue 19), end to end against
//! the real binary: another user's DEMs, surveys, costmaps and routes
//! answer exactly like missing ones on every endpoint (reads, deletes,
//! downloads, SSE, elevation queries, routes, replans, a `dem_id` or
//! land-cover source naming them), lists never show them, a viewer member
//! reads but gets 403 on writes, and two users working at once never see
//! each other's work, through the caches either. Runs on SQLite, and on
//! PostgreSQL when the test command sets `TERRAPLAN_TEST_DATABASE_URL`.

use serde_json::{Value, json};
use terraplan_e2e::{
    Auth, Framing, Reply, Server, assert_invalid_at, assert_problem, example_survey_request,
    get_as, get_with_timeout, last_line, post_json_as, send_as, sse_events, text, unique_user_name,
    user_command,
};

/// An id no resource has, as long as a real one (ids are UUIDs).
const MISSING: &str = "00000000-0000-7000-8000-000000000000";

/// A user of the test server: its name and credentials.
struct User {
    name: String,
    auth: Auth,
}

/// The harness's admin of `server`.
fn admin(server: &Server) -> User {
    User {
        name: server.user.clone(),
        auth: Auth::Bearer(server.token.clone()),
    }
}

/// A new (non-admin) user made with `terraplan user create`.
fn new_user(server: &Server, prefix: &str) -> User {
    let name = unique_user_name(prefix);
    let out = user_command(&server.data_dir, &["create", &name], None);
    assert!(
        out.status.success(),
        "{}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    User {
        name,
        auth: Auth::Bearer(last_line(&out)),
    }
}

/// A flat-ish ESRI ASCII grid in EPSG:32633 (UTM 33N) of 100 × 100 cells
/// of 2 m, rising 1 cm per cell eastwards plus `offset` metres.
fn asc_grid(offset: f64) -> Vec<u8> {
    let mut s =
        String::from("ncols 100\nnrows 100\nxllcorner 500000\nyllcorner 5000000\ncellsize 2\n");
    for _ in 0..100 {
        let row: Vec<String> = (0..100)
            .map(|c| format!("{:.2}", 100.0 + offset + 0.01 * c as f64))
            .collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    s.into_bytes()
}

/// Upload the grid as `user` (into `project`, else the personal
/// project); the DEM.
fn upload_as(base: &str, user: &User, project: Option<&str>, offset: f64) -> Reply {
    let query = match project {
        Some(p) => format!("?crs=EPSG:32633&project_id={p}"),
        None => "?crs=EPSG:32633".to_string(),
    };
    send_as(
        &user.auth,
        "POST",
        &format!("{base}/api/v1/dems{query}"),
        &[("Content-Type", "text/plain")],
        &asc_grid(offset),
        Framing::Length,
    )
}

fn created(r: &Reply, status: u16) -> Value {
    assert_eq!(r.status, status, "{}", r.text());
    r.json()
}

/// What `user` made: a DEM, a finished costmap of it, a route on that
/// and its replan, and a survey, all in `project` (else the personal one).
struct Made {
    dem: Value,
    costmap: Value,
    route: Value,
    replan: Value,
    survey: Value,
}

fn make_everything(server: &Server, user: &User, project: Option<&str>) -> Made {
    let dem = created(&upload_as(&server.base, user, project, 0.0), 201);
    let mut body = json!({"dem_id": dem["id"], "name": "iso", "options": {"layers": ["slope"]}});
    let mut survey_body = example_survey_request();
    if let Some(p) = project {
        body["project_id"] = json!(p);
        survey_body["project_id"] = json!(p);
    }
    let r = post_json_as(&user.auth, &server.url("/api/v1/costmaps"), &body);
    let id = created(&r, 202)["id"].as_str().unwrap().to_string();
    let costmap = wait_as(&server.base, user, &id);
    assert_eq!(costmap["status"], "done", "{costmap}");
    let route_body = json!({
        "start": {"utm": [500040.0, 5000040.0]},
        "goal": {"utm": [500160.0, 5000150.0]},
    });
    let r = post_json_as(
        &user.auth,
        &server.url(&format!("/api/v1/costmaps/{id}/routes")),
        &route_body,
    );
    let route = created(&r, 201);
    let r = post_json_as(
        &user.auth,
        &server.url(&format!(
            "/api/v1/routes/{}/replan",
            route["id"].as_str().unwrap()
        )),
        &json!({"position": {"utm": [500060.0, 5000060.0]}}),
    );
    let replan = created(&r, 201);
    let r = post_json_as(&user.auth, &server.url("/api/v1/surveys"), &survey_body);
    let survey = created(&r, 201);
    Made {
        dem,
        costmap,
        route,
        replan,
        survey,
    }
}

/// Poll costmap `id` as `user` until it is finished.
fn wait_as(base: &str, user: &User, id: &str) -> Value {
    let start = std::time::Instant::now();
    loop {
        let r = get_as(&user.auth, &format!("{base}/api/v1/costmaps/{id}"));
        assert_eq!(r.status, 200, "{}", r.text());
        let job = r.json();
        if job["status"] == "done" || job["status"] == "failed" {
            return job;
        }
        assert!(start.elapsed().as_secs() < 120, "costmap {id}: {job}");
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

fn id(v: &Value) -> &str {
    v["id"].as_str().unwrap()
}

/// One request of `user`: method, path with `{}` for the id, JSON body.
fn request(server: &Server, user: &User, method: &str, path: &str, body: Option<&Value>) -> Reply {
    let url = server.url(path);
    match body {
        Some(b) => send_as(
            &user.auth,
            method,
            &url,
            &[("Content-Type", "application/json")],
            b.to_string().as_bytes(),
            Framing::Length,
        ),
        None => send_as(&user.auth, method, &url, &[], &[], Framing::Length),
    }
}

/// The endpoints of a resource, as (method, path template, body): `{}`
/// is the resource's id.
fn endpoints(made: &Made) -> Vec<(&'static str, String, Option<Value>, &'static str)> {
    let uav = made.survey["uavs"][0]["id"].as_str().unwrap();
    let points = json!({"points": [[15.00127, 45.15438]]});
    let route =
        json!({"start": {"utm": [500040.0, 5000040.0]}, "goal": {"utm": [500160.0, 5000150.0]}});
    let replan = json!({"position": {"utm": [500060.0, 5000060.0]}});
    let mut all = Vec::new();
    let mut add = |method, template: &str, real: &'static str, body: Option<Value>| {
        all.push((method, template.to_string(), body, real));
    };
    add("GET", "/api/v1/dems/{}", "dem", None);
    add("GET", "/api/v1/dems/{}/hillshade.png", "dem", None);
    add(
        "GET",
        "/api/v1/dems/{}/elevation?lon=15.00127&lat=45.15438",
        "dem",
        None,
    );
    add("POST", "/api/v1/dems/{}/elevation", "dem", Some(points));
    add("GET", "/api/v1/costmaps/{}", "costmap", None);
    add("GET", "/api/v1/costmaps/{}/events", "costmap", None);
    add("GET", "/api/v1/costmaps/{}/costmap.tif", "costmap", None);
    add("GET", "/api/v1/costmaps/{}/preview.png", "costmap", None);
    add("GET", "/api/v1/costmaps/{}/legend.svg", "costmap", None);
    add(
        "GET",
        "/api/v1/costmaps/{}/layers/slope.tif",
        "costmap",
        None,
    );
    add("POST", "/api/v1/costmaps/{}/routes", "costmap", Some(route));
    add("GET", "/api/v1/routes/{}", "route", None);
    add("GET", "/api/v1/routes/{}/route.geojson", "route", None);
    add("GET", "/api/v1/routes/{}/route.csv", "route", None);
    add("GET", "/api/v1/routes/{}/mission.waypoints", "route", None);
    add("POST", "/api/v1/routes/{}/replan", "route", Some(replan));
    add("GET", "/api/v1/surveys/{}", "survey", None);
    add("GET", "/api/v1/surveys/{}/cells.geojson", "survey", None);
    let file = format!("/api/v1/surveys/{{}}/uavs/{uav}/mission.waypoints");
    add("GET", &file, "survey", None);
    // Deletes last, so that the reads above meet the resources.
    add("DELETE", "/api/v1/routes/{}", "route", None);
    add("DELETE", "/api/v1/surveys/{}", "survey", None);
    add("DELETE", "/api/v1/costmaps/{}", "costmap", None);
    add("DELETE", "/api/v1/dems/{}", "dem", None);
    all
}

fn real_id<'a>(made: &'a Made, kind: &str) -> &'a str {
    match kind {
        "dem" => id(&made.dem),
        "costmap" => id(&made.costmap),
        "route" => id(&made.route),
        _ => id(&made.survey),
    }
}

/// `hidden` (about `hidden_id`) is answered exactly as `missing` (about
/// `MISSING`): the same status, headers that matter and body but for
/// the id.
fn same_as_missing(what: &str, hidden: &Reply, hidden_id: &str, missing: &Reply) {
    assert_eq!(hidden.status, missing.status, "{what}: {}", hidden.text());
    assert_eq!(
        hidden.header("content-type"),
        missing.header("content-type"),
        "{what}"
    );
    assert_eq!(
        hidden.text().replace(hidden_id, MISSING),
        missing.text(),
        "{what}"
    );
}

/// Every endpoint of another user's resources answers 404 exactly like
/// a missing resource; the lists of the other user never show them; a
/// `dem_id`, land-cover source or `project_id` naming them is a 422 like
/// one naming nothing; and nothing of the owner's was touched.
#[test]
fn another_users_resources_are_missing_to_them() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let a = admin(&server);
    let b = new_user(&server, "iso-b");
    let made = make_everything(&server, &a, None);
    let personal_a = made.dem["project_id"].as_str().unwrap().to_string();
    assert!(!personal_a.is_empty(), "{}", made.dem);
    // Every representation names its project; a route its costmap's.
    for v in [&made.costmap, &made.route, &made.replan, &made.survey] {
        assert_eq!(v["project_id"], personal_a.as_str(), "{v}");
    }

    for (method, template, body, kind) in endpoints(&made) {
        let real = real_id(&made, kind);
        let path = template.replace("{}", real);
        let what = format!("{method} {template}");
        let hidden = request(&server, &b, method, &path, body.as_ref());
        let missing = request(
            &server,
            &b,
            method,
            &template.replace("{}", MISSING),
            body.as_ref(),
        );
        assert_problem(&hidden, 404, "there is no");
        same_as_missing(&what, &hidden, real, &missing);
        // The owner still has it (B's deletes deleted nothing).
        let owner = request(&server, &a, "GET", &format!("/api/v1/{kind}s/{real}"), None);
        assert_eq!(owner.status, 200, "{what}: {}", owner.text());
    }

    // B's lists are empty, however asked; A's own project is no project
    // of B's, just like one that does not exist.
    for list in ["dems", "surveys", "costmaps", "routes"] {
        let r = get_as(&b.auth, &server.url(&format!("/api/v1/{list}")));
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(r.json()["total"], 0, "{list}: {}", r.text());
        assert_eq!(r.json()["items"], json!([]), "{list}");
        let costmap_filter = format!("/api/v1/{list}?costmap_id={}", id(&made.costmap));
        let r = get_as(&b.auth, &server.url(&costmap_filter));
        assert_eq!(r.json()["total"], 0, "{list}: {}", r.text());
        let theirs = get_as(
            &b.auth,
            &server.url(&format!("/api/v1/{list}?project_id={personal_a}")),
        );
        let none = get_as(
            &b.auth,
            &server.url(&format!("/api/v1/{list}?project_id={MISSING}")),
        );
        assert_problem(&theirs, 404, "there is no project");
        same_as_missing(list, &theirs, &personal_a, &none);
        // A sees them, with and without the filter.
        for query in ["", &format!("?project_id={personal_a}")] {
            let r = get_as(&a.auth, &server.url(&format!("/api/v1/{list}{query}")));
            assert_eq!(r.status, 200, "{}", r.text());
            let expected = if list == "routes" { 2 } else { 1 };
            assert_eq!(r.json()["total"], expected, "{list}{query}: {}", r.text());
            for item in r.json()["items"].as_array().unwrap() {
                assert_eq!(item["project_id"], personal_a.as_str(), "{item}");
            }
        }
    }

    // Naming A's DEM in B's requests: the answer of a missing DEM.
    let dem_a = id(&made.dem);
    let costmaps = server.url("/api/v1/costmaps");
    let surveys = server.url("/api/v1/surveys");
    for (url, body_of, pointer) in [
        (
            &costmaps,
            (|d: &str| json!({"dem_id": d})) as fn(&str) -> Value,
            "/dem_id",
        ),
        (
            &surveys,
            |d: &str| {
                let mut s = example_survey_request();
                s["dem_id"] = json!(d);
                s
            },
            "/dem_id",
        ),
    ] {
        let hidden = post_json_as(&b.auth, url, &body_of(dem_a));
        let missing = post_json_as(&b.auth, url, &body_of(MISSING));
        assert_invalid_at(&hidden, url, pointer, "no DEM with id");
        same_as_missing(url, &hidden, dem_a, &missing);
    }
    // As a land-cover source, next to a DEM of B's own.
    let dem_b = created(&upload_as(&server.base, &b, None, 1.0), 201);
    let landcover = |source: &str| {
        json!({"dem_id": id(&dem_b), "options": {"landcover": {
            "source": source, "classes": [{"code": 1, "cost": 3.0}]
        }}})
    };
    let hidden = post_json_as(&b.auth, &costmaps, &landcover(dem_a));
    let missing = post_json_as(&b.auth, &costmaps, &landcover(MISSING));
    assert_invalid_at(
        &hidden,
        "landcover",
        "/options/landcover/source",
        "no DEM with id",
    );
    same_as_missing("landcover", &hidden, dem_a, &missing);
    // A's project as the project of B's new resources.
    for (url, body) in [
        (
            &costmaps,
            json!({"dem_id": id(&dem_b), "project_id": personal_a}),
        ),
        (&surveys, {
            let mut s = example_survey_request();
            s["project_id"] = json!(personal_a);
            s
        }),
    ] {
        let hidden = post_json_as(&b.auth, url, &body);
        let mut other = body.clone();
        other["project_id"] = json!(MISSING);
        let missing = post_json_as(&b.auth, url, &other);
        assert_invalid_at(&hidden, url, "/project_id", "no project");
        same_as_missing(url, &hidden, &personal_a, &missing);
    }
    let upload = upload_as(&server.base, &b, Some(&personal_a), 0.0);
    let missing = upload_as(&server.base, &b, Some(MISSING), 0.0);
    assert_invalid_at(&upload, "upload", "/project_id", "no project");
    same_as_missing("upload", &upload, &personal_a, &missing);
    // B's own DEM is B's: in B's personal project, which is not A's.
    assert_ne!(dem_b["project_id"], personal_a.as_str());
    let r = get_as(&b.auth, &server.url("/api/v1/dems"));
    assert_eq!(r.json()["total"], 1, "{}", r.text());
    assert_eq!(r.json()["items"][0]["id"], id(&dem_b));
    server.stop();
}

/// A viewer member of a project reads, lists and downloads its resources
/// but gets 403 on every write; as an editor the same writes succeed.
#[test]
fn viewers_read_and_editors_write() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let a = admin(&server);
    let b = new_user(&server, "iso-viewer");
    let r = post_json_as(
        &a.auth,
        &server.url("/api/v1/projects"),
        &json!({"name": "shared"}),
    );
    let project = created(&r, 201)["id"].as_str().unwrap().to_string();
    let members = server.url(&format!("/api/v1/projects/{project}/members"));
    let r = post_json_as(
        &a.auth,
        &members,
        &json!({"user": b.name, "role": "viewer"}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let made = make_everything(&server, &a, Some(&project));
    for v in [
        &made.dem,
        &made.costmap,
        &made.route,
        &made.replan,
        &made.survey,
    ] {
        assert_eq!(v["project_id"], project.as_str(), "{v}");
    }

    let mut writes = 0;
    for (method, template, body, kind) in endpoints(&made) {
        let path = template.replace("{}", real_id(&made, kind));
        let r = request(&server, &b, method, &path, body.as_ref());
        let write = method == "DELETE" || path.ends_with("/routes") || path.ends_with("/replan");
        if write {
            writes += 1;
            let p = assert_problem(&r, 403, "needs the editor role");
            assert!(p["detail"].as_str().unwrap().contains(&project), "{p}");
        } else {
            assert!(r.status == 200, "{method} {template}: {}", r.text());
        }
    }
    assert_eq!(writes, 6);
    // Listed with and without the filter.
    for list in ["dems", "surveys", "costmaps", "routes"] {
        for query in ["".to_string(), format!("?project_id={project}")] {
            let r = get_as(&b.auth, &server.url(&format!("/api/v1/{list}{query}")));
            let expected = if list == "routes" { 2 } else { 1 };
            assert_eq!(r.json()["total"], expected, "{list}{query}: {}", r.text());
        }
    }
    // New resources in the project: 403 too (a member, but a viewer).
    let r = post_json_as(
        &b.auth,
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": id(&made.dem), "project_id": project}),
    );
    assert_problem(&r, 403, "needs the editor role");
    let mut survey = example_survey_request();
    survey["project_id"] = json!(project);
    assert_problem(
        &post_json_as(&b.auth, &server.url("/api/v1/surveys"), &survey),
        403,
        "needs the editor role",
    );
    assert_problem(
        &upload_as(&server.base, &b, Some(&project), 0.0),
        403,
        "needs the editor role",
    );
    // A DEM it can read is one it may build on, in its own project.
    let r = post_json_as(
        &b.auth,
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": id(&made.dem)}),
    );
    let own = created(&r, 202);
    assert_ne!(own["project_id"], project.as_str(), "{own}");

    // As an editor, the writes go through.
    let r = post_json_as(
        &a.auth,
        &members,
        &json!({"user": b.name, "role": "editor"}),
    );
    assert_eq!(r.status, 200, "{}", r.text());
    let r = request(
        &server,
        &b,
        "DELETE",
        &format!("/api/v1/surveys/{}", id(&made.survey)),
        None,
    );
    assert_eq!(r.status, 204, "{}", r.text());
    let r = get_as(
        &a.auth,
        &server.url(&format!("/api/v1/surveys/{}", id(&made.survey))),
    );
    assert_eq!(r.status, 404, "{}", r.text());
    server.stop();
}

/// Two users working at once, in parallel threads, never see each
/// other's work: their lists hold only their own items, and the same
/// costmap and DEM ids asked by both (the owner's, cached by its use)
/// answer the owner and are missing to the other, over polling, SSE and
/// the DEM cache.
#[test]
fn concurrent_users_never_cross() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let a = admin(&server);
    let b = new_user(&server, "iso-par");
    let shared = created(&upload_as(&server.base, &a, None, 0.0), 201);
    let r = post_json_as(
        &a.auth,
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": id(&shared)}),
    );
    let costmap = created(&r, 202)["id"].as_str().unwrap().to_string();
    let dem = id(&shared).to_string();

    let base = server.base.clone();
    let url = |path: &str| format!("{base}{path}");
    let work = |user: &User, owner: bool| {
        let mut mine = Vec::new();
        for round in 0..6 {
            let dem_r = created(&upload_as(&base, user, None, round as f64), 201);
            mine.push(id(&dem_r).to_string());
            let r = post_json_as(
                &user.auth,
                &url("/api/v1/surveys"),
                &example_survey_request(),
            );
            mine.push(id(&created(&r, 201)).to_string());
            for list in ["dems", "surveys"] {
                let r = get_as(&user.auth, &url(&format!("/api/v1/{list}?limit=100")));
                assert_eq!(r.status, 200, "{}", r.text());
                for item in r.json()["items"].as_array().unwrap() {
                    let item_id = item["id"].as_str().unwrap();
                    let known = mine.iter().any(|m| m == item_id) || (owner && item_id == dem);
                    assert!(known, "{} sees {list} item {item}", user.name);
                }
            }
            // The owner's costmap and DEM, asked by both at once.
            let status = if owner { 200 } else { 404 };
            let r = get_as(&user.auth, &url(&format!("/api/v1/costmaps/{costmap}")));
            assert_eq!(r.status, status, "{}: {}", user.name, r.text());
            let elevation = format!("/api/v1/dems/{dem}/elevation?lon=15.00127&lat=45.15438");
            let r = get_as(&user.auth, &url(&elevation));
            assert_eq!(r.status, status, "{}: {}", user.name, r.text());
            if owner {
                let h = r.json()["elevation"].as_f64().unwrap();
                assert!((100.0..=101.0).contains(&h), "{h}");
            }
        }
        // The event stream of the owner's costmap.
        let url = url(&format!("/api/v1/costmaps/{costmap}/events"));
        if owner {
            wait_as(&base, user, &costmap);
            let r = get_with_timeout(&url, std::time::Duration::from_secs(60));
            assert_eq!(r.status, 200, "{}", r.text());
            let events = sse_events(&r.text());
            assert_eq!(
                events.last().map(|e| e.0.as_str()),
                Some("done"),
                "{events:?}"
            );
        } else {
            let r = get_as(&user.auth, &url);
            assert_problem(&r, 404, "there is no costmap");
        }
        mine
    };
    let (mine_a, mine_b) = std::thread::scope(|s| {
        let ta = s.spawn(|| work(&a, true));
        let tb = s.spawn(|| work(&b, false));
        (ta.join().unwrap(), tb.join().unwrap())
    });
    // Afterwards each list holds exactly its owner's items.
    for (user, mine, extra) in [(&a, &mine_a, 1), (&b, &mine_b, 0)] {
        let r = get_as(&user.auth, &server.url("/api/v1/dems?limit=100"));
        assert_eq!(r.json()["total"], mine.len() / 2 + extra, "{}", r.text());
        let r = get_as(&user.auth, &server.url("/api/v1/surveys?limit=100"));
        assert_eq!(r.json()["total"], mine.len() / 2, "{}", r.text());
    }
    server.stop();
}
