//! Splitting coverage into pieces: with more UAVs than cells the longest
//! coverage path is halved until the counts match (thesis §5.5), and a
//! piece too long for one battery is cut into shorter ones.
//!
//! A path of several lanes is cut between two lanes, where its two parts
//! are closest in length (the link between them is not flown); a single
//! lane is cut at its middle.

use geo_types::Coord;
use serde::{Deserialize, Serialize};

use crate::coverage::{CellPlan, Lane};

/// Which part of a cell's planned lanes a piece flies: lanes
/// `first_lane .. first_lane + lanes` of the cell's plan, and of a single
/// lane only the stretch from `lane_from` to `lane_to` (fractions of its
/// length, in planned direction).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Piece {
    pub cell: usize,
    pub first_lane: usize,
    pub lanes: usize,
    pub lane_from: f64,
    pub lane_to: f64,
}

/// A piece of coverage and its flown path.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    pub piece: Piece,
    pub plan: CellPlan,
}

impl Part {
    /// A whole cell's plan.
    pub fn whole(plan: CellPlan) -> Part {
        Part {
            piece: Piece {
                cell: plan.cell_index,
                first_lane: 0,
                lanes: plan.lanes.len(),
                lane_from: 0.0,
                lane_to: 1.0,
            },
            plan,
        }
    }

    /// Cuts the part in two, near the middle of its path; `None` when it
    /// has no length to share.
    pub fn halve(&self) -> Option<(Part, Part)> {
        let plan = &self.plan;
        match plan.lanes.len() {
            0 => None,
            1 => self.cut_lane(0.5),
            n => {
                // Length up to the end of lane k (links before it included).
                let total = plan.length_m();
                let mut best: Option<(f64, usize)> = None;
                let mut run = 0.0;
                for k in 0..n - 1 {
                    run += dist(plan.lanes[k].start, plan.lanes[k].end);
                    let after_link = run + link_length(plan, k);
                    let rest = total - after_link;
                    let gap = (run - rest).abs();
                    if best.is_none_or(|(g, _)| gap < g) {
                        best = Some((gap, k + 1));
                    }
                    run = after_link;
                }
                let (_, k) = best?;
                Some(self.cut_between(k))
            }
        }
    }

    /// The first `k` lanes and the rest (the link between them dropped).
    fn cut_between(&self, k: usize) -> (Part, Part) {
        let plan = &self.plan;
        let head = CellPlan {
            cell_index: plan.cell_index,
            direction_deg: plan.direction_deg,
            lanes: plan.lanes[..k].to_vec(),
            links: plan.links[..k - 1].to_vec(),
        };
        let tail = CellPlan {
            cell_index: plan.cell_index,
            direction_deg: plan.direction_deg,
            lanes: plan.lanes[k..].to_vec(),
            links: plan.links[k..].to_vec(),
        };
        let p = &self.piece;
        (
            Part {
                piece: Piece {
                    lanes: k,
                    ..p.clone()
                },
                plan: head,
            },
            Part {
                piece: Piece {
                    first_lane: p.first_lane + k,
                    lanes: p.lanes - k,
                    ..p.clone()
                },
                plan: tail,
            },
        )
    }

    /// A one-lane part cut at fraction `t` of its length.
    fn cut_lane(&self, t: f64) -> Option<(Part, Part)> {
        let lane = self.plan.lanes[0];
        if dist(lane.start, lane.end) < 1e-3 {
            return None;
        }
        let mid = Coord {
            x: lane.start.x + t * (lane.end.x - lane.start.x),
            y: lane.start.y + t * (lane.end.y - lane.start.y),
        };
        let p = &self.piece;
        let at = p.lane_from + t * (p.lane_to - p.lane_from);
        let one = |lane: Lane, from: f64, to: f64| Part {
            piece: Piece {
                lane_from: from,
                lane_to: to,
                ..p.clone()
            },
            plan: CellPlan {
                lanes: vec![lane],
                links: vec![],
                ..self.plan.clone()
            },
        };
        Some((
            one(
                Lane {
                    start: lane.start,
                    end: mid,
                },
                p.lane_from,
                at,
            ),
            one(
                Lane {
                    start: mid,
                    end: lane.end,
                },
                at,
                p.lane_to,
            ),
        ))
    }
}

/// Halves the longest part (by `length`) until there are `count` parts or
/// nothing more can be halved (thesis §5.5: more UAVs than cells).
pub fn halve_until(
    mut parts: Vec<Part>,
    count: usize,
    length: impl Fn(&CellPlan) -> f64,
) -> Vec<Part> {
    let mut lengths: Vec<f64> = parts.iter().map(|p| length(&p.plan)).collect();
    while parts.len() < count {
        // Longest first; ties to the lowest index.
        let mut order: Vec<usize> = (0..parts.len()).collect();
        order.sort_by(|&a, &b| lengths[b].total_cmp(&lengths[a]).then(a.cmp(&b)));
        let Some((i, (a, b))) = order
            .into_iter()
            .find_map(|i| parts[i].halve().map(|halves| (i, halves)))
        else {
            break;
        };
        lengths[i] = length(&a.plan);
        lengths.insert(i + 1, length(&b.plan));
        parts[i] = a;
        parts.insert(i + 1, b);
    }
    parts
}

fn link_length(plan: &CellPlan, k: usize) -> f64 {
    let mut pts = vec![plan.lanes[k].end];
    if let Some(link) = plan.links.get(k) {
        pts.extend_from_slice(link);
    }
    pts.push(plan.lanes[k + 1].start);
    pts.windows(2).map(|w| dist(w[0], w[1])).sum()
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::test_support::{lawnmower, rect};
    use approx::assert_relative_eq;

    #[test]
    fn halving_a_lawnmower_keeps_every_lane_once() {
        let plan = lawnmower(3, &rect(0.0, 0.0, 70.0, 100.0), 7);
        let (a, b) = Part::whole(plan.clone()).halve().unwrap();
        assert_eq!(a.plan.lanes.len() + b.plan.lanes.len(), 7);
        // 3 + 4 and 4 + 3 lanes tie: the first cut wins.
        assert_eq!((a.piece.first_lane, a.piece.lanes), (0, 3));
        assert_eq!((b.piece.first_lane, b.piece.lanes), (3, 4));
        let mut lanes = a.plan.lanes.clone();
        lanes.extend(b.plan.lanes.clone());
        assert_eq!(lanes, plan.lanes);
        assert_eq!(a.plan.links.len(), 2);
        assert_eq!(b.plan.links.len(), 3);
    }

    #[test]
    fn a_single_lane_is_cut_at_its_middle() {
        let plan = lawnmower(0, &rect(0.0, 0.0, 10.0, 102.0), 1);
        let (a, b) = Part::whole(plan).halve().unwrap();
        assert_relative_eq!(a.plan.length_m(), 50.0, epsilon = 1e-9);
        assert_relative_eq!(b.plan.length_m(), 50.0, epsilon = 1e-9);
        assert_eq!((a.piece.lane_from, a.piece.lane_to), (0.0, 0.5));
        let (c, d) = b.halve().unwrap();
        assert_eq!((c.piece.lane_from, c.piece.lane_to), (0.5, 0.75));
        assert_eq!((d.piece.lane_from, d.piece.lane_to), (0.75, 1.0));
    }

    #[test]
    fn halves_the_longest_until_the_counts_match() {
        let parts = vec![
            Part::whole(lawnmower(0, &rect(0.0, 0.0, 40.0, 100.0), 4)),
            Part::whole(lawnmower(1, &rect(100.0, 0.0, 120.0, 50.0), 2)),
        ];
        let out = halve_until(parts, 5, CellPlan::length_m);
        assert_eq!(out.len(), 5);
        // Cell 0 (≈ 420 m) is halved first, then its halves (≈ 200 m) before
        // cell 1 (≈ 106 m).
        let per_cell = |c: usize| out.iter().filter(|p| p.piece.cell == c).count();
        assert_eq!((per_cell(0), per_cell(1)), (4, 1));
        let lanes: usize = out.iter().map(|p| p.plan.lanes.len()).sum();
        assert_eq!(lanes, 6, "no lane lost or doubled");
    }
}
