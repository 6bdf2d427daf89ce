//! Test helpers: polygon builders and a check of every output invariant of
//! SPEC §3.2, so each unit test states its expectations on top of them.

use geo::{Area, BooleanOps, BoundingRect, Intersects, Validation, Winding, unary_union};
use geo_types::{Coord, LineString, MultiPolygon, Polygon};

/// The CCW rectangle [x0, x1] × [y0, y1].
pub(crate) fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
    poly(&[(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
}

/// A polygon without holes from its vertices.
pub(crate) fn poly(v: &[(f64, f64)]) -> Polygon<f64> {
    Polygon::new(LineString::from(v.to_vec()), vec![])
}

/// Panics unless `cells` is a valid boustrophedon decomposition of `free`
/// for slice lines of bearing `slice_angle_deg`.
pub(crate) fn assert_valid_decomposition(
    free: &MultiPolygon<f64>,
    cells: &[Polygon<f64>],
    slice_angle_deg: f64,
) {
    let free_area = free.unsigned_area();
    let bbox = free.bounding_rect().expect("free space is not empty");
    let size = bbox.width().max(bbox.height());
    let (s, c) = slice_angle_deg.to_radians().sin_cos();
    // Position across the slice lines; slice lines are its level sets.
    let h = |p: Coord<f64>| p.x * c - p.y * s;

    for (i, cell) in cells.iter().enumerate() {
        assert!(cell.interiors().is_empty(), "cell {i} has holes");
        let ring = &cell.exterior().0;
        assert!(ring.len() >= 4, "cell {i} has too few vertices: {cell:?}");
        assert_eq!(ring.first(), ring.last(), "cell {i} is not closed");
        assert!(cell.exterior().is_ccw(), "cell {i} is not CCW: {cell:?}");
        assert!(
            cell.is_valid(),
            "cell {i} is invalid: {:?}: {cell:?}",
            cell.validation_errors()
        );
        let open = &ring[..ring.len() - 1];
        let n = open.len();
        for k in 0..n {
            let (a, b, d) = (open[k], open[(k + 1) % n], open[(k + 2) % n]);
            assert_ne!(a, b, "cell {i} repeats a vertex");
            let (u, v) = (d - a, b - a);
            let dist = (u.x * v.y - u.y * v.x).abs() / u.x.hypot(u.y);
            assert!(
                dist > 1e-12 * size,
                "cell {i}: {b:?} is collinear with its neighbours"
            );
        }
        // Monotone: a slice line just beside any vertex (where a violation
        // would show) and a few in between meets the boundary at most twice.
        let hs: Vec<f64> = open.iter().map(|&p| h(p)).collect();
        let (lo, hi) = hs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), &v| {
                (l.min(v), u.max(v))
            });
        let delta = 1e-7 * (hi - lo);
        let mut probes: Vec<f64> = hs.iter().flat_map(|&v| [v - delta, v + delta]).collect();
        probes.extend([0.01, 0.3, 0.5, 0.77, 0.99].map(|t| lo + t * (hi - lo)));
        for probe in probes.into_iter().filter(|&p| p > lo && p < hi) {
            let crossings = (0..n)
                .filter(|&k| (hs[k] - probe) * (hs[(k + 1) % n] - probe) < 0.0)
                .count();
            assert!(
                crossings <= 2,
                "cell {i} is not monotone: {crossings} crossings at h={probe}: {cell:?}"
            );
        }
    }

    for i in 0..cells.len() {
        for j in i + 1..cells.len() {
            let (a, b) = (
                cells[i].bounding_rect().unwrap(),
                cells[j].bounding_rect().unwrap(),
            );
            if a.intersects(&b) {
                let overlap = cells[i].intersection(&cells[j]).unsigned_area();
                assert!(
                    overlap <= 1e-9 * free_area,
                    "cells {i} and {j} overlap by {overlap}"
                );
            }
        }
    }

    let total: f64 = cells.iter().map(|p| p.unsigned_area()).sum();
    assert!(
        (total - free_area).abs() <= 1e-6 * free_area,
        "cells cover {total}, free space is {free_area}"
    );
    let mismatch = unary_union(cells).xor(free).unsigned_area();
    assert!(
        mismatch <= 1e-6 * free_area,
        "union of cells differs from the free space by {mismatch}"
    );
}
