//! The service's defences that are not about who may see what: the
//! `Host` check against DNS rebinding, the security headers of every
//! answer, and the rate limits on sign-in and planning (429 with
//! `Retry-After`).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Duration;

use serde_json::json;
use terraplan_e2e::{
    Auth, Server, assert_problem, example_survey_request, get, post_json, post_json_as, text,
};

/// A GET of `path` naming `host` in its `Host` header; the status line and
/// the whole answer.
fn get_with_host(server: &Server, path: &str, host: &str) -> (u16, String) {
    let authority = server.base.strip_prefix("http://").unwrap();
    let mut s = TcpStream::connect(authority).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\n{}Connection: close\r\n\r\n",
        server.auth_line()
    )
    .unwrap();
    let mut answer = Vec::new();
    s.read_to_end(&mut answer).unwrap();
    let answer = text(&answer);
    let status = answer
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("no status line: {answer:?}"));
    (status, answer)
}

#[test]
fn only_the_configured_host_names_are_answered() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--allowed-host", "survey.example.org"]);
    let port = server.base.rsplit(':').next().unwrap().to_string();
    for host in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
        "survey.example.org".to_string(),
        "SURVEY.example.org:443".to_string(),
    ] {
        let (status, answer) = get_with_host(&server, "/api/v1/surveys", &host);
        assert_eq!(status, 200, "{host}: {answer}");
    }
    for host in [
        "evil.example",
        "evil.example:8080",
        "127.0.0.2",
        "survey.example.org.evil.example",
    ] {
        let (status, answer) = get_with_host(&server, "/api/v1/surveys", host);
        assert_eq!(status, 400, "{host}: {answer}");
        assert!(answer.contains("application/problem+json"), "{answer}");
        assert!(answer.contains("--allowed-host"), "{answer}");
        // The web page is refused too: rebinding targets it first.
        let (status, _) = get_with_host(&server, "/", host);
        assert_eq!(status, 400, "{host} /");
    }
    // Probes that name the machine by address still see health.
    let (status, answer) = get_with_host(&server, "/healthz", "10.9.8.7:8080");
    assert_eq!(status, 200, "{answer}");
}

#[test]
fn every_answer_carries_the_security_headers() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    for path in [
        "/",
        "/healthz",
        "/api/v1/surveys",
        "/api/v1/openapi.json",
        "/api/v1/no-such",
    ] {
        let r = get(&server.url(path));
        assert_eq!(
            r.header("x-content-type-options"),
            Some("nosniff"),
            "{path}"
        );
        assert_eq!(r.header("referrer-policy"), Some("no-referrer"), "{path}");
        assert_eq!(r.header("x-frame-options"), Some("DENY"), "{path}");
        let csp = r.header("content-security-policy").unwrap_or_default();
        assert!(csp.contains("default-src 'self'"), "{path}: {csp}");
        assert!(csp.contains("frame-ancestors 'none'"), "{path}: {csp}");
        assert!(
            !csp.contains("script-src 'self' 'unsafe-inline'"),
            "{path}: {csp}"
        );
    }
}

#[test]
fn sign_in_attempts_are_rate_limited_per_address() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--sign-in-per-minute", "3"]);
    let url = server.url("/api/v1/session");
    let wrong = json!({"user": server.user, "password": "not the password"});
    let mut statuses = Vec::new();
    for _ in 0..5 {
        statuses.push(post_json_as(&Auth::None, &url, &wrong));
    }
    assert_eq!(statuses[0].status, 401, "{}", statuses[0].text());
    let limited = statuses.last().unwrap();
    let p = assert_problem(limited, 429, "too many sign-in attempts");
    assert!(
        p["detail"].as_str().unwrap().contains("try again in"),
        "{p}"
    );
    let retry: u64 = limited
        .header("retry-after")
        .expect("Retry-After")
        .parse()
        .unwrap();
    assert!((1..=60).contains(&retry), "Retry-After {retry}");
    // The limit is on sign-ins, not on the caller's other work.
    assert_eq!(get(&server.url("/api/v1/surveys")).status, 200);
}

#[test]
fn planning_requests_are_rate_limited_per_user() {
    let dir = tempfile::tempdir().unwrap();
    // Two a minute, one at once: the second at once is refused.
    let server = Server::start(dir.path(), &["--planning-per-minute", "2"]);
    let url = server.url("/api/v1/surveys");
    let first = post_json(&url, &example_survey_request());
    assert_eq!(first.status, 201, "{}", first.text());
    let second = post_json(&url, &example_survey_request());
    let p = assert_problem(&second, 429, "too many planning requests");
    assert!(second.header("retry-after").is_some(), "{p}");
    // Reads are not limited.
    for _ in 0..5 {
        assert_eq!(get(&url).status, 200);
    }
}
