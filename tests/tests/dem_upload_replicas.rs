//! DEM uploads on replicas sharing PostgreSQL (issue 22 item 1): an upload
//! running on one replica is never swept by another (its lease is
//! renewed), and the tiles of one whose replica is killed (SIGKILL)
//! mid-way are swept by a replica still running once its lease has run
//! out. Needs PostgreSQL (`TERRAPLAN_TEST_DATABASE_URL`, as
//! scripts/test.sh sets it); skipped without.

#[path = "support/dem_rows.rs"]
mod dem_rows;

use std::time::Duration;

use dem_rows::upload_in_background_to;
use terraplan_e2e::replicas::{Replica, Role, TestDatabase, wait_until};
use terraplan_e2e::{get, run_tool, shared_data};

/// Short leases (s), so the test waits seconds, not minutes.
const LEASE_S: &str = "1";
const WAIT: Duration = Duration::from_secs(120);

fn start(name: &str, db: &TestDatabase) -> Replica {
    Replica::start(name, Role::Serve, &db.url, &["--job-lease-s", LEASE_S])
}

/// (tiles, upload records) in the database.
fn counts(db: &TestDatabase) -> (u64, u64) {
    let rows = db.query(
        "SELECT (SELECT COUNT(*) FROM dem_tiles), (SELECT COUNT(*) FROM dem_uploads), \
         (SELECT COUNT(*) FROM dems)",
    );
    let n: Vec<u64> = rows[0].iter().map(|v| v.parse().unwrap()).collect();
    assert_eq!(n[2], 0, "no DEM is stored by an upload cut short");
    (n[0], n[1])
}

#[test]
fn a_killed_replicas_upload_is_swept_by_another_and_a_running_one_is_not() {
    let Some(db) = TestDatabase::create("dem_upload_replicas") else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    // 6000 × 6000 Deflate strips: seconds of cutting in a debug build,
    // 144 level-0 tiles.
    let file = work.path().join("big.tif");
    run_tool(
        "gdal_translate",
        &[
            "-q",
            "-outsize",
            "6000",
            "6000",
            "-r",
            "bilinear",
            "-co",
            "COMPRESS=DEFLATE",
            shared_data("dems/opengeos_data__elevation_dtm.tif")
                .to_str()
                .unwrap(),
            file.to_str().unwrap(),
        ],
        None,
    );
    let mut a = start("a", &db);
    let token = wait_until(WAIT, "the first start's token", || {
        a.stdout_lines().iter().find_map(|l| {
            l.split("Bearer ")
                .nth(1)
                .map(|t| t.trim_end_matches('"').trim().to_string())
        })
    });
    a.use_token(&token);
    let b = start("b", &db);
    b.use_token(&token);

    let _sending = upload_in_background_to(
        &a.base,
        &format!("Authorization: Bearer {token}\r\n"),
        "crs=EPSG:32618",
        std::fs::read(&file).unwrap(),
    );
    let first = wait_until(WAIT, "the upload's first tiles", || {
        let (tiles, uploads) = counts(&db);
        (tiles > 0).then_some((tiles, uploads))
    });
    assert_eq!(first.1, 1);
    let lease = || -> i64 {
        db.query("SELECT lease_until FROM dem_uploads")[0][0]
            .parse()
            .unwrap()
    };
    let before = lease();
    // Three leases later the upload still runs on a: its lease renewed,
    // b's sweeps (every lease) left it alone.
    std::thread::sleep(Duration::from_secs(3));
    let (tiles, uploads) = counts(&db);
    assert_eq!(uploads, 1, "the running upload was swept");
    assert!(tiles >= first.0, "{tiles} tiles");
    let after = lease();
    assert!(
        after >= before + 1000,
        "the lease was not renewed: {before} then {after}"
    );
    assert!(
        b.logged(&["swept"]).is_empty(),
        "{:?}",
        b.logged(&["swept"])
    );

    a.kill();
    // b sweeps it once its lease (1 s) has run out.
    wait_until(WAIT, "the killed upload swept", || {
        (counts(&db) == (0, 0)).then_some(())
    });
    let swept = b.logged(&["swept the tiles of an upload whose lease ran out"]);
    assert_eq!(swept.len(), 1, "{swept:?}");
    assert_eq!(get(&b.url("/healthz")).status, 200);
}
