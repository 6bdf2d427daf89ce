//! The `balanced` policy (beyond the thesis): start from the competition's
//! routes, or from the least makespan itself where a flock is small enough
//! to solve exactly ([`super::exact`]), and shorten the makespan, the
//! longest mission time, by local search until no move helps.
//!
//! Moves always involve the critical UAV (the one flying longest):
//! - *reorder / reverse* inside its route: 2-opt segment reversal (a single
//!   job reversed is the flip), and or-opt moves of 1–3 jobs, either way;
//! - *relocate* one of its jobs into another UAV's route, at the best place
//!   and way;
//! - *swap* one of its jobs with another UAV's job, each flown its best way.
//!
//! The score is the makespan, then the sum of squared mission times (so a
//! move that shortens one of several equally critical UAVs counts). Only
//! strictly better scores are taken, so the result is never worse than the
//! start, and the search ends. Candidates are first costed with straight
//! distances (a lower bound of every transit) and only searched round the
//! no-fly zones when that bound could win. No UAV is left without work.

use super::exact::exact_routes;
use super::problem::{Flock, Routes, Stop, Visit};
use super::transit::TransitError;

/// Relative margin a score must win by, against rounding.
const REL_EPS: f64 = 1e-9;
/// Improvement rounds (each strictly better; a guard, not a tuning knob).
const MAX_ROUNDS: usize = 20_000;
/// Passes of the route-internal search per call.
const MAX_ROUTE_PASSES: usize = 50;
/// Route-internal moves look this many positions ahead and back.
const ROUTE_WINDOW: usize = 40;

/// Makespan, then the sum of squared times.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Score {
    makespan: f64,
    sum_sq: f64,
}

impl Score {
    fn of(times: &[f64]) -> Score {
        Score {
            makespan: times.iter().copied().fold(0.0, f64::max),
            sum_sq: times.iter().map(|t| t * t).sum(),
        }
    }

    fn beats(&self, other: &Score) -> bool {
        let tol = REL_EPS * other.makespan.max(1.0);
        self.makespan < other.makespan - tol
            || (self.makespan <= other.makespan
                && self.sum_sq < other.sum_sq - REL_EPS * other.sum_sq.max(1.0))
    }
}

/// A move between the critical UAV `c` and another UAV.
#[derive(Clone, Copy, Debug)]
enum Move {
    /// Job at `from` of `c` goes to UAV `v` before position `at`.
    Relocate {
        from: usize,
        v: usize,
        at: usize,
        visit: Visit,
    },
    /// Job at `p` of `c` and job at `q` of `v` change UAVs.
    Swap {
        p: usize,
        v: usize,
        q: usize,
        into_c: Visit,
        into_v: Visit,
    },
}

/// Where UAV `u` is before position `k` of `route`.
fn before(u: usize, route: &[Visit], k: usize) -> Stop {
    if k == 0 {
        Stop::Home(u)
    } else {
        Stop::exit_of(route[k - 1])
    }
}

/// Where UAV `u` goes after position `k` of `route`.
fn after(u: usize, route: &[Visit], k: usize) -> Stop {
    if k + 1 >= route.len() {
        Stop::Home(u)
    } else {
        Stop::entry_of(route[k + 1])
    }
}

/// Improves `start` (normally the competition's routes) for the makespan;
/// a flock small enough starts from its optimum instead (see
/// [`exact_routes`]), the search then only evening out the other UAVs.
pub fn balanced(flock: &mut Flock, start: Routes) -> Result<Routes, TransitError> {
    let m = flock.uavs.len();
    let mut routes = start;
    if let Some(optimum) = exact_routes(flock)?
        && Score::of(&flock.times(&optimum)?).beats(&Score::of(&flock.times(&routes)?))
    {
        routes = optimum;
    }
    for (u, route) in routes.iter_mut().enumerate() {
        improve_route(flock, u, route)?;
    }
    let mut times = flock.times(&routes)?;
    for _ in 0..MAX_ROUNDS {
        let Some(c) = (0..m).max_by(|&a, &b| times[a].total_cmp(&times[b])) else {
            break;
        };
        if improve_route(flock, c, &mut routes[c])? {
            times[c] = flock.route_time(c, &routes[c])?;
            continue;
        }
        let Some(mv) = best_move(flock, &routes, &times, c)? else {
            break;
        };
        let v = match mv {
            Move::Relocate { from, v, at, visit } => {
                routes[c].remove(from);
                routes[v].insert(at, visit);
                v
            }
            Move::Swap {
                p,
                v,
                q,
                into_c,
                into_v,
            } => {
                routes[c][p] = into_c;
                routes[v][q] = into_v;
                v
            }
        };
        for u in [c, v] {
            improve_route(flock, u, &mut routes[u])?;
            times[u] = flock.route_time(u, &routes[u])?;
        }
    }
    Ok(routes)
}

/// The best strictly improving relocate or swap between `c` and another
/// UAV, if any.
fn best_move(
    flock: &mut Flock,
    routes: &Routes,
    times: &[f64],
    c: usize,
) -> Result<Option<Move>, TransitError> {
    let m = times.len();
    let current = Score::of(times);
    // The three longest, to find the longest UAV outside a pair quickly.
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| times[b].total_cmp(&times[a]));
    order.truncate(3);
    // Single-flight times: with a battery, the sorties only add to them, so
    // bounds built on these still bound the time with sorties.
    let mut plain = times.to_vec();
    for (u, route) in routes.iter().enumerate() {
        if flock.has_battery(u) {
            plain[u] = flock.flight_time(u, route)?;
        }
    }
    let mut search = MoveSearch {
        routes,
        times,
        c,
        current,
        order,
        plain,
        best: None,
    };
    let rc = &routes[c];
    for p in 0..rc.len() {
        let x = rc[p];
        let (bp, ap) = (before(c, rc, p), after(c, rc, p));
        let with_x = flock.leg_time_of(c, bp, Stop::entry_of(x))?
            + flock.job_time(c, x.job)
            + flock.leg_time_of(c, Stop::exit_of(x), ap)?;
        // c without x (only if c keeps some work).
        let c_without = if rc.len() < 2 {
            None
        } else if flock.has_battery(c) {
            let mut r = rc.clone();
            r.remove(p);
            Some(flock.route_time(c, &r)?)
        } else {
            Some(times[c] - with_x + flock.leg_time_of(c, bp, ap)?)
        };
        let taken = Taken {
            p,
            x,
            bp,
            ap,
            with_x,
        };
        for v in (0..m).filter(|&v| v != c) {
            if let Some(new_c) = c_without {
                search.relocations(flock, &taken, new_c, v)?;
            }
            search.swaps(flock, &taken, v)?;
        }
    }
    Ok(search.best.map(|(_, mv)| mv))
}

/// Visit `x` at position `p` of the longest route, between stops `bp` and
/// `ap`; `with_x` is what its legs and job cost there.
struct Taken {
    p: usize,
    x: Visit,
    bp: Stop,
    ap: Stop,
    with_x: f64,
}

/// State of one [`best_move`] search: what candidate moves are scored
/// against, and the best move so far.
struct MoveSearch<'r> {
    routes: &'r Routes,
    times: &'r [f64],
    /// The UAV whose work is moved or swapped.
    c: usize,
    current: Score,
    /// The three longest UAVs, longest first.
    order: Vec<usize>,
    /// Times without sorties (see [`best_move`]).
    plain: Vec<f64>,
    best: Option<(Score, Move)>,
}

impl MoveSearch<'_> {
    /// The score if `c` and `v` took `new_c` and `new_v`.
    fn score_with(&self, v: usize, new_c: f64, new_v: f64) -> Score {
        let (c, times) = (self.c, self.times);
        let rest = self
            .order
            .iter()
            .find(|&&k| k != c && k != v)
            .map_or(0.0, |&k| times[k]);
        Score {
            makespan: rest.max(new_c).max(new_v),
            sum_sq: self.current.sum_sq - times[c] * times[c] - times[v] * times[v]
                + new_c * new_c
                + new_v * new_v,
        }
    }

    /// The score a move must beat.
    fn bar(&self) -> Score {
        self.best.as_ref().map_or(self.current, |b| b.0)
    }

    /// Relocations of `taken` into every position and way of `v`'s route,
    /// `c` taking `new_c` without it.
    fn relocations(
        &mut self,
        flock: &mut Flock,
        taken: &Taken,
        new_c: f64,
        v: usize,
    ) -> Result<(), TransitError> {
        let Taken { p, x, .. } = *taken;
        let routes = self.routes;
        let rv = &routes[v];
        for at in 0..=rv.len() {
            let prev = before(v, rv, at);
            let next = if at < rv.len() {
                Stop::entry_of(rv[at])
            } else {
                Stop::Home(v)
            };
            let base = if rv.is_empty() {
                self.plain[v]
            } else {
                self.plain[v] - flock.leg_time_of(v, prev, next)?
            };
            for way in 0..2 {
                let xv = Visit::new(x.job, way);
                let (entry, exit) = (Stop::entry_of(xv), Stop::exit_of(xv));
                let job = flock.job_time(v, x.job);
                let lower = base
                    + flock.leg_time_lower(v, prev, entry)
                    + job
                    + flock.leg_time_lower(v, exit, next);
                let bar = self.bar();
                if !self.score_with(v, new_c, lower).beats(&bar) {
                    continue;
                }
                let new_v = if flock.has_battery(v) {
                    let mut r = rv.clone();
                    r.insert(at, xv);
                    flock.route_time(v, &r)?
                } else {
                    base + flock.leg_time_of(v, prev, entry)?
                        + job
                        + flock.leg_time_of(v, exit, next)?
                };
                let s = self.score_with(v, new_c, new_v);
                if s.beats(&bar) {
                    self.best = Some((
                        s,
                        Move::Relocate {
                            from: p,
                            v,
                            at,
                            visit: xv,
                        },
                    ));
                }
            }
        }
        Ok(())
    }

    /// Swaps of `taken` with every visit of `v`'s route, each flown the way
    /// that suits its new route best.
    fn swaps(&mut self, flock: &mut Flock, taken: &Taken, v: usize) -> Result<(), TransitError> {
        let Taken {
            p,
            x,
            bp,
            ap,
            with_x,
        } = *taken;
        let (c, times, routes) = (self.c, self.times, self.routes);
        let (rc, rv) = (&routes[c], &routes[v]);
        for q in 0..rv.len() {
            let y = rv[q];
            let (bq, aq) = (before(v, rv, q), after(v, rv, q));
            let with_y = flock.leg_time_of(v, bq, Stop::entry_of(y))?
                + flock.job_time(v, y.job)
                + flock.leg_time_of(v, Stop::exit_of(y), aq)?;
            // Lower bounds over both ways, then exact values.
            let bar = self.bar();
            let batteries = flock.has_battery(c) || flock.has_battery(v);
            let new_c_lower = self.plain[c] - with_x + lower_in(flock, c, y.job, bp, ap);
            let new_v_lower = self.plain[v] - with_y + lower_in(flock, v, x.job, bq, aq);
            if !self.score_with(v, new_c_lower, new_v_lower).beats(&bar) {
                continue;
            }
            let (into_c, in_c) = best_way(flock, c, y.job, bp, ap)?;
            let (into_v, in_v) = best_way(flock, v, x.job, bq, aq)?;
            let (new_c, new_v) = if batteries {
                let (mut r_c, mut r_v) = (rc.clone(), rv.clone());
                r_c[p] = into_c;
                r_v[q] = into_v;
                (flock.route_time(c, &r_c)?, flock.route_time(v, &r_v)?)
            } else {
                (times[c] - with_x + in_c, times[v] - with_y + in_v)
            };
            let s = self.score_with(v, new_c, new_v);
            if s.beats(&bar) {
                self.best = Some((
                    s,
                    Move::Swap {
                        p,
                        v,
                        q,
                        into_c,
                        into_v,
                    },
                ));
            }
        }
        Ok(())
    }
}

/// A lower bound of what UAV `u` spends on `job` between stops `b` and `a`,
/// over both ways.
fn lower_in(f: &Flock, u: usize, job: usize, b: Stop, a: Stop) -> f64 {
    (0..2)
        .map(|w| {
            let vis = Visit::new(job, w);
            f.leg_time_lower(u, b, Stop::entry_of(vis)) + f.leg_time_lower(u, Stop::exit_of(vis), a)
        })
        .fold(f64::INFINITY, f64::min)
        + f.job_time(u, job)
}

/// The way of flying `job` between stops `b` and `a` that costs UAV `u`
/// least, and that cost (legs and job).
fn best_way(
    flock: &mut Flock,
    u: usize,
    job: usize,
    b: Stop,
    a: Stop,
) -> Result<(Visit, f64), TransitError> {
    let mut best = (Visit::new(job, 0), f64::INFINITY);
    for w in 0..2 {
        let vis = Visit::new(job, w);
        let t = flock.leg_time_of(u, b, Stop::entry_of(vis))?
            + flock.leg_time_of(u, Stop::exit_of(vis), a)?;
        if t < best.1 {
            best = (vis, t);
        }
    }
    Ok((best.0, best.1 + flock.job_time(u, job)))
}

/// Route-internal local search for UAV `u`: 2-opt (with single flips) and
/// or-opt, first improvement, until no move helps. True if it changed.
pub(super) fn improve_route(
    flock: &mut Flock,
    u: usize,
    route: &mut Vec<Visit>,
) -> Result<bool, TransitError> {
    let mut changed = false;
    for _ in 0..MAX_ROUTE_PASSES {
        // The moves are costed on the single flight; with a battery a
        // sweep is kept only if the time with sorties improves too.
        let before = flock.route_time(u, route)?;
        let saved = flock.has_battery(u).then(|| route.clone());
        let scale = REL_EPS * flock.flight_time(u, route)?.max(1.0);
        if !(two_opt(flock, u, route, scale)? || or_opt(flock, u, route, scale)?) {
            break;
        }
        if let Some(saved) = saved
            && flock.route_time(u, route)? >= before - REL_EPS * before.max(1.0)
        {
            *route = saved;
            break;
        }
        changed = true;
    }
    Ok(changed)
}

/// One sweep of 2-opt: reverses `route[i..=j]` (each job flown the other
/// way) wherever that gains more than `eps` seconds. True if it changed.
fn two_opt(
    flock: &mut Flock,
    u: usize,
    route: &mut [Visit],
    eps: f64,
) -> Result<bool, TransitError> {
    let n = route.len();
    let mut changed = false;
    for i in 0..n {
        for j in i..n.min(i + ROUTE_WINDOW) {
            let (b, a) = (before(u, route, i), after(u, route, j));
            let (first_in, last_out) = (Stop::entry_of(route[i]), Stop::exit_of(route[j]));
            let old = flock.leg_time_of(u, b, first_in)? + flock.leg_time_of(u, last_out, a)?;
            let lower = flock.leg_time_lower(u, b, last_out) + flock.leg_time_lower(u, first_in, a);
            if old - lower <= eps {
                continue;
            }
            let new = flock.leg_time_of(u, b, last_out)? + flock.leg_time_of(u, first_in, a)?;
            if old - new > eps {
                route[i..=j].reverse();
                for v in &mut route[i..=j] {
                    *v = v.reversed();
                }
                changed = true;
            }
        }
    }
    Ok(changed)
}

/// One sweep of or-opt: moves 1–3 consecutive jobs elsewhere in the route
/// (as they are or reversed) wherever that gains more than `eps` seconds.
/// True if it changed.
fn or_opt(
    flock: &mut Flock,
    u: usize,
    route: &mut Vec<Visit>,
    eps: f64,
) -> Result<bool, TransitError> {
    let n = route.len();
    let mut changed = false;
    for len in 1..=3.min(n.saturating_sub(1)) {
        let mut i = 0;
        while i + len <= n {
            if try_or_move(flock, u, route, i, len, eps)? {
                changed = true;
            } else {
                i += 1;
            }
        }
    }
    Ok(changed)
}

/// Moves `route[i..i + len]` to the first gap (within the window) where it
/// gains more than `eps`; true if it did.
fn try_or_move(
    flock: &mut Flock,
    u: usize,
    route: &mut Vec<Visit>,
    i: usize,
    len: usize,
    eps: f64,
) -> Result<bool, TransitError> {
    let n = route.len();
    let last = i + len - 1;
    let (b, a) = (before(u, route, i), after(u, route, last));
    let (seg_in, seg_out) = (Stop::entry_of(route[i]), Stop::exit_of(route[last]));
    let removed = flock.leg_time_of(u, b, seg_in)? + flock.leg_time_of(u, seg_out, a)?
        - flock.leg_time_of(u, b, a)?;
    let lo = i.saturating_sub(ROUTE_WINDOW);
    let hi = (last + 1 + ROUTE_WINDOW).min(n);
    // Gap g lies between positions g - 1 and g.
    for g in (lo..=hi).filter(|&g| g < i || g > last + 1) {
        let gp = before(u, route, g);
        let gn = if g < n {
            Stop::entry_of(route[g])
        } else {
            Stop::Home(u)
        };
        let gap = flock.leg_time_of(u, gp, gn)?;
        for reversed in [false, true] {
            let (s_in, s_out) = if reversed {
                (seg_out, seg_in)
            } else {
                (seg_in, seg_out)
            };
            let lower =
                flock.leg_time_lower(u, gp, s_in) + flock.leg_time_lower(u, s_out, gn) - gap;
            if removed - lower <= eps {
                continue;
            }
            let added = flock.leg_time_of(u, gp, s_in)? + flock.leg_time_of(u, s_out, gn)? - gap;
            if removed - added > eps {
                let mut segment: Vec<Visit> = route.drain(i..=last).collect();
                if reversed {
                    segment.reverse();
                    for v in &mut segment {
                        *v = v.reversed();
                    }
                }
                let at = if g > last { g - len } else { g };
                route.splice(at..at, segment);
                return Ok(true);
            }
        }
    }
    Ok(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coverage::{CellPlan, Lane};
    use crate::flock::competition::competition;
    use crate::flock::problem::{FlockJob, FlockUav};
    use crate::flock::test_support::{Lcg, rect};
    use crate::flock::transit::ObstacleMap;
    use geo_types::{Coord, MultiPolygon, coord};

    fn lanes_job(x: f64, y: f64, lanes: usize, len: f64) -> FlockJob {
        let lanes: Vec<Lane> = (0..lanes)
            .map(|k| {
                let lx = x + 10.0 * k as f64;
                let (s, e) = (coord! { x: lx, y: y }, coord! { x: lx, y: y + len });
                if k % 2 == 0 {
                    Lane { start: s, end: e }
                } else {
                    Lane { start: e, end: s }
                }
            })
            .collect();
        let plan = CellPlan {
            cell_index: 0,
            direction_deg: 0.0,
            links: vec![Vec::new(); lanes.len() - 1],
            lanes,
        };
        FlockJob::from_plan(&plan, plan.length_m()).unwrap()
    }

    fn random_flock(rng: &mut Lcg, m: usize, n: usize) -> (Vec<FlockUav>, Vec<FlockJob>) {
        let uavs = (0..m)
            .map(|_| FlockUav {
                home: coord! { x: rng.next() * 2000.0, y: -100.0 - rng.next() * 200.0 },
                speed_m_s: 8.0 + 4.0 * rng.next(),
            })
            .collect();
        let jobs = (0..n)
            .map(|_| {
                lanes_job(
                    rng.next() * 2000.0,
                    rng.next() * 1500.0,
                    1 + (rng.next() * 12.0) as usize,
                    50.0 + rng.next() * 400.0,
                )
            })
            .collect();
        (uavs, jobs)
    }

    fn check_partition(routes: &Routes, n: usize) {
        let mut seen = vec![0; n];
        for r in routes {
            assert!(!r.is_empty(), "every UAV keeps work");
            for v in r {
                seen[v.job] += 1;
            }
        }
        assert!(seen.iter().all(|&s| s == 1), "every job once: {seen:?}");
    }

    #[test]
    fn never_worse_than_the_competition_and_usually_much_better() {
        let mut rng = Lcg(0xba1a_0ced);
        let nfz = MultiPolygon(vec![
            rect(700.0, 300.0, 900.0, 900.0),
            rect(1300.0, 1000.0, 1500.0, 1200.0),
        ]);
        let map = ObstacleMap::new(&nfz, 5.0);
        let mut gains = Vec::new();
        for trial in 0..24 {
            let m = 2 + trial % 6;
            let (uavs, jobs) = loop {
                let (u, j) = random_flock(&mut rng, m, 12);
                let clear = |p: Coord<f64>| !map.contains_point(p);
                if u.iter().all(|u| clear(u.home))
                    && j.iter().all(|j| j.ends.iter().all(|e| clear(e.at)))
                {
                    break (u, j);
                }
            };
            let mut flock = Flock::flat(uavs, jobs, 2.0, &map, 40.0);
            let (start, _) = competition(&mut flock).unwrap();
            let before = flock.makespan(&start).unwrap();
            let routes = balanced(&mut flock, start).unwrap();
            check_partition(&routes, 12);
            let after = flock.makespan(&routes).unwrap();
            assert!(
                after <= before * (1.0 + 1e-12),
                "trial {trial}: {after} > {before}"
            );
            gains.push(1.0 - after / before);
        }
        let mean = gains.iter().sum::<f64>() / gains.len() as f64;
        assert!(mean > 0.10, "mean makespan reduction {mean}");
    }

    #[test]
    fn batteries_count_their_sorties_and_are_never_worse() {
        let mut rng = Lcg(0x0bad_ba77);
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        for trial in 0..12 {
            let m = 2 + trial % 3;
            let (uavs, jobs) = random_flock(&mut rng, m, 10);
            let mut flock = Flock::flat(uavs, jobs, 2.0, &map, 40.0);
            // One UAV with a battery of about a third of its plain share.
            let (start, _) = competition(&mut flock).unwrap();
            let plain = flock.flight_time(0, &start[0]).unwrap();
            flock.batteries[0] = Some((plain / 3.0).max(400.0));
            let before = flock.makespan(&start).unwrap();
            let routes = balanced(&mut flock, start).unwrap();
            check_partition(&routes, 10);
            let after = flock.makespan(&routes).unwrap();
            assert!(
                after <= before * (1.0 + 1e-12),
                "trial {trial}: {after} > {before}"
            );
            // The battery UAV's time counts its returns home.
            let with = flock.route_time(0, &routes[0]).unwrap();
            let without = flock.flight_time(0, &routes[0]).unwrap();
            assert!(with >= without - 1e-9, "{with} < {without}");
        }
    }

    #[test]
    fn route_search_finds_the_obvious_order() {
        // Jobs on a line away from home, given in a zig-zag order.
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 0.0);
        let uav = FlockUav {
            home: coord! { x: 0.0, y: 0.0 },
            speed_m_s: 10.0,
        };
        let jobs: Vec<FlockJob> = (0..6)
            .map(|k| lanes_job(100.0 * k as f64 + 50.0, 0.0, 1, 20.0))
            .collect();
        let mut flock = Flock::flat(vec![uav], jobs, 0.0, &map, 0.0);
        let mut route: Vec<Visit> = [3, 0, 5, 1, 4, 2]
            .iter()
            .map(|&j| Visit::new(j, 0))
            .collect();
        let before = flock.route_time(0, &route).unwrap();
        assert!(improve_route(&mut flock, 0, &mut route).unwrap());
        let after = flock.route_time(0, &route).unwrap();
        // Optimal: the lanes flown up and down in turn on the way out, then
        // straight home: 2 × 550 m along the line plus 6 × 20 m of lanes
        // (no tour can be shorter: it must reach x = 550 and come back).
        let ideal = (2.0 * 550.0 + 6.0 * 20.0) / 10.0;
        assert!(after < before);
        assert!(after <= ideal + 1e-6, "{after} vs {ideal}");
    }
}
