//! Vehicles on 127.0.0.1 for the upload tests (`terraplan upload` and the
//! service's upload endpoint): MAVSDK's MissionRawServer
//! (tests/validators/mavsdk_vehicle.py) and a pymavlink vehicle that loses
//! and repeats messages, refuses or stores a wrong item on demand
//! (tests/validators/mavlink_vehicle.py). Each writes what it stored to a
//! JSON file read here.

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::{venv_python, workspace};

/// A vehicle process, killed when dropped.
pub struct Vehicle {
    child: Child,
    /// The UDP port it listens on.
    pub port: u16,
    out: PathBuf,
}

impl Drop for Vehicle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Vehicle {
    /// What the vehicle stored, once `ready` holds of it: MAVSDK reports
    /// a received mission from its own thread, after its MISSION_ACK
    /// (bounded wait, 30 s; then what is stored, whatever it is).
    pub fn stored_when(&self, ready: impl Fn(&Value) -> bool) -> Value {
        let limit = Instant::now() + Duration::from_secs(30);
        loop {
            let v = std::fs::read_to_string(&self.out)
                .ok()
                .and_then(|t| serde_json::from_str::<Value>(&t).ok());
            match v {
                Some(v) if ready(&v) => return v,
                _ if Instant::now() > limit => return self.stored(),
                _ => std::thread::sleep(Duration::from_millis(50)),
            }
        }
    }

    /// What the vehicle stored now (panics naming the file if nothing).
    pub fn stored(&self) -> Value {
        let text = std::fs::read_to_string(&self.out)
            .unwrap_or_else(|e| panic!("{}: nothing stored ({e})", self.out.display()));
        serde_json::from_str(&text).expect("vehicle's JSON parses")
    }

    /// Its address in `terraplan upload --to`'s syntax.
    pub fn address(&self) -> String {
        format!("udpout:127.0.0.1:{}", self.port)
    }
}

/// A UDP port free on 127.0.0.1 now.
pub fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Start a validator vehicle and wait for its READY line (which may name
/// the port it bound).
fn start_vehicle(script: &str, args: &[String], port: u16, out: PathBuf) -> Vehicle {
    let mut child = Command::new(venv_python())
        .arg(workspace().join("tests/validators").join(script))
        .args(args)
        .stdout(Stdio::piped())
        .spawn()
        .expect("start the vehicle");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .expect("vehicle's READY line");
    assert!(line.starts_with("READY"), "{script}: {line:?}");
    let port = line
        .split_whitespace()
        .nth(1)
        .map_or(port, |p| p.parse().unwrap());
    Vehicle { child, port, out }
}

/// MAVSDK's MissionRawServer on a free port, for up to 120 s.
pub fn mavsdk_vehicle(dir: &Path) -> Vehicle {
    let port = free_udp_port();
    let out = dir.join(format!("mavsdk-{port}.json"));
    let args = [port.to_string(), out.display().to_string(), "120".into()];
    start_vehicle("mavsdk_vehicle.py", &args, port, out)
}

/// The pymavlink vehicle on a port of its own choosing, for up to 120 s,
/// with `extra` arguments (loss, repeats, `--nack`, `--corrupt`, …).
pub fn pymavlink_vehicle(dir: &Path, extra: &[&str]) -> Vehicle {
    let out = dir.join(format!(
        "vehicle-{}.json",
        extra.join("_").replace([':', '.'], "-")
    ));
    let mut args: Vec<String> = vec![
        "--port".into(),
        "0".into(),
        "--out".into(),
        out.display().to_string(),
        "--max-seconds".into(),
        "120".into(),
    ];
    args.extend(extra.iter().map(|s| s.to_string()));
    start_vehicle("mavlink_vehicle.py", &args, 0, out)
}

/// Params 1-4 and z: the files print 6 decimals and MAVLink carries
/// float32; x/y are the files' degrees ×1e7, rounded.
pub const PARAM_TOL: f64 = 5e-6;

/// The rows of a QGC WPL 110 file's text as MISSION_ITEM_INT fields.
pub fn wpl_items(text: &str) -> Vec<Value> {
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("QGC WPL 110"));
    lines
        .map(|l| {
            let c: Vec<&str> = l.split('\t').collect();
            let f = |k: usize| c[k].parse::<f64>().unwrap();
            json!({"frame": f(2), "command": f(3), "params": [f(4), f(5), f(6), f(7)],
                   "x": (f(8) * 1e7).round(), "y": (f(9) * 1e7).round(), "z": f(10),
                   "autocontinue": f(11)})
        })
        .collect()
}

/// The vehicle's items equal the file's rows (NaN stored as null); x/y
/// within `xy_tol` (degrees ×1e7): 0 for items sent from the same file, 1
/// for a `.plan`'s items against the `.waypoints`, which prints lat/lon to
/// 1e-8° so that a value at a half may round to the neighbouring 1e-7.
pub fn assert_items_equal(what: &str, got: &[Value], want: &[Value], xy_tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}: item count");
    let num = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        for key in ["frame", "command", "autocontinue"] {
            assert_eq!(
                num(&g[key]),
                num(&w[key]),
                "{what} item {k} {key}: {g} vs {w}"
            );
        }
        for key in ["x", "y"] {
            let d = (num(&g[key]) - num(&w[key])).abs();
            assert!(d <= xy_tol, "{what} item {k} {key}: {g} vs {w}");
        }
        assert_eq!(g["seq"].as_u64(), Some(k as u64), "{what} item {k}");
        for (p, want_p) in w["params"].as_array().unwrap().iter().enumerate() {
            let (a, b) = (num(&g[format!("param{}", p + 1).as_str()]), num(want_p));
            assert!(
                (a.is_nan() && b.is_nan()) || (a - b).abs() <= PARAM_TOL * b.abs().max(1.0),
                "{what} item {k} param{}: {a} vs {b}",
                p + 1
            );
        }
        let (a, b) = (num(&g["z"]), num(&w["z"]));
        assert!(
            (a - b).abs() <= PARAM_TOL * b.abs().max(1.0),
            "{what} item {k} z: {a} vs {b}"
        );
    }
}

/// A list the vehicle stored (panics naming it if it is not a list).
pub fn items(v: &Value) -> Vec<Value> {
    v.as_array()
        .unwrap_or_else(|| panic!("not a list: {v}"))
        .clone()
}

/// A fence sent from a `.plan` as the vehicle stored it: the fence file's
/// items, then the breach return point (MAV_CMD_NAV_FENCE_RETURN_POINT) at
/// the first rally point (x/y within 1, degrees ×1e7); and the rally points
/// stored equal to the rally file's.
pub fn assert_fence_and_rally(what: &str, stored: &Value, fence: &[Value], rally: &[Value]) {
    let got_fence = items(&stored["fence"]);
    assert_eq!(got_fence.len(), fence.len() + 1, "{what}");
    assert_items_equal(
        &format!("{what} fence"),
        &got_fence[..fence.len()],
        fence,
        1.0,
    );
    let ret = &got_fence[fence.len()];
    assert_eq!(ret["command"], 5000, "{ret}");
    let num = |v: &Value| v.as_f64().unwrap();
    assert!((num(&ret["x"]) - num(&rally[0]["x"])).abs() <= 1.0, "{ret}");
    assert!((num(&ret["y"]) - num(&rally[0]["y"])).abs() <= 1.0, "{ret}");
    assert_items_equal(
        &format!("{what} rally"),
        &items(&stored["rally"]),
        rally,
        1.0,
    );
}
