//! A lower bound on the makespan of any assignment, to report how far a
//! plan can still be from the best possible one.
//!
//! Two bounds, the larger wins:
//! - some UAV must fly each job and come home: for every job, the cheapest
//!   home → job → home round trip over the UAVs (exact transits to the
//!   job's two path ends when the flock is small, straight lines otherwise);
//! - the work must be shared: every job's own time at the fastest speed,
//!   plus the shortest straight approach to it from anywhere, summed and
//!   divided among the UAVs.
//!
//! Both hold for the jobs as given (cells, or their halves when there are
//! more UAVs than cells), before battery sorties, flown as planned or
//! backwards. With `any_corner` they also hold when a job may be entered at
//! its other two corners with new links (as the single-UAV tour optimiser
//! does): straight lines to those corners, and the job's least length
//! (lanes and the straight gaps between them, a turn per gap).

use geo_types::Coord;

use super::problem::{Flock, Stop, Visit};
use super::transit::{TransitError, polyline_length};

/// Pairs of (UAV, job) up to which the round-trip bound uses exact
/// NFZ-avoiding transits.
const EXACT_PAIRS: usize = 4096;
/// Pairs times visibility-graph nodes up to which it does: each exact
/// transit is a search over the nodes, and the bound is only a report, not
/// worth more time than the plan (thousands of NFZs and cells would need
/// millions of node visits); beyond it, straight lines still give a bound.
const EXACT_WORK: usize = EXACT_PAIRS * 64;
/// Jobs up to which the approach term compares every pair of corners.
const APPROACH_JOBS: usize = 1000;

/// A lower bound of the makespan (seconds) over every way of sharing the
/// jobs among the UAVs.
pub fn makespan_lower_bound(flock: &mut Flock, any_corner: bool) -> Result<f64, TransitError> {
    let (m, n) = (flock.uavs.len(), flock.jobs.len());
    if m == 0 || n == 0 {
        return Ok(0.0);
    }
    let nodes = flock.obstacle_nodes().max(64);
    let exact = m * n <= EXACT_PAIRS && m * n * nodes <= EXACT_WORK;
    let line = |a: Coord<f64>, b: Coord<f64>| polyline_length(&[a, b]);
    let climb = 2.0 * flock.flat_altitude_m();
    let mut round_trip: f64 = 0.0;
    for j in 0..n {
        let mut cheapest = f64::INFINITY;
        for u in 0..m {
            let speed = flock.uavs[u].speed_m_s;
            let home = flock.uavs[u].home;
            for way in 0..2 {
                let v = Visit::new(j, way);
                let (h, entry, exit) = (Stop::Home(u), Stop::entry_of(v), Stop::exit_of(v));
                let legs = if exact {
                    flock.leg_time_of(u, h, entry)? + flock.leg_time_of(u, exit, h)?
                } else {
                    flock.leg_time_lower(u, h, entry) + flock.leg_time_lower(u, exit, h)
                };
                cheapest = cheapest.min(legs + flock.job_time(u, j));
            }
            if any_corner {
                let [a, b] = flock.jobs[j].across;
                let across = (line(home, a) + line(b, home)).min(line(home, b) + line(a, home));
                cheapest = cheapest.min((across + climb) / speed + flock.job_time_lower(u, j));
            }
        }
        round_trip = round_trip.max(cheapest);
    }

    let fastest = flock
        .uavs
        .iter()
        .map(|u| u.speed_m_s)
        .fold(f64::MIN_POSITIVE, f64::max);
    let corners = |f: &Flock, j: usize| -> Vec<Coord<f64>> {
        let job = &f.jobs[j];
        let mut c = vec![job.ends[0].at, job.ends[1].at];
        if any_corner {
            c.extend(job.across);
        }
        c
    };
    let mut work = 0.0;
    for j in 0..n {
        let own = (0..m)
            .map(|u| {
                if any_corner {
                    flock.job_time_lower(u, j)
                } else {
                    flock.job_time(u, j)
                }
            })
            .fold(f64::INFINITY, f64::min);
        // Straight approach to any corner, from a home or another job's corner.
        let mut approach = 0.0;
        if n <= APPROACH_JOBS {
            approach = f64::INFINITY;
            let mine = corners(flock, j);
            let homes: Vec<Coord<f64>> = flock.uavs.iter().map(|u| u.home).collect();
            let others = (0..n).filter(|&k| k != j).flat_map(|k| corners(flock, k));
            for from in homes.into_iter().chain(others) {
                for &to in mine.iter() {
                    approach = f64::min(approach, line(from, to));
                }
            }
        }
        work += own + approach / fastest;
    }
    Ok(round_trip.max(work / m as f64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::problem::{FlockJob, FlockUav};
    use crate::flock::test_support::{Lcg, lawnmower, rect};
    use crate::flock::transit::ObstacleMap;
    use crate::flock::{Policy, assign};
    use geo_types::{MultiPolygon, coord};

    #[test]
    fn no_assignment_beats_the_bound() {
        let mut rng = Lcg(0x10_b0_0d);
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(500.0, 200.0, 600.0, 700.0)]), 2.0);
        for trial in 0..12 {
            let m = 1 + trial % 4;
            let uavs: Vec<FlockUav> = (0..m)
                .map(|_| FlockUav {
                    home: coord! { x: rng.next() * 1000.0, y: -50.0 },
                    speed_m_s: 6.0 + 6.0 * rng.next(),
                })
                .collect();
            let jobs: Vec<FlockJob> = (0..6)
                .map(|k| {
                    let x = if k % 2 == 0 { 100.0 } else { 700.0 } + rng.next() * 150.0;
                    let y = 100.0 * k as f64;
                    let plan = lawnmower(
                        k,
                        &rect(x, y, x + 60.0, y + 80.0),
                        1 + (rng.next() * 5.0) as usize,
                    );
                    FlockJob::from_plan(&plan, plan.length_m()).unwrap()
                })
                .collect();
            let mut flock = Flock::flat(uavs, jobs, 3.0, &map, 30.0);
            let bound = makespan_lower_bound(&mut flock, false).unwrap();
            for policy in [Policy::MinReach, Policy::Competition, Policy::Balanced] {
                let routes = assign(&mut flock, policy).unwrap();
                let makespan = flock.makespan(&routes).unwrap();
                assert!(
                    bound <= makespan + 1e-9,
                    "{policy:?}: bound {bound} > {makespan}"
                );
            }
            assert!(bound > 0.0);
        }
    }
}
