//! D* Lite (Koenig & Likhachev 2002, the optimised version of their
//! figure 4) on the same graph and arc rules as [`astar`](super::astar()).
//!
//! The search runs backwards from the goal: g(s) is the cost from s to the
//! goal, rhs(s) = min over moves s → s' of arc(s, s') + g(s'), and the
//! queue orders inconsistent cells (g ≠ rhs) by the key
//! [min(g, rhs) + h(start, s) + k_m; min(g, rhs)]. When the robot moves,
//! k_m grows by the old heuristic's value at the new start, so queued keys
//! stay valid lower bounds; when cells change, only the cells whose moves
//! changed are re-evaluated and the previous search is repaired from there.
//!
//! The first search at A*'s speed: with the octile bound alone, the
//! backward search floods far more than A* forwards (15 M cells against
//! 5 M on the 4000² benchmark map, each dearer). So a fresh planner first
//! runs A* from the start (the fast dense search) and uses its costs as a
//! landmark heuristic (`landmark`): h(s, u) = max(octile, D(u) − D(s)),
//! exact along the route, so the backward search then only walks the
//! route. It goes on for a tenth of A*'s expansions beyond that, settling
//! the cells nearest in cost to the route, so that a replan after a block
//! repairs a settled neighbourhood instead of discovering it. Blocked cells
//! and raised costs keep the landmark admissible and consistent; a lowered
//! cost is checked around the cell and, if it breaks the landmark's bound,
//! the search starts over ([`landmark_restarts`](DStarLite::landmark_restarts)).
//!
//! Memory: the caller's f32 cost, an f64 g and one state byte per cell
//! (13 bytes), the landmark's A* labels (8 bytes per cell), and the queue.
//! rhs is not stored: each cell keeps the move to its best successor (3
//! bits + a flag) and rhs(s) = arc(s, bp(s)) + g(bp(s)). That is an exact
//! representation of D* Lite's rhs as long as every change of a
//! successor's g is followed by updating the cell, which D* Lite does
//! anyway (the optimised version's "rhs(s) == c(s,u) + g_old" test becomes
//! "bp(s) == u"). The queue is A*'s exact bucket queue with lazy deletion:
//! a cell's "in the queue" bit says whether its entries are live, and an
//! entry whose key is out of date is re-queued with the current key (the
//! algorithm's own "k_old < k_new" rule).
//!
//! Changes of the arc model: with `thesis` arcs every arc depends on the
//! map's cost range (min, max of the finite costs). After each
//! [`update_cells`](DStarLite::update_cells) the range of the current map is
//! used, exactly as a search from scratch would; when a change moves it
//! (a new cost above the max or below the min, or the last cell at the max
//! or min changed), every arc changes and the planner starts over (a full
//! re-plan; [`restarts`](DStarLite::restarts) counts them). Changes inside
//! the range are repaired incrementally. With `integrated` arcs only the
//! heuristic depends on the range (its factor is the least cost): a new
//! cost below it restarts the search, other changes never do.

use std::sync::Arc;

use super::arc_model::ArcModel;
use super::astar::{open_list, search_tree};
use super::bucket_queue::BucketQueue;
use super::dist_array::DistArray;
use super::landmark::{Landmark, StartHeuristic};
use super::neighbourhood::{ByteMarks, Neighbourhood, flood_budget, opposite};
use super::pages::fresh_zeroed;
use super::{
    CANCEL_CHECK_INTERVAL, Cell, CostGrid, End, Route, RouteError, RouteOptions, finite_range,
};
use crate::geo::Issue;

const BEST_MOVE: u8 = 0b0000_0111;
const HAS_BEST: u8 = 0b0000_1000;
const QUEUED: u8 = 0b0001_0000;
const MARK: u8 = 0b0010_0000;
const FLOOD: u8 = 0b1000_0000;

/// After the first search with a new landmark, D* Lite goes on settling
/// cells near the route for 1/BAND_SHARE of the landmark A*'s expansions
/// (see the module docs).
const BAND_SHARE: u64 = 10;

/// Relative slack on the termination test (see `may_matter`).
const KEY_TOLERANCE: f64 = 1e-12;

/// A queue entry ordered by (k1, k2); keys are ≥ 0 so their bit patterns
/// order like the numbers (+∞ last). k2 = min(g, rhs) is kept as an f32:
/// it only orders cells of equal k1, whose g differ by at least an arc
/// where it matters (a cell and the one its rhs goes through), and the
/// termination test does not rely on it (`may_matter`).
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
struct QueueEntry {
    k1: u64,
    k2: u32,
    cell: u32,
}

impl QueueEntry {
    fn key(&self) -> (u64, u32) {
        (self.k1, self.k2)
    }

    /// As the bucket queue holds it: k1's bits on top, then k2's, then the cell.
    #[inline]
    fn packed(self) -> u128 {
        (u128::from(self.k1) << 64) | (u128::from(self.k2) << 32) | u128::from(self.cell)
    }

    #[inline]
    fn unpack(entry: u128) -> QueueEntry {
        QueueEntry {
            k1: (entry >> 64) as u64,
            k2: (entry >> 32) as u32,
            cell: entry as u32,
        }
    }
}

/// An incremental planner for one goal: plan, then move the start and
/// change cells, and plan again reusing the previous search. Cloning
/// copies the search state (about 13 bytes per cell; the landmark is
/// shared).
#[derive(Clone)]
pub struct DStarLite {
    grid: CostGrid,
    hood: Neighbourhood,
    options: RouteOptions,
    model: ArcModel,
    /// The finite cost range the model was built for.
    model_range: Option<(f32, f32)>,
    /// The current finite cost range of the grid.
    range: Option<(f32, f32)>,
    heuristic: StartHeuristic,
    landmark: LandmarkState,
    start: usize,
    goal: usize,
    /// The start when k_m was last updated.
    last_start: usize,
    km: f64,
    g: DistArray,
    state: Vec<u8>,
    queue: BucketQueue,
    restarts: u64,
    landmark_restarts: u64,
    /// Expansions the next search may spend settling cells beyond the
    /// start (set with a new landmark).
    band: u64,
}

/// Whether the heuristic has a landmark (see `landmark`).
#[derive(Clone)]
enum LandmarkState {
    /// Not yet: the search is fresh and the next `plan` runs A* for it.
    Pending,
    Ready(Arc<Landmark>),
    /// Not used (A* gave up within `max_expansions`, or the costs are too
    /// long for its rounding margin): the octile bound alone.
    Off,
}

impl DStarLite {
    /// A planner on `grid` (which it owns: changes go through
    /// [`update_cells`](Self::update_cells)). Start and goal must be inside
    /// the grid; whether they are blocked is checked by [`plan`](Self::plan),
    /// since cells change. `options.epsilon` must be 1.
    pub fn new(
        grid: CostGrid,
        start: Cell,
        goal: Cell,
        options: RouteOptions,
    ) -> Result<DStarLite, RouteError> {
        options.validate()?;
        if options.epsilon != 1.0 {
            return Err(RouteError::InvalidOptions(vec![Issue::new(
                "/epsilon",
                "D* Lite replans optimally: epsilon must be 1",
            )]));
        }
        let start = inside(&grid, start, End::Start)?;
        let goal = inside(&grid, goal, End::Goal)?;
        let hood = Neighbourhood::new(&grid);
        let range = grid.finite_cost_range();
        let model = ArcModel::new(options.arc_cost, range);
        let heuristic = StartHeuristic::new(&hood, start, model.heuristic_factor(), None);
        let n = grid.cell_count();
        let queue = open_list(&hood, &model, 1.0);
        let mut planner = DStarLite {
            grid,
            hood,
            options,
            model,
            model_range: range,
            range,
            heuristic,
            landmark: LandmarkState::Pending,
            start,
            goal,
            last_start: start,
            km: 0.0,
            g: DistArray::new(n),
            state: fresh_zeroed(n),
            queue,
            restarts: 0,
            landmark_restarts: 0,
            band: 0,
        };
        planner.update_vertex(goal, 0.0);
        Ok(planner)
    }

    /// The current grid, with all changes applied.
    pub fn grid(&self) -> &CostGrid {
        &self.grid
    }

    pub fn start(&self) -> Cell {
        self.cell(self.start)
    }

    pub fn goal(&self) -> Cell {
        self.cell(self.goal)
    }

    /// How many times a change of the arc model forced a search from
    /// scratch (see the module docs).
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// How many times a lowered cost broke the landmark heuristic's bound
    /// and forced a search from scratch (see the module docs).
    pub fn landmark_restarts(&self) -> u64 {
        self.landmark_restarts
    }

    /// Estimated bytes held: the costs, g and the state byte per cell, the
    /// landmark's labels once built, the per-row cell widths, and 4 bytes
    /// per cell of slack for the open list.
    pub fn estimated_bytes(&self) -> usize {
        let cells = self.grid.cell_count();
        let landmark = match self.landmark {
            LandmarkState::Off => 0,
            // Padded to whole 16 × 16 tiles.
            _ => {
                let (w, h) = (self.grid.width(), self.grid.height());
                w.div_ceil(16) * h.div_ceil(16) * 256 * Landmark::BYTES_PER_CELL
            }
        };
        cells
            .saturating_mul(17)
            .saturating_add(landmark)
            .saturating_add(self.grid.height() * 8)
    }

    /// The robot is now at `start` (anywhere inside the grid; usually a
    /// cell further along the last route).
    pub fn move_start(&mut self, start: Cell) -> Result<(), RouteError> {
        let s = inside(&self.grid, start, End::Start)?;
        // Queued keys were computed from the old start; they stay lower
        // bounds if k_m grows by the old heuristic's value at the new one
        // (`landmark` shows this holds with the landmark too).
        self.km += self.heuristic.at(&self.hood, s);
        self.start = s;
        self.last_start = s;
        self.heuristic = self.heuristic_from(s);
        Ok(())
    }

    /// Sets new costs, `(row-major index, cost)`; a non-finite cost blocks
    /// the cell. All changes are checked before any is applied. The next
    /// [`plan`](Self::plan) repairs the search.
    pub fn update_cells(&mut self, changes: &[(usize, f32)]) -> Result<(), RouteError> {
        let n = self.grid.cell_count();
        for &(index, cost) in changes {
            if index >= n {
                return Err(RouteError::ChangeOutside { index, cells: n });
            }
            if cost.is_finite() && cost <= 0.0 {
                return Err(RouteError::InvalidChangeCost { index, cost });
            }
        }
        let (mut lo, mut hi) = self.range.unwrap_or((f32::INFINITY, f32::NEG_INFINITY));
        let mut rescan = false;
        let mut lowered = false;
        let mut changed = Vec::with_capacity(changes.len());
        let costs = self.grid.costs_mut();
        for &(i, new) in changes {
            let old = costs[i];
            if old == new || (!old.is_finite() && !new.is_finite()) {
                costs[i] = new;
                continue;
            }
            // Losing a cell at the min or max may shrink the range.
            if old.is_finite() && (old <= lo || old >= hi) {
                rescan = true;
            }
            if new.is_finite() {
                lo = lo.min(new);
                hi = hi.max(new);
                // An obstacle opened up, or a cost fell.
                lowered |= !old.is_finite() || new < old;
            }
            costs[i] = new;
            changed.push(i);
        }
        if changed.is_empty() {
            return Ok(());
        }
        self.range = if rescan {
            finite_range(self.grid.costs())
        } else {
            (lo <= hi).then_some((lo, hi))
        };
        let model_changes = if self.model.is_thesis() {
            self.range != self.model_range
        } else {
            match (self.range, self.model_range) {
                (Some((lo, _)), Some((model_lo, _))) => lo < model_lo,
                (Some(_), None) => true,
                (None, _) => false,
            }
        };
        if model_changes {
            self.model = ArcModel::new(self.options.arc_cost, self.range);
            self.model_range = self.range;
            self.restarts += 1;
            self.restart();
            return Ok(());
        }
        // Every cell whose moves changed: the changed cells and their
        // neighbours (a cell's moves depend on its 3×3 block).
        let (width, height) = (self.grid.width(), self.grid.height());
        let mut affected = Vec::with_capacity(changed.len() * 9);
        for &i in &changed {
            let (r, c) = (i / width, i % width);
            for nr in r.saturating_sub(1)..=(r + 1).min(height - 1) {
                for nc in c.saturating_sub(1)..=(c + 1).min(width - 1) {
                    let j = nr * width + nc;
                    if self.state[j] & MARK == 0 {
                        self.state[j] |= MARK;
                        affected.push(j);
                    }
                }
            }
        }
        for &s in &affected {
            self.state[s] &= !MARK;
        }
        if lowered && !self.landmark_holds(&affected) {
            self.landmark_restarts += 1;
            self.restart();
            return Ok(());
        }
        for s in affected {
            let rhs = self.best_successor(s);
            self.update_vertex(s, rhs);
        }
        Ok(())
    }

    /// The cheapest route from the current start to the goal, repairing the
    /// previous search. `cancel` is asked every [`CANCEL_CHECK_INTERVAL`]
    /// expansions; an interrupted search (cancelled or over
    /// `max_expansions`) stays valid and the next call continues it.
    pub fn plan(&mut self, cancel: &dyn Fn() -> bool) -> Result<Route, RouteError> {
        let start = self.grid.endpoint(self.start(), End::Start)?;
        let goal = self.grid.endpoint(self.goal(), End::Goal)?;
        let n = self.grid.cell_count();
        let (path, expanded) = if start == goal {
            (vec![start], 0)
        } else {
            // The start in a small pocket without the goal: answer at once.
            let mut marks = ByteMarks {
                bytes: &mut self.state,
                bit: FLOOD,
            };
            if self.hood.region_excludes(
                self.grid.costs(),
                &mut marks,
                start,
                goal,
                flood_budget(n),
            ) {
                return Err(RouteError::Unreachable);
            }
            // A fresh search with a new landmark also settles a band of
            // cells around the route, a tenth of A*'s effort (see the
            // module docs).
            let (first, _) = self.prepare_landmark(cancel)?;
            let expanded = first + self.compute_shortest_path(first, self.band, cancel)?;
            self.band = 0;
            if self.rhs(start) == f64::INFINITY {
                return Err(RouteError::Unreachable);
            }
            (self.extract_path()?, expanded)
        };
        Ok(self.route_along(&path, expanded))
    }

    /// A* from the start of a fresh planner: the route [`astar`](super::astar())
    /// finds (the same search), whose costs become this planner's landmark
    /// so that the next [`plan`](Self::plan) only walks back along the
    /// route and settles the cells around it. For a new route whose
    /// replans this planner will repair: the route answers at A*'s speed
    /// and the rest of the first search can follow later. On a planner
    /// that has searched already it is `plan`.
    pub fn plan_with_astar(&mut self, cancel: &dyn Fn() -> bool) -> Result<Route, RouteError> {
        if !matches!(self.landmark, LandmarkState::Pending) {
            return self.plan(cancel);
        }
        let start = self.grid.endpoint(self.start(), End::Start)?;
        let goal = self.grid.endpoint(self.goal(), End::Goal)?;
        let (expanded, path) = if start == goal {
            (0, vec![start])
        } else {
            self.prepare_landmark(cancel)?
        };
        Ok(self.route_along(&path, expanded))
    }

    /// The route along `path` (cell indices), as [`plan`](Self::plan) and
    /// [`plan_with_astar`](Self::plan_with_astar) answer it.
    fn route_along(&self, path: &[usize], expanded: u64) -> Route {
        super::finish_route(
            &self.grid,
            &self.hood,
            &self.model,
            path,
            expanded,
            self.options.smooth,
        )
    }

    fn cell(&self, i: usize) -> Cell {
        (i / self.grid.width(), i % self.grid.width())
    }

    /// The heuristic for start `s`, with the landmark once there is one.
    fn heuristic_from(&self, s: usize) -> StartHeuristic {
        let landmark = match &self.landmark {
            LandmarkState::Ready(l) => Some(l),
            _ => None,
        };
        StartHeuristic::new(&self.hood, s, self.model.heuristic_factor(), landmark)
    }

    /// Before the first search of a fresh planner: A* from the start to the
    /// goal, whose costs become the landmark heuristic (`landmark`). The
    /// expansions it took; on cancellation the planner stays fresh, and
    /// when it runs out of `max_expansions` the search goes on without a
    /// landmark.
    /// Also the A* route's cells (none when there was nothing to do).
    fn prepare_landmark(
        &mut self,
        cancel: &dyn Fn() -> bool,
    ) -> Result<(u64, Vec<usize>), RouteError> {
        if !matches!(self.landmark, LandmarkState::Pending) {
            return Ok((0, Vec::new()));
        }
        let ends = (self.start, self.goal);
        match search_tree(
            &self.grid,
            &self.hood,
            &self.model,
            ends,
            &self.options,
            cancel,
        ) {
            Ok((path, expanded, tree)) => {
                let cheapest_arc = self.hood.shortest_step() * self.model.heuristic_factor();
                let factor = self.model.heuristic_factor();
                self.landmark =
                    match Landmark::new(tree, &self.hood, self.goal, factor, cheapest_arc) {
                        Some(l) => LandmarkState::Ready(Arc::new(l)),
                        None => LandmarkState::Off,
                    };
                // Only the goal is queued, with a key that stays a lower
                // bound: the new heuristic is never smaller.
                self.heuristic = self.heuristic_from(self.start);
                self.band = expanded / BAND_SHARE;
                Ok((expanded, path))
            }
            Err(e @ RouteError::TooManyExpansions { .. }) => {
                self.landmark = LandmarkState::Off;
                Err(e)
            }
            Err(e) => Err(e),
        }
    }

    /// Whether the landmark's bound D(v) ≤ D(u) + c(u, v) still holds on
    /// every move out of `cells` (after costs fell there).
    fn landmark_holds(&self, cells: &[usize]) -> bool {
        let LandmarkState::Ready(landmark) = &self.landmark else {
            return true;
        };
        let (width, costs) = (self.grid.width(), self.grid.costs());
        cells.iter().all(|&u| {
            let (r, c) = (u / width, u % width);
            let at_u = landmark.value(&self.hood, u);
            let mut moves = self.hood.moves(costs, u, r, c);
            let mut holds = true;
            while moves != 0 && holds {
                let d = moves.trailing_zeros() as usize;
                moves &= moves - 1;
                let v = self.hood.neighbour(u, d);
                let arc = self.model.arc(self.hood.step_len(r, d), costs[u], costs[v]);
                holds = landmark.value(&self.hood, v) <= at_u + arc;
            }
            holds
        })
    }

    /// Forget the search and start it again (the arc model changed, or a
    /// lowered cost broke the landmark's bound).
    fn restart(&mut self) {
        let n = self.grid.cell_count();
        self.g = DistArray::new(n);
        self.state = fresh_zeroed(n);
        self.queue = open_list(&self.hood, &self.model, 1.0);
        self.km = 0.0;
        self.last_start = self.start;
        self.landmark = LandmarkState::Pending;
        self.heuristic = self.heuristic_from(self.start);
        self.update_vertex(self.goal, 0.0);
    }

    /// rhs(s) from the stored best move.
    #[inline]
    fn rhs(&self, s: usize) -> f64 {
        if s == self.goal {
            return 0.0;
        }
        let st = self.state[s];
        if st & HAS_BEST == 0 {
            return f64::INFINITY;
        }
        let d = (st & BEST_MOVE) as usize;
        let v = self.hood.neighbour(s, d);
        let costs = self.grid.costs();
        let len = self.hood.step_len(s / self.grid.width(), d);
        self.model.arc(len, costs[s], costs[v]) + self.g.get(v)
    }

    /// Recomputes rhs(s) over all moves and stores the best one.
    fn best_successor(&mut self, s: usize) -> f64 {
        if s == self.goal {
            return 0.0;
        }
        let (best, best_move) = self.cheapest_move(s);
        self.state[s] = match best_move {
            Some(d) => (self.state[s] & !BEST_MOVE) | HAS_BEST | d as u8,
            None => self.state[s] & !(BEST_MOVE | HAS_BEST),
        };
        best
    }

    /// The least arc + g over the moves from `s`, and the move giving it
    /// (`None` when no move leads to a finite value).
    fn cheapest_move(&self, s: usize) -> (f64, Option<usize>) {
        let width = self.grid.width();
        let costs = self.grid.costs();
        let (r, c) = (s / width, s % width);
        let mut moves = self.hood.moves(costs, s, r, c);
        let (mut best, mut best_move) = (f64::INFINITY, None);
        while moves != 0 {
            let d = moves.trailing_zeros() as usize;
            moves &= moves - 1;
            let v = self.hood.neighbour(s, d);
            let value =
                self.model.arc(self.hood.step_len(r, d), costs[s], costs[v]) + self.g.get(v);
            if value < best {
                best = value;
                best_move = Some(d);
            }
        }
        (best, best_move)
    }

    #[inline]
    fn key(&self, s: usize, g: f64, rhs: f64) -> QueueEntry {
        let m = g.min(rhs);
        QueueEntry {
            k1: (m + self.heuristic.at(&self.hood, s) + self.km).to_bits(),
            k2: (m as f32).to_bits(),
            cell: s as u32,
        }
    }

    /// Queue s if inconsistent (with rhs(s) = `rhs`), else mark it out.
    #[inline]
    fn update_vertex(&mut self, s: usize, rhs: f64) {
        let g = self.g.get(s);
        if g != rhs {
            let entry = self.key(s, g, rhs);
            self.queue.push(entry.packed());
            self.state[s] |= QUEUED;
        } else {
            self.state[s] &= !QUEUED;
        }
    }

    /// D* Lite's main loop; `spent` expansions of this `plan` call went to
    /// the landmark's A* already. Once the start is settled it goes on for
    /// up to `beyond` more expansions (stopping quietly at the limit or on
    /// cancellation): cells settled now are not searched by later replans.
    fn compute_shortest_path(
        &mut self,
        spent: u64,
        beyond: u64,
        cancel: &dyn Fn() -> bool,
    ) -> Result<u64, RouteError> {
        let limit = self.options.max_expansions.unwrap_or(u64::MAX);
        let budget = limit.saturating_sub(spent);
        let mut expanded = 0u64;
        // Expansions left once the start is settled.
        let mut extra: Option<u64> = None;
        loop {
            // Drop entries of cells no longer queued (those of a bucket
            // reached from the ring before it is sorted).
            let state = &self.state;
            while let Some(top) = self
                .queue
                .peek_live(|e| state[e as u32 as usize] & QUEUED != 0)
            {
                if self.state[top as u32 as usize] & QUEUED == 0 {
                    self.queue.pop();
                } else {
                    break;
                }
            }
            let Some(top) = self.queue.peek().map(QueueEntry::unpack) else {
                break;
            };
            if extra.is_none() {
                let (g_start, rhs_start) = (self.g.get(self.start), self.rhs(self.start));
                let start_key = self.key(self.start, g_start, rhs_start);
                if !self.may_matter(top, start_key) && rhs_start <= g_start {
                    extra = Some(beyond);
                }
            }
            if extra == Some(0) {
                break;
            }
            self.queue.pop();
            let u = top.cell as usize;
            let (g_u, rhs_u) = (self.g.get(u), self.rhs(u));
            if g_u == rhs_u {
                self.state[u] &= !QUEUED;
                continue;
            }
            let current = self.key(u, g_u, rhs_u);
            if top.key() < current.key() {
                self.queue.push(current.packed());
                continue;
            }
            let stop = if expanded >= budget {
                Some(RouteError::TooManyExpansions { limit })
            } else if expanded.is_multiple_of(CANCEL_CHECK_INTERVAL) && cancel() {
                Some(RouteError::Cancelled)
            } else {
                None
            };
            if let Some(error) = stop {
                self.queue.push(current.packed());
                return match extra {
                    Some(_) => Ok(expanded),
                    None => Err(error),
                };
            }
            expanded += 1;
            if let Some(left) = extra.as_mut() {
                *left -= 1;
            }
            self.expand(u, g_u, rhs_u);
        }
        Ok(expanded)
    }

    /// Expands u (popped with g(u) = `g_u` ≠ rhs(u) = `rhs_u`).
    #[inline]
    fn expand(&mut self, u: usize, g_u: f64, rhs_u: f64) {
        self.state[u] &= !QUEUED;
        let (r, c) = (u / self.grid.width(), u % self.grid.width());
        let mut moves = self.hood.moves(self.grid.costs(), u, r, c);
        if g_u > rhs_u {
            // Overconsistent: u's cost to the goal is now final.
            self.g.set(u, rhs_u);
            while moves != 0 {
                let d = moves.trailing_zeros() as usize;
                moves &= moves - 1;
                let s = self.hood.neighbour(u, d);
                if s == self.goal {
                    continue;
                }
                let costs = self.grid.costs();
                let via_u = self.model.arc(self.hood.step_len(r, d), costs[s], costs[u]) + rhs_u;
                let back = opposite(d) as u8;
                let st = self.state[s];
                if st & HAS_BEST != 0 && st & BEST_MOVE == back {
                    // rhs(s) went through u and fell with g(u).
                    self.update_vertex(s, via_u);
                } else if via_u < self.rhs(s) {
                    self.state[s] = (st & !BEST_MOVE) | HAS_BEST | back;
                    self.update_vertex(s, via_u);
                }
            }
        } else {
            // Underconsistent: u got dearer; cells that relied on it look
            // for their best move again.
            self.g.set(u, f64::INFINITY);
            while moves != 0 {
                let d = moves.trailing_zeros() as usize;
                moves &= moves - 1;
                let s = self.hood.neighbour(u, d);
                if s == self.goal {
                    continue;
                }
                let st = self.state[s];
                if st & HAS_BEST != 0 && st & BEST_MOVE == opposite(d) as u8 {
                    let rhs = self.best_successor(s);
                    self.update_vertex(s, rhs);
                }
            }
            self.update_vertex(u, rhs_u);
        }
    }

    /// The loop condition "key(top) < key(start)", made robust to rounding:
    /// keys are sums (min(g, rhs) + h + k_m) whose mathematically equal
    /// values can differ in the last bit, and stopping one ulp short of a
    /// cell that ties with the start leaves its stale g on the route (the
    /// path walk could even cycle). So every cell whose k1 is within a
    /// relative 1e-12 of the start's is still processed, whatever its k2
    /// (deciding such near-ties by k2 is not safe either: k1 values that
    /// truly differ by less than the slack exist). Processing more cells
    /// than needed is always correct for D* Lite.
    #[inline]
    fn may_matter(&self, top: QueueEntry, start_key: QueueEntry) -> bool {
        let (top_k1, start_k1) = (f64::from_bits(top.k1), f64::from_bits(start_key.k1));
        top.key() < start_key.key() || top_k1 <= start_k1 + KEY_TOLERANCE * start_k1
    }

    /// Follows the cheapest move (arc + g) from the start to the goal.
    fn extract_path(&self) -> Result<Vec<usize>, RouteError> {
        let costs = self.grid.costs();
        let mut path = vec![self.start];
        let mut s = self.start;
        while s != self.goal {
            let next = self.cheapest_move(s).1.map(|d| self.hood.neighbour(s, d));
            // Neither can happen after a completed search (D* Lite's
            // theorem); guard so that a bug can never loop forever.
            let Some(v) = next else {
                return Err(RouteError::Unreachable);
            };
            if path.len() > costs.len() {
                return Err(RouteError::Unreachable);
            }
            path.push(v);
            s = v;
        }
        Ok(path)
    }
}

fn inside(grid: &CostGrid, cell: Cell, end: End) -> Result<usize, RouteError> {
    grid.index(cell).ok_or(match end {
        End::Start => RouteError::StartOutside {
            row: cell.0,
            col: cell.1,
            width: grid.width(),
            height: grid.height(),
        },
        End::Goal => RouteError::GoalOutside {
            row: cell.0,
            col: cell.1,
            width: grid.width(),
            height: grid.height(),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::testing::{Rng, assert_path_valid, dijkstra, random_endpoints, random_grid};
    use crate::route::{ArcCost, astar};

    const X: f32 = f32::NAN;

    fn check_against_scratch(
        planner: &mut DStarLite,
        arc: ArcCost,
        context: &str,
    ) -> Option<Route> {
        let grid = planner.grid().clone();
        let (start, goal) = (planner.start(), planner.goal());
        let expected = dijkstra(&grid, start, goal, arc);
        match (planner.plan(&|| false), expected) {
            (Ok(route), Some(best)) => {
                assert!(
                    (route.cost - best).abs() <= 1e-9 * best.max(1e-300),
                    "{context}: D* Lite {} vs from scratch {best}",
                    route.cost
                );
                assert_eq!(route.cells.first(), Some(&start), "{context}");
                assert_eq!(route.cells.last(), Some(&goal), "{context}");
                assert_path_valid(&grid, &route.cells);
                Some(route)
            }
            (Err(RouteError::Unreachable), None) => None,
            (got, want) => panic!("{context}: D* Lite {got:?}, from scratch {want:?}"),
        }
    }

    #[test]
    fn replans_equal_a_search_from_scratch() {
        let mut rng = Rng::new(99);
        let (mut routes, mut unreachable, mut moves) = (0, 0, 0);
        for trial in 0..24 {
            let (w, h) = (20 + rng.below(30) as usize, 20 + rng.below(30) as usize);
            let grid = random_grid(&mut rng, w, h, 0.1, trial % 2 == 0);
            let Some((start, goal)) = random_endpoints(&mut rng, &grid) else {
                continue;
            };
            let arc = if trial % 3 == 2 {
                ArcCost::Thesis {
                    d_max: 1.0 + 9.0 * rng.unit(),
                }
            } else {
                ArcCost::Integrated
            };
            let options = RouteOptions {
                arc_cost: arc,
                ..RouteOptions::default()
            };
            let mut planner = DStarLite::new(grid, start, goal, options).unwrap();
            let mut last =
                check_against_scratch(&mut planner, arc, &format!("trial {trial} initial"));
            for batch in 0..50 {
                let context = format!("trial {trial} batch {batch}");
                // Sometimes drive a few cells along the last route.
                if let Some(route) = &last
                    && rng.below(3) == 0
                    && route.cells.len() > 2
                {
                    let k = 1 + rng.below((route.cells.len() - 1).min(5) as u64) as usize;
                    planner.move_start(route.cells[k]).unwrap();
                    moves += 1;
                }
                let (s, g) = (
                    planner.grid().index(planner.start()).unwrap(),
                    planner.grid().index(planner.goal()).unwrap(),
                );
                let mut changes = Vec::new();
                // Block cells, often on or next to the last route.
                for _ in 0..1 + rng.below(6) {
                    let i = match &last {
                        Some(route) if rng.below(2) == 0 => {
                            let (r, c) = route.cells[rng.below(route.cells.len() as u64) as usize];
                            let r = (r + rng.below(3) as usize).saturating_sub(1).min(h - 1);
                            let c = (c + rng.below(3) as usize).saturating_sub(1).min(w - 1);
                            r * w + c
                        }
                        _ => rng.below((w * h) as u64) as usize,
                    };
                    changes.push((i, f32::INFINITY));
                }
                // Cost changes (some may unblock), mostly inside the range.
                for _ in 0..rng.below(5) {
                    let i = rng.below((w * h) as u64) as usize;
                    let (lo, hi) = planner.grid().finite_cost_range().unwrap_or((1.0, 20.0));
                    let cost = if rng.below(8) == 0 {
                        rng.range_f32(0.5 * lo, 1.5 * hi)
                    } else {
                        rng.range_f32(lo, hi)
                    };
                    changes.push((i, cost));
                }
                changes.retain(|&(i, _)| i != s && i != g);
                planner.update_cells(&changes).unwrap();
                match check_against_scratch(&mut planner, arc, &context) {
                    Some(route) => {
                        routes += 1;
                        last = Some(route);
                    }
                    None => {
                        unreachable += 1;
                        last = None;
                    }
                }
            }
        }
        assert!(
            routes > 600 && unreachable > 10 && moves > 100,
            "{routes} {unreachable} {moves}"
        );
    }

    #[test]
    fn thesis_range_changes_restart_and_inside_changes_do_not() {
        let mut rng = Rng::new(5);
        let mut grid = random_grid(&mut rng, 30, 30, 0.0, false);
        // Pin the range to [1, 20] with two dedicated cells far from the route.
        let mut costs = grid.clone().into_costs();
        for c in costs.iter_mut() {
            *c = c.clamp(2.0, 19.0);
        }
        costs[0] = 1.0;
        costs[29] = 20.0;
        grid = CostGrid::with_cell_size(30, 30, costs, 1.0, 1.0).unwrap();
        let arc = ArcCost::thesis();
        let options = RouteOptions {
            arc_cost: arc,
            ..RouteOptions::default()
        };
        let mut planner = DStarLite::new(grid, (29, 0), (15, 29), options).unwrap();
        check_against_scratch(&mut planner, arc, "initial");
        planner
            .update_cells(&[(15 * 30 + 10, 7.0), (16 * 30 + 10, f32::NAN)])
            .unwrap();
        check_against_scratch(&mut planner, arc, "inside the range");
        assert_eq!(planner.restarts(), 0);
        planner.update_cells(&[(29, 5.0)]).unwrap(); // the max cell: max falls
        check_against_scratch(&mut planner, arc, "max falls");
        assert_eq!(planner.restarts(), 1);
        planner.update_cells(&[(100, 25.0)]).unwrap(); // above the max
        check_against_scratch(&mut planner, arc, "max rises");
        assert_eq!(planner.restarts(), 2);
        planner.update_cells(&[(0, f32::INFINITY)]).unwrap(); // the min cell blocked
        check_against_scratch(&mut planner, arc, "min rises");
        assert_eq!(planner.restarts(), 3);
        // Integrated: only a new least cost restarts.
        let mut planner = DStarLite::new(
            planner.grid().clone(),
            (29, 0),
            (15, 29),
            RouteOptions::default(),
        )
        .unwrap();
        planner.plan(&|| false).unwrap();
        planner
            .update_cells(&[(200, 100.0), (1, f32::NAN)])
            .unwrap();
        check_against_scratch(&mut planner, ArcCost::Integrated, "integrated");
        assert_eq!(planner.restarts(), 0);
        planner.update_cells(&[(300, 0.5)]).unwrap();
        check_against_scratch(&mut planner, ArcCost::Integrated, "integrated new min");
        assert_eq!(planner.restarts(), 1);
    }

    #[test]
    fn errors_and_blocked_endpoints() {
        let grid = CostGrid::with_cell_size(4, 3, vec![1.0; 12], 1.0, 1.0).unwrap();
        let o = RouteOptions::default();
        assert!(matches!(
            DStarLite::new(grid.clone(), (3, 0), (0, 0), o.clone()),
            Err(RouteError::StartOutside { row: 3, .. })
        ));
        assert!(matches!(
            DStarLite::new(grid.clone(), (0, 0), (0, 4), o.clone()),
            Err(RouteError::GoalOutside { col: 4, .. })
        ));
        let weighted = RouteOptions {
            epsilon: 2.0,
            ..RouteOptions::default()
        };
        assert!(matches!(
            DStarLite::new(grid.clone(), (0, 0), (2, 3), weighted),
            Err(RouteError::InvalidOptions(_))
        ));
        let mut p = DStarLite::new(grid, (0, 0), (2, 3), o).unwrap();
        assert!((p.plan(&|| false).unwrap().cost - (1.0 + 2.0 * 2f64.sqrt())).abs() < 1e-12);
        assert_eq!(
            p.update_cells(&[(12, 1.0)]),
            Err(RouteError::ChangeOutside {
                index: 12,
                cells: 12
            })
        );
        assert_eq!(
            p.update_cells(&[(1, 2.0), (3, -1.0)]),
            Err(RouteError::InvalidChangeCost {
                index: 3,
                cost: -1.0
            })
        );
        assert_eq!(p.grid().costs()[1], 1.0, "nothing applied on error");
        p.update_cells(&[(11, X)]).unwrap();
        assert_eq!(
            p.plan(&|| false),
            Err(RouteError::GoalBlocked { row: 2, col: 3 })
        );
        p.update_cells(&[(11, 1.0), (0, X)]).unwrap();
        assert_eq!(
            p.plan(&|| false),
            Err(RouteError::StartBlocked { row: 0, col: 0 })
        );
        assert!(matches!(
            p.move_start((9, 9)),
            Err(RouteError::StartOutside { .. })
        ));
        p.move_start((1, 0)).unwrap();
        let r = p.plan(&|| false).unwrap();
        assert_eq!(r.cells.first(), Some(&(1, 0)));
        // Wall off the goal, then open it again.
        p.update_cells(&[(7, X), (10, X)]).unwrap();
        assert_eq!(p.plan(&|| false), Err(RouteError::Unreachable));
        p.update_cells(&[(10, 3.0)]).unwrap();
        assert!(p.plan(&|| false).is_ok());
        // Start = goal.
        p.move_start((2, 3)).unwrap();
        let r = p.plan(&|| false).unwrap();
        assert_eq!((r.cells.len(), r.cost), (1, 0.0));
    }

    #[test]
    fn cancel_and_limit_leave_a_resumable_search() {
        let mut rng = Rng::new(12);
        let grid = random_grid(&mut rng, 120, 120, 0.05, false);
        let (start, goal) = ((0, 0), (119, 119));
        let mut costs = grid.clone().into_costs();
        costs[0] = 1.0;
        costs[119 * 120 + 119] = 1.0;
        let grid = CostGrid::with_cell_size(120, 120, costs, 1.0, 1.0).unwrap();
        let expected = astar(&grid, start, goal, &RouteOptions::default(), &|| false);
        let limited = RouteOptions {
            max_expansions: Some(100),
            ..RouteOptions::default()
        };
        let mut p = DStarLite::new(grid.clone(), start, goal, limited).unwrap();
        assert_eq!(p.plan(&|| true), Err(RouteError::Cancelled));
        let mut calls = 0;
        let result = loop {
            calls += 1;
            match p.plan(&|| false) {
                Err(RouteError::TooManyExpansions { limit: 100 }) => continue,
                other => break other,
            }
        };
        assert!(calls > 5, "the limit applies per call ({calls})");
        match (result, expected) {
            (Ok(a), Ok(b)) => assert!((a.cost - b.cost).abs() <= 1e-9 * b.cost),
            (a, b) => assert_eq!(a.map(|r| r.cost), b.map(|r| r.cost)),
        }
    }

    #[test]
    fn replanning_reuses_the_previous_search() {
        let mut rng = Rng::new(3);
        let grid = crate::route::testing::smooth_costmap(&mut rng, 300, 300, 0.05);
        let (start, goal) = crate::route::testing::far_corners(&grid);
        let mut p = DStarLite::new(grid, start, goal, RouteOptions::default()).unwrap();
        let first = p.plan(&|| false).unwrap();
        // Drive a tenth of the way, then find a wall across the route ahead.
        let here = first.cells[first.cells.len() / 10];
        p.move_start(here).unwrap();
        let ahead = first.cells[first.cells.len() / 5];
        let width = p.grid().width();
        let wall: Vec<(usize, f32)> = (0..10)
            .map(|k| {
                (
                    ahead.0 * width + (ahead.1 + k).saturating_sub(5).min(width - 1),
                    f32::INFINITY,
                )
            })
            .filter(|&(i, _)| i != p.grid().index(here).unwrap())
            .collect();
        p.update_cells(&wall).unwrap();
        let second = p.plan(&|| false).unwrap();
        let scratch = astar(p.grid(), here, goal, &RouteOptions::default(), &|| false).unwrap();
        assert!((second.cost - scratch.cost).abs() <= 1e-9 * scratch.cost);
        assert!(
            second.expanded * 4 < first.expanded,
            "replan {} vs initial {}",
            second.expanded,
            first.expanded
        );
    }

    /// A smooth random costmap (`seed`, `width` × `height`), A*'s route
    /// between the traversable cells nearest its far corners, and a D* Lite
    /// planner for the same ends.
    fn across_a_smooth_map(seed: u64, width: usize, height: usize) -> (Route, DStarLite) {
        let mut rng = Rng::new(seed);
        let grid = crate::route::testing::smooth_costmap(&mut rng, width, height, 0.05);
        let (start, goal) = crate::route::testing::far_corners(&grid);
        let scratch = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
        let planner = DStarLite::new(grid, start, goal, RouteOptions::default()).unwrap();
        (scratch, planner)
    }

    #[test]
    fn first_search_follows_the_route() {
        // The landmark A* plus the backward walk along the route plus the
        // settled band (a tenth of A*): far below the octile-only backward
        // search, which floods most of this map.
        let (scratch, mut p) = across_a_smooth_map(17, 300, 300);
        let first = p.plan(&|| false).unwrap();
        assert!((first.cost - scratch.cost).abs() <= 1e-9 * scratch.cost);
        let backward = first.expanded - scratch.expanded;
        assert!(
            backward <= scratch.expanded / BAND_SHARE + 4 * scratch.cells.len() as u64,
            "backward {backward}, A* {}, route {} cells",
            scratch.expanded,
            scratch.cells.len()
        );
    }

    #[test]
    fn replans_after_random_blocks_equal_astar_from_scratch() {
        // A robot driving along its route on larger maps, finding blocked
        // squares and costlier ground on and near it: every replan costs
        // what A* from scratch does (1e-9 relative), and blocking or raising
        // costs never restarts the search.
        let mut rng = Rng::new(77);
        let mut replans = 0;
        for trial in 0..4 {
            let grid = crate::route::testing::smooth_costmap(&mut rng, 160, 140, 0.04);
            let (start, goal) = crate::route::testing::far_corners(&grid);
            let arc = if trial == 3 {
                ArcCost::thesis()
            } else {
                ArcCost::Integrated
            };
            let options = RouteOptions {
                arc_cost: arc,
                ..RouteOptions::default()
            };
            let mut p = DStarLite::new(grid, start, goal, options.clone()).unwrap();
            let Ok(mut route) = p.plan(&|| false) else {
                continue;
            };
            let (w, h) = (p.grid().width(), p.grid().height());
            for round in 0..12 {
                let ahead = route.cells.len() / 4;
                if ahead < 2 {
                    break;
                }
                let here = route.cells[1 + rng.below(ahead as u64 / 2) as usize];
                p.move_start(here).unwrap();
                let (cr, cc) = route.cells[ahead + rng.below(ahead as u64) as usize];
                let half = 1 + rng.below(4) as usize;
                let mut changes = Vec::new();
                for r in cr.saturating_sub(half)..=(cr + half).min(h - 1) {
                    for c in cc.saturating_sub(half)..=(cc + half).min(w - 1) {
                        changes.push((r * w + c, f32::INFINITY));
                    }
                }
                // Raise some costs inside the range (thesis keeps its range).
                for _ in 0..rng.below(20) {
                    let i = rng.below((w * h) as u64) as usize;
                    let old = p.grid().costs()[i];
                    if old.is_finite() && old < 19.0 {
                        changes.push((i, old + 0.5));
                    }
                }
                let (s, g) = (here.0 * w + here.1, goal.0 * w + goal.1);
                changes.retain(|&(i, _)| i != s && i != g);
                p.update_cells(&changes).unwrap();
                let fresh = astar(p.grid(), here, goal, &options, &|| false);
                match (p.plan(&|| false), fresh) {
                    (Ok(replan), Ok(fresh)) => {
                        assert!(
                            (replan.cost - fresh.cost).abs() <= 1e-9 * fresh.cost,
                            "trial {trial} round {round}: {} vs {}",
                            replan.cost,
                            fresh.cost
                        );
                        assert_path_valid(p.grid(), &replan.cells);
                        route = replan;
                        replans += 1;
                    }
                    (Err(RouteError::Unreachable), Err(RouteError::Unreachable)) => break,
                    (a, b) => panic!("trial {trial} round {round}: {a:?} vs {b:?}"),
                }
            }
            assert_eq!(p.landmark_restarts(), 0, "trial {trial}");
        }
        assert!(replans > 30, "{replans}");
    }

    #[test]
    fn astar_first_then_the_rest_of_the_first_search() {
        // plan_with_astar answers with A*'s route; the next plan completes
        // the first search (the walk back and the band) without a second A*,
        // and replans from there equal A* from scratch.
        let (scratch, mut p) = across_a_smooth_map(23, 200, 180);
        let route = p.plan_with_astar(&|| false).unwrap();
        assert_eq!(route, scratch, "the same search");
        let rest = p.plan(&|| false).unwrap();
        assert!((rest.cost - scratch.cost).abs() <= 1e-9 * scratch.cost);
        assert!(
            rest.expanded <= scratch.expanded / BAND_SHARE + 4 * scratch.cells.len() as u64,
            "{} expanded after A*'s {}",
            rest.expanded,
            scratch.expanded
        );
        let w = p.grid().width();
        let (r, c) = route.cells[route.cells.len() / 2];
        p.move_start(route.cells[route.cells.len() / 3]).unwrap();
        p.update_cells(&[(r * w + c, X), (r * w + c + 1, X), ((r + 1) * w + c, X)])
            .unwrap();
        check_against_scratch(&mut p, ArcCost::Integrated, "after a block");
        // Start = goal: nothing to search.
        let grid = CostGrid::with_cell_size(3, 3, vec![1.0; 9], 1.0, 1.0).unwrap();
        let mut p = DStarLite::new(grid, (1, 1), (1, 1), RouteOptions::default()).unwrap();
        assert_eq!(p.plan_with_astar(&|| false).unwrap().cells, vec![(1, 1)]);
    }

    #[test]
    fn lowered_costs_keep_the_landmark_or_restart() {
        let mut rng = Rng::new(8);
        let grid = crate::route::testing::smooth_costmap(&mut rng, 120, 120, 0.0);
        let (lo, _) = grid.finite_cost_range().unwrap();
        // Along the main diagonal, away from the far corners.
        let (start, goal) = ((10, 10), (60, 60));
        let mut p = DStarLite::new(grid, start, goal, RouteOptions::default()).unwrap();
        p.plan(&|| false).unwrap();
        // A cell far from anything A* looked at: the bound still holds.
        let far = 119 * 120 + 119;
        p.update_cells(&[(far, lo)]).unwrap();
        check_against_scratch(&mut p, ArcCost::Integrated, "far");
        assert_eq!(p.landmark_restarts(), 0);
        // A cheap lane beside the route: the costs from the start fall, the
        // landmark overestimates, and the search starts over.
        let lane: Vec<(usize, f32)> = (12..60).map(|k| (k * 120 + k + 2, lo)).collect();
        p.update_cells(&lane).unwrap();
        assert_eq!(p.landmark_restarts(), 1);
        assert_eq!(p.restarts(), 0, "the arc model did not change");
        let route = check_against_scratch(&mut p, ArcCost::Integrated, "lane").unwrap();
        // The search goes on from there with a new landmark.
        p.update_cells(&[(route.cells[20].0 * 120 + route.cells[20].1, X)])
            .unwrap();
        check_against_scratch(&mut p, ArcCost::Integrated, "blocked after restart");
        assert_eq!(p.landmark_restarts(), 1);
    }

    /// Release-mode timing (run with `cargo test --release -p planner-core
    /// --lib route::dstar_lite::tests::timing -- --ignored --nocapture`;
    /// sizes from `ROUTE_SIZES`): the initial plan, then a 20 m wall across
    /// the route 2 m ahead of the robot, at 10 %, 50 % and 90 % of the way.
    #[test]
    #[ignore]
    fn timing_replan_after_a_blocked_stretch() {
        use crate::route::neighbourhood::DIRECTIONS;
        use crate::route::testing::{far_corners, timing_costmaps};
        for (size, kind, grid) in timing_costmaps() {
            let (start, goal) = far_corners(&grid);
            let t0 = std::time::Instant::now();
            let scratch = astar(&grid, start, goal, &RouteOptions::default(), &|| false).unwrap();
            let t_astar = t0.elapsed().as_secs_f64();
            let t0 = std::time::Instant::now();
            let mut planned = DStarLite::new(grid, start, goal, RouteOptions::default()).unwrap();
            let first = planned.plan(&|| false).unwrap();
            let t_first = t0.elapsed().as_secs_f64();
            assert!((first.cost - scratch.cost).abs() <= 1e-9 * scratch.cost);
            println!(
                "{kind} {size}²: A* {t_astar:.3} s ({} expanded); D* Lite initial plan \
                 {t_first:.3} s ({} expanded)",
                scratch.expanded, first.expanded
            );
            let cell = planned.grid().dx(0);
            let width = planned.grid().width();
            for fraction in [0.1, 0.5, 0.9] {
                let mut p = planned.clone();
                let k = (first.cells.len() as f64 * fraction) as usize;
                let ahead = (2.0 / cell).round() as usize;
                let here = first.cells[k - ahead];
                p.move_start(here).unwrap();
                // A wall through cells[k], across the route's local direction.
                let (r, c) = first.cells[k];
                let (pr, pc) = first.cells[k - 5];
                let (nr, nc) = first.cells[k + 5];
                let along = (
                    (nr as f64 - pr as f64).signum(),
                    (nc as f64 - pc as f64).signum(),
                );
                let across = DIRECTIONS
                    .iter()
                    .copied()
                    .find(|&(dr, dc)| (dr as f64, dc as f64) == (-along.1, along.0))
                    .unwrap();
                let step = if across.0 != 0 && across.1 != 0 {
                    cell * 2f64.sqrt()
                } else {
                    cell
                };
                let half = (10.0 / step).round() as isize;
                let wall: Vec<(usize, f32)> = (-half..=half)
                    .filter_map(|j| {
                        let (wr, wc) = (r as isize + j * across.0, c as isize + j * across.1);
                        p.grid()
                            .index((wr.max(0) as usize, wc.max(0) as usize))
                            .filter(|_| wr >= 0 && wc >= 0)
                    })
                    .filter(|&i| i != here.0 * width + here.1)
                    .map(|i| (i, f32::INFINITY))
                    .collect();
                p.update_cells(&wall).unwrap();
                let t0 = std::time::Instant::now();
                let replan = p.plan(&|| false);
                let t_replan = t0.elapsed().as_secs_f64();
                let t0 = std::time::Instant::now();
                let fresh = astar(p.grid(), here, goal, &RouteOptions::default(), &|| false);
                let t_fresh = t0.elapsed().as_secs_f64();
                let (a, b) = (
                    replan.as_ref().map(|r| r.cost),
                    fresh.as_ref().map(|r| r.cost),
                );
                match (a, b) {
                    (Ok(a), Ok(b)) => assert!((a - b).abs() <= 1e-9 * b),
                    (a, b) => assert_eq!(a, b),
                }
                println!(
                    "{kind} {size}²: wall at {:.0}%: replan {:.4} s ({} expanded) = {:.1}% of \
                     A* from the robot ({:.3} s), {:.1}% of D* Lite's initial plan; cost {:.3}",
                    100.0 * fraction,
                    t_replan,
                    replan.as_ref().map(|r| r.expanded).unwrap_or(0),
                    100.0 * t_replan / t_fresh,
                    t_fresh,
                    100.0 * t_replan / t_first,
                    a.unwrap_or(f64::NAN)
                );
            }
        }
    }
}
