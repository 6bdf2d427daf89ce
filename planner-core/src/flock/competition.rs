//! Thesis policy 2, the flock competition (Algorithm 3, with the reach
//! paths of Algorithm 2).
//!
//! Every UAV's *total path length* for a job is the distance it has
//! travelled so far, plus the 3D length of the NFZ-avoiding path to the
//! nearer end of the job (Algorithm 2: the first end unless the last is
//! strictly nearer), plus the job's coverage length. A round fixes the
//! smallest (UAV, job) entry, takes both out of the round, and repeats until
//! every UAV has a job or no job is left; then each UAV moves to the far end
//! of its job, lengths are updated, and the next round starts. Ties go to
//! the lowest job, then the lowest UAV index. Lengths, not times, as in the
//! thesis.

use super::problem::{Flock, Routes, Stop, Visit};
use super::transit::TransitError;

/// Algorithm 2 for one UAV at `at` and one job: the way whose entry is
/// nearer (3D length of the reach path) and that length.
pub(super) fn nearer_end(
    flock: &mut Flock,
    at: Stop,
    job: usize,
) -> Result<(Visit, f64), TransitError> {
    let to_first = flock.leg(at, Stop::End { job, end: 0 })?.length_3d_m;
    let to_last = flock.leg(at, Stop::End { job, end: 1 })?.length_3d_m;
    Ok(if to_first < to_last {
        (Visit::new(job, 0), to_first)
    } else {
        (Visit::new(job, 1), to_last)
    })
}

/// A (UAV, job) pair of a round: a lower bound of its total, and the exact
/// way and total once searched.
struct Pair {
    lower: f64,
    job: usize,
    uav: usize,
    exact: Option<(Visit, f64)>,
}

/// One round's fixed pair, for inspection (and the hand-computed test).
#[derive(Clone, Debug, PartialEq)]
pub struct RoundPick {
    pub round: usize,
    pub uav: usize,
    pub visit: Visit,
    /// The winning total path length: travelled + reach + coverage.
    pub total_m: f64,
}

/// The competition's routes, and each fixed pair in order.
pub fn competition(flock: &mut Flock) -> Result<(Routes, Vec<RoundPick>), TransitError> {
    let m = flock.uavs.len();
    let n = flock.jobs.len();
    let mut routes: Routes = vec![Vec::new(); m];
    let mut picks = Vec::with_capacity(n);
    let mut position: Vec<Stop> = (0..m).map(Stop::Home).collect();
    let mut travelled = vec![0.0f64; m];
    let mut left: Vec<usize> = (0..n).collect();
    let mut round = 0;
    while !left.is_empty() && m > 0 {
        round += 1;
        // total(j, i) = travelled + reach + coverage for this round. Reach
        // paths are searched lazily: a straight-line lower bound orders the
        // pairs, and a pair is searched round the NFZs only while its bound
        // could still beat the best exact total (same result as the full
        // table, far fewer searches).
        let mut pairs: Vec<Pair> = Vec::with_capacity(left.len() * m);
        for &j in &left {
            let coverage = flock.jobs[j].length_3d_m;
            for (i, &at) in position.iter().enumerate() {
                let reach = flock
                    .leg_lower_3d(at, Stop::End { job: j, end: 0 })
                    .min(flock.leg_lower_3d(at, Stop::End { job: j, end: 1 }));
                pairs.push(Pair {
                    lower: travelled[i] + reach + coverage,
                    job: j,
                    uav: i,
                    exact: None,
                });
            }
        }
        pairs.sort_by(|a, b| a.lower.total_cmp(&b.lower));
        let mut uav_free = vec![true; m];
        let mut job_free: Vec<bool> = vec![true; n];
        for _ in 0..m {
            // (total, job, uav, visit) of the best pair so far.
            let mut best: Option<(f64, usize, usize, Visit)> = None;
            for pair in pairs.iter_mut() {
                if !(job_free[pair.job] && uav_free[pair.uav]) {
                    continue;
                }
                if let Some((total, ..)) = best
                    && pair.lower > total
                {
                    break;
                }
                let (visit, total) = match pair.exact {
                    Some(e) => e,
                    None => {
                        let (visit, reach) = nearer_end(flock, position[pair.uav], pair.job)?;
                        let total = travelled[pair.uav] + reach + flock.jobs[pair.job].length_3d_m;
                        pair.exact = Some((visit, total));
                        (visit, total)
                    }
                };
                let wins = best.is_none_or(|(t, j, i, _)| {
                    total
                        .total_cmp(&t)
                        .then(pair.job.cmp(&j))
                        .then(pair.uav.cmp(&i))
                        == std::cmp::Ordering::Less
                });
                if wins {
                    best = Some((total, pair.job, pair.uav, visit));
                }
            }
            let Some((total, j, i, visit)) = best else {
                break;
            };
            job_free[j] = false;
            uav_free[i] = false;
            routes[i].push(visit);
            picks.push(RoundPick {
                round,
                uav: i,
                visit,
                total_m: total,
            });
        }
        // Update positions and travelled lengths of this round's winners.
        for p in picks.iter().filter(|p| p.round == round) {
            travelled[p.uav] = p.total_m;
            position[p.uav] = Stop::exit_of(p.visit);
        }
        left.retain(|&j| job_free[j]);
    }
    Ok((routes, picks))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::problem::{FlockJob, FlockUav};
    use crate::flock::test_support::rect;
    use crate::flock::transit::ObstacleMap;
    use approx::assert_relative_eq;
    use geo_types::{MultiPolygon, coord};

    /// A one-lane job from `a` to `b` with a given coverage length.
    fn job(a: (f64, f64), b: (f64, f64), coverage: f64) -> FlockJob {
        let plan = crate::coverage::CellPlan {
            cell_index: 0,
            direction_deg: 0.0,
            lanes: vec![crate::coverage::Lane {
                start: coord! { x: a.0, y: a.1 },
                end: coord! { x: b.0, y: b.1 },
            }],
            links: vec![],
        };
        FlockJob::from_plan(&plan, coverage).unwrap()
    }

    /// Two UAVs, three one-lane jobs on a line, no NFZ, flat at altitude 0
    /// (3D = 2D). Worked by hand:
    ///
    /// UAV 0 at (0, 0), UAV 1 at (100, 0).
    /// Job 0: (10, 0) → (20, 0), coverage 10.
    /// Job 1: (90, 0) → (60, 0), coverage 30.
    /// Job 2: (40, 0) → (50, 0), coverage 10.
    ///
    /// Round 1 (travelled 0):
    ///   UAV 0: job 0 reach 10 (first end) → 20; job 1 reach 60 (last end,
    ///   (60, 0)) → 90; job 2 reach 40 → 50.
    ///   UAV 1: job 0 reach 80 (last end (20, 0)) → 90; job 1 reach 10 →
    ///   40; job 2 reach 50 (last end (50, 0)) → 60.
    ///   Smallest: UAV 0 / job 0 (20). Left for UAV 1: job 1 (40) < job 2
    ///   (60): UAV 1 / job 1 (40).
    ///   UAV 0 now at (20, 0) with 20 travelled; UAV 1 at (60, 0) with 40.
    /// Round 2: job 2 only. UAV 0: reach 20 → 20 + 20 + 10 = 50; UAV 1:
    ///   reach 10 (last end) → 40 + 10 + 10 = 60. UAV 0 wins with 50,
    ///   entering at (40, 0).
    #[test]
    fn walks_the_hand_computed_instance_round_by_round() {
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let uavs = vec![
            FlockUav {
                home: coord! { x: 0.0, y: 0.0 },
                speed_m_s: 10.0,
            },
            FlockUav {
                home: coord! { x: 100.0, y: 0.0 },
                speed_m_s: 10.0,
            },
        ];
        let jobs = vec![
            job((10.0, 0.0), (20.0, 0.0), 10.0),
            job((90.0, 0.0), (60.0, 0.0), 30.0),
            job((40.0, 0.0), (50.0, 0.0), 10.0),
        ];
        let mut flock = Flock::flat(uavs, jobs, 0.0, &map, 0.0);
        let (routes, picks) = competition(&mut flock).unwrap();
        let got: Vec<(usize, usize, Visit)> =
            picks.iter().map(|p| (p.round, p.uav, p.visit)).collect();
        assert_eq!(
            got,
            vec![
                (1, 0, Visit::new(0, 0)),
                (1, 1, Visit::new(1, 0)),
                (2, 0, Visit::new(2, 0)),
            ]
        );
        let totals: Vec<f64> = picks.iter().map(|p| p.total_m).collect();
        for (t, want) in totals.iter().zip([20.0, 40.0, 50.0]) {
            assert_relative_eq!(*t, want, epsilon = 1e-9);
        }
        assert_eq!(
            routes,
            vec![
                vec![Visit::new(0, 0), Visit::new(2, 0)],
                vec![Visit::new(1, 0)]
            ]
        );
    }

    #[test]
    fn reach_goes_round_no_fly_zones_and_ties_take_the_last_end() {
        // A wall between the UAV and the first end: the last end is nearer.
        let nfz = MultiPolygon(vec![rect(20.0, -100.0, 30.0, 25.0)]);
        let map = ObstacleMap::new(&nfz, 0.0);
        let uav = FlockUav {
            home: coord! { x: 0.0, y: 0.0 },
            speed_m_s: 10.0,
        };
        let jobs = vec![
            job((40.0, 0.0), (40.0, 30.0), 30.0),
            job((-10.0, 0.0), (10.0, 0.0), 20.0),
        ];
        let mut flock = Flock::flat(vec![uav], jobs, 0.0, &map, 0.0);
        let (visit, reach) = nearer_end(&mut flock, Stop::Home(0), 0).unwrap();
        assert_eq!(visit, Visit::new(0, 1));
        let direct_to_last = 40f64.hypot(30.0);
        assert!(reach >= direct_to_last - 1e-9, "{reach}");
        // Equidistant ends: Algorithm 2's strict `<` picks the last one.
        let (visit, _) = nearer_end(&mut flock, Stop::Home(0), 1).unwrap();
        assert_eq!(visit, Visit::new(1, 1));
    }
}
