//! What the benches share: the 4 km × 4 km test area and its no-fly zones.

use geo_types::{Coord, Polygon};

/// Side of the square ROI, metres.
pub const SIDE_M: f64 = 4000.0;

/// Deterministic pseudo-random numbers (no RNG dependency for a bench).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `n` disjoint octagonal NFZs, one per cell of a jittered grid.
pub fn nfzs(n: usize) -> Vec<Polygon<f64>> {
    let mut rng = Lcg(42);
    let per_row = (n as f64).sqrt().ceil() as usize;
    let pitch = SIDE_M / per_row as f64;
    (0..n)
        .map(|i| {
            let (r, c) = (i / per_row, i % per_row);
            let radius = pitch * (0.15 + 0.15 * rng.next());
            let cx = (c as f64 + 0.5) * pitch + (rng.next() - 0.5) * (pitch - 2.0 * radius) * 0.8;
            let cy = (r as f64 + 0.5) * pitch + (rng.next() - 0.5) * (pitch - 2.0 * radius) * 0.8;
            let rot = rng.next();
            let ring: Vec<Coord<f64>> = (0..8)
                .map(|k| {
                    let t = (k as f64 + rot) * std::f64::consts::TAU / 8.0;
                    Coord {
                        x: cx + radius * t.cos(),
                        y: cy + radius * t.sin(),
                    }
                })
                .collect();
            Polygon::new(ring.into(), vec![])
        })
        .collect()
}
