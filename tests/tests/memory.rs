//! Memory stays bounded (issue 17, part 4): stored files are streamed a
//! chunk at a time, uploads are spooled as they arrive and read under the
//! memory budget (`--memory-budget-mb`), and a raster whose declared size
//! needs more than the budget is refused before it is read.
//!
//! The server's resident memory is read from `/proc/<pid>/status`; its
//! peak (VmHWM) is reset before each measured burst by writing 5 to
//! `/proc/<pid>/clear_refs`, so that it is the burst's peak.

use std::time::{Duration, Instant};

use serde_json::json;
use terraplan_e2e::*;

const MIB: u64 = 1024 * 1024;

/// (VmRSS, VmHWM) of process `pid`, bytes.
fn rss(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        let line = status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .unwrap_or_else(|| panic!("no {name} in /proc/{pid}/status"));
        line.trim()
            .trim_end_matches("kB")
            .trim()
            .parse::<u64>()
            .unwrap()
            * 1024
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// Reset the peak resident set (VmHWM) to the current one.
fn reset_peak(pid: u32) {
    std::fs::write(format!("/proc/{pid}/clear_refs"), "5").unwrap();
}

/// Wait until the server's resident set has settled (freed memory given
/// back after work; the allocator trims a moment after large work ends):
/// its VmRSS once two reads 0.5 s apart differ by under 1 MiB.
fn settled_rss(pid: u32) -> u64 {
    let mut last = rss(pid).0;
    for _ in 0..20 {
        std::thread::sleep(Duration::from_millis(500));
        let now = rss(pid).0;
        if now.abs_diff(last) < MIB {
            return now;
        }
        last = now;
    }
    last
}

/// A north-up little-endian GeoTIFF of `w` × `h` float samples of `bits`
/// (32 or 64) bits, 1 m cells, in strips of `rows_per_strip` rows (the
/// CRS is given at upload); `pixel` gives each height.
fn float_tiff(
    w: u32,
    h: u32,
    bits: u16,
    rows_per_strip: u32,
    pixel: impl Fn(u32, u32) -> f64,
) -> Vec<u8> {
    let bytes = u32::from(bits / 8);
    let strips = h.div_ceil(rows_per_strip);
    let mut data = Vec::with_capacity((w * h * bytes) as usize);
    for y in 0..h {
        for x in 0..w {
            let v = pixel(x, y);
            if bits == 64 {
                data.extend_from_slice(&v.to_le_bytes());
            } else {
                data.extend_from_slice(&(v as f32).to_le_bytes());
            }
        }
    }
    strip_tiff(w, h, bits, rows_per_strip, strips, &data)
}

/// The TIFF around `data` (the strips one after another).
fn strip_tiff(w: u32, h: u32, bits: u16, rows_per_strip: u32, strips: u32, data: &[u8]) -> Vec<u8> {
    const ENTRIES: u32 = 12;
    let ifd_len = 2 + ENTRIES * 12 + 4;
    let offsets_at = 8 + ifd_len;
    let counts_at = offsets_at + 4 * strips;
    let scale_at = counts_at + 4 * strips;
    let tie_at = scale_at + 24;
    let data_at = tie_at + 48;
    let strip_bytes = w * rows_per_strip * u32::from(bits / 8);
    let mut b = Vec::new();
    b.extend_from_slice(b"II*\0");
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&(ENTRIES as u16).to_le_bytes());
    let mut entry = |tag: u16, kind: u16, count: u32, value: u32| {
        b.extend_from_slice(&tag.to_le_bytes());
        b.extend_from_slice(&kind.to_le_bytes());
        b.extend_from_slice(&count.to_le_bytes());
        if kind == 3 && count == 1 {
            b.extend_from_slice(&(value as u16).to_le_bytes());
            b.extend_from_slice(&[0, 0]);
        } else {
            b.extend_from_slice(&value.to_le_bytes());
        }
    };
    let one_strip = strips == 1;
    entry(256, 4, 1, w);
    entry(257, 4, 1, h);
    entry(258, 3, 1, u32::from(bits));
    entry(259, 3, 1, 1); // no compression
    entry(262, 3, 1, 1); // black is zero
    entry(273, 4, strips, if one_strip { data_at } else { offsets_at });
    entry(277, 3, 1, 1);
    entry(278, 4, 1, rows_per_strip);
    let single_count = u32::try_from(data.len()).unwrap();
    entry(
        279,
        4,
        strips,
        if one_strip { single_count } else { counts_at },
    );
    entry(339, 3, 1, 3); // IEEE float
    entry(33550, 12, 3, scale_at); // ModelPixelScale
    entry(33922, 12, 6, tie_at); // ModelTiepoint
    b.extend_from_slice(&0u32.to_le_bytes());
    for i in 0..strips {
        b.extend_from_slice(&(data_at + i * strip_bytes).to_le_bytes());
    }
    for i in 0..strips {
        let rows = rows_per_strip.min(h - i * rows_per_strip);
        b.extend_from_slice(&(rows * w * u32::from(bits / 8)).to_le_bytes());
    }
    for v in [1.0f64, 1.0, 0.0] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.0f64, 0.0, 0.0, 500_000.0, 5_000_000.0, 0.0] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    // (With one strip the two arrays are unused: the values are inline.)
    assert_eq!(b.len() as u32, data_at);
    b.extend_from_slice(data);
    b
}

/// Gentle hills: slopes under 10°.
fn hills(x: u32, y: u32) -> f64 {
    let (x, y) = (f64::from(x), f64::from(y));
    100.0 + 5.0 * (x / 60.0).sin() + 4.0 * (y / 45.0).cos()
}

fn upload(server: &Server, tiff: &[u8]) -> Reply {
    post(
        &server.url("/api/v1/dems?crs=EPSG:32633"),
        "image/tiff",
        tiff,
    )
}

/// Eight parallel downloads of a stored costmap.tif hold a few chunks,
/// not eight files: the server's peak resident set during them grows by
/// under a quarter of the bytes sent, and stays under its budget.
#[test]
fn parallel_downloads_are_streamed() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--memory-budget-mb", "512"]);
    let pid = server.pid();
    // 2000 × 2000 cells: costmap.tif (Float32 cost and Byte class pages)
    // is about 20 MB.
    let tiff = float_tiff(2000, 2000, 32, 16, hills);
    let r = upload(&server, &tiff);
    assert_eq!(r.status, 201, "{}", r.text());
    let dem = r.json()["id"].as_str().unwrap().to_string();
    let r = post_json(&server.url("/api/v1/costmaps"), &json!({"dem_id": dem}));
    assert_eq!(r.status, 202, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let job = wait_costmap_finished(&server, &id);
    assert_eq!(job["status"], "done", "{job}");

    let url = server.url(&format!("/api/v1/costmaps/{id}/costmap.tif"));
    let size = get(&url).body.len() as u64;
    assert!(size > 18 * MIB, "costmap.tif is {size} bytes");

    let before = settled_rss(pid);
    reset_peak(pid);
    let downloads: Vec<_> = (0..8)
        .map(|_| {
            let url = url.clone();
            std::thread::spawn(move || get(&url))
        })
        .collect();
    let replies: Vec<Reply> = downloads.into_iter().map(|t| t.join().unwrap()).collect();
    let (_, peak) = rss(pid);
    for r in &replies {
        assert_eq!(r.status, 200);
        assert_eq!(r.header("content-type"), Some("image/tiff"));
        assert_eq!(r.header("content-length"), Some(size.to_string().as_str()));
        assert_eq!(r.body, replies[0].body, "every download is the same file");
    }
    let sent = 8 * size;
    let growth = peak.saturating_sub(before);
    eprintln!(
        "8 downloads of {:.1} MiB: RSS {:.1} MiB before, peak {:.1} MiB (+{:.1} MiB)",
        size as f64 / MIB as f64,
        before as f64 / MIB as f64,
        peak as f64 / MIB as f64,
        growth as f64 / MIB as f64
    );
    assert!(
        growth < sent / 4,
        "the peak grew by {growth} bytes for {sent} bytes sent"
    );
    assert!(peak < 512 * MIB, "peak {peak} over the budget");

    // The file streamed is the costmap: GDAL reads its size.
    let out = dir.path().join("download.tif");
    std::fs::write(&out, &replies[0].body).unwrap();
    let info = gdalinfo(&out);
    assert_eq!(info["size"], json!([2000, 2000]), "{info}");
    // The class page (page 2) is there too, after the cost page.
    let class = gdalinfo(&class_page(&out));
    assert_eq!(class["bands"][0]["type"], "Byte", "{class}");
}

/// Uploads are spooled as they arrive and read one at a time when only
/// one fits the budget: six parallel 16 MB uploads all succeed, and the
/// server's peak grows by less than the budget (all six bodies at once
/// would be 96 MB, their rasters as f64 another 192 MB). Afterwards the
/// freed memory goes back to the system.
#[test]
fn parallel_uploads_are_spooled_within_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    // No parsed DEM kept: the cache's memory is apart from the budget.
    let server = Server::start(
        dir.path(),
        &["--memory-budget-mb", "96", "--dem-cache-mb", "0"],
    );
    let pid = server.pid();
    // 2000 × 2000 Float32 in strips of 16 rows: a 16 MB file; reading it
    // takes 32 MB of heights, the file twice and 16 MiB of slack: about
    // 80 MB, so only one is read at a time.
    let tiff = std::sync::Arc::new(float_tiff(2000, 2000, 32, 16, hills));
    let before = settled_rss(pid);
    reset_peak(pid);
    let started = Instant::now();
    let uploads: Vec<_> = (0..6)
        .map(|_| {
            let (url, tiff) = (server.url("/api/v1/dems?crs=EPSG:32633"), tiff.clone());
            std::thread::spawn(move || post(&url, "image/tiff", &tiff))
        })
        .collect();
    let replies: Vec<Reply> = uploads.into_iter().map(|t| t.join().unwrap()).collect();
    let (_, peak) = rss(pid);
    for r in &replies {
        assert_eq!(r.status, 201, "{}", r.text());
        let dem = r.json();
        assert_eq!(
            (dem["width"].as_u64(), dem["height"].as_u64()),
            (Some(2000), Some(2000))
        );
        assert_eq!(dem["size_bytes"].as_u64(), Some(tiff.len() as u64));
    }
    let growth = peak.saturating_sub(before);
    eprintln!(
        "6 uploads of {:.1} MiB in {:.1} s: RSS {:.1} MiB before, peak {:.1} MiB (+{:.1} MiB)",
        tiff.len() as f64 / MIB as f64,
        started.elapsed().as_secs_f64(),
        before as f64 / MIB as f64,
        peak as f64 / MIB as f64,
        growth as f64 / MIB as f64
    );
    assert!(growth < 96 * MIB, "the peak grew by {growth} bytes");

    // Stored whole: a stored DEM reads again (no cache: from its chunks),
    // its height at the centre that of the file.
    let dem = replies[0].json();
    let id = dem["id"].as_str().unwrap();
    let b = &dem["bounds_wgs84"];
    let (lon, lat) = (
        (b[0].as_f64().unwrap() + b[2].as_f64().unwrap()) / 2.0,
        (b[1].as_f64().unwrap() + b[3].as_f64().unwrap()) / 2.0,
    );
    let r = get(&server.url(&format!("/api/v1/dems/{id}/elevation?lon={lon}&lat={lat}")));
    assert_eq!(r.status, 200, "{}", r.text());
    let h = r.json()["elevation"].as_f64().unwrap();
    assert!((91.0..=109.0).contains(&h), "{h}");
    let r = get(&server.url(&format!("/api/v1/dems/{id}/hillshade.png?max_side=256")));
    assert_eq!(r.status, 200, "{}", r.text());
    // 2000 pixels reduced by whole factors to at most 256: by 8.
    assert_eq!(png_size(&r.body), (250, 250));

    // Idle again, the memory of the work is given back.
    let after = settled_rss(pid);
    eprintln!(
        "idle RSS after the uploads: {:.1} MiB",
        after as f64 / MIB as f64
    );
    assert!(
        after < before + 24 * MIB,
        "idle RSS {after} after the uploads, {before} before"
    );
    // Nothing is left in the spool.
    let spool: Vec<_> = std::fs::read_dir(dir.path().join("uploads"))
        .unwrap()
        .collect();
    assert!(spool.is_empty(), "{spool:?}");
}

/// A 1 KB TIFF declaring 8000 × 8000 Float64 pixels (within the pixel
/// limit, 64 M) needs about 1 GB to read: refused with a 413 naming the
/// numbers, before anything of that size is allocated. Work on a stored
/// DEM that alone needs more than the budget is refused with a 422.
#[test]
fn declared_size_over_the_budget_is_refused_before_reading() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--memory-budget-mb", "64"]);
    let pid = server.pid();
    let bomb = strip_tiff(8000, 8000, 64, 8000, 1, &[0u8; 1024]);
    assert!(bomb.len() < 2048);
    let before = settled_rss(pid);
    reset_peak(pid);
    let started = Instant::now();
    let r = upload(&server, &bomb);
    let (_, peak) = rss(pid);
    let p = assert_problem(&r, 413, "8000 × 8000 Float64 pixels");
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.contains("64000000")
            && detail.contains("memory budget of 64.0 MiB")
            && detail.contains("--memory-budget-mb"),
        "{detail}"
    );
    assert!(started.elapsed() < Duration::from_secs(5));
    assert!(
        peak < before + 16 * MIB,
        "the refusal grew the peak from {before} to {peak}"
    );

    // 1500 × 1500 Float32 is read (about 53 MB), but a costmap of it
    // (about 81 MB) does not fit in 64 MiB: 422 at /dem_id.
    let small = float_tiff(1500, 1500, 32, 16, hills);
    let r = upload(&server, &small);
    assert_eq!(r.status, 201, "{}", r.text());
    let dem = r.json()["id"].as_str().unwrap().to_string();
    let r = post_json(&server.url("/api/v1/costmaps"), &json!({"dem_id": dem}));
    assert_invalid_at(
        &r,
        "costmap over the budget",
        "/dem_id",
        "memory budget of 64.0 MiB",
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);
}
