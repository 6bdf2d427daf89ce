//! The pieces a plane flies on a sortie, in order: each cell's lanes pulled
//! back from the no-fly zones (a corridor's bent lanes laid round their
//! bends), the climb-out, the turns and transits between lanes (worked out
//! side by side), a lane no way reaches flown the other way or left out,
//! and the way home to the first landing approach a transit reaches.

use geo_types::Coord;

use super::cells::dist;
use super::plane_flight::{Entered, PlaneFlight};
use super::request::PlanError;
use crate::coverage::Lane;
use crate::coverage::airframe::lane_poses;
use crate::coverage::arcs::Flown;
use crate::coverage::dubins::{Piece, Pose};
use crate::flock::Tour;

impl PlaneFlight<'_> {
    /// The pieces of `tour` flown from `home` and back, and the lengths
    /// (lanes, transits).
    pub(super) fn pieces(&self, tour: &Tour, home: Coord<f64>) -> Result<Flight, PlanError> {
        let mut f = Flight::default();
        let lanes = self.laid_lanes(tour);
        let climb_out = self.departure(&mut f, home, &lanes)?;
        let (at, from_lane) = self.fly_lanes(&mut f, &lanes, climb_out)?;
        self.way_home(&mut f, home, at, from_lane)?;
        Ok(f)
    }

    /// Each cell's lanes pulled back from the no-fly zones (a corridor's
    /// bent lanes laid round their bends), the cells side by side; cells
    /// with nothing left are left out.
    fn laid_lanes(&self, tour: &Tour) -> Vec<Vec<Entered>> {
        use rayon::prelude::*;
        let token = crate::cancel::current();
        tour.visits
            .par_iter()
            .map(|visit| {
                token.scope(|| {
                    let mut kept = Vec::new();
                    // A corridor's bent lane is a run of legs (an area's
                    // lanes are runs of one).
                    for run in visit.runs() {
                        if run.len() == 1 {
                            kept.extend(self.trim(&visit.lanes[run.start]));
                        } else {
                            kept.extend(self.bent_lane(&visit.lanes[run]));
                        }
                    }
                    kept
                })
            })
            .filter(|kept| !kept.is_empty())
            .collect()
    }

    /// The climb-out: straight out of the take-off, towards the first lane;
    /// where it ends.
    fn departure(
        &self,
        f: &mut Flight,
        home: Coord<f64>,
        lanes: &[Vec<Entered>],
    ) -> Result<Pose, PlanError> {
        let first_target = lanes
            .first()
            .and_then(|c| c.first())
            .map_or(home, |l| l.lane.start);
        let heading = if dist(home, first_target) > 1e-9 {
            Pose::towards(home, first_target).heading
        } else {
            0.0
        };
        let climb_out = self
            .straight_at_home(home, heading, self.turns.radius_m)
            .ok_or_else(|| self.fault(home, "the climb-out"))?;
        f.push_transit(vec![Piece::Line {
            from: home,
            to: climb_out.at,
        }]);
        Ok(climb_out)
    }

    /// Every lane flown in turn from pose `at` (a lane no way reaches,
    /// either way round, left out); the pose after the last and its
    /// overshoot.
    fn fly_lanes(
        &self,
        f: &mut Flight,
        lanes: &[Vec<Entered>],
        mut at: Pose,
    ) -> Result<(Pose, Option<f64>), PlanError> {
        // The overshoot after the lane last flown, if any.
        let mut from_lane: Option<f64> = None;
        // A lane no way reaches (either way round) is left out, and the
        // coverage figure of the lanes flown shows it; the first such
        // fault is the plan's when no lane is reached at all.
        let mut fault = None;
        let mut ahead = self.ways_ahead(lanes);
        // The lane last flown: its place in `ahead` and whether reversed.
        let mut last: Option<(usize, bool)> = None;
        let mut k = 0;
        for cell in lanes {
            let mut prev: Option<Entered> = None;
            for entered in cell {
                k += 1;
                // The way worked out ahead is this one's if the lane before
                // was flown as laid.
                let mut known = (k >= 2 && last == Some((k - 2, false)))
                    .then(|| ahead.get_mut(k - 2).and_then(Option::take))
                    .flatten();
                let mut reached = None;
                // A leg of a bent lane is flown the way its bends go.
                let in_chain =
                    entered.bend.is_some() || prev.as_ref().is_some_and(|p| p.bend.is_some());
                let ways = if in_chain {
                    vec![entered.clone()]
                } else {
                    vec![entered.clone(), entered.reversed()]
                };
                for (n, way_round) in ways.into_iter().enumerate() {
                    let way = match known.take().filter(|_| n == 0) {
                        Some(way) => way,
                        None => self.way_to(at, from_lane, prev.as_ref(), &way_round),
                    };
                    match way {
                        Ok(way) => {
                            reached = Some((way_round, way, n == 1));
                            break;
                        }
                        Err(e @ PlanError::Invalid(_)) => {
                            fault.get_or_insert(e);
                        }
                        Err(e) => return Err(e),
                    }
                }
                let Some((entered, way, reversed)) = reached else {
                    continue;
                };
                last = Some((k - 1, reversed));
                if prev.is_some() {
                    f.push_turn(way);
                } else {
                    f.push_transit(way);
                }
                f.push_lane(&entered.lane);
                at = lane_poses(&entered.lane).1;
                from_lane = Some(entered.over);
                prev = Some(entered);
            }
        }
        if let Some(e) = fault.filter(|_| f.lanes.is_empty()) {
            return Err(e);
        }
        Ok((at, from_lane))
    }

    /// From pose `at` (after the overshoot `from_lane` of the lane last
    /// flown) home by the first landing direction a transit reaches.
    fn way_home(
        &self,
        f: &mut Flight,
        home: Coord<f64>,
        at: Pose,
        from_lane: Option<f64>,
    ) -> Result<(), PlanError> {
        let (out, mut way) = match from_lane {
            Some(over) => {
                let out = at.ahead(over);
                let line = Piece::Line {
                    from: at.at,
                    to: out.at,
                };
                (out, vec![line])
            }
            None => (at, Vec::new()),
        };
        let mut landing = None;
        let mut fault = None;
        for approach in self.landings(home, at)? {
            match self.connect(out, approach) {
                Ok(w) => {
                    way.extend(w);
                    landing = Some(approach);
                    break;
                }
                Err(e @ PlanError::Invalid(_)) => {
                    fault.get_or_insert(e);
                }
                Err(e) => return Err(e),
            }
        }
        let Some(landing) = landing else {
            return Err(fault.unwrap_or_else(|| self.fault(home, "the landing approach")));
        };
        f.push_transit(way);
        f.push_transit(vec![Piece::Line {
            from: landing.at,
            to: home,
        }]);
        Ok(())
    }

    /// The way from each lane to the next as laid (`[k]` from the k-th to
    /// the (k + 1)-th, a turn within a cell, a transit between cells),
    /// worked out side by side: each depends on those two lanes alone, and
    /// the flight takes it where it flies them in turn (no lane between
    /// left out or reversed).
    fn ways_ahead(&self, lanes: &[Vec<Entered>]) -> Vec<Option<Result<Vec<Piece>, PlanError>>> {
        use rayon::prelude::*;
        let flat: Vec<(usize, &Entered)> = lanes
            .iter()
            .enumerate()
            .flat_map(|(c, cell)| cell.iter().map(move |e| (c, e)))
            .collect();
        let token = crate::cancel::current();
        flat.par_windows(2)
            .map(|w| {
                let ((ca, a), (cb, b)) = (w[0], w[1]);
                let end = lane_poses(&a.lane).1;
                let prev = (ca == cb).then_some(a);
                Some(token.scope(|| self.way_to(end, Some(a.over), prev, b)))
            })
            .collect()
    }

    /// The way to lane `next` from pose `at`: the turn from `prev` (the
    /// lane before in its cell) if any, else a transit, after the
    /// overshoot `over` of the lane last flown if any.
    fn way_to(
        &self,
        at: Pose,
        over: Option<f64>,
        prev: Option<&Entered>,
        next: &Entered,
    ) -> Result<Vec<Piece>, PlanError> {
        let (start, _) = lane_poses(&next.lane);
        if let Some(p) = prev {
            // Round the bend into the next leg of a bent lane.
            if let Some(bend) = &p.bend
                && bend
                    .last()
                    .is_some_and(|b| dist(b.end(), next.lane.start) < 1e-6)
            {
                return Ok(bend.clone());
            }
            return self.lane_turn(p, next);
        }
        if let Some(over) = over {
            return self.around(at, over, start, next.lead);
        }
        let lead = start.ahead(-next.lead);
        let mut w = self.connect(at, lead)?;
        w.push(Piece::Line {
            from: lead.at,
            to: start.at,
        });
        Ok(w)
    }

    /// Where the final straight to the landing may start ([`PlaneFlight::final_m`]
    /// before home): the clear directions, the one nearest to arriving
    /// straight from `from` first.
    fn landings(&self, home: Coord<f64>, from: Pose) -> Result<Vec<Pose>, PlanError> {
        let base = if dist(from.at, home) > 1e-9 {
            Pose::towards(from.at, home).heading
        } else {
            from.heading
        };
        let out: Vec<Pose> = self.straights_at_home(home, base, -self.final_m).collect();
        if out.is_empty() {
            return Err(self.fault(home, "the landing approach"));
        }
        Ok(out)
    }

    /// A straight of `length` m out of `home` (into it when negative),
    /// headed as near `base` as the keep-out area allows (in 15° steps);
    /// its far end.
    pub(super) fn straight_at_home(
        &self,
        home: Coord<f64>,
        base: f64,
        length: f64,
    ) -> Option<Pose> {
        self.straights_at_home(home, base, length).next()
    }

    /// Every clear straight of [`PlaneFlight::straight_at_home`], the
    /// nearest to `base` first.
    fn straights_at_home(
        &self,
        home: Coord<f64>,
        base: f64,
        length: f64,
    ) -> impl Iterator<Item = Pose> + '_ {
        (0..24).filter_map(move |k| {
            let turn = (k as f64 / 2.0).ceil() * if k % 2 == 0 { 1.0 } else { -1.0 };
            let pose = Pose::new(home, base + turn * std::f64::consts::PI / 12.0).ahead(length);
            (self.obstacles.is_clear(pose.at, home) && !self.blocked_at(pose.at)).then_some(pose)
        })
    }
}

/// The pieces of a sortie and what they add up to.
#[derive(Default)]
pub(super) struct Flight {
    pub path: Vec<Flown>,
    pub lanes: Vec<Lane>,
    pub transit_m: f64,
}

impl Flight {
    /// Appends `pieces`, each joined to the one before where they are one
    /// arc or one line (a lattice path's arcs of one circle): fewer
    /// waypoints, and no corner pair at a join too close for the turn rule.
    fn push(&mut self, pieces: Vec<Piece>, lane: bool) {
        for piece in pieces.into_iter().filter(|p| p.length() > 1e-9) {
            if let Some(last) = self.path.last_mut()
                && last.lane == lane
                && !lane
                && let Some(joined) = last.piece.joined(&piece)
            {
                last.piece = joined;
                continue;
            }
            self.path.push(Flown { piece, lane });
        }
    }

    fn push_transit(&mut self, pieces: Vec<Piece>) {
        self.transit_m += pieces.iter().map(Piece::length).sum::<f64>();
        self.push(pieces, false);
    }

    fn push_turn(&mut self, pieces: Vec<Piece>) {
        self.push(pieces, false);
    }

    fn push_lane(&mut self, lane: &Lane) {
        self.lanes.push(*lane);
        self.push(
            vec![Piece::Line {
                from: lane.start,
                to: lane.end,
            }],
            true,
        );
    }
}
