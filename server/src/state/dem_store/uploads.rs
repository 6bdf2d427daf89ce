//! DEM uploads in progress (issue 22 item 1): an upload's tiles are
//! stored before its DEM's row, so each upload is recorded
//! (`dem_uploads`) before its first tile, held by this process under a
//! lease renewed while it runs, and its DEM's row commits with the
//! record's removal. An upload that fails is removed (tiles and record)
//! before its answer is sent; one whose process died (killed mid-upload)
//! is swept once its lease has run out, by any process on the database,
//! and a SQLite server (the only process on its file) sweeps every
//! upload it finds at start-up.
//!
//! The bytes of the tiles stored so far count in the project's storage
//! quota while the upload runs (`dem_uploads.size_bytes`), and each batch
//! of tiles is checked against the quota before it is stored.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use crate::clock::now_millis;
use crate::db::Db;
use crate::error::ApiError;
use crate::quota::Quotas;

/// Leases are renewed this many times per lease, so a late round or two
/// does not lose an upload still running.
const RENEWALS_PER_LEASE: u32 = 5;

/// One upload in progress, recorded in the database and held by this
/// process until [`UploadLease::finished`] or [`UploadLease::abandon`];
/// dropped otherwise (the client went away), its tiles and record are
/// removed in the background.
pub struct UploadLease {
    db: Db,
    dem_id: String,
    owner: String,
    lease_ms: i64,
    project_id: String,
    quotas: Quotas,
    /// Set when the record was found gone (swept: this process was taken
    /// for dead); the upload then stops.
    lost: Arc<AtomicBool>,
    renewer: tokio::task::JoinHandle<()>,
    settled: bool,
}

impl UploadLease {
    /// Record upload `dem_id` of project `project_id` as held by `owner`
    /// for `lease_ms` and renew that lease until the upload settles.
    pub async fn begin(
        db: &Db,
        dem_id: &str,
        project_id: &str,
        owner: &str,
        lease_ms: i64,
        quotas: Quotas,
    ) -> Result<UploadLease, ApiError> {
        let now = now_millis();
        db.begin_dem_upload(dem_id, Some(project_id), owner, now, now + lease_ms)
            .await?;
        let lost = Arc::new(AtomicBool::new(false));
        let renewer = tokio::spawn(renew(
            db.clone(),
            dem_id.to_string(),
            owner.to_string(),
            lease_ms,
            lost.clone(),
        ));
        Ok(UploadLease {
            db: db.clone(),
            dem_id: dem_id.to_string(),
            owner: owner.to_string(),
            lease_ms,
            project_id: project_id.to_string(),
            quotas,
            lost,
            renewer,
            settled: false,
        })
    }

    pub fn dem_id(&self) -> &str {
        &self.dem_id
    }

    pub fn owner(&self) -> &str {
        &self.owner
    }

    /// The lease's end if renewed now, ms.
    pub fn lease_until(&self) -> i64 {
        now_millis() + self.lease_ms
    }

    /// 503 when the upload's record was swept (this process was taken for
    /// dead): what it stores from now on would be stored for nothing.
    pub fn check_held(&self) -> Result<(), ApiError> {
        if self.lost.load(Ordering::Relaxed) {
            return Err(swept_error());
        }
        Ok(())
    }

    /// 413 when storing `adding` more bytes of tiles would take the
    /// project past its storage quota (the upload's tiles stored so far
    /// are counted in its usage, `so_far` of them).
    pub async fn check_quota(&self, so_far: u64, adding: u64) -> Result<(), ApiError> {
        if self.quotas.bytes.is_none() {
            return Ok(());
        }
        let usage = self.quotas.usage(&self.db, &self.project_id).await?;
        usage.check_tiles(&self.project_id, so_far, adding)
    }

    /// 413 when storing the uploaded file too (`file_bytes`, kept for an
    /// ESRI grid or `.hgt` file) would take the project past its quota;
    /// the upload's tiles are counted in its usage.
    pub async fn check_file_quota(&self, file_bytes: u64) -> Result<(), ApiError> {
        if self.quotas.bytes.is_none() || file_bytes == 0 {
            return Ok(());
        }
        let usage = self.quotas.usage(&self.db, &self.project_id).await?;
        usage.check_bytes(
            &self.project_id,
            file_bytes,
            "the DEM file, kept with its tiles",
        )
    }

    /// The DEM's row committed (with the record's removal).
    pub fn finished(mut self) {
        self.settled = true;
    }

    /// The upload failed: its tiles and record are removed before this
    /// returns (so its answer is sent with nothing of it left).
    pub async fn abandon(mut self) {
        self.settled = true;
        self.renewer.abort();
        if let Err(e) = self.db.abandon_dem_upload(&self.dem_id).await {
            tracing::warn!(dem_id = self.dem_id, error = %e,
                "the tiles of a failed upload were not deleted: they are swept once its lease runs out");
        }
    }
}

impl Drop for UploadLease {
    fn drop(&mut self) {
        self.renewer.abort();
        if self.settled {
            return;
        }
        // Dropped mid-upload (the client went away): the handler cannot
        // wait, so the tiles go in the background.
        let (db, id) = (self.db.clone(), std::mem::take(&mut self.dem_id));
        if let Ok(rt) = tokio::runtime::Handle::try_current() {
            rt.spawn(async move {
                if let Err(e) = db.abandon_dem_upload(&id).await {
                    tracing::warn!(dem_id = id, error = %e,
                        "the tiles of a dropped upload were not deleted: they are swept once its lease runs out");
                }
            });
        }
    }
}

/// The answer to an upload whose record was swept under it.
pub fn swept_error() -> ApiError {
    ApiError::Unavailable(
        "the upload's lease ran out (the server could not renew it in time: is the database \
         overloaded?) and what it stored was swept: send it again"
            .into(),
    )
}

/// Renew the lease on upload `dem_id` a few times per lease until the
/// task is aborted, or the record is found gone (then `lost` is set).
async fn renew(db: Db, dem_id: String, owner: String, lease_ms: i64, lost: Arc<AtomicBool>) {
    let every = Duration::from_millis(lease_ms.unsigned_abs()) / RENEWALS_PER_LEASE;
    let mut tick = tokio::time::interval(every);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    tick.tick().await;
    loop {
        tick.tick().await;
        match db
            .renew_dem_upload(&dem_id, &owner, now_millis() + lease_ms)
            .await
        {
            Ok(true) => {}
            Ok(false) => {
                lost.store(true, Ordering::Relaxed);
                return;
            }
            Err(e) => tracing::warn!(dem_id, error = %e, "cannot renew a DEM upload's lease"),
        }
    }
}

/// At start-up: sweep the uploads whose lease ran out (every upload on
/// SQLite, where this is the only process), and tiles of no DEM and no
/// upload; how many uploads were swept.
pub async fn sweep_at_start(db: &Db) -> Result<usize, sqlx::Error> {
    let every = db.backend() == "sqlite";
    let swept = db.sweep_dem_uploads(now_millis(), every).await?;
    for id in &swept {
        tracing::info!(
            dem_id = id,
            "swept the tiles of an upload that did not finish"
        );
    }
    let unowned = db.sweep_unowned_dem_tiles().await?;
    for id in &unowned {
        tracing::info!(dem_id = id, "swept tiles of no DEM and no upload");
    }
    Ok(swept.len() + unowned.len())
}

/// Sweep the uploads whose lease ran out (their process died: on
/// PostgreSQL another replica's) every `every`, for as long as the
/// runtime runs.
pub fn start_sweeping(db: Db, every: Duration) {
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(every.max(Duration::from_millis(100)));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        tick.tick().await;
        loop {
            tick.tick().await;
            match db.sweep_dem_uploads(now_millis(), false).await {
                Ok(swept) => {
                    for id in swept {
                        tracing::info!(
                            dem_id = id,
                            "swept the tiles of an upload whose lease ran out"
                        );
                    }
                }
                Err(e) => tracing::warn!(error = %e, "cannot sweep abandoned DEM uploads"),
            }
        }
    });
}
