//! The least makespan of a small flock, exactly: dynamic programming over
//! subsets of jobs (each UAV's best route through every subset, then the
//! best sharing of the jobs among the UAVs), for the `balanced` policy to
//! start from where the work stays within [`MAX_WORK`].
//!
//! Exact in [`Flock`]'s model without batteries: every job flown once,
//! whole, from one of its two ends to the other; every UAV flies home to
//! home; the makespan is the longest single flight. Ties in the makespan
//! go to the smaller sum of times. Every UAV gets work when there are at
//! least as many jobs as UAVs.

use super::problem::{Flock, Leg, Routes, Stop, Visit};
use super::transit::TransitError;

/// Most jobs solved exactly (the subsets of 16 jobs fill 64 Ki entries).
pub const MAX_JOBS: usize = 16;
/// Most elementary steps of the two programs together (a few tens of
/// milliseconds).
pub const MAX_WORK: usize = 1 << 25;

/// "No predecessor": the visit is the route's first.
const FIRST: u8 = u8::MAX;

/// Subset programs of one UAV: its best time for every subset of jobs,
/// and how to fly it.
struct Subsets {
    /// Best home-to-home time per subset (`INFINITY` where none).
    time: Vec<f64>,
    /// The subset's last visit (oriented job `2j + way`) in that route.
    last: Vec<u8>,
    /// Per subset and last visit, the visit before it ([`FIRST`] if none).
    parent: Vec<u8>,
}

/// Whether the programs fit [`MAX_WORK`] for `m` UAVs and `n` jobs.
pub fn fits(m: usize, n: usize) -> bool {
    if n == 0 || m == 0 || n > MAX_JOBS {
        return false;
    }
    let k = 2 * n;
    let routes = m.saturating_mul(1 << n).saturating_mul(k * k);
    let sharing = m.saturating_mul(3usize.pow(n as u32));
    routes.saturating_add(sharing) <= MAX_WORK
}

/// Routes of the least makespan, or `None` when the flock is too large for
/// [`fits`], a UAV has a battery (sorties are not in the model) or some
/// leg has no transit (the search may still find routes without it).
pub fn exact_routes(flock: &mut Flock) -> Result<Option<Routes>, TransitError> {
    let (m, n) = (flock.uavs.len(), flock.jobs.len());
    if !fits(m, n) || (0..m).any(|u| flock.has_battery(u)) {
        return Ok(None);
    }
    let per_uav = match programs(flock) {
        Ok(p) => p,
        Err(e @ TransitError::Cancelled(_)) => return Err(e),
        Err(_) => return Ok(None),
    };
    let shares = share(&per_uav, n);
    Ok(Some(
        shares
            .iter()
            .enumerate()
            .map(|(u, &set)| route_of(&per_uav[u], n, set))
            .collect(),
    ))
}

/// Every UAV's subset programs, every leg priced exactly.
fn programs(flock: &mut Flock) -> Result<Vec<Subsets>, TransitError> {
    let (m, n) = (flock.uavs.len(), flock.jobs.len());
    let k = 2 * n;
    // Oriented visit o = 2j + way enters at end `way` of job j (stop o
    // below) and leaves at its other end (stop o ^ 1).
    let ends: Vec<Stop> = (0..k)
        .map(|o| Stop::End {
            job: o / 2,
            end: (o % 2) as u8,
        })
        .collect();
    let mut between: Vec<Option<Leg>> = vec![None; k * k];
    for a in 0..k {
        for b in 0..k {
            if a / 2 != b / 2 {
                between[a * k + b] = Some(flock.leg(ends[a], ends[b])?);
            }
        }
    }
    (0..m)
        .map(|u| subsets_of(flock, u, &ends, &between))
        .collect()
}

/// UAV `u`'s best route through every subset of jobs (Held–Karp over
/// oriented visits).
fn subsets_of(
    flock: &mut Flock,
    u: usize,
    ends: &[Stop],
    between: &[Option<Leg>],
) -> Result<Subsets, TransitError> {
    let k = ends.len();
    let n = k / 2;
    let home = Stop::Home(u);
    let job: Vec<f64> = (0..n).map(|j| flock.job_time(u, j)).collect();
    let mut out = vec![0.0; k];
    let mut back = vec![0.0; k];
    for o in 0..k {
        out[o] = flock.leg_time_of(u, home, ends[o])? + job[o / 2];
        back[o] = flock.leg_time_of(u, ends[o ^ 1], home)?;
    }
    // From leaving visit a to leaving visit b.
    let step: Vec<f64> = (0..k * k)
        .map(|i| {
            let (a, b) = (i / k, i % k);
            between[(a ^ 1) * k + b]
                .map_or(f64::INFINITY, |leg| flock.leg_time(u, leg) + job[b / 2])
        })
        .collect();
    let subsets = 1usize << n;
    let mut best = vec![f64::INFINITY; subsets * k];
    let mut parent = vec![FIRST; subsets * k];
    for o in 0..k {
        best[(1 << (o / 2)) * k + o] = out[o];
    }
    let mut time = vec![f64::INFINITY; subsets];
    let mut last = vec![FIRST; subsets];
    time[0] = 0.0;
    for set in 1..subsets {
        for a in 0..k {
            let t = best[set * k + a];
            if !t.is_finite() {
                continue;
            }
            let home_t = t + back[a];
            if home_t < time[set] {
                time[set] = home_t;
                last[set] = a as u8;
            }
            for b in 0..k {
                let bit = 1 << (b / 2);
                if set & bit != 0 {
                    continue;
                }
                let i = (set | bit) * k + b;
                let v = t + step[a * k + b];
                if v < best[i] {
                    best[i] = v;
                    parent[i] = a as u8;
                }
            }
        }
    }
    Ok(Subsets { time, last, parent })
}

/// The best sharing of all jobs: per UAV its subset. Minimises the largest
/// time, then the sum of times; no UAV goes empty while `n >= m`.
fn share(per_uav: &[Subsets], n: usize) -> Vec<usize> {
    let m = per_uav.len();
    let full = (1usize << n) - 1;
    let allow_empty = n < m;
    let time = |u: usize, set: usize| {
        if set == 0 && !allow_empty {
            f64::INFINITY
        } else {
            per_uav[u].time[set]
        }
    };
    // (makespan, sum) of the first u + 1 UAVs flying each subset exactly.
    let mut score: Vec<(f64, f64)> = (0..=full).map(|s| (time(0, s), time(0, s))).collect();
    let mut choice = vec![vec![0u32; full + 1]; m];
    for (u, chosen) in choice.iter_mut().enumerate().skip(1) {
        let mut next = vec![(f64::INFINITY, f64::INFINITY); full + 1];
        for set in 0..=full {
            let mut sub = set;
            loop {
                let mine = time(u, sub);
                let (span, sum) = score[set ^ sub];
                let cand = (span.max(mine), sum + mine);
                if cand.0 < next[set].0 || (cand.0 == next[set].0 && cand.1 < next[set].1) {
                    next[set] = cand;
                    chosen[set] = sub as u32;
                }
                if sub == 0 {
                    break;
                }
                sub = (sub - 1) & set;
            }
        }
        score = next;
    }
    let mut shares = vec![0; m];
    let mut set = full;
    for u in (1..m).rev() {
        shares[u] = choice[u][set] as usize;
        set ^= shares[u];
    }
    shares[0] = set;
    shares
}

/// The route that flies `set` in the best time found for it.
fn route_of(s: &Subsets, n: usize, mut set: usize) -> Vec<Visit> {
    let k = 2 * n;
    let mut route = Vec::new();
    if set == 0 {
        return route;
    }
    let mut o = s.last[set];
    while o != FIRST {
        let a = usize::from(o);
        route.push(Visit::new(a / 2, (a % 2) as u8));
        let prev = s.parent[set * k + a];
        set ^= 1 << (a / 2);
        o = prev;
    }
    route.reverse();
    route
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flock::test_support::{lawnmower, rect};
    use crate::flock::{FlockJob, FlockUav, ObstacleMap};
    use geo_types::{MultiPolygon, coord};

    /// Every way of sharing and ordering the jobs, each job either way.
    fn brute_force(flock: &mut Flock) -> f64 {
        let (m, n) = (flock.uavs.len(), flock.jobs.len());
        let mut best = f64::INFINITY;
        let mut routes: Routes = vec![Vec::new(); m];
        fn go(flock: &mut Flock, routes: &mut Routes, j: usize, n: usize, best: &mut f64) {
            if j == n {
                if routes.iter().all(|r| !r.is_empty()) {
                    *best = best.min(flock.makespan(routes).unwrap());
                }
                return;
            }
            for u in 0..routes.len() {
                for at in 0..=routes[u].len() {
                    for way in 0..2 {
                        routes[u].insert(at, Visit::new(j, way));
                        go(flock, routes, j + 1, n, best);
                        routes[u].remove(at);
                    }
                }
            }
        }
        go(flock, &mut routes, 0, n, &mut best);
        let _ = m;
        best
    }

    #[test]
    fn the_programs_find_the_brute_force_optimum_round_an_nfz() {
        let cells = [
            rect(0.0, 0.0, 40.0, 100.0),
            rect(60.0, 0.0, 100.0, 100.0),
            rect(140.0, 0.0, 180.0, 60.0),
            rect(0.0, 150.0, 60.0, 200.0),
            rect(100.0, 130.0, 180.0, 170.0),
        ];
        let jobs: Vec<FlockJob> = cells
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let p = lawnmower(i, c, 2 + i % 3);
                FlockJob::from_plan(&p, p.length_m()).unwrap()
            })
            .collect();
        let nfz = MultiPolygon(vec![rect(45.0, 20.0, 55.0, 180.0)]);
        let map = ObstacleMap::new(&nfz, 0.0);
        let uav = |x: f64, y: f64| FlockUav {
            home: coord! { x: x, y: y },
            speed_m_s: 5.0,
        };
        let homes = [uav(-20.0, -20.0), uav(200.0, 90.0)];
        let mut flock = Flock::flat(homes.to_vec(), jobs, 2.0, &map, 30.0);
        let routes = exact_routes(&mut flock).unwrap().unwrap();
        assert!(routes.iter().all(|r| !r.is_empty()));
        let mut flown: Vec<usize> = routes.iter().flatten().map(|v| v.job).collect();
        flown.sort_unstable();
        assert_eq!(flown, vec![0, 1, 2, 3, 4]);
        let got = flock.makespan(&routes).unwrap();
        let optimum = brute_force(&mut flock);
        assert!(
            (got - optimum).abs() <= 1e-9 * optimum,
            "programs {got} vs brute force {optimum}"
        );
    }

    #[test]
    fn too_many_jobs_or_a_battery_is_left_to_the_search() {
        assert!(fits(8, 12));
        assert!(!fits(8, MAX_JOBS + 1));
        assert!(!fits(64, 16));
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let p = lawnmower(0, &rect(0.0, 0.0, 40.0, 100.0), 3);
        let job = FlockJob::from_plan(&p, p.length_m()).unwrap();
        let uav = FlockUav {
            home: coord! { x: 0.0, y: 0.0 },
            speed_m_s: 5.0,
        };
        let mut flock = Flock::flat(vec![uav, uav], vec![job.clone(), job], 0.0, &map, 0.0);
        flock.batteries[0] = Some(900.0);
        assert!(exact_routes(&mut flock).unwrap().is_none());
    }

    #[test]
    fn a_job_no_transit_reaches_is_left_to_the_search() {
        // A ring-shaped NFZ walls in the second job.
        let ring = geo_types::Polygon::new(
            rect(100.0, 0.0, 160.0, 60.0).exterior().clone(),
            vec![rect(110.0, 10.0, 150.0, 50.0).exterior().clone()],
        );
        let map = ObstacleMap::new(&MultiPolygon(vec![ring]), 0.0);
        let plans = [
            lawnmower(0, &rect(0.0, 0.0, 40.0, 60.0), 2),
            lawnmower(1, &rect(120.0, 20.0, 140.0, 40.0), 2),
        ];
        let jobs = plans
            .iter()
            .map(|p| FlockJob::from_plan(p, p.length_m()).unwrap())
            .collect();
        let uav = FlockUav {
            home: coord! { x: -10.0, y: -10.0 },
            speed_m_s: 5.0,
        };
        let mut flock = Flock::flat(vec![uav, uav], jobs, 0.0, &map, 0.0);
        assert!(exact_routes(&mut flock).unwrap().is_none());
    }
}
