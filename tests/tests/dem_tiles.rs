//! DEMs stored as tiles (issue 22 item 1), end to end against the real
//! binary on SQLite: GeoTIFFs made by `gdal_translate` in strips and in
//! tiles, uploaded and read back from their tiles (`GET …/window`) equal to
//! GDAL's read of the file, their overview level the 2×2 means; truncated
//! and corrupt uploads answered with a 4xx and nothing left in the
//! database; and the server's peak resident memory while it cuts an
//! 8000 × 8000 Float32 GeoTIFF into tiles far below the raster's size;
//! and a server killed (SIGKILL) mid-upload leaves no tiles once it is
//! started again.

#[path = "support/dem_rows.rs"]
mod dem_rows;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use dem_rows::{DemRows, dem_rows, upload_in_background};

use serde_json::Value;
use terraplan_e2e::{Server, assert_problem, get, post, run_tool, shared_data};

const MIB: u64 = 1024 * 1024;

/// `gdal_translate` `src` to `dst` with `args`.
fn translate(src: &Path, dst: &Path, args: &[&str]) {
    let mut all = vec!["-q"];
    all.extend_from_slice(args);
    all.push(src.to_str().unwrap());
    all.push(dst.to_str().unwrap());
    run_tool("gdal_translate", &all, None);
}

/// GDAL's read of `path`: (width, height, cells as f64 row-major with its
/// nodata value as NaN), through a raw Float64 copy (ENVI).
fn gdal_cells(path: &Path, dir: &Path) -> (usize, usize, Vec<f64>) {
    let info: Value = serde_json::from_str(&run_tool(
        "gdalinfo",
        &["-json", path.to_str().unwrap()],
        None,
    ))
    .unwrap();
    let (w, h) = (
        info["size"][0].as_u64().unwrap() as usize,
        info["size"][1].as_u64().unwrap() as usize,
    );
    let nodata = info["bands"][0]["noDataValue"].as_f64();
    let raw = dir.join(format!(
        "{}.f64",
        path.file_name().unwrap().to_str().unwrap()
    ));
    translate(path, &raw, &["-ot", "Float64", "-of", "ENVI"]);
    let bytes = std::fs::read(&raw).unwrap();
    assert_eq!(bytes.len(), w * h * 8);
    let cells = bytes
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .map(|v| {
            if Some(v) == nodata || !v.is_finite() {
                f64::NAN
            } else {
                v
            }
        })
        .collect();
    (w, h, cells)
}

fn upload(server: &Server, path: &Path, crs: &str) -> terraplan_e2e::Reply {
    post(
        &server.url(&format!("/api/v1/dems?crs={crs}")),
        "image/tiff",
        &std::fs::read(path).unwrap(),
    )
}

/// A window of stored DEM `id` at `level`, as f64s.
fn window(server: &Server, id: &str, level: usize, w: usize, h: usize) -> Vec<f64> {
    let r = get(&server.url(&format!(
        "/api/v1/dems/{id}/window?col=0&row=0&width={w}&height={h}&level={level}"
    )));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.body.len(), w * h * 8);
    r.body
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
        .collect()
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Rows of `dems`, `dem_tile_sets` and `dem_tiles` in the server's
/// SQLite file; no upload is left recorded as running.
fn stored_rows(data_dir: &Path) -> (u64, u64, u64) {
    let rows = dem_rows(data_dir);
    assert_eq!(rows.uploads, 0, "{rows:?}");
    (rows.dems, rows.tile_sets, rows.tiles)
}

/// The 2×2 means of the non-NaN cells (the overview rule).
fn halve(v: &[f64], w: usize, h: usize) -> Vec<f64> {
    let (w2, h2) = (w.div_ceil(2), h.div_ceil(2));
    let mut out = Vec::with_capacity(w2 * h2);
    for r in 0..h2 {
        for c in 0..w2 {
            let mut cells = Vec::new();
            for y in 2 * r..(2 * r + 2).min(h) {
                for x in 2 * c..(2 * c + 2).min(w) {
                    if !v[y * w + x].is_nan() {
                        cells.push(v[y * w + x]);
                    }
                }
            }
            out.push(if cells.is_empty() {
                f64::NAN
            } else {
                cells.iter().sum::<f64>() / cells.len() as f64
            });
        }
    }
    out
}

/// A larger raster of real terrain: `src` resampled to `w` × `h`
/// (bilinear), in GDAL's default layout plus `args`.
fn resampled(src: &Path, dst: &Path, w: usize, h: usize, args: &[&str]) -> PathBuf {
    let (ws, hs) = (w.to_string(), h.to_string());
    let mut all = vec!["-outsize", ws.as_str(), hs.as_str(), "-r", "bilinear"];
    all.extend_from_slice(args);
    translate(src, dst, &all);
    dst.to_path_buf()
}

#[test]
fn geotiffs_in_strips_and_tiles_read_back_from_their_tiles_as_gdal_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let work = tempfile::tempdir().unwrap();
    let dtm = shared_data("dems/opengeos_data__elevation_dtm.tif"); // Float32, 283 × 259
    let dsm64 = shared_data("dems/codem__AOI-DigitalSurfaceModel.tif"); // Float64, 463 × 432
    // A DEM of several tiles and overview levels: 1300 × 1100 resampled.
    let big = resampled(&dtm, &work.path().join("src1300.tif"), 1300, 1100, &[]);
    let variants: Vec<(&str, &Path, Vec<&str>)> = vec![
        ("strips of 1 row", &dtm, vec!["-co", "BLOCKYSIZE=1"]),
        (
            "Deflate strips of 3 rows, predictor 2",
            &dtm,
            vec![
                "-co",
                "COMPRESS=DEFLATE",
                "-co",
                "PREDICTOR=2",
                "-co",
                "BLOCKYSIZE=3",
            ],
        ),
        (
            "LZW tiles of 128 × 64, predictor 3",
            &big,
            vec![
                "-co",
                "TILED=YES",
                "-co",
                "BLOCKXSIZE=128",
                "-co",
                "BLOCKYSIZE=64",
                "-co",
                "COMPRESS=LZW",
                "-co",
                "PREDICTOR=3",
            ],
        ),
        (
            "Int16 PackBits tiles",
            &big,
            vec![
                "-ot",
                "Int16",
                "-co",
                "TILED=YES",
                "-co",
                "COMPRESS=PACKBITS",
            ],
        ),
        (
            "Float64 Deflate strips",
            &dsm64,
            vec!["-co", "COMPRESS=DEFLATE", "-co", "BLOCKYSIZE=16"],
        ),
        (
            "a BigTIFF in tiles",
            &big,
            vec!["-co", "BIGTIFF=YES", "-co", "TILED=YES"],
        ),
    ];
    for (i, (what, src, args)) in variants.iter().enumerate() {
        let file = work.path().join(format!("variant{i}.tif"));
        translate(src, &file, args);
        let (w, h, want) = gdal_cells(&file, work.path());
        let r = upload(&server, &file, "EPSG:32618");
        assert_eq!(r.status, 201, "{what}: {}", r.text());
        let dem = r.json();
        let id = dem["id"].as_str().unwrap();
        assert_eq!(
            (dem["width"].as_u64(), dem["height"].as_u64()),
            (Some(w as u64), Some(h as u64)),
            "{what}"
        );
        let got = window(&server, id, 0, w, h);
        for (k, (a, b)) in got.iter().zip(&want).enumerate() {
            assert!(
                same(*a, *b),
                "{what}: cell ({}, {}) is {a} from the tiles, {b} from GDAL",
                k % w,
                k / w
            );
        }
        // The download, a tiled GeoTIFF streamed from the tiles: GDAL reads
        // the same cells and georeferencing.
        let r = get(&server.url(&format!("/api/v1/dems/{id}/dem.tif")));
        assert_eq!(r.status, 200, "{what}: {}", r.text());
        assert_eq!(r.header("content-type"), Some("image/tiff"));
        let copy = work.path().join(format!("download{i}.tif"));
        std::fs::write(&copy, &r.body).unwrap();
        let (cw, ch, back) = gdal_cells(&copy, work.path());
        assert_eq!((cw, ch), (w, h), "{what}");
        for (k, (a, b)) in back.iter().zip(&want).enumerate() {
            assert!(
                same(*a, *b),
                "{what}: downloaded cell {k} is {a}, GDAL read {b}"
            );
        }
        let gt = |p: &Path| {
            let info: Value =
                serde_json::from_str(&run_tool("gdalinfo", &["-json", p.to_str().unwrap()], None))
                    .unwrap();
            info["geoTransform"].clone()
        };
        assert_eq!(gt(&copy), gt(&file), "{what}");
        // The stored statistics are the cells'.
        let valid: Vec<f64> = want.iter().copied().filter(|v| !v.is_nan()).collect();
        let min = valid.iter().copied().fold(f64::INFINITY, f64::min);
        let max = valid.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        // (JSON numbers compared within the parser's last-digit rounding.)
        let close =
            |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() <= 1e-12 * b.abs().max(1.0));
        assert!(
            close(dem["min"].as_f64(), min),
            "{what}: min {} not {min}",
            dem["min"]
        );
        assert!(
            close(dem["max"].as_f64(), max),
            "{what}: max {} not {max}",
            dem["max"]
        );
        let fraction = (want.len() - valid.len()) as f64 / want.len() as f64;
        assert!((dem["nodata_fraction"].as_f64().unwrap() - fraction).abs() < 1e-12);
        // Level 1: the 2×2 means, stored as f32 or f64 (1e-3 m covers f32
        // rounding of heights up to a few thousand metres).
        if w > 512 || h > 512 {
            let (w1, h1) = (w.div_ceil(2), h.div_ceil(2));
            let got1 = window(&server, id, 1, w1, h1);
            for (a, b) in got1.iter().zip(&halve(&want, w, h)) {
                assert!(
                    (a.is_nan() && b.is_nan()) || (a - b).abs() <= 1e-3,
                    "{what}: level 1 cell {a}, mean {b}"
                );
            }
        } else {
            let r = get(&server.url(&format!(
                "/api/v1/dems/{id}/window?col=0&row=0&width=1&height=1&level=1"
            )));
            assert_problem(&r, 400, "level 1 does not exist");
        }
        // Read whole again from its tiles for the heights and the preview.
        let r = get(&server.url(&format!("/api/v1/dems/{id}/hillshade.png?max_side=128")));
        assert_eq!(r.status, 200, "{what}: {}", r.text());
    }
    let r = get(&server.url(&format!(
        "/api/v1/dems/{}/window?col=1000&row=0&width=10&height=10",
        upload(&server, &dtm, "EPSG:32618").json()["id"]
            .as_str()
            .unwrap()
    )));
    assert_problem(&r, 400, "not inside");
}

#[test]
fn truncated_and_corrupt_uploads_are_4xx_and_store_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let work = tempfile::tempdir().unwrap();
    let dtm = shared_data("dems/opengeos_data__elevation_dtm.tif");
    // 6000 × 3000 in LZW tiles: 72 tiles of 512² before the last band, so
    // tiles are stored before the corrupt ones are met.
    let file = resampled(
        &dtm,
        &work.path().join("wide.tif"),
        6000,
        3000,
        &["-co", "TILED=YES", "-co", "COMPRESS=LZW"],
    );
    let bytes = std::fs::read(&file).unwrap();
    assert_eq!(stored_rows(dir.path()), (0, 0, 0));

    // Cut short: the tiles' offsets lie past its end.
    let short = work.path().join("short.tif");
    std::fs::write(&short, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let r = upload(&server, &short, "EPSG:32618");
    assert_problem(&r, 422, "truncated");
    assert_eq!(stored_rows(dir.path()), (0, 0, 0));

    // The last fifth of the tile data overwritten with noise: the file
    // opens, the first bands are cut and stored, then a tile does not
    // decode; what was stored is removed.
    let mut noisy = bytes.clone();
    let mut state = 0x1234_5678u32;
    let n = noisy.len();
    // (The IFD and the tile offsets are at the start: GDAL writes them first.)
    for b in &mut noisy[n * 4 / 5..n - 16] {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        *b = state as u8;
    }
    let corrupt = work.path().join("corrupt.tif");
    std::fs::write(&corrupt, &noisy).unwrap();
    let r = upload(&server, &corrupt, "EPSG:32618");
    assert!(
        r.status == 422 || r.status == 400,
        "{} {}",
        r.status,
        r.text()
    );
    assert!(r.text().contains("tile"), "{}", r.text());
    assert_eq!(stored_rows(dir.path()), (0, 0, 0));

    // The intact file is stored: one tile set, every level's tiles
    // (12 × 6, 6 × 3, 3 × 2, 2 × 1, 1).
    let r = upload(&server, &file, "EPSG:32618");
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(stored_rows(dir.path()), (1, 1, 72 + 18 + 6 + 2 + 1));
    // Deleting it deletes its tiles.
    let id = r.json()["id"].as_str().unwrap().to_string();
    let r = terraplan_e2e::delete(&server.url(&format!("/api/v1/dems/{id}")));
    assert_eq!(r.status, 204);
    assert_eq!(stored_rows(dir.path()), (0, 0, 0));
}

/// (VmRSS, VmHWM) of process `pid`, bytes.
fn rss(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap();
    let field = |name: &str| -> u64 {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .unwrap()
            .trim()
            .trim_end_matches("kB")
            .trim()
            .parse::<u64>()
            .unwrap()
            * 1024
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// An 8000 × 8000 Float32 GeoTIFF (Deflate, GDAL's default strips of one
/// row) is cut into tiles a band at a time: the server's peak resident
/// memory grows by far less than the raster's 256 MB of Float32 (its
/// heights as f64, as a whole read holds them, would be 512 MB).
#[test]
fn a_large_geotiff_is_stored_within_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--memory-budget-mb", "1024"]);
    let work = tempfile::tempdir().unwrap();
    let file = resampled(
        &shared_data("dems/opengeos_data__elevation_dtm.tif"),
        &work.path().join("big.tif"),
        8000,
        8000,
        &["-co", "COMPRESS=DEFLATE"],
    );
    let pid = server.pid();
    std::thread::sleep(std::time::Duration::from_millis(300));
    let (before, _) = rss(pid);
    // The peak from here on.
    std::fs::write(format!("/proc/{pid}/clear_refs"), "5").unwrap();
    let r = upload(&server, &file, "EPSG:32618");
    let (_, peak) = rss(pid);
    assert_eq!(r.status, 201, "{}", r.text());
    let growth = peak.saturating_sub(before);
    eprintln!(
        "8000 x 8000 Float32 ({:.1} MiB file): RSS {:.1} MiB before, peak {:.1} MiB (+{:.1} MiB)",
        std::fs::metadata(&file).unwrap().len() as f64 / MIB as f64,
        before as f64 / MIB as f64,
        peak as f64 / MIB as f64,
        growth as f64 / MIB as f64
    );
    // A band of 512 rows as f64 is 31 MiB; with the overview bands, the
    // decoded strips and the tiles in flight, well under 200 MiB.
    assert!(growth < 200 * MIB, "the peak grew by {growth} bytes");

    // A window far into the raster equals GDAL's.
    let id = r.json()["id"].as_str().unwrap().to_string();
    let crop = work.path().join("crop.tif");
    translate(&file, &crop, &["-srcwin", "5000", "6100", "300", "200"]);
    let (_, _, want) = gdal_cells(&crop, work.path());
    let r = get(&server.url(&format!(
        "/api/v1/dems/{id}/window?col=5000&row=6100&width=300&height=200"
    )));
    assert_eq!(r.status, 200, "{}", r.text());
    for (k, b) in r.body.chunks_exact(8).enumerate() {
        let a = f64::from_le_bytes(b.try_into().unwrap());
        assert!(
            same(a, want[k]),
            "cell {k}: {a} from the tiles, {} GDAL",
            want[k]
        );
    }
}

/// The download of a DEM cut into tiles (a 121 MiB tiled GeoTIFF, from a
/// 5400 × 5400 Float32 raster) is streamed a tile at a time: the server's
/// peak grows by a few tiles, not the file; GDAL reads the cells uploaded.
#[test]
fn a_large_download_is_streamed() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let work = tempfile::tempdir().unwrap();
    let file = resampled(
        &shared_data("dems/opengeos_data__elevation_dtm.tif"),
        &work.path().join("big.tif"),
        5400,
        5400,
        &["-co", "TILED=YES", "-co", "COMPRESS=DEFLATE"],
    );
    let r = upload(&server, &file, "EPSG:32618");
    assert_eq!(r.status, 201, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let pid = server.pid();
    std::thread::sleep(std::time::Duration::from_millis(300));
    let (before, _) = rss(pid);
    std::fs::write(format!("/proc/{pid}/clear_refs"), "5").unwrap();
    let r = get(&server.url(&format!("/api/v1/dems/{id}/dem.tif")));
    let (_, peak) = rss(pid);
    assert_eq!(r.status, 200, "{}", r.text());
    let growth = peak.saturating_sub(before);
    eprintln!(
        "download of {:.1} MiB: RSS {:.1} MiB before, peak {:.1} MiB (+{:.1} MiB)",
        r.body.len() as f64 / MIB as f64,
        before as f64 / MIB as f64,
        peak as f64 / MIB as f64,
        growth as f64 / MIB as f64
    );
    // 11 × 11 tiles of 1 MiB.
    assert!(r.body.len() as u64 > 121 * MIB);
    assert!(
        growth < 48 * MIB,
        "the download grew the peak by {growth} bytes"
    );
    let copy = work.path().join("download.tif");
    std::fs::write(&copy, &r.body).unwrap();
    let (crop, crop2) = (work.path().join("c1.tif"), work.path().join("c2.tif"));
    translate(&file, &crop, &["-srcwin", "4000", "4700", "700", "700"]);
    translate(&copy, &crop2, &["-srcwin", "4000", "4700", "700", "700"]);
    let (_, _, want) = gdal_cells(&crop, work.path());
    let (_, _, back) = gdal_cells(&crop2, work.path());
    for (k, (a, b)) in back.iter().zip(&want).enumerate() {
        assert!(same(*a, *b), "downloaded cell {k}: {a}, GDAL read {b}");
    }
}

/// With `--max-dem-pixels` raised, a DEM larger than the memory budget
/// can hold whole (9000 × 9000: 648 MB of heights, budget 400 MiB) is
/// stored by tiles; its preview comes from an overview level, any window
/// reads, and work that still needs it whole (a costmap) is refused with
/// a 422 naming the budget instead of allocating.
#[test]
fn a_dem_over_the_memory_budget_is_stored_and_served_by_tiles() {
    let dir = tempfile::tempdir().unwrap();
    // Costmaps are built whole up to 900 M cells here: this one would be,
    // and does not fit.
    let whole_only = [
        "--max-dem-pixels",
        "900000000",
        "--memory-budget-mb",
        "400",
        "--costmap-tile-cells",
        "900000000",
    ];
    let server = Server::start(dir.path(), &whole_only);
    let work = tempfile::tempdir().unwrap();
    let file = resampled(
        &shared_data("dems/opengeos_data__elevation_dtm.tif"),
        &work.path().join("big.tif"),
        9000,
        9000,
        &["-co", "TILED=YES", "-co", "COMPRESS=DEFLATE"],
    );
    let r = upload(&server, &file, "EPSG:32618");
    assert_eq!(r.status, 201, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();

    let r = get(&server.url(&format!("/api/v1/dems/{id}/hillshade.png?max_side=512")));
    assert_eq!(r.status, 200, "{}", r.text());
    let (w, h) = terraplan_e2e::png_size(&r.body);
    assert!(w.max(h) <= 512 && w.max(h) >= 256, "{w} × {h}");

    let r = get(&server.url(&format!(
        "/api/v1/dems/{id}/window?col=8990&row=8990&width=10&height=10"
    )));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.body.len(), 800);

    let r = terraplan_e2e::post_json(
        &server.url("/api/v1/costmaps"),
        &serde_json::json!({"dem_id": id}),
    );
    let p = assert_problem(&r, 422, "memory budget of 400 MiB (--memory-budget-mb)");
    assert!(
        p["detail"].as_str().unwrap().contains("9000 × 9000 pixels"),
        "{p}"
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);

    // With the default --costmap-tile-cells (64 M) the same costmap is
    // built as tiles, a tile's room at a time: accepted. (Deleted at once:
    // building 81 M cells takes minutes in a debug build.)
    drop(server);
    let server = Server::start(
        dir.path(),
        &["--max-dem-pixels", "900000000", "--memory-budget-mb", "400"],
    );
    let r = terraplan_e2e::post_json(
        &server.url("/api/v1/costmaps"),
        &serde_json::json!({"dem_id": id}),
    );
    assert_eq!(r.status, 202, "{}", r.text());
    let costmap = r.json()["id"].as_str().unwrap().to_string();
    let r = terraplan_e2e::delete(&server.url(&format!("/api/v1/costmaps/{costmap}")));
    assert_eq!(r.status, 204, "{}", r.text());
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// A server killed (SIGKILL) in the middle of an upload, its tiles partly
/// written, leaves them recorded as an upload running; the next server on
/// the database sweeps them at start-up, before it listens: no tile and no
/// record of the upload is left, and uploads work as before.
#[test]
fn tiles_of_an_upload_killed_mid_way_are_swept_at_the_next_start() {
    let dir = tempfile::tempdir().unwrap();
    let work = tempfile::tempdir().unwrap();
    // 6000 × 6000 Deflate strips: 144 level-0 tiles, stored 16 at a time.
    let file = resampled(
        &shared_data("dems/opengeos_data__elevation_dtm.tif"),
        &work.path().join("big.tif"),
        6000,
        6000,
        &["-co", "COMPRESS=DEFLATE"],
    );
    let server = Server::start(dir.path(), &[]);
    let sending = upload_in_background(&server, "crs=EPSG:32618", std::fs::read(&file).unwrap());
    // Until the first tiles are committed (and long before the last).
    let deadline = Instant::now() + Duration::from_secs(120);
    let during = loop {
        let rows = dem_rows(dir.path());
        if rows.tiles > 0 {
            break rows;
        }
        assert!(
            Instant::now() < deadline,
            "no tile stored in 120 s: {rows:?}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    server.kill();
    let _ = sending.join();
    let left = dem_rows(dir.path());
    assert_eq!(
        (left.dems, left.tile_sets, left.uploads),
        (0, 0, 1),
        "killed mid-upload: {left:?} (seen {during:?})"
    );
    assert!(left.tiles >= during.tiles && left.tiles < 144, "{left:?}");

    let server = Server::start(dir.path(), &[]);
    assert_eq!(dem_rows(dir.path()), DemRows::NONE);
    let r = upload(
        &server,
        &shared_data("dems/opengeos_data__elevation_dtm.tif"),
        "EPSG:32618",
    );
    assert_eq!(r.status, 201, "{}", r.text());
    assert_eq!(
        dem_rows(dir.path()),
        DemRows {
            dems: 1,
            tile_sets: 1,
            tiles: 1,
            uploads: 0
        }
    );
}
