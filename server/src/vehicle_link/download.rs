//! Reading a list back from the vehicle (MAVLink mission download):
//! MISSION_REQUEST_LIST, its MISSION_COUNT, MISSION_REQUEST_INT for each
//! item in turn (MISSION_ITEM_INT or the legacy MISSION_ITEM accepted),
//! then MISSION_ACK. Each request is sent at most `retries + 1` times.

use mavlink::dialects::common::{
    MISSION_REQUEST_INT_DATA, MISSION_REQUEST_LIST_DATA, MavMessage, MavMissionResult,
};
use tokio::time::{Instant, timeout_at};

use super::connection::Link;
use super::exchange::{
    Options, Progress, ProtocolError, Stage, ack, cancel_transfer, for_us, mav_type,
    result_meaning, wire_of_float, wire_of_int,
};
use super::items::{MissionKind, WireItem};

/// The vehicle's `kind` list.
pub async fn download<L: Link>(
    link: &mut L,
    opts: &Options,
    kind: MissionKind,
    progress: &mut (dyn FnMut(Progress) + Send),
) -> Result<Vec<WireItem>, ProtocolError> {
    let result = run(link, opts, kind, progress).await;
    if result.is_err() {
        cancel_transfer(link, opts, kind).await;
    }
    result
}

// MISSION_ITEM is deprecated but still sent by older autopilots.
#[allow(deprecated)]
async fn run<L: Link>(
    link: &mut L,
    opts: &Options,
    kind: MissionKind,
    progress: &mut (dyn FnMut(Progress) + Send),
) -> Result<Vec<WireItem>, ProtocolError> {
    let want = mav_type(kind);
    let list_request = MavMessage::MISSION_REQUEST_LIST(MISSION_REQUEST_LIST_DATA {
        target_system: opts.target_system,
        target_component: opts.target_component,
        mission_type: want,
    });
    let count = exchange(
        link,
        opts,
        kind,
        &list_request,
        "MISSION_COUNT",
        |m| match m {
            MavMessage::MISSION_COUNT(c) if c.mission_type == want && for_us(c.target_system) => {
                Some(c.count)
            }
            _ => None,
        },
    )
    .await?;
    let total = usize::from(count);
    let mut items = Vec::with_capacity(total);
    progress(Progress {
        kind,
        stage: Stage::ReadBack,
        done: 0,
        total,
    });
    for seq in 0..count {
        let request = MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
            target_system: opts.target_system,
            target_component: opts.target_component,
            seq,
            mission_type: want,
        });
        let waiting_for = format!("MISSION_ITEM_INT {seq}");
        let item = exchange(link, opts, kind, &request, &waiting_for, |m| match m {
            MavMessage::MISSION_ITEM_INT(m)
                if m.mission_type == want && m.seq == seq && for_us(m.target_system) =>
            {
                Some(wire_of_int(m))
            }
            MavMessage::MISSION_ITEM(m)
                if m.mission_type == want && m.seq == seq && for_us(m.target_system) =>
            {
                Some(wire_of_float(m))
            }
            _ => None,
        })
        .await?;
        items.push(item);
        progress(Progress {
            kind,
            stage: Stage::ReadBack,
            done: items.len(),
            total,
        });
    }
    link.send(&ack(opts, kind, MavMissionResult::MAV_MISSION_ACCEPTED))
        .await?;
    Ok(items)
}

/// Send `request` until `accept` takes an answer; a MISSION_ACK with an
/// error for this list ends the read-back. Other messages are skipped and
/// do not extend the wait.
async fn exchange<L: Link, T>(
    link: &mut L,
    opts: &Options,
    kind: MissionKind,
    request: &MavMessage,
    waiting_for: &str,
    accept: impl Fn(&MavMessage) -> Option<T>,
) -> Result<T, ProtocolError> {
    let want = mav_type(kind);
    for _ in 0..=opts.retries {
        link.send(request).await?;
        let deadline = Instant::now() + opts.timeout;
        while let Ok(received) = timeout_at(deadline, link.recv()).await {
            let received = received?;
            if received.system != opts.target_system {
                continue;
            }
            let message = received.message;
            if let Some(answer) = accept(&message) {
                return Ok(answer);
            }
            if let MavMessage::MISSION_ACK(a) = &message
                && a.mission_type == want
                && for_us(a.target_system)
                && a.mavtype != MavMissionResult::MAV_MISSION_ACCEPTED
            {
                return Err(ProtocolError::Rejected {
                    kind,
                    stage: Stage::ReadBack,
                    result: format!("{:?}", a.mavtype),
                    meaning: result_meaning(a.mavtype),
                });
            }
        }
    }
    Err(ProtocolError::TimedOut {
        kind,
        stage: Stage::ReadBack,
        waiting_for: waiting_for.to_string(),
        tries: opts.retries + 1,
        timeout: opts.timeout,
    })
}
