//! Accounts end to end (issue 19): `terraplan user …`, the first start's
//! admin, credentials (API tokens, the session cookie and its CSRF token),
//! the token, user, project and member endpoints, and secrets never stored
//! in clear. On PostgreSQL too (`TERRAPLAN_TEST_DATABASE_URL`): every name
//! is unique, as all servers of that run share one database.

use std::path::Path;
use std::time::Duration;

use serde_json::{Value, json};
use terraplan_e2e::{
    Auth, Framing, Reply, Server, assert_invalid_at, assert_problem, delete_as, get, get_as,
    last_line, post_json, post_json_as, send_as, text, unique_user_name, user_command,
};

const PASSWORD: &str = "correct horse battery";
/// No sign-in rate limit: these tests sign in many times from one address.
const NO_LIMIT: &[&str] = &["--sign-in-per-minute", "0"];

fn on_postgres() -> bool {
    std::env::var("TERRAPLAN_TEST_DATABASE_URL").is_ok()
}

/// `terraplan user create NAME` (with `--password-stdin` when `password`
/// is given); the user's name and token.
fn make_user(dir: &Path, prefix: &str, password: Option<&str>, admin: bool) -> (String, String) {
    let name = unique_user_name(prefix);
    let mut args = vec!["create", name.as_str()];
    if admin {
        args.push("--admin");
    }
    if password.is_some() {
        args.push("--password-stdin");
    }
    let out = user_command(dir, &args, password.map(|p| format!("{p}\n")).as_deref());
    assert!(out.status.success(), "{}", text(&out.stderr));
    let token = last_line(&out);
    assert!(token.starts_with("tp_"), "{token}");
    (name, token)
}

fn bearer(token: &str) -> Auth {
    Auth::Bearer(token.to_string())
}

/// The name `GET /api/v1/session` reports for `auth`.
fn whoami(server: &Server, auth: &Auth) -> Reply {
    get_as(auth, &server.url("/api/v1/session"))
}

/// `POST /api/v1/session` with `body` (and extra headers).
fn sign_in(server: &Server, body: &Value, headers: &[(&str, &str)]) -> Reply {
    let mut all = vec![("Content-Type", "application/json")];
    all.extend_from_slice(headers);
    send_as(
        &Auth::None,
        "POST",
        &server.url("/api/v1/session"),
        &all,
        body.to_string().as_bytes(),
        Framing::Length,
    )
}

/// The session cookie's value in a sign-in answer.
fn session_of(r: &Reply) -> String {
    let cookie = r.header("set-cookie").expect("Set-Cookie");
    cookie
        .split(';')
        .next()
        .and_then(|c| c.strip_prefix("terraplan_session="))
        .unwrap_or_else(|| panic!("{cookie}"))
        .to_string()
}

/// Run `statement` on the test database (sqlite3 on the data directory's
/// file, psql on PostgreSQL); what it prints, bare values one a line.
fn sql(dir: &Path, statement: &str) -> String {
    let out = match std::env::var("TERRAPLAN_TEST_DATABASE_URL") {
        Ok(url) => std::process::Command::new("psql")
            .args([
                url.as_str(),
                "-tA",
                "-v",
                "ON_ERROR_STOP=1",
                "-c",
                statement,
            ])
            .output(),
        Err(_) => std::process::Command::new("sqlite3")
            .arg(dir.join("terraplan.sqlite3"))
            .arg(statement)
            .output(),
    }
    .expect("sqlite3 / psql");
    assert!(out.status.success(), "{statement}: {}", text(&out.stderr));
    text(&out.stdout).trim().to_string()
}

/// `terraplan user create` prints a working token last; `user token`,
/// `list` and `disable` work on the same database, and bad input exits 2
/// naming the fault.
#[test]
fn the_user_command() {
    let dir = tempfile::tempdir().unwrap();
    // Before any server ran on the directory: the command migrates it.
    let (alice, alice_token) = make_user(dir.path(), "alice", Some(PASSWORD), false);
    let server = Server::start(dir.path(), NO_LIMIT);
    let me = whoami(&server, &bearer(&alice_token));
    assert_eq!(me.status, 200, "{}", me.text());
    assert_eq!(me.json()["user"]["name"], alice.as_str());
    assert_eq!(me.json()["user"]["admin"], false);
    assert_eq!(me.json()["csrf_token"], Value::Null);

    let out = user_command(dir.path(), &["token", &alice], None);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let second = last_line(&out);
    assert_ne!(second, alice_token);
    assert_eq!(whoami(&server, &bearer(&second)).status, 200);

    let out = user_command(dir.path(), &["list"], None);
    assert!(out.status.success());
    let listed = text(&out.stdout);
    assert!(
        listed.contains(&alice) && listed.contains(&server.user),
        "{listed}"
    );

    for (args, stdin, says) in [
        (vec!["create", alice.as_str()], None, "already a user named"),
        (vec!["create", "has space"], None, "only letters, digits"),
        (vec!["create", ""], None, "may not be empty"),
        (vec!["token", "nobody-at-all-here"], None, "no user named"),
        (vec!["disable", "bad/name"], None, "only letters, digits"),
        (
            vec!["create", "short-pw-user", "--password-stdin"],
            Some("short\n"),
            "at least 8 characters",
        ),
    ] {
        let out = user_command(dir.path(), &args, stdin);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            text(&out.stderr)
        );
        assert!(
            text(&out.stderr).contains(says),
            "{args:?}: {}",
            text(&out.stderr)
        );
    }
    let long = "x".repeat(65);
    let out = user_command(dir.path(), &["create", &long], None);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        text(&out.stderr).contains("at most 64"),
        "{}",
        text(&out.stderr)
    );

    // A new password: the old one and the sessions it opened stop working,
    // the tokens go on.
    let r = sign_in(&server, &json!({"user": alice, "password": PASSWORD}), &[]);
    assert_eq!(r.status, 201, "{}", r.text());
    let old_session = session_of(&r);
    let new_password = "a brand new passphrase";
    let out = user_command(
        dir.path(),
        &["password", &alice],
        Some(&format!("{new_password}\n")),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    let r = sign_in(&server, &json!({"user": alice, "password": PASSWORD}), &[]);
    assert_problem(&r, 401, "wrong user name, password or token");
    let old = Auth::Cookie {
        session: old_session,
        csrf: None,
    };
    assert_problem(&whoami(&server, &old), 401, "sign in again");
    let r = sign_in(
        &server,
        &json!({"user": alice, "password": new_password}),
        &[],
    );
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(whoami(&server, &bearer(&alice_token)).status, 200);
    let out = user_command(dir.path(), &["password", &alice], Some("short\n"));
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let out = user_command(
        dir.path(),
        &["password", "nobody-at-all-here"],
        Some("long enough pw\n"),
    );
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));

    // Users change their own password over HTTP, giving the current one.
    let r = sign_in(
        &server,
        &json!({"user": alice, "password": new_password}),
        &[],
    );
    let session = session_of(&r);
    let csrf = r.json()["csrf_token"].as_str().unwrap().to_string();
    let cookie = Auth::Cookie {
        session: session.clone(),
        csrf: Some(csrf),
    };
    let url = server.url("/api/v1/session/password");
    for (body, pointer) in [
        (
            json!({"current": "not it at all", "new": "third password here"}),
            "/current",
        ),
        (json!({"new": "third password here"}), "/current"),
        (json!({"current": new_password, "new": "short"}), "/new"),
        (
            json!({"current": new_password, "new": "third password here", "x": 1}),
            "/x",
        ),
    ] {
        let r = post_json_as(&cookie, &url, &body);
        assert_eq!(r.status, 422, "{body}: {}", r.text());
        assert_eq!(r.json()["errors"][0]["pointer"], pointer, "{}", r.text());
    }
    let without_csrf = Auth::Cookie {
        session: session.clone(),
        csrf: None,
    };
    let body = json!({"current": new_password, "new": "third password here"});
    assert_problem(
        &post_json_as(&without_csrf, &url, &body),
        403,
        "X-CSRF-Token",
    );
    let r = post_json_as(&cookie, &url, &body);
    assert_eq!(r.status, 204, "{}", r.text());
    assert_problem(&whoami(&server, &cookie), 401, "sign in again");
    let r = sign_in(
        &server,
        &json!({"user": alice, "password": "third password here"}),
        &[],
    );
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(whoami(&server, &bearer(&alice_token)).status, 200);

    let out = user_command(dir.path(), &["disable", &alice], None);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for token in [&alice_token, &second] {
        assert_problem(&whoami(&server, &bearer(token)), 401, "not valid");
    }
    let r = sign_in(&server, &json!({"user": alice, "password": PASSWORD}), &[]);
    assert_problem(&r, 401, "wrong user name, password or token");
    let out = user_command(dir.path(), &["token", &alice], None);
    assert_eq!(out.status.code(), Some(2), "a disabled user gets no token");
}

/// Without valid credentials every closed `/api/v1` route answers 401
/// problem+json with `WWW-Authenticate`; the open ones answer.
#[test]
fn credentials_are_required() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let surveys = server.url("/api/v1/surveys");
    let r = get_as(&Auth::None, &surveys);
    assert_problem(&r, 401, "sign in first");
    assert!(r.header("www-authenticate").unwrap().starts_with("Bearer"));
    let wrong = format!("tp_{}_{}", "0".repeat(16), "A".repeat(43));
    for auth in [
        bearer(&wrong),
        bearer("not a token"),
        bearer(&format!("{}x", server.token)),
    ] {
        assert_problem(&get_as(&auth, &surveys), 401, "not valid");
    }
    let r = send_as(
        &Auth::None,
        "GET",
        &surveys,
        &[("Authorization", "Basic YTpi")],
        &[],
        Framing::Length,
    );
    assert_problem(&r, 401, "Bearer");
    let r = post_json_as(
        &Auth::None,
        &surveys,
        &terraplan_e2e::example_survey_request(),
    );
    assert_eq!(r.status, 401);
    assert_eq!(get(&surveys).status, 200, "the harness token works");
    for open in [
        "/healthz",
        "/api/v1/openapi.json",
        "/api/v1/vehicles",
        "/api/v1/cameras",
    ] {
        assert_eq!(get_as(&Auth::None, &server.url(open)).status, 200, "{open}");
    }

    // An expired token is refused.
    let r = post_json(
        &server.url("/api/v1/tokens"),
        &json!({"name": "soon", "expires_in_days": 1}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let made = r.json();
    let expiring = made["token"].as_str().unwrap().to_string();
    assert_eq!(whoami(&server, &bearer(&expiring)).status, 200);
    sql(
        dir.path(),
        &format!(
            "UPDATE api_tokens SET expires_at = 1 WHERE id = '{}'",
            made["id"].as_str().unwrap()
        ),
    );
    assert_problem(&whoami(&server, &bearer(&expiring)), 401, "not valid");
}

/// Signing in with a password or a token sets the session cookie; cookie
/// writes need the CSRF token, bearer writes do not; signing out ends it.
#[test]
fn sessions_cookies_and_csrf() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let (name, token) = make_user(dir.path(), "carol", Some(PASSWORD), false);

    for body in [
        json!({"user": name, "password": "wrong password"}),
        json!({"user": "no-such-user-anywhere", "password": PASSWORD}),
        // A name no user can have (PostgreSQL refuses NUL in text).
        json!({"user": "a\u{0}b", "password": PASSWORD}),
        json!({"token": format!("{token}x")}),
    ] {
        let r = sign_in(&server, &body, &[]);
        assert_problem(&r, 401, "wrong user name, password or token");
        assert!(r.header("set-cookie").is_none());
    }
    assert_invalid_at(
        &sign_in(&server, &json!({"user": name}), &[]),
        "no password",
        "/password",
        "required",
    );

    let r = sign_in(&server, &json!({"user": name, "password": PASSWORD}), &[]);
    assert_eq!(r.status, 201, "{}", r.text());
    let cookie = r.header("set-cookie").unwrap().to_string();
    for attribute in ["HttpOnly", "SameSite=Strict", "Path=/"] {
        assert!(cookie.split("; ").any(|a| a == attribute), "{cookie}");
    }
    assert!(!cookie.contains("Secure"), "plain HTTP: {cookie}");
    let body = r.json();
    assert_eq!(body["user"]["name"], name.as_str());
    let csrf = body["csrf_token"].as_str().unwrap().to_string();
    let personal = body["personal_project_id"].as_str().unwrap().to_string();
    let session = session_of(&r);
    assert!(session.starts_with("ts_"));

    let via_proxy = sign_in(
        &server,
        &json!({"token": token}),
        &[("X-Forwarded-Proto", "https")],
    );
    assert_eq!(via_proxy.status, 201, "{}", via_proxy.text());
    assert!(via_proxy.header("set-cookie").unwrap().contains("; Secure"));

    let with_csrf = Auth::Cookie {
        session: session.clone(),
        csrf: Some(csrf.clone()),
    };
    let without_csrf = Auth::Cookie {
        session: session.clone(),
        csrf: None,
    };
    let me = whoami(&server, &without_csrf);
    assert_eq!(me.status, 200, "reads need no CSRF token");
    assert_eq!(me.json()["csrf_token"], csrf.as_str());
    assert_eq!(me.json()["personal_project_id"], personal.as_str());

    let projects = server.url("/api/v1/projects");
    let r = post_json_as(&without_csrf, &projects, &json!({"name": "p"}));
    assert_problem(&r, 403, "X-CSRF-Token");
    let wrong_csrf = Auth::Cookie {
        session: session.clone(),
        csrf: Some(format!("{csrf}x")),
    };
    assert_problem(
        &post_json_as(&wrong_csrf, &projects, &json!({"name": "p"})),
        403,
        "X-CSRF-Token",
    );
    assert_eq!(
        post_json_as(&with_csrf, &projects, &json!({"name": "p"})).status,
        201
    );
    assert_eq!(
        post_json_as(&bearer(&token), &projects, &json!({"name": "q"})).status,
        201
    );

    let r = delete_as(&without_csrf, &server.url("/api/v1/session"));
    assert_problem(&r, 403, "X-CSRF-Token");
    let r = delete_as(&with_csrf, &server.url("/api/v1/session"));
    assert_eq!(r.status, 204);
    assert!(r.header("set-cookie").unwrap().contains("Max-Age=0"));
    assert_problem(&whoami(&server, &without_csrf), 401, "sign in again");
    // A session idle for longer than 12 h has ended; the next sign-in
    // forgets it.
    let idle = sign_in(&server, &json!({"token": token}), &[]);
    let idle_session = session_of(&idle);
    let idle_id = &idle_session[3..19];
    sql(
        dir.path(),
        &format!("UPDATE sessions SET last_used_at = 1 WHERE id = '{idle_id}'"),
    );
    assert_eq!(sign_in(&server, &json!({"token": token}), &[]).status, 201);
    let left = sql(
        dir.path(),
        &format!("SELECT COUNT(*) FROM sessions WHERE id = '{idle_id}'"),
    );
    assert_eq!(left, "0");
    let idle_cookie = Auth::Cookie {
        session: idle_session.clone(),
        csrf: None,
    };
    assert_problem(&whoami(&server, &idle_cookie), 401, "sign in again");
    // A stale cookie does not keep anyone from signing in again.
    let again = sign_in(
        &server,
        &json!({"user": name, "password": PASSWORD}),
        &[("Cookie", &format!("terraplan_session={session}"))],
    );
    assert_eq!(again.status, 201, "{}", again.text());
}

/// A user's own tokens: made (shown once), listed without secrets,
/// revoked; another user's cannot be revoked (404).
#[test]
fn tokens_are_listed_and_revoked_by_their_owner() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let (_, dave) = make_user(dir.path(), "dave", None, false);
    let tokens = server.url("/api/v1/tokens");
    let r = post_json_as(
        &bearer(&dave),
        &tokens,
        &json!({"name": "ci", "expires_in_days": 30}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let made = r.json();
    let ci = made["token"].as_str().unwrap().to_string();
    assert!(
        made["expires_at"].is_string() && made["last_used_at"].is_null(),
        "{made}"
    );
    assert_eq!(whoami(&server, &bearer(&ci)).status, 200);

    let list = get_as(&bearer(&dave), &tokens).json();
    assert_eq!(list["total"], 2, "the token of user create, and ci: {list}");
    for item in list["items"].as_array().unwrap() {
        assert!(item.get("token").is_none(), "{item}");
    }
    assert!(
        list["items"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["name"] == "ci")
    );
    let theirs = get(&tokens).json();
    assert!(
        theirs["items"]
            .as_array()
            .unwrap()
            .iter()
            .all(|t| t["id"] != made["id"]),
        "only one's own tokens are listed: {theirs}"
    );

    let one = server.url(&format!("/api/v1/tokens/{}", made["id"].as_str().unwrap()));
    assert_problem(&delete_as(&Auth::Server, &one), 404, "no token");
    assert_eq!(whoami(&server, &bearer(&ci)).status, 200, "still valid");
    assert_eq!(delete_as(&bearer(&dave), &one).status, 204);
    assert_problem(&whoami(&server, &bearer(&ci)), 401, "not valid");
    assert_problem(&delete_as(&bearer(&dave), &one), 404, "no token");

    for (body, pointer) in [
        (json!({}), "/name"),
        (json!({"name": ""}), "/name"),
        (json!({"name": 5}), "/name"),
        (
            json!({"name": "x", "expires_in_days": 0}),
            "/expires_in_days",
        ),
        (
            json!({"name": "x", "expires_in_days": 3651}),
            "/expires_in_days",
        ),
    ] {
        let r = post_json_as(&bearer(&dave), &tokens, &body);
        assert_invalid_at(&r, &body.to_string(), pointer, "");
    }
}

/// `/api/v1/users` is for admins; they make and disable users.
#[test]
fn admins_manage_users() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let users = server.url("/api/v1/users");
    let name = unique_user_name("erin");
    let r = post_json(&users, &json!({"name": name, "password": PASSWORD}));
    assert_eq!(r.status, 201, "{}", r.text());
    let made = r.json();
    assert_eq!(made["user"]["name"], name.as_str());
    assert_eq!(made["user"]["admin"], false);
    assert_eq!(made["user"]["disabled"], false);
    let erin = made["token"].as_str().unwrap().to_string();
    assert_eq!(whoami(&server, &bearer(&erin)).status, 200);
    let signed = sign_in(&server, &json!({"user": name, "password": PASSWORD}), &[]);
    assert_eq!(signed.status, 201, "{}", signed.text());

    assert_problem(&get_as(&bearer(&erin), &users), 403, "admin");
    assert_problem(
        &post_json_as(&bearer(&erin), &users, &json!({"name": "x-y"})),
        403,
        "admin",
    );
    let disable = |who: &str| server.url(&format!("/api/v1/users/{who}/disable"));
    assert_problem(
        &post_json_as(&bearer(&erin), &disable(&server.user), &json!({})),
        403,
        "admin",
    );

    let list = get(&format!("{users}?limit=100")).json();
    assert!(list["total"].as_i64().unwrap() >= 2, "{list}");
    assert!(
        list["items"]
            .as_array()
            .unwrap()
            .iter()
            .any(|u| u["name"] == name.as_str())
    );

    assert_problem(&post_json(&users, &json!({"name": name})), 409, "already");
    let r = post_json(&users, &json!({"name": "bad name"}));
    assert_invalid_at(&r, "bad name", "/name", "only letters");
    let r = post_json(
        &users,
        &json!({"name": unique_user_name("f"), "password": "short"}),
    );
    assert_invalid_at(&r, "short password", "/password", "at least 8");
    let r = post_json(
        &users,
        &json!({"name": unique_user_name("f"), "admin": "yes"}),
    );
    assert_invalid_at(&r, "admin flag", "/admin", "true or false");

    let r = post_json(&disable(&name), &json!({}));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json()["disabled"], true);
    assert_problem(&whoami(&server, &bearer(&erin)), 401, "not valid");
    let cookie = Auth::Cookie {
        session: session_of(&signed),
        csrf: None,
    };
    assert_eq!(whoami(&server, &cookie).status, 401, "its sessions end too");
    assert_problem(
        &post_json(&disable("no-such-user-here"), &json!({})),
        404,
        "no user",
    );
    assert_problem(
        &post_json(&disable(&server.user), &json!({})),
        409,
        "yourself",
    );
}

/// Projects and members: roles open and close a project, the last owner
/// stays, personal and non-empty projects are not deleted, and an admin
/// sees no one else's project.
#[test]
fn projects_members_and_roles() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let (alice_name, alice) = make_user(dir.path(), "alice", None, false);
    let (bob_name, bob) = make_user(dir.path(), "bob", None, false);
    let (alice, bob) = (bearer(&alice), bearer(&bob));

    let r = post_json_as(
        &alice,
        &server.url("/api/v1/projects"),
        &json!({"name": "Field A"}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let p = r.json();
    assert_eq!(
        (
            p["name"].as_str(),
            p["personal"].as_bool(),
            p["role"].as_str()
        ),
        (Some("Field A"), Some(false), Some("owner"))
    );
    let id = p["id"].as_str().unwrap().to_string();
    let project = server.url(&format!("/api/v1/projects/{id}"));
    let members = format!("{project}/members");

    // Not a member: exactly as a missing project (apart from the id).
    let missing = server.url("/api/v1/projects/00000000-0000-0000-0000-000000000000");
    let hidden = get_as(&bob, &project);
    assert_problem(&hidden, 404, "no project");
    let absent = get_as(&bob, &missing);
    assert_eq!(
        hidden.json()["detail"].as_str().unwrap().replace(&id, "ID"),
        absent.json()["detail"]
            .as_str()
            .unwrap()
            .replace("00000000-0000-0000-0000-000000000000", "ID")
    );
    assert_eq!(
        get(&project).status,
        404,
        "an admin sees no one else's project"
    );
    assert_eq!(get_as(&bob, &members).status, 404);

    let r = post_json_as(
        &alice,
        &members,
        &json!({"user": bob_name, "role": "viewer"}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(r.json(), json!({"user": bob_name, "role": "viewer"}));
    let seen = get_as(&bob, &project);
    assert_eq!(seen.status, 200);
    assert_eq!(seen.json()["role"], "viewer");
    let listed = get_as(&bob, &members).json();
    assert_eq!(listed["total"], 2);
    assert_eq!(
        listed["items"][0],
        json!({"user": alice_name, "role": "owner"})
    );
    let bobs = get_as(&bob, &server.url("/api/v1/projects")).json();
    assert_eq!(
        bobs["items"][0]["personal"], true,
        "the personal project first: {bobs}"
    );
    assert!(
        bobs["items"]
            .as_array()
            .unwrap()
            .iter()
            .any(|q| q["id"] == id.as_str())
    );

    let r = post_json_as(&bob, &members, &json!({"user": bob_name, "role": "owner"}));
    assert_problem(&r, 403, "needs the owner role");
    assert_problem(&delete_as(&bob, &project), 403, "needs the owner role");
    // A viewer cannot create resources in the project.
    let mut survey = terraplan_e2e::example_survey_request();
    survey["project_id"] = json!(id);
    assert_problem(
        &post_json_as(&bob, &server.url("/api/v1/surveys"), &survey),
        403,
        "editor",
    );

    let r = post_json_as(
        &alice,
        &members,
        &json!({"user": bob_name, "role": "editor"}),
    );
    assert_eq!(r.status, 200, "a changed role: {}", r.text());
    let r = post_json_as(&bob, &server.url("/api/v1/surveys"), &survey);
    assert_eq!(r.status, 201, "{}", r.text());
    let survey_url = server.url(&format!(
        "/api/v1/surveys/{}",
        r.json()["id"].as_str().unwrap()
    ));

    for nobody in ["nobody-by-that-name", "a\u{0}b"] {
        let r = post_json_as(&alice, &members, &json!({"user": nobody, "role": "viewer"}));
        assert_invalid_at(&r, "unknown user", "/user", "no user named");
    }
    let r = post_json_as(&alice, &members, &json!({"user": bob_name, "role": "boss"}));
    assert_invalid_at(&r, "bad role", "/role", "viewer");
    let r = post_json_as(
        &alice,
        &members,
        &json!({"user": alice_name, "role": "editor"}),
    );
    assert_problem(&r, 409, "last owner");
    let me = server.url(&format!("/api/v1/projects/{id}/members/{alice_name}"));
    assert_problem(&delete_as(&alice, &me), 409, "last owner");

    // A project holding a resource is not deleted; emptied, it is.
    assert_problem(&delete_as(&alice, &project), 409, "still holds");
    assert_eq!(delete_as(&alice, &survey_url).status, 204);

    // Bob an owner too: Alice may leave, then Bob deletes the project.
    let r = post_json_as(
        &alice,
        &members,
        &json!({"user": bob_name, "role": "owner"}),
    );
    assert_eq!(r.status, 200);
    assert_eq!(delete_as(&alice, &me).status, 204);
    assert_eq!(get_as(&alice, &project).status, 404);
    let gone = server.url(&format!("/api/v1/projects/{id}/members/{alice_name}"));
    assert_problem(&delete_as(&bob, &gone), 404, "not a member");
    assert_eq!(delete_as(&bob, &project).status, 204);
    assert_eq!(get_as(&bob, &project).status, 404);

    let personal = whoami(&server, &alice).json()["personal_project_id"]
        .as_str()
        .unwrap()
        .to_string();
    let r = delete_as(&alice, &server.url(&format!("/api/v1/projects/{personal}")));
    assert_problem(&r, 409, "personal project");
    for body in [json!({}), json!({"name": ""}), json!({"name": "a\u{1}b"})] {
        let r = post_json_as(&alice, &server.url("/api/v1/projects"), &body);
        assert_invalid_at(&r, &body.to_string(), "/name", "");
    }
}

/// The first start on an empty database makes `admin` and prints, once,
/// how to sign in; the password and the token it prints both work.
#[test]
fn the_first_start_prints_the_admin_once() {
    if on_postgres() {
        // The run's shared database has users already.
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start_without_user(dir.path(), NO_LIMIT);
    let line = server
        .stdout_line(Duration::from_secs(10))
        .expect("the first-start line");
    let prefix = format!(
        "first start: sign in at {} as \"admin\" with the one-time password ",
        server.base
    );
    let rest = line
        .strip_prefix(&prefix)
        .unwrap_or_else(|| panic!("{line}"));
    let (password, rest) = rest
        .split_once(", or call the API with \"Authorization: Bearer ")
        .unwrap();
    let token = rest.strip_suffix('"').unwrap();
    assert_eq!(password.len(), 20, "{line}");
    let me = whoami(&server, &bearer(token));
    assert_eq!(me.status, 200, "{}", me.text());
    assert_eq!(
        me.json()["user"],
        json!({"id": me.json()["user"]["id"], "name": "admin", "admin": true})
    );
    let r = sign_in(
        &server,
        &json!({"user": "admin", "password": password}),
        &[],
    );
    assert_eq!(r.status, 201, "{}", r.text());
    drop(server);

    let again = Server::start_without_user(dir.path(), NO_LIMIT);
    assert_eq!(
        again.stdout_line(Duration::from_secs(2)),
        None,
        "printed once only"
    );
    assert_eq!(whoami(&again, &bearer(token)).status, 200);
}

/// Passwords, tokens and session keys are stored only as hashes: none of
/// those made here is found in the SQLite files (or, on PostgreSQL, in a
/// `pg_dump` of the database).
#[test]
fn secrets_are_not_stored_in_clear() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let password = format!("pw-{}", unique_user_name("secret"));
    let (name, token) = make_user(dir.path(), "gina", Some(&password), false);
    let r = post_json_as(
        &bearer(&token),
        &server.url("/api/v1/tokens"),
        &json!({"name": "t"}),
    );
    assert_eq!(r.status, 201);
    let api_token = r.json()["token"].as_str().unwrap().to_string();
    let r = sign_in(&server, &json!({"user": name, "password": password}), &[]);
    assert_eq!(r.status, 201);
    let session = session_of(&r);
    let csrf = r.json()["csrf_token"].as_str().unwrap().to_string();
    assert_eq!(whoami(&server, &bearer(&api_token)).status, 200);
    // The secret part of each bearer secret (after `tp_{id}_`).
    let secret_part = |s: &str| s[20..].to_string();
    let mut secrets = vec![
        password.clone(),
        token.clone(),
        api_token.clone(),
        session.clone(),
        server.token.clone(),
    ];
    secrets.extend([&token, &api_token, &session, &server.token].map(|s| secret_part(s)));
    let _ = csrf; // Not a credential by itself: stored to be compared.
    drop(server);

    let haystacks: Vec<(String, Vec<u8>)> = if on_postgres() {
        let url = std::env::var("TERRAPLAN_TEST_DATABASE_URL").unwrap();
        let Ok(out) = std::process::Command::new("pg_dump").arg(&url).output() else {
            eprintln!("pg_dump is not on PATH: the PostgreSQL dump is not scanned");
            return;
        };
        assert!(out.status.success(), "pg_dump: {}", text(&out.stderr));
        let dump = out.stdout;
        assert!(
            dump.windows(name.len()).any(|w| w == name.as_bytes()),
            "the dump holds the user"
        );
        vec![("pg_dump".to_string(), dump)]
    } else {
        std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.to_string_lossy().contains("sqlite3"))
            .map(|p| (p.display().to_string(), std::fs::read(&p).unwrap()))
            .collect()
    };
    let all: Vec<u8> = haystacks.iter().flat_map(|(_, b)| b.clone()).collect();
    assert!(
        all.windows(name.len()).any(|w| w == name.as_bytes()),
        "the files scanned hold the user's name, so they hold the accounts"
    );
    for (file, bytes) in &haystacks {
        for secret in &secrets {
            assert!(
                !bytes.windows(secret.len()).any(|w| w == secret.as_bytes()),
                "{file} holds a secret in clear"
            );
        }
    }
}

/// Resources made before accounts (no project) move into the personal
/// project of the admin the first start makes. (SQLite: the state before
/// accounts is made by hand on the database file.)
#[test]
fn the_first_admin_adopts_older_resources() {
    if on_postgres() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), NO_LIMIT);
    let dem = terraplan_e2e::upload_dem(&server, &terraplan_e2e::dtm());
    server.stop();
    // As before accounts: no users, no projects, a DEM of no project.
    sql(
        dir.path(),
        "PRAGMA foreign_keys = ON; DELETE FROM users; DELETE FROM projects; \
         UPDATE dems SET project_id = NULL;",
    );
    let server = Server::start_without_user(dir.path(), NO_LIMIT);
    let line = server
        .stdout_line(Duration::from_secs(10))
        .expect("first start");
    let token = line
        .rsplit_once("Bearer ")
        .map(|(_, t)| t.trim_end_matches('"').to_string())
        .unwrap_or_else(|| panic!("{line}"));
    let admin = bearer(&token);
    let r = get_as(&admin, &server.url(&format!("/api/v1/dems/{dem}")));
    assert_eq!(r.status, 200, "{}", r.text());
    let personal = whoami(&server, &admin).json()["personal_project_id"].clone();
    assert_eq!(r.json()["project_id"], personal);
}
