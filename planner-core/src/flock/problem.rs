//! The flock assignment problem (SPEC §3.5): UAVs with a home and a speed,
//! jobs (pieces of coverage, each flown in one go and in either direction)
//! and the priced legs between them.
//!
//! Every policy works on this one model, so their results compare: a UAV's
//! mission time is the 3D length flown (transits and jobs) over its speed
//! plus a penalty per turn. Turns at the junctions between a transit and a
//! lane are counted on the leg, with the lane's direction known from the
//! job's end, so legs and jobs add up to the turns of the whole flown path.

use std::collections::HashMap;

use geo_types::Coord;

use super::transit::{ObstacleMap, TransitError, polyline_length};
use crate::coverage::CellPlan;

/// Cost of work a UAV cannot reach and come back from within its battery:
/// huge but finite, so that scores still compare.
pub const INFEASIBLE_S: f64 = 1e9;

/// Heading changes above this many degrees count as turns.
pub const TURN_THRESHOLD_DEG: f64 = 10.0;

/// One UAV as the assignment sees it: planning coordinates (UTM metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlockUav {
    pub home: Coord<f64>,
    pub speed_m_s: f64,
}

/// Where a job is entered or left, and the next point flown inside it (the
/// lane's direction at that end, for counting the turn there).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JobEnd {
    pub at: Coord<f64>,
    pub inner: Coord<f64>,
}

/// A piece of coverage flown in one go: a cell's lawnmower path, or part of
/// it after a split. Way 0 flies it as planned (in at `ends[0]`, out at
/// `ends[1]`), way 1 backwards.
#[derive(Clone, Debug, PartialEq)]
pub struct FlockJob {
    pub ends: [JobEnd; 2],
    /// Horizontal length of the flown path, m.
    pub length_m: f64,
    /// 3D length flown (over terrain), m; `length_m` when flat.
    pub length_3d_m: f64,
    /// Turns inside the job (between its lanes).
    pub turns: usize,
    /// The other two corners, where the tour optimiser may also enter and
    /// leave (the first lane's end and the last lane's start).
    pub across: [Coord<f64>; 2],
    /// A lower bound of the job's horizontal length however it is flown:
    /// its lanes plus the straight gap between each two consecutive lanes.
    pub least_length_m: f64,
    /// Lanes in the job (a turn at least between each two).
    pub lanes: usize,
}

impl FlockJob {
    /// The job flying `plan`; `None` for a plan without lanes.
    pub fn from_plan(plan: &CellPlan, length_3d_m: f64) -> Option<FlockJob> {
        let path = plan.path();
        let (&first, &last) = (path.first()?, path.last()?);
        // A degenerate one-point path still has a direction-less end.
        let second = path.iter().copied().find(|&p| p != first).unwrap_or(first);
        let before_last = path
            .iter()
            .rev()
            .copied()
            .find(|&p| p != last)
            .unwrap_or(last);
        let lanes = &plan.lanes;
        let d = |a: Coord<f64>, b: Coord<f64>| (b.x - a.x).hypot(b.y - a.y);
        let gaps: f64 = lanes
            .windows(2)
            .map(|w| {
                [w[0].start, w[0].end]
                    .iter()
                    .flat_map(|&p| [w[1].start, w[1].end].map(|q| d(p, q)))
                    .fold(f64::INFINITY, f64::min)
            })
            .sum();
        let (first_lane, last_lane) = (lanes.first()?, lanes.last()?);
        Some(FlockJob {
            across: [first_lane.end, last_lane.start],
            least_length_m: lanes.iter().map(|l| d(l.start, l.end)).sum::<f64>() + gaps,
            lanes: lanes.len(),
            ends: [
                JobEnd {
                    at: first,
                    inner: second,
                },
                JobEnd {
                    at: last,
                    inner: before_last,
                },
            ],
            length_m: plan.length_m(),
            length_3d_m,
            turns: count_turns(&path),
        })
    }

    /// End where way `way` enters the job.
    pub fn entry(&self, way: u8) -> Coord<f64> {
        self.ends[usize::from(way & 1)].at
    }

    /// End where way `way` leaves the job.
    pub fn exit(&self, way: u8) -> Coord<f64> {
        self.ends[usize::from(!way & 1)].at
    }
}

/// One job in a route, flown in `way` (0 as planned, 1 backwards).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Visit {
    pub job: usize,
    pub way: u8,
}

impl Visit {
    pub fn new(job: usize, way: u8) -> Visit {
        Visit { job, way: way & 1 }
    }

    pub fn reversed(self) -> Visit {
        Visit::new(self.job, self.way ^ 1)
    }
}

/// The jobs of each UAV in flight order (`routes[u]` for `uavs[u]`).
pub type Routes = Vec<Vec<Visit>>;

/// A priced transit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leg {
    pub length_m: f64,
    pub length_3d_m: f64,
    /// Turns along the transit and at both its junctions.
    pub turns: u32,
}

/// 3D length of a transit polyline flown at transit height; the flags say
/// which ends are a home (take-off or landing) rather than a job end.
pub type Lift<'a> = dyn Fn(&[Coord<f64>], [bool; 2]) -> f64 + 'a;

/// Identifies a leg end: `Home(u)` or the end `end` (0/1) of job `job`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stop {
    Home(usize),
    End { job: usize, end: u8 },
}

impl Stop {
    /// Where UAV `u` is before flying `v`'s job: the entry end.
    pub fn entry_of(v: Visit) -> Stop {
        Stop::End {
            job: v.job,
            end: v.way & 1,
        }
    }

    /// Where the UAV is after flying `v`'s job: the exit end.
    pub fn exit_of(v: Visit) -> Stop {
        Stop::End {
            job: v.job,
            end: !v.way & 1,
        }
    }
}

/// A leg's price and its polyline, as memoised.
type PricedLeg = (Leg, Vec<Coord<f64>>);

/// The flock problem with memoised NFZ-avoiding legs.
pub struct Flock<'a> {
    pub uavs: Vec<FlockUav>,
    pub jobs: Vec<FlockJob>,
    /// Seconds added per turn.
    pub turn_penalty_s: f64,
    /// Battery endurance per UAV, s (see [`Flock::route_time`]).
    pub batteries: Vec<Option<f64>>,
    obstacles: &'a ObstacleMap,
    lift: Option<&'a Lift<'a>>,
    /// Flat surveys: the climb after take-off and the descent before
    /// landing, added to every leg from or to a home.
    flat_altitude_m: f64,
    memo: HashMap<(Stop, Stop), PricedLeg>,
}

impl<'a> Flock<'a> {
    /// A flock over flat ground flown at `altitude_m`.
    pub fn flat(
        uavs: Vec<FlockUav>,
        jobs: Vec<FlockJob>,
        turn_penalty_s: f64,
        obstacles: &'a ObstacleMap,
        altitude_m: f64,
    ) -> Flock<'a> {
        Flock::new(uavs, jobs, turn_penalty_s, obstacles, None, altitude_m)
    }

    /// A flock whose transits' 3D lengths come from `lift`.
    pub fn over_terrain(
        uavs: Vec<FlockUav>,
        jobs: Vec<FlockJob>,
        turn_penalty_s: f64,
        obstacles: &'a ObstacleMap,
        lift: &'a Lift<'a>,
    ) -> Flock<'a> {
        Flock::new(uavs, jobs, turn_penalty_s, obstacles, Some(lift), 0.0)
    }

    fn new(
        uavs: Vec<FlockUav>,
        jobs: Vec<FlockJob>,
        turn_penalty_s: f64,
        obstacles: &'a ObstacleMap,
        lift: Option<&'a Lift<'a>>,
        flat_altitude_m: f64,
    ) -> Flock<'a> {
        Flock {
            batteries: vec![None; uavs.len()],
            uavs,
            jobs,
            turn_penalty_s,
            obstacles,
            lift,
            flat_altitude_m,
            memo: HashMap::new(),
        }
    }

    pub fn obstacles(&self) -> &'a ObstacleMap {
        self.obstacles
    }

    fn point(&self, s: Stop) -> (Coord<f64>, Option<Coord<f64>>) {
        match s {
            Stop::Home(u) => (self.uavs[u].home, None),
            Stop::End { job, end } => {
                let e = self.jobs[job].ends[usize::from(end)];
                (e.at, Some(e.inner))
            }
        }
    }

    /// The NFZ-avoiding transit from `a` to `b`, priced (memoised; a leg and
    /// its reverse are priced once).
    pub fn leg(&mut self, a: Stop, b: Stop) -> Result<Leg, TransitError> {
        if let Some((leg, _)) = self.memo.get(&(a, b)).or_else(|| self.memo.get(&(b, a))) {
            return Ok(*leg);
        }
        let (pa, pb) = (self.point(a).0, self.point(b).0);
        let path = self.obstacles.shortest_path(pa, pb)?;
        Ok(self.insert_leg(a, b, path))
    }

    /// Records `path` as the transit from `a` to `b`, already planned
    /// elsewhere (the single-UAV tour plans every transit it flies): it
    /// must be the one [`Flock::leg`] would find, from `a`'s point to `b`'s.
    pub fn know_leg(&mut self, a: Stop, b: Stop, path: Vec<Coord<f64>>) {
        let (pa, pb) = (self.point(a).0, self.point(b).0);
        if path.first() == Some(&pa)
            && path.last() == Some(&pb)
            && !self.memo.contains_key(&(a, b))
            && !self.memo.contains_key(&(b, a))
        {
            self.insert_leg(a, b, path);
        }
    }

    fn insert_leg(&mut self, a: Stop, b: Stop, path: Vec<Coord<f64>>) -> Leg {
        let inner_a = self.point(a).1;
        let inner_b = self.point(b).1;
        let length_m = polyline_length(&path);
        let homes = [matches!(a, Stop::Home(_)), matches!(b, Stop::Home(_))];
        let length_3d_m = match self.lift {
            Some(lift) => lift(&path, homes),
            None => length_m + self.flat_altitude_m * homes.iter().filter(|&&h| h).count() as f64,
        };
        // Turns along the transit and where it meets the lanes.
        let mut chain = Vec::with_capacity(path.len() + 2);
        chain.extend(inner_a);
        chain.extend_from_slice(&path);
        chain.extend(inner_b);
        let leg = Leg {
            length_m,
            length_3d_m,
            turns: count_turns(&chain) as u32,
        };
        self.memo.insert((a, b), (leg, path));
        leg
    }

    /// A lower bound of `leg(a, b)`'s 3D length that never searches: the
    /// memoised value, else the straight distance.
    pub fn leg_lower_3d(&self, a: Stop, b: Stop) -> f64 {
        match self.memo.get(&(a, b)).or_else(|| self.memo.get(&(b, a))) {
            Some((leg, _)) => leg.length_3d_m,
            None => {
                // The same arithmetic as an exact straight leg, so that the
                // bound is never a rounding above it.
                let (pa, _) = self.point(a);
                let (pb, _) = self.point(b);
                let homes = [a, b].iter().filter(|s| matches!(s, Stop::Home(_))).count();
                polyline_length(&[pa, pb]) + self.flat_altitude_m * homes as f64
            }
        }
    }

    /// A lower bound of UAV `u`'s time for `leg(a, b)` that never searches:
    /// the memoised time, else the straight distance at its speed.
    pub fn leg_time_lower(&self, u: usize, a: Stop, b: Stop) -> f64 {
        match self.memo.get(&(a, b)).or_else(|| self.memo.get(&(b, a))) {
            Some((leg, _)) => self.leg_time(u, *leg),
            None => self.leg_lower_3d(a, b) / self.uavs[u].speed_m_s,
        }
    }

    /// Nodes of the obstacle map's visibility graph: what one exact
    /// transit search may have to visit.
    pub(crate) fn obstacle_nodes(&self) -> usize {
        self.obstacles.node_count()
    }

    /// UAV `u`'s time for `leg(a, b)`.
    pub fn leg_time_of(&mut self, u: usize, a: Stop, b: Stop) -> Result<f64, TransitError> {
        let leg = self.leg(a, b)?;
        Ok(self.leg_time(u, leg))
    }

    /// The transit polyline from `a` to `b` (both included).
    pub fn leg_path(&mut self, a: Stop, b: Stop) -> Result<Vec<Coord<f64>>, TransitError> {
        self.leg(a, b)?;
        if let Some((_, path)) = self.memo.get(&(a, b)) {
            return Ok(path.clone());
        }
        Ok(self
            .memo
            .get(&(b, a))
            .map(|(_, p)| p.iter().rev().copied().collect())
            .unwrap_or_default())
    }

    /// Seconds UAV `u` needs for a leg.
    pub fn leg_time(&self, u: usize, leg: Leg) -> f64 {
        leg.length_3d_m / self.uavs[u].speed_m_s + f64::from(leg.turns) * self.turn_penalty_s
    }

    /// Seconds UAV `u` needs for the job itself.
    pub fn job_time(&self, u: usize, job: usize) -> f64 {
        let j = &self.jobs[job];
        j.length_3d_m / self.uavs[u].speed_m_s + j.turns as f64 * self.turn_penalty_s
    }

    /// A lower bound of UAV `u`'s time for the job flown any way, also
    /// entered at its other corners with new links (as the tour optimiser
    /// may): its lanes and the straight gaps between them, a turn per gap.
    pub fn job_time_lower(&self, u: usize, job: usize) -> f64 {
        let j = &self.jobs[job];
        let any_way = j.least_length_m / self.uavs[u].speed_m_s
            + j.lanes.saturating_sub(1) as f64 * self.turn_penalty_s;
        any_way.min(self.job_time(u, job))
    }

    /// The flat survey's climb and descent per home end, m (0 over terrain).
    pub fn flat_altitude_m(&self) -> f64 {
        self.flat_altitude_m
    }

    /// The stops of a route: home, each job in and out, home.
    pub fn legs_of(u: usize, route: &[Visit]) -> Vec<(Stop, Stop)> {
        let mut out = Vec::with_capacity(route.len() + 1);
        let mut at = Stop::Home(u);
        for &v in route {
            out.push((at, Stop::entry_of(v)));
            at = Stop::exit_of(v);
        }
        if !route.is_empty() {
            out.push((at, Stop::Home(u)));
        }
        out
    }

    /// True if UAV `u` has a battery limit.
    pub fn has_battery(&self, u: usize) -> bool {
        self.batteries.get(u).is_some_and(Option::is_some)
    }

    /// Mission time of UAV `u` flying `route`, all sorties included: with a
    /// battery the route is cut into sorties the way the survey flies it
    /// (greedily, in order, back home when the next job would not fit),
    /// and a job too long for one battery counts as flown in pieces, each
    /// a round trip from home. Work the UAV cannot reach and come back from
    /// within its battery costs [`INFEASIBLE_S`].
    pub fn route_time(&mut self, u: usize, route: &[Visit]) -> Result<f64, TransitError> {
        let Some(limit) = self.batteries.get(u).copied().flatten() else {
            return self.flight_time(u, route);
        };
        let home = Stop::Home(u);
        let mut total = 0.0;
        // The open sortie: time so far (without the way home) and where.
        let (mut open, mut at) = (0.0, home);
        for &v in route {
            let (entry, exit) = (Stop::entry_of(v), Stop::exit_of(v));
            let job = self.job_time(u, v.job);
            let back = self.leg_time_of(u, exit, home)?;
            let with = open + self.leg_time_of(u, at, entry)? + job;
            if with + back <= limit {
                (open, at) = (with, exit);
                continue;
            }
            if at != home {
                total += open + self.leg_time_of(u, at, home)?;
                (open, at) = (0.0, home);
            }
            let out = self.leg_time_of(u, home, entry)?;
            if out + job + back <= limit {
                (open, at) = (out + job, exit);
                continue;
            }
            let round_trip = out + back;
            if round_trip >= limit {
                return Ok(INFEASIBLE_S + total);
            }
            let pieces = (job / (limit - round_trip)).ceil();
            total += pieces * round_trip + job;
        }
        if at != home {
            total += open + self.leg_time_of(u, at, home)?;
        }
        Ok(total)
    }

    /// Time of UAV `u` flying `route` in one flight, home to home (0 for
    /// an empty route), whatever its battery.
    pub fn flight_time(&mut self, u: usize, route: &[Visit]) -> Result<f64, TransitError> {
        let mut t = 0.0;
        for (a, b) in Self::legs_of(u, route) {
            let leg = self.leg(a, b)?;
            t += self.leg_time(u, leg);
        }
        Ok(t + route.iter().map(|v| self.job_time(u, v.job)).sum::<f64>())
    }

    /// 3D length flown by a route, m.
    pub fn route_length_3d(&mut self, u: usize, route: &[Visit]) -> Result<f64, TransitError> {
        let mut l = 0.0;
        for (a, b) in Self::legs_of(u, route) {
            l += self.leg(a, b)?.length_3d_m;
        }
        Ok(l + route
            .iter()
            .map(|v| self.jobs[v.job].length_3d_m)
            .sum::<f64>())
    }

    /// Mission times of all routes.
    pub fn times(&mut self, routes: &Routes) -> Result<Vec<f64>, TransitError> {
        routes
            .iter()
            .enumerate()
            .map(|(u, r)| self.route_time(u, r))
            .collect()
    }

    /// The longest mission time of `routes`.
    pub fn makespan(&mut self, routes: &Routes) -> Result<f64, TransitError> {
        Ok(self.times(routes)?.into_iter().fold(0.0, f64::max))
    }
}

/// Heading changes above [`TURN_THRESHOLD_DEG`] along a polyline.
pub fn count_turns(path: &[Coord<f64>]) -> usize {
    let mut headings = path
        .windows(2)
        .filter(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y) > 1e-6)
        .map(|w| (w[1].y - w[0].y).atan2(w[1].x - w[0].x));
    let Some(mut prev) = headings.next() else {
        return 0;
    };
    let mut turns = 0;
    for h in headings {
        let mut d = (h - prev).abs();
        if d > std::f64::consts::PI {
            d = 2.0 * std::f64::consts::PI - d;
        }
        if d.to_degrees() > TURN_THRESHOLD_DEG {
            turns += 1;
        }
        prev = h;
    }
    turns
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::test_support::{lawnmower, rect};
    use approx::assert_relative_eq;
    use geo_types::{MultiPolygon, coord};

    #[test]
    fn legs_and_jobs_add_up_to_the_turns_of_the_whole_path() {
        // Two cells side by side, flown by one UAV from the south-west.
        let cells = [rect(0.0, 0.0, 40.0, 100.0), rect(60.0, 0.0, 100.0, 100.0)];
        let plans = [lawnmower(0, &cells[0], 4), lawnmower(1, &cells[1], 4)];
        let jobs: Vec<FlockJob> = plans
            .iter()
            .map(|p| FlockJob::from_plan(p, p.length_m()).unwrap())
            .collect();
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let uav = FlockUav {
            home: coord! { x: -20.0, y: -20.0 },
            speed_m_s: 5.0,
        };
        let mut flock = Flock::flat(vec![uav], jobs, 2.0, &map, 30.0);
        let route = vec![Visit::new(0, 0), Visit::new(1, 1)];

        // The whole path as flown, counted in one go.
        let mut path = vec![uav.home];
        path.extend(plans[0].path());
        let mut back = plans[1].path();
        back.reverse();
        path.extend(back);
        path.push(uav.home);
        let turns = count_turns(&path);

        let legs = Flock::legs_of(0, &route);
        let leg_turns: u32 = legs
            .iter()
            .map(|&(a, b)| flock.leg(a, b).unwrap().turns)
            .sum();
        let job_turns: usize = flock.jobs.iter().map(|j| j.turns).sum();
        assert_eq!(leg_turns as usize + job_turns, turns);

        let length: f64 = path
            .windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum();
        let time = flock.route_time(0, &route).unwrap();
        // Flat: 3D adds the climb to 30 m and the descent from it.
        assert_relative_eq!(
            time,
            (length + 60.0) / 5.0 + turns as f64 * 2.0,
            epsilon = 1e-9
        );
        assert_relative_eq!(
            flock.route_length_3d(0, &route).unwrap(),
            length + 60.0,
            epsilon = 1e-9
        );
    }

    #[test]
    fn ways_enter_and_leave_at_opposite_ends() {
        let plan = lawnmower(0, &rect(0.0, 0.0, 40.0, 100.0), 3);
        let job = FlockJob::from_plan(&plan, 1.0).unwrap();
        assert_eq!(job.entry(0), plan.entry().unwrap());
        assert_eq!(job.exit(0), plan.exit().unwrap());
        assert_eq!(job.entry(1), plan.exit().unwrap());
        assert_eq!(job.exit(1), plan.entry().unwrap());
        assert_eq!(Visit::new(3, 0).reversed(), Visit::new(3, 1));
    }

    #[test]
    fn a_leg_round_an_obstacle_is_memoised_both_ways() {
        let nfz = MultiPolygon(vec![rect(40.0, -50.0, 60.0, 50.0)]);
        let map = ObstacleMap::new(&nfz, 0.0);
        let plan = lawnmower(0, &rect(80.0, -10.0, 100.0, 10.0), 1);
        let job = FlockJob::from_plan(&plan, plan.length_m()).unwrap();
        let uav = FlockUav {
            home: coord! { x: 0.0, y: 0.0 },
            speed_m_s: 10.0,
        };
        let mut flock = Flock::flat(vec![uav], vec![job], 0.0, &map, 0.0);
        let a = Stop::Home(0);
        let b = Stop::End { job: 0, end: 0 };
        let leg = flock.leg(a, b).unwrap();
        assert!(leg.length_m > 90.0, "goes round the NFZ: {leg:?}");
        assert!(flock.leg_lower_3d(a, b) == leg.length_3d_m);
        let there = flock.leg_path(a, b).unwrap();
        let back = flock.leg_path(b, a).unwrap();
        assert_eq!(there.iter().rev().copied().collect::<Vec<_>>(), back);
        assert_eq!(flock.leg(b, a).unwrap(), leg);
    }
}
