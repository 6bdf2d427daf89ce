//! A corridor's bent lane as a plane flies it: legs too short for the turns
//! at both their ends merged into the corner of their neighbours' lines,
//! each bend rounded by an arc of the turn radius with the camera off, and
//! the lane split where no clear arc fits (its pieces are then entered
//! straight and joined by the plane's turns, like separate lanes).

use geo_types::Coord;

use super::plane_flight::{Entered, PlaneFlight};
use crate::coverage::Lane;
use crate::coverage::dubins::{Piece, Pose};

/// Sharpest bend rounded by one arc, radians (150°): sharper ones split
/// the lane.
const MAX_BEND: f64 = 2.618;
/// Least straight between the camera's stop or start and a bend's arc, m
/// (a leg of a few millimetres would be all but turned by the mission's
/// rounded positions).
const MIN_STRAIGHT_M: f64 = 1.0;
/// Least camera run left on a leg between two rounded bends, m.
const MIN_CAMERA_M: f64 = 1.0;

/// A leg of a bent lane: its line from `a` to `b` (moved to the corners
/// of its neighbours where legs between were merged) and the stretch the
/// camera may fly, `lo` to `hi` (the lane as laid, inside the corridor).
#[derive(Clone, Copy, Debug)]
struct Leg {
    a: Coord<f64>,
    b: Coord<f64>,
    lo: Coord<f64>,
    hi: Coord<f64>,
}

impl Leg {
    fn unit(&self) -> Coord<f64> {
        let d = self.b - self.a;
        d / d.x.hypot(d.y).max(1e-12)
    }

    fn heading(&self) -> f64 {
        let d = self.b - self.a;
        d.y.atan2(d.x)
    }

    /// Where along the line (from `a`) point `p` lies.
    fn along(&self, p: Coord<f64>) -> f64 {
        let u = self.unit();
        (p.x - self.a.x) * u.x + (p.y - self.a.y) * u.y
    }

    fn length(&self) -> f64 {
        dist(self.a, self.b)
    }
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// The signed turn from leg `a` to leg `b`, radians (left positive).
fn turn(a: &Leg, b: &Leg) -> f64 {
    let (u, v) = (a.unit(), b.unit());
    (u.x * v.y - u.y * v.x).atan2(u.x * v.x + u.y * v.y)
}

/// Where the lines of `a` and `b` meet, if they are not parallel.
fn corner(a: &Leg, b: &Leg) -> Option<Coord<f64>> {
    let (u, v) = (a.unit(), b.unit());
    let den = u.x * v.y - u.y * v.x;
    if den.abs() < 1e-9 {
        return None;
    }
    let w = b.a - a.a;
    let t = (w.x * v.y - w.y * v.x) / den;
    Some(a.a + u * t)
}

impl PlaneFlight<'_> {
    /// The legs of a bent lane (consecutive, joined end to start) as the
    /// plane flies them: each leg's camera stretch, and on every leg before
    /// a rounded bend the way round it (see the module's doc). Legs nothing
    /// of which is left (pulled back from a no-fly zone) are left out.
    pub(super) fn bent_lane(&self, lanes: &[Lane]) -> Vec<Entered> {
        let mut legs: Vec<Leg> = lanes
            .iter()
            .filter(|l| dist(l.start, l.end) > 1e-9)
            .map(|l| Leg {
                a: l.start,
                b: l.end,
                lo: l.start,
                hi: l.end,
            })
            .collect();
        self.merge_short_legs(&mut legs);
        let mut round: Vec<bool> = legs
            .windows(2)
            .map(|w| turn(&w[0], &w[1]).abs() <= MAX_BEND)
            .collect();
        // Each failure splits one more bend: this ends.
        loop {
            match self.lay(&legs, &round) {
                Ok(out) => return out,
                Err(j) => round[j] = false,
            }
        }
    }

    /// How far before (and after) a bend of `theta` the camera stops: the
    /// arc's tangent length and the straight before it.
    fn bend_reach(&self, theta: f64) -> f64 {
        self.turns.radius_m * (theta.abs() / 2.0).tan() + self.bend_straight(theta)
    }

    /// The straight between the camera's stop and a bend's arc of `theta`:
    /// with it the leg to the arc's first corner (corners at most 30°
    /// apart) holds the turn rule, `radius · tan(step / 2)` within half of
    /// it, with a quarter to spare: short by a slight bend, so that the
    /// camera stops only just before it.
    fn bend_straight(&self, theta: f64) -> f64 {
        let corners = (theta.abs() / std::f64::consts::FRAC_PI_6).ceil().max(1.0);
        let half_step = (theta.abs() / corners / 2.0).tan();
        let need = (2.0 * self.radius - self.turns.radius_m).max(0.0) * half_step;
        1.25 * need + MIN_STRAIGHT_M
    }

    /// Legs too short for the bends at both their ends (turning the same
    /// way, less than [`MAX_BEND`] together) merged: their neighbours'
    /// lines meet at a corner instead (the round outside of a corridor's
    /// bend becomes the corner of its straight lanes).
    fn merge_short_legs(&self, legs: &mut Vec<Leg>) {
        loop {
            let short = (1..legs.len().saturating_sub(1)).find(|&k| {
                let (t0, t1) = (turn(&legs[k - 1], &legs[k]), turn(&legs[k], &legs[k + 1]));
                t0 * t1 > 0.0
                    && (t0 + t1).abs() <= MAX_BEND
                    && legs[k].length() < self.bend_reach(t0) + self.bend_reach(t1) + MIN_CAMERA_M
            });
            let Some(k) = short else { return };
            let Some(c) = corner(&legs[k - 1], &legs[k + 1]) else {
                return;
            };
            legs[k - 1].b = c;
            legs[k + 1].a = c;
            legs.remove(k);
        }
    }

    /// The legs laid with the bends `round[j]` (between legs j and j + 1)
    /// rounded; `Err(j)` names a rounded bend that cannot be flown (no
    /// camera stretch left beside it, or its arc not clear).
    fn lay(&self, legs: &[Leg], round: &[bool]) -> Result<Vec<Entered>, usize> {
        let n = legs.len();
        let mut laid: Vec<Option<Entered>> = Vec::with_capacity(n);
        for (i, leg) in legs.iter().enumerate() {
            let before = i > 0 && round[i - 1];
            let after = i + 1 < n && round[i];
            let len = leg.length();
            // The camera stretch along the line: within the lane as laid,
            // and clear of the bends' arcs and the runs before them.
            let from = leg.along(leg.lo).max(if before {
                self.bend_reach(turn(&legs[i - 1], leg))
            } else {
                f64::NEG_INFINITY
            });
            let to = leg.along(leg.hi).min(if after {
                len - self.bend_reach(turn(leg, &legs[i + 1]))
            } else {
                f64::INFINITY
            });
            let u = leg.unit();
            let lane = Lane {
                start: leg.a + u * from,
                end: leg.a + u * to,
            };
            let entered = (to - from >= MIN_CAMERA_M)
                .then(|| self.trim_ends(&lane, !before, !after))
                .flatten();
            if entered.is_none() {
                if before {
                    return Err(i - 1);
                }
                if after {
                    return Err(i);
                }
            }
            laid.push(entered);
        }
        for j in (0..n.saturating_sub(1)).filter(|&j| round[j]) {
            let (Some(a), Some(b)) = (&laid[j], &laid[j + 1]) else {
                return Err(j);
            };
            let bend = self.round_bend(&legs[j], &legs[j + 1], a.lane.end, b.lane.start);
            if !self.all_clear(&bend) {
                return Err(j);
            }
            if let Some(a) = laid[j].as_mut() {
                a.bend = Some(bend);
            }
        }
        Ok(laid.into_iter().flatten().collect())
    }

    /// From the camera's stop `off` on leg `a` round the bend into leg `b`
    /// to its start `on`: a straight, the arc tangent to both lines, a
    /// straight.
    fn round_bend(&self, a: &Leg, b: &Leg, off: Coord<f64>, on: Coord<f64>) -> Vec<Piece> {
        let theta = turn(a, b);
        let t = self.turns.radius_m * (theta.abs() / 2.0).tan();
        let into = a.b - a.unit() * t;
        let out = b.a + b.unit() * t;
        let side = if theta >= 0.0 { 1.0 } else { -1.0 };
        let mut pieces = vec![Piece::Line {
            from: off,
            to: into,
        }];
        if theta.abs() > 1e-9 {
            pieces.push(self.arc_from(Pose::new(into, a.heading()), side, theta.abs()));
        }
        pieces.push(Piece::Line { from: out, to: on });
        pieces.retain(|p| p.length() > 1e-9);
        pieces
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::ObstacleMap;
    use geo_types::coord;

    fn flight(obstacles: &ObstacleMap) -> PlaneFlight<'_> {
        let a = super::super::Aircraft {
            kind: super::super::AircraftType::FixedWing,
            turn_radius_m: Some(40.0),
            ..Default::default()
        };
        PlaneFlight::new(&a, 100.0, obstacles)
    }

    fn lane(x0: f64, y0: f64, x1: f64, y1: f64) -> Lane {
        Lane {
            start: coord! {x: x0, y: y0},
            end: coord! {x: x1, y: y1},
        }
    }

    #[test]
    fn a_bend_is_rounded_and_a_round_outside_merged_into_a_corner() {
        let none = ObstacleMap::new(&geo_types::MultiPolygon(vec![]), 0.0);
        let f = flight(&none);
        // East 500 m, then round a 90° left bend in three 30° chords of an
        // arc of 30 m (too short for the plane), then north 500 m.
        let r = 30.0;
        let mut pts = vec![coord! {x: 0.0, y: 0.0}, coord! {x: 500.0, y: 0.0}];
        for k in 1..=3 {
            let a = -std::f64::consts::FRAC_PI_2 + f64::from(k) * std::f64::consts::FRAC_PI_6;
            pts.push(coord! {x: 500.0 + r * a.cos(), y: r + r * a.sin()});
        }
        pts.push(coord! {x: 500.0 + r, y: 530.0});
        let lanes: Vec<Lane> = pts
            .windows(2)
            .map(|w| Lane {
                start: w[0],
                end: w[1],
            })
            .collect();
        let flown = f.bent_lane(&lanes);
        // Two camera stretches, the first with the way round the bend.
        assert_eq!(
            flown.len(),
            2,
            "{:?}",
            flown.iter().map(|e| e.lane).collect::<Vec<_>>()
        );
        let bend = flown[0].bend.as_ref().unwrap();
        assert!(flown[1].bend.is_none());
        // The camera stretches lie on the lane as laid.
        assert!(flown[0].lane.end.x < 500.0 && flown[0].lane.start == pts[0]);
        assert!((flown[1].lane.start.x - 530.0).abs() < 1e-6 && flown[1].lane.start.y > 30.0);
        // The way round: one arc of 90° at the planned radius, from the
        // first stretch's end to the second's start.
        let arcs: Vec<&Piece> = bend
            .iter()
            .filter(|p| matches!(p, Piece::Arc { .. }))
            .collect();
        assert_eq!(arcs.len(), 1);
        if let Piece::Arc { radius, sweep, .. } = *arcs[0] {
            assert!((radius - f.turns.radius_m).abs() < 1e-9);
            assert!(
                (sweep - std::f64::consts::FRAC_PI_2).abs() < 1e-6,
                "{sweep}"
            );
        }
        assert!(dist(bend[0].start(), flown[0].lane.end) < 1e-9);
        assert!(dist(bend[bend.len() - 1].end(), flown[1].lane.start) < 1e-6);
        for w in bend.windows(2) {
            assert!(dist(w[0].end(), w[1].start()) < 1e-6);
        }
        // Sharper than 150°: split (no way round), each piece pulled back
        // as a lane of its own.
        let hairpin = [lane(0.0, 0.0, 500.0, 0.0), lane(500.0, 0.0, 0.0, 60.0)];
        let flown = f.bent_lane(&hairpin);
        assert_eq!(flown.len(), 2);
        assert!(flown.iter().all(|e| e.bend.is_none()));
    }
}
