//! The slice frame: a rotation (plus a shift to a local origin) that turns the
//! slice lines of a given bearing into vertical lines `x = const`, swept
//! towards `+x`.
//!
//! Bearings are degrees clockwise from grid north; a slice line of bearing θ
//! has the direction (sin θ, cos θ) in (east, north). Lines of bearing θ and
//! θ + 180° are the same, so only θ mod 180° matters. The sweep runs along the
//! normal of the slice lines that points east; for exactly east–west lines
//! (θ = 90°) it points north. So 0° sweeps west→east (the thesis' h = x) and
//! 90° sweeps south→north (h = y).

use geo_types::Coord;

/// A proper rotation (orientation-preserving, so CCW rings stay CCW) about
/// `origin`, mapping world coordinates to the slice frame and back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SliceFrame {
    /// Local origin in world coordinates. Shifting to it before rotating keeps
    /// the full f64 precision for UTM-sized coordinates (northings ~ 10⁶ m).
    origin: Coord<f64>,
    /// Unit sweep direction (local +x) in world coordinates.
    sweep: Coord<f64>,
    /// Unit slice-line direction (local +y) = `sweep` turned 90° CCW.
    along: Coord<f64>,
}

impl SliceFrame {
    /// The frame for slice lines of bearing `slice_angle_deg` (must be finite).
    pub(crate) fn new(slice_angle_deg: f64, origin: Coord<f64>) -> Self {
        let sweep = sweep_direction(slice_angle_deg);
        SliceFrame {
            origin,
            sweep,
            along: Coord {
                x: -sweep.y,
                y: sweep.x,
            },
        }
    }

    pub(crate) fn to_local(self, p: Coord<f64>) -> Coord<f64> {
        self.rotate(p - self.origin)
    }

    /// The rotation alone, of a point already relative to the origin.
    pub(crate) fn rotate(self, d: Coord<f64>) -> Coord<f64> {
        Coord {
            x: d.x * self.sweep.x + d.y * self.sweep.y,
            y: d.x * self.along.x + d.y * self.along.y,
        }
    }

    pub(crate) fn to_world(self, q: Coord<f64>) -> Coord<f64> {
        Coord {
            x: self.origin.x + (q.x * self.sweep.x + q.y * self.along.x),
            y: self.origin.y + (q.x * self.sweep.y + q.y * self.along.y),
        }
    }
}

/// Unit normal of the slice lines in the sweep direction (see module docs).
fn sweep_direction(slice_angle_deg: f64) -> Coord<f64> {
    let mut a = slice_angle_deg.rem_euclid(180.0);
    if a >= 180.0 {
        // rem_euclid of a tiny negative number rounds up to 180.
        a = 0.0;
    }
    // The thesis' two slices must be exact: sin/cos of π/2 are not.
    if a == 0.0 {
        return Coord { x: 1.0, y: 0.0 };
    }
    if a == 90.0 {
        return Coord { x: 0.0, y: 1.0 };
    }
    let (s, c) = a.to_radians().sin_cos();
    // ±(cos θ, −sin θ) are the normals of (sin θ, cos θ); take the eastward one.
    if a < 90.0 {
        Coord { x: c, y: -s }
    } else {
        Coord { x: -c, y: s }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn c(x: f64, y: f64) -> Coord<f64> {
        Coord { x, y }
    }

    #[test]
    fn zero_degrees_is_a_pure_shift() {
        let f = SliceFrame::new(0.0, c(500_000.0, 5_000_000.0));
        assert_eq!(f.to_local(c(500_010.0, 5_000_020.0)), c(10.0, 20.0));
        assert_eq!(f.to_world(c(10.0, 20.0)), c(500_010.0, 5_000_020.0));
    }

    #[test]
    fn ninety_degrees_sweeps_north_with_exact_axes() {
        let f = SliceFrame::new(90.0, c(0.0, 0.0));
        // North becomes the sweep axis; an east–west line becomes vertical.
        assert_eq!(f.to_local(c(0.0, 5.0)), c(5.0, 0.0));
        let a = f.to_local(c(-3.0, 2.0));
        let b = f.to_local(c(7.0, 2.0));
        assert_eq!(a.x, b.x);
    }

    #[test]
    fn slice_lines_become_vertical_and_sweep_points_east() {
        for deg in [
            0.0, 10.0, 45.0, 89.9, 90.0, 90.1, 135.0, 179.9, -30.0, 200.0, 720.0,
        ] {
            let f = SliceFrame::new(deg, c(1.0, 2.0));
            let t = f64::to_radians(deg);
            let dir = c(t.sin(), t.cos());
            let p = c(3.0, -4.0);
            let q = f.to_local(p + dir * 10.0) - f.to_local(p);
            assert!(q.x.abs() < 1e-12, "{deg}: {q:?}");
            assert_relative_eq!(q.y.abs(), 10.0, epsilon = 1e-12);
            // Sweep direction in world coordinates has a positive east
            // component, or points north for east–west lines.
            let s = f.to_world(c(1.0, 0.0)) - f.to_world(c(0.0, 0.0));
            let normalised = deg.rem_euclid(180.0);
            if (normalised - 90.0).abs() < 1e-9 {
                assert_relative_eq!(s.y, 1.0, epsilon = 1e-12);
            } else {
                assert!(s.x > 0.0, "{deg}: {s:?}");
            }
        }
    }

    #[test]
    fn round_trip_and_orientation_preserved() {
        let f = SliceFrame::new(33.0, c(400_000.0, 6_000_000.0));
        let pts = [
            c(400_100.0, 6_000_000.0),
            c(400_000.0, 6_000_100.0),
            c(399_950.5, 5_999_990.25),
        ];
        for p in pts {
            let back = f.to_world(f.to_local(p));
            assert_relative_eq!(back.x, p.x, epsilon = 1e-8);
            assert_relative_eq!(back.y, p.y, epsilon = 1e-8);
        }
        // (x → y) turns CCW in both frames: the rotation is proper.
        let a = f.to_local(c(400_001.0, 6_000_000.0)) - f.to_local(c(400_000.0, 6_000_000.0));
        let b = f.to_local(c(400_000.0, 6_000_001.0)) - f.to_local(c(400_000.0, 6_000_000.0));
        assert!(a.x * b.y - a.y * b.x > 0.0);
    }
}
