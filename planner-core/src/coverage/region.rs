//! Tolerant point and segment queries against a polygonal region.
//!
//! Lane end points and link corners are computed by intersecting lines with
//! polygon edges, so they lie *on* boundaries only up to rounding. Exact
//! predicates (DE-9IM `Relate`) would then flip between "touches" and
//! "crosses" at random; these queries instead treat everything within
//! [`EPS`] of the boundary as boundary, which counts as inside.

use geo_types::{Coord, LineString, MultiPolygon, Polygon};
use rstar::{AABB, RTree, RTreeObject, SelectionFunction};

/// Distance (metres) under which a point counts as lying on a boundary.
pub(crate) const EPS: f64 = 1e-6;

/// Regions with fewer edges than this are scanned edge by edge: an R-tree
/// does not pay for itself on a cell's handful of edges.
const INDEX_MIN_EDGES: usize = 32;

/// Free space (ROI minus NFZs) prepared for the coverage queries: its edges
/// go into an R-tree once, so clipping a lane or checking a link only looks
/// at the edges near it instead of every edge of every NFZ.
///
/// Build it once per survey and pass it to [`plan_cell_in`](super::plan_cell_in)
/// and [`CellPlan::reoriented_in`](super::CellPlan::reoriented_in); the
/// results are exactly those of [`plan_cell`](super::plan_cell) and
/// [`CellPlan::reoriented`](super::CellPlan::reoriented) with the same
/// multipolygon.
#[derive(Clone, Debug)]
pub struct FreeSpace {
    region: Region,
}

impl FreeSpace {
    /// Prepares `free` (the free space, ROI minus NFZs, in UTM metres).
    pub fn new(free: &MultiPolygon<f64>) -> Self {
        FreeSpace {
            region: Region::from_multi_polygon(free).indexed(),
        }
    }

    /// The same free space without an index: every query scans all edges
    /// (the reference the indexed queries are tested against).
    #[cfg(test)]
    pub(crate) fn unindexed(free: &MultiPolygon<f64>) -> Self {
        FreeSpace {
            region: Region::from_multi_polygon(free),
        }
    }

    pub(crate) fn region(&self) -> &Region {
        &self.region
    }
}

/// Where a point lies relative to a [`Region`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Position {
    Inside,
    Boundary,
    Outside,
}

/// One boundary edge, from `a` to `b`.
#[derive(Clone, Copy, Debug)]
struct Edge {
    a: Coord<f64>,
    b: Coord<f64>,
}

/// An edge in the R-tree, with the index of its ring in [`Region::rings`].
#[derive(Clone, Copy, Debug)]
struct TreeEdge {
    edge: Edge,
    ring: usize,
}

impl RTreeObject for TreeEdge {
    type Envelope = AABB<[f64; 2]>;

    fn envelope(&self) -> Self::Envelope {
        let Edge { a, b } = self.edge;
        AABB::from_corners([a.x, a.y], [b.x, b.y])
    }
}

/// R-tree over a region's edges. Queries only prune: every edge they return
/// still goes through the same exact test as in a full scan, and the query
/// windows are widened by [`EdgeIndex::margin`] so that no edge the full
/// scan would accept can be pruned by rounding. Indexed and unindexed
/// queries therefore give identical results.
#[derive(Clone, Debug)]
struct EdgeIndex {
    tree: RTree<TreeEdge>,
    /// Bounding boxes of the rings, for the crossing-number test.
    rings: RTree<RingBox>,
    /// Largest coordinate magnitude of any edge.
    scale: f64,
}

impl EdgeIndex {
    /// Slack added to query windows: far above the rounding error of the
    /// exact tests at the coordinates involved, and far below anything that
    /// would make a query look at many more edges.
    fn margin(&self, magnitude: f64) -> f64 {
        1e-3 + 1e-12 * (self.scale + magnitude)
    }
}

/// Bounding box of ring `id`.
#[derive(Clone, Copy, Debug)]
struct RingBox {
    id: usize,
    lower: [f64; 2],
    upper: [f64; 2],
}

impl RTreeObject for RingBox {
    type Envelope = AABB<[f64; 2]>;

    fn envelope(&self) -> Self::Envelope {
        AABB::from_corners(self.lower, self.upper)
    }
}

/// Rings with more edges than this are searched through the edge R-tree in
/// the crossing-number test rather than scanned.
const SCAN_RING_MAX_EDGES: usize = 64;

/// Window of an indexed query: an axis-aligned box and, optionally, the
/// line `o + t·d` the wanted edges must come within `reach` of.
struct Query {
    lower: [f64; 2],
    upper: [f64; 2],
    line: Option<(Coord<f64>, Coord<f64>, f64)>,
}

impl Query {
    /// Whether something inside `envelope` may be wanted. NaN anywhere
    /// makes every comparison false, which keeps the envelope (a full scan
    /// rather than a wrong answer).
    fn accepts(&self, envelope: &AABB<[f64; 2]>) -> bool {
        let (lo, hi) = (envelope.lower(), envelope.upper());
        if lo[0] > self.upper[0]
            || hi[0] < self.lower[0]
            || lo[1] > self.upper[1]
            || hi[1] < self.lower[1]
        {
            return false;
        }
        if let Some((o, d, reach)) = self.line {
            // The box lies wholly on one side of the line, farther than
            // `reach`: so does every edge in it (the signed distance is
            // linear, so its extremes over the box are at the corners).
            let s = [
                [lo[0], lo[1]],
                [hi[0], lo[1]],
                [lo[0], hi[1]],
                [hi[0], hi[1]],
            ]
            .map(|[x, y]| cross(d, Coord { x, y } - o));
            if s.iter().all(|v| *v > reach) || s.iter().all(|v| *v < -reach) {
                return false;
            }
        }
        true
    }
}

impl SelectionFunction<TreeEdge> for Query {
    fn should_unpack_parent(&self, envelope: &AABB<[f64; 2]>) -> bool {
        self.accepts(envelope)
    }

    fn should_unpack_leaf(&self, _leaf: &TreeEdge) -> bool {
        // Callers run their exact per-edge test (which starts with the
        // same box check) on every returned edge anyway.
        true
    }
}

/// The closed point set bounded by a set of rings (even-odd rule), as a flat
/// list of edges. Valid polygons and multipolygons give their usual interior.
#[derive(Clone, Debug)]
pub(crate) struct Region {
    edges: Vec<Edge>,
    /// Each ring's edges, as a range of `edges`.
    rings: Vec<std::ops::Range<usize>>,
    /// Present for large regions (see [`Region::indexed`]).
    index: Option<EdgeIndex>,
}

impl Region {
    pub(crate) fn from_polygon(polygon: &Polygon<f64>) -> Self {
        Self::from_polygons(std::iter::once(polygon))
    }

    pub(crate) fn from_multi_polygon(mp: &MultiPolygon<f64>) -> Self {
        Self::from_polygons(mp)
    }

    fn from_polygons<'a>(polygons: impl IntoIterator<Item = &'a Polygon<f64>>) -> Self {
        let (mut edges, mut rings) = (Vec::new(), Vec::new());
        for polygon in polygons {
            push_ring(&mut edges, &mut rings, polygon.exterior());
            for ring in polygon.interiors() {
                push_ring(&mut edges, &mut rings, ring);
            }
        }
        Region {
            edges,
            rings,
            index: None,
        }
    }

    /// The same region with an R-tree over its edges, if it has enough of
    /// them and all are finite (otherwise queries keep scanning every edge).
    pub(crate) fn indexed(mut self) -> Self {
        let finite = |c: Coord<f64>| c.x.is_finite() && c.y.is_finite();
        if self.edges.len() < INDEX_MIN_EDGES
            || !self.edges.iter().all(|e| finite(e.a) && finite(e.b))
        {
            self.index = None;
            return self;
        }
        let mut scale = 0.0f64;
        let mut boxes = Vec::with_capacity(self.rings.len());
        for (id, range) in self.rings.iter().enumerate() {
            let (mut lower, mut upper) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for e in &self.edges[range.clone()] {
                for c in [e.a, e.b] {
                    lower = [lower[0].min(c.x), lower[1].min(c.y)];
                    upper = [upper[0].max(c.x), upper[1].max(c.y)];
                    scale = scale.max(c.x.abs()).max(c.y.abs());
                }
            }
            if !range.is_empty() {
                boxes.push(RingBox { id, lower, upper });
            }
        }
        self.index = Some(EdgeIndex {
            tree: RTree::bulk_load(
                self.rings
                    .iter()
                    .enumerate()
                    .flat_map(|(ring, range)| {
                        self.edges[range.clone()]
                            .iter()
                            .map(move |&edge| TreeEdge { edge, ring })
                    })
                    .collect(),
            ),
            rings: RTree::bulk_load(boxes),
            scale,
        });
        self
    }

    /// Classifies `p`: within [`EPS`] of an edge is `Boundary`, otherwise the
    /// crossing-number test decides.
    pub(crate) fn position(&self, p: Coord<f64>) -> Position {
        let Some(index) = &self.index else {
            let mut inside = false;
            for e in &self.edges {
                if near_edge(p, e) {
                    return Position::Boundary;
                }
                if crosses_ray(p, e) {
                    inside = !inside;
                }
            }
            return if inside {
                Position::Inside
            } else {
                Position::Outside
            };
        };
        // Same answer as the scan above: `Boundary` if any edge is near,
        // else the parity of the crossings (both independent of the order
        // in which edges are seen).
        let m = index.margin(p.x.abs() + p.y.abs());
        let r = EPS + m;
        let near = Query {
            lower: [p.x - r, p.y - r],
            upper: [p.x + r, p.y + r],
            line: None,
        };
        if index
            .tree
            .locate_with_selection_function(near)
            .any(|e| near_edge(p, &e.edge))
        {
            return Position::Boundary;
        }
        // Crossings per ring. A ring whose box (widened by the margin)
        // misses `p` adds an even number: none if it lies above, below or
        // west of `p`; if it lies east, every edge straddling the ray's
        // height crosses it, and a closed ring has an even number of those.
        let at = AABB::from_corners([p.x - m, p.y - m], [p.x + m, p.y + m]);
        let mut crossings = 0;
        for ring in index.rings.locate_in_envelope_intersecting(&at) {
            let edges = &self.edges[self.rings[ring.id].clone()];
            crossings += if edges.len() <= SCAN_RING_MAX_EDGES {
                edges.iter().filter(|e| crosses_ray(p, e)).count()
            } else {
                // A crossing lies on the edge (up to rounding), east of `p`.
                let ray = Query {
                    lower: [p.x - m, p.y - m],
                    upper: [ring.upper[0] + m, p.y + m],
                    line: None,
                };
                index
                    .tree
                    .locate_with_selection_function(ray)
                    .filter(|e| e.ring == ring.id && crosses_ray(p, &e.edge))
                    .count()
            };
        }
        if crossings % 2 == 1 {
            Position::Inside
        } else {
            Position::Outside
        }
    }
    /// The parts of the segment `o + t·d`, `t ∈ [t0, t1]` (`d` a unit vector)
    /// that lie in the closed region, as sorted, disjoint parameter intervals.
    /// Pieces running along the boundary count as inside; adjacent inside
    /// pieces are merged, so an interval ends only where the segment leaves.
    pub(crate) fn intervals(
        &self,
        o: Coord<f64>,
        d: Coord<f64>,
        t0: f64,
        t1: f64,
    ) -> Vec<(f64, f64)> {
        let Some(cuts) = self.pieces(o, d, t0, t1) else {
            return if self.inside_at(o, d, (t0 + t1) / 2.0) {
                vec![(t0, t1)]
            } else {
                Vec::new()
            };
        };
        let mut out: Vec<(f64, f64)> = Vec::new();
        for w in cuts.windows(2) {
            if !self.inside_at(o, d, (w[0] + w[1]) / 2.0) {
                continue;
            }
            match out.last_mut() {
                Some(last) if (w[0] - last.1).abs() <= EPS => last.1 = w[1],
                _ => out.push((w[0], w[1])),
            }
        }
        out
    }

    /// The first of [`Region::intervals`]`(o, d, t0, t1)` that comes within
    /// [`EPS`] of `t`, found by classifying only the pieces around `t`
    /// instead of every piece of the segment: a lane across a field of
    /// thousands of NFZs is cut hundreds of times, and each piece's test
    /// walks a ray across the field.
    pub(crate) fn interval_around(
        &self,
        o: Coord<f64>,
        d: Coord<f64>,
        (t0, t1): (f64, f64),
        t: f64,
    ) -> Option<(f64, f64)> {
        let Some(cuts) = self.pieces(o, d, t0, t1) else {
            let hit = t0 <= t + EPS && t1 >= t - EPS;
            return (hit && self.inside_at(o, d, (t0 + t1) / 2.0)).then_some((t0, t1));
        };
        let pieces = cuts.len() - 1;
        let inside = |k: usize| self.inside_at(o, d, (cuts[k] + cuts[k + 1]) / 2.0);
        // Pieces ending before `t − EPS` belong to runs that cannot reach
        // `t`; of the pieces from there that start by `t + EPS`, the first
        // inside one lies in the wanted run (any earlier run reaching `t`
        // would hold one of the pieces already seen to be outside).
        let first = cuts[1..].partition_point(|&c| c < t - EPS);
        let k = (first..pieces)
            .take_while(|&k| cuts[k] <= t + EPS)
            .find(|&k| inside(k))?;
        let (mut lo, mut hi) = (k, k);
        while lo > 0 && inside(lo - 1) {
            lo -= 1;
        }
        while hi + 1 < pieces && inside(hi + 1) {
            hi += 1;
        }
        Some((cuts[lo], cuts[hi + 1]))
    }

    /// Whether `o + t·d` is in the closed region.
    fn inside_at(&self, o: Coord<f64>, d: Coord<f64>, t: f64) -> bool {
        self.position(o + d * t) != Position::Outside
    }

    /// The cut parameters of `[t0, t1]` where the segment meets the
    /// boundary, sorted and at least [`EPS`] apart, starting at `t0` and
    /// ending at `t1`: consecutive ones bound a piece that is wholly inside
    /// or wholly outside. `None` for a segment no longer than `EPS`.
    fn pieces(&self, o: Coord<f64>, d: Coord<f64>, t0: f64, t1: f64) -> Option<Vec<f64>> {
        let span = t1 - t0;
        if span.is_nan() || span <= EPS {
            return None;
        }
        let mut cuts = self.cuts(o, d, t0, t1);
        cuts.push(t0);
        cuts.push(t1);
        cuts.retain(|t| *t >= t0 && *t <= t1);
        cuts.sort_by(f64::total_cmp);
        cuts.dedup_by(|b, a| *b - *a <= EPS);
        // dedup keeps the first of a run; make sure the segment ends at t1.
        if let Some(last) = cuts.last_mut() {
            *last = t1;
        }
        Some(cuts)
    }

    /// Whether the straight segment `a`–`b` stays in the closed region
    /// (touching or running along the boundary is fine).
    pub(crate) fn covers_segment(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        let len = (b.x - a.x).hypot(b.y - a.y);
        if len <= EPS {
            return self.position(a) != Position::Outside && self.position(b) != Position::Outside;
        }
        let d = (b - a) / len;
        // Every piece from 0 to `len` inside: one interval covering it all.
        match self.pieces(a, d, 0.0, len) {
            Some(cuts) => cuts
                .windows(2)
                .all(|w| self.inside_at(a, d, (w[0] + w[1]) / 2.0)),
            None => self.inside_at(a, d, len / 2.0),
        }
    }

    /// Parameters `t ∈ [t0 − EPS, t1 + EPS]` where the line `o + t·d` meets an
    /// edge (both end points of an edge lying along the line).
    fn cuts(&self, o: Coord<f64>, d: Coord<f64>, t0: f64, t1: f64) -> Vec<f64> {
        let p0 = o + d * t0;
        let p1 = o + d * t1;
        let (xmin, xmax) = (p0.x.min(p1.x) - EPS, p0.x.max(p1.x) + EPS);
        let (ymin, ymax) = (p0.y.min(p1.y) - EPS, p0.y.max(p1.y) + EPS);
        let mut out = Vec::new();
        let mut cut = |e: &Edge| {
            let (a, b) = (e.a, e.b);
            if a.x.max(b.x) < xmin
                || a.x.min(b.x) > xmax
                || a.y.max(b.y) < ymin
                || a.y.min(b.y) > ymax
            {
                return;
            }
            // Signed distances of the edge's ends from the line.
            let sa = cross(d, a - o);
            let sb = cross(d, b - o);
            let ta = dot(d, a - o);
            let tb = dot(d, b - o);
            if sa.abs() <= EPS {
                out.push(ta);
            }
            if sb.abs() <= EPS {
                out.push(tb);
            }
            if (sa > EPS && sb < -EPS) || (sa < -EPS && sb > EPS) {
                out.push(ta + (tb - ta) * sa / (sa - sb));
            }
        };
        match &self.index {
            None => self.edges.iter().for_each(&mut cut),
            Some(index) => {
                // Only edges in the segment's box and not wholly on one side
                // of its line can add a cut. The order of the cuts differs
                // from a full scan, but callers sort them.
                let magnitude = [p0, p1, o]
                    .iter()
                    .map(|c| c.x.abs().max(c.y.abs()))
                    .fold(0.0, f64::max);
                let m = index.margin(magnitude);
                let query = Query {
                    lower: [xmin - m, ymin - m],
                    upper: [xmax + m, ymax + m],
                    line: Some((o, d, EPS + m)),
                };
                index
                    .tree
                    .locate_with_selection_function(query)
                    .for_each(|e| cut(&e.edge));
            }
        }
        out.retain(|t| *t >= t0 - EPS && *t <= t1 + EPS);
        out
    }
}

/// Whether `p` is within [`EPS`] of the edge (the boundary test of
/// [`Region::position`]).
fn near_edge(p: Coord<f64>, e: &Edge) -> bool {
    let (a, b) = (e.a, e.b);
    p.x >= a.x.min(b.x) - EPS
        && p.x <= a.x.max(b.x) + EPS
        && p.y >= a.y.min(b.y) - EPS
        && p.y <= a.y.max(b.y) + EPS
        && point_segment_distance(p, a, b) <= EPS
}

/// Whether the edge crosses the ray from `p` towards +x. Half-open rule: a
/// vertex on the ray is counted exactly once.
fn crosses_ray(p: Coord<f64>, e: &Edge) -> bool {
    let (a, b) = (e.a, e.b);
    if (a.y > p.y) != (b.y > p.y) {
        let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
        x > p.x
    } else {
        false
    }
}

fn push_ring(
    edges: &mut Vec<Edge>,
    rings: &mut Vec<std::ops::Range<usize>>,
    ring: &LineString<f64>,
) {
    let coords = &ring.0;
    if coords.len() < 2 {
        return;
    }
    let start = edges.len();
    for w in coords.windows(2) {
        if w[0] != w[1] {
            edges.push(Edge { a: w[0], b: w[1] });
        }
    }
    // Accept implicitly closed rings.
    let (first, last) = (coords[0], coords[coords.len() - 1]);
    if first != last {
        edges.push(Edge { a: last, b: first });
    }
    rings.push(start..edges.len());
}

/// A finite number greater than zero (false for NaN).
pub(crate) fn is_positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

pub(crate) fn dot(a: Coord<f64>, b: Coord<f64>) -> f64 {
    a.x * b.x + a.y * b.y
}

pub(crate) fn cross(a: Coord<f64>, b: Coord<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

pub(crate) fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// Closest point to `p` on the segment `a`–`b`, with its parameter in [0, 1].
pub(crate) fn closest_on_segment(p: Coord<f64>, a: Coord<f64>, b: Coord<f64>) -> (Coord<f64>, f64) {
    let ab = b - a;
    let len2 = dot(ab, ab);
    if len2 == 0.0 {
        return (a, 0.0);
    }
    let t = (dot(p - a, ab) / len2).clamp(0.0, 1.0);
    (a + ab * t, t)
}

pub(crate) fn point_segment_distance(p: Coord<f64>, a: Coord<f64>, b: Coord<f64>) -> f64 {
    dist(p, closest_on_segment(p, a, b).0)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use geo_types::{coord, polygon};

    fn square_with_hole() -> Polygon<f64> {
        polygon!(
            exterior: [(x: 0., y: 0.), (x: 10., y: 0.), (x: 10., y: 10.), (x: 0., y: 10.)],
            interiors: [[(x: 4., y: 4.), (x: 6., y: 4.), (x: 6., y: 6.), (x: 4., y: 6.)]],
        )
    }

    #[test]
    fn positions() {
        let r = Region::from_polygon(&square_with_hole());
        assert_eq!(r.position(coord! { x: 1., y: 1. }), Position::Inside);
        assert_eq!(r.position(coord! { x: 5., y: 5. }), Position::Outside);
        assert_eq!(r.position(coord! { x: 11., y: 5. }), Position::Outside);
        assert_eq!(r.position(coord! { x: 10., y: 5. }), Position::Boundary);
        assert_eq!(
            r.position(coord! { x: 4., y: 5. + 1e-9 }),
            Position::Boundary
        );
        // A vertex at the ray's height is counted once.
        assert_eq!(r.position(coord! { x: 2., y: 4. }), Position::Inside);
        assert_eq!(r.position(coord! { x: -1., y: 0. }), Position::Outside);
    }

    #[test]
    fn intervals_across_a_hole() {
        let r = Region::from_polygon(&square_with_hole());
        let iv = r.intervals(coord! { x: -5., y: 5. }, coord! { x: 1., y: 0. }, 0.0, 20.0);
        assert_eq!(iv.len(), 2);
        approx::assert_abs_diff_eq!(iv[0].0, 5.0, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(iv[0].1, 9.0, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(iv[1].0, 11.0, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(iv[1].1, 15.0, epsilon = 1e-9);
        // Along the hole's edge: boundary counts as inside, so one interval.
        let iv = r.intervals(coord! { x: -5., y: 4. }, coord! { x: 1., y: 0. }, 0.0, 20.0);
        assert_eq!(iv.len(), 1);
        approx::assert_abs_diff_eq!(iv[0].0, 5.0, epsilon = 1e-9);
        approx::assert_abs_diff_eq!(iv[0].1, 15.0, epsilon = 1e-9);
    }

    #[test]
    fn segment_cover() {
        let r = Region::from_polygon(&square_with_hole());
        assert!(r.covers_segment(coord! { x: 1., y: 1. }, coord! { x: 9., y: 2. }));
        assert!(!r.covers_segment(coord! { x: 1., y: 5. }, coord! { x: 9., y: 5. }));
        // Along the outer boundary and along the hole's boundary.
        assert!(r.covers_segment(coord! { x: 0., y: 0. }, coord! { x: 10., y: 0. }));
        assert!(r.covers_segment(coord! { x: 4., y: 4. }, coord! { x: 6., y: 4. }));
        // Leaving the square.
        assert!(!r.covers_segment(coord! { x: 1., y: 1. }, coord! { x: 12., y: 1. }));
        // Corner to corner through the hole's corner only touches it.
        assert!(r.covers_segment(coord! { x: 0., y: 0. }, coord! { x: 4., y: 4. }));
        assert!(!r.covers_segment(coord! { x: 0., y: 0. }, coord! { x: 10., y: 10. }));
    }

    #[test]
    fn multipolygon_gap() {
        let mp = MultiPolygon(vec![
            polygon![(x: 0., y: 0.), (x: 2., y: 0.), (x: 2., y: 2.), (x: 0., y: 2.)],
            polygon![(x: 3., y: 0.), (x: 5., y: 0.), (x: 5., y: 2.), (x: 3., y: 2.)],
        ]);
        let r = Region::from_multi_polygon(&mp);
        assert!(!r.covers_segment(coord! { x: 1., y: 1. }, coord! { x: 4., y: 1. }));
        assert!(r.covers_segment(coord! { x: 3.5, y: 1. }, coord! { x: 4., y: 1. }));
    }

    /// Free space of a UTM-sized field with `n` octagonal NFZs on a jittered
    /// grid; some overlap each other or the ROI border.
    pub(crate) fn field_with_nfzs(n: usize) -> MultiPolygon<f64> {
        let (x0, y0, side) = (480_000.0, 5_200_000.0, 1500.0);
        let mut seed = 7u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let per_row = (n as f64).sqrt().ceil() as usize;
        let pitch = side / per_row as f64;
        let nfz: Vec<Polygon<f64>> = (0..n)
            .map(|i| {
                let (r, c) = (i / per_row, i % per_row);
                let radius = pitch * (0.2 + 0.4 * rnd());
                let cx = x0 + (c as f64 + rnd()) * pitch;
                let cy = y0 + (r as f64 + rnd()) * pitch;
                let rot = rnd();
                let ring: Vec<Coord<f64>> = (0..8)
                    .map(|k| {
                        let t = (k as f64 + rot) * std::f64::consts::TAU / 8.0;
                        coord! { x: cx + radius * t.cos(), y: cy + radius * t.sin() }
                    })
                    .collect();
                Polygon::new(ring.into(), vec![])
            })
            .collect();
        let roi = polygon![
            (x: x0, y: y0), (x: x0 + side, y: y0),
            (x: x0 + side, y: y0 + side), (x: x0, y: y0 + side),
        ];
        crate::decompose::free_space(&roi, &nfz)
    }

    #[test]
    fn indexed_queries_match_full_scan() {
        assert_same_answers(&field_with_nfzs(120));
        // A curved outline (one ring larger than SCAN_RING_MAX_EDGES) with
        // holes, around the same origin.
        let (cx, cy) = (480_750.0, 5_200_750.0);
        let ngon = |r: f64, k: usize, x: f64, y: f64| -> LineString<f64> {
            (0..k)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / k as f64;
                    coord! { x: x + r * a.cos(), y: y + r * a.sin() }
                })
                .collect()
        };
        let holes = (0..30)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / 30.0;
                ngon(40.0, 6, cx + 500.0 * a.cos(), cy + 500.0 * a.sin())
            })
            .collect();
        let curved = MultiPolygon(vec![Polygon::new(ngon(760.0, 300, cx, cy), holes)]);
        let r = Region::from_multi_polygon(&curved);
        assert!(r.rings.iter().any(|x| x.len() > SCAN_RING_MAX_EDGES));
        assert_same_answers(&curved);
    }

    fn assert_same_answers(free: &MultiPolygon<f64>) {
        let plain = Region::from_multi_polygon(free);
        let indexed = Region::from_multi_polygon(free).indexed();
        assert!(indexed.index.is_some() && plain.index.is_none());
        assert!(plain.edges.len() > 300, "{}", plain.edges.len());
        // Probe points: vertices, edge midpoints, points just off edges
        // (inside and outside EPS), and a grid over the whole field.
        let mut points = Vec::new();
        for e in &plain.edges {
            let mid = (e.a + e.b) / 2.0;
            let len = dist(e.a, e.b);
            let normal = coord! { x: -(e.b.y - e.a.y) / len, y: (e.b.x - e.a.x) / len };
            points.extend([e.a, mid]);
            for off in [0.5 * EPS, 2.0 * EPS, 0.01, -0.5 * EPS, -2.0 * EPS, -0.01] {
                points.push(mid + normal * off);
            }
        }
        let (x0, y0) = (480_000.0 - 50.0, 5_200_000.0 - 50.0);
        for i in 0..=40 {
            for j in 0..=40 {
                points.push(coord! { x: x0 + 40.0 * i as f64, y: y0 + 40.0 * j as f64 });
            }
        }
        let mut kinds = [0usize; 3];
        for &p in &points {
            let pos = plain.position(p);
            assert_eq!(indexed.position(p), pos, "{p:?}");
            kinds[pos as usize] += 1;
        }
        assert!(kinds.iter().all(|k| *k > 100), "{kinds:?}");
        // Segments: along edges, vertex to vertex, between probe points at
        // many angles (axis-aligned ones run through vertices).
        let mut segments: Vec<(Coord<f64>, Coord<f64>)> =
            plain.edges.iter().map(|e| (e.a, e.b)).collect();
        let verts: Vec<Coord<f64>> = plain.edges.iter().map(|e| e.a).collect();
        for k in 0..verts.len() {
            let a = verts[k];
            for step in [1, 7, 31, 97] {
                segments.push((a, verts[(k * 13 + step) % verts.len()]));
            }
            segments.push((a, a + coord! { x: 300.0, y: 0.0 }));
            segments.push((a - coord! { x: 0.0, y: 250.0 }, a));
        }
        for w in points.chunks(3) {
            if let [a, _, b] = w {
                segments.push((*a, *b));
            }
        }
        let mut cut = 0;
        for &(a, b) in &segments {
            assert_eq!(
                indexed.covers_segment(a, b),
                plain.covers_segment(a, b),
                "{a:?} {b:?}"
            );
            let len = dist(a, b);
            if len > 0.0 {
                let d = (b - a) / len;
                let iv = plain.intervals(a, d, -1.0, len + 1.0);
                assert_eq!(indexed.intervals(a, d, -1.0, len + 1.0), iv, "{a:?} {b:?}");
                cut += usize::from(iv.len() > 1);
                // The run around one parameter, found without classifying
                // every piece, is the one `intervals` gives; so is the
                // early-exit cover test.
                let ends = iv
                    .iter()
                    .flat_map(|&(s, e)| [s, e, s - 2.0 * EPS, e + 0.5 * EPS]);
                for t in [-1.0, 0.0, len / 3.0, len / 2.0, len]
                    .into_iter()
                    .chain(ends)
                {
                    let want = iv
                        .iter()
                        .copied()
                        .find(|&(s, e)| s <= t + EPS && e >= t - EPS);
                    let range = (-1.0, len + 1.0);
                    assert_eq!(
                        indexed.interval_around(a, d, range, t),
                        want,
                        "{a:?} {b:?} {t}"
                    );
                    assert_eq!(
                        plain.interval_around(a, d, range, t),
                        want,
                        "{a:?} {b:?} {t}"
                    );
                }
                let whole = plain.intervals(a, d, 0.0, len);
                let covered = matches!(whole.as_slice(), [(s, e)] if *s <= EPS && *e >= len - EPS);
                assert_eq!(plain.covers_segment(a, b), covered, "{a:?} {b:?}");
            }
        }
        assert!(cut > 100, "{cut}");
    }

    #[test]
    fn small_or_non_finite_regions_are_not_indexed() {
        assert!(
            Region::from_polygon(&square_with_hole())
                .indexed()
                .index
                .is_none()
        );
        let nan = polygon![(x: 0., y: 0.), (x: f64::NAN, y: 0.), (x: 1., y: 1.)];
        let many = MultiPolygon(vec![nan; 20]);
        let r = Region::from_multi_polygon(&many).indexed();
        assert!(r.index.is_none());
        assert_eq!(r.position(coord! { x: 0.5, y: 0.2 }), Position::Outside);
    }
}
