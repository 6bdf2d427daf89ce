//! Progress of a costmap run: its stages, the callback that hears of them
//! (and may cancel), and the counter the parallel passes tick.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use serde::{Deserialize, Serialize};

use super::CostmapError;

/// The pipeline's stages, as progress reports them.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Resample,
    Steps,
    /// Smoothing and normals, band by band.
    Normals,
    Layers,
    Regions,
    Inflate,
    Cost,
}

impl Stage {
    /// Share of the whole run where this stage starts, and its length
    /// (rough timings on real DEMs), so progress moves evenly.
    pub(crate) fn span(self) -> (f64, f64) {
        match self {
            Stage::Resample => (0.0, 0.05),
            Stage::Steps => (0.05, 0.15),
            Stage::Normals => (0.20, 0.45),
            Stage::Layers => (0.65, 0.05),
            Stage::Regions => (0.70, 0.10),
            Stage::Inflate => (0.80, 0.12),
            Stage::Cost => (0.92, 0.08),
        }
    }
}

/// Progress reports: the stage and the fraction of the whole run done,
/// [0, 1]. Returning `false` cancels the run.
pub trait Progress: Sync {
    fn report(&self, stage: Stage, done: f64) -> bool;
}

impl<F: Fn(Stage, f64) -> bool + Sync> Progress for F {
    fn report(&self, stage: Stage, done: f64) -> bool {
        self(stage, done)
    }
}

/// Counts the rows a stage has done and reports progress now and then,
/// from any thread; remembers a cancellation.
pub struct Ticker<'a> {
    progress: &'a dyn Progress,
    stage: Stage,
    total: usize,
    every: usize,
    done: AtomicUsize,
    cancelled: AtomicBool,
}

impl<'a> Ticker<'a> {
    /// A stage of `total` rows; reports its start.
    pub fn new(progress: &'a dyn Progress, stage: Stage, total: usize) -> Ticker<'a> {
        let t = Ticker {
            progress,
            stage,
            total: total.max(1),
            every: (total / 50).max(1),
            done: AtomicUsize::new(0),
            cancelled: AtomicBool::new(false),
        };
        if !progress.report(stage, stage.span().0) {
            t.cancelled.store(true, Ordering::Relaxed);
        }
        t
    }

    /// One more row done; false once the run is cancelled.
    pub fn tick(&self) -> bool {
        if self.cancelled.load(Ordering::Relaxed) {
            return false;
        }
        let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_multiple_of(self.every) {
            let (start, len) = self.stage.span();
            let done = start + len * (n.min(self.total) as f64 / self.total as f64);
            if !self.progress.report(self.stage, done) {
                self.cancelled.store(true, Ordering::Relaxed);
                return false;
            }
        }
        true
    }

    pub fn cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }

    /// `Err(Cancelled)` if the run was cancelled.
    pub(crate) fn check(&self) -> Result<(), CostmapError> {
        if self.cancelled() {
            Err(CostmapError::Cancelled)
        } else {
            Ok(())
        }
    }
}

/// Passes progress on never lower than before: rows finish out of order
/// on several threads, and the optional ditch stage runs between others.
pub(crate) struct Monotone<'a> {
    inner: &'a dyn Progress,
    best: Mutex<f64>,
}

impl<'a> Monotone<'a> {
    pub(crate) fn new(inner: &'a dyn Progress) -> Monotone<'a> {
        Monotone {
            inner,
            best: Mutex::new(0.0),
        }
    }
}

impl Progress for Monotone<'_> {
    fn report(&self, stage: Stage, done: f64) -> bool {
        // Held while reporting, so reports also arrive in order.
        let mut best = self.best.lock().unwrap_or_else(|p| p.into_inner());
        *best = best.max(done);
        self.inner.report(stage, *best)
    }
}
