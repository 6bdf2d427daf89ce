//! Helpers for the end-to-end tests in `tests/`: locate the real
//! `terraplan` binary, the shared test data and the validators' venv.

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

/// A real `terraplan serve` process on a free loopback port, stopped with
/// SIGTERM (graceful shutdown) when dropped.
pub struct Server {
    child: Option<std::process::Child>,
    pub base: String,
    pub data_dir: PathBuf,
}

impl Server {
    /// Start on `data_dir`. With `TERRAPLAN_TEST_DATABASE_URL` set (the
    /// test command sets it for the PostgreSQL run) the server uses that
    /// database instead of the embedded SQLite.
    pub fn start(data_dir: &Path, extra_args: &[&str]) -> Server {
        use std::io::{BufRead, BufReader};
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
        let mut child = cmd.spawn().expect("start terraplan serve");
        let stdout = child.stdout.take().expect("stdout");
        let mut line = String::new();
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("read address");
        let base = line
            .trim()
            .strip_prefix("listening on ")
            .unwrap_or_else(|| panic!("unexpected first line from terraplan serve: {line:?}"))
            .to_string();
        Server {
            child: Some(child),
            base,
            data_dir: data_dir.to_path_buf(),
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
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
    }
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
    reply(agent.get(url).call())
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
    reply(agent().get(url).call())
}

pub fn delete(url: &str) -> Reply {
    reply(agent().delete(url).call())
}

pub fn post(url: &str, content_type: &str, body: &[u8]) -> Reply {
    reply(
        agent()
            .post(url)
            .header("Content-Type", content_type)
            .send(body),
    )
}

/// GET with extra request headers.
pub fn get_with_headers(url: &str, headers: &[(&str, &str)]) -> Reply {
    let mut req = agent().get(url);
    for (k, v) in headers {
        req = req.header(*k, *v);
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
    let values: Vec<f64> = run_tool(
        "/usr/bin/python3",
        &[script.to_str().unwrap()],
        Some(&input),
    )
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
