//! `GET /api/v1/costmaps/{id}/events`: a job's progress as Server-Sent
//! Events, on whichever server runs it: a job this process runs is
//! followed live in memory; one another process runs (a replica on the
//! same PostgreSQL database) through the notes its holder sends
//! ([`crate::jobs::JobNote`]), with a look at the job table every second
//! for what notes cannot tell (the error of a failure, a holder that
//! died, a note lost while reconnecting).

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::{Path, State};
use axum::response::sse::{Event, KeepAlive, Sse};
use futures_util::Stream;
use tokio::sync::{broadcast, mpsc};

use super::handlers::visible_costmap;
use super::model::{JobEvent, JobState, job_state};
use crate::auth::{Caller, Role};
use crate::error::{ApiError, Problem};
use crate::jobs::{JobNote, JobStatus};
use crate::state::AppState;

/// How often an event stream reads the row of a job another server runs.
const EVENTS_POLL: Duration = Duration::from_secs(1);
/// Least time between two progress events.
const EVENTS_MIN_GAP: Duration = Duration::from_millis(100);

fn event_of(state: &JobState, error: Option<String>) -> JobEvent {
    JobEvent {
        status: state.status,
        progress: state.progress,
        stage: state.stage,
        error,
    }
}

fn event_of_note(note: &JobNote) -> JobEvent {
    JobEvent {
        status: note.status,
        progress: note.progress,
        stage: note.stage,
        error: None,
    }
}

/// True when `read` (from the table) is older news than `last` (sent from
/// a note): the same run's progress, behind. The row is written less often
/// than notes are sent.
fn is_behind(read: &JobEvent, last: Option<&JobEvent>) -> bool {
    last.is_some_and(|l| {
        read.status == JobStatus::Running
            && l.status == JobStatus::Running
            && read.progress < l.progress
    })
}

fn sse_event(data: &JobEvent) -> Event {
    let kind = match data.status {
        JobStatus::Done => "done",
        JobStatus::Failed => "failed",
        JobStatus::Queued | JobStatus::Running => "progress",
    };
    Event::default()
        .event(kind)
        .json_data(data)
        .unwrap_or_else(|_| Event::default().event(kind))
}

/// Feed the events of job `id` to `tx` until the job ends, the client
/// goes, or the server shuts down.
async fn follow(state: AppState, id: String, tx: mpsc::Sender<Event>) {
    let jobs = state.costmaps.clone();
    // Subscribed before the first read, so no note after it is missed.
    let mut notes = jobs.notes();
    let mut last: Option<JobEvent> = None;
    // Send `ev` unless it repeats the last one; false once the client is gone.
    let send = |ev: JobEvent, last: &mut Option<JobEvent>| {
        let tx = tx.clone();
        let repeat = last.as_ref() == Some(&ev);
        *last = Some(ev.clone());
        async move { repeat || tx.send(sse_event(&ev)).await.is_ok() }
    };
    loop {
        // A job this process runs: follow its live progress until its
        // outcome is stored (the channel closes).
        if let Some(mut rx) = jobs.subscribe(&id) {
            loop {
                let live = *rx.borrow_and_update();
                let ev = JobEvent {
                    status: live.status,
                    progress: live.progress,
                    stage: live.stage,
                    error: None,
                };
                if !send(ev, &mut last).await {
                    return;
                }
                tokio::select! {
                    changed = rx.changed() => if changed.is_err() { break },
                    () = jobs.shutdown_signal() => return,
                    () = tx.closed() => return,
                }
                tokio::time::sleep(EVENTS_MIN_GAP).await;
            }
        }
        let row = match state.db.get_costmap(&id).await {
            Ok(Some(row)) => row,
            Ok(None) => {
                let ev = JobEvent {
                    status: JobStatus::Failed,
                    progress: last.as_ref().map_or(0.0, |l| l.progress),
                    stage: None,
                    error: Some("the costmap was deleted".into()),
                };
                send(ev, &mut last).await;
                return;
            }
            Err(e) => {
                tracing::warn!(costmap = %id, error = %e, "event stream cannot read the job");
                return;
            }
        };
        let Ok(state_now) = job_state(&row, jobs.live(&id)) else {
            return;
        };
        let finished = state_now.status.is_finished();
        let read = event_of(&state_now, row.error.clone());
        if !finished && is_behind(&read, last.as_ref()) {
            // Keep the newer progress the notes told.
        } else if !send(read, &mut last).await || finished {
            return;
        }
        // Queued or running on another server, or between two states
        // here: follow its notes until the next read of the row.
        let poll = tokio::time::sleep(EVENTS_POLL);
        tokio::pin!(poll);
        loop {
            tokio::select! {
                () = &mut poll => break,
                note = notes.recv() => match note {
                    Ok(note) if note.id == id => {
                        // An outcome is read from the row (a failure's
                        // error is there); so is a job now run here.
                        if note.status.is_finished() || jobs.live(&id).is_some() {
                            break;
                        }
                        if !send(event_of_note(&note), &mut last).await {
                            return;
                        }
                    }
                    Ok(_) | Err(broadcast::error::RecvError::Lagged(_)) => {}
                    // The notes outlive the server's jobs; should they end,
                    // the row alone is followed.
                    Err(broadcast::error::RecvError::Closed) => {
                        (&mut poll).await;
                        break;
                    }
                },
                () = jobs.shutdown_signal() => return,
                () = tx.closed() => return,
            }
        }
    }
}

/// The job's progress as Server-Sent Events: `progress` events (data
/// `{status, progress, stage}`) while it is queued or running, then one
/// `done` or `failed` (with `error`) event, and the stream ends. For a
/// finished job only the last event is sent. Comments keep the connection
/// alive.
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/events",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "An event stream: `event: progress|done|failed`, `data:` a JobEvent as JSON",
            content_type = "text/event-stream", body = JobEvent),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn costmap_events(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    // Checked once: a costmap never changes project, and a deleted one
    // ends the stream.
    visible_costmap(&state, &caller, &id, Role::Viewer).await?;
    let (tx, rx) = mpsc::channel(16);
    tokio::spawn(follow(state, id, tx));
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv().await.map(|ev| (Ok(ev), rx))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ev(status: JobStatus, progress: f64) -> JobEvent {
        JobEvent {
            status,
            progress,
            stage: None,
            error: None,
        }
    }

    #[test]
    fn a_row_behind_the_notes_is_not_sent() {
        let noted = ev(JobStatus::Running, 0.5);
        assert!(is_behind(&ev(JobStatus::Running, 0.3), Some(&noted)));
        assert!(!is_behind(&ev(JobStatus::Running, 0.5), Some(&noted)));
        assert!(!is_behind(&ev(JobStatus::Running, 0.7), Some(&noted)));
        // A change of status is news: taken over, queued again, finished.
        assert!(!is_behind(&ev(JobStatus::Queued, 0.0), Some(&noted)));
        assert!(!is_behind(&ev(JobStatus::Done, 1.0), Some(&noted)));
        assert!(!is_behind(&ev(JobStatus::Running, 0.3), None));
    }
}
