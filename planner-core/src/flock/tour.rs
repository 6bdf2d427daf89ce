//! One UAV's tour over all cells: cell order and the end each cell is entered
//! at (SPEC §3.4, §3.5).
//!
//! A lawnmower cell can be flown four ways (start at the first or last lane,
//! at either end), so the tour is a small generalised TSP: visit every cell
//! once in one of its ways, starting and ending at home, minimising the
//! transit length. The four ways of a cell come in reverse pairs (`w` and
//! `w ^ 1` fly the same path backwards), which is what makes 2-opt segment
//! reversal valid here.
//!
//! 1. Construction: nearest neighbour over all (cell, way) entry points.
//! 2. Euclidean local search: exact orientation DP for the current order,
//!    then 2-opt, or-opt (segments of 1–3 cells, either direction, any way
//!    for a single cell) and in-place way changes on K-nearest-neighbour
//!    candidate lists, driven by a queue of cells whose surroundings changed
//!    ("don't-look bits"), so large tours converge in near-linear time.
//! 3. The same local search on real NFZ-avoiding transit lengths. Euclidean
//!    distance is a lower bound of the real one, so a move is only costed
//!    with [`ObstacleMap::shortest_path`] when its optimistic gain is
//!    positive; the number of such queries is capped.
//!
//! All effort is bounded by round, move and query budgets (no wall clock),
//! so the result is deterministic. 2000 cells take about 0.25 s (release
//! build), even among 1000 NFZs.

use std::collections::VecDeque;

use geo_types::{Coord, MultiPolygon, Polygon};
use rstar::RTree;
use rstar::primitives::GeomWithData;

mod legs;

use self::legs::{Legs, dist};
use super::transit::{Endpoint, ObstacleMap, TransitError, polyline_length};
use crate::coverage::{CellPlan, FreeSpace};

/// The flight of one UAV: its cells in order and the transits around them.
#[derive(Clone, Debug, PartialEq)]
pub struct Tour {
    /// Cells in flight order, each oriented as flown.
    pub visits: Vec<CellPlan>,
    /// `visits.len() + 1` transits: start → `visits[0]` entry, each exit →
    /// next entry, last exit → start. Every polyline includes its endpoints.
    pub transits: Vec<Vec<Coord<f64>>>,
}

impl Tour {
    /// The whole flown polyline (transits and cells) without consecutive
    /// duplicate points.
    pub fn path(&self) -> Vec<Coord<f64>> {
        let mut out: Vec<Coord<f64>> = Vec::new();
        let mut extend = |points: &[Coord<f64>]| {
            for &p in points {
                if out.last() != Some(&p) {
                    out.push(p);
                }
            }
        };
        for (i, transit) in self.transits.iter().enumerate() {
            extend(transit);
            if let Some(visit) = self.visits.get(i) {
                extend(&visit.path());
            }
        }
        out
    }

    /// Total length of the transits, metres.
    pub fn transit_length_m(&self) -> f64 {
        self.transits.iter().map(|t| polyline_length(t)).sum()
    }

    /// Transits plus the flown cell paths, metres.
    pub fn length_m(&self) -> f64 {
        self.transit_length_m() + self.visits.iter().map(CellPlan::length_m).sum::<f64>()
    }
}

/// Neighbours per cell in the candidate lists of the local search.
const NEIGHBOURS: usize = 10;
/// Rounds of (orientation DP, queued local moves) per phase.
const MAX_ROUNDS: usize = 25;
/// Job visits (each trying all moves around one cell) allowed per phase,
/// per cell.
const EFFORT_PER_JOB: usize = 40;
/// Real-length queries allowed in the second phase: `BASE + PER_CELL · n`.
const QUERY_BUDGET_BASE: usize = 500;
const QUERY_BUDGET_PER_CELL: usize = 4;
/// Moves must gain at least this much (metres) to count, against rounding.
const MIN_GAIN: f64 = 1e-6;
/// Tolerance when matching a re-oriented plan to the requested ends.
const END_MATCH_TOL: f64 = 1e-6;

/// Plans the tour of one UAV from `start` over every plan with lanes, and
/// back. `plans[i].cell_index` indexes `cells`; `free` is the free space the
/// cells' inner links must stay in (used to re-orient cells). Plans without
/// lanes are skipped. Fails if a transit cannot avoid the obstacles
/// (start inside an NFZ, or a cell unreachable), or if `start` or a lane end
/// is not finite.
pub fn plan_tour(
    start: Coord<f64>,
    plans: &[CellPlan],
    cells: &[Polygon<f64>],
    free: &MultiPolygon<f64>,
    obstacles: &ObstacleMap,
) -> Result<Tour, TransitError> {
    plan_tour_in(start, plans, cells, &FreeSpace::new(free), obstacles)
}

/// [`plan_tour`] in a free space already indexed: the survey's angle search
/// prices a tour per slice angle over the same free space.
pub fn plan_tour_in(
    start: Coord<f64>,
    plans: &[CellPlan],
    cells: &[Polygon<f64>],
    free: &FreeSpace,
    obstacles: &ObstacleMap,
) -> Result<Tour, TransitError> {
    let finite = |c: Coord<f64>| c.x.is_finite() && c.y.is_finite();
    if !finite(start) {
        return Err(TransitError::NonFinite {
            endpoint: Endpoint::Start,
        });
    }
    let jobs: Vec<Job> = plans
        .iter()
        .enumerate()
        .filter_map(|(i, plan)| Job::new(i, plan, cells.get(plan.cell_index).is_some()))
        .collect();
    // A corrupt plan must not reach the R-trees (NaN breaks their sorting).
    if jobs
        .iter()
        .any(|j| j.ways.iter().any(|w| !finite(w.entry) || !finite(w.exit)))
    {
        return Err(TransitError::NonFinite {
            endpoint: Endpoint::End,
        });
    }
    let mut legs = Legs::new(obstacles);

    let mut search = Search::new(start, &jobs);
    search.nearest_neighbour();
    search.improve(&mut legs);
    crate::cancel::check()?;
    legs.exact = true;
    legs.budget = QUERY_BUDGET_BASE + QUERY_BUDGET_PER_CELL * jobs.len();
    search.improve(&mut legs);
    crate::cancel::check()?;

    let visits: Vec<CellPlan> = search
        .seq
        .iter()
        .map(|&(j, way)| jobs[j].materialise(way, plans, cells, free))
        .collect();
    let mut transits = Vec::with_capacity(visits.len() + 1);
    let mut at = start;
    for visit in &visits {
        let (entry, exit) = (visit.entry().unwrap_or(at), visit.exit().unwrap_or(at));
        transits.push(legs.path(at, entry)?);
        at = exit;
    }
    transits.push(legs.path(at, start)?);
    Ok(Tour { visits, transits })
}

/// Entry and exit of one way of flying a cell.
#[derive(Clone, Copy, Debug)]
struct Way {
    entry: Coord<f64>,
    exit: Coord<f64>,
}

/// A cell to visit. Ways: 0 = as planned, 1 = its exact reverse, 2 = start
/// at the other end of the first lane, 3 = the reverse of 2.
#[derive(Clone, Debug)]
struct Job {
    plan: usize,
    ways: [Way; 4],
    centre: Coord<f64>,
}

impl Job {
    fn new(plan: usize, cell_plan: &CellPlan, has_cell: bool) -> Option<Job> {
        let first = cell_plan.lanes.first()?;
        let last = cell_plan.lanes.last()?;
        let forward = Way {
            entry: first.start,
            exit: last.end,
        };
        // Ways 2 and 3 need new links through the cell; without the cell
        // polygon they fall back to ways 0 and 1.
        let across = if has_cell {
            // The other end of the first run of lanes (a corridor's lane
            // is a run of several), and the start of the last.
            let runs = cell_plan.runs();
            let first_run_end = runs
                .first()
                .map_or(first.end, |r| cell_plan.lanes[r.end - 1].end);
            let last_run_start = runs
                .last()
                .map_or(last.start, |r| cell_plan.lanes[r.start].start);
            Way {
                entry: first_run_end,
                exit: last_run_start,
            }
        } else {
            forward
        };
        let rev = |w: Way| Way {
            entry: w.exit,
            exit: w.entry,
        };
        let c = [first.start, first.end, last.start, last.end];
        Some(Job {
            plan,
            ways: [forward, rev(forward), across, rev(across)],
            centre: Coord {
                x: c.iter().map(|p| p.x).sum::<f64>() / 4.0,
                y: c.iter().map(|p| p.y).sum::<f64>() / 4.0,
            },
        })
    }

    /// The cell plan flown in `way`. Ways 0 and 1 are the planned path
    /// forwards and backwards; ways 2 and 3 need new links, from
    /// [`CellPlan::reoriented`], whose result is checked to have the ends
    /// the search assumed (the closest match is kept otherwise).
    fn materialise(
        &self,
        way: u8,
        plans: &[CellPlan],
        cells: &[Polygon<f64>],
        free: &FreeSpace,
    ) -> CellPlan {
        let plan = &plans[self.plan];
        let forwards = way.is_multiple_of(2);
        let Some(cell) = cells.get(plan.cell_index).filter(|_| way >= 2) else {
            // The planned path forwards or backwards; ways 2 and 3 of a
            // plan whose cell is missing are these too (see `new`).
            return if forwards {
                plan.clone()
            } else {
                plan.reversed()
            };
        };
        let candidates: [(bool, bool); 3] = if forwards {
            [(false, true), (true, false), (true, true)]
        } else {
            [(true, false), (false, true), (true, true)]
        };
        let want = self.ways[way as usize];
        let mismatch = |p: &CellPlan| match (p.entry(), p.exit()) {
            (Some(a), Some(b)) => dist(a, want.entry) + dist(b, want.exit),
            _ => f64::INFINITY,
        };
        let mut best: Option<(f64, CellPlan)> = None;
        for (reverse_order, flip_lanes) in candidates {
            let p = plan.reoriented_in(reverse_order, flip_lanes, cell, free);
            let m = mismatch(&p);
            if m <= END_MATCH_TOL {
                return p;
            }
            if best.as_ref().is_none_or(|(bm, _)| m < *bm) {
                best = Some((m, p));
            }
        }
        best.map_or_else(|| plan.clone(), |(_, p)| p)
    }
}

/// The local search state: the sequence of (job, way) and each job's
/// position in it.
struct Search<'a> {
    start: Coord<f64>,
    jobs: &'a [Job],
    seq: Vec<(usize, u8)>,
    pos: Vec<usize>,
    neighbours: Vec<Vec<usize>>,
    home_neighbours: Vec<usize>,
}

impl<'a> Search<'a> {
    fn new(start: Coord<f64>, jobs: &'a [Job]) -> Self {
        let tree: RTree<GeomWithData<[f64; 2], usize>> = RTree::bulk_load(
            jobs.iter()
                .enumerate()
                .map(|(i, j)| GeomWithData::new([j.centre.x, j.centre.y], i))
                .collect(),
        );
        let nearest = |c: Coord<f64>, skip: Option<usize>| -> Vec<usize> {
            tree.nearest_neighbor_iter(&[c.x, c.y])
                .map(|g| g.data)
                .filter(|&i| Some(i) != skip)
                .take(NEIGHBOURS)
                .collect()
        };
        Search {
            start,
            jobs,
            seq: Vec::new(),
            pos: vec![0; jobs.len()],
            neighbours: jobs
                .iter()
                .enumerate()
                .map(|(i, j)| nearest(j.centre, Some(i)))
                .collect(),
            home_neighbours: nearest(start, None),
        }
    }

    /// Greedy construction: always fly to the nearest unvisited entry.
    fn nearest_neighbour(&mut self) {
        let mut tree: RTree<GeomWithData<[f64; 2], (usize, u8)>> = RTree::bulk_load(
            self.jobs
                .iter()
                .enumerate()
                .flat_map(|(i, j)| {
                    (0..4u8).map(move |w| {
                        let e = j.ways[w as usize].entry;
                        GeomWithData::new([e.x, e.y], (i, w))
                    })
                })
                .collect(),
        );
        let mut at = self.start;
        while let Some(&next) = tree.nearest_neighbor(&[at.x, at.y]) {
            let (job, way) = next.data;
            for w in 0..4u8 {
                let e = self.jobs[job].ways[w as usize].entry;
                tree.remove(&GeomWithData::new([e.x, e.y], (job, w)));
            }
            self.seq.push((job, way));
            at = self.jobs[job].ways[way as usize].exit;
        }
        self.reindex(0, self.seq.len());
    }

    fn reindex(&mut self, from: usize, to: usize) {
        for k in from..to.min(self.seq.len()) {
            self.pos[self.seq[k].0] = k;
        }
    }

    fn way(&self, k: usize) -> Way {
        let (job, way) = self.seq[k];
        self.jobs[job].ways[way as usize]
    }

    /// Exit of position `k`, home for `k = -1`.
    fn exit_of(&self, k: isize) -> Coord<f64> {
        if k < 0 {
            self.start
        } else {
            self.way(k as usize).exit
        }
    }

    /// Entry of position `k`, home past the end.
    fn entry_of(&self, k: usize) -> Coord<f64> {
        if k >= self.seq.len() {
            self.start
        } else {
            self.way(k).entry
        }
    }

    /// Local search until no move gains or the effort budget is spent.
    /// Jobs are processed from a queue ("don't-look bits"): after the first
    /// pass a job is only looked at again once a move changed a leg next to
    /// it, so quiet parts of a large tour cost next to nothing.
    fn improve(&mut self, legs: &mut Legs) {
        let n = self.seq.len();
        if n == 0 {
            return;
        }
        if legs.exact {
            // Price the current tour exactly (without budget: it is needed
            // for the final transits anyway).
            let tour: Vec<_> = (0..=n)
                .map(|k| (self.exit_of(k as isize - 1), self.entry_of(k)))
                .collect();
            legs.price_all(&tour);
        }
        let mut queued = vec![true; self.jobs.len()];
        let mut queue: VecDeque<usize> = self.seq.iter().map(|&(job, _)| job).collect();
        let mut effort = EFFORT_PER_JOB * n;
        for _ in 0..MAX_ROUNDS {
            let changed = self.orient(legs);
            let was_idle = queue.is_empty();
            for job in &changed {
                let k = self.pos[*job] as isize;
                self.activate(&mut queue, &mut queued, &[k - 1, k, k + 1]);
            }
            if changed.is_empty() && was_idle {
                break;
            }
            while let Some(job) = queue.pop_front() {
                queued[job] = false;
                // Cancelled: stop here, the caller checks again.
                if effort == 0
                    || (legs.exact && (legs.budget == 0 || legs.work_budget == 0))
                    || crate::cancel::check().is_err()
                {
                    return;
                }
                effort -= 1;
                if let Some(touched) = self.improve_job(job, legs) {
                    self.activate(&mut queue, &mut queued, &touched);
                }
            }
        }
    }

    /// Queues the jobs at `positions` (home and out-of-range are skipped).
    fn activate(&self, queue: &mut VecDeque<usize>, queued: &mut [bool], positions: &[isize]) {
        for &k in positions {
            if k >= 0 && (k as usize) < self.seq.len() {
                let job = self.seq[k as usize].0;
                if !queued[job] {
                    queued[job] = true;
                    queue.push_back(job);
                }
            }
        }
    }

    /// Neighbour list of the job at position `k`, or of home.
    fn near(&self, k: isize) -> &[usize] {
        if k < 0 || k as usize >= self.seq.len() {
            &self.home_neighbours
        } else {
            &self.neighbours[self.seq[k as usize].0]
        }
    }

    /// Tries the moves that remove a leg next to `job`; applies the first
    /// that gains and returns the positions whose legs changed.
    fn improve_job(&mut self, job: usize, legs: &mut Legs) -> Option<Vec<isize>> {
        let n = self.seq.len() as isize;
        let i = self.pos[job] as isize;

        // Another way of flying the cell, in place.
        let (_, w) = self.seq[i as usize];
        for v in [w ^ 1, w ^ 2, w ^ 3] {
            let (before, after) = (self.exit_of(i - 1), self.entry_of(i as usize + 1));
            let (old, new) = (self.way(i as usize), self.jobs[job].ways[v as usize]);
            let gain = Self::gain(
                legs,
                &[(before, old.entry), (old.exit, after)],
                &[(before, new.entry), (new.exit, after)],
            );
            if gain.is_some() {
                self.seq[i as usize].1 = v;
                return Some(vec![i - 1, i, i + 1]);
            }
        }

        // 2-opt moves that give the cell a new leg to a neighbour `c`
        // (reversing s..=e replaces legs exit(s-1) → entry(s) and
        // exit(e) → entry(e+1) by exit(s-1) → exit(e) and entry(s) →
        // entry(e+1)); plus the moves that send it home.
        let mut segments: Vec<(isize, isize)> =
            vec![(i, n - 1), (i + 1, n - 1), (0, i), (0, i - 1)];
        for &c in self.near(i) {
            let k = self.pos[c] as isize;
            // exit(i) → exit(k), exit(k) → exit(i), entry(i) → entry(k),
            // entry(k) → entry(i).
            segments.extend([(i + 1, k), (k + 1, i), (i, k - 1), (k, i - 1)]);
        }
        for (s, e) in segments {
            if s <= e && s >= 0 && e < n && self.try_reverse(legs, s as usize, e as usize) {
                return Some(vec![s - 1, s, e, e + 1]);
            }
        }

        // Or-opt: a segment of 1–3 cells starting or ending at i, moved
        // next to a neighbour of one of its ends.
        for len in 1..=3isize {
            for first in [i, i - len + 1] {
                if first < 0 || first + len > n || (len == 1 && first != i) {
                    continue;
                }
                let last = first + len - 1;
                let mut targets: Vec<isize> = vec![-1, n - 1];
                for &c in self.near(first).iter().chain(self.near(last)) {
                    let q = self.pos[c] as isize;
                    targets.extend([q, q - 1]);
                }
                for q in targets {
                    if let Some(at) = self.try_move(legs, first as usize, len as usize, q) {
                        let at = at as isize;
                        return Some(vec![first - 1, first, at - 1, at, at + len - 1, at + len]);
                    }
                }
            }
        }
        None
    }

    /// Gain test for a move replacing legs `old` by legs `new`: cheap bound
    /// first, then exact costs. Returns the exact gain if worth taking.
    fn gain(
        legs: &mut Legs,
        old: &[(Coord<f64>, Coord<f64>)],
        new: &[(Coord<f64>, Coord<f64>)],
    ) -> Option<f64> {
        let old_cost: f64 = old.iter().map(|&(p, q)| legs.lower(p, q)).sum();
        let optimistic: f64 = new.iter().map(|&(p, q)| legs.lower(p, q)).sum();
        if old_cost - optimistic <= MIN_GAIN {
            return None;
        }
        let mut new_cost = 0.0;
        for &(p, q) in new {
            new_cost += legs.cost(p, q)?;
        }
        let gain = old_cost - new_cost;
        (gain > MIN_GAIN).then_some(gain)
    }

    /// Best ways for the current order: a shortest path through 4 states per
    /// position (exact for Euclidean costs; with real costs, legs not yet
    /// priced count at their lower bound and the result is verified).
    /// Returns the jobs whose way changed.
    fn orient(&mut self, legs: &mut Legs) -> Vec<usize> {
        let n = self.seq.len();
        let mut cost = [0.0f64; 4];
        let mut back: Vec<[u8; 4]> = Vec::with_capacity(n);
        for k in 0..n {
            let ways = &self.jobs[self.seq[k].0].ways;
            let mut next = [f64::INFINITY; 4];
            let mut from = [0u8; 4];
            for w in 0..4 {
                if k == 0 {
                    next[w] = legs.lower(self.start, ways[w].entry);
                    continue;
                }
                let prev = &self.jobs[self.seq[k - 1].0].ways;
                for v in 0..4 {
                    let c = cost[v] + legs.lower(prev[v].exit, ways[w].entry);
                    if c < next[w] {
                        next[w] = c;
                        from[w] = v as u8;
                    }
                }
            }
            back.push(from);
            cost = next;
        }
        let last = &self.jobs[self.seq[n - 1].0].ways;
        let mut best = 0u8;
        let mut best_cost = f64::INFINITY;
        for w in 0..4 {
            let c = cost[w] + legs.lower(last[w].exit, self.start);
            if c < best_cost {
                best_cost = c;
                best = w as u8;
            }
        }
        let mut chosen = vec![0u8; n];
        chosen[n - 1] = best;
        for k in (1..n).rev() {
            chosen[k - 1] = back[k][chosen[k] as usize];
        }
        let trial: Vec<(usize, u8)> = self
            .seq
            .iter()
            .zip(&chosen)
            .map(|(&(j, _), &w)| (j, w))
            .collect();
        // Only the legs that change enter the comparison (less rounding).
        let (mut old_legs, mut new_legs) = (Vec::new(), Vec::new());
        for (o, n) in self
            .legs_of(&self.seq)
            .into_iter()
            .zip(self.legs_of(&trial))
        {
            if o != n {
                old_legs.push(o);
                new_legs.push(n);
            }
        }
        if old_legs.is_empty() || Self::gain(legs, &old_legs, &new_legs).is_none() {
            return Vec::new();
        }
        let changed = self
            .seq
            .iter()
            .zip(&trial)
            .filter(|(a, b)| a.1 != b.1)
            .map(|(a, _)| a.0)
            .collect();
        self.seq = trial;
        changed
    }

    /// All legs of the tour flying `seq`, home to home.
    fn legs_of(&self, seq: &[(usize, u8)]) -> Vec<(Coord<f64>, Coord<f64>)> {
        let mut out = Vec::with_capacity(seq.len() + 1);
        let mut at = self.start;
        for &(j, w) in seq {
            let way = self.jobs[j].ways[w as usize];
            out.push((at, way.entry));
            at = way.exit;
        }
        out.push((at, self.start));
        out
    }

    /// 2-opt: reverse positions `i..=j`, flying each cell backwards.
    fn try_reverse(&mut self, legs: &mut Legs, i: usize, j: usize) -> bool {
        let before = self.exit_of(i as isize - 1);
        let after = self.entry_of(j + 1);
        let (first, last) = (self.way(i), self.way(j));
        let old = [(before, first.entry), (last.exit, after)];
        let new = [(before, last.exit), (first.entry, after)];
        if Self::gain(legs, &old, &new).is_none() {
            return false;
        }
        self.seq[i..=j].reverse();
        for step in &mut self.seq[i..=j] {
            step.1 ^= 1;
        }
        self.reindex(i, j + 1);
        true
    }

    /// Or-opt: moves `seq[i..i+len]` between positions `q` and `q + 1` (in
    /// the current indexing; `q = -1` is right after home), as is, reversed,
    /// or for a single cell in another way. Returns the segment's new start.
    fn try_move(&mut self, legs: &mut Legs, i: usize, len: usize, q: isize) -> Option<usize> {
        let n = self.seq.len() as isize;
        let (i_s, end) = (i as isize, (i + len) as isize);
        if q < -1 || q >= n || (q >= i_s - 1 && q < end) {
            return None;
        }
        let before = self.exit_of(i_s - 1);
        let after = self.entry_of(i + len);
        let (first, last) = (self.way(i), self.way(i + len - 1));
        let (x, y) = (self.exit_of(q), self.entry_of((q + 1) as usize));

        // The segment as is, backwards, or (a single cell) flown another
        // way: its ends are priced before anything is copied.
        let ((j0, w0), (j1, w1)) = (self.seq[i], self.seq[i + len - 1]);
        let option_count = if len == 1 { 4 } else { 2 };
        let old = [(before, first.entry), (last.exit, after), (x, y)];
        for option in 0..option_count {
            let (entry, exit) = match option {
                0 => (first.entry, last.exit),
                1 => (
                    self.jobs[j1].ways[(w1 ^ 1) as usize].entry,
                    self.jobs[j0].ways[(w0 ^ 1) as usize].exit,
                ),
                _ => {
                    let way = self.jobs[j0].ways[(w0 ^ option as u8) as usize];
                    (way.entry, way.exit)
                }
            };
            let new = [(before, after), (x, entry), (exit, y)];
            if Self::gain(legs, &old, &new).is_none() {
                continue;
            }
            let segment: Vec<(usize, u8)> = match option {
                0 => self.seq[i..i + len].to_vec(),
                1 => self.seq[i..i + len]
                    .iter()
                    .rev()
                    .map(|&(j, w)| (j, w ^ 1))
                    .collect(),
                _ => vec![(j0, w0 ^ option as u8)],
            };
            self.seq.drain(i..i + len);
            // Insertion index after the removal.
            let at = if q < i_s {
                (q + 1) as usize
            } else {
                (q + 1) as usize - len
            };
            self.seq.splice(at..at, segment);
            self.reindex(i.min(at), (i + len).max(at + len));
            return Some(at);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coverage::Lane;
    use crate::flock::test_support::{Lcg, lawnmower, rect};
    use approx::assert_relative_eq;
    use geo_types::coord;

    struct Case {
        cells: Vec<Polygon<f64>>,
        plans: Vec<CellPlan>,
        free: MultiPolygon<f64>,
    }

    impl Case {
        /// The jobs `plan_tour` makes of the plans (every cell is present).
        fn jobs(&self) -> Vec<Job> {
            self.plans
                .iter()
                .enumerate()
                .filter_map(|(i, p)| Job::new(i, p, true))
                .collect()
        }
    }

    fn case(cells: Vec<Polygon<f64>>, lanes: usize, order: &[usize]) -> Case {
        let plans = order
            .iter()
            .map(|&i| lawnmower(i, &cells[i], lanes))
            .collect();
        let free = MultiPolygon(cells.clone());
        Case { cells, plans, free }
    }

    /// Structural checks every tour must pass.
    fn check_tour(tour: &Tour, start: Coord<f64>, map: &ObstacleMap, case: &Case) {
        assert_eq!(tour.transits.len(), tour.visits.len() + 1);
        let mut seen: Vec<usize> = tour.visits.iter().map(|v| v.cell_index).collect();
        seen.sort_unstable();
        let mut expected: Vec<usize> = case
            .plans
            .iter()
            .filter(|p| !p.lanes.is_empty())
            .map(|p| p.cell_index)
            .collect();
        expected.sort_unstable();
        assert_eq!(seen, expected, "every cell exactly once");
        let mut at = start;
        for (i, transit) in tour.transits.iter().enumerate() {
            assert_eq!(transit.first(), Some(&at));
            let to = tour.visits.get(i).map_or(start, |v| v.entry().unwrap());
            assert_eq!(transit.last(), Some(&to));
            for w in transit.windows(2) {
                assert!(map.is_clear(w[0], w[1]), "transit {i} segment {w:?}");
            }
            if let Some(v) = tour.visits.get(i) {
                at = v.exit().unwrap();
            }
        }
        // Each visit flies the same lanes as its plan, in one of four ways.
        for v in &tour.visits {
            let plan = case
                .plans
                .iter()
                .find(|p| p.cell_index == v.cell_index)
                .unwrap();
            let mut a: Vec<_> = plan.lanes.iter().map(sorted_ends).collect();
            let mut b: Vec<_> = v.lanes.iter().map(sorted_ends).collect();
            a.sort_by(|x, y| x.partial_cmp(y).unwrap());
            b.sort_by(|x, y| x.partial_cmp(y).unwrap());
            assert_eq!(a, b);
        }
        let path = tour.path();
        assert_eq!(path.first(), Some(&start));
        assert_eq!(path.last(), Some(&start));
        assert!(path.windows(2).all(|w| w[0] != w[1]));
        assert_relative_eq!(polyline_length(&path), tour.length_m(), max_relative = 1e-9);
    }

    fn sorted_ends(l: &Lane) -> [f64; 4] {
        let (p, q) = if (l.start.x, l.start.y) <= (l.end.x, l.end.y) {
            (l.start, l.end)
        } else {
            (l.end, l.start)
        };
        [p.x, p.y, q.x, q.y]
    }

    /// Transit length of flying `plans` as given, in input order.
    fn input_order_length(start: Coord<f64>, plans: &[CellPlan], map: &ObstacleMap) -> f64 {
        let mut at = start;
        let mut total = 0.0;
        for p in plans {
            total += map.shortest_length(at, p.entry().unwrap()).unwrap();
            at = p.exit().unwrap();
        }
        total + map.shortest_length(at, start).unwrap()
    }

    #[test]
    fn row_of_cells_is_flown_in_row_order() {
        // Six cells in a row east of home, handed over shuffled.
        let cells: Vec<_> = (0..6)
            .map(|k| rect(20.0 * k as f64, 0.0, 20.0 * k as f64 + 15.0, 40.0))
            .collect();
        let c = case(cells, 3, &[3, 0, 5, 1, 4, 2]);
        let start = coord! { x: -10.0, y: 0.0 };
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 1.0);
        let tour = plan_tour(start, &c.plans, &c.cells, &c.free, &map).unwrap();
        check_tour(&tour, start, &map, &c);
        let order: Vec<usize> = tour.visits.iter().map(|v| v.cell_index).collect();
        assert_eq!(order, vec![0, 1, 2, 3, 4, 5]);
        // Ends are chosen so each cell is entered where the previous one
        // was left: every inner transit just crosses a 5 m gap.
        for t in &tour.transits[1..6] {
            assert_relative_eq!(polyline_length(t), 10.0, epsilon = 1e-9);
        }
        assert!(tour.transit_length_m() < input_order_length(start, &c.plans, &map) / 2.0);
    }

    #[test]
    fn shuffled_grid_beats_input_order() {
        let mut cells = Vec::new();
        for i in 0..6 {
            for j in 0..6 {
                let (x, y) = (30.0 * i as f64, 50.0 * j as f64);
                cells.push(rect(x, y, x + 25.0, y + 45.0));
            }
        }
        // A fixed scramble of 0..36.
        let order: Vec<usize> = (0..36).map(|k| (k * 17 + 5) % 36).collect();
        let c = case(cells, 4, &order);
        let start = coord! { x: -20.0, y: -20.0 };
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 1.0);
        let tour = plan_tour(start, &c.plans, &c.cells, &c.free, &map).unwrap();
        check_tour(&tour, start, &map, &c);
        let given = input_order_length(start, &c.plans, &map);
        let planned = tour.transit_length_m();
        assert!(planned < given / 4.0, "{planned} vs {given}");
        // At least as good as the hand-made answer: a row-by-row serpentine
        // with the best ways for that order.
        let jobs = c.jobs();
        let mut search = Search::new(start, &jobs);
        let job_of_cell = |cell: usize| c.plans.iter().position(|p| p.cell_index == cell).unwrap();
        for j in 0..6 {
            for i in 0..6 {
                let i = if j % 2 == 0 { i } else { 5 - i };
                search.seq.push((job_of_cell(i * 6 + j), 0));
            }
        }
        search.reindex(0, 36);
        let mut legs = Legs::new(&map);
        search.orient(&mut legs);
        let serpentine: f64 = search
            .legs_of(&search.seq)
            .iter()
            .map(|&(p, q)| dist(p, q))
            .sum();
        assert!(
            planned <= serpentine + 1e-6,
            "{planned} vs serpentine {serpentine}"
        );
    }

    /// Exhaustive optimum over all orders and ways (Euclidean, no NFZ).
    fn brute_force(start: Coord<f64>, jobs: &[Job]) -> f64 {
        fn rec(
            at: Coord<f64>,
            start: Coord<f64>,
            jobs: &[Job],
            used: &mut Vec<bool>,
            acc: f64,
            best: &mut f64,
        ) {
            if acc >= *best {
                return;
            }
            if used.iter().all(|&u| u) {
                *best = best.min(acc + dist(at, start));
                return;
            }
            for j in 0..jobs.len() {
                if used[j] {
                    continue;
                }
                used[j] = true;
                for w in &jobs[j].ways {
                    rec(w.exit, start, jobs, used, acc + dist(at, w.entry), best);
                }
                used[j] = false;
            }
        }
        let mut best = f64::INFINITY;
        rec(
            start,
            start,
            jobs,
            &mut vec![false; jobs.len()],
            0.0,
            &mut best,
        );
        best
    }

    #[test]
    fn small_random_instances_are_solved_optimally() {
        let mut rng = Lcg(3);
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 1.0);
        let mut worse = 0;
        for _ in 0..40 {
            let cells: Vec<_> = (0..6)
                .map(|_| {
                    let (x, y) = (rng.next() * 300.0, rng.next() * 300.0);
                    rect(
                        x,
                        y,
                        x + 10.0 + rng.next() * 40.0,
                        y + 10.0 + rng.next() * 40.0,
                    )
                })
                .collect();
            let lanes = 1 + (rng.next() * 4.0) as usize;
            let c = case(cells, lanes, &[0, 1, 2, 3, 4, 5]);
            let start = coord! { x: rng.next() * 300.0, y: rng.next() * 300.0 };
            let tour = plan_tour(start, &c.plans, &c.cells, &c.free, &map).unwrap();
            check_tour(&tour, start, &map, &c);
            let optimum = brute_force(start, &c.jobs());
            let got = tour.transit_length_m();
            assert!(got >= optimum - 1e-6);
            if got > optimum + 1e-6 {
                worse += 1;
                assert!(got < optimum * 1.1, "{got} vs optimum {optimum}");
            }
        }
        assert!(worse <= 2, "{worse} of 40 instances not optimal");
    }

    #[test]
    fn transits_avoid_nfzs_and_real_lengths_steer_the_order() {
        // Two columns of cells separated by a long NFZ wall with a gap at
        // the south end. Euclid sees the columns as neighbours; flying
        // across means going round the wall.
        let mut cells = Vec::new();
        for j in 0..5 {
            let y = 100.0 + 60.0 * j as f64;
            cells.push(rect(0.0, y, 40.0, y + 50.0));
            cells.push(rect(60.0, y, 100.0, y + 50.0));
        }
        let wall = rect(45.0, 50.0, 55.0, 420.0);
        let nfz = MultiPolygon(vec![wall]);
        let map = ObstacleMap::new(&nfz, 2.0);
        let c = case(cells, 3, &(0..10).collect::<Vec<_>>());
        let start = coord! { x: 50.0, y: 0.0 };
        let tour = plan_tour(start, &c.plans, &c.cells, &c.free, &map).unwrap();
        check_tour(&tour, start, &map, &c);
        // The wall is crossed only round its ends: at most twice in all.
        let side = |v: &CellPlan| v.lanes[0].start.x < 50.0;
        let switches = tour
            .visits
            .windows(2)
            .filter(|w| side(&w[0]) != side(&w[1]))
            .count();
        assert!(switches <= 1, "{switches} wall crossings");
        assert!(
            tour.transits.iter().any(|t| t.len() > 2),
            "some transit bends round the wall"
        );
    }

    #[test]
    fn degenerate_inputs() {
        let map = ObstacleMap::new(&MultiPolygon(vec![]), 1.0);
        let start = coord! { x: 1.0, y: 2.0 };
        let tour = plan_tour(start, &[], &[], &MultiPolygon(vec![]), &map).unwrap();
        assert!(tour.visits.is_empty());
        assert_eq!(tour.transits, vec![vec![start, start]]);
        assert_eq!(tour.path(), vec![start]);
        assert_eq!(tour.length_m(), 0.0);

        // A plan without lanes is skipped; a plan whose cell is missing is
        // only flown forwards or backwards.
        let cells = vec![rect(0.0, 0.0, 20.0, 20.0)];
        let mut empty = lawnmower(0, &cells[0], 2);
        empty.lanes.clear();
        empty.links.clear();
        let orphan = CellPlan {
            cell_index: 7,
            ..lawnmower(0, &rect(50.0, 0.0, 70.0, 20.0), 2)
        };
        let plans = vec![empty, orphan.clone()];
        let tour = plan_tour(start, &plans, &cells, &MultiPolygon(cells.clone()), &map).unwrap();
        assert_eq!(tour.visits.len(), 1);
        let v = &tour.visits[0];
        assert!(*v == orphan || *v == orphan.reversed());

        // Non-finite input is an error, not a panic.
        let nan = coord! { x: f64::NAN, y: 0.0 };
        let err = plan_tour(nan, &plans, &cells, &MultiPolygon(cells.clone()), &map);
        assert_eq!(
            err,
            Err(TransitError::NonFinite {
                endpoint: Endpoint::Start
            })
        );
        let mut bad = orphan.clone();
        bad.lanes[1].end = nan;
        let err = plan_tour(start, &[bad], &cells, &MultiPolygon(cells.clone()), &map);
        assert!(matches!(err, Err(TransitError::NonFinite { .. })));
    }

    #[test]
    fn start_inside_an_nfz_is_an_error() {
        let cells = vec![rect(0.0, 0.0, 20.0, 20.0)];
        let c = case(cells, 2, &[0]);
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(30.0, 0.0, 40.0, 10.0)]), 1.0);
        let start = coord! { x: 35.0, y: 5.0 };
        let err = plan_tour(start, &c.plans, &c.cells, &c.free, &map).unwrap_err();
        assert!(matches!(err, TransitError::InsideObstacle { .. }), "{err}");
    }
}

#[cfg(test)]
mod timing {
    //! `cargo test --release -p planner-core --lib flock::tour::timing -- --ignored --nocapture`
    use super::*;
    use crate::coverage::Lane;
    use crate::flock::test_support::{Lcg, lawnmower, octagon_field, rect};
    use geo_types::{LineString, coord};
    use std::time::Instant;

    #[test]
    #[ignore = "timing run, not a check"]
    fn cells_scattered_in_a_dense_nfz_field() {
        // ~1000 random 8-gon NFZs on a 32 × 32 grid of 300 m blocks, and
        // 2000 small 20 × 20 m cells dropped wherever they fit: most legs
        // have to bend round NFZs.
        let mut rng = Lcg(5);
        let (blocks, block) = (32, 300.0);
        let nfz = octagon_field(&mut rng, blocks, block, coord! { x: 0.0, y: 0.0 });
        let map = ObstacleMap::new(&MultiPolygon(nfz), 2.0);
        let side = blocks as f64 * block;
        let mut cells = Vec::new();
        while cells.len() < 2000 {
            let (x, y) = (rng.next() * (side - 20.0), rng.next() * (side - 20.0));
            let c = rect(x, y, x + 20.0, y + 20.0);
            let ring = &c.exterior().0;
            if ring.windows(2).all(|w| map.is_clear(w[0], w[1]))
                && !map.contains_point(coord! { x: x + 10.0, y: y + 10.0 })
            {
                cells.push(c);
            }
        }
        let plans: Vec<CellPlan> = cells
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let o = c.exterior().0[0];
                let lanes = (0..2)
                    .map(|l| {
                        let x = o.x + 5.0 + 10.0 * l as f64;
                        let (s, e) = (
                            coord! { x: x, y: o.y + 1.0 },
                            coord! { x: x, y: o.y + 19.0 },
                        );
                        if l == 0 {
                            Lane { start: s, end: e }
                        } else {
                            Lane { start: e, end: s }
                        }
                    })
                    .collect();
                CellPlan {
                    cell_index: i,
                    direction_deg: 0.0,
                    lanes,
                    links: vec![Vec::new()],
                }
            })
            .collect();
        let free = MultiPolygon(cells.clone());
        let start = coord! { x: side / 2.0, y: -10.0 };
        let t = Instant::now();
        let tour = plan_tour(start, &plans, &cells, &free, &map).unwrap();
        println!(
            "dense field, {} cells, {} NFZs: plan_tour {:?}, transit {:.0} m, {} bent transits",
            cells.len(),
            map.obstacle_count(),
            t.elapsed(),
            tour.transit_length_m(),
            tour.transits.iter().filter(|t| t.len() > 2).count()
        );
    }

    #[test]
    #[ignore = "timing run, not a check"]
    fn two_thousand_cells() {
        // A 50 × 50 grid of 40 × 60 m blocks; one block in five is an NFZ,
        // the others are cells with four lanes, listed in a scrambled order.
        let (nx, ny) = (50usize, 50usize);
        let (x0, y0) = (500_000.0, 5_000_000.0);
        let (mut cells, mut nfz) = (Vec::new(), Vec::new());
        for k in 0..nx * ny {
            let (i, j) = (k % nx, k / nx);
            let (x, y) = (x0 + 45.0 * i as f64, y0 + 65.0 * j as f64);
            if (k * 7919) % 5 == 0 {
                nfz.push(rect(x, y, x + 40.0, y + 60.0));
            } else {
                cells.push(rect(x, y, x + 40.0, y + 60.0));
            }
        }
        let holes: Vec<LineString<f64>> = nfz.iter().map(|p| p.exterior().clone()).collect();
        let roi = rect(
            x0 - 5.0,
            y0 - 5.0,
            x0 + 45.0 * nx as f64,
            y0 + 65.0 * ny as f64,
        );
        let free = MultiPolygon(vec![Polygon::new(roi.exterior().clone(), holes)]);
        let n = cells.len();
        let plans: Vec<CellPlan> = (0..n)
            .map(|k| {
                let i = (k * 7 + 3) % n;
                lawnmower(i, &cells[i], 4)
            })
            .collect();
        let t = Instant::now();
        let map = ObstacleMap::new(&MultiPolygon(nfz), 2.0);
        println!(
            "{} cells, {} NFZs: obstacle map {:?}",
            n,
            map.obstacle_count(),
            t.elapsed()
        );
        let start = coord! { x: x0 - 3.0, y: y0 - 3.0 };
        let t = Instant::now();
        let tour = plan_tour(start, &plans, &cells, &free, &map).unwrap();
        println!(
            "plan_tour {:?}: transit {:.0} m, total {:.0} m, {} bent transits",
            t.elapsed(),
            tour.transit_length_m(),
            tour.length_m(),
            tour.transits.iter().filter(|t| t.len() > 2).count()
        );
    }
}
