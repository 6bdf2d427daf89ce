//! Lanes as a plane flies them: a lead-in before and an overshoot after
//! each lane, the turn between two lanes (the shortest Dubins path, a loop
//! turn where the lanes are closer than two turn radii), and the lane order
//! of a cell that makes the turns shortest: back and forth, or skipping
//! lanes (the racetrack order of Fields2Cover's route planners).

use geo_types::Coord;

use super::dubins::{Piece, Pose, dubins_length, dubins_paths};
use super::{CellPlan, Lane};

/// How a plane enters and leaves lanes: turn radius (of the planned arcs)
/// and the straight runs before and after each lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneTurns {
    pub radius_m: f64,
    pub lead_in_m: f64,
    pub overshoot_m: f64,
}

/// The pose of a lane's start and of its end (heading along the lane).
pub fn lane_poses(lane: &Lane) -> (Pose, Pose) {
    let heading = (lane.end.y - lane.start.y).atan2(lane.end.x - lane.start.x);
    (Pose::new(lane.start, heading), Pose::new(lane.end, heading))
}

impl PlaneTurns {
    /// Every way from the end of lane `a` to the start of lane `b`:
    /// overshoot, a Dubins word, lead-in; shortest first.
    pub fn between(&self, a: &Lane, b: &Lane) -> Vec<Vec<Piece>> {
        let (_, end) = lane_poses(a);
        let (start, _) = lane_poses(b);
        self.between_poses(end, start)
    }

    /// Every way from pose `end` (a lane's end) to `start` (the next lane's
    /// start) through the overshoot and the lead-in, shortest first.
    pub fn between_poses(&self, end: Pose, start: Pose) -> Vec<Vec<Piece>> {
        let out = end.ahead(self.overshoot_m);
        let lead = start.ahead(-self.lead_in_m);
        dubins_paths(out, lead, self.radius_m)
            .into_iter()
            .map(|word| {
                let mut path = Vec::with_capacity(word.len() + 2);
                if self.overshoot_m > 0.0 {
                    path.push(Piece::Line {
                        from: end.at,
                        to: out.at,
                    });
                }
                path.extend(word);
                if self.lead_in_m > 0.0 {
                    path.push(Piece::Line {
                        from: lead.at,
                        to: start.at,
                    });
                }
                path
            })
            .collect()
    }

    /// Length of the shortest turn from lane `a` to lane `b`.
    pub fn turn_length(&self, a: &Lane, b: &Lane) -> f64 {
        let (_, end) = lane_poses(a);
        let (start, _) = lane_poses(b);
        self.overshoot_m
            + self.lead_in_m
            + dubins_length(
                end.ahead(self.overshoot_m),
                start.ahead(-self.lead_in_m),
                self.radius_m,
            )
    }

    /// The horizontal length a plane flies over a cell's plan: its lanes
    /// and the turns between them (lead-ins and overshoots included).
    pub fn plan_length(&self, plan: &CellPlan) -> f64 {
        let lanes: f64 = plan.lanes.iter().map(|l| dist(l.start, l.end)).sum();
        let turns: f64 = plan
            .lanes
            .windows(2)
            .map(|w| self.turn_length(&w[0], &w[1]))
            .sum();
        lanes + turns
    }

    /// The plan's lanes in the order (and directions) a plane turns
    /// between most quickly: back and forth, or skipping lanes in blocks
    /// (racetrack) where neighbours are closer than two turn radii. The
    /// first lane keeps its direction; links are straight (the plane's
    /// turns replace them).
    pub fn order(&self, plan: &CellPlan) -> CellPlan {
        let n = plan.lanes.len();
        let mut out = plan.clone();
        out.links = vec![Vec::new(); n.saturating_sub(1)];
        if n < 3 {
            return out;
        }
        // Lanes by their offset across the lane direction.
        let forward = plan.lanes[0].end - plan.lanes[0].start;
        let len = forward.x.hypot(forward.y).max(1e-12);
        let (u, normal) = (
            forward / len,
            Coord {
                x: -forward.y / len,
                y: forward.x / len,
            },
        );
        let canonical: Vec<Lane> = plan
            .lanes
            .iter()
            .map(|l| {
                let d = l.end - l.start;
                if d.x * u.x + d.y * u.y >= 0.0 {
                    *l
                } else {
                    Lane {
                        start: l.end,
                        end: l.start,
                    }
                }
            })
            .collect();
        let offset = |l: &Lane| {
            let m = (l.start + l.end) / 2.0;
            m.x * normal.x + m.y * normal.y
        };
        let mut sorted: Vec<usize> = (0..n).collect();
        sorted.sort_by(|&a, &b| offset(&canonical[a]).total_cmp(&offset(&canonical[b])));
        // Flown from the side the plan starts on.
        if sorted[n - 1] == 0 {
            sorted.reverse();
        }
        let spacing = (offset(&canonical[sorted[n - 1]]) - offset(&canonical[sorted[0]])).abs()
            / (n - 1) as f64;
        let widest = if spacing > 1e-9 {
            ((2.0 * self.radius_m / spacing).ceil() as usize + 1).min(n)
        } else {
            1
        };
        let mut best: Option<(f64, Vec<Lane>)> = None;
        for m in 1..=widest.max(1) {
            let lanes: Vec<Lane> = racetrack(n, m)
                .into_iter()
                .enumerate()
                .map(|(j, k)| {
                    let l = canonical[sorted[k]];
                    if j % 2 == 0 {
                        l
                    } else {
                        Lane {
                            start: l.end,
                            end: l.start,
                        }
                    }
                })
                .collect();
            let first_flipped = dist(lanes[0].start, plan.lanes[0].start) > 1e-9;
            let lanes = if first_flipped {
                lanes
                    .iter()
                    .map(|l| Lane {
                        start: l.end,
                        end: l.start,
                    })
                    .collect()
            } else {
                lanes
            };
            let cost: f64 = lanes
                .windows(2)
                .map(|w| self.turn_length(&w[0], &w[1]))
                .sum();
            if best.as_ref().is_none_or(|(c, _)| cost < c - 1e-6) {
                best = Some((cost, lanes));
            }
        }
        if let Some((_, lanes)) = best {
            out.lanes = lanes;
        }
        out
    }
}

/// The racetrack order of `n` lanes (by offset) skipping `m − 1`: in blocks
/// of `2m`, lanes b, b+m, b+1, b+m+1, …; `m = 1` is back and forth.
fn racetrack(n: usize, m: usize) -> Vec<usize> {
    if m <= 1 {
        return (0..n).collect();
    }
    let mut out = Vec::with_capacity(n);
    let mut base = 0;
    while base < n {
        let block = (n - base).min(2 * m);
        // A short last block is split in two halves as even as it allows.
        let half = block.div_ceil(2);
        for i in 0..half {
            out.push(base + i);
            if half + i < block {
                out.push(base + half + i);
            }
        }
        base += block;
    }
    out
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::coord;

    fn grid(n: usize, spacing: f64) -> CellPlan {
        let lanes: Vec<Lane> = (0..n)
            .map(|i| {
                let x = i as f64 * spacing;
                let (a, b) = (coord! {x: x, y: 0.0}, coord! {x: x, y: 300.0});
                if i % 2 == 0 {
                    Lane { start: a, end: b }
                } else {
                    Lane { start: b, end: a }
                }
            })
            .collect();
        CellPlan {
            cell_index: 0,
            direction_deg: 0.0,
            links: vec![Vec::new(); n - 1],
            lanes,
        }
    }

    #[test]
    fn racetrack_visits_every_lane_once() {
        for n in 1..30 {
            for m in 1..6 {
                let mut r = racetrack(n, m);
                r.sort_unstable();
                assert_eq!(r, (0..n).collect::<Vec<_>>(), "{n} {m}");
            }
        }
        assert_eq!(racetrack(8, 3), vec![0, 3, 1, 4, 2, 5, 6, 7]);
    }

    #[test]
    fn close_lanes_are_skipped_wide_ones_flown_in_turn() {
        let turns = PlaneTurns {
            radius_m: 40.0,
            lead_in_m: 40.0,
            overshoot_m: 40.0,
        };
        // Spacing 100 m ≥ 2 radii: back and forth is best.
        let wide = grid(6, 100.0);
        assert_eq!(turns.order(&wide).lanes, wide.lanes);
        // Spacing 20 m: skipping lanes is shorter than loop turns.
        let close = grid(12, 20.0);
        let ordered = turns.order(&close);
        let before = turns.plan_length(&close);
        let after = turns.plan_length(&ordered);
        assert!(after < before * 0.9, "{after} {before}");
        assert_eq!(ordered.lanes[0], close.lanes[0]);
        // Every lane flown once, directions alternating.
        let mut xs: Vec<i64> = ordered
            .lanes
            .iter()
            .map(|l| l.start.x.round() as i64)
            .collect();
        xs.sort_unstable();
        assert_eq!(xs, (0..12).map(|i| i * 20).collect::<Vec<i64>>());
        for w in ordered.lanes.windows(2) {
            assert!((w[0].end.y - w[1].start.y).abs() < 1e-9);
        }
    }
}
