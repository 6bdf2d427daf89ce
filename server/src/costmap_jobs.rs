//! The costmap job runner: costmaps are built in the background, at most
//! `--costmap-jobs` at a time, the rest wait their turn (status `queued`).
//!
//! The database is the record of every job. A job is held by one server
//! process (`owner`) under a lease the holder renews every few seconds;
//! a job whose holder died (its lease ran out) is taken over and run
//! again by another server, or by the next one to start. At start-up on
//! SQLite (one server per database) every unfinished job is taken over at
//! once. A run writes its stage to the database when it changes; live
//! progress lives in memory, one [`watch`] channel per job, for `GET` and
//! the event stream. A result is stored with its files in one transaction
//! (never half-written); a failure stores its reason. On shutdown the
//! runs are cancelled and their jobs given back, queued, for the next
//! server.

use std::collections::HashMap;
use std::io::Cursor;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use planner_core::costmap::{
    Costmap, CostmapError, CostmapOptions, CostmapStats, Layer, ResolvedParams, Stage, Vehicle,
    build_costmap, legend_svg, preview_png,
};
use planner_core::terrain::{Crs, Dem};
use serde::{Deserialize, Serialize};
use tokio::sync::{Notify, Semaphore, watch};
use utoipa::ToSchema;

use crate::app::AppState;
use crate::db::{CostmapFileRow, CostmapRow, Db};
use crate::error::ApiError;

/// How long a claim on a job lasts unless renewed, ms.
pub const LEASE_MS: i64 = 15_000;
/// How often leases are renewed and orphaned jobs looked for.
const MAINTENANCE_EVERY: Duration = Duration::from_secs(3);
/// Runs a job may start; one interrupted more often (its server killed
/// each time) is failed rather than run again.
pub const MAX_ATTEMPTS: i64 = 3;
/// Longest side of the stored preview image, pixels.
pub const PREVIEW_MAX_SIDE: usize = 1024;
/// How long shutdown waits for the runs to stop.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

pub const COSTMAP_TIF: &str = "costmap.tif";
pub const PREVIEW_PNG: &str = "preview.png";
pub const LEGEND_SVG: &str = "legend.svg";

/// The stored name of a layer's file.
pub fn layer_file(layer: Layer) -> String {
    format!("layers/{}.tif", layer.name())
}

pub fn now_millis() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// Where a job stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    /// Waiting for a free slot (`--costmap-jobs`).
    Queued,
    Running,
    /// Finished: the files are ready.
    Done,
    /// Stopped by an error (see `error`).
    Failed,
}

impl JobStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Done => "done",
            JobStatus::Failed => "failed",
        }
    }

    pub fn parse(s: &str) -> Option<JobStatus> {
        [
            JobStatus::Queued,
            JobStatus::Running,
            JobStatus::Done,
            JobStatus::Failed,
        ]
        .into_iter()
        .find(|j| j.as_str() == s)
    }

    pub fn is_finished(self) -> bool {
        matches!(self, JobStatus::Done | JobStatus::Failed)
    }
}

/// A stage's name as stored (its serde name).
pub fn stage_name(stage: Stage) -> String {
    serde_json::to_value(stage)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

pub fn parse_stage(name: &str) -> Option<Stage> {
    serde_json::from_value(serde_json::Value::String(name.to_string())).ok()
}

/// A job's progress as it happens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Live {
    pub status: JobStatus,
    /// [0, 1].
    pub progress: f64,
    pub stage: Option<Stage>,
}

/// What a finished job found, stored as JSON with status done.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CostmapResult {
    pub vehicle: Vehicle,
    pub params: ResolvedParams,
    pub stats: CostmapStats,
    pub warnings: Vec<String>,
    pub width: usize,
    pub height: usize,
    pub crs: Crs,
    /// The layers kept, each with a file.
    pub layers: Vec<Layer>,
}

/// What a job was asked for, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StoredRequest {
    /// The vehicle as given (preset and overrides); `null` for the default.
    pub vehicle: serde_json::Value,
    pub options: CostmapOptions,
}

/// One job this process holds.
struct JobHandle {
    live: watch::Sender<Live>,
    /// Set by `DELETE` (and shutdown): the run stops at its next report.
    cancel: AtomicBool,
    /// Wakes a queued job that was cancelled.
    cancelled: Notify,
}

impl JobHandle {
    fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
        self.cancelled.notify_one();
    }
}

/// The costmap jobs of this server process.
pub struct CostmapJobs {
    /// This process' name as a job holder.
    instance: String,
    slots: Arc<Semaphore>,
    jobs: Mutex<HashMap<String, Arc<JobHandle>>>,
    shutdown: watch::Sender<bool>,
    /// Job tasks alive.
    active: watch::Sender<usize>,
}

/// Counts a job task as alive while it exists.
struct ActiveGuard<'a>(&'a watch::Sender<usize>);

impl Drop for ActiveGuard<'_> {
    fn drop(&mut self) {
        self.0.send_modify(|n| *n = n.saturating_sub(1));
    }
}

impl CostmapJobs {
    /// A runner of at most `max_jobs` (≥ 1) builds at once.
    pub fn new(max_jobs: usize) -> CostmapJobs {
        CostmapJobs {
            instance: uuid::Uuid::new_v4().to_string(),
            slots: Arc::new(Semaphore::new(max_jobs.max(1))),
            jobs: Mutex::new(HashMap::new()),
            shutdown: watch::Sender::new(false),
            active: watch::Sender::new(0),
        }
    }

    /// This process' name as a job holder.
    pub fn instance(&self) -> &str {
        &self.instance
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Arc<JobHandle>>> {
        // The map guards no invariant a panic could break half-way.
        self.jobs.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Live progress of a job this process holds.
    pub fn live(&self, id: &str) -> Option<Live> {
        self.lock().get(id).map(|h| *h.live.borrow())
    }

    /// Follow the live progress of a job this process holds; the channel
    /// closes once the job's outcome is in the database.
    pub fn subscribe(&self, id: &str) -> Option<watch::Receiver<Live>> {
        self.lock().get(id).map(|h| h.live.subscribe())
    }

    /// Stop a job this process holds (queued or running).
    pub fn cancel(&self, id: &str) {
        if let Some(h) = self.lock().get(id) {
            h.cancel();
        }
    }

    /// True once shutdown has begun; see [`CostmapJobs::shutdown_signal`].
    pub fn is_shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    /// Resolves when shutdown begins.
    pub fn shutdown_signal(&self) -> impl Future<Output = ()> + Send + 'static {
        let mut rx = self.shutdown.subscribe();
        async move {
            let _ = rx.wait_for(|s| *s).await;
        }
    }

    /// Stop taking work: cancel every run and end the event streams.
    pub fn begin_shutdown(&self) {
        self.shutdown.send_replace(true);
        for h in self.lock().values() {
            h.cancel();
        }
    }

    /// After [`CostmapJobs::begin_shutdown`]: wait (briefly) for the runs
    /// to stop, then give back every job still held, queued for the next
    /// server.
    pub async fn finish(&self, db: &Db) {
        let mut active = self.active.subscribe();
        if tokio::time::timeout(SHUTDOWN_GRACE, active.wait_for(|n| *n == 0))
            .await
            .is_err()
        {
            tracing::warn!("costmap runs still busy at shutdown: their jobs are given back");
        }
        match db
            .release_costmaps(&self.instance, None, now_millis())
            .await
        {
            Ok(0) => {}
            Ok(n) => tracing::info!(jobs = n, "costmap jobs given back for the next start"),
            Err(e) => tracing::warn!(error = %e, "cannot give back the costmap jobs"),
        }
    }

    /// Hold job `id` (stored, queued, owned by this process) and run it
    /// when a slot is free.
    pub fn enqueue(&self, state: &AppState, id: &str) {
        let handle = Arc::new(JobHandle {
            live: watch::Sender::new(Live {
                status: JobStatus::Queued,
                progress: 0.0,
                stage: None,
            }),
            cancel: AtomicBool::new(false),
            cancelled: Notify::new(),
        });
        if self.is_shutting_down() {
            handle.cancel();
        }
        self.lock().insert(id.to_string(), handle.clone());
        self.active.send_modify(|n| *n += 1);
        let state = state.clone();
        let id = id.to_string();
        tokio::spawn(async move {
            let jobs = state.costmaps.clone();
            let _active = ActiveGuard(&jobs.active);
            run_job(&state, &id, &handle).await;
            let mut map = jobs.lock();
            if map.get(&id).is_some_and(|h| Arc::ptr_eq(h, &handle)) {
                map.remove(&id);
            }
        });
    }

    /// Take over the unfinished jobs nobody holds (leases ended before
    /// `expired_before`) and queue them here.
    pub async fn adopt_orphans(&self, state: &AppState, expired_before: i64) -> usize {
        let ids = match state.db.orphaned_costmaps(expired_before).await {
            Ok(ids) => ids,
            Err(e) => {
                tracing::warn!(error = %e, "cannot look for orphaned costmap jobs");
                return 0;
            }
        };
        let mut adopted = 0;
        for id in ids {
            if self.is_shutting_down() {
                break;
            }
            let now = now_millis();
            match state
                .db
                .adopt_costmap(&id, &self.instance, expired_before, now, now + LEASE_MS)
                .await
            {
                Ok(true) => {
                    tracing::info!(costmap = %id, "costmap job taken over and queued again");
                    self.enqueue(state, &id);
                    adopted += 1;
                }
                Ok(false) => {}
                Err(e) => {
                    tracing::warn!(costmap = %id, error = %e, "cannot take over a costmap job")
                }
            }
        }
        adopted
    }

    /// At start-up: queue again every job a previous server left queued
    /// or running. On SQLite the database is this server's alone, so every
    /// unfinished job is taken over at once; on PostgreSQL other servers
    /// may share it, so only jobs whose holder's lease ran out (the rest
    /// are taken over by the maintenance loop when theirs does).
    pub async fn recover(&self, state: &AppState) -> usize {
        let expired_before = match state.db {
            Db::Sqlite(_) => i64::MAX,
            Db::Postgres(_) => now_millis(),
        };
        self.adopt_orphans(state, expired_before).await
    }

    /// Renew this process' leases and take over orphaned jobs, every few
    /// seconds until shutdown.
    pub fn start_maintenance(&self, state: &AppState) {
        let state = state.clone();
        let stop = self.shutdown_signal();
        tokio::spawn(async move {
            let jobs = state.costmaps.clone();
            let work = async {
                let mut tick = tokio::time::interval(MAINTENANCE_EVERY);
                tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                loop {
                    tick.tick().await;
                    if let Err(e) = state
                        .db
                        .renew_costmap_leases(&jobs.instance, now_millis() + LEASE_MS)
                        .await
                    {
                        tracing::warn!(error = %e, "cannot renew the costmap job leases");
                    }
                    jobs.adopt_orphans(&state, now_millis()).await;
                }
            };
            tokio::select! {
                () = work => {},
                () = stop => {},
            }
        });
    }
}

/// How a run ended.
enum Outcome {
    Built(Box<Built>),
    /// Cancelled: deleted, taken over, or shutdown.
    Cancelled,
    Failed(String),
}

/// A finished costmap, encoded for storage.
struct Built {
    result: String,
    files: Vec<CostmapFileRow>,
}

async fn run_job(state: &AppState, id: &str, handle: &Arc<JobHandle>) {
    let jobs = &state.costmaps;
    let owner = jobs.instance.clone();
    let permit = tokio::select! {
        p = jobs.slots.clone().acquire_owned() => p.ok(),
        () = jobs.shutdown_signal() => None,
        () = handle.cancelled.notified() => None,
    };
    let Some(_permit) = permit.filter(|_| !handle.is_cancelled()) else {
        if jobs.is_shutting_down() {
            give_back(state, id).await;
        }
        return;
    };
    let now = now_millis();
    let row = match state
        .db
        .claim_costmap(id, &owner, now, now + LEASE_MS)
        .await
    {
        Ok(Some(row)) => row,
        // Deleted, or no longer ours.
        Ok(None) => return,
        Err(e) => {
            tracing::error!(costmap = %id, error = %e, "cannot start a costmap job");
            return;
        }
    };
    handle.live.send_replace(Live {
        status: JobStatus::Running,
        progress: 0.0,
        stage: None,
    });
    tracing::info!(costmap = %id, dem = %row.dem_id, attempt = row.attempts, "costmap job started");
    let started = std::time::Instant::now();
    let outcome = if row.attempts > MAX_ATTEMPTS {
        Outcome::Failed(format!(
            "the job was interrupted {} times (its server stopped while it ran) and is not \
             tried again",
            row.attempts - 1
        ))
    } else {
        build(state, &row, handle).await
    };
    let now = now_millis();
    match outcome {
        Outcome::Built(built) => {
            match state
                .db
                .finish_costmap(id, &owner, &built.result, &built.files, now)
                .await
            {
                Ok(true) => tracing::info!(
                    costmap = %id,
                    seconds = started.elapsed().as_secs_f64(),
                    "costmap job done"
                ),
                Ok(false) => {
                    tracing::info!(costmap = %id, "costmap finished after it was deleted or taken over: discarded")
                }
                Err(e) => {
                    tracing::error!(costmap = %id, error = %e, "cannot store a costmap");
                    fail(state, id, &format!("the result could not be stored: {e}")).await;
                }
            }
        }
        Outcome::Cancelled => {
            if jobs.is_shutting_down() {
                give_back(state, id).await;
            } else {
                tracing::info!(costmap = %id, "costmap job cancelled");
            }
        }
        Outcome::Failed(message) => {
            tracing::warn!(costmap = %id, error = %message, "costmap job failed");
            fail(state, id, &message).await;
        }
    }
}

async fn fail(state: &AppState, id: &str, message: &str) {
    if let Err(e) = state
        .db
        .fail_costmap(id, &state.costmaps.instance, message, now_millis())
        .await
    {
        tracing::error!(costmap = %id, error = %e, "cannot record a costmap job's failure");
    }
}

/// Give a job back, queued, for whichever server runs next (at shutdown).
async fn give_back(state: &AppState, id: &str) {
    if let Err(e) = state
        .db
        .release_costmaps(&state.costmaps.instance, Some(id), now_millis())
        .await
    {
        tracing::warn!(costmap = %id, error = %e, "cannot give back a costmap job");
    }
}

/// The DEM a job needs, or why the job cannot run.
async fn job_dem(state: &AppState, id: &str, what: &str) -> Result<Arc<Dem>, String> {
    state.load_dem(id).await.map_err(|e| match e {
        ApiError::NotFound(_) => format!(
            "the {what} (DEM {id:?}) was deleted before the costmap was built: upload it again \
             and ask for a new costmap"
        ),
        ApiError::Internal(m) => format!("the {what} (DEM {id:?}) cannot be read: {m}"),
        other => format!("the {what} (DEM {id:?}) cannot be loaded: {other}"),
    })
}

async fn build(state: &AppState, row: &CostmapRow, handle: &Arc<JobHandle>) -> Outcome {
    let request: StoredRequest = match serde_json::from_str(&row.request) {
        Ok(r) => r,
        Err(e) => return Outcome::Failed(format!("the stored request is unreadable: {e}")),
    };
    let vehicle: Vehicle = match serde_json::from_str(&row.vehicle) {
        Ok(v) => v,
        Err(e) => return Outcome::Failed(format!("the stored vehicle is unreadable: {e}")),
    };
    let options = request.options;
    let dem = match job_dem(state, &row.dem_id, "DEM").await {
        Ok(d) => d,
        Err(m) => return Outcome::Failed(m),
    };
    let landcover = match &options.landcover {
        None => None,
        Some(l) => match job_dem(state, &l.source, "land-cover raster").await {
            Ok(d) => Some(d),
            Err(m) => return Outcome::Failed(m),
        },
    };
    if handle.is_cancelled() {
        return Outcome::Cancelled;
    }

    // Persist stage changes (not every report) while the build runs.
    let monitor = {
        let db = state.db.clone();
        let id = row.id.clone();
        let owner = state.costmaps.instance.clone();
        let mut rx = handle.live.subscribe();
        let handle = handle.clone();
        tokio::spawn(async move {
            let mut stored: Option<Stage> = None;
            while rx.changed().await.is_ok() {
                let live = *rx.borrow_and_update();
                if live.stage.is_none() || live.stage == stored {
                    continue;
                }
                stored = live.stage;
                let stage = live.stage.map(stage_name);
                match db
                    .set_costmap_progress(
                        &id,
                        &owner,
                        live.progress,
                        stage.as_deref(),
                        now_millis(),
                    )
                    .await
                {
                    Ok(true) => {}
                    // Deleted, or taken over by another server: stop.
                    Ok(false) => handle.cancel(),
                    Err(e) => {
                        tracing::warn!(costmap = %id, error = %e, "cannot record a costmap job's stage")
                    }
                }
            }
        })
    };

    let reporter = handle.clone();
    let task = tokio::task::spawn_blocking(move || {
        let progress = move |stage: Stage, done: f64| -> bool {
            if reporter.is_cancelled() {
                return false;
            }
            let done = if done.is_finite() {
                done.clamp(0.0, 1.0)
            } else {
                0.0
            };
            reporter.live.send_if_modified(|l| {
                let changed = l.stage != Some(stage) || (done - l.progress).abs() >= 0.005;
                if changed {
                    l.stage = Some(stage);
                    l.progress = done;
                }
                changed
            });
            true
        };
        let costmap = build_costmap(&dem, &vehicle, &options, landcover.as_deref(), &progress);
        match costmap {
            Ok(c) => encode(&c).map(|b| Outcome::Built(Box::new(b))),
            Err(CostmapError::Cancelled) => Ok(Outcome::Cancelled),
            Err(CostmapError::Invalid(issues)) => Ok(Outcome::Failed(format!(
                "the costmap cannot be built with these parameters: {}",
                issues
                    .iter()
                    .map(ToString::to_string)
                    .collect::<Vec<_>>()
                    .join("; ")
            ))),
        }
    });
    let outcome = match task.await {
        Ok(Ok(outcome)) => outcome,
        Ok(Err(e)) => Outcome::Failed(format!("the costmap files could not be written: {e}")),
        Err(e) if e.is_panic() => {
            let payload = e.into_panic();
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".to_string());
            Outcome::Failed(format!(
                "internal error: the costmap builder panicked ({what}); this is a bug, please \
                 report it"
            ))
        }
        Err(_) => Outcome::Cancelled,
    };
    monitor.abort();
    outcome
}

/// The files and the result document of a finished costmap.
fn encode(costmap: &Costmap) -> std::io::Result<Built> {
    let mut files = Vec::new();
    let mut tif = Cursor::new(Vec::new());
    costmap.write_geotiff(&mut tif)?;
    files.push(CostmapFileRow {
        name: COSTMAP_TIF.to_string(),
        content_type: "image/tiff".to_string(),
        data: tif.into_inner(),
    });
    files.push(CostmapFileRow {
        name: PREVIEW_PNG.to_string(),
        content_type: "image/png".to_string(),
        data: preview_png(costmap, PREVIEW_MAX_SIDE),
    });
    files.push(CostmapFileRow {
        name: LEGEND_SVG.to_string(),
        content_type: "image/svg+xml".to_string(),
        data: legend_svg(costmap).into_bytes(),
    });
    let mut layers = Vec::new();
    for (layer, _) in &costmap.layers {
        let mut tif = Cursor::new(Vec::new());
        if costmap.write_layer_geotiff(*layer, &mut tif)? {
            layers.push(*layer);
            files.push(CostmapFileRow {
                name: layer_file(*layer),
                content_type: "image/tiff".to_string(),
                data: tif.into_inner(),
            });
        }
    }
    let result = CostmapResult {
        vehicle: costmap.vehicle.clone(),
        params: costmap.params.clone(),
        stats: costmap.stats.clone(),
        warnings: costmap.warnings.clone(),
        width: costmap.width,
        height: costmap.height,
        crs: costmap.crs.clone(),
        layers,
    };
    let result = serde_json::to_string(&result).map_err(std::io::Error::other)?;
    Ok(Built { result, files })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_and_stage_names() {
        for s in [
            JobStatus::Queued,
            JobStatus::Running,
            JobStatus::Done,
            JobStatus::Failed,
        ] {
            assert_eq!(JobStatus::parse(s.as_str()), Some(s));
            assert_eq!(
                serde_json::to_value(s).unwrap(),
                serde_json::json!(s.as_str())
            );
        }
        assert_eq!(JobStatus::parse("lost"), None);
        assert_eq!(stage_name(Stage::Normals), "normals");
        assert_eq!(parse_stage("inflate"), Some(Stage::Inflate));
        assert_eq!(parse_stage("nope"), None);
    }

    #[test]
    fn layer_files() {
        assert_eq!(layer_file(Layer::NegativeStep), "layers/negative_step.tif");
    }
}
