//! Segment tests against the obstacle edges: where a segment meets an edge
//! (a clean crossing or a touch) and whether its pieces between contacts lie
//! in the interior of the obstacles' union.

use geo::kernels::{Kernel, Orientation, RobustKernel};
use geo_types::Coord;
use rstar::{AABB, RTreeObject, SelectionFunction};

use super::{EPS, Edge, ObstacleMap, point_segment_distance};

/// Sideways probe distance used to tell an edge shared by two touching
/// obstacles (interior on both sides) from an outer boundary.
const SIDE_PROBE: f64 = 10.0 * EPS;

/// Length of the pieces a segment is checked in, metres, and most pieces.
const CHECK_PIECE_M: f64 = 25.0;
const MAX_CHECK_PIECES: usize = 128;

impl ObstacleMap {
    /// Does a segment piece with midpoint `m` and unit normal `normal` lie in
    /// the interior of the obstacles' union? Either `m` is strictly inside one
    /// obstacle, or it lies on a boundary with obstacle interior on both
    /// sides (an edge shared by touching obstacles).
    fn piece_blocked(&self, m: Coord<f64>, normal: Coord<f64>) -> bool {
        if self.contains_point(m) {
            return true;
        }
        let probe = normal * SIDE_PROBE;
        self.near_boundary(m, None) && self.inside_any(m + probe) && self.inside_any(m - probe)
    }

    /// Segment test. The segment is split at every contact with an obstacle
    /// edge and each piece's midpoint is tested for strict interior; a clean
    /// transversal crossing is an immediate "blocked". (A segment touching
    /// no edge still gets its midpoint tested: it may be a chord between two
    /// boundary points that rounding put a hair inside the obstacle.)
    pub(super) fn segment_clear(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        self.segment_check(a, b).is_ok()
    }

    /// [`ObstacleMap::segment_clear`], reporting on failure the edge that
    /// was crossed cleanly, if that is what blocked the segment.
    fn segment_check(&self, a: Coord<f64>, b: Coord<f64>) -> Result<(), Option<Edge>> {
        self.segment_check_counted(a, b, &mut 0)
    }

    /// [`ObstacleMap::segment_check`], adding the edges it tested to `work`.
    pub(super) fn segment_check_counted(
        &self,
        a: Coord<f64>,
        b: Coord<f64>,
        work: &mut usize,
    ) -> Result<(), Option<Edge>> {
        let d = b - a;
        let len = (d.x * d.x + d.y * d.y).sqrt();
        if len <= EPS {
            return if self.contains_point(a) {
                Err(None)
            } else {
                Ok(())
            };
        }
        let mut cuts: Vec<f64> = Vec::new();
        // The R-tree is walked piece by piece from `a`: a long segment
        // through a dense field is usually blocked near its start, and a
        // walk of the whole segment's box would visit most of the field
        // first. Every edge that meets the segment meets one of the pieces
        // (they share their ends exactly), so the answer is the same.
        let pieces = ((len / CHECK_PIECE_M).ceil() as usize).clamp(1, MAX_CHECK_PIECES);
        let mut from = a;
        for k in 1..=pieces {
            let to = if k == pieces {
                b
            } else {
                a + d * (k as f64 / pieces as f64)
            };
            let select = SegmentSelect { a: from, b: to };
            for edge in self.edge_tree.locate_with_selection_function(select) {
                *work += 1;
                match contact(a, b, len, edge.p, edge.q) {
                    Contact::None => {}
                    Contact::Crossing => return Err(Some(*edge)),
                    Contact::Touch(ts) => cuts.extend(ts.into_iter().flatten()),
                }
            }
            from = to;
        }
        cuts.push(0.0);
        cuts.push(1.0);
        cuts.sort_by(f64::total_cmp);
        let normal = Coord {
            x: -d.y / len,
            y: d.x / len,
        };
        let clear = cuts.windows(2).all(|w| {
            // Pieces shorter than the tolerance hug a contact point.
            (w[1] - w[0]) * len <= EPS || !self.piece_blocked(a + d * (0.5 * (w[0] + w[1])), normal)
        });
        if clear { Ok(()) } else { Err(None) }
    }
}

/// R-tree selection of edges whose (tolerance-inflated) box meets a segment.
struct SegmentSelect {
    a: Coord<f64>,
    b: Coord<f64>,
}

impl SelectionFunction<Edge> for SegmentSelect {
    fn should_unpack_parent(&self, envelope: &AABB<[f64; 2]>) -> bool {
        segment_meets_box(self.a, self.b, envelope)
    }

    fn should_unpack_leaf(&self, leaf: &Edge) -> bool {
        segment_meets_box(self.a, self.b, &leaf.envelope())
    }
}

/// How a segment `a`–`b` meets one obstacle edge `p`–`q`.
pub(super) enum Contact {
    None,
    /// Clean transversal crossing away from all four endpoints: the segment
    /// enters the obstacle interior next to the crossing.
    Crossing,
    /// Contact at up to three segment parameters (touching a vertex, running
    /// along the edge, or a crossing within tolerance of an endpoint).
    Touch([Option<f64>; 3]),
}

pub(super) fn contact(
    a: Coord<f64>,
    b: Coord<f64>,
    len: f64,
    p: Coord<f64>,
    q: Coord<f64>,
) -> Contact {
    let d = b - a;
    let param = |c: Coord<f64>| ((c - a).x * d.x + (c - a).y * d.y) / (len * len);
    let near_ab = |c: Coord<f64>| point_segment_distance(c, a, b) <= EPS;
    let touch_p = near_ab(p).then(|| param(p).clamp(0.0, 1.0));
    let touch_q = near_ab(q).then(|| param(q).clamp(0.0, 1.0));

    let side_p = RobustKernel::orient2d(a, b, p);
    let side_q = RobustKernel::orient2d(a, b, q);
    let side_a = RobustKernel::orient2d(p, q, a);
    let side_b = RobustKernel::orient2d(p, q, b);
    let strictly_apart = |s: Orientation, t: Orientation| {
        s != Orientation::Collinear && t != Orientation::Collinear && s != t
    };
    if strictly_apart(side_p, side_q) && strictly_apart(side_a, side_b) {
        let e = q - p;
        let denom = d.x * e.y - d.y * e.x;
        let t = (((p - a).x * e.y - (p - a).y * e.x) / denom).clamp(0.0, 1.0);
        let elen = (e.x * e.x + e.y * e.y).sqrt();
        let a_on_edge_line = ((a - p).x * e.y - (a - p).y * e.x).abs() / elen <= EPS;
        let b_on_edge_line = ((b - p).x * e.y - (b - p).y * e.x).abs() / elen <= EPS;
        let degenerate = touch_p.is_some()
            || touch_q.is_some()
            || (a_on_edge_line && b_on_edge_line)
            || t * len <= EPS
            || (1.0 - t) * len <= EPS;
        if !degenerate {
            return Contact::Crossing;
        }
        return Contact::Touch([Some(t), touch_p, touch_q]);
    }
    if touch_p.is_some() || touch_q.is_some() {
        Contact::Touch([None, touch_p, touch_q])
    } else {
        Contact::None
    }
}

/// Liang–Barsky clip of segment `a`–`b` against a box inflated by [`EPS`].
fn segment_meets_box(a: Coord<f64>, b: Coord<f64>, envelope: &AABB<[f64; 2]>) -> bool {
    let (lower, upper) = (envelope.lower(), envelope.upper());
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (start, delta, min, max) in [
        (a.x, b.x - a.x, lower[0] - EPS, upper[0] + EPS),
        (a.y, b.y - a.y, lower[1] - EPS, upper[1] + EPS),
    ] {
        if delta == 0.0 {
            if start < min || start > max {
                return false;
            }
        } else {
            let (mut ta, mut tb) = ((min - start) / delta, (max - start) / delta);
            if ta > tb {
                std::mem::swap(&mut ta, &mut tb);
            }
            t0 = t0.max(ta);
            t1 = t1.min(tb);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}
