//! The tile runner: costmaps over `--costmap-tile-cells` working cells are
//! built as tile jobs ([`crate::db::TileStage`]) by every process on the
//! database, `terraplan serve` replicas and `terraplan worker`s alike.
//!
//! Each process claims a tile job whenever it has a free costmap slot
//! (`--costmap-jobs`, shared with the whole-costmap jobs), woken by the
//! job notes of every process ([`super::feed`]: a finished job may open the
//! next stage) and by a poll a few times per lease. A job runs its stage on
//! a blocking thread ([`stages`], [`finish`]) while its lease is renewed;
//! its outputs and its status done are stored in one transaction guarded
//! by its owner, and the costmap's progress is written and noted, so event
//! streams on every replica follow it. A job whose lease cannot be renewed
//! (its costmap was deleted or failed, or it was taken over) is stopped and
//! its outcome discarded. A stage that can never succeed fails the costmap
//! at once; a fault that may pass lets the job go to be run again, and the
//! costmap fails once a job has started too often ([`MAX_ATTEMPTS`]). On
//! shutdown the process stops claiming, stops its runs and gives their jobs
//! back, queued and not counted, and tells the others.

mod codec;
pub(crate) mod context;
mod finish;
mod stages;

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::{Notify, Semaphore, broadcast, watch};

use self::context::{ContextError, CostmapContext};
use self::stages::StageError;
use super::feed::{Feed, JobNote};
use super::record::{JobStatus, MAX_ATTEMPTS, parse_stage};
use crate::clock::now_millis;
use crate::db::{Db, TileClaim, TileJob, TileJobKey, TileProgress};
use crate::memory::BudgetError;
use crate::state::dem_store::DemLoader;

/// Leases are renewed (and the queue polled) this many times per lease.
const RENEWALS_PER_LEASE: u32 = 5;
/// Costmaps whose plan and inputs a process keeps at once.
const CONTEXTS_KEPT: usize = 4;
/// How long shutdown waits for the runs to stop.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);

/// When a costmap is built as tiles, and how big they are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileSettings {
    /// Costmaps of more working cells than this are built as tiles
    /// (`--costmap-tile-cells`).
    pub cells: u64,
    /// The tiles' side, working cells (`--costmap-tile-side`).
    pub side: usize,
}

/// The tile jobs of this process.
pub(super) struct TileRunner {
    dems: DemLoader,
    feed: Arc<Feed>,
    /// This process' name as a job holder.
    instance: String,
    lease_ms: i64,
    /// The costmap slots, shared with the whole-costmap jobs.
    slots: Arc<Semaphore>,
    shutdown: watch::Receiver<bool>,
    /// The jobs running here and the flags that stop them.
    running: Mutex<HashMap<TileJobKey, Arc<AtomicBool>>>,
    /// Job tasks alive.
    active: watch::Sender<usize>,
    contexts: Mutex<VecDeque<(String, Arc<CostmapContext>)>>,
    /// Something may be claimable (a note came, a job ended).
    wake: Notify,
}

/// Counts a job task as alive while it exists.
struct ActiveGuard<'a>(&'a watch::Sender<usize>);

impl Drop for ActiveGuard<'_> {
    fn drop(&mut self) {
        self.0.send_modify(|n| *n = n.saturating_sub(1));
    }
}

impl TileRunner {
    pub(super) fn new(
        dems: DemLoader,
        feed: Arc<Feed>,
        instance: String,
        lease_ms: i64,
        slots: Arc<Semaphore>,
        shutdown: watch::Receiver<bool>,
    ) -> TileRunner {
        TileRunner {
            dems,
            feed,
            instance,
            lease_ms,
            slots,
            shutdown,
            running: Mutex::new(HashMap::new()),
            active: watch::Sender::new(0),
            contexts: Mutex::new(VecDeque::new()),
            wake: Notify::new(),
        }
    }

    fn db(&self) -> &Db {
        &self.dems.db
    }

    fn every(&self) -> Duration {
        Duration::from_millis(self.lease_ms.unsigned_abs()) / RENEWALS_PER_LEASE
    }

    fn is_shutting_down(&self) -> bool {
        *self.shutdown.borrow()
    }

    fn stopped(&self) -> impl Future<Output = ()> + Send + 'static {
        let mut rx = self.shutdown.clone();
        async move {
            let _ = rx.wait_for(|s| *s).await;
        }
    }

    fn lock_running(&self) -> std::sync::MutexGuard<'_, HashMap<TileJobKey, Arc<AtomicBool>>> {
        // The map guards no invariant a panic could break half-way.
        self.running.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Something may be claimable now.
    pub(super) fn wake(&self) {
        self.wake.notify_one();
    }

    /// At start-up: on SQLite (this process' database alone) the tile jobs
    /// a previous process left running are claimable at once.
    pub(super) async fn recover(&self) {
        if let Db::Sqlite(_) = self.db() {
            match self.db().requeue_running_tile_jobs(now_millis()).await {
                Ok(0) => {}
                Ok(n) => tracing::info!(jobs = n, "unfinished costmap tile jobs queued again"),
                Err(e) => tracing::warn!(error = %e, "cannot queue the unfinished tile jobs again"),
            }
        }
    }

    /// Until shutdown: claim tile jobs into free slots, woken by the job
    /// notes of every process and a poll a few times per lease.
    pub(super) fn start(self: &Arc<Self>, mut notes: broadcast::Receiver<JobNote>) {
        let runner = self.clone();
        let stop = self.stopped();
        tokio::spawn(async move {
            let listen = async {
                // Missed notes may have said something is claimable too.
                while let Ok(_) | Err(broadcast::error::RecvError::Lagged(_)) = notes.recv().await {
                    runner.wake();
                }
            };
            tokio::select! {
                () = listen => {},
                () = stop => {},
            }
        });
        let runner = self.clone();
        tokio::spawn(async move { runner.claim_loop().await });
    }

    async fn claim_loop(self: Arc<Self>) {
        loop {
            let permit = tokio::select! {
                p = self.slots.clone().acquire_owned() => p.ok(),
                () = self.stopped() => None,
            };
            let Some(permit) = permit.filter(|_| !self.is_shutting_down()) else {
                break;
            };
            let now = now_millis();
            match self
                .db()
                .claim_tile_job(&self.instance, now, now + self.lease_ms, MAX_ATTEMPTS)
                .await
            {
                Ok(Some(TileClaim::Job(job))) => {
                    self.spawn_job(job, permit);
                    continue;
                }
                Ok(Some(TileClaim::GaveUp { costmap_id, error })) => {
                    tracing::warn!(costmap = %costmap_id, %error, "tiled costmap failed");
                    self.forget(&costmap_id);
                    self.note(&costmap_id, JobStatus::Failed, None).await;
                    continue;
                }
                Ok(None) => {}
                Err(e) => tracing::warn!(error = %e, "cannot claim a costmap tile job"),
            }
            drop(permit);
            tokio::select! {
                () = self.wake.notified() => {},
                () = tokio::time::sleep(self.every()) => {},
                () = self.stopped() => break,
            }
        }
        // Shutdown: stop the runs (their jobs are given back by `finish`).
        for cancel in self.lock_running().values() {
            cancel.store(true, Ordering::Relaxed);
        }
    }

    fn spawn_job(self: &Arc<Self>, job: TileJob, permit: tokio::sync::OwnedSemaphorePermit) {
        let cancel = Arc::new(AtomicBool::new(self.is_shutting_down()));
        self.lock_running().insert(job.key.clone(), cancel.clone());
        self.active.send_modify(|n| *n += 1);
        let runner = self.clone();
        tokio::spawn(async move {
            let _active = ActiveGuard(&runner.active);
            runner.run_job(&job, &cancel).await;
            runner.lock_running().remove(&job.key);
            drop(permit);
            runner.wake();
        });
    }

    /// Renew job `key`'s lease a few times per lease until aborted; once
    /// it is no longer this process' the run is stopped.
    fn keep_lease(
        self: &Arc<Self>,
        key: &TileJobKey,
        cancel: &Arc<AtomicBool>,
    ) -> tokio::task::JoinHandle<()> {
        let (runner, key, cancel) = (self.clone(), key.clone(), cancel.clone());
        tokio::spawn(async move {
            let mut tick = tokio::time::interval(runner.every());
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            tick.tick().await;
            loop {
                tick.tick().await;
                let until = now_millis() + runner.lease_ms;
                match runner
                    .db()
                    .renew_tile_lease(&key, &runner.instance, until)
                    .await
                {
                    Ok(true) => {}
                    Ok(false) => {
                        cancel.store(true, Ordering::Relaxed);
                        break;
                    }
                    Err(e) => tracing::warn!(
                        costmap = %key.costmap_id, error = %e, "cannot renew a tile job's lease"
                    ),
                }
            }
        })
    }

    /// The plan and inputs of costmap `id`, kept for its next jobs.
    async fn context(&self, id: &str) -> Result<Arc<CostmapContext>, ContextError> {
        let kept = {
            let contexts = self.contexts.lock().unwrap_or_else(|p| p.into_inner());
            contexts
                .iter()
                .find(|(c, _)| c == id)
                .map(|(_, x)| x.clone())
        };
        if let Some(ctx) = kept {
            return Ok(ctx);
        }
        let ctx = Arc::new(context::load(&self.dems, id).await?);
        let mut contexts = self.contexts.lock().unwrap_or_else(|p| p.into_inner());
        contexts.retain(|(c, _)| c != id);
        contexts.push_back((id.to_string(), ctx.clone()));
        while contexts.len() > CONTEXTS_KEPT {
            contexts.pop_front();
        }
        Ok(ctx)
    }

    /// Costmap `id` is finished (or gone): its context is not kept.
    fn forget(&self, id: &str) {
        self.contexts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .retain(|(c, _)| c != id);
    }

    /// Tell every process where costmap `id` stands now (a job of it was
    /// let go: one with a free slot takes it at once), as running with its
    /// progress so far.
    async fn note_progress(&self, id: &str) {
        match self.db().tile_progress(id).await {
            Ok(p) => self.note(id, JobStatus::Running, Some(p)).await,
            Err(e) => tracing::warn!(costmap = %id, error = %e, "cannot read a costmap's progress"),
        }
    }

    async fn note(&self, id: &str, status: JobStatus, progress: Option<TileProgress>) {
        let (progress, stage) = match progress {
            Some(p) => (p.progress, p.stage.and_then(|s| parse_stage(s.shown_as()))),
            None => (if status == JobStatus::Done { 1.0 } else { 0.0 }, None),
        };
        self.feed
            .publish(JobNote {
                id: id.to_string(),
                status,
                progress,
                stage,
            })
            .await;
    }

    async fn run_job(self: &Arc<Self>, job: &TileJob, cancel: &Arc<AtomicBool>) {
        let key = &job.key;
        let id = key.costmap_id.as_str();
        let lease = self.keep_lease(key, cancel);
        tracing::info!(
            costmap = %id,
            stage = key.stage.name(),
            tile = key.tile,
            attempt = job.attempts,
            holder = %self.instance,
            "costmap tile job started"
        );
        let started = std::time::Instant::now();
        let outcome = self.run_stage(job, cancel).await;
        lease.abort();
        let what = key.stage.job_name(key.tile);
        match outcome {
            Ok(Some(progress)) => {
                tracing::info!(
                    costmap = %id,
                    stage = key.stage.name(),
                    tile = key.tile,
                    attempt = job.attempts,
                    seconds = started.elapsed().as_secs_f64(),
                    "costmap tile job done"
                );
                self.note(id, JobStatus::Running, Some(progress)).await;
            }
            Ok(None) => {
                tracing::info!(costmap = %id, stage = key.stage.name(), tile = key.tile,
                    "costmap tile job done after its costmap was deleted or it was taken over: discarded");
            }
            Err(StageError::Cancelled) => {
                if !self.is_shutting_down() {
                    tracing::info!(costmap = %id, "{what} stopped: its costmap was deleted or failed, or the job was taken over");
                }
            }
            Err(StageError::Fatal(message)) => {
                tracing::warn!(costmap = %id, error = %message, "{what} failed: the costmap fails");
                match self
                    .db()
                    .fail_tiled_costmap(id, &message, now_millis())
                    .await
                {
                    Ok(true) => self.note(id, JobStatus::Failed, None).await,
                    Ok(false) => {}
                    Err(e) => {
                        self.release(
                            job,
                            &format!("{message} (and the failure could not be recorded: {e})"),
                        )
                        .await;
                    }
                }
                self.forget(id);
            }
            Err(StageError::Fault(message)) => {
                tracing::warn!(costmap = %id, error = %message, "{what} stopped on a fault: it is run again");
                self.release(job, &message).await;
                self.forget(id);
            }
        }
    }

    /// Let job `job` go after a fault, queued to be run again (here or
    /// elsewhere); should that fail too, its lease runs out.
    async fn release(&self, job: &TileJob, error: &str) {
        let id = &job.key.costmap_id;
        match self
            .db()
            .release_tile_job(&job.key, &self.instance, error, now_millis())
            .await
        {
            Ok(true) => self.note_progress(id).await,
            Ok(false) => {}
            Err(e) => tracing::warn!(costmap = %id, error = %e,
                "cannot let go of a tile job: it is taken over once its lease runs out"),
        }
    }

    /// Run job `job`'s stage and store its outputs: the costmap's progress
    /// then, or `None` when the job was no longer this process' to finish.
    async fn run_stage(
        self: &Arc<Self>,
        job: &TileJob,
        cancel: &Arc<AtomicBool>,
    ) -> Result<Option<TileProgress>, StageError> {
        let id = job.key.costmap_id.as_str();
        let ctx = match self.context(id).await {
            Ok(ctx) => ctx,
            Err(ContextError::Gone) => return Err(StageError::Cancelled),
            Err(ContextError::Fatal(m)) => return Err(StageError::Fatal(m)),
            Err(ContextError::Fault(m)) => return Err(StageError::Fault(m)),
        };
        // Room in the memory budget for the job, waited for as long as it
        // takes (a background job); a tile that alone needs more than the
        // budget cannot be built here.
        let k = usize::try_from(job.key.tile).unwrap_or(0);
        let need = stages::job_bytes(&ctx.plan, job.key.stage, k);
        let what = format!("{} of a costmap", job.key.stage.job_name(job.key.tile));
        let _room = tokio::select! {
            room = self.dems.memory.reserve_within(need, &what, None) => match room {
                Ok(room) => room,
                Err(_) if self.is_shutting_down() => {
                    return Err(StageError::Cancelled);
                }
                Err(e @ BudgetError::OverBudget { .. }) => {
                    return Err(StageError::Fatal(format!(
                        "the costmap cannot be built on this server: {e}"
                    )));
                }
                Err(e) => return Err(StageError::Fault(e.to_string())),
            },
            () = self.stopped() => return Err(StageError::Cancelled),
        };
        if cancel.load(Ordering::Relaxed) {
            return Err(StageError::Cancelled);
        }
        let db = self.db();
        if job.key.stage == crate::db::TileStage::Finish {
            let finished = finish::finish(db, &ctx, job, &self.instance, cancel).await?;
            if !finish::store(db, job, &self.instance, &finished).await? {
                return Ok(None);
            }
            self.forget(id);
            self.note(id, JobStatus::Done, None).await;
            tracing::info!(costmap = %id, "tiled costmap done");
            return Ok(Some(TileProgress {
                progress: 1.0,
                stage: None,
            }));
        }
        let outputs = stages::run_stage(db, &ctx, job, cancel).await?;
        if cancel.load(Ordering::Relaxed) {
            return Err(StageError::Cancelled);
        }
        db.complete_tile_job(&job.key, &self.instance, &outputs, now_millis())
            .await
            .map_err(|e| StageError::Fault(format!("the tile's results cannot be stored: {e}")))
    }

    /// After shutdown began: wait (briefly) for the runs to stop, then give
    /// back every tile job still held, queued for the other processes.
    pub(super) async fn finish(&self) {
        for cancel in self.lock_running().values() {
            cancel.store(true, Ordering::Relaxed);
        }
        let mut active = self.active.subscribe();
        if tokio::time::timeout(SHUTDOWN_GRACE, active.wait_for(|n| *n == 0))
            .await
            .is_err()
        {
            tracing::warn!("costmap tile jobs still busy at shutdown: they are given back");
        }
        match self
            .db()
            .give_back_tile_jobs(&self.instance, now_millis())
            .await
        {
            Ok(ids) => {
                for id in ids {
                    tracing::info!(costmap = %id, "costmap tile jobs given back for another process");
                    self.note_progress(&id).await;
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot give back the costmap tile jobs"),
        }
    }
}
