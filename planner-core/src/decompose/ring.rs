//! Small ring utilities shared by the decomposition: shoelace area and the
//! clean-up that gives cells no duplicate or collinear consecutive vertices.

use geo_types::Coord;

/// Signed shoelace area of an open or closed ring (positive when CCW).
/// Coordinates are taken relative to the first vertex, which keeps the
/// products small when the ring is far from the origin.
pub(crate) fn signed_area(ring: &[Coord<f64>]) -> f64 {
    let Some(&first) = ring.first() else {
        return 0.0;
    };
    let mut twice = 0.0;
    for w in ring.windows(2) {
        let (a, b) = (w[0] - first, w[1] - first);
        twice += a.x * b.y - a.y * b.x;
    }
    // The closing edge (last → first) ends at the shifted origin, so its
    // cross product is zero: open and closed rings give the same sum.
    twice / 2.0
}

/// Removes the closing vertex and then, cyclically, every vertex that is
/// within `eps` of its predecessor or within `eps` of the line through its
/// two neighbours (which also removes zero-width spikes). Returns an open
/// ring; fewer than three vertices means nothing of it had any width.
pub(crate) fn clean_ring(points: &[Coord<f64>], eps: f64) -> Vec<Coord<f64>> {
    let mut out: Vec<Coord<f64>> = Vec::with_capacity(points.len());
    for &p in points {
        out.push(p);
        // A removal can make the previous triple degenerate, so repeat.
        loop {
            let n = out.len();
            if n >= 2 && near(out[n - 2], out[n - 1], eps) {
                out.pop();
            } else if n >= 3 && collinear(out[n - 3], out[n - 2], out[n - 1], eps) {
                out.remove(n - 2);
            } else {
                break;
            }
        }
    }
    // The same tests across the seam between the last and the first vertex.
    loop {
        let n = out.len();
        if n < 3 {
            break;
        }
        if near(out[n - 1], out[0], eps) || collinear(out[n - 2], out[n - 1], out[0], eps) {
            out.pop();
        } else if collinear(out[n - 1], out[0], out[1], eps) {
            out.remove(0);
        } else {
            break;
        }
    }
    out
}

fn near(a: Coord<f64>, b: Coord<f64>, eps: f64) -> bool {
    (a.x - b.x).abs() <= eps && (a.y - b.y).abs() <= eps
}

/// Whether `b` lies within `eps` of the line through `a` and `c`.
fn collinear(a: Coord<f64>, b: Coord<f64>, c: Coord<f64>, eps: f64) -> bool {
    let (u, v) = (c - a, b - a);
    let cross = u.x * v.y - u.y * v.x;
    cross.abs() <= eps * u.x.hypot(u.y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts(v: &[(f64, f64)]) -> Vec<Coord<f64>> {
        v.iter().map(|&(x, y)| Coord { x, y }).collect()
    }

    #[test]
    fn area_sign_follows_orientation() {
        let ccw = pts(&[(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (0.0, 1.0)]);
        assert_eq!(signed_area(&ccw), 2.0);
        let mut cw = ccw.clone();
        cw.reverse();
        assert_eq!(signed_area(&cw), -2.0);
        let mut closed = ccw.clone();
        closed.push(ccw[0]);
        assert_eq!(signed_area(&closed), 2.0);
        assert_eq!(signed_area(&[]), 0.0);
    }

    #[test]
    fn area_is_precise_far_from_origin() {
        let far = pts(&[
            (500_000.0, 5_000_000.0),
            (500_000.1, 5_000_000.0),
            (500_000.1, 5_000_000.1),
        ]);
        // Unshifted, the products of ~10¹² m² would leave errors of ~10⁻⁴ m².
        assert!((signed_area(&far) - 0.005).abs() < 1e-9);
    }

    #[test]
    fn removes_duplicates_collinear_and_closing_vertices() {
        let ring = pts(&[
            (0.0, 0.0),
            (1.0, 0.0),
            (1.0, 0.0),
            (2.0, 0.0),
            (2.0, 1.0),
            (1.0, 1.0),
            (0.0, 1.0),
            (0.0, 0.5),
            (0.0, 0.0),
        ]);
        assert_eq!(
            clean_ring(&ring, 1e-9),
            pts(&[(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (0.0, 1.0)])
        );
    }

    #[test]
    fn removes_spikes_and_keeps_real_corners() {
        // (3,0) is a zero-width spike going out and back along the bottom.
        let ring = pts(&[
            (0.0, 0.0),
            (2.0, 0.0),
            (3.0, 0.0),
            (2.0, 0.0),
            (2.0, 2.0),
            (0.0, 2.0),
        ]);
        let cleaned = clean_ring(&ring, 1e-9);
        assert_eq!(cleaned.len(), 4);
        assert!((signed_area(&cleaned) - 4.0).abs() < 1e-12);
        // A bend of 1e-6 is kept at eps 1e-9.
        let bent = pts(&[(0.0, 0.0), (1.0, 1e-6), (2.0, 0.0), (1.0, 1.0)]);
        assert_eq!(clean_ring(&bent, 1e-9).len(), 4);
    }

    #[test]
    fn degenerate_ring_collapses() {
        let flat = pts(&[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (1.0, 0.0)]);
        assert!(clean_ring(&flat, 1e-9).len() < 3);
        let point = pts(&[(1.0, 1.0), (1.0, 1.0), (1.0, 1.0)]);
        assert!(clean_ring(&point, 1e-9).len() < 3);
    }
}
