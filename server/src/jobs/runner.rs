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
//! the event stream; its holder also notes the progress to every process
//! sharing the database ([`super::feed`]), and writes it to the job's row
//! at least every second. A result is stored with its files in one transaction
//! (never half-written); a failure stores its reason. A run left without
//! an outcome by a storage error (the job could not be started, or its
//! result or failure could not be recorded) lets the job go, queued with
//! no owner, to be taken over and run again; only the jobs a process
//! actually has in hand have their leases renewed, so a job it let go of
//! any other way is taken over once its lease runs out. On PostgreSQL a
//! process takes over orphaned jobs only while it has a free slot, so
//! that idle replicas get them first. On shutdown the process stops
//! taking jobs, the runs are cancelled and their jobs given back, queued
//! with no holder, and the other processes are told, so that one of them
//! takes each over at once.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{Semaphore, broadcast, watch};

use super::build::{Outcome, Run, build};
use super::feed::{Feed, JobNote};
use super::live::{JobHandle, Live};
use super::record::{JobStatus, MAX_ATTEMPTS};
use super::tiles::{TileRunner, TileSettings};
use crate::clock::now_millis;
use crate::db::Db;
use crate::state::dem_store::DemLoader;

/// Leases are renewed (and orphaned jobs looked for) this many times
/// per lease, so a late round or two does not lose a job still running.
const RENEWALS_PER_LEASE: u32 = 5;
/// The shortest lease; see `--job-lease-s`.
pub const MIN_LEASE: Duration = Duration::from_secs(1);
/// How long shutdown waits for the runs to stop.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

/// The costmap jobs of this server process.
pub struct CostmapJobs {
    /// This process' name as a job holder.
    instance: String,
    /// How long a claim lasts unless renewed, ms.
    lease_ms: i64,
    /// Builds at once.
    max_jobs: usize,
    slots: Arc<Semaphore>,
    jobs: Mutex<HashMap<String, Arc<JobHandle>>>,
    shutdown: watch::Sender<bool>,
    /// Job tasks alive.
    active: watch::Sender<usize>,
    /// The database of the jobs and the DEMs they are built from.
    dems: DemLoader,
    /// Notes to and from the other processes on the database.
    feed: Arc<Feed>,
    /// When a costmap is built as tiles instead of whole here.
    tile_settings: TileSettings,
    /// The tile jobs this process runs.
    tiles: Arc<TileRunner>,
}

/// Counts a job task as alive while it exists.
struct ActiveGuard<'a>(&'a watch::Sender<usize>);

impl Drop for ActiveGuard<'_> {
    fn drop(&mut self) {
        self.0.send_modify(|n| *n = n.saturating_sub(1));
    }
}

impl CostmapJobs {
    /// A runner of at most `max_jobs` (≥ 1) builds (or tile jobs) at
    /// once, of the jobs stored in `dems.db`, holding each under a lease of
    /// `lease` (at least [`MIN_LEASE`]); costmaps over `tiles.cells` working
    /// cells are built as tiles by every process.
    pub fn new(
        max_jobs: usize,
        dems: DemLoader,
        lease: Duration,
        tiles: TileSettings,
    ) -> CostmapJobs {
        let max_jobs = max_jobs.max(1);
        let lease = lease.max(MIN_LEASE);
        let instance = uuid::Uuid::new_v4().to_string();
        let lease_ms = i64::try_from(lease.as_millis()).unwrap_or(i64::MAX / 2);
        let slots = Arc::new(Semaphore::new(max_jobs));
        let shutdown = watch::Sender::new(false);
        let feed = Arc::new(Feed::new(dems.db.clone()));
        let tile_runner = TileRunner::new(
            dems.clone(),
            feed.clone(),
            instance.clone(),
            lease_ms,
            slots.clone(),
            shutdown.subscribe(),
        );
        CostmapJobs {
            instance,
            lease_ms,
            max_jobs,
            slots,
            jobs: Mutex::new(HashMap::new()),
            shutdown,
            active: watch::Sender::new(0),
            feed,
            dems,
            tile_settings: tiles,
            tiles: Arc::new(tile_runner),
        }
    }

    /// How long a claim on a job lasts unless renewed, ms.
    pub fn lease_ms(&self) -> i64 {
        self.lease_ms
    }

    /// How often leases are renewed and orphaned jobs looked for.
    fn maintenance_every(&self) -> Duration {
        Duration::from_millis(self.lease_ms.unsigned_abs()) / RENEWALS_PER_LEASE
    }

    /// The notes of every job from now on, from every process on the
    /// database (see [`super::feed`]).
    pub fn notes(&self) -> broadcast::Receiver<JobNote> {
        self.feed.subscribe()
    }

    fn db(&self) -> &Db {
        &self.dems.db
    }

    /// When costmaps are built as tiles, and their tiles' side.
    pub fn tile_settings(&self) -> TileSettings {
        self.tile_settings
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
    pub async fn finish(&self) {
        let mut active = self.active.subscribe();
        if tokio::time::timeout(SHUTDOWN_GRACE, active.wait_for(|n| *n == 0))
            .await
            .is_err()
        {
            tracing::warn!("costmap runs still busy at shutdown: their jobs are given back");
        }
        let held = self.held();
        match self
            .db()
            .release_costmaps(&self.instance, None, now_millis())
            .await
        {
            Ok(0) => {}
            Ok(_) => {
                for id in held {
                    tracing::info!(costmap = %id, "costmap job given back for another server");
                    self.note_queued(&id).await;
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot give back the costmap jobs"),
        }
        self.tiles.finish().await;
    }

    /// Tell every process that job `id` is queued with no holder, for one
    /// with a free slot to take over now.
    async fn note_queued(&self, id: &str) {
        self.feed
            .publish(JobNote {
                id: id.to_string(),
                status: JobStatus::Queued,
                progress: 0.0,
                stage: None,
            })
            .await;
    }

    /// True while this process may take over another job: on SQLite
    /// always (the jobs are all its own); on PostgreSQL while it holds
    /// fewer than it can build at once, leaving the rest to idle replicas.
    fn has_room(&self) -> bool {
        match self.db() {
            Db::Sqlite(_) => true,
            Db::Postgres(_) => self.lock().len() < self.max_jobs,
        }
    }

    /// Hold job `id` (stored, queued, owned by this process) and run it
    /// when a slot is free.
    pub fn enqueue(self: &Arc<Self>, id: &str) {
        let handle = Arc::new(JobHandle::queued());
        if self.is_shutting_down() {
            handle.cancel();
        }
        self.lock().insert(id.to_string(), handle.clone());
        self.active.send_modify(|n| *n += 1);
        // Join the queue for a slot now, in the order jobs are enqueued: the
        // task's own first poll may come after the next job's (tokio's
        // semaphore serves waiters in the order they first asked).
        let mut wait: SlotWait = Box::pin(self.slots.clone().acquire_owned());
        let slot = match wait
            .as_mut()
            .poll(&mut std::task::Context::from_waker(std::task::Waker::noop()))
        {
            std::task::Poll::Ready(permit) => Slot::Held(permit.ok()),
            std::task::Poll::Pending => Slot::Waiting(wait),
        };
        let jobs = self.clone();
        let id = id.to_string();
        tokio::spawn(async move {
            let _active = ActiveGuard(&jobs.active);
            jobs.run_job(&id, &handle, slot).await;
            let mut map = jobs.lock();
            if map.get(&id).is_some_and(|h| Arc::ptr_eq(h, &handle)) {
                map.remove(&id);
            }
        });
    }

    /// Take over the unfinished jobs nobody holds (leases ended before
    /// `expired_before`) and queue them here.
    pub async fn adopt_orphans(self: &Arc<Self>, expired_before: i64) -> usize {
        let ids = match self.db().orphaned_costmaps(expired_before).await {
            Ok(ids) => ids,
            Err(e) => {
                tracing::warn!(error = %e, "cannot look for orphaned costmap jobs");
                return 0;
            }
        };
        let mut adopted = 0;
        for id in ids {
            if self.is_shutting_down() || !self.has_room() {
                break;
            }
            // Still in hand here (its lease lapsed while the database was
            // unreachable): the run goes on and the next renewal covers it.
            if self.lock().contains_key(&id) {
                continue;
            }
            let now = now_millis();
            match self
                .db()
                .adopt_costmap(
                    &id,
                    &self.instance,
                    expired_before,
                    now,
                    now + self.lease_ms,
                )
                .await
            {
                Ok(true) => {
                    tracing::info!(costmap = %id, "costmap job taken over and queued again");
                    self.enqueue(&id);
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
    pub async fn recover(self: &Arc<Self>) -> usize {
        let expired_before = match self.db() {
            Db::Sqlite(_) => i64::MAX,
            Db::Postgres(_) => now_millis(),
        };
        self.tiles.recover().await;
        self.adopt_orphans(expired_before).await
    }

    /// The jobs this process has in hand, queued or running.
    fn held(&self) -> Vec<String> {
        self.lock().keys().cloned().collect()
    }

    /// Renew the leases of the jobs this process has in hand. A job it
    /// owns in the database but no longer has in hand (its run ended
    /// without recording an outcome) is left to run out its lease and be
    /// taken over.
    async fn renew_leases(&self) {
        let held = self.held();
        if held.is_empty() {
            return;
        }
        if let Err(e) = self
            .db()
            .renew_costmap_leases(&self.instance, &held, now_millis() + self.lease_ms)
            .await
        {
            tracing::warn!(error = %e, "cannot renew the costmap job leases");
        }
    }

    /// Until shutdown: listen for the other processes' notes, renew this
    /// process' leases and take over orphaned jobs, a few times per lease
    /// and whenever a job is given back.
    pub fn start_maintenance(self: &Arc<Self>) {
        self.feed.start_listening(self.shutdown_signal());
        self.tiles.start(self.notes());
        let jobs = self.clone();
        let stop = self.shutdown_signal();
        let mut notes = self.notes();
        tokio::spawn(async move {
            let work = async {
                let mut tick = tokio::time::interval(jobs.maintenance_every());
                tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
                loop {
                    tokio::select! {
                        _ = tick.tick() => {
                            jobs.renew_leases().await;
                            jobs.adopt_orphans(now_millis()).await;
                        }
                        note = notes.recv() => match note {
                            // Given back by its holder (or missed notes,
                            // one of which may have been): take it now.
                            Ok(JobNote { status: JobStatus::Queued, .. })
                            | Err(broadcast::error::RecvError::Lagged(_)) => {
                                jobs.adopt_orphans(now_millis()).await;
                            }
                            Ok(_) => {}
                            // The feed lives as long as `jobs`.
                            Err(broadcast::error::RecvError::Closed) => break,
                        },
                    }
                }
            };
            tokio::select! {
                () = work => {},
                () = stop => {},
            }
        });
    }
}

/// A job's request for a slot, made when it was enqueued.
type SlotWait = std::pin::Pin<
    Box<
        dyn std::future::Future<
                Output = Result<tokio::sync::OwnedSemaphorePermit, tokio::sync::AcquireError>,
            > + Send,
    >,
>;

enum Slot {
    /// Granted at once (`None`: the semaphore is closed).
    Held(Option<tokio::sync::OwnedSemaphorePermit>),
    /// In the queue.
    Waiting(SlotWait),
}

impl CostmapJobs {
    /// Run job `id` once it has a slot, and record its outcome.
    async fn run_job(&self, id: &str, handle: &Arc<JobHandle>, slot: Slot) {
        let jobs = self;
        let owner = jobs.instance.clone();
        let permit = match slot {
            Slot::Held(permit) => permit,
            Slot::Waiting(wait) => tokio::select! {
                p = wait => p.ok(),
                () = jobs.shutdown_signal() => None,
                () = handle.cancelled.notified() => None,
            },
        };
        let Some(_permit) = permit.filter(|_| !handle.is_cancelled()) else {
            if jobs.is_shutting_down() {
                self.give_back(id).await;
            }
            return;
        };
        let now = now_millis();
        let row = match self
            .db()
            .claim_costmap(id, &owner, now, now + self.lease_ms)
            .await
        {
            Ok(Some(row)) => row,
            // Deleted, or no longer ours.
            Ok(None) => return,
            Err(e) => {
                tracing::error!(costmap = %id, error = %e, "cannot start a costmap job");
                self.release_after_error(id, &format!("the job could not be started: {e}"))
                    .await;
                return;
            }
        };
        handle.live.send_replace(Live {
            status: JobStatus::Running,
            progress: 0.0,
            stage: None,
        });
        self.feed
            .publish(JobNote {
                id: id.to_string(),
                status: JobStatus::Running,
                progress: 0.0,
                stage: None,
            })
            .await;
        tracing::info!(costmap = %id, dem = %row.dem_id, attempt = row.attempts, "costmap job started");
        let started = std::time::Instant::now();
        let outcome = if row.attempts > MAX_ATTEMPTS {
            Outcome::Failed(format!(
                "the job was interrupted {} times (its server stopped while it ran) and is not \
             tried again",
                row.attempts - 1
            ))
        } else {
            let run = Run {
                dems: &self.dems,
                feed: &self.feed,
                owner: &owner,
                shutdown: self.shutdown_signal(),
                tiles: self.tile_settings,
            };
            build(run, &row, handle).await
        };
        let now = now_millis();
        match outcome {
            Outcome::Built(built) => {
                match self
                    .db()
                    .finish_costmap(id, &owner, &built.result, &built.files, now)
                    .await
                {
                    Ok(true) => {
                        tracing::info!(
                            costmap = %id,
                            attempt = row.attempts,
                            seconds = started.elapsed().as_secs_f64(),
                            "costmap job done"
                        );
                        self.feed
                            .publish(JobNote {
                                id: id.to_string(),
                                status: JobStatus::Done,
                                progress: 1.0,
                                stage: None,
                            })
                            .await;
                    }
                    Ok(false) => {
                        tracing::info!(costmap = %id, "costmap finished after it was deleted or taken over: discarded")
                    }
                    Err(e) => {
                        tracing::error!(costmap = %id, error = %e, "cannot store a costmap");
                        self.fail(id, &format!("the result could not be stored: {e}"))
                            .await;
                    }
                }
            }
            Outcome::Tiled(tiles) => {
                tracing::info!(
                    costmap = %id,
                    tiles,
                    tile_side = self.tile_settings.side,
                    "costmap planned as tiles: built by the tile jobs of every process"
                );
                self.feed
                    .publish(JobNote {
                        id: id.to_string(),
                        status: JobStatus::Running,
                        progress: 0.0,
                        stage: None,
                    })
                    .await;
                self.tiles.wake();
            }
            Outcome::Cancelled => {
                if jobs.is_shutting_down() {
                    self.give_back(id).await;
                } else {
                    tracing::info!(costmap = %id, "costmap job cancelled");
                }
            }
            Outcome::Failed(message) => {
                tracing::warn!(costmap = %id, error = %message, "costmap job failed");
                self.fail(id, &message).await;
            }
        }
    }

    async fn fail(&self, id: &str, message: &str) {
        match self
            .db()
            .fail_costmap(id, &self.instance, message, now_millis())
            .await
        {
            Ok(true) => self.note_failed(id).await,
            Ok(false) => {}
            Err(e) => {
                tracing::error!(costmap = %id, error = %e, "cannot record a costmap job's failure");
                self.release_after_error(
                    id,
                    &format!("{message} (and the failure could not be recorded: {e})"),
                )
                .await;
            }
        }
    }

    async fn note_failed(&self, id: &str) {
        self.feed
            .publish(JobNote {
                id: id.to_string(),
                status: JobStatus::Failed,
                progress: 0.0,
                stage: None,
            })
            .await;
    }

    /// After a storage error left a run without a recorded outcome: let the
    /// job go, queued with no owner, so that the maintenance loop (here or on
    /// another server) takes it over and runs it again within a few seconds;
    /// once [`MAX_ATTEMPTS`] runs have started it is failed with `error`
    /// instead. Should this fail too (the database is unreachable), the job
    /// is no longer in hand here, so its lease is not renewed and it is taken
    /// over once the lease runs out.
    async fn release_after_error(&self, id: &str, error: &str) {
        let give_up = format!("{error}; given up after {MAX_ATTEMPTS} attempts");
        match self
            .db()
            .release_costmap_after_error(id, &self.instance, now_millis(), MAX_ATTEMPTS, &give_up)
            .await
        {
            Ok(Some(status)) if status == JobStatus::Failed.as_str() => {
                tracing::warn!(costmap = %id, "costmap job failed: {give_up}");
                self.note_failed(id).await;
            }
            Ok(Some(_)) => {
                tracing::info!(costmap = %id, "costmap job let go after a storage error: it is run again");
                self.note_queued(id).await;
            }
            Ok(None) => {}
            Err(e) => tracing::warn!(
                costmap = %id,
                error = %e,
                "cannot let go of a costmap job: it is taken over once its lease runs out"
            ),
        }
    }

    /// Give a job back, queued with no holder, for another server to take
    /// over at once (at shutdown).
    async fn give_back(&self, id: &str) {
        match self
            .db()
            .release_costmaps(&self.instance, Some(id), now_millis())
            .await
        {
            Ok(0) => {}
            Ok(_) => {
                tracing::info!(costmap = %id, "costmap job given back for another server");
                self.note_queued(id).await;
            }
            Err(e) => {
                tracing::warn!(costmap = %id, error = %e, "cannot give back a costmap job")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // SQLite triggers that refuse one kind of update (`RAISE(ABORT)`, an
    // ordinary database error to the server), so the production code runs
    // unchanged, with no test hook; no maintenance loop runs, so every
    // renewal and take-over happens when the test asks for it.

    use std::path::PathBuf;

    use planner_core::costmap::{CostmapOptions, VehicleSpec};
    use planner_core::terrain::DemLimits;

    use crate::db::{CostmapRow, DemMetaRow};
    use crate::jobs::record::{COSTMAP_TIF, DEFAULT_LEASE, LEGEND_SVG, PREVIEW_PNG, StoredRequest};
    use crate::memory::MemoryBudget;
    use crate::state::{DemStore, Planners};

    /// A server's costmap jobs on a SQLite database of its own, removed on
    /// drop.
    struct TestServer {
        db: Db,
        jobs: Arc<CostmapJobs>,
        dir: PathBuf,
    }

    impl Drop for TestServer {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }

    impl TestServer {
        async fn start() -> TestServer {
            TestServer::start_with(TileSettings {
                cells: u64::MAX,
                side: 512,
            })
            .await
        }

        /// A server that builds costmaps of over 100 working cells as
        /// tiles of 16 (the test DEM's 40 × 40: 9 tiles).
        async fn start_tiled() -> TestServer {
            TestServer::start_with(TileSettings {
                cells: 100,
                side: 16,
            })
            .await
        }

        async fn start_with(tiles: TileSettings) -> TestServer {
            let dir = std::env::temp_dir()
                .join(format!("terraplan-costmap-jobs-{}", uuid::Uuid::new_v4()));
            std::fs::create_dir_all(&dir).unwrap();
            let db = Db::connect(None, &dir).await.unwrap();
            let limits = DemLimits {
                max_pixels: u64::MAX,
                max_side: u32::MAX,
            };
            let dems = DemLoader {
                db: db.clone(),
                store: Arc::new(DemStore::new(limits, usize::MAX, 64 << 20)),
                memory: Arc::new(MemoryBudget::new(1024)),
                planner: Arc::new(Planners::default()),
            };
            let jobs = Arc::new(CostmapJobs::new(1, dems, DEFAULT_LEASE, tiles));
            TestServer { db, jobs, dir }
        }

        fn jobs(&self) -> &Arc<CostmapJobs> {
            &self.jobs
        }

        fn pool(&self) -> &sqlx::SqlitePool {
            match &self.db {
                Db::Sqlite(pool) => pool,
                Db::Postgres(_) => unreachable!("the tests run on SQLite"),
            }
        }

        async fn sql(&self, sql: &'static str) {
            sqlx::query(sql).execute(self.pool()).await.unwrap();
        }

        /// A 40 × 40 DEM of 0.5 m cells, a gentle ramp, in UTM 33N.
        async fn dem(&self) -> String {
            let mut asc = String::from(
                "ncols 40\nnrows 40\nxllcorner 500000\nyllcorner 5000000\ncellsize 0.5\n\
                 NODATA_value -9999\n",
            );
            for r in 0..40 {
                let row: Vec<String> = (0..40)
                    .map(|c| format!("{}", 0.01 * (c + r) as f64))
                    .collect();
                asc.push_str(&row.join(" "));
                asc.push('\n');
            }
            let id = uuid::Uuid::now_v7().to_string();
            let meta = DemMetaRow {
                id: id.clone(),
                name: None,
                created_at: now_millis(),
                file_name: Some("ramp.asc".into()),
                crs_override: Some(32633),
                // The info an upload stores (loading reads its size and
                // format).
                info: serde_json::to_string(
                    &planner_core::terrain::read_dem(
                        asc.as_bytes(),
                        Some("ramp.asc"),
                        Some(32633),
                        &planner_core::terrain::DemLimits::default(),
                    )
                    .and_then(|d| d.info())
                    .unwrap(),
                )
                .unwrap(),
                size_bytes: asc.len() as i64,
                read_bytes: None,
                project_id: None,
            };
            self.db.insert_dem(&meta, asc.as_bytes()).await.unwrap();
            id
        }

        /// A job for `dem_id` stored queued and held by this server, as
        /// `POST /api/v1/costmaps` stores it (not queued here yet).
        async fn job(&self, dem_id: &str) -> String {
            let now = now_millis();
            let request = StoredRequest {
                vehicle: serde_json::Value::Null,
                options: CostmapOptions::default(),
            };
            let vehicle = VehicleSpec::default().resolve("/vehicle").unwrap();
            let row = CostmapRow {
                id: uuid::Uuid::now_v7().to_string(),
                name: None,
                dem_id: dem_id.to_string(),
                created_at: now,
                updated_at: now,
                request: serde_json::to_string(&request).unwrap(),
                vehicle: serde_json::to_string(&vehicle).unwrap(),
                status: JobStatus::Queued.as_str().to_string(),
                progress: 0.0,
                stage: None,
                result: None,
                error: None,
                attempts: 0,
                project_id: None,
            };
            self.db
                .insert_costmap(&row, self.jobs().instance(), now + self.jobs().lease_ms())
                .await
                .unwrap();
            row.id
        }

        /// Until every job task here has ended.
        async fn settle(&self) {
            let mut active = self.jobs().active.subscribe();
            tokio::time::timeout(Duration::from_secs(120), active.wait_for(|n| *n == 0))
                .await
                .expect("the job tasks end")
                .unwrap();
        }

        async fn row(&self, id: &str) -> CostmapRow {
            self.db.get_costmap(id).await.unwrap().unwrap()
        }

        /// The job's holder and lease.
        async fn holder(&self, id: &str) -> (Option<String>, i64) {
            sqlx::query_as("SELECT owner, lease_until FROM costmaps WHERE id = $1")
                .bind(id)
                .fetch_one(self.pool())
                .await
                .unwrap()
        }

        /// Take over the orphaned jobs (as the maintenance loop does) and
        /// let them run.
        async fn adopt(&self, expired_before: i64) -> usize {
            let n = self.jobs().adopt_orphans(expired_before).await;
            self.settle().await;
            n
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn claim_error_lets_the_job_go_to_be_run_again() {
        let t = TestServer::start().await;
        let dem = t.dem().await;
        let id = t.job(&dem).await;
        t.sql(
            "CREATE TRIGGER refuse_claim BEFORE UPDATE OF status ON costmaps \
             WHEN NEW.status = 'running' BEGIN SELECT RAISE(ABORT, 'disk I/O error'); END",
        )
        .await;
        t.jobs().enqueue(&id);
        t.settle().await;
        // Not started (no attempt counted), no longer held: any server's
        // maintenance takes it over at once, and its events follow the
        // stored row meanwhile.
        let row = t.row(&id).await;
        assert_eq!((row.status.as_str(), row.attempts), ("queued", 0));
        assert_eq!(t.holder(&id).await, (None, 0));
        assert!(t.jobs().live(&id).is_none());
        assert_eq!(
            t.db.orphaned_costmaps(now_millis()).await.unwrap(),
            std::slice::from_ref(&id)
        );

        // While the database refuses, it is tried again (and let go again).
        assert_eq!(t.adopt(now_millis()).await, 1);
        assert_eq!(t.holder(&id).await, (None, 0));

        t.sql("DROP TRIGGER refuse_claim").await;
        assert_eq!(t.adopt(now_millis()).await, 1);
        let row = t.row(&id).await;
        assert_eq!(row.status, "done", "{:?}", row.error);
        assert_eq!(row.attempts, 1);
        assert!(
            t.db.get_costmap_file(&id, COSTMAP_TIF)
                .await
                .unwrap()
                .is_some()
        );
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn unrecorded_failure_lets_the_job_go_then_gives_up() {
        let t = TestServer::start().await;
        // Its DEM does not exist: every run fails, saying so.
        let id = t.job("no-such-dem").await;
        // Refuse the run's own failure, not the release's final one.
        t.sql(
            "CREATE TRIGGER refuse_failure BEFORE UPDATE OF status ON costmaps \
             WHEN NEW.status = 'failed' AND NEW.error NOT LIKE '%given up after%' \
             BEGIN SELECT RAISE(ABORT, 'disk I/O error'); END",
        )
        .await;
        t.jobs().enqueue(&id);
        t.settle().await;
        for attempt in 1..MAX_ATTEMPTS {
            let row = t.row(&id).await;
            assert_eq!((row.status.as_str(), row.attempts), ("queued", attempt));
            assert_eq!(t.holder(&id).await, (None, 0));
            assert_eq!(t.adopt(now_millis()).await, 1);
        }
        let row = t.row(&id).await;
        assert_eq!(
            (row.status.as_str(), row.attempts),
            ("failed", MAX_ATTEMPTS)
        );
        let error = row.error.unwrap();
        assert!(
            error.contains("deleted")
                && error.contains("could not be recorded")
                && error.contains("given up after 3 attempts"),
            "{error}"
        );
        assert_eq!(t.holder(&id).await, (None, 0));
        assert!(t.db.orphaned_costmaps(i64::MAX).await.unwrap().is_empty());

        // Once the database records failures again, one is stored at once.
        t.sql("DROP TRIGGER refuse_failure").await;
        let id = t.job("no-such-dem").await;
        t.jobs().enqueue(&id);
        t.settle().await;
        let row = t.row(&id).await;
        assert_eq!((row.status.as_str(), row.attempts), ("failed", 1));
        assert!(row.error.unwrap().contains("deleted"));
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn only_jobs_in_hand_keep_their_lease() {
        let t = TestServer::start().await;
        let dem = t.dem().await;
        // A job this server still owns in the database but no longer has
        // in hand (its run ended and even letting it go failed), with its
        // lease about to end; and one queued here behind a busy slot.
        let stray = t.job(&dem).await;
        let queued = t.job(&dem).await;
        let busy = t.jobs().slots.clone().acquire_owned().await.unwrap();
        t.jobs().enqueue(&queued);
        let lease = now_millis() + 100;
        sqlx::query("UPDATE costmaps SET lease_until = $1")
            .bind(lease)
            .execute(t.pool())
            .await
            .unwrap();

        t.jobs().renew_leases().await;
        let (owner, stray_lease) = t.holder(&stray).await;
        assert_eq!(owner.as_deref(), Some(t.jobs().instance()));
        assert_eq!(stray_lease, lease, "a job not in hand is not renewed");
        let (_, queued_lease) = t.holder(&queued).await;
        assert!(
            queued_lease > lease + t.jobs().lease_ms() / 2,
            "{queued_lease}"
        );

        // Once its lease has run out the stray job is taken over and run;
        // the queued one is still in hand, so it is not taken over twice.
        let later = lease + 1;
        assert_eq!(
            t.db.orphaned_costmaps(later).await.unwrap(),
            std::slice::from_ref(&stray)
        );
        assert_eq!(t.jobs().adopt_orphans(i64::MAX).await, 1);
        drop(busy);
        t.settle().await;
        for id in [&stray, &queued] {
            let row = t.row(id).await;
            assert_eq!(
                (row.status.as_str(), row.attempts),
                ("done", 1),
                "{:?}",
                row.error
            );
        }
    }

    impl TestServer {
        /// Run the tile jobs (as the maintenance loop starts them).
        fn run_tiles(&self) {
            self.jobs().tiles.start(self.jobs().notes());
        }

        /// Until costmap `id` is done or failed.
        async fn finished(&self, id: &str) -> CostmapRow {
            tokio::time::timeout(Duration::from_secs(120), async {
                loop {
                    let row = self.row(id).await;
                    if row.status == "done" || row.status == "failed" {
                        return row;
                    }
                    tokio::time::sleep(Duration::from_millis(20)).await;
                }
            })
            .await
            .expect("the costmap finishes")
        }

        /// The cost band of a stored costmap.tif.
        async fn costs(&self, id: &str) -> Vec<f64> {
            let tif = self.db.get_costmap_file(id, COSTMAP_TIF).await.unwrap();
            let limits = DemLimits {
                max_pixels: u64::MAX,
                max_side: u32::MAX,
            };
            planner_core::terrain::read_dem(&tif.unwrap().data, Some("c.tif"), None, &limits)
                .unwrap()
                .values
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_costmap_over_the_threshold_is_built_as_tiles_like_the_whole_build() {
        let whole = TestServer::start().await;
        let id = whole.job(&whole.dem().await).await;
        whole.jobs().enqueue(&id);
        whole.settle().await;
        let reference = whole.row(&id).await;
        assert_eq!(reference.status, "done", "{:?}", reference.error);

        let t = TestServer::start_tiled().await;
        t.run_tiles();
        let tiled = t.job(&t.dem().await).await;
        t.jobs().enqueue(&tiled);
        let row = t.finished(&tiled).await;
        assert_eq!(row.status, "done", "{:?}", row.error);
        assert_eq!((row.progress, row.attempts), (1.0, 1));
        assert_eq!(row.result, reference.result);
        for name in [PREVIEW_PNG, LEGEND_SVG] {
            let a = whole.db.get_costmap_file(&id, name).await.unwrap().unwrap();
            let b = t.db.get_costmap_file(&tiled, name).await.unwrap().unwrap();
            assert!(a.data == b.data, "{name}");
        }
        let (a, b) = (whole.costs(&id).await, t.costs(&tiled).await);
        assert_eq!(a.len(), 1600);
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
        let (jobs,): (i64,) = sqlx::query_as("SELECT COUNT(*) FROM costmap_tile_jobs")
            .fetch_one(t.pool())
            .await
            .unwrap();
        assert_eq!(jobs, 0);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_tile_job_failing_on_a_fault_is_retried_then_fails_its_costmap() {
        let t = TestServer::start_tiled().await;
        // The fill stage's results cannot be stored.
        t.sql(
            "CREATE TRIGGER refuse_final BEFORE INSERT ON costmap_tiles \
             WHEN NEW.kind = 'final' BEGIN SELECT RAISE(ABORT, 'disk I/O error'); END",
        )
        .await;
        t.run_tiles();
        let id = t.job(&t.dem().await).await;
        t.jobs().enqueue(&id);
        let row = t.finished(&id).await;
        assert_eq!(row.status, "failed");
        let error = row.error.unwrap();
        assert!(
            error.starts_with("tile 0 of stage fill failed 3 times, the last time: ")
                && error.contains("disk I/O error"),
            "{error}"
        );
        // Its tile jobs and tiles are gone.
        let (left,): (i64,) = sqlx::query_as(
            "SELECT (SELECT COUNT(*) FROM costmap_tile_jobs) + (SELECT COUNT(*) FROM costmap_tiles)",
        )
        .fetch_one(t.pool())
        .await
        .unwrap();
        assert_eq!(left, 0);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_tiled_costmap_whose_dem_is_deleted_fails_saying_so() {
        let t = TestServer::start_tiled().await;
        let dem = t.dem().await;
        let id = t.job(&dem).await;
        // Planned as tiles by its costmap job; no tile runs yet.
        t.jobs().enqueue(&id);
        t.settle().await;
        assert_eq!(t.db.costmap_tile_side(&id).await.unwrap(), Some(16));
        assert!(t.db.delete_dem(&dem).await.unwrap());
        t.run_tiles();
        let row = t.finished(&id).await;
        assert_eq!(row.status, "failed");
        assert!(row.error.unwrap().contains("was deleted"));
    }
}
