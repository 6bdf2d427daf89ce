//! An in-memory vehicle for the protocol engine's unit tests: it answers
//! the ground station's messages at once (no clock of its own), keeps a
//! list per mission type, and can drop or repeat its answers, refuse an
//! upload, change an item it stores, or say nothing at all.

// It can play an older autopilot, with MISSION_REQUEST.
#![allow(deprecated)]

use std::collections::{HashMap, VecDeque};

use mavlink::dialects::common::{
    MISSION_ACK_DATA, MISSION_COUNT_DATA, MISSION_ITEM_INT_DATA, MISSION_REQUEST_INT_DATA,
    MavMessage, MavMissionResult, MavMissionType,
};

use super::connection::{GCS_SYSTEM, Link, LinkError, Received};

#[derive(Default)]
pub(super) struct TestVehicle {
    pub lists: HashMap<u32, Vec<MISSION_ITEM_INT_DATA>>,
    /// Answer MISSION_COUNT with this result instead of taking the list.
    pub refuse_with: Option<MavMissionResult>,
    /// Drop every n-th answer (before it is sent).
    pub drop_every: Option<usize>,
    /// Send every n-th answer twice.
    pub repeat_every: Option<usize>,
    /// Add this to x of the stored item with this seq (a vehicle that
    /// stores something else than it was sent).
    pub corrupt: Option<(u16, i32)>,
    /// Answer nothing.
    pub silent: bool,
    /// Ask with the deprecated MISSION_REQUEST.
    pub legacy_requests: bool,
    receiving: Option<(MavMissionType, u16, Vec<MISSION_ITEM_INT_DATA>)>,
    /// The list last received in full: its type and count.
    completed: Option<(MavMissionType, u16)>,
    outbox: VecDeque<MavMessage>,
    answers: usize,
    /// Every message the ground station sent.
    pub heard: Vec<MavMessage>,
}

fn key(t: MavMissionType) -> u32 {
    t as u32
}

impl TestVehicle {
    fn answer(&mut self, m: MavMessage) {
        self.answers += 1;
        let n = self.answers;
        if self.drop_every.is_some_and(|k| n.is_multiple_of(k)) {
            return;
        }
        if self.repeat_every.is_some_and(|k| n.is_multiple_of(k)) {
            self.outbox.push_back(m.clone());
        }
        self.outbox.push_back(m);
    }

    fn ack(&mut self, mission_type: MavMissionType, result: MavMissionResult) {
        self.answer(MavMessage::MISSION_ACK(MISSION_ACK_DATA {
            target_system: GCS_SYSTEM,
            mavtype: result,
            mission_type,
            ..Default::default()
        }));
    }

    fn request(&mut self, mission_type: MavMissionType, seq: u16) {
        let m = if self.legacy_requests {
            MavMessage::MISSION_REQUEST(mavlink::dialects::common::MISSION_REQUEST_DATA {
                target_system: GCS_SYSTEM,
                seq,
                mission_type,
                ..Default::default()
            })
        } else {
            MavMessage::MISSION_REQUEST_INT(MISSION_REQUEST_INT_DATA {
                target_system: GCS_SYSTEM,
                seq,
                mission_type,
                ..Default::default()
            })
        };
        self.answer(m);
    }

    fn hear(&mut self, m: &MavMessage) {
        self.heard.push(m.clone());
        if self.silent {
            return;
        }
        match m {
            MavMessage::MISSION_COUNT(c) => {
                if let Some(r) = self.refuse_with {
                    self.ack(c.mission_type, r);
                } else if c.count == 0 {
                    self.lists.insert(key(c.mission_type), Vec::new());
                    self.ack(c.mission_type, MavMissionResult::MAV_MISSION_ACCEPTED);
                } else {
                    self.receiving = Some((c.mission_type, c.count, Vec::new()));
                    self.request(c.mission_type, 0);
                }
            }
            MavMessage::MISSION_ITEM_INT(item) => {
                let Some((t, count, mut got)) = self.receiving.take() else {
                    // The last item again after the list was complete:
                    // our MISSION_ACK was lost, so send it again.
                    if self.completed == Some((item.mission_type, item.seq + 1)) {
                        self.ack(item.mission_type, MavMissionResult::MAV_MISSION_ACCEPTED);
                    }
                    return;
                };
                let seq = usize::from(item.seq);
                // An older duplicate is ignored; a repeat of the last item
                // means our request was lost, so ask again (as PX4 does).
                if item.mission_type != t || seq + 1 < got.len() {
                    self.receiving = Some((t, count, got));
                    return;
                }
                if seq == got.len() {
                    let mut stored = item.clone();
                    if let Some((seq, dx)) = self.corrupt
                        && seq == item.seq
                    {
                        stored.x += dx;
                    }
                    got.push(stored);
                }
                if got.len() == usize::from(count) {
                    self.completed = Some((t, count));
                    self.lists.insert(key(t), got);
                    self.ack(t, MavMissionResult::MAV_MISSION_ACCEPTED);
                } else {
                    let next = got.len() as u16;
                    self.receiving = Some((t, count, got));
                    self.request(t, next);
                }
            }
            MavMessage::MISSION_REQUEST_LIST(r) => {
                let count = self.lists.get(&key(r.mission_type)).map_or(0, Vec::len) as u16;
                self.answer(MavMessage::MISSION_COUNT(MISSION_COUNT_DATA {
                    target_system: GCS_SYSTEM,
                    count,
                    mission_type: r.mission_type,
                    ..Default::default()
                }));
            }
            MavMessage::MISSION_REQUEST_INT(r) => {
                let item = self
                    .lists
                    .get(&key(r.mission_type))
                    .and_then(|l| l.get(usize::from(r.seq)))
                    .cloned();
                match item {
                    Some(mut item) => {
                        item.target_system = GCS_SYSTEM;
                        self.answer(MavMessage::MISSION_ITEM_INT(item));
                    }
                    None => self.ack(
                        r.mission_type,
                        MavMissionResult::MAV_MISSION_INVALID_SEQUENCE,
                    ),
                }
            }
            _ => {}
        }
    }
}

impl Link for TestVehicle {
    async fn send(&mut self, message: &MavMessage) -> Result<(), LinkError> {
        self.hear(message);
        Ok(())
    }

    async fn recv(&mut self) -> Result<Received, LinkError> {
        match self.outbox.pop_front() {
            Some(message) => Ok(Received { system: 1, message }),
            // Nothing more will come until the ground station speaks.
            None => std::future::pending().await,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::vehicle_link::exchange::{Options, Progress, ProtocolError, Stage};
    use crate::vehicle_link::items::{MissionKind, WireItem};
    use crate::vehicle_link::mission_file::ItemList;
    use crate::vehicle_link::transfer::send_and_verify;

    fn opts() -> Options {
        Options {
            timeout: Duration::from_millis(20),
            retries: 4,
            ..Options::default()
        }
    }

    fn list(kind: MissionKind, n: usize) -> ItemList {
        let command = match kind {
            MissionKind::Mission => 16,
            MissionKind::Fence => 5001,
            MissionKind::Rally => 5100,
        };
        ItemList {
            kind,
            items: (0..n)
                .map(|k| WireItem {
                    command,
                    frame: 3,
                    params: [k as f32, 0.0, 0.0, f32::NAN],
                    x: 520_000_000 + k as i32,
                    y: 51_000_000 - k as i32,
                    z: 40.0 + k as f32,
                    autocontinue: true,
                })
                .collect(),
            home_first: false,
        }
    }

    async fn send(
        v: &mut TestVehicle,
        lists: &[ItemList],
    ) -> (
        Result<Vec<crate::vehicle_link::transfer::Sent>, ProtocolError>,
        Vec<Progress>,
    ) {
        let mut seen = Vec::new();
        let r = send_and_verify(v, &opts(), lists, &mut |p| seen.push(p)).await;
        (r, seen)
    }

    #[tokio::test]
    async fn every_list_arrives_and_reads_back_equal() {
        let mut v = TestVehicle::default();
        let lists = [
            list(MissionKind::Mission, 12),
            list(MissionKind::Fence, 4),
            list(MissionKind::Rally, 2),
        ];
        let (r, progress) = send(&mut v, &lists).await;
        let sent = r.unwrap();
        assert_eq!(sent.iter().map(|s| s.items).collect::<Vec<_>>(), [12, 4, 2]);
        assert_eq!(v.lists[&0].len(), 12);
        assert_eq!(v.lists[&1].len(), 4);
        assert_eq!(v.lists[&2].len(), 2);
        assert_eq!(v.lists[&0][7].x, 520_000_007);
        assert!(v.lists[&0][7].param4.is_nan());
        // Progress ends each stage of each list at its total.
        for kind in [MissionKind::Mission, MissionKind::Fence, MissionKind::Rally] {
            for stage in [Stage::Upload, Stage::ReadBack] {
                let last = progress
                    .iter()
                    .rfind(|p| p.kind == kind && p.stage == stage)
                    .unwrap();
                assert_eq!(last.done, last.total, "{kind:?} {stage:?}");
            }
        }
    }

    #[tokio::test]
    async fn dropped_and_repeated_answers_are_recovered() {
        for (drop_every, repeat_every) in [
            (Some(3), None),
            (None, Some(2)),
            (Some(4), Some(3)),
            (Some(2), Some(5)),
        ] {
            let mut v = TestVehicle {
                drop_every,
                repeat_every,
                ..TestVehicle::default()
            };
            let (r, _) = send(
                &mut v,
                &[list(MissionKind::Mission, 9), list(MissionKind::Rally, 3)],
            )
            .await;
            assert!(r.is_ok(), "{drop_every:?} {repeat_every:?}: {r:?}");
            assert_eq!(v.lists[&0].len(), 9);
        }
    }

    #[tokio::test]
    async fn legacy_requests_get_int_items() {
        let mut v = TestVehicle {
            legacy_requests: true,
            ..TestVehicle::default()
        };
        let (r, _) = send(&mut v, &[list(MissionKind::Mission, 3)]).await;
        assert!(r.is_ok(), "{r:?}");
        assert!(
            v.heard
                .iter()
                .all(|m| !matches!(m, MavMessage::MISSION_ITEM(_)))
        );
    }

    #[tokio::test]
    async fn a_refusal_names_the_mission_result() {
        let mut v = TestVehicle {
            refuse_with: Some(MavMissionResult::MAV_MISSION_NO_SPACE),
            ..TestVehicle::default()
        };
        let (r, _) = send(&mut v, &[list(MissionKind::Fence, 3)]).await;
        let e = r.unwrap_err();
        assert!(matches!(e, ProtocolError::Rejected { .. }));
        assert_eq!(
            e.to_string(),
            "fence upload: the vehicle answered MAV_MISSION_NO_SPACE (the list has more items than the vehicle can store)"
        );
    }

    #[tokio::test]
    async fn a_silent_vehicle_times_out_after_the_retries() {
        let mut v = TestVehicle {
            silent: true,
            ..TestVehicle::default()
        };
        let (r, _) = send(&mut v, &[list(MissionKind::Mission, 3)]).await;
        let e = r.unwrap_err();
        assert_eq!(
            e.to_string(),
            "mission upload: timed out waiting for MISSION_REQUEST_INT for item 0 (or MISSION_ACK) (5 tries, 20ms each)"
        );
        // MISSION_COUNT 5 times, then the cancelling MISSION_ACK.
        let counts = v
            .heard
            .iter()
            .filter(|m| matches!(m, MavMessage::MISSION_COUNT(_)))
            .count();
        assert_eq!(counts, 5);
        assert!(matches!(
            v.heard.last(),
            Some(MavMessage::MISSION_ACK(a)) if a.mavtype == MavMissionResult::MAV_MISSION_OPERATION_CANCELLED
        ));
    }

    #[tokio::test]
    async fn a_changed_item_is_reported_as_a_mismatch() {
        let mut v = TestVehicle {
            corrupt: Some((2, 5)),
            ..TestVehicle::default()
        };
        let (r, _) = send(&mut v, &[list(MissionKind::Mission, 4)]).await;
        assert_eq!(
            r.unwrap_err().to_string(),
            "mission read-back differs from what was sent: item 2: x/y (520000007, 50999998) read back, (520000002, 50999998) sent"
        );
    }

    #[tokio::test]
    async fn an_empty_list_clears_the_vehicles() {
        let mut v = TestVehicle::default();
        v.lists.insert(2, vec![MISSION_ITEM_INT_DATA::default()]);
        let (r, _) = send(&mut v, &[list(MissionKind::Rally, 0)]).await;
        assert!(r.is_ok(), "{r:?}");
        assert!(v.lists[&2].is_empty());
    }
}
