//! Fraction of free space seen by the camera (SPEC §3.3): every lane is
//! swept by a strip as wide as the footprint (a rectangle with flat ends),
//! the strips are united, clipped to free space and measured.

use geo::Area;

use crate::overlay::{intersection, unary_union};
use geo_types::{Coord, LineString, MultiPolygon, Polygon};

use super::Lane;
use super::region::{cross, dot, is_positive};

/// Lanes whose bearings differ by less than this (radians) share one frame
/// for the union: a 2 km lane then moves by at most 1 cm.
const SAME_DIRECTION_RAD: f64 = 5e-6;

/// Strip corners are put on this grid (metres) in their lane frame, so that
/// nearly coincident strip edges become exactly coincident.
const GRID_M: f64 = 1e-6;

/// Area of (∪ lane strips) ∩ `free`, divided by the area of `free`.
///
/// Returns 0 when `free` has no area or the swath is not a positive number.
/// The strips are united in one sweep ([`unary_union`]) per lane direction,
/// in a frame where they are axis-aligned: the overlay snaps coordinates to
/// an integer grid, and the nearly collinear, slanted edges of strips of
/// neighbouring cells would otherwise cross at tiny angles over and over
/// (305 strips took 18 s).
pub fn coverage_ratio(lanes: &[Lane], swath_width_m: f64, free: &MultiPolygon<f64>) -> f64 {
    let free_area = free.unsigned_area();
    if !is_positive(free_area) || !is_positive(swath_width_m) {
        return 0.0;
    }
    // Work relative to a local origin: UTM coordinates are ~10⁶ m, and the
    // overlay snaps to a grid scaled by the coordinates' magnitude.
    let Some(origin) = free
        .0
        .iter()
        .flat_map(|p| p.exterior().0.first())
        .next()
        .copied()
    else {
        return 0.0;
    };
    let covered = swept_area(lanes, swath_width_m / 2.0, origin);
    if covered.0.is_empty() {
        return 0.0;
    }
    let local_free = MultiPolygon(
        free.0
            .iter()
            .map(|p| {
                let shift = |ring: &LineString<f64>| {
                    LineString(ring.0.iter().map(|c| *c - origin).collect())
                };
                Polygon::new(
                    shift(p.exterior()),
                    p.interiors().iter().map(shift).collect(),
                )
            })
            .collect(),
    );
    let seen = intersection(&covered, &local_free).unsigned_area();
    (seen / free_area).clamp(0.0, 1.0)
}

/// The union of the strips of half-width `half` along the lanes, relative
/// to `origin`. Zero-length and non-finite lanes sweep nothing.
fn swept_area(lanes: &[Lane], half: f64, origin: Coord<f64>) -> MultiPolygon<f64> {
    // (direction in [0, π), lane) for every lane with a length.
    let mut directed: Vec<(f64, &Lane)> = lanes
        .iter()
        .filter_map(|lane| {
            let d = lane.end - lane.start;
            if !is_positive(d.x.hypot(d.y)) {
                return None;
            }
            Some((d.y.atan2(d.x).rem_euclid(std::f64::consts::PI), lane))
        })
        .filter(|(a, _)| a.is_finite())
        .collect();
    directed.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut groups: Vec<MultiPolygon<f64>> = Vec::new();
    let mut rest = directed.as_slice();
    while let Some(&(angle, _)) = rest.first() {
        let n = rest.partition_point(|(a, _)| *a - angle < SAME_DIRECTION_RAD);
        let (group, tail) = rest.split_at(n);
        groups.push(frame_union(
            angle,
            group.iter().map(|(_, l)| *l),
            half,
            origin,
        ));
        rest = tail;
    }
    match groups.len() {
        0 => MultiPolygon(vec![]),
        1 => groups.pop().unwrap_or_else(|| MultiPolygon(vec![])),
        _ => unary_union(groups.iter().flat_map(|g| g.0.iter())),
    }
}

/// Union of the strips of lanes running (nearly) along `angle`, built as
/// axis-aligned rectangles in the lane frame and turned back.
fn frame_union<'a>(
    angle: f64,
    lanes: impl Iterator<Item = &'a Lane>,
    half: f64,
    origin: Coord<f64>,
) -> MultiPolygon<f64> {
    let d = Coord {
        x: angle.cos(),
        y: angle.sin(),
    };
    let snap = |x: f64| (x / GRID_M).round() * GRID_M;
    let rects: Vec<Polygon<f64>> = lanes
        .map(|lane| {
            let (a, b) = (lane.start - origin, lane.end - origin);
            let (ua, ub) = (dot(a, d), dot(b, d));
            // Signed offsets left of the frame direction.
            let v = (cross(d, a) + cross(d, b)) / 2.0;
            let (u0, u1) = (snap(ua.min(ub)), snap(ua.max(ub)));
            let (v0, v1) = (snap(v - half), snap(v + half));
            Polygon::new(
                LineString(vec![
                    Coord { x: u0, y: v0 },
                    Coord { x: u1, y: v0 },
                    Coord { x: u1, y: v1 },
                    Coord { x: u0, y: v1 },
                    Coord { x: u0, y: v0 },
                ]),
                vec![],
            )
        })
        .collect();
    let to_world = |c: &Coord<f64>| Coord {
        x: d.x * c.x - d.y * c.y,
        y: d.y * c.x + d.x * c.y,
    };
    let turn = |ring: &LineString<f64>| LineString(ring.0.iter().map(to_world).collect());
    MultiPolygon(
        unary_union(&rects)
            .0
            .iter()
            .map(|p| Polygon::new(turn(p.exterior()), p.interiors().iter().map(turn).collect()))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use geo_types::{coord, polygon};
    use std::time::Instant;

    fn lane(x0: f64, y0: f64, x1: f64, y1: f64) -> Lane {
        Lane {
            start: coord! { x: x0, y: y0 },
            end: coord! { x: x1, y: y1 },
        }
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
        polygon![(x: x0, y: y0), (x: x1, y: y0), (x: x1, y: y1), (x: x0, y: y1)]
    }

    #[test]
    fn one_lane_over_a_rectangle() {
        // 100 × 40 field, one lane along the middle seeing 10 m: a quarter.
        let free = MultiPolygon(vec![rect(500_000.0, 5_000_000.0, 500_100.0, 5_000_040.0)]);
        let lanes = [lane(500_000.0, 5_000_020.0, 500_100.0, 5_000_020.0)];
        assert_abs_diff_eq!(coverage_ratio(&lanes, 10.0, &free), 0.25, epsilon = 1e-9);
        // Overshooting the field changes nothing; flat ends: a lane stopping
        // 10 m short of the east edge misses exactly 10 × 10 m².
        let long = [lane(499_950.0, 5_000_020.0, 500_200.0, 5_000_020.0)];
        assert_abs_diff_eq!(coverage_ratio(&long, 10.0, &free), 0.25, epsilon = 1e-9);
        let short = [lane(500_000.0, 5_000_020.0, 500_090.0, 5_000_020.0)];
        assert_abs_diff_eq!(
            coverage_ratio(&short, 10.0, &free),
            900.0 / 4000.0,
            epsilon = 1e-9
        );
    }

    #[test]
    fn overlapping_strips_count_once_and_holes_are_excluded() {
        // 100 × 100 with a 20 × 20 NFZ hole; free area 9600.
        let free = MultiPolygon(vec![Polygon::new(
            rect(0.0, 0.0, 100.0, 100.0).exterior().clone(),
            vec![rect(40.0, 40.0, 60.0, 60.0).exterior().clone()],
        )]);
        // Two strips 30 m wide centred at y = 45 and y = 55 overlap on
        // y ∈ [40, 60]; together they see y ∈ [30, 70] minus the hole:
        // 100·40 − 400 = 3600.
        let lanes = [lane(0.0, 45.0, 100.0, 45.0), lane(100.0, 55.0, 0.0, 55.0)];
        assert_abs_diff_eq!(
            coverage_ratio(&lanes, 30.0, &free),
            3600.0 / 9600.0,
            epsilon = 1e-9
        );
    }

    #[test]
    fn slanted_lane() {
        // A diagonal lane across a square: the strip is a rotated rectangle,
        // clipped by the square to a hexagon of area
        // 100² − 2·(½·(100 − 5√2)²) for a 10 m swath.
        let free = MultiPolygon(vec![rect(0.0, 0.0, 100.0, 100.0)]);
        let lanes = [lane(0.0, 0.0, 100.0, 100.0)];
        let leg = 100.0 - 5.0 * 2f64.sqrt();
        let expected = (10_000.0 - leg * leg) / 10_000.0;
        assert_abs_diff_eq!(
            coverage_ratio(&lanes, 10.0, &free),
            expected,
            epsilon = 1e-9
        );
    }

    #[test]
    fn full_and_degenerate() {
        let free = MultiPolygon(vec![rect(0.0, 0.0, 100.0, 50.0)]);
        let lanes: Vec<Lane> = (0..5)
            .map(|i| {
                let y = 5.0 + 10.0 * f64::from(i);
                if i % 2 == 0 {
                    lane(0.0, y, 100.0, y)
                } else {
                    lane(100.0, y, 0.0, y)
                }
            })
            .collect();
        assert_abs_diff_eq!(coverage_ratio(&lanes, 10.0, &free), 1.0, epsilon = 1e-9);
        assert_abs_diff_eq!(coverage_ratio(&lanes, 5.0, &free), 0.5, epsilon = 1e-9);
        assert_eq!(coverage_ratio(&[], 10.0, &free), 0.0);
        assert_eq!(coverage_ratio(&lanes, 0.0, &free), 0.0);
        assert_eq!(coverage_ratio(&lanes, f64::NAN, &free), 0.0);
        assert_eq!(coverage_ratio(&lanes, 10.0, &MultiPolygon(vec![])), 0.0);
        assert_eq!(
            coverage_ratio(&[lane(1.0, 1.0, 1.0, 1.0)], 10.0, &free),
            0.0
        );
    }

    #[test]
    fn crossing_directions_are_united() {
        // A north–south and an east–west strip, 10 m wide, over a 100 m
        // square: 2·1000 − 100 m² of overlap.
        let free = MultiPolygon(vec![rect(0.0, 0.0, 100.0, 100.0)]);
        let lanes = [lane(50.0, 0.0, 50.0, 100.0), lane(0.0, 50.0, 100.0, 50.0)];
        assert_abs_diff_eq!(coverage_ratio(&lanes, 10.0, &free), 0.19, epsilon = 1e-9);
        // Opposite directions are one direction.
        let back = [lane(50.0, 100.0, 50.0, 0.0), lane(50.0, 0.0, 50.0, 100.0)];
        assert_abs_diff_eq!(coverage_ratio(&back, 10.0, &free), 0.1, epsilon = 1e-9);
    }

    /// Lanes of stacked narrow cells (between NFZs): parallel, slanted,
    /// with offsets a rounding apart and staggered ends.
    fn stacked_cell_lanes(tilt_deg: f64) -> (Vec<Lane>, MultiPolygon<f64>) {
        let (s, c) = tilt_deg.to_radians().sin_cos();
        let turn = |x: f64, y: f64| coord! { x: 500_000.0 + x * c + y * s, y: 5_200_000.0 - x * s + y * c };
        let mut lanes = Vec::new();
        for i in 0..300 {
            let x = 13.7 * f64::from(i % 150) + 1e-7 * f64::from(i);
            let y0 = if i < 150 {
                0.0
            } else {
                1000.0 + 0.37 * f64::from(i % 7)
            };
            let y1 = if i < 150 {
                1000.0 - 0.51 * f64::from(i % 5)
            } else {
                2000.0
            };
            lanes.push(Lane {
                start: turn(x, y0),
                end: turn(x, y1),
            });
        }
        let corners = [
            (-100.0, -10.0),
            (2200.0, -10.0),
            (2200.0, 2010.0),
            (-100.0, 2010.0),
        ];
        let ring: Vec<Coord<f64>> = corners.iter().map(|&(x, y)| turn(x, y)).collect();
        (
            lanes,
            MultiPolygon(vec![Polygon::new(LineString(ring), vec![])]),
        )
    }

    #[test]
    fn slanted_nearly_collinear_strips_match_the_axis_aligned_case() {
        // Axis-aligned, the strips' union is exact; tilted by a UTM grid
        // convergence-like angle, the same configuration must measure the
        // same (this used to take the overlay tens of seconds).
        let (lanes, free) = stacked_cell_lanes(0.0);
        let (tilted, tilted_free) = stacked_cell_lanes(0.3657);
        let want = coverage_ratio(&lanes, 180.0, &free);
        assert!(want > 0.9 && want < 1.0, "{want}");
        assert_abs_diff_eq!(
            coverage_ratio(&tilted, 180.0, &tilted_free),
            want,
            epsilon = 1e-9
        );
        assert_abs_diff_eq!(
            coverage_ratio(&tilted, 5.0, &tilted_free),
            coverage_ratio(&lanes, 5.0, &free),
            epsilon = 1e-9
        );
    }

    #[test]
    fn thousands_of_lanes_stay_fast() {
        // 3000 lanes 2 m apart over a 6 km × 1 km field, 2.5 m swath.
        let free = MultiPolygon(vec![rect(0.0, 0.0, 1000.0, 6000.0)]);
        let lanes: Vec<Lane> = (0..3000)
            .map(|i| {
                let y = 1.0 + 2.0 * f64::from(i);
                lane(0.0, y, 1000.0, y)
            })
            .collect();
        let t = Instant::now();
        let r = coverage_ratio(&lanes, 2.5, &free);
        assert_abs_diff_eq!(r, 1.0, epsilon = 1e-9);
        assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    }
}
