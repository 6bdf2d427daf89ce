//! Fraction of free space seen by the camera (SPEC §3.3): every lane is
//! swept by a strip as wide as the footprint (a rectangle with flat ends),
//! the strips are united, clipped to free space and measured.

use geo::{Area, BooleanOps, unary_union};
use geo_types::{Coord, LineString, MultiPolygon, Polygon};

use super::Lane;
use super::region::is_positive;

/// Area of (∪ lane strips) ∩ `free`, divided by the area of `free`.
///
/// Returns 0 when `free` has no area or the swath is not a positive number.
/// The strips are united in one sweep ([`unary_union`]), so thousands of lanes
/// stay fast.
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
    let half = swath_width_m / 2.0;
    let strips: Vec<Polygon<f64>> = lanes
        .iter()
        .filter_map(|lane| strip(lane.start - origin, lane.end - origin, half))
        .collect();
    if strips.is_empty() {
        return 0.0;
    }
    let covered = unary_union(&strips);
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
    let seen = covered.intersection(&local_free).unsigned_area();
    (seen / free_area).clamp(0.0, 1.0)
}

/// The rectangle swept by a strip of half-width `half` along `a`→`b`, wound
/// counter-clockwise; `None` for a zero-length or non-finite lane.
fn strip(a: Coord<f64>, b: Coord<f64>, half: f64) -> Option<Polygon<f64>> {
    let len = (b.x - a.x).hypot(b.y - a.y);
    if !is_positive(len) {
        return None;
    }
    // Left normal of the lane direction, scaled to the half width.
    let n = Coord {
        x: -(b.y - a.y) / len * half,
        y: (b.x - a.x) / len * half,
    };
    Some(Polygon::new(
        LineString(vec![a - n, b - n, b + n, a + n, a - n]),
        vec![],
    ))
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
