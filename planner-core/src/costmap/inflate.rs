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

use rayon::prelude::*;

use super::InflationMode;
use super::distance::squared_distance_f32;
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
            let mut v = squared_distance_f32(obstacle, width, height, sx, sy);
            let k = 1.0 / (2.0 * sigma_m * sigma_m);
            v.par_chunks_mut(1 << 16).for_each(|chunk| {
                for d2 in chunk {
                    let x = f64::from(*d2) * k;
                    // exp(−40) ≈ 4e−18: nothing at f32 precision, and most
                    // cells are that far from any obstacle.
                    *d2 = if x > 40.0 { 0.0 } else { (-x).exp() as f32 };
                }
            });
            v
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
}
