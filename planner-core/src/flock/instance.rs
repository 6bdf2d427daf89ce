//! A flock problem written out as a plain routing instance (issue 21): UAV
//! starts and job ends as nodes, the travel times between them priced by
//! [`Flock`]'s own cost model, and a plan's routes, so that general
//! solvers can be run on exactly the problem the policies solve.
//!
//! The survey records its flock problem only inside [`recording`]: the
//! flock stage calls [`Solving::start`] before its policy and
//! [`Solving::done`] with the routes; outside a recording both cost
//! nothing.

use std::cell::RefCell;
use std::time::Instant;

use serde::Serialize;

use super::problem::{Flock, Routes, Stop};
use super::transit::TransitError;

/// Why a flock problem cannot be written as an instance.
#[derive(Debug, Clone, thiserror::Error)]
pub enum InstanceError {
    #[error("the instance has one travel-time matrix: all UAVs must fly at one speed")]
    MixedSpeeds,
    #[error("the instance format has no batteries")]
    Battery,
    #[error("job {0} is flown {1} times by the routes (once expected)")]
    JobCount(usize, usize),
    #[error("the survey recorded no flock problem")]
    NotRecorded,
    #[error(transparent)]
    Transit(#[from] TransitError),
}

/// A job of the instance: flown from either end to the other.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InstanceJob {
    /// The nodes of its two ends.
    pub ends: [usize; 2],
    /// Time flying it, s (the same either way).
    pub duration_s: f64,
}

/// One job of a route: the instance's job index and whether it is flown
/// from `ends[1]` to `ends[0]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct RouteStep(pub usize, pub bool);

/// The flock problem as a routing instance, with the plan's answer. Nodes
/// are numbered UAV starts first (`0..uavs`), then job `j`'s ends at
/// `uavs + 2j` and `uavs + 2j + 1`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Instance {
    /// The start (and return) node of each UAV.
    pub starts: Vec<usize>,
    pub jobs: Vec<InstanceJob>,
    /// NFZ-avoiding travel time between any two nodes, s: climbs, descents
    /// and the turns along a transit and at its junctions with the lanes
    /// included; 0 on the diagonal.
    pub travel_s: Vec<Vec<f64>>,
    /// Each UAV's jobs in flight order.
    pub routes: Vec<Vec<RouteStep>>,
    /// The routes' makespan in this model, s.
    pub makespan_s: f64,
    pub lower_bound_s: f64,
    /// Time of the policy (lower bound included), s.
    pub solve_s: f64,
}

impl Instance {
    /// The makespan of `routes` recomputed from the matrix alone.
    pub fn makespan_of(&self, routes: &[Vec<RouteStep>]) -> f64 {
        routes
            .iter()
            .zip(&self.starts)
            .map(|(route, &start)| {
                let mut at = start;
                let mut t = 0.0;
                for &RouteStep(job, reversed) in route {
                    let [a, b] = self.jobs[job].ends;
                    let (entry, exit) = if reversed { (b, a) } else { (a, b) };
                    t += self.travel_s[at][entry] + self.jobs[job].duration_s;
                    at = exit;
                }
                t + self.travel_s[at][start]
            })
            .fold(0.0, f64::max)
    }
}

/// Builds the instance of `flock` with `routes` as its plan.
pub fn instance_of(
    flock: &mut Flock,
    routes: &Routes,
    lower_bound_s: f64,
    solve_s: f64,
) -> Result<Instance, InstanceError> {
    let m = flock.uavs.len();
    if flock
        .uavs
        .windows(2)
        .any(|w| w[0].speed_m_s != w[1].speed_m_s)
    {
        return Err(InstanceError::MixedSpeeds);
    }
    if (0..m).any(|u| flock.has_battery(u)) {
        return Err(InstanceError::Battery);
    }
    // Jobs no route flies (parts replaced by the single-UAV tour's) are
    // left out; every other job must be flown exactly once.
    let mut count = vec![0usize; flock.jobs.len()];
    for v in routes.iter().flatten() {
        count[v.job] += 1;
    }
    if let Some(j) = count.iter().position(|&c| c > 1) {
        return Err(InstanceError::JobCount(j, count[j]));
    }
    let used: Vec<usize> = (0..flock.jobs.len()).filter(|&j| count[j] == 1).collect();
    let mut index = vec![usize::MAX; flock.jobs.len()];
    for (k, &j) in used.iter().enumerate() {
        index[j] = k;
    }
    let stops: Vec<Stop> = (0..m)
        .map(Stop::Home)
        .chain(
            used.iter()
                .flat_map(|&job| [0, 1].map(|end| Stop::End { job, end })),
        )
        .collect();
    let mut travel_s = vec![vec![0.0; stops.len()]; stops.len()];
    for a in 0..stops.len() {
        for b in a + 1..stops.len() {
            // Legs are priced the same both ways (see `Flock::leg`).
            let t = flock.leg_time_of(0, stops[a], stops[b])?;
            travel_s[a][b] = t;
            travel_s[b][a] = t;
        }
    }
    let jobs = used
        .iter()
        .enumerate()
        .map(|(k, &j)| InstanceJob {
            ends: [m + 2 * k, m + 2 * k + 1],
            duration_s: flock.job_time(0, j),
        })
        .collect();
    let steps = routes
        .iter()
        .map(|r| {
            r.iter()
                .map(|v| RouteStep(index[v.job], v.way == 1))
                .collect()
        })
        .collect();
    let mut makespan_s: f64 = 0.0;
    for (u, r) in routes.iter().enumerate() {
        makespan_s = makespan_s.max(flock.flight_time(u, r)?);
    }
    Ok(Instance {
        starts: (0..m).collect(),
        jobs,
        travel_s,
        routes: steps,
        makespan_s,
        lower_bound_s,
        solve_s,
    })
}

thread_local! {
    /// The instances recorded on this thread, while [`recording`].
    static RECORDED: RefCell<Option<Vec<Result<Instance, InstanceError>>>> =
        const { RefCell::new(None) };
}

/// Runs `f` (a survey) and returns what it returns with the flock problem
/// it solved on this thread, the last one if several.
pub fn recording<T>(f: impl FnOnce() -> T) -> (T, Result<Instance, InstanceError>) {
    let outer = RECORDED.with(|r| r.borrow_mut().replace(Vec::new()));
    let out = f();
    let recorded = RECORDED.with(|r| std::mem::replace(&mut *r.borrow_mut(), outer));
    let last = recorded
        .and_then(|mut v| v.pop())
        .unwrap_or(Err(InstanceError::NotRecorded));
    (out, last)
}

/// The clock of one flock stage's policy, running only while recording.
#[derive(Debug)]
pub struct Solving(Option<Instant>);

impl Solving {
    pub fn start() -> Solving {
        let on = RECORDED.with(|r| r.borrow().is_some());
        Solving(on.then(Instant::now))
    }

    /// Records the flock problem with the policy's `routes` (when
    /// recording; the plan goes on whatever the outcome).
    pub fn done(self, flock: &mut Flock, routes: &Routes, lower_bound_s: f64) {
        let Some(started) = self.0 else {
            return;
        };
        let solve_s = started.elapsed().as_secs_f64();
        let instance = instance_of(flock, routes, lower_bound_s, solve_s);
        RECORDED.with(|r| {
            if let Some(v) = r.borrow_mut().as_mut() {
                v.push(instance);
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::test_support::{lawnmower, rect};
    use crate::flock::{FlockJob, FlockUav, ObstacleMap, Visit};
    use approx::assert_relative_eq;
    use geo_types::{MultiPolygon, coord};

    fn flock_of(map: &ObstacleMap) -> Flock<'_> {
        let cells = [
            rect(0.0, 0.0, 40.0, 100.0),
            rect(60.0, 0.0, 100.0, 100.0),
            rect(140.0, 0.0, 180.0, 60.0),
        ];
        let jobs = cells
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let p = lawnmower(i, c, 3);
                FlockJob::from_plan(&p, p.length_m()).unwrap()
            })
            .collect();
        let uav = |x: f64| FlockUav {
            home: coord! { x: x, y: -30.0 },
            speed_m_s: 5.0,
        };
        Flock::flat(vec![uav(0.0), uav(150.0)], jobs, 2.0, map, 30.0)
    }

    #[test]
    fn the_matrix_gives_the_routes_their_makespan() {
        // An NFZ between the first two cells: transits go round it.
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(45.0, 20.0, 55.0, 120.0)]), 0.0);
        let mut flock = flock_of(&map);
        let routes = vec![
            vec![Visit::new(1, 1), Visit::new(0, 0)],
            vec![Visit::new(2, 1)],
        ];
        let inst = instance_of(&mut flock, &routes, 1.0, 0.5).unwrap();
        assert_eq!(inst.starts, vec![0, 1]);
        assert_eq!(inst.jobs.len(), 3);
        assert_eq!(inst.jobs[2].ends, [6, 7]);
        assert_eq!(inst.travel_s.len(), 8);
        let expected = flock.makespan(&routes).unwrap();
        assert_relative_eq!(inst.makespan_s, expected, epsilon = 1e-9);
        assert_relative_eq!(inst.makespan_of(&inst.routes), expected, epsilon = 1e-9);
        assert_eq!(
            inst.routes[0],
            vec![RouteStep(1, true), RouteStep(0, false)]
        );
        // Symmetric, zero on the diagonal, climbs on home legs.
        for a in 0..8 {
            assert_eq!(inst.travel_s[a][a], 0.0);
            for b in 0..8 {
                assert_eq!(inst.travel_s[a][b], inst.travel_s[b][a]);
            }
        }
        assert!(inst.travel_s[0][1] >= (150.0 + 60.0) / 5.0);
    }

    #[test]
    fn only_a_recording_records_and_the_last_problem_wins() {
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let mut flock = flock_of(&map);
        let routes = vec![
            vec![Visit::new(0, 0), Visit::new(1, 0)],
            vec![Visit::new(2, 0)],
        ];
        // Outside a recording nothing is kept (and nothing is priced).
        Solving::start().done(&mut flock, &routes, 0.0);
        let ((), got) = recording(|| {
            Solving::start().done(&mut flock, &vec![vec![], vec![]], 0.0);
            Solving::start().done(&mut flock, &routes, 3.0);
        });
        let inst = got.unwrap();
        assert_eq!(inst.lower_bound_s, 3.0);
        assert_eq!(inst.routes[0].len(), 2);
        let ((), none) = recording(|| ());
        assert!(matches!(none, Err(InstanceError::NotRecorded)));
    }

    #[test]
    fn a_job_flown_twice_or_a_battery_is_refused() {
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let mut flock = flock_of(&map);
        let twice = vec![vec![Visit::new(0, 0)], vec![Visit::new(0, 1)]];
        assert!(matches!(
            instance_of(&mut flock, &twice, 0.0, 0.0),
            Err(InstanceError::JobCount(0, 2))
        ));
        flock.batteries[1] = Some(600.0);
        let routes = vec![vec![Visit::new(0, 0)], vec![]];
        assert!(matches!(
            instance_of(&mut flock, &routes, 0.0, 0.0),
            Err(InstanceError::Battery)
        ));
    }
}
