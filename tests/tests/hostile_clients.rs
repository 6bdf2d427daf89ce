//! Clients that are slow, careless or hostile, against the real
//! `terraplan serve`: slow requests do not lock healthy clients out,
//! whatever the file limit; hyper's parse errors are problem+json; names
//! with control characters are refused on both databases; infinite
//! heights are nodata; a second server cannot take over a live server's
//! database. Runs on SQLite, and on PostgreSQL when the test command sets
//! `TERRAPLAN_TEST_DATABASE_URL`.

use std::io::{BufRead, BufReader, ErrorKind, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use terraplan_e2e::{
    Server, assert_invalid_at, assert_problem, example_survey_request, get, post, post_json,
    read_answer, terraplan_bin, text, wait_costmap_finished,
};

/// `host:port` of a server's base URL.
fn authority(base: &str) -> String {
    base.strip_prefix("http://").unwrap().to_string()
}

/// One GET on a fresh connection; its answer's status and how long the
/// whole exchange took.
fn timed_get(authority: &str, path: &str) -> (u16, Duration) {
    let t = Instant::now();
    let mut s = TcpStream::connect(authority).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let credentials = terraplan_e2e::credential_lines(authority);
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n{credentials}\r\n"
    )
    .unwrap();
    let r = read_answer(&mut s);
    (r.status, t.elapsed())
}

/// A slow client: a request head never finished, or a body trickling.
struct Slow {
    stream: TcpStream,
    trickles: bool,
    opened: Instant,
    /// When the server ended it, and the first bytes it sent.
    ended: Option<(Instant, Vec<u8>)>,
}

impl Slow {
    fn open(authority: &str, trickles: bool) -> Slow {
        let mut stream = TcpStream::connect(authority).unwrap();
        let opened = Instant::now();
        if trickles {
            let credentials = terraplan_e2e::credential_lines(authority);
            write!(
                stream,
                "POST /api/v1/surveys HTTP/1.1\r\nHost: {authority}\r\nContent-Type: \
                 application/json\r\nContent-Length: 100000\r\n{credentials}\r\n{{"
            )
            .unwrap();
        } else {
            write!(
                stream,
                "GET /healthz HTTP/1.1\r\nHost: {authority}\r\nX-Slow: "
            )
            .unwrap();
        }
        stream.set_nonblocking(true).unwrap();
        Slow {
            stream,
            trickles,
            opened,
            ended: None,
        }
    }

    /// Look whether the server answered or closed; a trickling client
    /// sends one more byte of its body.
    fn poll(&mut self, send: bool) {
        if self.ended.is_some() {
            return;
        }
        let mut buf = [0u8; 4096];
        match self.stream.read(&mut buf) {
            Ok(0) => self.ended = Some((Instant::now(), Vec::new())),
            Ok(n) => self.ended = Some((Instant::now(), buf[..n].to_vec())),
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                if send && self.trickles && self.stream.write_all(b" ").is_err() {
                    self.ended = Some((Instant::now(), Vec::new()));
                }
            }
            Err(_) => self.ended = Some((Instant::now(), Vec::new())),
        }
    }
}

/// Hold `slow` open, trickling, until each has been ended by the server
/// or `deadline` passes.
fn watch(slow: &mut [Slow], deadline: Instant) {
    let mut last_send = Instant::now();
    while Instant::now() < deadline && slow.iter().any(|s| s.ended.is_none()) {
        let send = last_send.elapsed() >= Duration::from_millis(250);
        if send {
            last_send = Instant::now();
        }
        for s in slow.iter_mut() {
            s.poll(send);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// 300 slow clients against a server that takes 64 connections: half
/// never finish their request head, half trickle their body at 4 bytes/s.
/// Healthy clients are still answered, far sooner than the slow ones'
/// timeouts, and every slow one is ended by the server within its
/// timeout (or earlier, closed to make room), the trickling ones that
/// were read answered 408 problem+json.
#[test]
fn slow_clients_do_not_lock_out_healthy_ones() {
    const TIMEOUT_S: u64 = 5;
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        dir.path(),
        &[
            "--max-connections",
            "64",
            "--header-read-timeout-s",
            &TIMEOUT_S.to_string(),
            "--body-read-timeout-s",
            &TIMEOUT_S.to_string(),
        ],
    );
    let addr = authority(&server.base);
    let mut slow: Vec<Slow> = (0..300).map(|i| Slow::open(&addr, i % 2 == 1)).collect();
    let opened = Instant::now();

    // Healthy clients while every slow one is still within its timeout.
    let mut latencies = Vec::new();
    for i in 0..10 {
        let path = if i % 2 == 0 {
            "/healthz"
        } else {
            "/api/v1/surveys?limit=1"
        };
        let (status, took) = timed_get(&addr, path);
        assert_eq!(status, 200, "{path}");
        latencies.push(took);
        for s in &mut slow {
            s.poll(false);
        }
    }
    let worst = latencies.iter().max().unwrap();
    eprintln!(
        "healthy clients among 300 slow ones at 64 connections: worst {worst:?}, all {latencies:?}"
    );
    assert!(
        *worst < Duration::from_secs(TIMEOUT_S) / 2,
        "a healthy client waited {worst:?}, as if for the slow ones' timeouts"
    );
    assert!(
        opened.elapsed() < Duration::from_secs(TIMEOUT_S),
        "the healthy clients were served after the timeouts: {:?}",
        opened.elapsed()
    );

    // Every slow client is ended by the server: a head by its timeout, a
    // body by its timeout plus its 1 s per 1024 bytes (none here).
    let margin = Duration::from_secs(5);
    watch(
        &mut slow,
        Instant::now() + Duration::from_secs(TIMEOUT_S) + margin,
    );
    let mut answered_408 = 0;
    for s in &slow {
        let Some((at, bytes)) = &s.ended else {
            panic!(
                "a slow client ({}) is still connected after {:?}",
                if s.trickles { "body" } else { "head" },
                s.opened.elapsed()
            );
        };
        assert!(
            *at - s.opened <= Duration::from_secs(TIMEOUT_S) + margin,
            "{:?}",
            *at - s.opened
        );
        if !bytes.is_empty() {
            let answer = text(bytes);
            assert!(s.trickles, "a head never finished got an answer: {answer}");
            assert!(answer.starts_with("HTTP/1.1 408 "), "{answer}");
            assert!(
                answer.contains("application/problem+json") && answer.contains("too slowly"),
                "{answer}"
            );
            answered_408 += 1;
        }
    }
    eprintln!("{answered_408} trickling bodies were answered 408, the rest closed to make room");
    assert!(answered_408 > 0);
    let (status, took) = timed_get(&addr, "/healthz");
    assert_eq!(status, 200);
    assert!(took < Duration::from_secs(2), "{took:?}");
}

/// A trickle within the minimum rate is never cut: a body sent at about
/// 4 KiB/s for longer than the body timeout arrives whole.
#[test]
fn a_slow_but_steady_body_is_read() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--body-read-timeout-s", "1"]);
    let addr = authority(&server.base);
    let mut body = example_survey_request();
    body["name"] = json!("x".repeat(100));
    let mut body = body.to_string().into_bytes();
    // Padding to 10 KiB: 2.5 s at 4 KiB/s, over the 1 s timeout but within
    // its allowance of 1 s per 1024 bytes.
    body.resize(10 * 1024, b' ');
    let mut s = TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    write!(
        s,
        "POST /api/v1/surveys HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: \
         application/json\r\nContent-Length: {}\r\n{}\r\n",
        body.len(),
        server.auth_line()
    )
    .unwrap();
    let t = Instant::now();
    for chunk in body.chunks(512) {
        s.write_all(chunk).unwrap();
        std::thread::sleep(Duration::from_millis(125));
    }
    let r = read_answer(&mut s);
    assert!(t.elapsed() > Duration::from_secs(2));
    assert_eq!(r.status, 201, "{}", r.text());
}

/// `terraplan serve` under a file limit of `nofile` (prlimit), on the
/// test database as [`Server::start`]; its address and the process.
fn serve_with_file_limit(dir: &Path, nofile: u32, args: &[&str]) -> (String, Child) {
    let (_, token) = terraplan_e2e::harness_user(dir);
    let mut cmd = Command::new("prlimit");
    cmd.arg(format!("--nofile={nofile}:{nofile}"))
        .arg(terraplan_bin())
        .args(["serve", "--host", "127.0.0.1", "--port", "0", "--data-dir"])
        .arg(dir)
        .args(["--header-read-timeout-s", "30"])
        .args(args)
        .env_remove("DATABASE_URL")
        .env("TERRAPLAN_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Ok(url) = std::env::var("TERRAPLAN_TEST_DATABASE_URL") {
        cmd.env("DATABASE_URL", url);
    }
    let mut child = cmd.spawn().expect("prlimit (util-linux) runs terraplan");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let base = line
        .trim()
        .strip_prefix("listening on ")
        .unwrap_or_else(|| panic!("{line:?}"))
        .to_string();
    terraplan_e2e::remember_token(&base, &token);
    (authority(&base), child)
}

/// Stop `child` and return what it logged.
fn stop_and_log(child: Child) -> String {
    let _ = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status();
    let out = child.wait_with_output().unwrap();
    text(&out.stderr)
}

/// The case, scaled down: at `ulimit -n 256`, 400 connections
/// that never finish a request. The default connection limit stays under
/// the file limit (192, keeping 64 descriptors for files), and healthy
/// clients are still answered. With a limit set above what the file limit
/// allows, accepting fails for want of descriptors: the server makes
/// room and keeps serving instead of failing.
#[test]
fn the_file_limit_is_never_exhausted_by_clients() {
    for (args, room) in [
        (&[][..], "max_connections=192"),
        (&["--max-connections", "1000"][..], "max_connections=1000"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (addr, child) = serve_with_file_limit(dir.path(), 256, args);
        let mut slow: Vec<Slow> = (0..400).map(|_| Slow::open(&addr, false)).collect();
        let within_limit = args.is_empty();
        let mut worst = Duration::ZERO;
        for _ in 0..5 {
            let (status, took) = timed_get(&addr, "/healthz");
            worst = worst.max(took);
            if within_limit {
                // Room was kept for the database's files.
                assert_eq!(status, 200);
                let r = post_json(
                    &format!("http://{addr}/api/v1/surveys"),
                    &example_survey_request(),
                );
                assert_eq!(r.status, 201, "{}", r.text());
            }
        }
        for s in &mut slow {
            s.poll(false);
        }
        let closed = slow.iter().filter(|s| s.ended.is_some()).count();
        eprintln!(
            "{args:?} at ulimit -n 256: healthz worst {worst:?} beside 400 slow connections, \
             {closed} of them closed to make room"
        );
        assert!(worst < Duration::from_secs(10), "{worst:?}");
        drop(slow);
        // The slow clients gone, everything works again.
        std::thread::sleep(Duration::from_millis(200));
        assert_eq!(timed_get(&addr, "/healthz").0, 200);
        let r = post_json(
            &format!("http://{addr}/api/v1/surveys"),
            &example_survey_request(),
        );
        assert_eq!(r.status, 201, "{}", r.text());
        let log = stop_and_log(child);
        assert!(log.contains(room), "{log}");
        assert!(!log.contains("panicked"), "{log}");
        if within_limit {
            assert!(!log.contains("cannot accept"), "{log}");
        } else {
            assert!(
                log.contains("cannot accept a connection: retrying"),
                "{log}"
            );
        }
    }
}

/// Requests hyper refuses before the application sees them are answered
/// with problem+json too.
#[test]
fn unparsable_requests_are_problems() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let addr = authority(&server.base);
    let raw = |head: &[u8]| {
        let mut s = TcpStream::connect(&addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        // The server may answer and close before all of it is sent.
        let _ = s.write_all(head);
        read_answer(&mut s)
    };
    let long_uri = format!("GET /{} HTTP/1.1\r\nHost: x\r\n\r\n", "a".repeat(70_000));
    let many_fields: String = (0..150).map(|i| format!("X-F{i}: 1\r\n")).collect();
    let many_fields = format!("GET /healthz HTTP/1.1\r\nHost: x\r\n{many_fields}\r\n");
    let huge_field = format!(
        "GET /healthz HTTP/1.1\r\nHost: x\r\nX-Big: {}\r\n\r\n",
        "y".repeat(600_000)
    );
    for (what, head, status, detail) in [
        (
            "a 70 000-byte URI",
            long_uri.as_bytes(),
            414,
            "URI is too long",
        ),
        (
            "150 header fields",
            many_fields.as_bytes(),
            431,
            "header is too large",
        ),
        (
            "a 600 kB header field",
            huge_field.as_bytes(),
            431,
            "header is too large",
        ),
        (
            "a malformed header field",
            &b"GET / HTTP/1.1\r\nHost: x\r\nno colon here\r\n\r\n"[..],
            400,
            "not valid HTTP/1.1",
        ),
    ] {
        let r = raw(head);
        eprintln!("{what}: {} {}", r.status, r.text());
        let p = assert_problem(&r, status, detail);
        assert_eq!(
            r.header("content-length"),
            Some(r.body.len().to_string().as_str())
        );
        assert_eq!(p["type"], "about:blank", "{what}");
    }
    // The application's own 400s are untouched.
    assert_problem(&get(&server.url("/api/v1/surveys?limit=0")), 400, "limit");
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// A name holding NUL or another control character is refused with a 422
/// naming the field, on SQLite as on PostgreSQL (whose text cannot hold
/// NUL: it was a 500), for every resource; ids in paths and bodies with
/// them are not found instead of failing the lookup.
#[test]
fn names_with_control_characters_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let bad = ["a\u{0}b", "tab\there", "bell\u{7}", "line\nbreak"];
    for name in bad {
        let mut req = example_survey_request();
        req["name"] = json!(name);
        let r = post_json(&server.url("/api/v1/surveys"), &req);
        assert_invalid_at(&r, "survey name", "/name", "control character");
    }
    // Names of other characters are kept as they are.
    let mut req = example_survey_request();
    req["name"] = json!("Süd – Feld 7 ✈");
    let r = post_json(&server.url("/api/v1/surveys"), &req);
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(r.json()["name"], "Süd – Feld 7 ✈");

    // DEMs: the name in the query or the form, the file name.
    let grid = dem_grid(20, 20, |_, _| 100.0);
    let dems = server.url("/api/v1/dems?crs=EPSG:32633");
    let r = post(&format!("{dems}&name=a%00b"), "text/plain", grid.as_bytes());
    assert_invalid_at(&r, "DEM name", "/name", "control character");
    let r = post(
        &format!("{dems}&file_name=x%0A.asc"),
        "text/plain",
        grid.as_bytes(),
    );
    assert_invalid_at(&r, "DEM file name", "/file_name", "control character");
    let r = terraplan_e2e::post_multipart(
        &dems,
        &[
            terraplan_e2e::Part {
                name: "file",
                file_name: Some("grid.asc"),
                content_type: Some("text/plain"),
                data: grid.as_bytes(),
            },
            terraplan_e2e::Part {
                name: "name",
                file_name: None,
                content_type: None,
                data: "nul \u{0} in the form".as_bytes(),
            },
        ],
    );
    assert_invalid_at(&r, "DEM name in the form", "/name", "control character");
    let r = post(&format!("{dems}&name=flat"), "text/plain", grid.as_bytes());
    assert_eq!(r.status, 201, "{}", r.text());
    let dem_id = r.json()["id"].as_str().unwrap().to_string();

    // Costmaps: the name, and a DEM id with one.
    let costmaps = server.url("/api/v1/costmaps");
    let r = post_json(&costmaps, &json!({"dem_id": dem_id, "name": "c\u{0}"}));
    assert_invalid_at(&r, "costmap name", "/name", "control character");
    let r = post_json(&costmaps, &json!({"dem_id": "nope\u{0}"}));
    assert_invalid_at(&r, "DEM id", "/dem_id", "control character");
    let r = post_json(&costmaps, &json!({"dem_id": dem_id}));
    assert_eq!(r.status, 202, "{}", r.text());
    let costmap_id = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_costmap_finished(&server, &costmap_id);
    assert_eq!(job["status"], "done", "{job}");

    // Routes: refused as the request is read, before any search (on
    // PostgreSQL the insert after the search failed).
    let routes = server.url(&format!("/api/v1/costmaps/{costmap_id}/routes"));
    let r = post_json(
        &routes,
        &json!({"start": {"utm": [500005, 5000005]}, "goal": {"utm": [500015, 5000015]},
                "name": "r\u{0}"}),
    );
    assert_invalid_at(&r, "route name", "/name", "control character");
    let r = post_json(
        &routes,
        &json!({"start": {"utm": [500005, 5000005]}, "goal": {"utm": [500015, 5000015]},
                "name": "fine"}),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let route_id = r.json()["id"].as_str().unwrap().to_string();
    let r = post_json(
        &server.url(&format!("/api/v1/routes/{route_id}/replan")),
        &json!({"name": "again\u{1b}[31m"}),
    );
    assert_invalid_at(&r, "replan name", "/name", "control character");

    // Ids with control characters: not found (no 500 from the database).
    for path in [
        "/api/v1/surveys/a%00b",
        "/api/v1/dems/%00",
        "/api/v1/costmaps/x%0d%0a",
        "/api/v1/routes/%00/route.geojson",
    ] {
        assert_problem(&get(&server.url(path)), 404, "control characters");
    }
    assert_problem(
        &get(&server.url("/api/v1/routes?costmap_id=%00")),
        400,
        "control character",
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// An ESRI ASCII grid of `w`×`h` 1 m cells in UTM 33N, heights `z(col,
/// row)`.
fn dem_grid(w: usize, h: usize, z: impl Fn(usize, usize) -> f64) -> String {
    let mut s = format!("ncols {w}\nnrows {h}\nxllcorner 500000\nyllcorner 5000000\ncellsize 1\n");
    for r in 0..h {
        let row: Vec<String> = (0..w).map(|c| format!("{:.3}", z(c, r))).collect();
        s.push_str(&row.join(" "));
        s.push('\n');
    }
    s
}

/// A little-endian Float32 GeoTIFF of `w`×`h` 1 m cells, its top-left
/// corner at (500000, 5000020) in a CRS given apart, `values` row-major.
fn float32_tiff(w: u32, h: u32, values: &[f32]) -> Vec<u8> {
    assert_eq!(values.len(), (w * h) as usize);
    const SHORT: u16 = 3;
    const LONG: u16 = 4;
    const DOUBLE: u16 = 12;
    let entries = 12u32;
    let ifd_len = 2 + entries * 12 + 4;
    let scale_at = 8 + ifd_len;
    let tie_at = scale_at + 24;
    let pixels_at = tie_at + 48;
    let mut b = Vec::new();
    b.extend_from_slice(b"II");
    b.extend_from_slice(&42u16.to_le_bytes());
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&(entries as u16).to_le_bytes());
    let fields: [(u16, u16, u32, u32); 12] = [
        (256, LONG, 1, w),
        (257, LONG, 1, h),
        (258, SHORT, 1, 32),
        (259, SHORT, 1, 1),
        (262, SHORT, 1, 1),
        (273, LONG, 1, pixels_at),
        (277, SHORT, 1, 1),
        (278, LONG, 1, h),
        (279, LONG, 1, w * h * 4),
        (339, SHORT, 1, 3),
        (33550, DOUBLE, 3, scale_at), // ModelPixelScale
        (33922, DOUBLE, 6, tie_at),   // ModelTiepoint
    ];
    for (tag, kind, count, value) in fields {
        b.extend_from_slice(&tag.to_le_bytes());
        b.extend_from_slice(&kind.to_le_bytes());
        b.extend_from_slice(&count.to_le_bytes());
        if kind == SHORT {
            b.extend_from_slice(&(value as u16).to_le_bytes());
            b.extend_from_slice(&[0, 0]);
        } else {
            b.extend_from_slice(&value.to_le_bytes());
        }
    }
    b.extend_from_slice(&0u32.to_le_bytes());
    for v in [1.0f64, 1.0, 0.0, 0.0, 0.0, 0.0, 500_000.0, 5_000_020.0, 0.0] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    assert_eq!(b.len() as u32, pixels_at);
    for v in values {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b
}

/// A DEM of infinite heights has no heights at all, as one of nodata:
/// its metadata says so, and its costmap is unknown everywhere (it was
/// "64 % traversable"). Infinite cells among finite ones are nodata.
#[test]
fn infinite_heights_are_nodata() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let dems = server.url("/api/v1/dems?crs=EPSG:32633");
    let upload = |values: &[f32]| -> Value {
        let r = post(&dems, "image/tiff", &float32_tiff(20, 20, values));
        assert_eq!(r.status, 201, "{}", r.text());
        r.json()
    };
    let costmap = |dem: &Value| -> Value {
        let r = post_json(
            &server.url("/api/v1/costmaps"),
            &json!({"dem_id": dem["id"]}),
        );
        assert_eq!(r.status, 202, "{}", r.text());
        wait_costmap_finished(&server, r.json()["id"].as_str().unwrap())
    };
    let inf = upload(&[f32::INFINITY; 400]);
    let nan = upload(&[f32::NAN; 400]);
    for dem in [&inf, &nan] {
        assert_eq!(dem["nodata_fraction"], 1.0, "{dem}");
        assert!(dem["min"].is_null() && dem["max"].is_null(), "{dem}");
    }
    let (inf_map, nan_map) = (costmap(&inf), costmap(&nan));
    assert_eq!(inf_map["status"], nan_map["status"], "{inf_map}");
    assert_eq!(
        inf_map["stats"]["class_fractions"], nan_map["stats"]["class_fractions"],
        "{inf_map}"
    );
    assert_eq!(inf_map["status"], "done", "{inf_map}");
    assert_eq!(
        inf_map["stats"]["class_fractions"]["unknown"], 1.0,
        "{inf_map}"
    );
    assert_eq!(inf_map["stats"]["traversable_area_m2"], 0.0, "{inf_map}");
    // A quarter of the cells infinite (either sign), the rest 100 m.
    let mixed: Vec<f32> = (0..400)
        .map(|i| match i % 8 {
            0 => f32::INFINITY,
            4 => f32::NEG_INFINITY,
            _ => 100.0,
        })
        .collect();
    let dem = upload(&mixed);
    assert_eq!(dem["nodata_fraction"], 0.25, "{dem}");
    assert_eq!(
        (dem["min"].as_f64(), dem["max"].as_f64()),
        (Some(100.0), Some(100.0))
    );
}

/// A second server on a live server's SQLite database exits at once with
/// a clear message (status 1) instead of taking over its running costmap
/// job; once the first is gone (stopped or killed), a new one starts.
#[test]
fn a_second_server_cannot_take_over_a_live_ones_database() {
    if std::env::var("TERRAPLAN_TEST_DATABASE_URL").is_ok() {
        // PostgreSQL is shared by design: jobs are leased there.
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let first = Server::start(dir.path(), &[]);
    let dem = terraplan_e2e::upload_dem(&first, &terraplan_e2e::dtm());
    let r = post_json(
        &first.url("/api/v1/costmaps"),
        &json!({"dem_id": dem, "options": terraplan_e2e::slow_costmap_options()}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json()["id"].as_str().unwrap().to_string();

    let second = |dir: &Path| {
        let mut child = Command::new(terraplan_bin())
            .args(["serve", "--host", "127.0.0.1", "--port", "0", "--data-dir"])
            .arg(dir)
            .env_remove("DATABASE_URL")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                let mut err = String::new();
                child
                    .stderr
                    .take()
                    .unwrap()
                    .read_to_string(&mut err)
                    .unwrap();
                return Some((status, err));
            }
            if Instant::now() > deadline {
                // Still running: it started.
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    let t = Instant::now();
    let (status, err) = second(dir.path()).expect("the second server exits");
    assert_eq!(status.code(), Some(1), "{err}");
    assert!(
        err.contains("another terraplan server is using this database"),
        "{err}"
    );
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    // The first server's job was not disturbed.
    let done = wait_costmap_finished(&first, &job);
    assert_eq!(done["status"], "done", "{done}");

    // Killed (no clean shutdown), the lock goes with the process.
    first.kill();
    let next = Server::start(dir.path(), &[]);
    assert_eq!(get(&next.url("/healthz")).status, 200);
    assert_eq!(
        get(&next.url(&format!("/api/v1/costmaps/{job}"))).json()["status"],
        "done"
    );
}

/// Numbers a client sends back in the message that refuses them are
/// readable: `1e308`, not 309 digits (nor `1e-300` as 300 zeros); an
/// easting beyond the projection is a 422, not a 500.
#[test]
fn refused_numbers_are_printed_readably() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let surveys = server.url("/api/v1/surveys");
    let long_digits = |r: &terraplan_e2e::Reply| {
        let t = r.text();
        let mut run = 0;
        for c in t.chars() {
            run = if c.is_ascii_digit() { run + 1 } else { 0 };
            assert!(run < 20, "a number printed in full: {t}");
        }
    };
    let with = |field: &str, v: Value| {
        let mut req = example_survey_request();
        req["uavs"] = json!([{"id": "u1", "start": [6.0620, 51.5110]}]);
        req[field] = v;
        req
    };
    for (field, v, pointer, shown) in [
        ("altitude_m", json!(1e308), "/altitude_m", "1e308"),
        ("altitude_m", json!(1e-300), "/altitude_m", "1e-300"),
        ("speed_m_s", json!(-1e308), "/speed_m_s", "-1e308"),
        (
            "uavs",
            json!([{"id": "u1", "start": [1e308, 51.5]}]),
            "/uavs/0/start/0",
            "longitude 1e308",
        ),
        (
            "camera",
            json!({"sensor_width_mm": 1e308, "sensor_height_mm": 8.8, "focal_length_mm": 8.8,
                   "image_width_px": 5472, "image_height_px": 3648}),
            "/camera/sensor_width_mm",
            "(got 1e308)",
        ),
    ] {
        let r = post_json(&surveys, &with(field, v));
        assert_invalid_at(&r, field, pointer, shown);
        long_digits(&r);
    }

    let grid = dem_grid(40, 40, |_, _| 100.0);
    let r = post(
        &server.url("/api/v1/dems?crs=EPSG:32633"),
        "text/plain",
        grid.as_bytes(),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let dem = r.json()["id"].as_str().unwrap().to_string();
    let r = post_json(
        &server.url(&format!("/api/v1/dems/{dem}/elevation")),
        &json!({"points": [[1e308, 45.0]]}),
    );
    assert_invalid_at(&r, "elevation", "/points/0", "longitude 1e308");
    long_digits(&r);
    let r = get(&server.url(&format!("/api/v1/dems/{dem}/elevation?lon=15&lat=-1e308")));
    assert_problem(&r, 400, "latitude -1e308");
    long_digits(&r);
    let costmaps = server.url("/api/v1/costmaps");
    for (body, pointer, shown) in [
        (
            json!({"dem_id": dem, "options": {"pca_radius_m": 1e-300}}),
            "/options/pca_radius_m",
            "1e-300 m",
        ),
        (
            json!({"dem_id": dem, "vehicle": {"preset": "u-go", "width_m": 1e308}}),
            "/vehicle/width_m",
            "got 1e308",
        ),
    ] {
        let r = post_json(&costmaps, &body);
        assert_invalid_at(&r, pointer, pointer, shown);
        long_digits(&r);
    }
    let r = post_json(&costmaps, &json!({"dem_id": dem}));
    assert_eq!(r.status, 202, "{}", r.text());
    let costmap = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(wait_costmap_finished(&server, &costmap)["status"], "done");
    let routes = server.url(&format!("/api/v1/costmaps/{costmap}/routes"));
    let goal = json!({"utm": [500030, 5000030]});
    for (body, pointer, shown) in [
        (
            json!({"start": {"utm": [1e308, 1e308]}, "goal": goal}),
            "/start",
            "{utm: [1e308, 1e308]}",
        ),
        (
            json!({"start": [1e308, -1e308], "goal": goal}),
            "/start",
            "[1e308, -1e308]",
        ),
        (
            json!({"start": {"utm": [500010, 5000010]}, "goal": goal, "speed_m_s": 1e308}),
            "/speed_m_s",
            "got 1e308",
        ),
    ] {
        let r = post_json(&routes, &body);
        assert_invalid_at(&r, pointer, pointer, shown);
        long_digits(&r);
    }
}

/// A request head still arriving does not hold up a graceful shutdown:
/// with nothing to finish, the server stops at once instead of waiting
/// out the header timeout.
#[test]
fn a_half_sent_request_does_not_delay_shutdown() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--header-read-timeout-s", "60"]);
    let addr = authority(&server.base);
    let mut slow: Vec<Slow> = (0..10).map(|i| Slow::open(&addr, i % 2 == 1)).collect();
    // Held open, so the trickling bodies are being read, and judged
    // (after a second) slower than the minimum rate, when it stops.
    watch(&mut slow, Instant::now() + Duration::from_millis(1500));
    let t = Instant::now();
    let status = server.stop();
    let took = t.elapsed();
    assert!(status.success(), "{status:?}");
    assert!(took < Duration::from_secs(10), "shutdown took {took:?}");
}

/// A SIGTERM as soon as the address is announced is already a graceful
/// stop (the handlers are installed before), not the default kill.
#[test]
fn a_sigterm_right_after_start_is_a_clean_stop() {
    for _ in 0..5 {
        let dir = tempfile::tempdir().unwrap();
        let status = Server::start(dir.path(), &[]).stop();
        assert!(status.success(), "{status:?}");
    }
}
