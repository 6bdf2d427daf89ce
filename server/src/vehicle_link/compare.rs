//! The read-back compared with what was sent, item by item.
//!
//! Tolerances: command, frame, autocontinue and x/y (integer degrees ×1e7)
//! exactly; params 1-4 within 1e-4 × max(1, |sent|) and NaN only equal to
//! NaN (float32 both ways; the margin lets an autopilot that stores a
//! param in a narrower type through); z within 0.01 m (ArduPilot stores
//! altitudes in centimetres). Item 0 of a list sent with home first is
//! compared by command only: ArduPilot puts its own home there.

use super::items::WireItem;

pub const PARAM_RELATIVE_TOLERANCE: f32 = 1e-4;
pub const ALTITUDE_TOLERANCE_M: f32 = 0.01;

/// The first difference between `sent` and `got`, described.
pub fn first_difference(sent: &[WireItem], got: &[WireItem], home_first: bool) -> Option<String> {
    if sent.len() != got.len() {
        return Some(format!(
            "the vehicle holds {} items, {} were sent",
            got.len(),
            sent.len()
        ));
    }
    for (seq, (s, g)) in sent.iter().zip(got).enumerate() {
        if s.command != g.command {
            return Some(format!(
                "item {seq}: command {} read back, {} sent",
                g.command, s.command
            ));
        }
        if home_first && seq == 0 {
            continue;
        }
        if s.frame != g.frame {
            return Some(format!(
                "item {seq}: frame {} read back, {} sent",
                g.frame, s.frame
            ));
        }
        if s.autocontinue != g.autocontinue {
            return Some(format!(
                "item {seq}: autocontinue {} read back, {} sent",
                g.autocontinue, s.autocontinue
            ));
        }
        for (k, (&a, &b)) in s.params.iter().zip(&g.params).enumerate() {
            if !param_equal(a, b) {
                return Some(format!(
                    "item {seq}: param{} {b} read back, {a} sent",
                    k + 1
                ));
            }
        }
        if (s.x, s.y) != (g.x, g.y) {
            return Some(format!(
                "item {seq}: x/y ({}, {}) read back, ({}, {}) sent",
                g.x, g.y, s.x, s.y
            ));
        }
        if !((s.z - g.z).abs() <= ALTITUDE_TOLERANCE_M || (s.z.is_nan() && g.z.is_nan())) {
            return Some(format!(
                "item {seq}: altitude {} read back, {} sent",
                g.z, s.z
            ));
        }
    }
    None
}

fn param_equal(sent: f32, got: f32) -> bool {
    if sent.is_nan() || got.is_nan() {
        return sent.is_nan() && got.is_nan();
    }
    (sent - got).abs() <= PARAM_RELATIVE_TOLERANCE * sent.abs().max(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(x: i32) -> WireItem {
        WireItem {
            command: 16,
            frame: 3,
            params: [0.0, 0.0, 0.0, f32::NAN],
            x,
            y: 51_000_000,
            z: 40.0,
            autocontinue: true,
        }
    }

    #[test]
    fn equal_lists_have_no_difference() {
        let sent = vec![item(1), item(2)];
        assert_eq!(first_difference(&sent, &sent.clone(), false), None);
    }

    #[test]
    fn differences_are_named() {
        let sent = vec![item(1), item(2)];
        assert_eq!(
            first_difference(&sent, &sent[..1], false).as_deref(),
            Some("the vehicle holds 1 items, 2 were sent")
        );
        let mut got = sent.clone();
        got[1].x += 1;
        assert_eq!(
            first_difference(&sent, &got, false).as_deref(),
            Some("item 1: x/y (3, 51000000) read back, (2, 51000000) sent")
        );
        let mut got = sent.clone();
        got[0].params[3] = 0.0;
        assert_eq!(
            first_difference(&sent, &got, false).as_deref(),
            Some("item 0: param4 0 read back, NaN sent")
        );
        let mut got = sent.clone();
        got[0].z = 40.02;
        assert!(
            first_difference(&sent, &got, false)
                .unwrap()
                .contains("altitude")
        );
    }

    #[test]
    fn tolerances_hold_at_their_edges() {
        let sent = vec![item(1)];
        let mut got = sent.clone();
        got[0].z = 40.009;
        got[0].params[0] = 0.00009;
        assert_eq!(first_difference(&sent, &got, false), None);
        got[0].params[0] = 0.0002;
        assert!(first_difference(&sent, &got, false).is_some());
    }

    #[test]
    fn home_slot_is_compared_by_command_only() {
        let sent = vec![item(1), item(2)];
        let mut got = sent.clone();
        got[0].x = 999;
        got[0].z = 7.0;
        assert_eq!(first_difference(&sent, &got, true), None);
        assert!(first_difference(&sent, &got, false).is_some());
        got[0].command = 22;
        assert!(first_difference(&sent, &got, true).is_some());
    }
}
