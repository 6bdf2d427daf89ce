//! A job's live state in this process: its progress as it happens and
//! the flag that stops it.

use std::sync::atomic::{AtomicBool, Ordering};

use planner_core::costmap::Stage;
use tokio::sync::{Notify, watch};

use super::record::JobStatus;

/// A job's progress as it happens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Live {
    pub status: JobStatus,
    /// [0, 1].
    pub progress: f64,
    pub stage: Option<Stage>,
}

/// One job this process holds.
pub(super) struct JobHandle {
    pub(super) live: watch::Sender<Live>,
    /// Set by `DELETE` (and shutdown): the run stops at its next report.
    cancel: AtomicBool,
    /// Wakes a queued job that was cancelled.
    pub(super) cancelled: Notify,
}

impl JobHandle {
    /// A queued job's handle.
    pub(super) fn queued() -> JobHandle {
        JobHandle {
            live: watch::Sender::new(Live {
                status: JobStatus::Queued,
                progress: 0.0,
                stage: None,
            }),
            cancel: AtomicBool::new(false),
            cancelled: Notify::new(),
        }
    }

    pub(super) fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    pub(super) fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
        self.cancelled.notify_one();
    }
}
