//! The lazy A* over the implicit visibility graph (see the parent module
//! docs): slack rings of successors, one heap cursor per ring, and the
//! remembered occluders of each closed node.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use geo_types::Coord;
use rstar::{AABB, SelectionFunction};

use super::segment::{Contact, contact};
use super::{Edge, Graph, NodeRef, ObstacleMap, TransitError, dist};

/// First slack ring of the successor generation, as a fraction of the query
/// distance; each further ring is `RING_GROWTH` times wider.
const RING_BASE_FRACTION: f64 = 0.01;
const RING_GROWTH: f64 = 4.0;

impl ObstacleMap {
    /// Shortest path on `graph`, or `None`. Proving that there is none
    /// means closing every node reachable from `a`, which is slow in a large
    /// field when `b` is shut in a small enclosure; so a search that runs
    /// long is paused for a capped search from `b`, which either finds the
    /// path (just as short) or runs dry, proving there is none; otherwise
    /// the first search resumes.
    pub(super) fn find(
        &self,
        graph: &Graph,
        a: Coord<f64>,
        b: Coord<f64>,
        work: &mut usize,
        cap: usize,
    ) -> Result<Option<Vec<Coord<f64>>>, TransitError> {
        let mut forward = AStar::new(self, graph, a, b);
        forward.cap = cap.saturating_sub(*work);
        let first = forward.run(Some(self.probe_closed));
        *work += forward.work;
        match first {
            Search::Found(path) => return Ok(Some(path)),
            Search::Exhausted => return Ok(None),
            Search::OverBudget => return Err(TransitError::OverBudget),
            Search::Capped => {}
        }
        // Enclosures are small: the probe gets a quarter of the budget.
        let mut backward = AStar::new(self, graph, b, a);
        backward.cap = cap.saturating_sub(*work);
        let probe = backward.run(Some(self.probe_closed.div_ceil(4)));
        *work += backward.work;
        match probe {
            Search::Found(mut path) => {
                path.reverse();
                return Ok(Some(path));
            }
            Search::Exhausted => return Ok(None),
            Search::OverBudget => return Err(TransitError::OverBudget),
            Search::Capped => {}
        }
        let before = forward.work;
        forward.cap = forward.work.saturating_add(cap.saturating_sub(*work));
        let last = forward.run(None);
        *work += forward.work - before;
        match last {
            Search::Found(path) => Ok(Some(path)),
            Search::OverBudget => Err(TransitError::OverBudget),
            _ => Ok(None),
        }
    }
}

/// One lazy A* run over the implicit visibility graph (see the module
/// docs); it can be paused after a number of closed nodes and resumed.
pub(super) struct AStar<'m> {
    map: &'m ObstacleMap,
    graph: &'m Graph,
    a: Coord<f64>,
    b: Coord<f64>,
    g: Vec<f64>,
    parent: Vec<usize>,
    /// Closed nodes get a slot in `occluders`: the edges that blocked
    /// earlier candidate edges from that node. Obstacles next to a node hide
    /// most of the others from it, and testing a few remembered edges is far
    /// cheaper than an R-tree walk. A remembered edge is only trusted for a
    /// clean crossing, the same rule `segment_check` applies, so results are
    /// unchanged.
    slot: Vec<u32>,
    occluders: Vec<Vec<Edge>>,
    /// Successors of one closed node in one slack ring, sorted by slack; the
    /// heap holds a single cursor per list, keyed by its next edge, so it
    /// stays small however many candidates a ring has.
    lists: Vec<RingList>,
    heap: BinaryHeap<QueueEntry>,
    ring_base: f64,
    all_nodes: AABB<[f64; 2]>,
    /// Effort so far (closed nodes and obstacle edges tested), and the
    /// effort after which the run gives up.
    work: usize,
    cap: usize,
}

impl<'m> AStar<'m> {
    pub(super) fn new(
        map: &'m ObstacleMap,
        graph: &'m Graph,
        a: Coord<f64>,
        b: Coord<f64>,
    ) -> Self {
        let n = graph.nodes.len();
        let mut search = AStar {
            map,
            graph,
            a,
            b,
            g: vec![f64::INFINITY; n + 2],
            parent: vec![usize::MAX; n + 2],
            slot: vec![OPEN; n + 2],
            occluders: vec![Vec::new()],
            lists: Vec::new(),
            heap: BinaryHeap::new(),
            ring_base: (RING_BASE_FRACTION * dist(a, b)).max(1.0),
            all_nodes: graph.tree.root().envelope(),
            work: 0,
            cap: usize::MAX,
        };
        let start = search.start();
        search.g[start] = 0.0;
        search.slot[start] = 0;
        search.heap.push(QueueEntry {
            key: dist(a, b),
            kind: EntryKind::Expand {
                node: start,
                level: 0,
            },
        });
        search
    }

    fn start(&self) -> usize {
        self.graph.nodes.len()
    }

    fn goal(&self) -> usize {
        self.graph.nodes.len() + 1
    }

    fn pos(&self, i: usize) -> Coord<f64> {
        match i {
            _ if i < self.graph.nodes.len() => self.graph.nodes[i],
            _ if i == self.start() => self.a,
            _ => self.b,
        }
    }

    fn h(&self, c: Coord<f64>) -> f64 {
        dist(c, self.b)
    }

    /// Runs until the goal is closed, the queue runs dry, or (if given)
    /// `max_closed` nodes are closed in all.
    pub(super) fn run(&mut self, max_closed: Option<usize>) -> Search {
        let mut pace = crate::cancel::Pacer::new(4096);
        loop {
            if max_closed.is_some_and(|m| self.occluders.len() >= m) {
                return Search::Capped;
            }
            if pace.tick().is_err() {
                // Cancelled: the caller checks again and reports it.
                return Search::Exhausted;
            }
            if self.work > self.cap {
                return Search::OverBudget;
            }
            let Some(entry) = self.heap.pop() else {
                return Search::Exhausted;
            };
            let (from, to) = match entry.kind {
                EntryKind::Expand { node, level } => {
                    self.expand(node, level);
                    continue;
                }
                EntryKind::Cursor { list } => {
                    let ring = &mut self.lists[list];
                    let (_, to) = ring.cands[ring.next];
                    ring.next += 1;
                    let from = ring.from;
                    if let Some(&(next, _)) = ring.cands.get(ring.next) {
                        let pf = self.pos(from);
                        self.heap.push(QueueEntry {
                            key: self.g[from] + self.h(pf) + next,
                            kind: EntryKind::Cursor { list },
                        });
                    }
                    (from, to)
                }
            };
            if self.slot[to] != OPEN {
                continue;
            }
            let (pf, pt) = (self.pos(from), self.pos(to));
            let known = &mut self.occluders[self.slot[from] as usize];
            if let Some(k) = occluded(known, pf, pt) {
                // Move to front: the nearest occluders hit most often.
                known[..=k].rotate_right(1);
                continue;
            }
            if let Err(blocker) = self.map.segment_check_counted(pf, pt, &mut self.work) {
                if let Some(edge) = blocker {
                    if known.len() == MAX_OCCLUDERS {
                        known.pop();
                    }
                    known.insert(0, edge);
                }
                continue;
            }
            self.work += 1;
            self.slot[to] = self.occluders.len() as u32;
            self.occluders.push(Vec::new());
            self.g[to] = self.g[from] + dist(pf, pt);
            self.parent[to] = from;
            if to == self.goal() {
                let mut path = vec![self.b];
                let mut at = to;
                while at != self.start() {
                    at = self.parent[at];
                    path.push(self.pos(at));
                }
                path.reverse();
                return Search::Found(path);
            }
            self.heap.push(QueueEntry {
                key: self.g[to] + self.h(pt),
                kind: EntryKind::Expand { node: to, level: 0 },
            });
        }
    }

    /// Queues the successors of closed node `u` in slack ring `level`, and
    /// the next ring.
    fn expand(&mut self, u: usize, level: u32) {
        let (pu, gu) = (self.pos(u), self.g[u]);
        let hu = self.h(pu);
        let hi = self.ring_base * RING_GROWTH.powi(level as i32);
        let lo = if level == 0 {
            f64::NEG_INFINITY
        } else {
            hi / RING_GROWTH
        };
        let mut cands: Vec<(f64, usize)> = Vec::new();
        if level == 0 {
            // The goal has zero slack: always in the first ring.
            cands.push((0.0, self.goal()));
        }
        let ring = RingSelect {
            u: pu,
            b: self.b,
            hu,
            lo,
            hi,
        };
        for node in self.graph.tree.locate_with_selection_function(ring) {
            let v = node.data as usize;
            if self.slot[v] == OPEN {
                cands.push((slack(pu, self.graph.nodes[v], self.b, hu), v));
            }
        }
        cands.sort_unstable_by(|x, y| x.0.total_cmp(&y.0));
        if let Some(&(first, _)) = cands.first() {
            self.heap.push(QueueEntry {
                key: gu + hu + first,
                kind: EntryKind::Cursor {
                    list: self.lists.len(),
                },
            });
            self.lists.push(RingList {
                from: u,
                cands,
                next: 0,
            });
        }
        let max_slack =
            max_dist_to_box(pu, &self.all_nodes) + max_dist_to_box(self.b, &self.all_nodes) - hu;
        if !self.graph.nodes.is_empty() && hi < max_slack {
            self.heap.push(QueueEntry {
                key: gu + hu + hi,
                kind: EntryKind::Expand {
                    node: u,
                    level: level + 1,
                },
            });
        }
    }
}

/// Outcome of one (possibly capped) A* run.
pub(super) enum Search {
    Found(Vec<Coord<f64>>),
    /// Every node reachable from the start is closed: there is no path.
    Exhausted,
    /// Stopped at the cap on closed nodes.
    Capped,
    /// Stopped at the cap on effort.
    OverBudget,
}

/// Candidate successors of one closed node within one slack ring.
struct RingList {
    from: usize,
    /// `(slack, node)`, ascending.
    cands: Vec<(f64, usize)>,
    next: usize,
}

/// How much longer the way to `b` gets by going through `v` from `u`
/// (`hu = |ub|`).
fn slack(u: Coord<f64>, v: Coord<f64>, b: Coord<f64>, hu: f64) -> f64 {
    dist(u, v) + dist(v, b) - hu
}

/// `slot` value of a node not closed yet.
const OPEN: u32 = u32::MAX;

/// Occluding edges remembered per closed node.
const MAX_OCCLUDERS: usize = 12;

/// Index of the first remembered edge that `a`–`b` crosses cleanly.
fn occluded(edges: &[Edge], a: Coord<f64>, b: Coord<f64>) -> Option<usize> {
    let len = dist(a, b);
    edges
        .iter()
        .position(|e| matches!(contact(a, b, len, e.p, e.q), Contact::Crossing))
}

#[derive(Clone, Copy, Debug)]
enum EntryKind {
    /// The next candidate edge of ring list `list`.
    Cursor { list: usize },
    /// Generate the successors of closed node `node` in slack ring `level`.
    Expand { node: usize, level: u32 },
}

/// Min-heap entry ordered by `key`, a lower bound of the length of any path
/// through the entry's next edge.
#[derive(Clone, Copy, Debug)]
struct QueueEntry {
    key: f64,
    kind: EntryKind,
}

impl PartialEq for QueueEntry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for QueueEntry {}

impl PartialOrd for QueueEntry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for QueueEntry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.key.total_cmp(&self.key)
    }
}

/// R-tree selection of the nodes `v` whose slack `|uv| + |vb| − |ub|` lies in
/// `(lo, hi]`: an elliptic ring with foci `u` and `b`.
struct RingSelect {
    u: Coord<f64>,
    b: Coord<f64>,
    hu: f64,
    lo: f64,
    hi: f64,
}

impl SelectionFunction<NodeRef> for RingSelect {
    fn should_unpack_parent(&self, envelope: &AABB<[f64; 2]>) -> bool {
        let min = min_dist_to_box(self.u, envelope) + min_dist_to_box(self.b, envelope) - self.hu;
        let max = max_dist_to_box(self.u, envelope) + max_dist_to_box(self.b, envelope) - self.hu;
        min <= self.hi && max > self.lo
    }

    fn should_unpack_leaf(&self, leaf: &NodeRef) -> bool {
        let [x, y] = *leaf.geom();
        let v = Coord { x, y };
        let s = slack(self.u, v, self.b, self.hu);
        s > self.lo && s <= self.hi
    }
}

fn min_dist_to_box(p: Coord<f64>, envelope: &AABB<[f64; 2]>) -> f64 {
    envelope.distance_2(&[p.x, p.y]).sqrt()
}

fn max_dist_to_box(p: Coord<f64>, envelope: &AABB<[f64; 2]>) -> f64 {
    let (lower, upper) = (envelope.lower(), envelope.upper());
    let dx = (p.x - lower[0]).abs().max((upper[0] - p.x).abs());
    let dy = (p.y - lower[1]).abs().max((upper[1] - p.y).abs());
    (dx * dx + dy * dy).sqrt()
}
