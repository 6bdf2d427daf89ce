//! Obstacle inflation (thesis §3.5, SPEC §4.2 step 6): how close each
//! cell is to an obstacle, in [0, 1] (1 on the obstacle), later weighted
//! by w_infl.
//!
//! `blur` is the thesis' Gaussian convolution of the binary obstacle grid,
//! kernel (2·⌈2σ⌉+1) cells (eq. 3.3). It dilutes thin obstacles: beside a
//! one-cell wall the blur is far lower than beside a thick one.
//! `distance` (default) takes exp(−d²/2σ²) of the exact Euclidean distance
//! d to the nearest obstacle cell, so the cost depends only on how near
//! the obstacle is, not on how thick it is.

use super::InflationMode;
use super::distance::map_squared_distance_f32;
use super::smooth::gaussian_smooth_truncated;

/// Inflation of `obstacle` on a grid of `sx`×`sy` m cells with σ in metres.
pub fn inflation(
    obstacle: &[bool],
    width: usize,
    height: usize,
    [sx, sy]: [f64; 2],
    sigma_m: f64,
    mode: InflationMode,
) -> Vec<f32> {
    match mode {
        InflationMode::Distance => {
            let k = 1.0 / (2.0 * sigma_m * sigma_m);
            map_squared_distance_f32(obstacle, width, height, sx, sy, |d2| {
                let x = f64::from(d2) * k;
                // exp(−40) ≈ 4e−18: nothing at f32 precision. Cutting it
                // to 0 there lets the transform skip the cells that far
                // from any obstacle, which are most.
                if x > 40.0 { 0.0 } else { (-x).exp() as f32 }
            })
        }
        InflationMode::Blur => {
            let mut g: Vec<f64> = obstacle.iter().map(|&o| f64::from(u8::from(o))).collect();
            gaussian_smooth_truncated(&mut g, width, height, sigma_m / sx, sigma_m / sy);
            g.into_iter().map(|v| v as f32).collect()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Lcg;

    fn walls(w: usize, h: usize, cols: std::ops::RangeInclusive<usize>) -> Vec<bool> {
        (0..w * h).map(|i| cols.contains(&(i % w))).collect()
    }

    #[test]
    fn distance_mode_inflates_a_one_cell_wall_like_a_thick_one() {
        let (w, h) = (31, 9);
        let thin = inflation(
            &walls(w, h, 15..=15),
            w,
            h,
            [0.5, 0.5],
            1.0,
            InflationMode::Distance,
        );
        let thick = inflation(
            &walls(w, h, 11..=15),
            w,
            h,
            [0.5, 0.5],
            1.0,
            InflationMode::Distance,
        );
        for c in 15..w {
            let (a, b) = (thin[4 * w + c], thick[4 * w + c]);
            assert_eq!(a, b, "col {c}");
            let d = (c - 15) as f64 * 0.5;
            assert!((f64::from(a) - (-d * d / 2.0).exp()).abs() < 1e-6);
        }
        assert_eq!(thin[4 * w + 15], 1.0);
    }

    #[test]
    fn blur_mode_dilutes_a_one_cell_wall() {
        let (w, h) = (31, 9);
        let thin = inflation(
            &walls(w, h, 15..=15),
            w,
            h,
            [0.5, 0.5],
            1.0,
            InflationMode::Blur,
        );
        let thick = inflation(
            &walls(w, h, 9..=15),
            w,
            h,
            [0.5, 0.5],
            1.0,
            InflationMode::Blur,
        );
        // On the wall and beside it, the thin wall's blur is much weaker.
        assert!(thin[4 * w + 15] < 0.5 && thick[4 * w + 15] > 0.45);
        assert!(thin[4 * w + 16] < 0.7 * thick[4 * w + 16]);
        // The kernel reaches (2·⌈2σ⌉+1) cells: σ = 2 cells → 4 cells out.
        assert!(thin[4 * w + 19] > 0.0 && thin[4 * w + 20] == 0.0);
    }

    #[test]
    fn distance_mode_equals_the_gaussian_of_the_brute_force_distance() {
        let mut state = Lcg(0x1f1a7e_u64);
        let mut next = || state.next();
        let mut sizes = vec![(1, 1), (1, 3), (3, 1), (2, 3), (3, 3)];
        sizes.extend((0..25).map(|_| (1 + (next() * 30.0) as usize, 1 + (next() * 90.0) as usize)));
        for (w, h) in sizes {
            let (sx, sy) = (0.2 + next() * 2.0, 0.2 + next() * 2.0);
            for density in [0.0, 0.01, 0.1, 0.7, 1.0] {
                let obstacle: Vec<bool> = (0..w * h).map(|_| next() < density).collect();
                for sigma in [0.05, 0.52, 2.6, 30.0] {
                    let got = inflation(&obstacle, w, h, [sx, sy], sigma, InflationMode::Distance);
                    for (i, g) in got.iter().enumerate() {
                        let (x, y) = ((i % w) as f64, (i / w) as f64);
                        let d2 = (0..w * h)
                            .filter(|&j| obstacle[j])
                            .map(|j| {
                                let (ox, oy) = ((j % w) as f64, (j / w) as f64);
                                ((x - ox) * sx).powi(2) + ((y - oy) * sy).powi(2)
                            })
                            .fold(f64::INFINITY, f64::min);
                        let want = (-d2 / (2.0 * sigma * sigma)).exp();
                        assert!(
                            (f64::from(*g) - want).abs() <= 1e-6,
                            "{w}×{h} σ {sigma} cell {i}: {g} vs {want}"
                        );
                    }
                }
            }
        }
    }
}
