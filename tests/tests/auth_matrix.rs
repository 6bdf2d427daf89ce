//! Every operation of the OpenAPI document, called four ways: without
//! credentials (401 on every closed operation), as a user outside the
//! resource's project (404 exactly like a missing resource), as a viewer
//! of it (reads pass, writes get 403), and as its owner (success).
//!
//! Driven by the document: an operation the document lists and this file
//! has no case for fails the test, so a new endpoint cannot be left out
//! of the security matrix; a case for an operation the document no longer
//! has fails too.

use serde_json::{Value, json};
use terraplan_e2e::{
    Auth, Framing, Reply, Server, dtm, example_survey_request, get, last_line, post_json, send_as,
    text, unique_user_name, upload_dem, user_command, wait_costmap_finished,
};

/// What one identity gets from one operation.
#[derive(Clone, Copy, Debug)]
enum Want {
    Status(u16),
    /// Any 2xx.
    Success,
}

impl Want {
    fn accepts(self, status: u16) -> bool {
        match self {
            Want::Status(s) => s == status,
            Want::Success => (200..300).contains(&status),
        }
    }
}

/// One operation of the document, with what each identity gets.
struct Case {
    method: &'static str,
    template: &'static str,
    /// Reads run first, then writes, then deletes in this order (so what a
    /// later case needs still exists).
    phase: u8,
    stranger: Want,
    viewer: Want,
    owner: Want,
}

const OK: Want = Want::Success;
const S401: Want = Want::Status(401);
const S403: Want = Want::Status(403);
const S404: Want = Want::Status(404);
const S422: Want = Want::Status(422);

/// Open to anyone: every identity, and none, succeeds.
const OPEN: [(&str, &str); 4] = [
    ("GET", "/api/v1/openapi.json"),
    ("GET", "/api/v1/vehicles"),
    ("GET", "/api/v1/cameras"),
    ("POST", "/api/v1/session"),
];

fn cases() -> Vec<Case> {
    let c = |method, template, phase, stranger, viewer, owner| Case {
        method,
        template,
        phase,
        stranger,
        viewer,
        owner,
    };
    vec![
        // Lists show each caller its own; creating in a project one is not
        // a member of is a 422 at /project_id, as for a missing project.
        c("GET", "/api/v1/surveys", 0, OK, OK, OK),
        c("GET", "/api/v1/dems", 0, OK, OK, OK),
        c("GET", "/api/v1/costmaps", 0, OK, OK, OK),
        c("GET", "/api/v1/routes", 0, OK, OK, OK),
        c("GET", "/api/v1/projects", 0, OK, OK, OK),
        c("GET", "/api/v1/tokens", 0, OK, OK, OK),
        c("GET", "/api/v1/session", 0, OK, OK, OK),
        c("GET", "/api/v1/users", 0, S403, S403, OK),
        // Imports read a file and store nothing: any signed-in user.
        c("POST", "/api/v1/imports", 0, OK, OK, OK),
        // Reads of the shared project's resources.
        c("GET", "/api/v1/surveys/{id}", 0, S404, OK, OK),
        c(
            "GET",
            "/api/v1/surveys/{id}/uavs/{uav}/{file}",
            0,
            S404,
            OK,
            OK,
        ),
        c("GET", "/api/v1/surveys/{id}/cells.geojson", 0, S404, OK, OK),
        c("GET", "/api/v1/dems/{id}", 0, S404, OK, OK),
        c("GET", "/api/v1/dems/{id}/hillshade.png", 0, S404, OK, OK),
        c("GET", "/api/v1/dems/{id}/dem.tif", 0, S404, OK, OK),
        c("GET", "/api/v1/dems/{id}/window", 0, S404, OK, OK),
        c("GET", "/api/v1/dems/{id}/elevation", 0, S404, OK, OK),
        c("POST", "/api/v1/dems/{id}/elevation", 0, S404, OK, OK),
        c("GET", "/api/v1/costmaps/{id}", 0, S404, OK, OK),
        c("GET", "/api/v1/costmaps/{id}/events", 0, S404, OK, OK),
        c("GET", "/api/v1/costmaps/{id}/costmap.tif", 0, S404, OK, OK),
        c("GET", "/api/v1/costmaps/{id}/preview.png", 0, S404, OK, OK),
        c("GET", "/api/v1/costmaps/{id}/legend.svg", 0, S404, OK, OK),
        c(
            "GET",
            "/api/v1/costmaps/{id}/layers/{file}",
            0,
            S404,
            OK,
            OK,
        ),
        c("GET", "/api/v1/routes/{id}", 0, S404, OK, OK),
        c("GET", "/api/v1/routes/{id}/route.geojson", 0, S404, OK, OK),
        c("GET", "/api/v1/routes/{id}/route.csv", 0, S404, OK, OK),
        c(
            "GET",
            "/api/v1/routes/{id}/mission.waypoints",
            0,
            S404,
            OK,
            OK,
        ),
        c("GET", "/api/v1/projects/{id}", 0, S404, OK, OK),
        c("GET", "/api/v1/projects/{id}/members", 0, S404, OK, OK),
        c("GET", "/api/v1/vehicle-links", 0, OK, OK, OK),
        // Writes.
        c("POST", "/api/v1/surveys", 1, S422, S403, OK),
        c("POST", "/api/v1/dems", 1, S422, S403, OK),
        c("POST", "/api/v1/costmaps", 1, S422, S403, OK),
        c("POST", "/api/v1/costmaps/{id}/routes", 1, S404, S403, OK),
        c("POST", "/api/v1/routes/{id}/replan", 1, S404, S403, OK),
        c(
            "POST",
            "/api/v1/surveys/{id}/uavs/{uav}/upload",
            1,
            S404,
            S403,
            OK,
        ),
        c("POST", "/api/v1/projects", 1, OK, OK, OK),
        c("POST", "/api/v1/projects/{id}/members", 1, S404, S403, OK),
        c("POST", "/api/v1/tokens", 1, OK, OK, OK),
        c("POST", "/api/v1/users", 1, S403, S403, OK),
        // Each changes its own password (the test's users have none yet).
        c("POST", "/api/v1/session/password", 1, OK, OK, OK),
        // Deletes, children before parents.
        c("DELETE", "/api/v1/routes/{id}", 2, S404, S403, OK),
        c("DELETE", "/api/v1/costmaps/{id}", 3, S404, S403, OK),
        c("DELETE", "/api/v1/surveys/{id}", 3, S404, S403, OK),
        c("DELETE", "/api/v1/dems/{id}", 4, S404, S403, OK),
        c(
            "DELETE",
            "/api/v1/projects/{id}/members/{user}",
            4,
            S404,
            S403,
            OK,
        ),
        c("DELETE", "/api/v1/projects/{id}", 5, S404, S403, OK),
        c("DELETE", "/api/v1/tokens/{id}", 5, S404, S404, OK),
        c("POST", "/api/v1/users/{name}/disable", 5, S403, S403, OK),
        c("DELETE", "/api/v1/session", 6, OK, OK, OK),
    ]
}

/// The resources the cases act on: all in `project`, where the viewer is
/// a viewer and the stranger nothing.
struct Fixture {
    project: String,
    /// An empty project (the viewer a viewer in it), for the delete case.
    spare_project: String,
    dem: String,
    survey: String,
    uav: String,
    uav_file: String,
    costmap: String,
    layer: String,
    route: String,
    /// Request bodies of the route cases.
    route_body: Value,
    /// A point inside the DEM.
    point: [f64; 2],
    /// One of the owner's own tokens, to revoke.
    owner_token_id: String,
    /// The owner's token (signing in with it opens a session).
    owner_token: String,
    /// A member of `project` to remove, and a user to add.
    removable_member: String,
    new_member: String,
    /// A user to disable.
    disposable_user: String,
}

fn make_user(server: &Server, prefix: &str) -> (String, String) {
    let name = unique_user_name(prefix);
    let out = user_command(&server.data_dir, &["create", &name], None);
    assert!(
        out.status.success(),
        "terraplan user create {name}: {}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    (name.clone(), last_line(&out))
}

fn created(r: &Reply, what: &str) -> Value {
    assert!(
        (200..300).contains(&r.status),
        "{what}: {} {}",
        r.status,
        r.text()
    );
    r.json()
}

fn add_member(server: &Server, project: &str, user: &str, role: &str) {
    let r = post_json(
        &server.url(&format!("/api/v1/projects/{project}/members")),
        &json!({"user": user, "role": role}),
    );
    created(&r, "add a member");
}

fn fixture(server: &Server, viewer: &str) -> Fixture {
    let project = created(
        &post_json(&server.url("/api/v1/projects"), &json!({"name": "shared"})),
        "make a project",
    )["id"]
        .as_str()
        .unwrap()
        .to_string();
    let spare_project = created(
        &post_json(&server.url("/api/v1/projects"), &json!({"name": "spare"})),
        "make a project",
    )["id"]
        .as_str()
        .unwrap()
        .to_string();
    add_member(server, &project, viewer, "viewer");
    add_member(server, &spare_project, viewer, "viewer");
    let (removable_member, _) = make_user(server, "leaving");
    add_member(server, &project, &removable_member, "editor");
    let (new_member, _) = make_user(server, "joining");
    let (disposable_user, _) = make_user(server, "disposable");

    let data = std::fs::read(dtm()).unwrap();
    let r = send_as(
        &Auth::Server,
        "POST",
        &server.url(&format!("/api/v1/dems?project_id={project}")),
        &[("Content-Type", "image/tiff")],
        &data,
        Framing::Length,
    );
    let dem_doc = created(&r, "upload the DEM");
    let dem = dem_doc["id"].as_str().unwrap().to_string();
    let b = bounds_of(&dem_doc);
    let point = [(b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0];

    let mut survey_req = example_survey_request();
    survey_req["project_id"] = json!(project);
    let survey_doc = created(
        &post_json(&server.url("/api/v1/surveys"), &survey_req),
        "plan a survey",
    );
    let survey = survey_doc["id"].as_str().unwrap().to_string();
    let full = get(&server.url(&format!("/api/v1/surveys/{survey}")));
    let (uav, uav_file) = first_uav_file(&created(&full, "read the survey"));

    let r = post_json(
        &server.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "project_id": project, "options": {"layers": ["slope"]}}),
    );
    let costmap = created(&r, "ask for a costmap")["id"]
        .as_str()
        .unwrap()
        .to_string();
    let job = wait_costmap_finished(server, &costmap);
    assert_eq!(job["status"], "done", "{job}");
    let layer = first_layer(&job);
    let (route, route_body) = first_route(server, &costmap, b);
    let owner_token_id = created(
        &post_json(&server.url("/api/v1/tokens"), &json!({"name": "to revoke"})),
        "make a token",
    )["id"]
        .as_str()
        .unwrap()
        .to_string();
    Fixture {
        project,
        spare_project,
        dem,
        survey,
        uav,
        uav_file,
        costmap,
        layer,
        route,
        route_body,
        point,
        owner_token_id,
        owner_token: server.token.clone(),
        removable_member,
        new_member,
        disposable_user,
    }
}

/// `[west, south, east, north]` of a DEM document.
fn bounds_of(dem: &Value) -> [f64; 4] {
    let b = if dem["bounds_wgs84"].is_array() {
        &dem["bounds_wgs84"]
    } else {
        &dem["info"]["bounds_wgs84"]
    };
    let v: Vec<f64> = b
        .as_array()
        .unwrap_or_else(|| panic!("no bounds_wgs84 in {dem}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    [v[0], v[1], v[2], v[3]]
}

/// The first UAV of a survey and the name of one of its files, from the
/// download links the survey document gives.
fn first_uav_file(survey: &Value) -> (String, String) {
    let text = survey.to_string();
    let marker = "/uavs/";
    let at = text
        .find(marker)
        .unwrap_or_else(|| panic!("no UAV file link in {survey}"));
    let rest = &text[at + marker.len()..];
    let end = rest.find('"').unwrap();
    let (uav, file) = rest[..end].split_once('/').expect("uav/file");
    (uav.to_string(), file.to_string())
}

/// The name of one layer file of a finished costmap.
fn first_layer(job: &Value) -> String {
    let text = job.to_string();
    let marker = "/layers/";
    let at = text
        .find(marker)
        .unwrap_or_else(|| panic!("no layer link in {job}"));
    let rest = &text[at + marker.len()..];
    rest[..rest.find('"').unwrap()].to_string()
}

/// A route across the costmap: the first pair of points around the DEM's
/// centre that the planner joins.
fn first_route(server: &Server, costmap: &str, b: [f64; 4]) -> (String, Value) {
    let (cx, cy) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let (dx, dy) = ((b[2] - b[0]) / 4.0, (b[3] - b[1]) / 4.0);
    let offsets = [
        (-1.0, -1.0),
        (1.0, 1.0),
        (-1.0, 1.0),
        (1.0, -1.0),
        (0.0, -1.0),
        (0.0, 1.0),
    ];
    for (i, a) in offsets.iter().enumerate() {
        for z in &offsets[i + 1..] {
            let body = json!({
                "start": [cx + a.0 * dx, cy + a.1 * dy],
                "goal": [cx + z.0 * dx, cy + z.1 * dy],
            });
            let r = post_json(
                &server.url(&format!("/api/v1/costmaps/{costmap}/routes")),
                &body,
            );
            if r.status == 201 {
                return (r.json()["id"].as_str().unwrap().to_string(), body);
            }
        }
    }
    panic!("no route between any of the test points of costmap {costmap}");
}

impl Fixture {
    /// The URL, content type and body of `case` on this fixture.
    fn request(&self, case: &Case) -> (String, &'static str, Vec<u8>) {
        let id_of = |template: &str| -> String {
            let seg = template.trim_start_matches("/api/v1/");
            match seg.split('/').next().unwrap() {
                "surveys" => self.survey.clone(),
                "dems" => self.dem.clone(),
                "costmaps" => self.costmap.clone(),
                "routes" => self.route.clone(),
                "projects" if case.method == "DELETE" && !template.contains("members") => {
                    self.spare_project.clone()
                }
                "projects" => self.project.clone(),
                "tokens" => self.owner_token_id.clone(),
                other => panic!("no id for {other}"),
            }
        };
        let mut path = case.template.to_string();
        if path.contains("{id}") {
            path = path.replace("{id}", &id_of(case.template));
        }
        let mut path = path
            .replace("{uav}", &self.uav)
            .replace("{name}", &self.disposable_user)
            .replace("{user}", &self.removable_member);
        path = if path.contains("/uavs/") {
            path.replace("{file}", &self.uav_file)
        } else {
            path.replace("{file}", &self.layer)
        };
        let json_body = |v: Value| ("application/json", v.to_string().into_bytes());
        let (content_type, body) = match (case.method, case.template) {
            ("GET", "/api/v1/dems/{id}/elevation") => {
                path.push_str(&format!("?lon={}&lat={}", self.point[0], self.point[1]));
                ("", Vec::new())
            }
            ("POST", "/api/v1/dems/{id}/elevation") => json_body(json!({"points": [self.point]})),
            ("GET", "/api/v1/dems/{id}/window") => {
                path.push_str("?col=0&row=0&width=1&height=1");
                ("", Vec::new())
            }
            ("POST", "/api/v1/surveys") => {
                let mut req = example_survey_request();
                req["project_id"] = json!(self.project);
                json_body(req)
            }
            ("POST", "/api/v1/dems") => {
                path.push_str(&format!("?project_id={}", self.project));
                ("image/tiff", std::fs::read(dtm()).unwrap())
            }
            ("POST", "/api/v1/costmaps") => {
                json_body(json!({"dem_id": self.dem, "project_id": self.project}))
            }
            ("POST", "/api/v1/imports") => {
                let kml = "<kml><Placemark><LineString><coordinates>6.06,51.51 6.07,51.52\
                           </coordinates></LineString></Placemark></kml>";
                let (_, body) = terraplan_e2e::multipart_body(&[terraplan_e2e::Part {
                    name: "file",
                    file_name: Some("line.kml"),
                    content_type: None,
                    data: kml.as_bytes(),
                }]);
                (
                    "multipart/form-data; boundary=terraplan-e2e-7d1f0c9a4b2e",
                    body,
                )
            }
            ("POST", "/api/v1/costmaps/{id}/routes") => json_body(self.route_body.clone()),
            ("POST", "/api/v1/routes/{id}/replan") => {
                json_body(json!({"position": self.route_body["start"]}))
            }
            ("POST", "/api/v1/projects") => json_body(json!({"name": "another"})),
            ("POST", "/api/v1/projects/{id}/members") => {
                json_body(json!({"user": self.new_member, "role": "viewer"}))
            }
            ("POST", "/api/v1/surveys/{id}/uavs/{uav}/upload") => {
                json_body(json!({"to": "udpout:127.0.0.1:9", "timeout_ms": 10, "retries": 0}))
            }
            ("POST", "/api/v1/tokens") => json_body(json!({"name": "matrix"})),
            ("POST", "/api/v1/users") => {
                json_body(json!({"name": unique_user_name("made"), "password": "a long password"}))
            }
            ("POST", "/api/v1/session") => json_body(json!({"token": self.owner_token})),
            ("POST", "/api/v1/session/password") => {
                json_body(json!({"new": "a long enough password"}))
            }
            ("POST", _) => json_body(json!({})),
            _ => ("", Vec::new()),
        };
        (path, content_type, body)
    }
}

fn call(server: &Server, auth: &Auth, method: &str, path: &str, ct: &str, body: &[u8]) -> Reply {
    let headers: Vec<(&str, &str)> = if ct.is_empty() {
        vec![]
    } else {
        vec![("Content-Type", ct)]
    };
    send_as(
        auth,
        method,
        &server.url(path),
        &headers,
        body,
        Framing::Length,
    )
}

/// The operations of the served OpenAPI document.
fn documented_operations(server: &Server) -> Vec<(String, String)> {
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let mut ops = Vec::new();
    for (path, item) in doc["paths"].as_object().expect("paths") {
        for method in ["get", "post", "put", "patch", "delete"] {
            if item.get(method).is_some() {
                ops.push((method.to_uppercase(), path.clone()));
            }
        }
    }
    ops
}

#[test]
fn every_documented_operation_checks_credentials_membership_and_role() {
    let dir = tempfile::tempdir().unwrap();
    // Vehicle links on, to a port where no vehicle answers: the owner's
    // upload starts (200, an event stream ending in `failed`).
    let server = Server::start(
        &dir.path().join("data"),
        &["--vehicle-links", "udpout:127.0.0.1:9"],
    );
    let (viewer_name, viewer_token) = make_user(&server, "viewer");
    let (_, stranger_token) = make_user(&server, "stranger");
    let fx = fixture(&server, &viewer_name);

    let mut cases = cases();
    let documented = documented_operations(&server);
    let api: Vec<&(String, String)> = documented
        .iter()
        .filter(|(_, p)| p.starts_with("/api/v1/"))
        .collect();
    let missing: Vec<String> = api
        .iter()
        .filter(|(m, p)| {
            !OPEN.contains(&(m.as_str(), p.as_str()))
                && !cases.iter().any(|c| c.method == m && c.template == p)
        })
        .map(|(m, p)| format!("{m} {p}"))
        .collect();
    assert!(
        missing.is_empty(),
        "operations of the OpenAPI document without a case here: {missing:?}"
    );
    let stale: Vec<String> = cases
        .iter()
        .filter(|c| !api.iter().any(|(m, p)| m == c.method && p == c.template))
        .map(|c| format!("{} {}", c.method, c.template))
        .collect();
    assert!(
        stale.is_empty(),
        "cases for operations the document does not have: {stale:?}"
    );

    // Open operations answer without credentials.
    for (method, path) in OPEN {
        let case = Case {
            method,
            template: path,
            phase: 0,
            stranger: OK,
            viewer: OK,
            owner: OK,
        };
        let (url, ct, body) = fx.request(&case);
        let r = call(&server, &Auth::None, method, &url, ct, &body);
        assert_ne!(r.status, 401, "{method} {path} is open: {}", r.text());
        assert!(r.status < 500, "{method} {path}: {} {}", r.status, r.text());
    }

    cases.sort_by_key(|c| c.phase);
    let mut failures = Vec::new();
    let mut checked = 0;
    for case in &cases {
        let (url, ct, body) = fx.request(case);
        let who = [
            ("no credentials", Auth::None, S401),
            (
                "a stranger",
                Auth::Bearer(stranger_token.clone()),
                case.stranger,
            ),
            ("a viewer", Auth::Bearer(viewer_token.clone()), case.viewer),
            ("the owner", Auth::Bearer(server.token.clone()), case.owner),
        ];
        for (name, auth, want) in who {
            let r = call(&server, &auth, case.method, &url, ct, &body);
            checked += 1;
            if !want.accepts(r.status) {
                failures.push(format!(
                    "{} {} as {name}: {} (wanted {want:?}): {}",
                    case.method,
                    url,
                    r.status,
                    &r.text().chars().take(300).collect::<String>()
                ));
            } else if r.status >= 400 {
                let problem: Value = serde_json::from_slice(&r.body).unwrap_or(Value::Null);
                if problem["status"] != json!(r.status) {
                    failures.push(format!(
                        "{} {url} as {name}: {} is not problem+json: {}",
                        case.method,
                        r.status,
                        r.text()
                    ));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {checked} calls answered wrongly:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// A resource of another project and a missing one answer alike: the
/// same status and the same problem, apart from the id named.
#[test]
fn another_projects_resource_answers_like_a_missing_one() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let (_, stranger) = make_user(&server, "stranger");
    let dem = upload_dem(&server, &dtm());
    let missing = "00000000-0000-7000-8000-000000000000";
    for path in ["/api/v1/dems/{}", "/api/v1/dems/{}/hillshade.png"] {
        let theirs = call(
            &server,
            &Auth::Bearer(stranger.clone()),
            "GET",
            &path.replace("{}", &dem),
            "",
            &[],
        );
        let none = call(
            &server,
            &Auth::Bearer(stranger.clone()),
            "GET",
            &path.replace("{}", missing),
            "",
            &[],
        );
        assert_eq!(theirs.status, 404, "{}", theirs.text());
        assert_eq!(none.status, 404, "{}", none.text());
        assert_eq!(
            theirs.text().replace(&dem, "ID"),
            none.text().replace(missing, "ID"),
            "a hidden DEM must answer exactly like a missing one"
        );
    }
}
