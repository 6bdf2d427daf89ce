//! Replicas on one PostgreSQL database: a database of their own in the
//! cluster `TERRAPLAN_TEST_DATABASE_URL` names (dropped afterwards), and
//! `terraplan serve` / `terraplan worker` processes on it whose log lines
//! are kept, killed (SIGKILL) or stopped (SIGTERM) at will; and event
//! stream clients that keep what they received even when the stream is
//! cut.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
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
