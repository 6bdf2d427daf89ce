//! Transit paths that avoid no-fly zones (SPEC §3.4).
//!
//! A transit (start → cell, cell → cell, cell → home) is the shortest polyline
//! that never passes through the interior of a no-fly zone. Shortest paths
//! among polygonal obstacles bend only at convex obstacle corners, so the
//! search runs on a visibility graph whose nodes are those corners, each pushed
//! a little outward along its bisector so the flown path keeps a clearance
//! from the NFZ corners.
//!
//! The full visibility graph of ~8000 corners has tens of millions of
//! candidate edges, so it is never built. A* runs lazily instead: a candidate
//! edge `u → v` is keyed by `g(u) + |uv| + h(v)`, a lower bound of any path
//! through it, and its visibility is only tested once it is the cheapest
//! entry left; the first visible edge into a node then gives its optimal
//! `g`, as in plain A* with a consistent heuristic. Successors of a closed
//! node are generated in elliptic rings of growing *slack*
//! `|uv| + h(v) − h(u)` (an R-tree query on the nodes), each ring sorted and
//! represented in the heap by a single cursor, so corners that cannot beat
//! the final length are never touched. A visibility test first tries the
//! few edges that already blocked other candidates from the same node, then
//! walks an R-tree of obstacle edges along the segment.
//!
//! With ~1000 NFZs (6000 nodes) a transit between neighbouring cells takes
//! tens of microseconds and one across the whole field about 5 ms (release
//! build).

use std::fmt;

use geo::kernels::{Kernel, Orientation, RobustKernel};
use geo_types::{Coord, LineString, MultiPolygon};
use rstar::primitives::GeomWithData;
use rstar::{AABB, PointDistance, RTree, RTreeObject};

/// Geometric tolerance in metres. Lane ends computed on an NFZ border may be
/// off it by rounding noise; a point closer than this to an obstacle boundary
/// counts as *on* the boundary, never strictly inside. The free space that
/// lanes are clipped to and the NFZ union here come from separate boolean
/// operations, each snapped to a grid of ~1e-9 of its extent (micrometres to
/// tens of micrometres at survey scale), so the tolerance must sit well
/// above that; a millimetre is still far below anything a UAV can fly.
const EPS: f64 = 1e-3;

mod search;
mod segment;

/// Which end of a requested transit an error refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endpoint {
    Start,
    End,
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Endpoint::Start => "start",
            Endpoint::End => "end",
        })
    }
}

/// Why no transit could be planned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TransitError {
    #[error("transit {endpoint} point ({}, {}) lies inside a no-fly zone", .point.x, .point.y)]
    InsideObstacle {
        endpoint: Endpoint,
        point: Coord<f64>,
    },
    #[error("transit {endpoint} point has a non-finite coordinate")]
    NonFinite { endpoint: Endpoint },
    #[error(
        "no path from ({}, {}) to ({}, {}) avoids the no-fly zones",
        .from.x, .from.y, .to.x, .to.y
    )]
    NoPath { from: Coord<f64>, to: Coord<f64> },
    /// Stopped by its cancellation token (see [`crate::cancel`]).
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
    /// A budgeted search ([`ObstacleMap::shortest_path_counted`]) gave up.
    #[error("the transit search exceeded its effort budget")]
    OverBudget,
}

/// One obstacle boundary edge, indexed in an R-tree.
#[derive(Clone, Copy, Debug)]
struct Edge {
    p: Coord<f64>,
    q: Coord<f64>,
    obstacle: usize,
}

impl RTreeObject for Edge {
    type Envelope = AABB<[f64; 2]>;

    fn envelope(&self) -> Self::Envelope {
        AABB::from_corners([self.p.x, self.p.y], [self.q.x, self.q.y])
    }
}

/// Nearest-edge queries (the exit of an endpoint inside an obstacle).
impl PointDistance for Edge {
    fn distance_2(&self, point: &[f64; 2]) -> f64 {
        let c = Coord {
            x: point[0],
            y: point[1],
        };
        let d = closest_on_segment(c, self.p, self.q) - c;
        d.x * d.x + d.y * d.y
    }
}

/// Bounding box of one obstacle polygon, for point-in-obstacle queries.
#[derive(Clone, Debug)]
struct ObstacleBox {
    envelope: AABB<[f64; 2]>,
    index: usize,
}

impl RTreeObject for ObstacleBox {
    type Envelope = AABB<[f64; 2]>;

    fn envelope(&self) -> Self::Envelope {
        self.envelope
    }
}

/// An obstacle polygon as plain rings: exterior counter-clockwise, holes
/// clockwise, no closing duplicate, so the obstacle interior is always on the
/// left of every edge.
#[derive(Clone, Debug)]
struct Obstacle {
    exterior: Vec<Coord<f64>>,
    holes: Vec<Vec<Coord<f64>>>,
}

impl Obstacle {
    /// Crossing-number test; the result on the boundary itself is arbitrary
    /// (callers reject boundary points separately).
    fn contains(&self, p: Coord<f64>) -> bool {
        ring_contains(&self.exterior, p) && !self.holes.iter().any(|h| ring_contains(h, p))
    }

    fn rings(&self) -> impl Iterator<Item = &Vec<Coord<f64>>> {
        std::iter::once(&self.exterior).chain(self.holes.iter())
    }
}

type NodeRef = GeomWithData<[f64; 2], u32>;

/// No-fly zones prepared for many transit queries.
///
/// Build it once per mission from the NFZ union (overlapping or touching
/// polygons also work: an edge shared by two touching polygons is inside
/// their union, so no transit runs along it) and share it: it is immutable,
/// `Send` and `Sync`.
#[derive(Clone, Debug)]
pub struct ObstacleMap {
    obstacles: Vec<Obstacle>,
    obstacle_tree: RTree<ObstacleBox>,
    edge_tree: RTree<Edge>,
    /// Visibility-graph nodes: convex corners pushed out by the clearance.
    graph: Graph,
    /// The bare corners, used when the pushed nodes find no path (a door
    /// narrower than the clearance); `None` without clearance.
    bare: Option<Graph>,
    clearance_m: f64,
    /// Points inside an obstacle from which transits may start or end, each
    /// with its exit: the nearest point outside (see
    /// [`ObstacleMap::allow_endpoint`]).
    exits: Vec<(Coord<f64>, Coord<f64>)>,
    /// Closed nodes after which a search pauses to probe from the goal
    /// ([`PROBE_CLOSED`]; tests lower it to exercise every branch).
    probe_closed: usize,
}

/// Nodes of a visibility graph and their R-tree.
#[derive(Clone, Debug)]
struct Graph {
    nodes: Vec<Coord<f64>>,
    tree: RTree<NodeRef>,
}

impl Graph {
    fn new(nodes: Vec<Coord<f64>>) -> Self {
        let tree = RTree::bulk_load(
            nodes
                .iter()
                .enumerate()
                .map(|(i, c)| GeomWithData::new([c.x, c.y], i as u32))
                .collect(),
        );
        Graph { nodes, tree }
    }
}

impl ObstacleMap {
    /// Prepares `obstacles` (UTM metres). Graph nodes are the obstacles'
    /// convex corners moved `clearance_m` outward along the corner bisector;
    /// where that lands inside another obstacle the push is halved (down to
    /// the bare corner) so narrow gaps stay passable, and a corner that is
    /// itself inside another obstacle is dropped. A negative or
    /// non-finite clearance is treated as 0 (request validation is the
    /// caller's job). Rings with non-finite or repeated vertices are cleaned,
    /// degenerate rings (fewer than 3 vertices or zero area) are ignored.
    pub fn new(obstacles: &MultiPolygon<f64>, clearance_m: f64) -> Self {
        let clearance_m = if clearance_m.is_finite() {
            clearance_m.max(0.0)
        } else {
            0.0
        };
        let mut prepared = Vec::new();
        for polygon in obstacles {
            let Some(exterior) = clean_ring(polygon.exterior(), true) else {
                continue;
            };
            let holes = polygon
                .interiors()
                .iter()
                .filter_map(|ring| clean_ring(ring, false))
                .collect();
            prepared.push(Obstacle { exterior, holes });
        }

        let mut edges = Vec::new();
        let mut boxes = Vec::with_capacity(prepared.len());
        for (index, obstacle) in prepared.iter().enumerate() {
            let corners: Vec<[f64; 2]> = obstacle.exterior.iter().map(|c| [c.x, c.y]).collect();
            boxes.push(ObstacleBox {
                envelope: AABB::from_points(corners.iter()),
                index,
            });
            for ring in obstacle.rings() {
                for (i, &p) in ring.iter().enumerate() {
                    edges.push(Edge {
                        p,
                        q: ring[(i + 1) % ring.len()],
                        obstacle: index,
                    });
                }
            }
        }

        let mut map = ObstacleMap {
            obstacles: prepared,
            obstacle_tree: RTree::bulk_load(boxes),
            edge_tree: RTree::bulk_load(edges),
            graph: Graph::new(Vec::new()),
            bare: None,
            clearance_m,
            exits: Vec::new(),
            probe_closed: PROBE_CLOSED,
        };

        let (mut nodes, mut bare) = (Vec::new(), Vec::new());
        for obstacle in &map.obstacles {
            for ring in obstacle.rings() {
                let n = ring.len();
                for i in 0..n {
                    let (p, c, q) = (ring[(i + n - 1) % n], ring[i], ring[(i + 1) % n]);
                    // Interior on the left: a left turn is a convex corner of
                    // the obstacle (a reflex corner of free space), the only
                    // kind a shortest path can bend around.
                    if RobustKernel::orient2d(p, c, q) != Orientation::CounterClockwise
                        || map.contains_point(c)
                    {
                        continue;
                    }
                    bare.push(c);
                    // Where the full clearance would land in another
                    // obstacle (a gap narrower than the clearance), push
                    // less rather than lose the corner and the gap with it.
                    let out = outward_bisector(p, c, q);
                    let mut push = clearance_m;
                    loop {
                        let node = c + out * push;
                        if is_finite(node) && !map.contains_point(node) {
                            nodes.push(node);
                            break;
                        }
                        // Ends at the bare corner, which is outside.
                        push = if push > clearance_m / 64.0 {
                            push / 2.0
                        } else {
                            0.0
                        };
                    }
                }
            }
        }
        map.graph = Graph::new(nodes);
        map.bare = (clearance_m > 0.0).then(|| Graph::new(bare));
        map
    }

    /// The same obstacles (and allowed endpoints) with the graph nodes
    /// pushed `clearance_m` out from their corners instead: paths bend
    /// farther from the corners, as a turning plane needs.
    pub fn pushed(&self, clearance_m: f64) -> ObstacleMap {
        let mut map = ObstacleMap::new(&self.polygons(), clearance_m);
        map.exits = self.exits.clone();
        map
    }

    /// The obstacles kept, as polygons.
    pub fn polygons(&self) -> MultiPolygon<f64> {
        let ring = |r: &Vec<Coord<f64>>| LineString(r.clone());
        let polygons = self
            .obstacles
            .iter()
            .map(|o| geo_types::Polygon::new(ring(&o.exterior), o.holes.iter().map(ring).collect()))
            .collect();
        MultiPolygon(polygons)
    }

    /// The clearance used for the graph nodes, in metres.
    pub fn clearance_m(&self) -> f64 {
        self.clearance_m
    }

    /// Number of obstacle polygons kept.
    pub fn obstacle_count(&self) -> usize {
        self.obstacles.len()
    }

    /// Number of visibility-graph nodes (pushed convex corners).
    pub fn node_count(&self) -> usize {
        self.graph.nodes.len()
    }

    /// True iff `p` lies strictly inside an obstacle: inside it and farther
    /// than a micrometre from its boundary. A point on an edge shared by two
    /// touching obstacles is on a boundary, hence not inside. Non-finite
    /// points are never inside.
    pub fn contains_point(&self, p: Coord<f64>) -> bool {
        is_finite(p)
            && self.candidates(p).any(|index| {
                self.obstacles[index].contains(p) && !self.near_boundary(p, Some(index))
            })
    }

    /// True iff the segment `a`–`b` does not pass through any obstacle
    /// interior. Touching a boundary, running along an edge, or starting on a
    /// boundary and leaving outward are all clear.
    pub fn is_clear(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        is_finite(a) && is_finite(b) && self.segment_clear(a, b)
    }

    /// Shortest polyline from `a` to `b` (both included) that avoids every
    /// obstacle interior, bending only at the clearance-pushed corners;
    /// `[a, b]` when the direct segment is clear. If no such path exists
    /// (the only way leads through a gap narrower than the clearance) the
    /// path may bend at the bare corners instead.
    pub fn shortest_path(
        &self,
        a: Coord<f64>,
        b: Coord<f64>,
    ) -> Result<Vec<Coord<f64>>, TransitError> {
        self.shortest_path_counted(a, b, &mut 0, usize::MAX)
    }

    /// [`ObstacleMap::shortest_path`], adding its searches' effort (closed
    /// nodes and obstacle edges tested) to `work`, and giving up with
    /// [`TransitError::OverBudget`] once `work` would pass `cap`: callers
    /// that only look for improvements bound their time with it.
    pub(crate) fn shortest_path_counted(
        &self,
        a: Coord<f64>,
        b: Coord<f64>,
        work: &mut usize,
        cap: usize,
    ) -> Result<Vec<Coord<f64>>, TransitError> {
        // Flocks ask for many transits: each is a point to stop at.
        crate::cancel::check()?;
        for (endpoint, p) in [(Endpoint::Start, a), (Endpoint::End, b)] {
            if !is_finite(p) {
                return Err(TransitError::NonFinite { endpoint });
            }
        }
        let exit_a = self.exit_of(a);
        let exit_b = self.exit_of(b);
        if exit_a.is_some() || exit_b.is_some() {
            // Straight out of the obstacle to the exit, the transit between
            // the exits, straight in again.
            let (ea, eb) = (exit_a.unwrap_or(a), exit_b.unwrap_or(b));
            let mut path = vec![a];
            path.extend(self.shortest_path_counted(ea, eb, work, cap)?);
            path.push(b);
            path.dedup();
            return Ok(path);
        }
        for (endpoint, p) in [(Endpoint::Start, a), (Endpoint::End, b)] {
            if self.contains_point(p) {
                return Err(TransitError::InsideObstacle { endpoint, point: p });
            }
        }
        if self.segment_clear(a, b) {
            return Ok(vec![a, b]);
        }
        let found = match self.find(&self.graph, a, b, work, cap)? {
            Some(path) => Some(path),
            None => match &self.bare {
                Some(bare) => self.find(bare, a, b, work, cap)?,
                None => None,
            },
        };
        // A cancelled search gives up as if there were no path.
        crate::cancel::check()?;
        found.ok_or(TransitError::NoPath { from: a, to: b })
    }

    /// Let transits start or end at `p` although it lies inside an obstacle
    /// (a take-off point within the clearance band of an NFZ, where the
    /// vehicle climbs and lands vertically): they leave it straight to the
    /// nearest point outside every obstacle, which is returned. `None` when
    /// `p` is not inside an obstacle (nothing to do) or is not finite.
    pub fn allow_endpoint(&mut self, p: Coord<f64>) -> Option<Coord<f64>> {
        if !is_finite(p) || !self.contains_point(p) {
            return None;
        }
        let exit = self.nearest_outside(p)?;
        self.exits.push((p, exit));
        Some(exit)
    }

    /// The exit recorded for `p` by [`ObstacleMap::allow_endpoint`].
    fn exit_of(&self, p: Coord<f64>) -> Option<Coord<f64>> {
        self.exits.iter().find(|(q, _)| *q == p).map(|&(_, e)| e)
    }

    /// The nearest point outside every obstacle to `p`, which is inside one:
    /// the nearest boundary point, nudged a centimetre outward so that it is
    /// clear of the boundary tolerance. Boundary points inside another
    /// obstacle (shared edges of touching obstacles) are skipped.
    fn nearest_outside(&self, p: Coord<f64>) -> Option<Coord<f64>> {
        const NUDGE: f64 = 0.01;
        self.edge_tree
            .nearest_neighbor_iter_with_distance_2(&[p.x, p.y])
            .take(256)
            .find_map(|(edge, _)| {
                let q = closest_on_segment(p, edge.p, edge.q);
                let d = q - p;
                let len = d.x.hypot(d.y);
                if len <= 0.0 {
                    return None;
                }
                let out = q + d * (NUDGE / len);
                (!self.contains_point(out)).then_some(out)
            })
    }

    /// Length of [`ObstacleMap::shortest_path`].
    pub fn shortest_length(&self, a: Coord<f64>, b: Coord<f64>) -> Result<f64, TransitError> {
        Ok(polyline_length(&self.shortest_path(a, b)?))
    }

    /// Obstacles whose bounding box holds `p`.
    fn candidates(&self, p: Coord<f64>) -> impl Iterator<Item = usize> + '_ {
        self.obstacle_tree
            .locate_in_envelope_intersecting(&AABB::from_point([p.x, p.y]))
            .map(|b| b.index)
    }

    /// Is `p` inside some obstacle by the plain crossing test (no boundary
    /// tolerance)?
    fn inside_any(&self, p: Coord<f64>) -> bool {
        self.candidates(p)
            .any(|index| self.obstacles[index].contains(p))
    }

    /// Is `p` within [`EPS`] of an edge (of obstacle `only`, if given)?
    fn near_boundary(&self, p: Coord<f64>, only: Option<usize>) -> bool {
        let envelope = AABB::from_corners([p.x - EPS, p.y - EPS], [p.x + EPS, p.y + EPS]);
        self.edge_tree
            .locate_in_envelope_intersecting(&envelope)
            .any(|e| {
                only.is_none_or(|o| o == e.obstacle) && point_segment_distance(p, e.p, e.q) <= EPS
            })
    }
}

/// Closed nodes after which a search pauses to probe from the goal.
const PROBE_CLOSED: usize = 256;

/// Total length of a polyline.
pub fn polyline_length(path: &[Coord<f64>]) -> f64 {
    path.windows(2).map(|w| dist(w[0], w[1])).sum()
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    (dx * dx + dy * dy).sqrt()
}

fn is_finite(c: Coord<f64>) -> bool {
    c.x.is_finite() && c.y.is_finite()
}

/// The point of segment `a`–`b` nearest to `c`.
fn closest_on_segment(c: Coord<f64>, a: Coord<f64>, b: Coord<f64>) -> Coord<f64> {
    let d = b - a;
    let len2 = d.x * d.x + d.y * d.y;
    if len2 <= 0.0 {
        return a;
    }
    let t = (((c.x - a.x) * d.x + (c.y - a.y) * d.y) / len2).clamp(0.0, 1.0);
    a + d * t
}

fn point_segment_distance(c: Coord<f64>, a: Coord<f64>, b: Coord<f64>) -> f64 {
    dist(c, closest_on_segment(c, a, b))
}

/// Unit vector pointing out of the obstacle at convex corner `c` (interior
/// on the left of `p → c → q`).
fn outward_bisector(p: Coord<f64>, c: Coord<f64>, q: Coord<f64>) -> Coord<f64> {
    let unit = |v: Coord<f64>| v / (v.x * v.x + v.y * v.y).sqrt();
    let v = unit(c - p) - unit(q - c);
    if v.x * v.x + v.y * v.y > 1e-24 {
        unit(v)
    } else {
        // A nearly straight corner: the bisector is the edge's outer normal.
        let e = q - p;
        unit(Coord { x: e.y, y: -e.x })
    }
}

/// Even-odd crossing test against one closed ring (no closing duplicate).
fn ring_contains(ring: &[Coord<f64>], p: Coord<f64>) -> bool {
    let mut inside = false;
    let mut j = ring.len() - 1;
    for i in 0..ring.len() {
        let (a, b) = (ring[i], ring[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Drops non-finite and repeated vertices and the closing duplicate, and
/// orients the ring (counter-clockwise when `ccw`). `None` for rings without
/// area.
fn clean_ring(ring: &LineString<f64>, ccw: bool) -> Option<Vec<Coord<f64>>> {
    let mut out: Vec<Coord<f64>> = Vec::with_capacity(ring.0.len());
    for &c in ring.0.iter().filter(|c| is_finite(**c)) {
        if out.last() != Some(&c) {
            out.push(c);
        }
    }
    while out.len() > 1 && out.first() == out.last() {
        out.pop();
    }
    if out.len() < 3 {
        return None;
    }
    let twice_area: f64 = (0..out.len())
        .map(|i| {
            let (a, b) = (out[i], out[(i + 1) % out.len()]);
            a.x * b.y - a.y * b.x
        })
        .sum();
    if twice_area == 0.0 || !twice_area.is_finite() {
        return None;
    }
    if (twice_area > 0.0) != ccw {
        out.reverse();
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::search::{AStar, Search};
    use super::*;
    use crate::flock::test_support::{Lcg, rect};
    use approx::assert_relative_eq;
    use geo_types::{Polygon, coord};

    fn assert_path_clear(map: &ObstacleMap, path: &[Coord<f64>]) {
        for w in path.windows(2) {
            assert!(map.is_clear(w[0], w[1]), "segment {w:?} is blocked");
        }
    }

    #[test]
    fn direct_segment_when_nothing_blocks() {
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), 1.0);
        let path = map
            .shortest_path(coord! { x: -5.0, y: 20.0 }, coord! { x: 15.0, y: 20.0 })
            .unwrap();
        assert_eq!(
            path,
            vec![coord! { x: -5.0, y: 20.0 }, coord! { x: 15.0, y: 20.0 }]
        );
    }

    #[test]
    fn square_between_gives_two_corner_detour() {
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), 0.0);
        let a = coord! { x: -10.0, y: 5.0 };
        let b = coord! { x: 20.0, y: 5.0 };
        let path = map.shortest_path(a, b).unwrap();
        assert_eq!(path.len(), 4, "{path:?}");
        // Over either pair of corners: 2·√(10² + 5²) + 10.
        let expected = 2.0 * 125f64.sqrt() + 10.0;
        assert_relative_eq!(polyline_length(&path), expected, epsilon = 1e-9);
        assert_path_clear(&map, &path);
    }

    #[test]
    fn clearance_pushes_the_detour_off_the_corners() {
        let r = 2.0;
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), r);
        let path = map
            .shortest_path(coord! { x: -10.0, y: 5.0 }, coord! { x: 20.0, y: 5.0 })
            .unwrap();
        assert_eq!(path.len(), 4);
        let s = r / 2f64.sqrt();
        let corners = [(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)]
            .map(|(x, y)| coord! { x: x, y: y });
        for corner in &path[1..3] {
            // Each bend is a corner moved r along the diagonal.
            let nearest = corners
                .iter()
                .map(|c| dist(*corner, *c))
                .fold(f64::INFINITY, f64::min);
            assert_relative_eq!(nearest, r, epsilon = 1e-9);
            assert!(corner.x < 0.0 || corner.x > 10.0);
            assert_relative_eq!((corner.y - 5.0).abs(), 5.0 + s, epsilon = 1e-9);
        }
        assert_path_clear(&map, &path);
    }

    #[test]
    fn wall_of_touching_obstacles_is_walked_around() {
        // Five unit squares stacked into a wall x ∈ [0, 10], y ∈ [0, 50].
        let wall: Vec<_> = (0..5)
            .map(|i| rect(0.0, 10.0 * i as f64, 10.0, 10.0 * (i + 1) as f64))
            .collect();
        let map = ObstacleMap::new(&MultiPolygon(wall), 0.0);
        let a = coord! { x: -10.0, y: 15.0 };
        let b = coord! { x: 20.0, y: 15.0 };
        assert!(!map.is_clear(a, b));
        let path = map.shortest_path(a, b).unwrap();
        assert_path_clear(&map, &path);
        // Around the bottom: corners (0, 0) and (10, 0).
        let expected = 2.0 * (100.0f64 + 225.0).sqrt() + 10.0;
        assert_relative_eq!(polyline_length(&path), expected, epsilon = 1e-9);
        assert!(path.iter().all(|c| c.y <= 15.0));
    }

    #[test]
    fn boundary_points_are_valid_endpoints() {
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), 1.0);
        let on_edge = coord! { x: 10.0, y: 5.0 };
        let corner = coord! { x: 0.0, y: 0.0 };
        assert!(!map.contains_point(on_edge));
        assert!(!map.contains_point(corner));
        // Leaving outward is clear, cutting through is not.
        assert!(map.is_clear(on_edge, coord! { x: 20.0, y: 5.0 }));
        assert!(!map.is_clear(on_edge, coord! { x: -5.0, y: 5.0 }));
        // Sliding along the edge is clear.
        assert!(map.is_clear(coord! { x: 10.0, y: -5.0 }, coord! { x: 10.0, y: 15.0 }));
        // Rounding noise: a lane end a nanometre inside still counts as on it.
        let noisy = coord! { x: 10.0 - 1e-9, y: 5.0 };
        assert!(map.is_clear(noisy, coord! { x: 20.0, y: 5.0 }));

        // A chord between two boundary points that rounding put a hair
        // inside is still a chord through the obstacle.
        let (left, right) = (
            coord! { x: 1e-9, y: 3.0 },
            coord! { x: 10.0 - 1e-9, y: 7.0 },
        );
        assert!(!map.contains_point(left) && !map.contains_point(right));
        assert!(!map.is_clear(left, right));
        let path = map.shortest_path(left, right).unwrap();
        assert!(path.len() > 2);
        assert_path_clear(&map, &path);

        let path = map
            .shortest_path(on_edge, coord! { x: -5.0, y: 5.0 })
            .unwrap();
        assert_eq!(path.first(), Some(&on_edge));
        assert_path_clear(&map, &path);
        let path = map
            .shortest_path(corner, coord! { x: 10.0, y: 10.0 })
            .unwrap();
        assert_path_clear(&map, &path);
        assert!(polyline_length(&path) > 20.0);
    }

    #[test]
    fn endpoint_inside_is_an_error() {
        let map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), 1.0);
        let inside = coord! { x: 5.0, y: 5.0 };
        let outside = coord! { x: 20.0, y: 5.0 };
        assert_eq!(
            map.shortest_path(inside, outside),
            Err(TransitError::InsideObstacle {
                endpoint: Endpoint::Start,
                point: inside
            })
        );
        assert_eq!(
            map.shortest_path(outside, inside),
            Err(TransitError::InsideObstacle {
                endpoint: Endpoint::End,
                point: inside
            })
        );
        let nan = coord! { x: f64::NAN, y: 0.0 };
        assert_eq!(
            map.shortest_path(outside, nan),
            Err(TransitError::NonFinite {
                endpoint: Endpoint::End
            })
        );
        assert!(!map.is_clear(outside, nan));
    }

    #[test]
    fn allowed_endpoint_inside_leaves_straight_by_the_nearest_exit() {
        // The keep-out band of an NFZ: 10 × 10 m, home 1 m inside its west
        // edge, goal east of it.
        let mut map = ObstacleMap::new(&MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0)]), 0.0);
        let home = coord! { x: 1.0, y: 4.0 };
        let goal = coord! { x: 20.0, y: 4.0 };
        assert_eq!(map.allow_endpoint(goal), None, "outside: nothing to do");
        let exit = map.allow_endpoint(home).expect("an exit");
        assert!(
            (exit.x - -0.01).abs() < 1e-9 && (exit.y - 4.0).abs() < 1e-9,
            "{exit:?}"
        );
        for (a, b) in [(home, goal), (goal, home)] {
            let path = map.shortest_path(a, b).unwrap();
            assert_eq!(path.first(), Some(&a));
            assert_eq!(path.last(), Some(&b));
            let k = if a == home { 1 } else { path.len() - 2 };
            assert_eq!(path[k], exit);
            // Outside the exit leg the path stays out of the obstacle.
            let rest: Vec<Coord<f64>> = if a == home {
                path[1..].to_vec()
            } else {
                path[..path.len() - 1].to_vec()
            };
            assert_path_clear(&map, &rest);
            // Round the obstacle: longer than the straight line.
            assert!(polyline_length(&path) > 19.0 + 2.0);
        }
        // Between two allowed points: both exits.
        let other = coord! { x: 9.5, y: 9.0 };
        let exit2 = map.allow_endpoint(other).unwrap();
        assert!((exit2.x - 10.01).abs() < 1e-9, "{exit2:?}");
        let path = map.shortest_path(home, other).unwrap();
        assert_eq!((path[1], path[path.len() - 2]), (exit, exit2));
    }

    #[test]
    fn enclosed_goal_has_no_path() {
        // A ring-shaped NFZ (polygon with a hole) around the goal.
        let ring = Polygon::new(
            rect(0.0, 0.0, 30.0, 30.0).exterior().clone(),
            vec![rect(10.0, 10.0, 20.0, 20.0).exterior().clone()],
        );
        let map = ObstacleMap::new(&MultiPolygon(vec![ring]), 0.5);
        let a = coord! { x: -5.0, y: -5.0 };
        let b = coord! { x: 15.0, y: 15.0 };
        assert!(!map.contains_point(b));
        assert_eq!(
            map.shortest_path(a, b),
            Err(TransitError::NoPath { from: a, to: b })
        );
        // Inside the hole, paths work.
        let inner = map.shortest_path(b, coord! { x: 11.0, y: 19.0 }).unwrap();
        assert_eq!(inner.len(), 2);
    }

    #[test]
    fn enclosure_in_a_large_field_is_detected_from_either_end() {
        // 20 × 20 squares (1600 corners) and a walled yard round `inner`.
        let mut polys: Vec<Polygon<f64>> = (0..400)
            .map(|k| {
                let (x, y) = (10.0 * (k % 20) as f64, 10.0 * (k / 20) as f64);
                rect(x, y, x + 5.0, y + 5.0)
            })
            .collect();
        polys.push(Polygon::new(
            rect(300.0, 0.0, 340.0, 40.0).exterior().clone(),
            vec![rect(310.0, 10.0, 330.0, 30.0).exterior().clone()],
        ));
        let mut map = ObstacleMap::new(&MultiPolygon(polys), 1.0);
        let (outer, inner) = (coord! { x: -3.0, y: -3.0 }, coord! { x: 320.0, y: 20.0 });
        for probe in [PROBE_CLOSED, 8] {
            map.probe_closed = probe;
            for (a, b) in [(outer, inner), (inner, outer)] {
                assert_eq!(
                    map.shortest_path(a, b),
                    Err(TransitError::NoPath { from: a, to: b })
                );
            }
            // Paths across the field come out as short as an uncapped
            // search's when the search is capped and the goal side probes.
            for (a, b) in [
                (outer, coord! { x: 197.5, y: 197.5 }),
                (coord! { x: 7.5, y: 191.0 }, coord! { x: 196.0, y: 2.5 }),
            ] {
                let path = map.shortest_path(a, b).unwrap();
                assert_path_clear(&map, &path);
                let Search::Found(reference) = AStar::new(&map, &map.graph, a, b).run(None) else {
                    panic!("no reference path");
                };
                assert_relative_eq!(
                    polyline_length(&path),
                    polyline_length(&reference),
                    max_relative = 1e-9
                );
            }
        }
    }

    #[test]
    fn path_bends_around_hole_corners_inside_a_courtyard() {
        // An L-shaped courtyard: the hole's reflex corner must be a node.
        let outer = rect(0.0, 0.0, 40.0, 40.0);
        let hole = geo_types::LineString::from(vec![
            (10.0, 10.0),
            (30.0, 10.0),
            (30.0, 20.0),
            (20.0, 20.0),
            (20.0, 30.0),
            (10.0, 30.0),
        ]);
        let map = ObstacleMap::new(
            &MultiPolygon(vec![Polygon::new(outer.exterior().clone(), vec![hole])]),
            0.0,
        );
        let a = coord! { x: 28.0, y: 18.0 };
        let b = coord! { x: 18.0, y: 28.0 };
        let path = map.shortest_path(a, b).unwrap();
        assert_eq!(path.len(), 3);
        assert_relative_eq!(polyline_length(&path), 2.0 * 68f64.sqrt(), epsilon = 1e-9);
        // Touching the reflex corner itself is allowed.
        assert!(map.is_clear(coord! { x: 28.0, y: 12.0 }, coord! { x: 12.0, y: 28.0 }));
        assert_relative_eq!(path[1].x, 20.0, epsilon = 1e-9);
        assert_relative_eq!(path[1].y, 20.0, epsilon = 1e-9);
    }

    #[test]
    fn nodes_never_land_inside_obstacles() {
        // Two squares with facing corners 0.7 m apart diagonally: a 2 m
        // clearance would push each facing corner's node into the other
        // square, so those two corners get a smaller push.
        let map = ObstacleMap::new(
            &MultiPolygon(vec![
                rect(0.0, 0.0, 10.0, 10.0),
                rect(10.5, 10.5, 30.0, 30.0),
            ]),
            2.0,
        );
        assert_eq!(map.obstacle_count(), 2);
        assert_eq!(map.node_count(), 8);
        assert!(map.graph.nodes.iter().all(|&n| !map.contains_point(n)));
        let pushes: Vec<f64> = map
            .graph
            .nodes
            .iter()
            .map(|n| {
                [
                    (0.0, 0.0),
                    (10.0, 0.0),
                    (10.0, 10.0),
                    (0.0, 10.0),
                    (10.5, 10.5),
                    (30.0, 10.5),
                    (30.0, 30.0),
                    (10.5, 30.0),
                ]
                .iter()
                .map(|&(x, y)| dist(*n, coord! { x: x, y: y }))
                .fold(f64::INFINITY, f64::min)
            })
            .collect();
        assert_eq!(
            pushes.iter().filter(|&&d| (d - 2.0).abs() < 1e-9).count(),
            6
        );
        assert!(pushes.iter().all(|&d| d > 0.0 && d <= 2.0 + 1e-9));

        // A corner inside another obstacle is dropped altogether.
        let map = ObstacleMap::new(
            &MultiPolygon(vec![rect(0.0, 0.0, 10.0, 10.0), rect(5.0, 5.0, 20.0, 20.0)]),
            1.0,
        );
        assert_eq!(map.node_count(), 6);
    }

    #[test]
    fn door_narrower_than_the_clearance_stays_passable() {
        // A courtyard (a U and two bars on top) whose only door is 1 m wide
        // between x = 19.5 and 20.5; with a 3 m clearance no pushed corner
        // sees through it, so the bare corners are used.
        let u = Polygon::new(
            LineString::from(vec![
                (0.0, 0.0),
                (40.0, 0.0),
                (40.0, 40.0),
                (30.0, 40.0),
                (30.0, 10.0),
                (10.0, 10.0),
                (10.0, 40.0),
                (0.0, 40.0),
            ]),
            vec![],
        );
        let nfz = MultiPolygon(vec![
            u,
            rect(0.0, 40.0, 19.5, 50.0),
            rect(20.5, 40.0, 40.0, 50.0),
        ]);
        let map = ObstacleMap::new(&nfz, 3.0);
        let a = coord! { x: 20.0, y: 20.0 };
        let b = coord! { x: 35.0, y: 60.0 };
        assert_eq!(map.find(&map.graph, a, b, &mut 0, usize::MAX), Ok(None));
        let path = map.shortest_path(a, b).unwrap();
        assert_path_clear(&map, &path);
        assert_eq!(path.len(), 3, "{path:?}");
        // Budgeted: the same path with its effort counted, or a refusal
        // when the budget is too small for it.
        let mut work = 0;
        assert_eq!(
            map.shortest_path_counted(a, b, &mut work, usize::MAX),
            Ok(path.clone())
        );
        assert!(work > 2, "{work}");
        let mut spent = 0;
        assert_eq!(
            map.shortest_path_counted(a, b, &mut spent, work / 2),
            Err(TransitError::OverBudget)
        );
        assert!(spent <= work, "{spent} > {work}");
        assert_relative_eq!(path[1].x, 20.5, epsilon = 1e-9);
        assert_relative_eq!(path[1].y, 50.0, epsilon = 1e-9);
        // Without the door there is no way out at all.
        let closed = MultiPolygon(vec![nfz.0[0].clone(), rect(0.0, 40.0, 40.0, 50.0)]);
        let map = ObstacleMap::new(&closed, 3.0);
        assert_eq!(
            map.shortest_path(a, b),
            Err(TransitError::NoPath { from: a, to: b })
        );
    }

    /// Reference: the full visibility graph over the same nodes (the bare
    /// corners if the pushed ones fail), built with the same segment test,
    /// and an O(V²) Dijkstra.
    fn brute_force(map: &ObstacleMap, a: Coord<f64>, b: Coord<f64>) -> Option<f64> {
        brute_force_on(map, &map.graph, a, b)
            .or_else(|| brute_force_on(map, map.bare.as_ref()?, a, b))
    }

    fn brute_force_on(
        map: &ObstacleMap,
        graph: &Graph,
        a: Coord<f64>,
        b: Coord<f64>,
    ) -> Option<f64> {
        let mut pts = graph.nodes.clone();
        pts.push(a);
        pts.push(b);
        let n = pts.len();
        let (s, t) = (n - 2, n - 1);
        let mut d = vec![f64::INFINITY; n];
        let mut done = vec![false; n];
        d[s] = 0.0;
        loop {
            let u = (0..n)
                .filter(|&i| !done[i] && d[i].is_finite())
                .min_by(|&i, &j| d[i].total_cmp(&d[j]))?;
            if u == t {
                return Some(d[t]);
            }
            done[u] = true;
            for v in 0..n {
                if !done[v] && map.is_clear(pts[u], pts[v]) {
                    d[v] = d[v].min(d[u] + dist(pts[u], pts[v]));
                }
            }
        }
    }

    /// Random star-shaped (often non-convex) polygons on a jittered grid.
    fn random_obstacles(rng: &mut Lcg, cells: usize, cell: f64) -> MultiPolygon<f64> {
        let mut polys = Vec::new();
        for i in 0..cells {
            for j in 0..cells {
                if rng.next() < 0.3 {
                    continue;
                }
                let cx = (i as f64 + 0.5) * cell + (rng.next() - 0.5) * 0.2 * cell;
                let cy = (j as f64 + 0.5) * cell + (rng.next() - 0.5) * 0.2 * cell;
                let k = 3 + (rng.next() * 6.0) as usize;
                let pts: Vec<(f64, f64)> = (0..k)
                    .map(|m| {
                        let ang = (m as f64 + 0.8 * rng.next()) / k as f64 * std::f64::consts::TAU;
                        let r = cell * (0.15 + 0.3 * rng.next());
                        (cx + r * ang.cos(), cy + r * ang.sin())
                    })
                    .collect();
                polys.push(Polygon::new(LineString::from(pts), vec![]));
            }
        }
        MultiPolygon(polys)
    }

    #[test]
    fn agrees_with_brute_force_on_random_obstacles() {
        let mut rng = Lcg(7);
        let mut compared = 0;
        for round in 0..12 {
            let obstacles = random_obstacles(&mut rng, 5, 20.0);
            let clearance = [0.0, 0.5, 2.0][round % 3];
            let mut map = ObstacleMap::new(&obstacles, clearance);
            // Also run the capped searches and the probe from the goal.
            map.probe_closed = [PROBE_CLOSED, 1, 4, 16][round % 4];
            for _ in 0..15 {
                let a = coord! { x: rng.next() * 100.0, y: rng.next() * 100.0 };
                let b = coord! { x: rng.next() * 100.0, y: rng.next() * 100.0 };
                if map.contains_point(a) || map.contains_point(b) {
                    continue;
                }
                let fast = map.shortest_path(a, b).ok();
                let reference = brute_force(&map, a, b);
                match (&fast, reference) {
                    (Some(path), Some(len)) => {
                        assert_relative_eq!(polyline_length(path), len, max_relative = 1e-9);
                        assert_eq!(path.first(), Some(&a));
                        assert_eq!(path.last(), Some(&b));
                        assert_path_clear(&map, path);
                    }
                    (None, None) => {}
                    _ => panic!("fast {fast:?} vs reference {reference:?} for {a:?} → {b:?}"),
                }
                compared += 1;
            }
        }
        assert!(compared > 100);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        #[test]
        fn random_paths_are_clear_and_no_longer_than_detours(
            seed in 0u64..10_000,
            ax in 0.0..100.0f64, ay in 0.0..100.0f64,
            bx in 0.0..100.0f64, by in 0.0..100.0f64,
        ) {
            let mut rng = Lcg(seed);
            let map = ObstacleMap::new(&random_obstacles(&mut rng, 4, 25.0), 1.0);
            let (a, b) = (coord! { x: ax, y: ay }, coord! { x: bx, y: by });
            proptest::prop_assume!(!map.contains_point(a) && !map.contains_point(b));
            let path = map.shortest_path(a, b).unwrap();
            for w in path.windows(2) {
                proptest::prop_assert!(map.is_clear(w[0], w[1]));
            }
            let len = polyline_length(&path);
            proptest::prop_assert!(len >= dist(a, b) - 1e-9);
            // Symmetric: the reverse query has the same length.
            let back = polyline_length(&map.shortest_path(b, a).unwrap());
            proptest::prop_assert!((len - back).abs() <= 1e-6 * len.max(1.0));
        }
    }
}

#[cfg(test)]
mod timing {
    //! `cargo test --release -p planner-core --lib flock::transit::timing -- --ignored --nocapture`
    use super::*;
    use crate::flock::test_support::{Lcg, octagon_field};
    use geo_types::{Polygon, coord};
    use std::time::Instant;

    #[test]
    #[ignore = "timing run, not a check"]
    fn large_field() {
        let mut rng = Lcg(11);
        let (cells, cell) = (32, 300.0);
        let mut polys = octagon_field(
            &mut rng,
            cells,
            cell,
            coord! { x: 500_000.0, y: 5_000_000.0 },
        );
        // A walled yard outside the field, for unreachable goals.
        polys.push(Polygon::new(
            LineString::from(vec![
                (489_000.0, 4_990_000.0),
                (489_100.0, 4_990_000.0),
                (489_100.0, 4_990_100.0),
                (489_000.0, 4_990_100.0),
            ]),
            vec![LineString::from(vec![
                (489_010.0, 4_990_010.0),
                (489_090.0, 4_990_010.0),
                (489_090.0, 4_990_090.0),
                (489_010.0, 4_990_090.0),
            ])],
        ));
        let t = Instant::now();
        let map = ObstacleMap::new(&MultiPolygon(polys), 2.0);
        println!(
            "build: {} obstacles, {} nodes in {:?}",
            map.obstacle_count(),
            map.node_count(),
            t.elapsed()
        );
        let side = cells as f64 * cell;
        let yard = coord! { x: 489_050.0, y: 4_990_050.0 };
        let t = Instant::now();
        for k in 0..20 {
            let a = coord! { x: 500_000.0 + side * (k as f64 + 0.5) / 20.0, y: 5_000_000.0 - 10.0 };
            assert!(map.shortest_path(a, yard).is_err());
            assert!(map.shortest_path(yard, a).is_err());
        }
        println!("40 unreachable goals in {:?}", t.elapsed());
        for (label, reach) in [("short (≤ 600 m)", 600.0), ("long (any)", side)] {
            let mut queries = Vec::new();
            while queries.len() < 1000 {
                let a =
                    coord! { x: 500_000.0 + rng.next() * side, y: 5_000_000.0 + rng.next() * side };
                let b = coord! {
                    x: (a.x + (rng.next() - 0.5) * 2.0 * reach).clamp(500_000.0, 500_000.0 + side),
                    y: (a.y + (rng.next() - 0.5) * 2.0 * reach).clamp(5_000_000.0, 5_000_000.0 + side),
                };
                if !map.contains_point(a) && !map.contains_point(b) {
                    queries.push((a, b));
                }
            }
            let t = Instant::now();
            let mut bent = 0;
            let mut worst = std::time::Duration::ZERO;
            for &(a, b) in &queries {
                let q = Instant::now();
                let path = map.shortest_path(a, b).expect("open field");
                worst = worst.max(q.elapsed());
                bent += usize::from(path.len() > 2);
            }
            println!(
                "{label}: {} queries ({bent} not direct) in {:?}, worst {:?}",
                queries.len(),
                t.elapsed(),
                worst
            );
        }
    }
}
