//! Thesis policy 1, minimum reach: with as many UAVs as jobs, the one-to-one
//! assignment minimising the summed reach distance (3D length of the
//! NFZ-avoiding path to each job's nearer end, Algorithm 2), solved exactly
//! by the Hungarian method rather than by enumerating permutations.
//!
//! The thesis defines it for equal counts only. With fewer UAVs than jobs
//! terraplan repeats it in rounds, like the competition: each round assigns
//! every UAV one of the jobs left (or every job left a UAV) minimising that
//! round's summed reach from where the UAVs are, then the UAVs move to the
//! far ends of their jobs.

use super::FlockError;
use super::competition::nearer_end;
use super::hungarian::min_cost_assignment;
use super::problem::{Flock, Routes, Stop, Visit};

/// The minimum-reach routes.
pub fn min_reach(flock: &mut Flock) -> Result<Routes, FlockError> {
    let m = flock.uavs.len();
    let mut routes: Routes = vec![Vec::new(); m];
    let mut position: Vec<Stop> = (0..m).map(Stop::Home).collect();
    let mut left: Vec<usize> = (0..flock.jobs.len()).collect();
    while !left.is_empty() && m > 0 {
        // reach[i * cols + k]: UAV i to job left[k]. Entries start as
        // straight-line lower bounds and are searched round the NFZs only
        // when the optimal assignment picks them; once every picked entry is
        // exact, no other assignment can be cheaper (its entries are at
        // least their bounds), so the result is the exact optimum.
        let cols = left.len();
        let mut reach = Vec::with_capacity(m * cols);
        for &at in &position {
            for &j in &left {
                reach.push(
                    flock
                        .leg_lower_3d(at, Stop::End { job: j, end: 0 })
                        .min(flock.leg_lower_3d(at, Stop::End { job: j, end: 1 })),
                );
            }
        }
        let mut ways: Vec<Option<Visit>> = vec![None; m * cols];
        let pairs = loop {
            let pairs = solve(&reach, m, cols)?;
            let mut refined = false;
            for &(i, k) in &pairs {
                if ways[i * cols + k].is_none() {
                    let (visit, length) = nearer_end(flock, position[i], left[k])?;
                    reach[i * cols + k] = length;
                    ways[i * cols + k] = Some(visit);
                    refined = true;
                }
            }
            if !refined {
                break pairs;
            }
        };
        let mut taken = vec![false; cols];
        for (i, k) in pairs {
            let Some(visit) = ways[i * cols + k] else {
                continue;
            };
            routes[i].push(visit);
            position[i] = Stop::exit_of(visit);
            taken[k] = true;
        }
        let mut k = 0;
        left.retain(|_| {
            let keep = !taken[k];
            k += 1;
            keep
        });
    }
    Ok(routes)
}

/// The optimal (UAV, column) pairs of one round: every UAV a job when
/// there are enough, else every job a UAV.
fn solve(reach: &[f64], m: usize, cols: usize) -> Result<Vec<(usize, usize)>, FlockError> {
    Ok(if m <= cols {
        min_cost_assignment(reach, m, cols)?
            .into_iter()
            .enumerate()
            .collect()
    } else {
        let mut transposed = vec![0.0; m * cols];
        for i in 0..m {
            for k in 0..cols {
                transposed[k * m + i] = reach[i * cols + k];
            }
        }
        min_cost_assignment(&transposed, cols, m)?
            .into_iter()
            .enumerate()
            .map(|(k, i)| (i, k))
            .collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coverage::{CellPlan, Lane};
    use crate::flock::problem::{FlockJob, FlockUav};
    use crate::flock::test_support::{Lcg, rect};
    use crate::flock::transit::ObstacleMap;
    use geo_types::{Coord, MultiPolygon, coord};

    fn one_lane(a: Coord<f64>, b: Coord<f64>) -> FlockJob {
        let plan = CellPlan {
            cell_index: 0,
            direction_deg: 0.0,
            lanes: vec![Lane { start: a, end: b }],
            links: vec![],
        };
        FlockJob::from_plan(&plan, plan.length_m()).unwrap()
    }

    /// Every permutation of `0..n`, by Heap's algorithm.
    fn permutations(n: usize) -> Vec<Vec<usize>> {
        fn heap(k: usize, a: &mut Vec<usize>, out: &mut Vec<Vec<usize>>) {
            if k <= 1 {
                out.push(a.clone());
                return;
            }
            for i in 0..k {
                heap(k - 1, a, out);
                let swap = if k.is_multiple_of(2) { i } else { 0 };
                a.swap(swap, k - 1);
            }
        }
        let mut out = Vec::new();
        heap(n, &mut (0..n).collect(), &mut out);
        out
    }

    #[test]
    fn equals_brute_force_on_random_instances_up_to_seven_uavs() {
        let mut rng = Lcg(0x5eed_f10c);
        // Two NFZs so that reach paths bend.
        let nfz = MultiPolygon(vec![
            rect(300.0, 200.0, 420.0, 600.0),
            rect(600.0, 500.0, 700.0, 560.0),
        ]);
        let map = ObstacleMap::new(&nfz, 2.0);
        let point = |rng: &mut Lcg| loop {
            let p = coord! { x: rng.next() * 1000.0, y: rng.next() * 1000.0 };
            if !map.contains_point(p) && map.shortest_path(p, coord! { x: 0.0, y: 0.0 }).is_ok() {
                return p;
            }
        };
        for n in 1..=7 {
            for _ in 0..6 {
                let uavs: Vec<FlockUav> = (0..n)
                    .map(|_| FlockUav {
                        home: point(&mut rng),
                        speed_m_s: 10.0,
                    })
                    .collect();
                let jobs: Vec<FlockJob> = (0..n)
                    .map(|_| one_lane(point(&mut rng), point(&mut rng)))
                    .collect();
                let mut flock = Flock::flat(uavs, jobs, 0.0, &map, 0.0);
                let routes = min_reach(&mut flock).unwrap();
                let mut got = 0.0;
                let mut seen = vec![false; n];
                for (i, r) in routes.iter().enumerate() {
                    assert_eq!(r.len(), 1, "equal counts: one job each");
                    seen[r[0].job] = true;
                    got += flock
                        .leg(Stop::Home(i), Stop::entry_of(r[0]))
                        .unwrap()
                        .length_3d_m;
                }
                assert!(seen.iter().all(|&s| s));
                let mut best = f64::INFINITY;
                for perm in permutations(n) {
                    let mut sum = 0.0;
                    for (i, &j) in perm.iter().enumerate() {
                        sum += nearer_end(&mut flock, Stop::Home(i), j).unwrap().1;
                    }
                    best = best.min(sum);
                }
                assert!(
                    (got - best).abs() <= 1e-9 * best.max(1.0),
                    "n={n}: {got} vs brute force {best}"
                );
            }
        }
    }

    #[test]
    fn fewer_uavs_than_jobs_run_in_rounds() {
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let uavs = vec![
            FlockUav {
                home: coord! { x: 0.0, y: 0.0 },
                speed_m_s: 10.0,
            },
            FlockUav {
                home: coord! { x: 1000.0, y: 0.0 },
                speed_m_s: 10.0,
            },
        ];
        let jobs = vec![
            one_lane(coord! { x: 10.0, y: 0.0 }, coord! { x: 10.0, y: 50.0 }),
            one_lane(coord! { x: 990.0, y: 0.0 }, coord! { x: 990.0, y: 50.0 }),
            one_lane(coord! { x: 20.0, y: 60.0 }, coord! { x: 20.0, y: 100.0 }),
        ];
        let mut flock = Flock::flat(uavs, jobs, 0.0, &map, 0.0);
        let routes = min_reach(&mut flock).unwrap();
        assert_eq!(
            routes,
            vec![
                vec![Visit::new(0, 0), Visit::new(2, 0)],
                vec![Visit::new(1, 0)]
            ]
        );
    }
}
