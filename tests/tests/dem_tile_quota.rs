//! DEM tiles in the project storage quota (issue 22 item 1): a DEM counts
//! by its stored tiles (compressed, overviews included) and the file kept
//! with them (an ESRI grid's; a GeoTIFF's is not kept); an upload whose
//! file fits the quota but whose tiles do not is refused with a 413 while
//! its tiles are written, and leaves nothing stored.

#[path = "support/dem_rows.rs"]
mod dem_rows;

use std::path::Path;

use dem_rows::{DemRows, dem_rows};
use serde_json::Value;
use terraplan_e2e::{Server, assert_problem, get, post, run_tool, shared_data};

const MIB: u64 = 1024 * 1024;

fn personal_project(server: &Server) -> String {
    get(&server.url("/api/v1/session")).json()["personal_project_id"]
        .as_str()
        .expect("personal project")
        .to_string()
}

fn stored_bytes(server: &Server, project: &str) -> u64 {
    let p = get(&server.url(&format!("/api/v1/projects/{project}"))).json();
    p["usage"]["stored_bytes"].as_u64().unwrap()
}

/// (tile set's size_bytes, sum of its tiles' lengths) of DEM `id`.
fn tile_bytes(data_dir: &Path, id: &str) -> (u64, u64) {
    let out = run_tool(
        "python3",
        &[
            "-c",
            "import sqlite3, sys\n\
             c = sqlite3.connect('file:' + sys.argv[1] + '?mode=ro', uri=True)\n\
             print(c.execute('SELECT size_bytes FROM dem_tile_sets WHERE dem_id = ?', \
                             (sys.argv[2],)).fetchone()[0],\n\
                   c.execute('SELECT SUM(length(data)) FROM dem_tiles WHERE dem_id = ?', \
                             (sys.argv[2],)).fetchone()[0])",
            data_dir.join("terraplan.sqlite3").to_str().unwrap(),
            id,
        ],
        None,
    );
    let n: Vec<u64> = out.split_whitespace().map(|v| v.parse().unwrap()).collect();
    (n[0], n[1])
}

fn upload(server: &Server, body: &[u8], query: &str) -> terraplan_e2e::Reply {
    post(
        &server.url(&format!("/api/v1/dems?{query}")),
        "image/tiff",
        body,
    )
}

#[test]
fn dems_count_by_their_tiles_and_kept_files_and_tiles_past_the_quota_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let work = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--project-quota-mb", "16"]);
    let project = personal_project(&server);
    assert_eq!(stored_bytes(&server, &project), 0);

    // A GeoTIFF: its tiles count, not its file (which is not kept).
    let dtm = std::fs::read(shared_data("dems/opengeos_data__elevation_dtm.tif")).unwrap();
    let r = upload(&server, &dtm, "crs=EPSG:32618");
    assert_eq!(r.status, 201, "{}", r.text());
    let tif_id = r.json()["id"].as_str().unwrap().to_string();
    let (set_bytes, tiles) = tile_bytes(dir.path(), &tif_id);
    assert_eq!(set_bytes, tiles);
    assert_eq!(stored_bytes(&server, &project), tiles);

    // An ESRI grid: its tiles and its file, kept with them.
    let asc = std::fs::read(shared_data("dems/landlab__pre_runout_DEM.asc")).unwrap();
    let r = post(
        &server.url("/api/v1/dems?crs=EPSG:32613"),
        "text/plain",
        &asc,
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let asc_id = r.json()["id"].as_str().unwrap().to_string();
    let (asc_set, asc_tiles) = tile_bytes(dir.path(), &asc_id);
    assert_eq!(asc_set, asc_tiles);
    let before = stored_bytes(&server, &project);
    assert_eq!(before, tiles + asc_tiles + asc.len() as u64);
    let rows_before = dem_rows(dir.path());
    assert_eq!(
        rows_before,
        DemRows {
            dems: 2,
            tile_sets: 2,
            tiles: 2,
            uploads: 0
        }
    );

    // 3000 × 3000 Float32 with GDAL's floating-point predictor: an 8.7 MB
    // file, under what is left of 16 MiB, but about 26 MB of tiles (zlib
    // without a predictor) before its overviews: refused while its tiles
    // are written (after the first batch of 16), with nothing kept.
    let big = work.path().join("big.tif");
    run_tool(
        "gdal_translate",
        &[
            "-q",
            "-outsize",
            "3000",
            "3000",
            "-r",
            "bilinear",
            "-co",
            "COMPRESS=DEFLATE",
            "-co",
            "PREDICTOR=3",
            "-co",
            "ZLEVEL=9",
            shared_data("dems/opengeos_data__elevation_dtm.tif")
                .to_str()
                .unwrap(),
            big.to_str().unwrap(),
        ],
        None,
    );
    let body = std::fs::read(&big).unwrap();
    assert!((body.len() as u64) + before < 16 * MIB, "{}", body.len());
    let r = upload(&server, &body, "crs=EPSG:32618");
    let p: Value = assert_problem(&r, 413, "--project-quota-mb");
    let detail = p["detail"].as_str().unwrap();
    assert!(detail.contains("the DEM's tiles"), "{detail}");
    assert!(detail.contains(&project), "{detail}");
    assert!(detail.contains("16.0 MiB quota"), "{detail}");
    assert!(
        detail.contains("nothing of this upload was kept"),
        "{detail}"
    );
    assert_eq!(dem_rows(dir.path()), rows_before);
    assert_eq!(stored_bytes(&server, &project), before);

    // With room for it (another project quota), the same file is stored,
    // and counts by its tiles, more than its file.
    drop(server);
    let server = Server::start(dir.path(), &["--project-quota-mb", "64"]);
    let r = upload(&server, &body, "crs=EPSG:32618");
    assert_eq!(r.status, 201, "{}", r.text());
    let id = r.json()["id"].as_str().unwrap().to_string();
    let (set_bytes, big_tiles) = tile_bytes(dir.path(), &id);
    assert_eq!(set_bytes, big_tiles);
    assert!(big_tiles > 16 * MIB, "{big_tiles}");
    eprintln!(
        "3000 x 3000 Float32: file {} bytes, tiles {big_tiles} bytes",
        body.len()
    );
    assert_eq!(stored_bytes(&server, &project), before + big_tiles);
    // Deleting a DEM gives its bytes back.
    let r = terraplan_e2e::delete(&server.url(&format!("/api/v1/dems/{asc_id}")));
    assert_eq!(r.status, 204);
    assert_eq!(stored_bytes(&server, &project), tiles + big_tiles);
}
