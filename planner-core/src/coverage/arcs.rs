//! A path of lines and arcs as waypoints that an autopilot cutting corners
//! still flies: every arc becomes the corners of a polygon circumscribed
//! about it, refined until at each waypoint `radius · tan(θ/2)` fits in
//! half of each adjacent leg (θ the turn there); and the rounded path such
//! an autopilot flies through the waypoints (tangent arcs of that radius).

use geo_types::Coord;

use super::dubins::Piece;

/// Planned arcs are this much wider than the turn radius: the circumscribed
/// polygon's corners then keep some slack where two arcs meet.
pub const ARC_SLACK: f64 = 1.1;
/// Widest turn at one waypoint of an arc, radians (30°).
const MAX_STEP: f64 = std::f64::consts::FRAC_PI_6;
/// Most corners one arc is refined to.
const MAX_CORNERS: usize = 2048;
/// Arcs turning less than this (radians) get no corner: the lines on either
/// side are written as one leg (a kink a hair off the planned arc; the
/// rounded path is checked as written).
const TINY_SWEEP: f64 = 1e-3;
/// An arc turning less than this (radians) next to another arc may lose
/// its corner (see [`waypoints`]).
pub const SLIGHT_SWEEP: f64 = 0.05;
/// Slack in the turn rule, metres (rounding).
pub const RULE_TOL_M: f64 = 1e-6;

/// A piece of a flown path and whether it is a survey lane (camera on).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flown {
    pub piece: Piece,
    pub lane: bool,
}

/// What a waypoint is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    /// Start or end of the path, or where lines meet.
    Point,
    /// The camera starts here.
    LaneStart,
    /// The camera stops here.
    LaneEnd,
    /// A corner of an arc's polygon.
    Corner,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waypoint {
    pub at: Coord<f64>,
    pub mark: Mark,
}

/// Why a path cannot be written under the turn rule.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("the turn at ({:.1}, {:.1}) does not fit the legs next to it at this turn radius", .at.x, .at.y)]
pub struct TurnRuleError {
    pub at: Coord<f64>,
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// Turn angle at `b` between legs `a→b` and `b→c`, radians in [0, π].
pub fn turn_angle(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>) -> f64 {
    let (u, v) = (b - a, c - b);
    let cross = u.x * v.y - u.y * v.x;
    let dot = u.x * v.x + u.y * v.y;
    cross.atan2(dot).abs()
}

/// The turn rule at waypoint `i` of `pts` (interior points only): by how
/// many metres `radius · tan(θ/2)` exceeds half the shorter adjacent leg
/// (≤ 0 when it holds).
pub fn rule_excess(pts: &[Coord<f64>], i: usize, radius: f64) -> f64 {
    if i == 0 || i + 1 >= pts.len() {
        return 0.0;
    }
    let theta = turn_angle(pts[i - 1], pts[i], pts[i + 1]);
    let half = dist(pts[i - 1], pts[i]).min(dist(pts[i], pts[i + 1])) / 2.0;
    radius * (theta / 2.0).tan() - half
}

/// The waypoints of `path` (its pieces joined end to start) for an
/// autopilot turning at `radius` (at most the arcs' radius / [`ARC_SLACK`]).
pub fn waypoints(path: &[Flown], radius: f64) -> Result<Vec<Waypoint>, TurnRuleError> {
    let mut corners: Vec<usize> = path
        .iter()
        .map(|f| match f.piece {
            Piece::Arc { sweep, .. } => ((sweep.abs() / MAX_STEP).ceil() as usize).max(1),
            Piece::Line { .. } => 0,
        })
        .collect();
    loop {
        let (wps, owner) = emit(path, &corners);
        let pts: Vec<Coord<f64>> = wps.iter().map(|w| w.at).collect();
        let mut refined = false;
        for i in 1..pts.len().saturating_sub(1) {
            if rule_excess(&pts, i, radius) <= RULE_TOL_M {
                continue;
            }
            let Some(arc) = owner[i] else {
                return Err(TurnRuleError { at: pts[i] });
            };
            // A slight arc (a Dubins micro-jog) next to another leaves its
            // corners too close to the other's: it is written with none
            // instead, like a tiny arc (not by a lane, which is entered and
            // left straight).
            let near: Vec<usize> = [owner[i - 1], Some(arc), owner[i + 1]]
                .into_iter()
                .flatten()
                .collect();
            if let Some(&slight) = near.iter().find(|&&o| {
                corners[o] > 0
                    && sweep_of(&path[o]) < SLIGHT_SWEEP
                    && near.iter().any(|&other| other != o)
                    && !by_a_lane(path, o)
            }) {
                corners[slight] = 0;
                refined = true;
                continue;
            }
            if corners[arc] >= MAX_CORNERS {
                return Err(TurnRuleError { at: pts[i] });
            }
            corners[arc] = (corners[arc] + 1).max(corners[arc] * 5 / 4);
            refined = true;
        }
        if !refined {
            return Ok(wps);
        }
    }
}

/// The waypoints with `corners[i]` corners on arc `i`, and the arc each
/// waypoint belongs to.
fn emit(path: &[Flown], corners: &[usize]) -> (Vec<Waypoint>, Vec<Option<usize>>) {
    let mut wps: Vec<Waypoint> = Vec::new();
    let mut owner: Vec<Option<usize>> = Vec::new();
    let Some(first) = path.first() else {
        return (wps, owner);
    };
    let mut push = |wps: &mut Vec<Waypoint>, at: Coord<f64>, mark: Mark, arc: Option<usize>| {
        wps.push(Waypoint { at, mark });
        owner.push(arc);
    };
    push(&mut wps, first.piece.start(), Mark::Point, None);
    let mut was_lane = false;
    for (i, f) in path.iter().enumerate() {
        if f.lane && !was_lane {
            // The lane starts here: a waypoint (the path's start is one).
            if i > 0 {
                push(&mut wps, f.piece.start(), Mark::LaneStart, None);
            } else if let Some(w) = wps.last_mut() {
                w.mark = Mark::LaneStart;
            }
        }
        if !f.lane && was_lane {
            push(&mut wps, f.piece.start(), Mark::LaneEnd, None);
        } else if i > 0 && f.lane == was_lane && corner_between(&path[i - 1].piece, &f.piece) {
            // Two lines meeting at an angle: the corner is a waypoint
            // (which the rule then judges).
            push(&mut wps, f.piece.start(), Mark::Point, None);
        }
        was_lane = f.lane;
        if let Piece::Arc {
            centre,
            radius,
            start,
            sweep,
        } = f.piece
            && sweep.abs() >= TINY_SWEEP
        {
            let k = corners[i];
            let step = sweep / k as f64;
            let reach = radius / (step.abs() / 2.0).cos();
            for j in 0..k {
                let a = start + step * (j as f64 + 0.5);
                push(
                    &mut wps,
                    centre
                        + Coord {
                            x: reach * a.cos(),
                            y: reach * a.sin(),
                        },
                    Mark::Corner,
                    Some(i),
                );
            }
        }
    }
    let end = path[path.len() - 1].piece.end();
    push(
        &mut wps,
        end,
        if was_lane { Mark::LaneEnd } else { Mark::Point },
        None,
    );
    // Points that coincide (a zero-length piece) are written once.
    let mut keep = vec![true; wps.len()];
    for i in 1..wps.len() {
        if dist(wps[i - 1].at, wps[i].at) < 1e-6 && wps[i].mark == Mark::Point {
            keep[i] = false;
        }
    }
    let mut k = keep.iter();
    wps.retain(|_| *k.next().unwrap_or(&true));
    let mut k = keep.iter();
    owner.retain(|_| *k.next().unwrap_or(&true));
    (wps, owner)
}

/// How far an arc turns (0 for a line), radians.
fn sweep_of(f: &Flown) -> f64 {
    match f.piece {
        Piece::Arc { sweep, .. } => sweep.abs(),
        Piece::Line { .. } => 0.0,
    }
}

/// Does a lane, or a line and then a lane, follow or precede `path[i]`?
fn by_a_lane(path: &[Flown], i: usize) -> bool {
    let lane_via_line = |steps: &mut dyn Iterator<Item = &Flown>| {
        steps
            .take(2)
            .try_for_each(|f| {
                if f.lane {
                    Err(true)
                } else if matches!(f.piece, Piece::Line { .. }) {
                    Ok(())
                } else {
                    Err(false)
                }
            })
            .err()
            .unwrap_or(false)
    };
    lane_via_line(&mut path[i + 1..].iter()) || lane_via_line(&mut path[..i].iter().rev())
}

/// Do two consecutive lines meet at an angle? Lines joined at less than
/// [`TINY_SWEEP`] (a Dubins word's rounding, or a straight of no length
/// between a lattice straight and the next line) are written as one leg,
/// like a tiny arc: a waypoint there would cut the leg next to an arc
/// too short for the arc's corners.
fn corner_between(a: &Piece, b: &Piece) -> bool {
    match (*a, *b) {
        (Piece::Line { from, to }, Piece::Line { to: next, .. }) => {
            dist(from, to) > 1e-9
                && dist(to, next) > 1e-9
                && turn_angle(from, to, next) >= TINY_SWEEP
        }
        _ => false,
    }
}

/// The path an autopilot turning at `radius` flies through `pts`: at each
/// interior waypoint the arc tangent to both legs, sampled every 5° at
/// most; the points in flight order.
pub fn rounded(pts: &[Coord<f64>], radius: f64) -> Vec<Coord<f64>> {
    let mut out = Vec::with_capacity(pts.len() * 2);
    let Some(&first) = pts.first() else {
        return out;
    };
    out.push(first);
    for i in 1..pts.len() {
        if i + 1 == pts.len() {
            out.push(pts[i]);
            break;
        }
        let (a, b, c) = (pts[i - 1], pts[i], pts[i + 1]);
        let theta = turn_angle(a, b, c);
        let (lab, lbc) = (dist(a, b), dist(b, c));
        if theta < 1e-9 || lab < 1e-12 || lbc < 1e-12 {
            out.push(b);
            continue;
        }
        let t = radius * (theta / 2.0).tan();
        let (u, v) = ((b - a) / lab, (c - b) / lbc);
        let p = b - u * t;
        // The centre: `radius` from the entry tangent point, on the inside.
        let left = u.x * v.y - u.y * v.x > 0.0;
        let normal = if left {
            Coord { x: -u.y, y: u.x }
        } else {
            Coord { x: u.y, y: -u.x }
        };
        let centre = p + normal * radius;
        let start = (p.y - centre.y).atan2(p.x - centre.x);
        let sweep = if left { theta } else { -theta };
        let n = ((theta / 5f64.to_radians()).ceil() as usize).max(1);
        for j in 0..=n {
            let a = start + sweep * j as f64 / n as f64;
            out.push(
                centre
                    + Coord {
                        x: radius * a.cos(),
                        y: radius * a.sin(),
                    },
            );
        }
    }
    out
}

/// Length of the rounded path through `pts` at `radius`.
pub fn rounded_length(pts: &[Coord<f64>], radius: f64) -> f64 {
    let mut len: f64 = pts.windows(2).map(|w| dist(w[0], w[1])).sum();
    for i in 1..pts.len().saturating_sub(1) {
        let theta = turn_angle(pts[i - 1], pts[i], pts[i + 1]);
        len -= 2.0 * radius * (theta / 2.0).tan() - radius * theta;
    }
    len
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coverage::dubins::{Pose, dubins_paths};
    use std::f64::consts::FRAC_PI_2;

    fn c(x: f64, y: f64) -> Coord<f64> {
        Coord { x, y }
    }

    fn lines(path: &[Piece], lane: bool) -> Vec<Flown> {
        path.iter().map(|&piece| Flown { piece, lane }).collect()
    }

    #[test]
    fn turn_rule_holds_on_every_dubins_word() {
        let r = 30.0;
        let a = Pose::new(c(0., 0.), FRAC_PI_2);
        for (gx, gh) in [
            (10.0, -FRAC_PI_2),
            (60.0, -FRAC_PI_2),
            (200.0, 0.3),
            (-5.0, 2.0),
        ] {
            let b = Pose::new(c(gx, 40.0), gh);
            for word in dubins_paths(a.ahead(r), b.ahead(-r), r * ARC_SLACK) {
                let mut path = vec![
                    Flown {
                        piece: Piece::Line {
                            from: a.ahead(-r).at,
                            to: a.at,
                        },
                        lane: true,
                    },
                    Flown {
                        piece: Piece::Line {
                            from: a.at,
                            to: a.ahead(r).at,
                        },
                        lane: false,
                    },
                ];
                path.extend(lines(&word, false));
                path.push(Flown {
                    piece: Piece::Line {
                        from: b.ahead(-r).at,
                        to: b.at,
                    },
                    lane: false,
                });
                let wps = waypoints(&path, r).unwrap();
                let pts: Vec<Coord<f64>> = wps.iter().map(|w| w.at).collect();
                for i in 1..pts.len() - 1 {
                    assert!(rule_excess(&pts, i, r) <= RULE_TOL_M, "{gx} {i}");
                }
                assert_eq!(wps[0].mark, Mark::LaneStart);
                assert_eq!(wps[1].mark, Mark::LaneEnd);
                // The rounded path runs between the planned arcs and their
                // polygons: a little longer than planned.
                let planned: f64 = path.iter().map(|f| f.piece.length()).sum();
                let flown = rounded_length(&pts, r);
                assert!(
                    flown >= planned - 1e-6 && flown < planned * 1.01,
                    "{flown} {planned}"
                );
                let r_pts = rounded(&pts, r);
                let sampled: f64 = r_pts.windows(2).map(|w| dist(w[0], w[1])).sum();
                assert!((sampled - flown).abs() < flown * 2e-3, "{sampled} {flown}");
            }
        }
    }

    #[test]
    fn a_tiny_jog_is_one_leg() {
        // Two arcs of 0.0003 rad beside a lane end: no corner, one leg.
        let r = 60.0;
        let a = Pose::new(c(0., 0.), 0.0);
        let b = Pose::new(c(100., 0.01), 0.0);
        let word = dubins_paths(a, b, r * ARC_SLACK).remove(0);
        assert!(word.iter().any(|p| matches!(p, Piece::Arc { .. })));
        let mut path = vec![Flown {
            piece: Piece::Line {
                from: c(-50., 0.),
                to: c(0., 0.),
            },
            lane: true,
        }];
        path.extend(lines(&word, false));
        let wps = waypoints(&path, r).unwrap();
        assert_eq!(wps.len(), 3, "{wps:?}");
    }

    #[test]
    fn a_sharp_corner_between_lines_is_refused() {
        let path = [
            Flown {
                piece: Piece::Line {
                    from: c(0., 0.),
                    to: c(10., 0.),
                },
                lane: false,
            },
            Flown {
                piece: Piece::Line {
                    from: c(10., 0.),
                    to: c(10., 10.),
                },
                lane: true,
            },
        ];
        assert!(waypoints(&path, 30.0).is_err());
        // The same corner is fine for a tiny radius.
        assert!(waypoints(&path, 1.0).is_ok());
    }
}
