//! `POST /api/v1/surveys/{id}/uavs/{uav}/upload`: a stored survey's
//! mission (and fence and rally points) sent to a vehicle over MAVLink with
//! the `vehicle_link` engine — uploaded, read back and compared — with the
//! progress streamed back as Server-Sent Events in the answer itself.
//!
//! Faults found before anything is sent are problem+json answers: links
//! switched off or no such survey/UAV (404), an address not on
//! `--vehicle-links` or a viewer (403), an address in use (409), a bad body
//! (422). After that the answer is an event stream that ends with `done`
//! or `failed` (a NACK, a time-out, a read-back that differs). A client
//! that goes away stops the upload: the vehicle is sent MISSION_ACK
//! OPERATION_CANCELLED and the link closed.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::{Path, State};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use planner_core::geo::Issue;
use serde::Serialize;
use tokio::sync::mpsc;
use utoipa::ToSchema;

use super::request::{UploadRequest, lists_of, read_request};
use crate::api::access::visible;
use crate::api::json_body::JsonBody;
use crate::auth::{Caller, Role};
use crate::error::{ApiError, Problem};
use crate::jobs::CostmapJobs;
use crate::state::{AppState, off_runtime};
use crate::vehicle_link::busy::Claim;
use crate::vehicle_link::transfer::{Sent, cancel};
use crate::vehicle_link::{
    ItemList, MavlinkLink, MissionKind, Options, Progress, Stage, VehicleAddress, send_and_verify,
};

/// Least time between two progress events of one list (its first and
/// last are always sent): a browser needs no more, and a slow client
/// cannot make the queue grow with the items.
const PROGRESS_GAP: Duration = Duration::from_millis(100);

/// The failure of an upload the server's stop (SIGTERM) ended.
const SHUTTING_DOWN: &str =
    "the service is shutting down: the upload was stopped; send it again when the service is back";

/// The answer while uploads are switched off.
const LINKS_OFF: &str = "vehicle links are switched off on this service: its operator starts it \
                         with --vehicle-links ADDR,... to name the vehicles it may reach";

/// One event of an upload's stream; `event` is also the SSE event name.
#[derive(Clone, Debug, Serialize, ToSchema)]
pub struct UploadEvent {
    /// `started` (the lists and their sizes), `progress` (items of a list
    /// sent or read back), `verified` (a list read back equal to what was
    /// sent), then `done` or `failed`, the last.
    event: &'static str,
    /// The vehicle's address.
    to: String,
    /// `started`: the lists to send, in order.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<Object>>)]
    lists: Option<Vec<Sent>>,
    /// `progress`, `verified`, `failed`: the list (`mission`, `fence` or
    /// `rally`; none when the link itself failed).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<String>)]
    kind: Option<MissionKind>,
    /// `progress`: `upload` or `read_back`.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<String>)]
    stage: Option<Stage>,
    /// `progress`: items done of `total`; `verified`: the list's items.
    #[serde(skip_serializing_if = "Option::is_none")]
    done: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    total: Option<usize>,
    /// `done`: what arrived, every list read back equal (`{kind, items}`).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<Object>>)]
    sent: Option<Vec<Sent>>,
    /// `failed`: what went wrong, in plain words (e.g. `fence upload: the
    /// vehicle answered MAV_MISSION_NO_SPACE (…)`).
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

impl UploadEvent {
    fn new(event: &'static str, to: &str) -> UploadEvent {
        UploadEvent {
            event,
            to: to.to_string(),
            lists: None,
            kind: None,
            stage: None,
            done: None,
            total: None,
            sent: None,
            error: None,
        }
    }

    fn sse(&self) -> Event {
        Event::default()
            .event(self.event)
            .json_data(self)
            .unwrap_or_else(|_| Event::default().event(self.event))
    }
}

/// Send UAV `uav`'s mission of survey `id` to a vehicle: uploaded with the
/// MAVLink mission protocol, read back and compared item by item. The
/// answer is an event stream (`event: started|progress|verified|done|failed`,
/// `data:` an UploadEvent as JSON) ending with `done` or `failed`. One
/// upload per vehicle address at a time; closing the stream stops the
/// upload. Needs the editor role in the survey's project, and an address
/// the service's `--vehicle-links` allows: without that flag the endpoint
/// answers 404.
#[utoipa::path(
    post,
    path = "/api/v1/surveys/{id}/uavs/{uav}/upload",
    tag = "vehicle-links",
    params(
        ("id" = String, Path, description = "Survey id"),
        ("uav" = String, Path, description = "UAV id"),
    ),
    request_body(content = UploadRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "The upload's progress as an event stream: `event: started|progress|verified|done|failed`, `data:` an UploadEvent as JSON",
            content_type = "text/event-stream", body = UploadEvent),
        (status = 403, description = "The address is not one of the service's vehicle links (`serve --vehicle-links`), or the caller is a viewer of the survey's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "Vehicle links are switched off (the service was started without `--vehicle-links`), or no such survey or UAV", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Another upload to this address is running", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A bad member of the body (each named by its JSON pointer), e.g. a malformed address or a missing sortie number", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn upload_to_vehicle(
    State(state): State<AppState>,
    caller: Caller,
    Path((id, uav)): Path<(String, String)>,
    body: Result<JsonBody, ApiError>,
) -> Result<Response, ApiError> {
    let links = state.vehicle_links.clone();
    if !links.enabled() {
        return Err(ApiError::NotFound(LINKS_OFF.into()));
    }
    let row = state.db.get_survey(&id).await?;
    let row = visible(&state.db, &caller, row, "survey", &id, Role::Editor).await?;
    let JsonBody(body) = body?;
    let (req, opts) = read_request(&body)?;
    let address = VehicleAddress::parse(&req.to)
        .map_err(|e| ApiError::Validation(vec![Issue::new("/to", &e.to_string())]))?;
    if !links.allows(&address) {
        let allowed: Vec<String> = links.allowed().iter().map(|p| p.to_string()).collect();
        return Err(ApiError::Forbidden(format!(
            "{address} is not one of the vehicle links this service may reach \
             (serve --vehicle-links): {}",
            allowed.join(", ")
        )));
    }
    let lists = off_runtime(move || lists_of(&row.plan, &id, &uav, &req, &opts)).await??;
    let claim = links.claim(&address).ok_or_else(|| {
        ApiError::Conflict(format!(
            "{address} is busy: another upload to it is running; retry when it has ended"
        ))
    })?;
    let (tx, rx) = mpsc::unbounded_channel();
    // The server's graceful stop (SIGTERM) ends an upload too, rather than
    // wait for it: the same signal ends the costmap event streams.
    let jobs = state.costmaps.clone();
    tokio::spawn(run(address, opts, lists, tx, claim, jobs));
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv()
            .await
            .map(|ev: UploadEvent| (Ok::<_, Infallible>(ev.sse()), rx))
    });
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response())
}

/// Forwards a list's progress: its first and last report, and others at
/// most every [`PROGRESS_GAP`].
struct Throttle {
    last: Option<Instant>,
}

impl Throttle {
    fn pass(&mut self, p: &Progress) -> bool {
        let now = Instant::now();
        let edge = p.done == 0 || p.done == p.total;
        if edge
            || self
                .last
                .is_none_or(|t| now.duration_since(t) >= PROGRESS_GAP)
        {
            self.last = Some(now);
            true
        } else {
            false
        }
    }
}

fn progress_event(to: &str, p: Progress) -> UploadEvent {
    UploadEvent {
        kind: Some(p.kind),
        stage: Some(p.stage),
        done: Some(p.done),
        total: Some(p.total),
        ..UploadEvent::new("progress", to)
    }
}

fn failed(to: &str, kind: Option<MissionKind>, error: String) -> UploadEvent {
    UploadEvent {
        kind,
        error: Some(error),
        ..UploadEvent::new("failed", to)
    }
}

/// The upload, holding `_claim` on the address until it ends; events go
/// to `tx`. The client going away (`tx` closed) or the server stopping
/// (`jobs`' shutdown signal) stops it.
async fn run(
    address: VehicleAddress,
    opts: Options,
    lists: Vec<ItemList>,
    tx: mpsc::UnboundedSender<UploadEvent>,
    _claim: Claim,
    jobs: Arc<CostmapJobs>,
) {
    let to = address.to_string();
    let started = UploadEvent {
        lists: Some(
            lists
                .iter()
                .map(|l| Sent {
                    kind: l.kind,
                    items: l.items.len(),
                })
                .collect(),
        ),
        ..UploadEvent::new("started", &to)
    };
    if tx.send(started).is_err() {
        return;
    }
    let open = MavlinkLink::open(&address, opts.timeout * (opts.retries + 1));
    let opened = tokio::select! {
        opened = open => opened,
        () = tx.closed() => return,
        () = jobs.shutdown_signal() => {
            let _ = tx.send(failed(&to, None, SHUTTING_DOWN.into()));
            return;
        }
    };
    let mut link = match opened {
        Ok(link) => link,
        Err(e) => {
            let _ = tx.send(failed(&to, None, format!("{to}: {e}")));
            return;
        }
    };
    let mut sent = Vec::with_capacity(lists.len());
    for list in &lists {
        let events = tx.clone();
        let mut throttle = Throttle { last: None };
        let to_ = to.clone();
        let mut on_progress = move |p: Progress| {
            if throttle.pass(&p) {
                let _ = events.send(progress_event(&to_, p));
            }
        };
        let step = send_and_verify(
            &mut link,
            &opts,
            std::slice::from_ref(list),
            &mut on_progress,
        );
        let outcome = tokio::select! {
            result = step => Ok(result),
            () = tx.closed() => Err(None),
            () = jobs.shutdown_signal() => Err(Some(SHUTTING_DOWN)),
        };
        match outcome {
            // Stopped mid-transfer: let the vehicle leave it too; the link
            // closes as `link` is dropped.
            Err(why) => {
                tracing::info!(to = %to, kind = list.kind.name(), why = why.unwrap_or("the client went away"), "upload stopped");
                cancel(&mut link, &opts, list.kind).await;
                if let Some(why) = why {
                    let _ = tx.send(failed(&to, Some(list.kind), why.into()));
                }
                return;
            }
            Ok(Err(e)) => {
                tracing::info!(to = %to, error = %e, "upload failed");
                let _ = tx.send(failed(&to, Some(list.kind), format!("{to}: {e}")));
                return;
            }
            Ok(Ok(mut done)) => {
                let _ = tx.send(UploadEvent {
                    kind: Some(list.kind),
                    done: Some(list.items.len()),
                    total: Some(list.items.len()),
                    ..UploadEvent::new("verified", &to)
                });
                sent.append(&mut done);
            }
        }
    }
    let _ = tx.send(UploadEvent {
        sent: Some(sent),
        ..UploadEvent::new("done", &to)
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(done: usize, total: usize) -> Progress {
        Progress {
            kind: MissionKind::Mission,
            stage: Stage::Upload,
            done,
            total,
        }
    }

    #[test]
    fn throttle_keeps_the_first_and_last_report_of_a_list() {
        let mut t = Throttle { last: None };
        assert!(t.pass(&p(0, 100)));
        // Right after the first: dropped, unless it is the last.
        assert!(!t.pass(&p(1, 100)));
        assert!(t.pass(&p(100, 100)));
    }

    #[test]
    fn events_serialize_with_their_members_only() {
        let ev = failed("udpout:127.0.0.1:1", Some(MissionKind::Fence), "x".into());
        assert_eq!(
            serde_json::to_value(&ev).unwrap(),
            serde_json::json!({"event": "failed", "to": "udpout:127.0.0.1:1",
                               "kind": "fence", "error": "x"})
        );
        let ev = progress_event("a", p(3, 9));
        assert_eq!(
            serde_json::to_value(&ev).unwrap(),
            serde_json::json!({"event": "progress", "to": "a", "kind": "mission",
                               "stage": "upload", "done": 3, "total": 9})
        );
    }
}
