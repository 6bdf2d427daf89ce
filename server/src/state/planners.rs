//! The planner slots: CPU-heavy work runs on blocking threads, at most
//! `--planner-threads` jobs of each kind at once, each stopped by its own
//! cancellation token.

use std::sync::Arc;
use std::time::Duration;

use planner_core::cancel::CancelToken;
use tokio::sync::Semaphore;

use crate::config::{SURVEY_TIMEOUT, ServeConfig};
use crate::error::ApiError;

/// How long a request waits for a free planner before a 503.
const PLANNER_QUEUE_TIMEOUT: Duration = Duration::from_secs(120);
/// `--route-timeout-s` by default.
const ROUTE_TIMEOUT: Duration = Duration::from_secs(120);

/// The kinds of planning work, each with its own `--planner-threads`
/// slots: a slow survey never holds up a DEM upload, a hillshade or a
/// route search, and the other way round (at most three times
/// `--planner-threads` threads plan at once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// Survey planning: stopped after `--survey-timeout-s`.
    Survey,
    /// Route searches: stopped after `--route-timeout-s`.
    Route,
    /// Reading DEMs, hillshades and height sampling: bounded by the DEM
    /// size limits.
    Dem,
}

/// The planner slots of each kind of work, and their time limits.
pub struct Planners {
    surveys: Arc<Semaphore>,
    routes: Arc<Semaphore>,
    dems: Arc<Semaphore>,
    /// Longest a survey may plan (`--survey-timeout-s`).
    pub survey_timeout: Duration,
    /// Longest a route search may run (`--route-timeout-s`).
    pub route_timeout: Duration,
}

impl Planners {
    /// `threads` slots for each kind of work.
    pub fn new(threads: usize, survey_timeout: Duration, route_timeout: Duration) -> Planners {
        let slots = || Arc::new(Semaphore::new(threads.max(1)));
        Planners {
            surveys: slots(),
            routes: slots(),
            dems: slots(),
            survey_timeout,
            route_timeout,
        }
    }

    pub fn from_config(config: &ServeConfig) -> Planners {
        Planners::new(
            config.planner_threads,
            Duration::from_secs_f64(config.survey_timeout_s),
            Duration::from_secs_f64(config.route_timeout_s),
        )
    }

    fn slots(&self, work: Work) -> &Arc<Semaphore> {
        match work {
            Work::Survey => &self.surveys,
            Work::Route => &self.routes,
            Work::Dem => &self.dems,
        }
    }

    /// Run CPU-heavy planning off the async runtime, at most
    /// `planner_threads` jobs of each kind of `work` at a time; a job waits
    /// up to 2 minutes for its slot (then 503).
    ///
    /// The job gets a cancellation token, also set as its thread's
    /// ([`planner_core::cancel::check`]): it is cancelled when the
    /// returned future is dropped (the client went away) and runs out
    /// after the time limit of the kind of work, counted from the job's
    /// start. A job seeing it cancelled returns early, which frees its slot.
    pub async fn run<T: Send + 'static>(
        &self,
        work: Work,
        job: impl FnOnce(&CancelToken) -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let slots = self.slots(work).clone();
        let permit = tokio::time::timeout(PLANNER_QUEUE_TIMEOUT, slots.acquire_owned())
            .await
            .map_err(|_| ApiError::Unavailable("the planner is busy: retry in a moment".into()))?
            .map_err(|_| ApiError::Unavailable("the service is shutting down".into()))?;
        let token = match work {
            Work::Survey => CancelToken::with_limit(self.survey_timeout),
            Work::Route => CancelToken::with_limit(self.route_timeout),
            Work::Dem => CancelToken::new(),
        };
        // Dropped with this future when the client goes away.
        let _cancel = token.cancel_on_drop();
        let span = tracing::Span::current();
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            let _span = span.enter();
            let began = std::time::Instant::now();
            let out = token.scope(|| job(&token));
            if let Err(why) = token.check() {
                tracing::info!(
                    work = ?work,
                    after_ms = began.elapsed().as_millis() as u64,
                    "planning stopped: {why}"
                );
            }
            out
        })
        .await
        .map_err(|e| ApiError::Internal(format!("planner task failed: {e}")))
    }
}

impl Default for Planners {
    fn default() -> Self {
        Planners::new(1, SURVEY_TIMEOUT, ROUTE_TIMEOUT)
    }
}

/// Run `job` on a blocking thread, without waiting for a planner slot: for
/// request checks whose work grows with the request (bounded by the body
/// limit), which must not hold up the runtime threads.
pub async fn off_runtime<T: Send + 'static>(
    job: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(job)
        .await
        .map_err(|e| ApiError::Internal(format!("request check failed: {e}")))
}
