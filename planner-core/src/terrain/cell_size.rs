//! Cell sizes in metres: metres per degree on the WGS84 ellipsoid and the
//! size of a raster's cell at a pixel position, for projected and
//! geographic grids alike (degrees are never taken as metres).

use super::GeoTransform;

const WGS84_A: f64 = 6_378_137.0;
const WGS84_F: f64 = 1.0 / 298.257_223_563;

/// Metres per degree [east, north] at latitude `lat_deg` on the WGS84
/// ellipsoid: east `N·cos φ·π/180`, north `M·π/180` with the prime-vertical
/// and meridional radii of curvature `N = a/√(1−e² sin²φ)` and
/// `M = a(1−e²)/(1−e² sin²φ)^1.5`.
pub(crate) fn metres_per_degree(lat_deg: f64) -> [f64; 2] {
    let e2 = WGS84_F * (2.0 - WGS84_F);
    let phi = lat_deg.clamp(-90.0, 90.0).to_radians();
    let s = phi.sin();
    let q = 1.0 - e2 * s * s;
    let n = WGS84_A / q.sqrt();
    let m = WGS84_A * (1.0 - e2) / (q * q.sqrt());
    let k = std::f64::consts::PI / 180.0;
    [(n * phi.cos() * k).max(0.0), m * k]
}

/// Size in metres [along a row, along a column] of a cell whose centre is
/// at fractional pixel position (col, row). Projected CRSs are assumed to
/// be in metres; a geographic one's degrees are converted at the latitude
/// of that point.
pub(crate) fn cell_size_m(t: &GeoTransform, geographic: bool, col: f64, row: f64) -> [f64; 2] {
    if !geographic {
        return [
            t.pixel_width.hypot(t.col_rotation),
            t.row_rotation.hypot(t.pixel_height),
        ];
    }
    let (_, lat) = t.apply(col, row);
    let [me, mn] = metres_per_degree(lat);
    [
        (t.pixel_width * me).hypot(t.col_rotation * mn),
        (t.row_rotation * me).hypot(t.pixel_height * mn),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metres_per_degree_matches_wgs84() {
        // Equator: 111 319.49 m east, 110 574.28 m north; 45°: 78 846.8 /
        // 111 131.7; pole: 0 east, 111 693.9 north.
        let [e, n] = metres_per_degree(0.0);
        assert!(
            (e - 111_319.49).abs() < 0.01 && (n - 110_574.28).abs() < 0.01,
            "{e} {n}"
        );
        let [e, n] = metres_per_degree(45.0);
        assert!(
            (e - 78_846.8).abs() < 0.1 && (n - 111_131.7).abs() < 0.1,
            "{e} {n}"
        );
        let [e, n] = metres_per_degree(90.0);
        assert!(e.abs() < 1e-6 && (n - 111_693.9).abs() < 0.1, "{e} {n}");
    }
}
