//! Rows of the tables that hold DEMs, counted in a server's SQLite file
//! (opened read-only by Python's sqlite3, beside the running server), and
//! a raw upload sent without waiting for its answer.

// Each test file that includes this module uses a part of it.
#![allow(dead_code)]

use std::io::Write;
use std::path::Path;

use terraplan_e2e::{Server, run_tool};

/// What the database holds of DEMs: finished DEMs, their tile sets, tiles
/// (of DEMs or of uploads running) and uploads running.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DemRows {
    pub dems: u64,
    pub tile_sets: u64,
    pub tiles: u64,
    pub uploads: u64,
}

impl DemRows {
    pub const NONE: DemRows = DemRows {
        dems: 0,
        tile_sets: 0,
        tiles: 0,
        uploads: 0,
    };
}

/// The rows of `dems`, `dem_tile_sets`, `dem_tiles` and `dem_uploads` in
/// the SQLite database of `data_dir`.
pub fn dem_rows(data_dir: &Path) -> DemRows {
    let db = data_dir.join("terraplan.sqlite3");
    let out = run_tool(
        "python3",
        &[
            "-c",
            "import sqlite3, sys\n\
             c = sqlite3.connect('file:' + sys.argv[1] + '?mode=ro', uri=True)\n\
             print(*[c.execute(f'SELECT COUNT(*) FROM {t}').fetchone()[0] \
                     for t in ('dems', 'dem_tile_sets', 'dem_tiles', 'dem_uploads')])",
            db.to_str().unwrap(),
        ],
        None,
    );
    let n: Vec<u64> = out.split_whitespace().map(|v| v.parse().unwrap()).collect();
    DemRows {
        dems: n[0],
        tile_sets: n[1],
        tiles: n[2],
        uploads: n[3],
    }
}

/// A Python process that counts the rows of [`dem_rows`] on each call
/// (one process for many counts: a fuzz test counts after every upload).
pub struct RowCounter {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
}

impl RowCounter {
    pub fn new(data_dir: &Path) -> RowCounter {
        let db = data_dir.join("terraplan.sqlite3");
        let mut child = std::process::Command::new("python3")
            .args([
                "-c",
                "import sqlite3, sys\n\
                 c = sqlite3.connect('file:' + sys.argv[1] + '?mode=ro', uri=True)\n\
                 for _ in sys.stdin:\n\
                 \x20   print(*[c.execute(f'SELECT COUNT(*) FROM {t}').fetchone()[0] \
                           for t in ('dems', 'dem_tile_sets', 'dem_tiles', 'dem_uploads')], \
                           flush=True)",
                db.to_str().unwrap(),
            ])
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("python3");
        let out = std::io::BufReader::new(child.stdout.take().unwrap());
        RowCounter { child, out }
    }

    pub fn count(&mut self) -> DemRows {
        use std::io::BufRead;
        let stdin = self.child.stdin.as_mut().unwrap();
        stdin.write_all(b"\n").unwrap();
        stdin.flush().unwrap();
        let mut line = String::new();
        self.out.read_line(&mut line).unwrap();
        let n: Vec<u64> = line
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(n.len(), 4, "row counter answered {line:?}");
        DemRows {
            dems: n[0],
            tile_sets: n[1],
            tiles: n[2],
            uploads: n[3],
        }
    }
}

impl Drop for RowCounter {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Start sending `body` as a GeoTIFF upload (`query` after `?`) on a
/// connection of its own from another thread, its answer not awaited
/// (the server may be killed under it).
pub fn upload_in_background(
    server: &Server,
    query: &str,
    body: Vec<u8>,
) -> std::thread::JoinHandle<()> {
    upload_in_background_to(&server.url(""), &server.auth_line(), query, body)
}

/// [`upload_in_background`] to the server at `base` (`http://host:port`),
/// with the header line `auth` (`Authorization: …\r\n`).
pub fn upload_in_background_to(
    base: &str,
    auth: &str,
    query: &str,
    body: Vec<u8>,
) -> std::thread::JoinHandle<()> {
    let authority = base
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    let (auth, query) = (auth.to_string(), query.to_string());
    std::thread::spawn(move || {
        let Ok(mut s) = std::net::TcpStream::connect(&authority) else {
            return;
        };
        let head = format!(
            "POST /api/v1/dems?{query} HTTP/1.1\r\nHost: {authority}\r\n\
             Content-Type: image/tiff\r\nContent-Length: {}\r\n{auth}\
             Connection: close\r\n\r\n",
            body.len()
        );
        let _ = s.write_all(head.as_bytes());
        let _ = s.write_all(&body);
        let mut sink = Vec::new();
        let _ = std::io::Read::read_to_end(&mut s, &mut sink);
    })
}
