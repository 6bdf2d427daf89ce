//! Helpers for the end-to-end tests in `tests/`: locate the real
//! `terraplan` binary, the shared test data and the validators' venv.

pub mod replicas;
pub mod vehicles;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// The `terraplan` binary built by `cargo build --workspace --bins` (the
/// test command does that first); `TERRAPLAN_BIN` overrides it.
pub fn terraplan_bin() -> PathBuf {
    if let Ok(p) = std::env::var("TERRAPLAN_BIN") {
        return PathBuf::from(p);
    }
    let target = std::env::var("CARGO_TARGET_DIR")
        .map_or_else(|_| workspace().join("target"), PathBuf::from);
    let bin = target.join("debug").join("terraplan");
    assert!(
        bin.exists(),
        "{} is missing: run `cargo build --workspace --bins` first (scripts/test.sh does)",
        bin.display()
    );
    bin
}

/// A file of the shared real-world test data (`../shared/data` beside the
/// repository; `TERRAPLAN_SHARED_DATA` overrides it).
pub fn shared_data(rel: &str) -> PathBuf {
    let base = std::env::var("TERRAPLAN_SHARED_DATA")
        .map_or_else(|_| workspace().join("../shared/data"), PathBuf::from);
    let p = base.join(rel);
    assert!(p.exists(), "shared test data {} is missing", p.display());
    p
}

/// Python of the validators' venv (made by `scripts/setup.sh --with-validators`).
pub fn venv_python() -> PathBuf {
    let venv =
        std::env::var("TERRAPLAN_VENV").map_or_else(|_| workspace().join(".venv"), PathBuf::from);
    let py = venv.join("bin").join("python");
    assert!(
        py.exists(),
        "{} is missing: run `bash scripts/setup.sh --with-validators` (scripts/test.sh does)",
        py.display()
    );
    py
}

/// Run `terraplan` with `args`.
pub fn terraplan(args: &[&str]) -> Output {
    Command::new(terraplan_bin())
        .args(args)
        .output()
        .expect("run terraplan")
}

/// Run a validator script from `tests/validators` with the venv's Python.
pub fn validator(script: &str, args: &[&Path]) -> Output {
    Command::new(venv_python())
        .arg(workspace().join("tests/validators").join(script))
        .args(args)
        .output()
        .expect("run validator")
}

pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Writes `v` as JSON to `dir/name`; returns the path.
pub fn write_json(dir: &Path, name: &str, v: &serde_json::Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_string(v).unwrap()).unwrap();
    p
}

/// The area a survey covers: a region of interest (`--roi`) or a
/// corridor's centre line (`--corridor`).
pub enum SurveyArea<'a> {
    Roi(&'a Path),
    Corridor(&'a Path),
}

/// What `terraplan survey` reads in a test: the area, its no-fly zones, an
/// optional DEM and the params file.
pub struct SurveyFiles<'a> {
    pub area: SurveyArea<'a>,
    pub no_fly: &'a [&'a Path],
    pub dem: Option<&'a Path>,
    pub params: &'a Path,
}

/// `terraplan survey` of `files` into `out`, which must succeed (`what`
/// names the case in the failure message); returns its plan.json.
pub fn survey_cli(files: &SurveyFiles, out: &Path, what: &str) -> serde_json::Value {
    let (flag, area) = match files.area {
        SurveyArea::Roi(p) => ("--roi", p),
        SurveyArea::Corridor(p) => ("--corridor", p),
    };
    let mut args = vec!["survey", flag, area.to_str().unwrap()];
    for n in files.no_fly {
        args.extend(["--no-fly", n.to_str().unwrap()]);
    }
    if let Some(dem) = files.dem {
        args.extend(["--dem", dem.to_str().unwrap()]);
    }
    args.extend([
        "--params",
        files.params.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let o = terraplan(&args);
    assert!(
        o.status.success(),
        "{what}: terraplan survey failed: {}",
        text(&o.stderr)
    );
    serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap()
}

/// Debian's Python, which has GDAL's bindings (python3-gdal; the venv has
/// none).
pub const GDAL_PYTHON: &str = "/usr/bin/python3";

/// check_terrain.py (GDAL) on a survey's `plan_json` over `dem`, for UAV
/// `uav` and its `files` (its `.waypoints`, then optionally its
/// `.route.geojson`); asserts that it passes and returns its summary.
pub fn check_terrain(
    dem: &Path,
    plan_json: &Path,
    uav: &str,
    files: &[&Path],
) -> serde_json::Value {
    let out = Command::new(GDAL_PYTHON)
        .arg(workspace().join("tests/validators/check_terrain.py"))
        .arg(dem)
        .arg(plan_json)
        .arg(uav)
        .args(files)
        .output()
        .expect("run check_terrain.py");
    assert!(
        out.status.success(),
        "check_terrain.py on {} over {}, UAV {uav}: {}{}",
        plan_json.display(),
        dem.display(),
        text(&out.stdout),
        text(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("check_terrain.py prints its summary")
}

/// A real `terraplan serve` process on a free loopback port, stopped with
/// SIGTERM (graceful shutdown) when dropped.
pub struct Server {
    child: Option<std::process::Child>,
    pub base: String,
    pub data_dir: PathBuf,
    /// The admin user the harness made for this server (`terraplan user
    /// create … --admin`), empty for [`Server::start_without_user`].
    pub user: String,
    /// An API token of [`Server::user`], which the free request functions
    /// send to this server unless told otherwise (see [`Auth`]).
    pub token: String,
    /// The lines it logs, when started by [`Server::start_logging`].
    log: Option<std::sync::mpsc::Receiver<String>>,
    /// The lines it prints on stdout after `listening on …`.
    stdout: std::sync::mpsc::Receiver<String>,
}

/// The harness users, by data directory: a server started again on the
/// same directory gets a new token of the same user, so that it sees what
/// the first one made.
fn harness_users() -> &'static std::sync::Mutex<std::collections::HashMap<PathBuf, String>> {
    static USERS: std::sync::OnceLock<
        std::sync::Mutex<std::collections::HashMap<PathBuf, String>>,
    > = std::sync::OnceLock::new();
    USERS.get_or_init(Default::default)
}

/// The token of each running test server, by its authority (`host:port`).
fn server_tokens() -> &'static std::sync::Mutex<std::collections::HashMap<String, String>> {
    static TOKENS: std::sync::OnceLock<
        std::sync::Mutex<std::collections::HashMap<String, String>>,
    > = std::sync::OnceLock::new();
    TOKENS.get_or_init(Default::default)
}

/// The `host:port` of an `http://` URL.
fn authority(url: &str) -> &str {
    let rest = url.strip_prefix("http://").unwrap_or(url);
    rest.split(['/', '?']).next().unwrap_or(rest)
}

/// Send `token` to the server at `url` (its base URL or authority) from
/// now on, as for a server started by [`Server::start`].
pub fn remember_token(url: &str, token: &str) {
    server_tokens()
        .lock()
        .unwrap()
        .insert(authority(url).to_string(), token.to_string());
}

/// The credential header lines (`Authorization: Bearer …\r\n`, or none)
/// of the test server `url` names, for a request written by hand.
pub fn credential_lines(url: &str) -> String {
    token_for(url)
        .map(|t| format!("Authorization: Bearer {t}\r\n"))
        .unwrap_or_default()
}

/// The token of the test server `url` names, if this process started it.
pub fn token_for(url: &str) -> Option<String> {
    server_tokens().lock().unwrap().get(authority(url)).cloned()
}

/// A user name no other test server (of this or another process, on a
/// shared PostgreSQL database) has.
pub fn unique_user_name(prefix: &str) -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!(
        "{prefix}-{}-{}-{nanos}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// `terraplan user ARGS…` on the database of `data_dir` (or
/// `TERRAPLAN_TEST_DATABASE_URL`), with `stdin` as its input.
pub fn user_command(data_dir: &Path, args: &[&str], stdin: Option<&str>) -> Output {
    let mut cmd = Command::new(terraplan_bin());
    cmd.arg("user")
        .args(args)
        .arg("--data-dir")
        .arg(data_dir)
        .env_remove("DATABASE_URL")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    if let Ok(url) = std::env::var("TERRAPLAN_TEST_DATABASE_URL") {
        cmd.env("DATABASE_URL", url);
    }
    let mut child = cmd.spawn().expect("run terraplan user");
    let mut input = child.stdin.take().unwrap();
    let feed = stdin.unwrap_or("").to_string();
    let writer = std::thread::spawn(move || {
        let _ = input.write_all(feed.as_bytes());
    });
    let out = child.wait_with_output().expect("terraplan user");
    writer.join().unwrap();
    out
}

/// The last line of a command's stdout (where `terraplan user create` and
/// `user token` print the new token).
pub fn last_line(out: &Output) -> String {
    text(&out.stdout)
        .lines()
        .last()
        .unwrap_or_default()
        .trim()
        .to_string()
}

/// The harness's admin for `data_dir` and a new token of it: made by
/// `terraplan user create` the first time, by `user token` after.
/// [`Server::start`] calls it; tests that start `terraplan serve`
/// themselves call it first and then [`remember_token`].
pub fn harness_user(data_dir: &Path) -> (String, String) {
    let known = harness_users().lock().unwrap().get(data_dir).cloned();
    let (name, out) = match known {
        Some(name) => {
            let out = user_command(data_dir, &["token", &name], None);
            (name, out)
        }
        None => {
            let name = unique_user_name("e2e");
            let out = user_command(data_dir, &["create", &name, "--admin"], None);
            (name, out)
        }
    };
    assert!(
        out.status.success(),
        "terraplan user on {}: {}{}",
        data_dir.display(),
        text(&out.stdout),
        text(&out.stderr)
    );
    harness_users()
        .lock()
        .unwrap()
        .insert(data_dir.to_path_buf(), name.clone());
    (name, last_line(&out))
}

impl Server {
    /// Start on `data_dir`. With `TERRAPLAN_TEST_DATABASE_URL` set (the
    /// test command sets it for the PostgreSQL run) the server uses that
    /// database instead of the embedded SQLite.
    ///
    /// A user (an admin, its name unique) is made first on the same data
    /// directory / database, and its token sent by the free request
    /// functions to this server.
    pub fn start(data_dir: &Path, extra_args: &[&str]) -> Server {
        Server::spawn(data_dir, extra_args, None, true)
    }

    /// [`Server::start`] without making a user first (a first start).
    pub fn start_without_user(data_dir: &Path, extra_args: &[&str]) -> Server {
        Server::spawn(data_dir, extra_args, None, false)
    }

    /// The next line the server prints on stdout after `listening on …`,
    /// if one comes within `timeout`.
    pub fn stdout_line(&self, timeout: std::time::Duration) -> Option<String> {
        self.stdout.recv_timeout(timeout).ok()
    }

    /// `Authorization: Bearer …\r\n`, the header line of this server's
    /// token, for tests that write requests by hand.
    pub fn auth_line(&self) -> String {
        format!("Authorization: Bearer {}\r\n", self.token)
    }

    /// [`Server::start`] with the log filter `filter` (`TERRAPLAN_LOG`),
    /// its lines kept for [`Server::wait_for_log`] (and still shown).
    pub fn start_logging(data_dir: &Path, extra_args: &[&str], filter: &str) -> Server {
        Server::spawn(data_dir, extra_args, Some(filter), true)
    }

    /// Wait until the server logs a line holding every one of `needles`
    /// (lines logged earlier count); that line. Panics after `timeout`.
    pub fn wait_for_log(&self, needles: &[&str], timeout: std::time::Duration) -> String {
        let log = self
            .log
            .as_ref()
            .expect("a server started by Server::start_logging");
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match log.recv_timeout(left) {
                Ok(line) if needles.iter().all(|n| line.contains(n)) => return line,
                Ok(_) => {}
                Err(e) => panic!("the server logged no line with {needles:?} ({e})"),
            }
        }
    }

    fn spawn(
        data_dir: &Path,
        extra_args: &[&str],
        log_filter: Option<&str>,
        with_user: bool,
    ) -> Server {
        use std::io::{BufRead, BufReader};
        let (user, token) = if with_user {
            harness_user(data_dir)
        } else {
            Default::default()
        };
        let mut cmd = Command::new(terraplan_bin());
        cmd.args(["serve", "--host", "127.0.0.1", "--port", "0", "--data-dir"])
            .arg(data_dir)
            .args(extra_args)
            .env_remove("DATABASE_URL")
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::inherit());
        if let Ok(url) = std::env::var("TERRAPLAN_TEST_DATABASE_URL") {
            cmd.env("DATABASE_URL", url);
        }
        if let Some(filter) = log_filter {
            cmd.env("TERRAPLAN_LOG", filter)
                .stderr(std::process::Stdio::piped());
        }
        let mut child = cmd.spawn().expect("start terraplan serve");
        let log = child.stderr.take().map(|stderr| {
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    eprintln!("{line}");
                    let _ = tx.send(line);
                }
            });
            rx
        });
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut line = String::new();
        stdout.read_line(&mut line).expect("read address");
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected first line from terraplan serve: {line:?}"))
            .to_string();
        // Keep reading, so that what the server prints later never meets a
        // closed pipe.
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stdout.lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        if with_user {
            server_tokens()
                .lock()
                .unwrap()
                .insert(authority(&base).to_string(), token.clone());
        }
        Server {
            child: Some(child),
            base,
            data_dir: data_dir.to_path_buf(),
            user,
            token,
            log,
            stdout: rx,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// The server's process id (for `/proc/<pid>/status`).
    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("server running").id()
    }

    /// Send SIGTERM and wait for a clean exit; returns the exit status.
    pub fn stop(mut self) -> std::process::ExitStatus {
        self.terminate().expect("server was running")
    }

    /// Kill the process with SIGKILL (no shutdown at all, as in a crash)
    /// and wait for it to be gone.
    pub fn kill(mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    fn terminate(&mut self) -> Option<std::process::ExitStatus> {
        let mut child = self.child.take()?;
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        loop {
            if let Ok(Some(status)) = child.try_wait() {
                return Some(status);
            }
            if std::time::Instant::now() > deadline {
                let _ = child.kill();
                return child.wait().ok();
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.terminate();
        server_tokens()
            .lock()
            .unwrap()
            .remove(authority(&self.base));
    }
}

/// The credentials of a request.
#[derive(Clone, Debug, Default)]
pub enum Auth {
    /// The token of the test server the URL names (none for other URLs),
    /// unless the request's own headers carry `Authorization` or `Cookie`:
    /// what the free request functions send.
    #[default]
    Server,
    /// No credentials at all.
    None,
    /// `Authorization: Bearer TOKEN`.
    Bearer(String),
    /// The session cookie, and `X-CSRF-Token` when `csrf` is given.
    Cookie {
        session: String,
        csrf: Option<String>,
    },
}

impl Auth {
    /// The header fields this sends to `url`, given the request's own.
    pub fn headers(&self, url: &str, own: &[(&str, &str)]) -> Vec<(String, String)> {
        match self {
            Auth::Server => {
                let has = |name: &str| own.iter().any(|(k, _)| k.eq_ignore_ascii_case(name));
                if has("authorization") || has("cookie") {
                    return Vec::new();
                }
                token_for(url)
                    .map(|t| vec![("Authorization".to_string(), format!("Bearer {t}"))])
                    .unwrap_or_default()
            }
            Auth::None => Vec::new(),
            Auth::Bearer(t) => vec![("Authorization".to_string(), format!("Bearer {t}"))],
            Auth::Cookie { session, csrf } => {
                let mut h = vec![("Cookie".to_string(), format!("terraplan_session={session}"))];
                if let Some(c) = csrf {
                    h.push(("X-CSRF-Token".to_string(), c.clone()));
                }
                h
            }
        }
    }
}

/// `req` with the credentials [`Auth::Server`] gives `url`.
fn authorize<B>(mut req: ureq::RequestBuilder<B>, url: &str) -> ureq::RequestBuilder<B> {
    for (k, v) in Auth::Server.headers(url, &[]) {
        req = req.header(k, v);
    }
    req
}

/// An HTTP response read whole.
pub struct Reply {
    pub status: u16,
    pub headers: Vec<(String, String)>,
    pub body: Vec<u8>,
}

impl Reply {
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("body is not JSON ({e}): {}", text(&self.body)))
    }
    pub fn text(&self) -> String {
        text(&self.body)
    }
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into()
}

fn reply(res: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Reply {
    let mut res = res.expect("HTTP request");
    let status = res.status().as_u16();
    let headers = res
        .headers()
        .iter()
        .map(|(k, v)| (k.as_str().to_string(), v.to_str().unwrap_or("").to_string()))
        .collect();
    let body = res
        .body_mut()
        .with_config()
        .limit(256 * 1024 * 1024)
        .read_to_vec()
        .expect("read body");
    Reply {
        status,
        headers,
        body,
    }
}

/// GET whose whole exchange (a stream included) must end within `timeout`.
pub fn get_with_timeout(url: &str, timeout: std::time::Duration) -> Reply {
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(timeout))
        .build()
        .into();
    reply(authorize(agent.get(url), url).call())
}

/// The events of a `text/event-stream` body: (event name, data parsed as
/// JSON), comments and keep-alives skipped.
pub fn sse_events(body: &str) -> Vec<(String, serde_json::Value)> {
    let mut out = Vec::new();
    for block in body.replace("\r\n", "\n").split("\n\n") {
        let mut event = String::from("message");
        let mut data = Vec::new();
        for line in block.lines() {
            if let Some(v) = line.strip_prefix("event:") {
                event = v.trim().to_string();
            } else if let Some(v) = line.strip_prefix("data:") {
                data.push(v.strip_prefix(' ').unwrap_or(v).to_string());
            }
        }
        if !data.is_empty() {
            let text = data.join("\n");
            let value = serde_json::from_str(&text)
                .unwrap_or_else(|e| panic!("event data is not JSON ({e}): {text}"));
            out.push((event, value));
        }
    }
    out
}

pub fn get(url: &str) -> Reply {
    reply(authorize(agent().get(url), url).call())
}

pub fn delete(url: &str) -> Reply {
    reply(authorize(agent().delete(url), url).call())
}

/// GET with the credentials `auth`.
pub fn get_as(auth: &Auth, url: &str) -> Reply {
    send_as(auth, "GET", url, &[], &[], Framing::Length)
}

/// DELETE with the credentials `auth`.
pub fn delete_as(auth: &Auth, url: &str) -> Reply {
    send_as(auth, "DELETE", url, &[], &[], Framing::Length)
}

/// POST JSON with the credentials `auth`.
pub fn post_json_as(auth: &Auth, url: &str, body: &serde_json::Value) -> Reply {
    send_as(
        auth,
        "POST",
        url,
        &[("Content-Type", "application/json")],
        body.to_string().as_bytes(),
        Framing::Length,
    )
}

/// POST `body` as `content_type` (see [`send`]: an answer given before the
/// whole body was sent is returned, not a broken pipe).
pub fn post(url: &str, content_type: &str, body: &[u8]) -> Reply {
    send(
        "POST",
        url,
        &[("Content-Type", content_type)],
        body,
        Framing::Length,
    )
}

/// How [`send`] frames a request body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Framing {
    /// `Content-Length`, the body as is.
    Length,
    /// `Transfer-Encoding: chunked`, in chunks of 64 KiB.
    Chunked,
}

/// Longest [`send`] waits for the server between two reads: far above any
/// request of the tests on a loaded machine, but a hang still fails.
pub const REPLY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(300);

/// One HTTP/1.1 request on a connection of its own (`Connection: close`),
/// its answer read whole.
///
/// The body is written from another thread while the answer is read, as
/// curl and browsers do: a server may answer from the headers alone (413
/// from the Content-Length, 415 from the Content-Type) and stop reading,
/// after which writing the rest fails with EPIPE or ECONNRESET. That
/// failure is no error when a complete answer arrived; ureq, used for the
/// other methods, gives up at the failed write instead.
///
/// The credentials are [`Auth::Server`]'s; [`send_as`] chooses others.
pub fn send(
    method: &str,
    url: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    framing: Framing,
) -> Reply {
    send_as(&Auth::Server, method, url, headers, body, framing)
}

/// [`send`] with the credentials `auth`.
pub fn send_as(
    auth: &Auth,
    method: &str,
    url: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    framing: Framing,
) -> Reply {
    let extra = auth.headers(url, headers);
    let mut all: Vec<(&str, &str)> = headers.to_vec();
    all.extend(extra.iter().map(|(k, v)| (k.as_str(), v.as_str())));
    let (reply, written, received) = exchange(method, url, &all, body, framing);
    reply.unwrap_or_else(|e| {
        panic!(
            "{method} {url}: {e} (writing the request: {written:?}); received {:?}",
            text(&received[..received.len().min(2000)])
        )
    })
}

/// [`send`]'s work: the answer (or why there is none), how writing the
/// request went, and the bytes received.
fn exchange(
    method: &str,
    url: &str,
    headers: &[(&str, &str)],
    body: &[u8],
    framing: Framing,
) -> (Result<Reply, String>, std::io::Result<()>, Vec<u8>) {
    use std::net::{Shutdown, TcpStream};
    let rest = url
        .strip_prefix("http://")
        .unwrap_or_else(|| panic!("not an http:// URL: {url}"));
    let (authority, path) = rest.find('/').map_or((rest, "/"), |i| rest.split_at(i));
    let mut stream =
        TcpStream::connect(authority).unwrap_or_else(|e| panic!("connect to {authority}: {e}"));
    stream.set_read_timeout(Some(REPLY_TIMEOUT)).unwrap();
    let mut head =
        format!("{method} {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n");
    for (k, v) in headers {
        head.push_str(&format!("{k}: {v}\r\n"));
    }
    match framing {
        Framing::Length => head.push_str(&format!("Content-Length: {}\r\n\r\n", body.len())),
        Framing::Chunked => head.push_str("Transfer-Encoding: chunked\r\n\r\n"),
    }
    let mut w = stream.try_clone().expect("clone the socket");
    w.set_write_timeout(Some(REPLY_TIMEOUT)).unwrap();
    let body = body.to_vec();
    let writer = std::thread::spawn(move || -> std::io::Result<()> {
        w.write_all(head.as_bytes())?;
        match framing {
            Framing::Length => w.write_all(&body)?,
            Framing::Chunked => {
                for chunk in body.chunks(64 * 1024) {
                    write!(w, "{:x}\r\n", chunk.len())?;
                    w.write_all(chunk)?;
                    w.write_all(b"\r\n")?;
                }
                w.write_all(b"0\r\n\r\n")?;
            }
        }
        w.flush()
    });
    let (reply, buf) = read_reply(&mut stream);
    // Unblock the writer if the server stopped reading without closing.
    let _ = stream.shutdown(Shutdown::Both);
    let written = writer.join().expect("request writer thread");
    (reply, written, buf)
}

/// An answer whose head has arrived and whose body is still coming (an
/// event stream): see [`get_streaming`].
pub struct Streaming {
    stream: std::net::TcpStream,
    received: Vec<u8>,
    deadline: std::time::Instant,
    url: String,
}

/// GET `url` and return once the answer's head has arrived: the server is
/// then serving the request (an event stream follows its job), which a
/// thread started to make the request does not tell. [`Streaming::finish`]
/// reads the rest; the whole exchange must end within `timeout`.
pub fn get_streaming(url: &str, timeout: std::time::Duration) -> Streaming {
    use std::io::Read;
    let deadline = std::time::Instant::now() + timeout;
    let authority = url
        .strip_prefix("http://")
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("not an http:// URL: {url}"));
    let path = &url["http://".len() + authority.len()..];
    let mut stream = std::net::TcpStream::connect(authority)
        .unwrap_or_else(|e| panic!("connect to {authority}: {e}"));
    stream.set_read_timeout(Some(timeout)).unwrap();
    let credentials: String = Auth::Server
        .headers(url, &[])
        .iter()
        .map(|(k, v)| format!("{k}: {v}\r\n"))
        .collect();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {authority}\r\nConnection: close\r\n{credentials}\r\n"
    )
    .unwrap_or_else(|e| panic!("GET {url}: {e}"));
    let mut received = Vec::new();
    let mut chunk = [0u8; 4096];
    while !received.windows(4).any(|w| w == b"\r\n\r\n") {
        match stream.read(&mut chunk) {
            Ok(0) => panic!("GET {url}: closed before an answer: {:?}", text(&received)),
            Ok(n) => received.extend_from_slice(&chunk[..n]),
            Err(e) => panic!("GET {url}: {e}"),
        }
    }
    Streaming {
        stream,
        received,
        deadline,
        url: url.to_string(),
    }
}

impl Streaming {
    /// The answer's status code.
    pub fn status(&self) -> u16 {
        let line = text(&self.received);
        line.split(' ')
            .nth(1)
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("bad status line in {line:?}"))
    }

    /// Read the rest of the answer; panics if it is not whole by the deadline.
    pub fn finish(mut self) -> Reply {
        use std::io::Read;
        let mut chunk = vec![0u8; 64 * 1024];
        loop {
            if let Some(reply) = parse_reply(&self.received, false) {
                return reply;
            }
            let left = self
                .deadline
                .saturating_duration_since(std::time::Instant::now());
            assert!(!left.is_zero(), "GET {}: unfinished in time", self.url);
            self.stream.set_read_timeout(Some(left)).unwrap();
            match self.stream.read(&mut chunk) {
                Ok(0) => {
                    return parse_reply(&self.received, true).unwrap_or_else(|| {
                        panic!("GET {}: cut short: {:?}", self.url, text(&self.received))
                    });
                }
                Ok(n) => self.received.extend_from_slice(&chunk[..n]),
                Err(e) => panic!("GET {}: {e}", self.url),
            }
        }
    }
}

/// Read one whole answer from `stream` (which may stay open for another
/// request); panics if it ends or fails first.
pub fn read_answer(stream: &mut std::net::TcpStream) -> Reply {
    let (reply, received) = read_reply(stream);
    reply.unwrap_or_else(|e| panic!("{e}; received {:?}", text(&received)))
}

/// Read from `stream` until a whole answer is there; also the bytes read.
fn read_reply(stream: &mut std::net::TcpStream) -> (Result<Reply, String>, Vec<u8>) {
    use std::io::Read;
    let mut buf = Vec::new();
    let mut chunk = vec![0u8; 64 * 1024];
    let reply = loop {
        if let Some(reply) = parse_reply(&buf, false) {
            break Ok(reply);
        }
        match stream.read(&mut chunk) {
            Ok(0) => {
                break parse_reply(&buf, true)
                    .ok_or_else(|| "the connection closed before a whole answer".to_string());
            }
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            // A reset after the answer arrived (the server closed with the
            // rest of the body unread) still leaves the answer readable;
            // a reset before it is a failure.
            Err(e) => {
                break parse_reply(&buf, false).ok_or_else(|| format!("reading the answer: {e}"));
            }
        }
    };
    (reply, buf)
}

/// The first final (non-1xx) answer in `buf`, once it is complete; `eof`:
/// nothing more will arrive (ends a body framed by the connection's close).
fn parse_reply(buf: &[u8], eof: bool) -> Option<Reply> {
    let mut start = 0;
    loop {
        let head_len = buf[start..].windows(4).position(|w| w == b"\r\n\r\n")? + 4;
        let head = std::str::from_utf8(&buf[start..start + head_len]).expect("UTF-8 head");
        let mut lines = head.split("\r\n");
        let status_line = lines.next().unwrap_or("");
        let status: u16 = status_line
            .split(' ')
            .nth(1)
            .and_then(|s| s.parse().ok())
            .unwrap_or_else(|| panic!("bad status line {status_line:?}"));
        let headers: Vec<(String, String)> = lines
            .filter(|l| !l.is_empty())
            .map(|l| {
                let (k, v) = l.split_once(':').unwrap_or((l, ""));
                (k.trim().to_string(), v.trim().to_string())
            })
            .collect();
        let body_start = start + head_len;
        if (100..200).contains(&status) {
            start = body_start; // 100 Continue and the like: the answer follows.
            continue;
        }
        let find = |name: &str| {
            headers
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map(|(_, v)| v.clone())
        };
        let rest = &buf[body_start..];
        let body = if status == 204 || status == 304 {
            Vec::new()
        } else if find("transfer-encoding").is_some_and(|t| t.eq_ignore_ascii_case("chunked")) {
            dechunk(rest)?
        } else if let Some(n) = find("content-length") {
            let n: usize = n.parse().expect("Content-Length");
            rest.get(..n)?.to_vec()
        } else if eof {
            rest.to_vec()
        } else {
            return None;
        };
        return Some(Reply {
            status,
            headers,
            body,
        });
    }
}

/// A whole chunked body decoded, or None while it is incomplete.
fn dechunk(mut data: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    loop {
        let line_end = data.windows(2).position(|w| w == b"\r\n")?;
        let size_text = std::str::from_utf8(&data[..line_end]).expect("chunk size");
        let size_text = size_text.split(';').next().unwrap_or("").trim();
        let size = usize::from_str_radix(size_text, 16).expect("hexadecimal chunk size");
        data = &data[line_end + 2..];
        if size == 0 {
            // Then an empty line, or trailer fields ending with one.
            let done = data.starts_with(b"\r\n") || data.windows(4).any(|w| w == b"\r\n\r\n");
            return done.then_some(out);
        }
        out.extend_from_slice(data.get(..size)?);
        data = data.get(size + 2..)?;
    }
}

/// GET with extra request headers.
/// (The server's token unless they carry `Authorization` or `Cookie`.)
pub fn get_with_headers(url: &str, headers: &[(&str, &str)]) -> Reply {
    let mut req = agent().get(url);
    for (k, v) in headers {
        req = req.header(*k, *v);
    }
    for (k, v) in Auth::Server.headers(url, headers) {
        req = req.header(k, v);
    }
    reply(req.call())
}

/// One part of a `multipart/form-data` body.
pub struct Part<'a> {
    pub name: &'a str,
    /// The part's `filename`, for a file.
    pub file_name: Option<&'a str>,
    pub content_type: Option<&'a str>,
    pub data: &'a [u8],
}

/// A `multipart/form-data` body of `parts` and its Content-Type.
pub fn multipart_body(parts: &[Part<'_>]) -> (String, Vec<u8>) {
    let boundary = "terraplan-e2e-7d1f0c9a4b2e";
    let mut body = Vec::new();
    for p in parts {
        body.extend_from_slice(format!("--{boundary}\r\n").as_bytes());
        let mut disposition = format!("Content-Disposition: form-data; name=\"{}\"", p.name);
        if let Some(f) = p.file_name {
            disposition.push_str(&format!("; filename=\"{f}\""));
        }
        body.extend_from_slice(disposition.as_bytes());
        body.extend_from_slice(b"\r\n");
        if let Some(ct) = p.content_type {
            body.extend_from_slice(format!("Content-Type: {ct}\r\n").as_bytes());
        }
        body.extend_from_slice(b"\r\n");
        body.extend_from_slice(p.data);
        body.extend_from_slice(b"\r\n");
    }
    body.extend_from_slice(format!("--{boundary}--\r\n").as_bytes());
    (format!("multipart/form-data; boundary={boundary}"), body)
}

/// POST a `multipart/form-data` form.
pub fn post_multipart(url: &str, parts: &[Part<'_>]) -> Reply {
    let (content_type, body) = multipart_body(parts);
    post(url, &content_type, &body)
}

pub fn post_json(url: &str, body: &serde_json::Value) -> Reply {
    post(url, "application/json", body.to_string().as_bytes())
}

/// The example field (`examples/`) with its two no-fly zones as a
/// `POST /api/v1/surveys` body, at slice angle 0.
pub fn example_survey_request() -> serde_json::Value {
    let ex = workspace().join("examples");
    let read = |f: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(ex.join(f)).expect("example file"))
            .expect("example JSON")
    };
    serde_json::json!({
        "roi": read("field.geojson"),
        "no_fly_zones": [read("field-nfz.geojson")],
        "slice_angle_deg": 0,
    })
}

/// `r` is an RFC 9457 problem with `status` whose detail or errors mention
/// `detail_has`; returns the problem document.
pub fn assert_problem(r: &Reply, status: u16, detail_has: &str) -> serde_json::Value {
    assert_eq!(r.status, status, "{}", r.text());
    assert_eq!(
        r.header("content-type"),
        Some("application/problem+json"),
        "{}",
        r.text()
    );
    let p = r.json();
    assert_eq!(p["status"], status);
    assert!(p["title"].is_string());
    let all = format!("{} {}", p["detail"], p["errors"]);
    assert!(all.contains(detail_has), "expected {detail_has:?} in {p}");
    p
}

/// [`assert_problem`] for a 422 whose `errors` also name `pointer`; `what`
/// labels the case in failure messages.
pub fn assert_invalid_at(r: &Reply, what: &str, pointer: &str, detail_has: &str) {
    let p = assert_problem(r, 422, detail_has);
    let errors = p["errors"]
        .as_array()
        .unwrap_or_else(|| panic!("{what}: no errors in {p}"));
    assert!(
        errors.iter().any(|e| e["pointer"] == pointer),
        "{what}: pointer {pointer:?} not in {p}"
    );
}

/// Runs an external tool (GDAL's command-line tools, mostly) with `input`
/// on its standard input, asserts it succeeded and returns its output.
pub fn run_tool(cmd: &str, args: &[&str], input: Option<&str>) -> String {
    let mut child = Command::new(cmd)
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run {cmd} (GDAL's tools are needed): {e}"));
    let mut stdin = child.stdin.take().unwrap();
    let feed = input.unwrap_or("").to_string();
    let writer = std::thread::spawn(move || {
        let _ = stdin.write_all(feed.as_bytes());
    });
    let out = child.wait_with_output().unwrap();
    writer.join().unwrap();
    assert!(
        out.status.success(),
        "{cmd} {args:?} failed: {}",
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// The width and height in a PNG's IHDR chunk.
pub fn png_size(png: &[u8]) -> (u32, u32) {
    assert!(
        png.len() > 24 && png.starts_with(b"\x89PNG\r\n\x1a\n") && &png[12..16] == b"IHDR",
        "not a PNG"
    );
    let be = |b: &[u8]| u32::from_be_bytes(b.try_into().unwrap());
    (be(&png[16..20]), be(&png[20..24]))
}

/// `a` and `b` within `tol` of each other (absolute).
pub fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

// ------------------------------------------------- costmaps and GDAL

/// Long enough for any costmap job of the tests, on a loaded machine.
pub const JOB_DEADLINE: std::time::Duration = std::time::Duration::from_secs(300);

/// The real DTM most costmap and route tests use (283 × 259 cells of 2 m,
/// NAD83 / UTM 18N).
pub fn dtm() -> PathBuf {
    shared_data("dems/opengeos_data__elevation_dtm.tif")
}

/// Options that make the DTM's costmap job take seconds (PCA
/// neighbourhoods of 50 cells' radius, the most allowed: about 1.8 s on
/// the 2-core machine), so it is still running when looked at right away
/// and holds its slot while a test queues and breaks another job behind it.
pub fn slow_costmap_options() -> serde_json::Value {
    serde_json::json!({"pca_radius_m": 100})
}

/// Upload a DEM file (a GeoTIFF); its id.
pub fn upload_dem(server: &Server, path: &Path) -> String {
    let data = std::fs::read(path).unwrap();
    let r = post(&server.url("/api/v1/dems"), "image/tiff", &data);
    assert_eq!(r.status, 201, "{}", r.text());
    r.json()["id"].as_str().unwrap().to_string()
}

/// The costmap job `id`, which must exist.
pub fn costmap_job(server: &Server, id: &str) -> serde_json::Value {
    let r = get(&server.url(&format!("/api/v1/costmaps/{id}")));
    assert_eq!(r.status, 200, "{}", r.text());
    r.json()
}

/// Poll until the costmap job is done or failed, checking its status and
/// progress on the way.
pub fn wait_costmap_finished(server: &Server, id: &str) -> serde_json::Value {
    let start = std::time::Instant::now();
    loop {
        let job = costmap_job(server, id);
        let status = job["status"].as_str().unwrap().to_string();
        let p = job["progress"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&p), "{job}");
        assert!(
            ["queued", "running", "done", "failed"].contains(&status.as_str()),
            "{job}"
        );
        if status == "done" || status == "failed" {
            return job;
        }
        assert!(
            start.elapsed() < JOB_DEADLINE,
            "costmap {id} unfinished: {job}"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
}

/// `gdalinfo -json` of a raster.
pub fn gdalinfo(path: &Path) -> serde_json::Value {
    serde_json::from_str(&run_tool(
        "gdalinfo",
        &["-json", path.to_str().unwrap()],
        None,
    ))
    .expect("gdalinfo JSON")
}

/// GDAL's name for page 2 of a costmap GeoTIFF (`GTIFF_DIR:2:path`), its
/// Byte class band; page 1, the Float32 cost, is the file itself.
pub fn class_page(costmap_tif: &Path) -> PathBuf {
    PathBuf::from(format!("GTIFF_DIR:2:{}", costmap_tif.display()))
}

/// The EGM96 geoid undulation (m, geoid above the WGS 84 ellipsoid) at
/// each [lon, lat], from PROJ with the EGM96 grid of Debian's proj-data
/// (`tests/validators/egm96_proj.py`): independent of terraplan's own.
pub fn egm96_undulations(points: &[[f64; 2]]) -> Vec<f64> {
    let input: String = points
        .iter()
        .map(|p| format!("{} {}\n", p[0], p[1]))
        .collect();
    let script = workspace().join("tests/validators/egm96_proj.py");
    let values: Vec<f64> = run_tool(GDAL_PYTHON, &[script.to_str().unwrap()], Some(&input))
        .lines()
        .map(|l| l.parse().expect("egm96_proj.py prints numbers"))
        .collect();
    assert_eq!(values.len(), points.len());
    values
}

/// Every value of band `band`, row-major from the top row (NaN for nan),
/// as `gdal_translate -of XYZ` reads them.
pub fn band_values(path: &Path, band: usize) -> Vec<f64> {
    let b = band.to_string();
    run_tool(
        "gdal_translate",
        &[
            "-q",
            "-b",
            &b,
            "-of",
            "XYZ",
            path.to_str().unwrap(),
            "/vsistdout/",
        ],
        None,
    )
    .lines()
    .map(|l| {
        let z = l.split_whitespace().nth(2).unwrap();
        z.parse::<f64>().unwrap_or(f64::NAN)
    })
    .collect()
}

/// `gdallocationinfo -valonly -b band` of each (col, row).
pub fn pixel_values(path: &Path, band: usize, pixels: &[(usize, usize)]) -> Vec<f64> {
    let input: String = pixels.iter().map(|(c, r)| format!("{c} {r}\n")).collect();
    let b = band.to_string();
    let out = run_tool(
        "gdallocationinfo",
        &["-valonly", "-b", &b, path.to_str().unwrap()],
        Some(&input),
    );
    let values: Vec<f64> = out
        .lines()
        .map(|l| l.trim().parse().unwrap_or(f64::NAN))
        .collect();
    assert_eq!(values.len(), pixels.len(), "{out}");
    values
}

/// Checks with `tests/validators/clearance.py` (pymavlink, shapely) that a
/// survey's mission keeps the clearance its plan reports
/// (`stats.nfz_clearance_m`) from every NFZ of `no_fly_zones` (the
/// request's array) and from the `.plan`'s inclusion fence, away from home.
/// Returns the validator's summary.
pub fn assert_clearance(
    survey: &serde_json::Value,
    waypoints: &Path,
    plan: &Path,
    no_fly_zones: &serde_json::Value,
) -> serde_json::Value {
    let dir = waypoints.parent().expect("the waypoints' directory");
    let clearance = survey["stats"]["nfz_clearance_m"]
        .as_f64()
        .expect("stats.nfz_clearance_m");
    let mut args = vec![waypoints.to_path_buf(), plan.to_path_buf()];
    for (i, zone) in no_fly_zones.as_array().into_iter().flatten().enumerate() {
        let path = dir.join(format!("clearance-nfz{i}.geojson"));
        std::fs::write(&path, zone.to_string()).expect("write NFZ");
        args.push(path);
    }
    let out = Command::new(venv_python())
        .arg(workspace().join("tests/validators/clearance.py"))
        .arg(clearance.to_string())
        .args(&args)
        .output()
        .expect("run clearance.py");
    assert!(
        out.status.success(),
        "clearance.py: {}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("clearance.py summary")
}

/// `tests/validators/check_missions.py` on a directory of mission files:
/// each `.plan` and its `.waypoints` agree item by item (pymavlink and
/// JSON), and MAVSDK and MAVProxy load them with the fence and rally files.
/// Returns its summary.
pub fn check_missions(out: &Path) -> serde_json::Value {
    let v = validator("check_missions.py", &[out]);
    assert!(
        v.status.success(),
        "check_missions.py {}: {}{}",
        out.display(),
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).expect("check_missions.py summary")
}

/// A fixed pseudo-random sequence (a 64-bit linear congruential generator)
/// for test inputs that are the same every run.
pub struct Lcg(pub u64);

impl Lcg {
    /// The next number, uniform in [0, 1).
    pub fn next_unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use std::io::{Read, Write};
    use std::net::TcpListener;

    use super::*;

    /// Read a request's head from `s` (and whatever of the body came with it).
    fn read_head(s: &mut std::net::TcpStream) -> String {
        let mut got = Vec::new();
        let mut b = [0u8; 4096];
        while !got.windows(4).any(|w| w == b"\r\n\r\n") {
            let n = s.read(&mut b).unwrap();
            assert!(n > 0, "the client closed before its head");
            got.extend_from_slice(&b[..n]);
        }
        text(&got)
    }

    const EARLY: &[u8] = b"HTTP/1.1 415 Unsupported Media Type\r\n\
        content-type: application/problem+json\r\ncontent-length: 26\r\nconnection: close\r\n\r\n\
        {\"status\":415,\"title\":\"x\"}";

    /// A server that answers 415 from the head alone and closes with the
    /// body unread (so the kernel resets the connection): the client's
    /// write fails, and it still returns the answer.
    #[test]
    fn an_answer_before_the_body_is_returned() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/up", listener.local_addr().unwrap());
        let server = std::thread::spawn(move || {
            let (mut s, _) = listener.accept().unwrap();
            let head = read_head(&mut s);
            s.write_all(EARLY).unwrap();
            head
        });
        // 64 MiB: far more than the socket buffers of both ends hold, so
        // the write cannot complete before the server has closed.
        let body = vec![7u8; 64 * 1024 * 1024];
        let (reply, written, received) = exchange(
            "POST",
            &url,
            &[("Content-Type", "image/png")],
            &body,
            Framing::Length,
        );
        let head = server.join().unwrap();
        assert!(head.starts_with("POST /up HTTP/1.1\r\n"), "{head}");
        assert!(head.contains("Content-Length: 67108864\r\n"), "{head}");
        let err = written.expect_err("the server read none of the body");
        assert!(
            matches!(
                err.kind(),
                std::io::ErrorKind::BrokenPipe | std::io::ErrorKind::ConnectionReset
            ),
            "{err:?}"
        );
        let reply = reply.unwrap_or_else(|e| panic!("{e}: received {:?}", text(&received)));
        assert_eq!(reply.status, 415);
        assert_eq!(
            reply.header("Content-Type"),
            Some("application/problem+json")
        );
        assert_eq!(reply.json()["status"], 415);
    }

    /// The ordinary exchange: the whole body (chunked here) is read, and a
    /// chunked answer is decoded.
    #[test]
    fn a_whole_exchange_with_chunked_bodies() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}/echo?x=1", listener.local_addr().unwrap());
        let server = std::thread::spawn(move || {
            let (mut s, _) = listener.accept().unwrap();
            let mut got = Vec::new();
            let mut b = [0u8; 65536];
            while !got.ends_with(b"\r\n0\r\n\r\n") {
                let n = s.read(&mut b).unwrap();
                assert!(n > 0, "the client closed early");
                got.extend_from_slice(&b[..n]);
            }
            s.write_all(
                b"HTTP/1.1 100 Continue\r\n\r\nHTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n\
                  5\r\nhello\r\n7;ext=1\r\n, world\r\n0\r\nTrailer: x\r\n\r\n",
            )
            .unwrap();
            got
        });
        let body = vec![b'a'; 200_000];
        let reply = send("POST", &url, &[("X-Test", "1")], &body, Framing::Chunked);
        assert_eq!(reply.status, 200);
        assert_eq!(reply.text(), "hello, world");
        let got = server.join().unwrap();
        let at = got.windows(4).position(|w| w == b"\r\n\r\n").unwrap() + 4;
        let head = text(&got[..at]);
        assert!(head.starts_with("POST /echo?x=1 HTTP/1.1\r\n"), "{head}");
        assert!(head.contains("X-Test: 1\r\n"), "{head}");
        assert_eq!(dechunk(&got[at..]).expect("whole body"), body);
    }

    #[test]
    fn incomplete_answers_are_not_taken() {
        let whole = b"HTTP/1.1 201 Created\r\ncontent-length: 4\r\n\r\nabcd";
        for cut in 0..whole.len() {
            assert!(parse_reply(&whole[..cut], false).is_none(), "{cut}");
        }
        let r = parse_reply(whole, false).unwrap();
        assert_eq!((r.status, r.text().as_str()), (201, "abcd"));
        // No length: the body ends with the connection.
        let open = b"HTTP/1.1 200 OK\r\n\r\nab";
        assert!(parse_reply(open, false).is_none());
        assert_eq!(parse_reply(open, true).unwrap().text(), "ab");
        assert!(dechunk(b"4\r\nabcd\r\n0\r\n").is_none());
        assert!(dechunk(b"4\r\nab").is_none());
    }
}
