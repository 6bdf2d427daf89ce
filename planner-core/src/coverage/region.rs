//! Tolerant point and segment queries against a polygonal region.
//!
//! Lane end points and link corners are computed by intersecting lines with
//! polygon edges, so they lie *on* boundaries only up to rounding. Exact
//! predicates (DE-9IM `Relate`) would then flip between "touches" and
//! "crosses" at random; these queries instead treat everything within
//! [`EPS`] of the boundary as boundary, which counts as inside.

use geo_types::{Coord, LineString, MultiPolygon, Polygon};

/// Distance (metres) under which a point counts as lying on a boundary.
pub(crate) const EPS: f64 = 1e-6;

/// Where a point lies relative to a [`Region`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Position {
    Inside,
    Boundary,
    Outside,
}

/// The closed point set bounded by a set of rings (even-odd rule), as a flat
/// list of edges. Valid polygons and multipolygons give their usual interior.
#[derive(Clone, Debug)]
pub(crate) struct Region {
    edges: Vec<(Coord<f64>, Coord<f64>)>,
}

impl Region {
    pub(crate) fn from_polygon(polygon: &Polygon<f64>) -> Self {
        let mut edges = Vec::new();
        push_ring(&mut edges, polygon.exterior());
        for ring in polygon.interiors() {
            push_ring(&mut edges, ring);
        }
        Region { edges }
    }

    pub(crate) fn from_multi_polygon(mp: &MultiPolygon<f64>) -> Self {
        let mut edges = Vec::new();
        for polygon in mp {
            push_ring(&mut edges, polygon.exterior());
            for ring in polygon.interiors() {
                push_ring(&mut edges, ring);
            }
        }
        Region { edges }
    }

    /// Classifies `p`: within [`EPS`] of an edge is `Boundary`, otherwise the
    /// crossing-number test decides.
    pub(crate) fn position(&self, p: Coord<f64>) -> Position {
        let mut inside = false;
        for &(a, b) in &self.edges {
            if p.x >= a.x.min(b.x) - EPS
                && p.x <= a.x.max(b.x) + EPS
                && p.y >= a.y.min(b.y) - EPS
                && p.y <= a.y.max(b.y) + EPS
                && point_segment_distance(p, a, b) <= EPS
            {
                return Position::Boundary;
            }
            // Half-open rule: a vertex on the ray is counted exactly once.
            if (a.y > p.y) != (b.y > p.y) {
                let x = a.x + (p.y - a.y) / (b.y - a.y) * (b.x - a.x);
                if x > p.x {
                    inside = !inside;
                }
            }
        }
        if inside {
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
        let span = t1 - t0;
        if span.is_nan() || span <= EPS {
            let mid = o + d * ((t0 + t1) / 2.0);
            return if self.position(mid) == Position::Outside {
                Vec::new()
            } else {
                vec![(t0, t1)]
            };
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
        let mut out: Vec<(f64, f64)> = Vec::new();
        for w in cuts.windows(2) {
            let mid = o + d * ((w[0] + w[1]) / 2.0);
            if self.position(mid) == Position::Outside {
                continue;
            }
            match out.last_mut() {
                Some(last) if (w[0] - last.1).abs() <= EPS => last.1 = w[1],
                _ => out.push((w[0], w[1])),
            }
        }
        out
    }

    /// Whether the straight segment `a`–`b` stays in the closed region
    /// (touching or running along the boundary is fine).
    pub(crate) fn covers_segment(&self, a: Coord<f64>, b: Coord<f64>) -> bool {
        let len = (b.x - a.x).hypot(b.y - a.y);
        if len <= EPS {
            return self.position(a) != Position::Outside && self.position(b) != Position::Outside;
        }
        let d = (b - a) / len;
        match self.intervals(a, d, 0.0, len).as_slice() {
            [(s, e)] => *s <= EPS && *e >= len - EPS,
            _ => false,
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
        for &(a, b) in &self.edges {
            if a.x.max(b.x) < xmin
                || a.x.min(b.x) > xmax
                || a.y.max(b.y) < ymin
                || a.y.min(b.y) > ymax
            {
                continue;
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
        }
        out.retain(|t| *t >= t0 - EPS && *t <= t1 + EPS);
        out
    }
}

fn push_ring(edges: &mut Vec<(Coord<f64>, Coord<f64>)>, ring: &LineString<f64>) {
    let coords = &ring.0;
    if coords.len() < 2 {
        return;
    }
    for w in coords.windows(2) {
        if w[0] != w[1] {
            edges.push((w[0], w[1]));
        }
    }
    // Accept implicitly closed rings.
    let (first, last) = (coords[0], coords[coords.len() - 1]);
    if first != last {
        edges.push((last, first));
    }
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
mod tests {
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
}
