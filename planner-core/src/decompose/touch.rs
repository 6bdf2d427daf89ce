//! Makes every touch explicit: a vertex that lies on another edge (a hole
//! touching the outer ring mid-edge, two rings touching) is inserted into that
//! edge as well.
//!
//! Why: the sweep decides where a vertex lies relative to an edge by the
//! edge's y at the vertex's x. For an edge almost parallel to the slice that
//! value is extremely sensitive to x, so the rounding of the rotation can put
//! a touching vertex on either side of the edge, by far more than any
//! tolerance — and the rings appear to cross. Once the vertex is also a vertex
//! of the edge, the two meet exactly and no such evaluation is needed.

use geo_types::Coord;
use rstar::{AABB, RTree};

/// Inserts into each edge of `rings` every vertex of any ring that lies
/// within `eps` of the edge and more than `eps` from both its ends.
pub(crate) fn split_at_touches(rings: &mut [Vec<Coord<f64>>], eps: f64) {
    let points: Vec<[f64; 2]> = rings.iter().flatten().map(|c| [c.x, c.y]).collect();
    let tree = RTree::bulk_load(points);
    let mut on_edge: Vec<(f64, Coord<f64>)> = Vec::new();
    let mut pace = crate::cancel::Pacer::new(256);
    for ring in rings.iter_mut() {
        let n = ring.len();
        if n < 2 {
            continue;
        }
        let mut out = Vec::with_capacity(n);
        for k in 0..n {
            if pace.tick().is_err() {
                // Cancelled: the caller checks again and drops the rings.
                return;
            }
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            out.push(a);
            let d = b - a;
            let len = d.x.hypot(d.y);
            if len <= 2.0 * eps {
                continue;
            }
            let envelope = AABB::from_corners(
                [a.x.min(b.x) - eps, a.y.min(b.y) - eps],
                [a.x.max(b.x) + eps, a.y.max(b.y) + eps],
            );
            on_edge.clear();
            for &[x, y] in tree.locate_in_envelope(&envelope) {
                let v = Coord { x, y } - a;
                // Distance from the line and position along the edge.
                let off = (d.x * v.y - d.y * v.x).abs() / len;
                let along = (d.x * v.x + d.y * v.y) / len;
                if off <= eps && along > eps && along < len - eps {
                    on_edge.push((along, Coord { x, y }));
                }
            }
            on_edge.sort_by(|p, q| p.0.total_cmp(&q.0));
            on_edge.dedup_by(|p, q| p.1 == q.1);
            out.extend(on_edge.iter().map(|&(_, c)| c));
        }
        *ring = out;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(v: &[(f64, f64)]) -> Vec<Coord<f64>> {
        v.iter().map(|&(x, y)| Coord { x, y }).collect()
    }

    #[test]
    fn hole_vertex_on_the_outer_edge_is_inserted() {
        let mut rings = vec![
            ring(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]),
            ring(&[(1.0, 2.0), (3.0, 2.0), (2.0, 0.0)]),
        ];
        split_at_touches(&mut rings, 1e-9);
        assert_eq!(
            rings[0],
            ring(&[(0.0, 0.0), (2.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)])
        );
        assert_eq!(rings[1].len(), 3);
    }

    #[test]
    fn near_touch_within_eps_counts_and_beyond_does_not() {
        let mut rings = vec![
            ring(&[(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]),
            ring(&[(3.0, 1e-10), (4.0, 1.0), (3.0, 1.0)]),
            ring(&[(6.0, 1e-6), (7.0, 1.0), (6.0, 1.0)]),
        ];
        split_at_touches(&mut rings, 1e-9);
        assert_eq!(
            rings[0],
            ring(&[(0.0, 0.0), (3.0, 1e-10), (10.0, 0.0), (10.0, 10.0)])
        );
    }

    #[test]
    fn several_touches_are_inserted_in_order_once() {
        // Two rings share the vertex (5, 0); it is inserted once.
        let mut rings = vec![
            ring(&[(10.0, 0.0), (0.0, 0.0), (0.0, -5.0)]),
            ring(&[(5.0, 0.0), (6.0, 1.0), (5.0, 1.0)]),
            ring(&[(5.0, 0.0), (4.0, 2.0), (2.0, 0.0)]),
        ];
        split_at_touches(&mut rings, 1e-9);
        assert_eq!(
            rings[0],
            ring(&[(10.0, 0.0), (5.0, 0.0), (2.0, 0.0), (0.0, 0.0), (0.0, -5.0)])
        );
    }

    #[test]
    fn endpoints_and_far_vertices_are_left_alone() {
        let square = ring(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        let mut rings = vec![square.clone(), ring(&[(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)])];
        split_at_touches(&mut rings, 1e-9);
        assert_eq!(rings[0], square);
    }
}
