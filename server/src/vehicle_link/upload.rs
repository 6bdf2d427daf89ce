//! Sending one list to the vehicle (MAVLink mission upload): MISSION_COUNT,
//! then the item the vehicle asks for with MISSION_REQUEST_INT (or the
//! deprecated MISSION_REQUEST, answered with MISSION_ITEM_INT as the
//! protocol asks of ground stations), until its MISSION_ACK.
//!
//! Time-outs: with no request yet, MISSION_COUNT is sent again; after an
//! item, that item is sent again (a lost request or item both end there).
//! Each message is tried `retries + 1` times, and only a request for a
//! new item restarts the wait, so a dead or looping vehicle ends the
//! transfer in bounded time.

use mavlink::dialects::common::{MISSION_COUNT_DATA, MavMessage, MavMissionResult};
use tokio::time::{Instant, timeout_at};

use super::connection::Link;
use super::exchange::{
    Options, Progress, ProtocolError, Stage, cancel_transfer, for_us, item_message, mav_type,
    result_meaning,
};
use super::items::{MissionKind, WireItem};

/// Send `items` as the vehicle's `kind` list.
pub async fn upload<L: Link>(
    link: &mut L,
    opts: &Options,
    kind: MissionKind,
    items: &[WireItem],
    progress: &mut (dyn FnMut(Progress) + Send),
) -> Result<(), ProtocolError> {
    let result = run(link, opts, kind, items, progress).await;
    if let Err(ProtocolError::TimedOut { .. } | ProtocolError::Protocol { .. }) = result {
        cancel_transfer(link, opts, kind).await;
    }
    result
}

// MISSION_REQUEST is deprecated but still sent by older autopilots.
#[allow(deprecated)]
async fn run<L: Link>(
    link: &mut L,
    opts: &Options,
    kind: MissionKind,
    items: &[WireItem],
    progress: &mut (dyn FnMut(Progress) + Send),
) -> Result<(), ProtocolError> {
    let total = items.len();
    let count = u16::try_from(total).map_err(|_| ProtocolError::Protocol {
        kind,
        stage: Stage::Upload,
        why: format!("{total} items: a MAVLink list holds at most 65535"),
    })?;
    // Build every message first: a file item the wire cannot carry is
    // found before the vehicle's list is touched.
    let messages = items
        .iter()
        .enumerate()
        .map(|(seq, item)| item_message(opts, kind, seq as u16, item))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|why| ProtocolError::Protocol {
            kind,
            stage: Stage::Upload,
            why,
        })?;
    let count_message = MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
        target_system: opts.target_system,
        target_component: opts.target_component,
        count,
        mission_type: mav_type(kind),
        ..Default::default()
    });
    let protocol = |why: String| ProtocolError::Protocol {
        kind,
        stage: Stage::Upload,
        why,
    };
    progress(Progress {
        kind,
        stage: Stage::Upload,
        done: 0,
        total,
    });
    link.send(&count_message).await?;
    let mut tries = 1;
    let mut deadline = Instant::now() + opts.timeout;
    // The item last sent; `done` items (0..done) have been sent. Only a
    // request for a new item restarts the wait: repeats and requests for
    // earlier items are answered without it, so a vehicle that never
    // moves on ends in a time-out. A repeat of the request just answered
    // is answered once per wait (each duplicate item draws another
    // request, so answering every copy would let repeats multiply).
    let mut last_sent: Option<u16> = None;
    let mut answered_again = false;
    let mut done = 0;
    loop {
        let received = match timeout_at(deadline, link.recv()).await {
            Ok(r) => r?,
            Err(_) => {
                if tries > opts.retries {
                    return Err(ProtocolError::TimedOut {
                        kind,
                        stage: Stage::Upload,
                        waiting_for: match last_sent {
                            None => "MISSION_REQUEST_INT for item 0 (or MISSION_ACK)".into(),
                            Some(s) if s + 1 == count => "MISSION_ACK".into(),
                            Some(s) => format!("MISSION_REQUEST_INT for item {}", s + 1),
                        },
                        tries,
                        timeout: opts.timeout,
                    });
                }
                tries += 1;
                answered_again = false;
                match last_sent {
                    None => link.send(&count_message).await?,
                    Some(s) => link.send(&messages[usize::from(s)]).await?,
                }
                deadline = Instant::now() + opts.timeout;
                continue;
            }
        };
        if received.system != opts.target_system {
            continue;
        }
        let requested = match &received.message {
            MavMessage::MISSION_REQUEST_INT(r)
                if r.mission_type == mav_type(kind) && for_us(r.target_system) =>
            {
                Some(r.seq)
            }
            MavMessage::MISSION_REQUEST(r)
                if r.mission_type == mav_type(kind) && for_us(r.target_system) =>
            {
                Some(r.seq)
            }
            MavMessage::MISSION_ACK(a)
                if a.mission_type == mav_type(kind) && for_us(a.target_system) =>
            {
                if a.mavtype != MavMissionResult::MAV_MISSION_ACCEPTED {
                    return Err(ProtocolError::Rejected {
                        kind,
                        stage: Stage::Upload,
                        result: format!("{:?}", a.mavtype),
                        meaning: result_meaning(a.mavtype),
                    });
                }
                if done == total {
                    progress(Progress {
                        kind,
                        stage: Stage::Upload,
                        done: total,
                        total,
                    });
                    return Ok(());
                }
                // An early ACCEPTED ends the vehicle's side with a list we
                // did not finish sending.
                return Err(protocol(format!(
                    "the vehicle accepted the list after {done} of {total} items"
                )));
            }
            _ => None,
        };
        let Some(seq) = requested else { continue };
        let Some(message) = messages.get(usize::from(seq)) else {
            return Err(protocol(format!(
                "the vehicle asked for item {seq} of a {total}-item list"
            )));
        };
        let fresh = usize::from(seq) + 1 > done;
        if !fresh && last_sent == Some(seq) && answered_again {
            continue;
        }
        answered_again = !fresh && last_sent == Some(seq);
        link.send(message).await?;
        last_sent = Some(seq);
        if !fresh {
            continue;
        }
        tries = 1;
        deadline = Instant::now() + opts.timeout;
        done = usize::from(seq) + 1;
        // The last item is done when the vehicle accepts the list.
        if done < total {
            progress(Progress {
                kind,
                stage: Stage::Upload,
                done,
                total,
            });
        }
    }
}
