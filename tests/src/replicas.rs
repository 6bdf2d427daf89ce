//! Replicas on one PostgreSQL database: a database of their own in the
//! cluster `TERRAPLAN_TEST_DATABASE_URL` names (dropped afterwards), and
//! `terraplan serve` / `terraplan worker` processes on it whose log lines
//! are kept, killed (SIGKILL) or stopped (SIGTERM) at will; and event
//! stream clients that keep what they received even when the stream is
//! cut.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::{remember_token, terraplan_bin, text};

/// The `psql` client: on the `PATH`, or the newest in Debian's
/// PostgreSQL directories.
fn psql() -> PathBuf {
    let on_path = Command::new("psql")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if on_path {
        return PathBuf::from("psql");
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("bin/psql"))
        .filter(|p| p.exists())
        .collect();
    found.sort();
    found
        .pop()
        .expect("psql (PostgreSQL's client) is needed to make the test's database")
}

/// `url` with its database name replaced by `name`.
fn with_database(url: &str, name: &str) -> String {
    let (head, query) = match url.split_once('?') {
        Some((h, q)) => (h, Some(q)),
        None => (url, None),
    };
    let scheme_end = head.find("://").map_or(0, |i| i + 3);
    let base = match head[scheme_end..].find('/') {
        Some(i) => &head[..scheme_end + i],
        None => head,
    };
    match query {
        Some(q) => format!("{base}/{name}?{q}"),
        None => format!("{base}/{name}"),
    }
}

/// A database made for one test in the cluster of
/// `TERRAPLAN_TEST_DATABASE_URL`, dropped (connections and all) when
/// this is dropped.
pub struct TestDatabase {
    /// The cluster's own database, where the test's is made and dropped.
    admin_url: String,
    name: String,
    pub url: String,
}

impl TestDatabase {
    /// A new empty database, or `None` (with the reason printed) when
    /// `TERRAPLAN_TEST_DATABASE_URL` is not set.
    pub fn create(test: &str) -> Option<TestDatabase> {
        let Ok(admin_url) = std::env::var("TERRAPLAN_TEST_DATABASE_URL") else {
            println!(
                "skipped {test}: it needs PostgreSQL (set TERRAPLAN_TEST_DATABASE_URL, as \
                 scripts/test.sh does with scripts/pg-cluster.sh)"
            );
            return None;
        };
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let name = format!("terraplan_{test}_{}_{nanos}", std::process::id());
        let db = TestDatabase {
            url: with_database(&admin_url, &name),
            admin_url,
            name,
        };
        db.admin(&format!("CREATE DATABASE {}", db.name));
        Some(db)
    }

    fn admin(&self, sql: &str) -> String {
        run_psql(&self.admin_url, sql)
    }

    /// Rows of `sql` on the test's database, `|`-separated columns.
    pub fn query(&self, sql: &str) -> Vec<Vec<String>> {
        run_psql(&self.url, sql)
            .lines()
            .filter(|l| !l.is_empty())
            .map(|l| l.split('|').map(str::to_string).collect())
            .collect()
    }
}

fn run_psql(url: &str, sql: &str) -> String {
    let out = Command::new(psql())
        .args([
            url,
            "-X",
            "-q",
            "-A",
            "-t",
            "-v",
            "ON_ERROR_STOP=1",
            "-c",
            sql,
        ])
        .output()
        .expect("run psql");
    assert!(
        out.status.success(),
        "psql {sql:?}: {}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

impl Drop for TestDatabase {
    fn drop(&mut self) {
        let _ = Command::new(psql())
            .args([
                &self.admin_url,
                "-X",
                "-q",
                "-c",
                &format!("DROP DATABASE IF EXISTS {} WITH (FORCE)", self.name),
            ])
            .output();
    }
}

/// What a replica runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// `terraplan serve`: the HTTP service and the job runner.
    Serve,
    /// `terraplan worker`: the job runner alone.
    Worker,
}

/// A `terraplan serve` or `terraplan worker` process on a test database,
/// with a data directory of its own; killed when dropped.
pub struct Replica {
    pub name: String,
    pub role: Role,
    child: Option<Child>,
    /// `http://127.0.0.1:PORT` (empty for a worker).
    pub base: String,
    /// Every line it logged so far (also echoed to the test's stderr).
    log: Arc<Mutex<Vec<String>>>,
    /// The lines it printed on stdout after the first.
    stdout: Arc<Mutex<Vec<String>>>,
    _data_dir: ScratchDir,
}

/// A directory of its own under the system's temporary directory,
/// removed when dropped.
struct ScratchDir(PathBuf);

impl ScratchDir {
    fn new(name: &str) -> ScratchDir {
        static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!(
            "terraplan-replica-{name}-{}-{n}",
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a data directory");
        ScratchDir(dir)
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

impl Replica {
    /// Start `role` on `database_url` with `args`, and wait until it is
    /// ready (a server listening, a worker taking jobs).
    pub fn start(name: &str, role: Role, database_url: &str, args: &[&str]) -> Replica {
        let data_dir = ScratchDir::new(name);
        let mut cmd = Command::new(terraplan_bin());
        match role {
            Role::Serve => cmd.args(["serve", "--host", "127.0.0.1", "--port", "0"]),
            Role::Worker => cmd.arg("worker"),
        };
        cmd.arg("--data-dir")
            .arg(&data_dir.0)
            .args(args)
            .env("DATABASE_URL", database_url)
            .env("TERRAPLAN_LOG", "info,sqlx=warn")
            .env("TERRAPLAN_LOG_FORMAT", "text")
            .env("NO_COLOR", "1")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd
            .spawn()
            .unwrap_or_else(|e| panic!("start replica {name}: {e}"));
        let log = Arc::new(Mutex::new(Vec::new()));
        {
            let log = log.clone();
            let stderr = child.stderr.take().expect("stderr");
            let tag = name.to_string();
            std::thread::spawn(move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    eprintln!("[{tag}] {line}");
                    log.lock().unwrap().push(line);
                }
            });
        }
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
        let mut first = String::new();
        stdout.read_line(&mut first).expect("read the first line");
        let base = match role {
            Role::Serve => first
                .trim()
                .strip_prefix("listening on ")
                .unwrap_or_else(|| panic!("{name}: unexpected first line {first:?}"))
                .to_string(),
            Role::Worker => {
                assert!(
                    first.starts_with("worker ") && first.trim_end().ends_with(" ready"),
                    "{name}: unexpected first line {first:?}"
                );
                String::new()
            }
        };
        let printed = Arc::new(Mutex::new(Vec::new()));
        {
            let printed = printed.clone();
            std::thread::spawn(move || {
                for line in stdout.lines().map_while(Result::ok) {
                    printed.lock().unwrap().push(line);
                }
            });
        }
        Replica {
            name: name.to_string(),
            role,
            child: Some(child),
            base,
            log,
            stdout: printed,
            _data_dir: data_dir,
        }
    }

    /// Send `token` with every request of the free request functions to
    /// this server.
    pub fn use_token(&self, token: &str) {
        remember_token(&self.base, token);
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// The lines printed on stdout after the first, so far.
    pub fn stdout_lines(&self) -> Vec<String> {
        self.stdout.lock().unwrap().clone()
    }

    /// The log lines so far.
    pub fn log_lines(&self) -> Vec<String> {
        self.log.lock().unwrap().clone()
    }

    /// The log lines so far holding every one of `needles`.
    pub fn logged(&self, needles: &[&str]) -> Vec<String> {
        self.log_lines()
            .into_iter()
            .filter(|l| needles.iter().all(|n| l.contains(n)))
            .collect()
    }

    /// Wait until a log line holds every one of `needles`; that line.
    /// Panics after `timeout`, or if the process ends first.
    pub fn wait_for_log(&mut self, needles: &[&str], timeout: Duration) -> String {
        let name = self.name.clone();
        wait_until(timeout, &format!("{name} to log {needles:?}"), || {
            if let Some(line) = self.logged(needles).into_iter().next() {
                return Some(line);
            }
            let ended = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten());
            if let Some(status) = ended {
                panic!("{name} ended ({status}) before logging {needles:?}");
            }
            None
        })
    }

    /// SIGKILL: no shutdown at all, as in a crash; waits until it is gone.
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// SIGTERM, then wait (at most `timeout`) for it to exit; its exit
    /// status (`None` if it had to be killed after the timeout).
    pub fn terminate(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let mut child = self.child.take()?;
        let _ = Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status();
        let deadline = Instant::now() + timeout;
        loop {
            if let Ok(Some(status)) = child.try_wait() {
                return Some(status);
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                return None;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Replica {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Call `check` every 50 ms until it returns something; panics with `what`
/// after `timeout`.
pub fn wait_until<T>(timeout: Duration, what: &str, mut check: impl FnMut() -> Option<T>) -> T {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(v) = check() {
            return v;
        }
        assert!(Instant::now() < deadline, "waited {timeout:?} for {what}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A client of an event stream (`text/event-stream`) reading on its own
/// thread: the events it received so far, kept when the stream is cut.
pub struct EventClient {
    events: Arc<Mutex<Vec<(String, serde_json::Value)>>>,
    reader: Option<std::thread::JoinHandle<Result<(), String>>>,
}

impl EventClient {
    /// GET `url` with `token`, and return once the answer's head says 200
    /// (the server then follows the job); panics otherwise.
    pub fn connect(url: &str, token: &str, timeout: Duration) -> EventClient {
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(timeout))
            .build()
            .into();
        let res = agent
            .get(url)
            .header("Authorization", &format!("Bearer {token}"))
            .call()
            .unwrap_or_else(|e| panic!("GET {url}: {e}"));
        assert_eq!(res.status().as_u16(), 200, "GET {url}");
        let events = Arc::new(Mutex::new(Vec::new()));
        let kept = events.clone();
        let reader = std::thread::spawn(move || {
            let body = BufReader::new(res.into_body().into_reader());
            let mut name = String::from("message");
            let mut data: Vec<String> = Vec::new();
            for line in body.lines() {
                let line = line.map_err(|e| e.to_string())?;
                if line.is_empty() {
                    if !data.is_empty() {
                        let text = data.join("\n");
                        let value = serde_json::from_str(&text)
                            .map_err(|e| format!("event data is not JSON ({e}): {text}"))?;
                        kept.lock().unwrap().push((name.clone(), value));
                    }
                    name = String::from("message");
                    data.clear();
                } else if let Some(v) = line.strip_prefix("event:") {
                    name = v.trim().to_string();
                } else if let Some(v) = line.strip_prefix("data:") {
                    data.push(v.strip_prefix(' ').unwrap_or(v).to_string());
                }
            }
            Ok(())
        });
        EventClient {
            events,
            reader: Some(reader),
        }
    }

    /// The events received so far: (event name, data).
    pub fn events(&self) -> Vec<(String, serde_json::Value)> {
        self.events.lock().unwrap().clone()
    }

    /// Wait for the stream to end; how it ended (`Err`: cut short, with
    /// why) and every event received.
    pub fn finish(mut self) -> (Result<(), String>, Vec<(String, serde_json::Value)>) {
        let ended = self.reader.take().map_or(Ok(()), |r| {
            r.join().unwrap_or_else(|_| Err("panicked".into()))
        });
        (ended, self.events())
    }
}

/// The log lines of every replica in `replicas` holding all of `needles`,
/// each with its replica's name.
pub fn logged_anywhere<'a>(
    replicas: impl IntoIterator<Item = &'a Replica>,
    needles: &[&str],
) -> Vec<(String, String)> {
    replicas
        .into_iter()
        .flat_map(|r| {
            r.logged(needles)
                .into_iter()
                .map(move |l| (r.name.clone(), l))
        })
        .collect()
}

/// Compares two rasters with GDAL (osgeo, the system Python): size,
/// geotransform, projection, the first band's nodata, description, unit,
/// metadata, data type and every value (NaN where NaN); when `tile` is not
/// 0, the second must be in blocks of `tile` × `tile`. `a` and `b` may be
/// GDAL names (`GTIFF_DIR:2:…` for a costmap's class page). The cells
/// compared.
pub fn gdal_same_raster(a: &str, b: &str, tile: usize) -> u64 {
    const COMPARE: &str = r#"
import sys, math
import numpy as np
from osgeo import gdal
gdal.UseExceptions()
pa, pb, tile = sys.argv[1], sys.argv[2], int(sys.argv[3])
a = gdal.Open(pa)
b = gdal.Open(pb)
ba, bb = a.GetRasterBand(1), b.GetRasterBand(1)
assert (a.RasterXSize, a.RasterYSize) == (b.RasterXSize, b.RasterYSize)
assert a.GetGeoTransform() == b.GetGeoTransform()
assert a.GetProjection() == b.GetProjection()
assert tile == 0 or bb.GetBlockSize() == [tile, tile], bb.GetBlockSize()
for f in ("GetNoDataValue", "GetDescription", "GetUnitType", "GetMetadata"):
    va, vb = getattr(ba, f)(), getattr(bb, f)()
    same = va == vb or (isinstance(va, float) and math.isnan(va) and math.isnan(vb))
    assert same, (f, va, vb)
assert ba.DataType == bb.DataType
xa, xb = ba.ReadAsArray(), bb.ReadAsArray()
assert np.array_equal(xa, xb, equal_nan=xa.dtype.kind == "f")
print(xa.size)
"#;
    let out = Command::new(crate::GDAL_PYTHON)
        .args(["-c", COMPARE, a, b, &tile.to_string()])
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "{a} vs {b}: {}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
        .trim()
        .parse()
        .expect("the cells compared")
}

/// A costmap's files as downloaded into a directory: `costmap.tif`,
/// `preview.png`, `legend.svg` and `layers/<name>.tif`.
pub struct CostmapFiles {
    pub dir: PathBuf,
    pub layers: Vec<String>,
}

/// The costmap of `tiled` (built in tiles of `tile` cells) equals the one
/// of `whole` (built whole): GDAL reads every page of costmap.tif and
/// every layer equal (see [`gdal_same_raster`]), the tiled one in blocks of
/// `tile`; preview.png and legend.svg are the same bytes. The cells
/// compared.
pub fn assert_same_costmap_files(whole: &CostmapFiles, tiled: &CostmapFiles, tile: usize) -> u64 {
    assert_eq!(whole.layers, tiled.layers);
    for name in ["preview.png", "legend.svg"] {
        let a = std::fs::read(whole.dir.join(name)).expect("the whole build's file");
        let b = std::fs::read(tiled.dir.join(name)).expect("the tiled build's file");
        assert!(a == b, "{name} differs");
    }
    let path = |f: &CostmapFiles, name: &str| f.dir.join(name).display().to_string();
    let mut cells = 0;
    let (a, b) = (path(whole, "costmap.tif"), path(tiled, "costmap.tif"));
    cells += gdal_same_raster(&a, &b, tile);
    cells += gdal_same_raster(
        &format!("GTIFF_DIR:2:{a}"),
        &format!("GTIFF_DIR:2:{b}"),
        tile,
    );
    for l in &whole.layers {
        let name = format!("layers/{l}.tif");
        cells += gdal_same_raster(&path(whole, &name), &path(tiled, &name), tile);
    }
    cells
}

/// Download the files of done costmap `map` (its answer) through the
/// server at `base` into `dir`.
pub fn download_costmap_files(base: &str, map: &serde_json::Value, dir: &Path) -> CostmapFiles {
    let urls = map["urls"].as_object().expect("the costmap's urls");
    std::fs::create_dir_all(dir.join("layers")).expect("a directory for the files");
    let fetch = |url: &str, to: PathBuf| {
        let reply = crate::get(&format!("{base}{url}"));
        assert_eq!(reply.status, 200, "GET {url}: {}", reply.text());
        std::fs::write(to, &reply.body).expect("write a downloaded file");
    };
    for (key, name) in [
        ("costmap_tif", "costmap.tif"),
        ("preview_png", "preview.png"),
        ("legend_svg", "legend.svg"),
    ] {
        let url = urls[key]
            .as_str()
            .unwrap_or_else(|| panic!("no {key} in {map}"));
        fetch(url, dir.join(name));
    }
    let mut layers = Vec::new();
    for (name, url) in urls["layers"].as_object().into_iter().flatten() {
        fetch(
            url.as_str().expect("a layer's url"),
            dir.join(format!("layers/{name}.tif")),
        );
        layers.push(name.clone());
    }
    layers.sort();
    CostmapFiles {
        dir: dir.to_path_buf(),
        layers,
    }
}

/// The parts of a costmap's answer that are its content (not its id,
/// name, DEM, project, times or URLs): what a tiled and a whole build of
/// the same request must agree on.
pub fn costmap_content(map: &serde_json::Value) -> serde_json::Value {
    let mut m = map.clone();
    if let Some(o) = m.as_object_mut() {
        for k in [
            "id",
            "name",
            "dem_id",
            "project_id",
            "created_at",
            "updated_at",
            "urls",
        ] {
            o.remove(k);
        }
    }
    m
}

/// The first admin's API token, which the first replica on an empty
/// database prints (waiting up to `wait` for it).
pub fn first_token(wait: Duration, r: &Replica) -> String {
    wait_until(wait, "the first start's token", || {
        r.stdout_lines().iter().find_map(|l| {
            l.split("Bearer ")
                .nth(1)
                .map(|t| t.trim_end_matches('"').trim().to_string())
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn database_names_are_replaced() {
        assert_eq!(
            with_database("postgres://u@h:5/terraplan", "x"),
            "postgres://u@h:5/x"
        );
        assert_eq!(
            with_database("postgres://u@h:5/terraplan?sslmode=disable", "x"),
            "postgres://u@h:5/x?sslmode=disable"
        );
        assert_eq!(with_database("postgres://h", "x"), "postgres://h/x");
    }
}
