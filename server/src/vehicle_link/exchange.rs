//! What upload and read-back share: the options (time-out, retries,
//! target), the protocol's errors, the MISSION_* messages built from and
//! read into [`WireItem`]s, and progress reports.

use std::time::Duration;

#[allow(deprecated)] // MISSION_ITEM: read from vehicles that still send it.
use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_ITEM_DATA, MISSION_ITEM_INT_DATA, MavCmd, MavFrame, MavMessage,
    MavMissionResult, MavMissionType,
};
use num_traits::FromPrimitive;

use super::connection::{GCS_SYSTEM, Link, LinkError};
use super::items::{MissionKind, WireItem, is_global_frame};

/// How long to wait for each answer and how often to ask again.
#[derive(Clone, Copy, Debug)]
pub struct Options {
    /// Wait this long for each expected message (MAVLink's mission
    /// protocol suggests 1.5 s; slow radios need more).
    pub timeout: Duration,
    /// Resend a message this many times before giving up.
    pub retries: u32,
    pub target_system: u8,
    pub target_component: u8,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            timeout: Duration::from_millis(1500),
            retries: 5,
            target_system: 1,
            target_component: 1,
        }
    }
}

/// Upload or read-back, for progress reports and messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Upload,
    ReadBack,
}

/// `done` of `total` items of a list sent or read back.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Progress {
    pub kind: MissionKind,
    pub stage: Stage,
    pub done: usize,
    pub total: usize,
}

/// Why a transfer failed.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("{kind} {stage}: timed out waiting for {waiting_for} ({tries} tries, {timeout:?} each)", kind = .kind.name(), stage = stage_name(*.stage))]
    TimedOut {
        kind: MissionKind,
        stage: Stage,
        waiting_for: String,
        tries: u32,
        timeout: Duration,
    },
    #[error("{kind} {stage}: the vehicle answered {result} ({meaning})", kind = .kind.name(), stage = stage_name(*.stage))]
    Rejected {
        kind: MissionKind,
        stage: Stage,
        /// The MAV_MISSION_RESULT's name, e.g. MAV_MISSION_NO_SPACE.
        result: String,
        meaning: &'static str,
    },
    #[error("{kind} {stage}: {why}", kind = .kind.name(), stage = stage_name(*.stage))]
    Protocol {
        kind: MissionKind,
        stage: Stage,
        why: String,
    },
    #[error("{kind} read-back differs from what was sent: {why}", kind = .kind.name())]
    Mismatch { kind: MissionKind, why: String },
}

fn stage_name(stage: Stage) -> &'static str {
    match stage {
        Stage::Upload => "upload",
        Stage::ReadBack => "read-back",
    }
}

pub(super) fn mav_type(kind: MissionKind) -> MavMissionType {
    match kind {
        MissionKind::Mission => MavMissionType::MAV_MISSION_TYPE_MISSION,
        MissionKind::Fence => MavMissionType::MAV_MISSION_TYPE_FENCE,
        MissionKind::Rally => MavMissionType::MAV_MISSION_TYPE_RALLY,
    }
}

/// Whether a message addressed to `target` is for us (0 = broadcast).
pub(super) fn for_us(target: u8) -> bool {
    target == 0 || target == GCS_SYSTEM
}

/// What each MAV_MISSION_RESULT means, for the error message.
pub(super) fn result_meaning(result: MavMissionResult) -> &'static str {
    use MavMissionResult::*;
    match result {
        MAV_MISSION_ACCEPTED => "accepted",
        MAV_MISSION_ERROR => "generic error",
        MAV_MISSION_UNSUPPORTED_FRAME => "a coordinate frame is not supported",
        MAV_MISSION_UNSUPPORTED => "a command or this mission type is not supported",
        MAV_MISSION_NO_SPACE => "the list has more items than the vehicle can store",
        MAV_MISSION_INVALID => "a parameter is invalid",
        MAV_MISSION_INVALID_PARAM1
        | MAV_MISSION_INVALID_PARAM2
        | MAV_MISSION_INVALID_PARAM3
        | MAV_MISSION_INVALID_PARAM4
        | MAV_MISSION_INVALID_PARAM5_X
        | MAV_MISSION_INVALID_PARAM6_Y
        | MAV_MISSION_INVALID_PARAM7 => "a parameter is out of range",
        MAV_MISSION_INVALID_SEQUENCE => "an item arrived out of sequence",
        MAV_MISSION_DENIED => "the vehicle is not accepting missions now",
        MAV_MISSION_OPERATION_CANCELLED => "the vehicle cancelled the transfer",
    }
}

pub(super) fn ack(opts: &Options, kind: MissionKind, result: MavMissionResult) -> MavMessage {
    MavMessage::MISSION_ACK(MISSION_ACK_DATA {
        target_system: opts.target_system,
        target_component: opts.target_component,
        mavtype: result,
        mission_type: mav_type(kind),
        ..Default::default()
    })
}

/// Lets the vehicle leave its transfer state after a failed transfer
/// rather than wait for its own time-out; the link may be dead, so a
/// failure to send is moot.
pub(super) async fn cancel_transfer<L: Link>(link: &mut L, opts: &Options, kind: MissionKind) {
    let cancelled = ack(
        opts,
        kind,
        MavMissionResult::MAV_MISSION_OPERATION_CANCELLED,
    );
    let _ = link.send(&cancelled).await;
}

/// Why a wire item could not be put in a MISSION_ITEM_INT.
pub fn item_message(
    opts: &Options,
    kind: MissionKind,
    seq: u16,
    item: &WireItem,
) -> Result<MavMessage, String> {
    let command = MavCmd::from_u16(item.command).ok_or_else(|| {
        format!(
            "item {seq}: command {} is not in MAVLink's common set",
            item.command
        )
    })?;
    let frame = MavFrame::from_u8(item.frame)
        .ok_or_else(|| format!("item {seq}: frame {} is not a MAV_FRAME", item.frame))?;
    let [param1, param2, param3, param4] = item.params;
    Ok(MavMessage::MISSION_ITEM_INT(MISSION_ITEM_INT_DATA {
        param1,
        param2,
        param3,
        param4,
        x: item.x,
        y: item.y,
        z: item.z,
        seq,
        command,
        target_system: opts.target_system,
        target_component: opts.target_component,
        frame,
        // Mission item 0 is the current one after an upload.
        current: 0,
        autocontinue: u8::from(item.autocontinue),
        mission_type: mav_type(kind),
    }))
}

pub(super) fn wire_of_int(m: &MISSION_ITEM_INT_DATA) -> WireItem {
    WireItem {
        command: m.command as u16,
        frame: m.frame as u8,
        params: [m.param1, m.param2, m.param3, m.param4],
        x: m.x,
        y: m.y,
        z: m.z,
        autocontinue: m.autocontinue != 0,
    }
}

/// A legacy MISSION_ITEM (float x/y) in wire form: degrees become ×1e7
/// integers as MISSION_ITEM_INT would carry them (float32 degrees are only
/// good to about 1e-6°, so a legacy vehicle's read-back may differ there).
#[allow(deprecated)] // MISSION_ITEM: read from vehicles that still send it.
pub(super) fn wire_of_float(m: &MISSION_ITEM_DATA) -> WireItem {
    let frame = m.frame as u8;
    let scale = if is_global_frame(frame) { 1e7 } else { 1.0 };
    let int = |v: f32| {
        (f64::from(v) * scale)
            .round()
            .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
    };
    WireItem {
        command: m.command as u16,
        frame,
        params: [m.param1, m.param2, m.param3, m.param4],
        x: int(m.x),
        y: int(m.y),
        z: m.z,
        autocontinue: m.autocontinue != 0,
    }
}
