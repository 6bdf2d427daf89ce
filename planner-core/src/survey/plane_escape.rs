//! Ways through tight spots for a plane's transits, where no single Dubins
//! path between two poses keeps clear: through one pose nearby, or out of
//! a pocket by a quarter to three-quarter turn at either end.

use std::f64::consts::{FRAC_PI_2, PI};

use geo_types::Coord;

use super::plane_flight::PlaneFlight;
use crate::coverage::dubins::{Piece, Pose, end_pose};

impl PlaneFlight<'_> {
    /// Two clear Dubins words from `a` to `b` through a pose nearby (1 to 3
    /// turn radii from their midpoint, 8 directions and 8 headings), the
    /// shortest such; for turns too tight for one word.
    pub(super) fn detour(&self, a: Pose, b: Pose) -> Option<Vec<Piece>> {
        let r = self.turns.radius_m;
        let mid = (a.at + b.at) / 2.0;
        let mut best: Option<(f64, Vec<Piece>)> = None;
        for ring in 1..=3 {
            for k in 0..8 {
                let dir = k as f64 * std::f64::consts::FRAC_PI_4;
                let at = mid
                    + Coord {
                        x: ring as f64 * r * dir.cos(),
                        y: ring as f64 * r * dir.sin(),
                    };
                if self.blocked_at(at) {
                    continue;
                }
                for h in 0..8 {
                    let via = Pose::new(at, h as f64 * std::f64::consts::FRAC_PI_4);
                    let Some(first) = self.dubins_clear(a, via) else {
                        continue;
                    };
                    let Some(second) = self.dubins_clear(via, b) else {
                        continue;
                    };
                    let mut w = first;
                    w.extend(second);
                    let len: f64 = w.iter().map(Piece::length).sum();
                    if best.as_ref().is_none_or(|(l, _)| len < *l) {
                        best = Some((len, w));
                    }
                }
            }
            if best.is_some() {
                break;
            }
        }
        best.map(|(_, w)| w)
    }

    /// Out of a pocket: a clear quarter, half or three-quarter turn out of
    /// `a` to either side, and one into `b` (flown backwards from it), with
    /// a clear Dubins word between; the shortest such.
    pub(super) fn escape(&self, a: Pose, b: Pose) -> Option<Vec<Piece>> {
        let turns = |pose: Pose| -> Vec<Option<Piece>> {
            let mut out = vec![None];
            for side in [1.0, -1.0] {
                for quarters in 1..=3 {
                    let arc = self.arc_from(pose, side, f64::from(quarters) * FRAC_PI_2);
                    if self.clear(&arc) {
                        out.push(Some(arc));
                    }
                }
            }
            out
        };
        let back = |p: Pose| Pose::new(p.at, p.heading + PI);
        let mut best: Option<(f64, Vec<Piece>)> = None;
        for first in turns(a) {
            let from = first.as_ref().map_or(a, |arc| end_pose(arc, a.heading));
            for last in turns(back(b)) {
                // `last` is flown from b backwards: reversed, it ends in b.
                let into = last.as_ref().map(reverse_arc);
                let to = last
                    .as_ref()
                    .map_or(b, |arc| back(end_pose(arc, back(b).heading)));
                let Some(mid) = self.dubins_clear(from, to) else {
                    continue;
                };
                let mut w: Vec<Piece> = first.iter().copied().collect();
                w.extend(mid);
                w.extend(into);
                let len: f64 = w.iter().map(Piece::length).sum();
                if best.as_ref().is_none_or(|(l, _)| len < *l) {
                    best = Some((len, w));
                }
            }
        }
        best.map(|(_, w)| w)
    }
}

/// The arc flown the other way round.
fn reverse_arc(arc: &Piece) -> Piece {
    match *arc {
        Piece::Arc {
            centre,
            radius,
            start,
            sweep,
        } => Piece::Arc {
            centre,
            radius,
            start: start + sweep,
            sweep: -sweep,
        },
        line => line,
    }
}
