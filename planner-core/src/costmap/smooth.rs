//! Light Gaussian smoothing of the heights before the normals are
//! estimated (thesis §3.3: "a slightly smoothed version of the DEM").
//!
//! Separable, and normalised over the valid cells under the kernel, so
//! nodata neither spreads nor pulls heights towards zero; unknown cells
//! stay unknown. Kernel radius ⌈3σ⌉ cells per axis (⌈2σ⌉ for the
//! thesis' inflation blur, eq. 3.3).

use rayon::prelude::*;

/// Gaussian weights for offsets −r…r, r = ⌈reach·σ⌉, σ in cells (> 0).
fn kernel(sigma_cells: f64, reach: f64) -> Vec<f64> {
    let r = (reach * sigma_cells).ceil().max(1.0) as isize;
    (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma_cells * sigma_cells)).exp())
        .collect()
}

/// One 1D pass over the line `src` into `out`, for the cells in `cells`.
#[inline]
fn pass_line(src: &[f64], k: &[f64], out: &mut [f64], cells: std::ops::Range<usize>) {
    let n = src.len();
    let r = (k.len() / 2) as isize;
    for i in cells {
        let o = &mut out[i];
        let centre = src[i];
        if centre.is_nan() {
            *o = f64::NAN;
            continue;
        }
        let (mut s, mut w) = (0.0, 0.0);
        let lo = (i as isize - r).max(0);
        let hi = (i as isize + r).min(n as isize - 1);
        for j in lo..=hi {
            let v = src[j as usize];
            if !v.is_nan() {
                let kw = k[(j - i as isize + r) as usize];
                s += kw * v;
                w += kw;
            }
        }
        *o = s / w;
    }
}

/// Smooths the `width`×`height` grid `z` in place with a Gaussian of σ =
/// `sigma_x` cells along rows and `sigma_y` cells along columns (0 on
/// an axis leaves it alone).
pub fn gaussian_smooth(z: &mut [f64], width: usize, height: usize, sigma_x: f64, sigma_y: f64) {
    smooth(z, width, height, sigma_x, sigma_y, 3.0);
}

/// [`gaussian_smooth`] with the kernel cut at ⌈2σ⌉ cells, the thesis'
/// kernel size (2·⌈2σ⌉+1) cells.
pub fn gaussian_smooth_truncated(
    z: &mut [f64],
    width: usize,
    height: usize,
    sigma_x: f64,
    sigma_y: f64,
) {
    smooth(z, width, height, sigma_x, sigma_y, 2.0);
}

fn smooth(z: &mut [f64], width: usize, height: usize, sigma_x: f64, sigma_y: f64, reach: f64) {
    if width == 0 || height == 0 {
        return;
    }
    if sigma_x <= 0.0 && sigma_y <= 0.0 {
        return;
    }
    // Rows from `z` into a second buffer, then columns from it back into
    // `z` (or the rows copied back when only they are smoothed).
    let mut src = vec![0.0; z.len()];
    if sigma_x > 0.0 {
        let k = kernel(sigma_x, reach);
        let r = k.len() / 2;
        let norm: f64 = k.iter().sum();
        let kn: Vec<f64> = k.iter().map(|w| w / norm).collect();
        src.par_chunks_mut(width)
            .zip(z.par_chunks(width))
            .for_each(|(out, row)| {
                if width > 2 * r && !row.iter().any(|v| v.is_nan()) {
                    // No NaN: the edges with renormalised weights, the
                    // cells whose kernel lies inside the row without checks.
                    pass_line(row, &k, out, 0..r);
                    pass_line(row, &k, out, width - r..width);
                    for (o, window) in out[r..width - r].iter_mut().zip(row.windows(k.len())) {
                        *o = window.iter().zip(&kn).map(|(v, w)| v * w).sum();
                    }
                } else {
                    pass_line(row, &k, out, 0..width);
                }
            });
    } else {
        src.copy_from_slice(z);
    }
    if sigma_y <= 0.0 {
        z.copy_from_slice(&src);
        return;
    }
    {
        let k = kernel(sigma_y, reach);
        let row_has_nan: Vec<bool> = src
            .par_chunks(width)
            .map(|row| row.iter().any(|v| v.is_nan()))
            .collect();
        let norm: f64 = k.iter().sum();
        let kn: Vec<f64> = k.iter().map(|w| w / norm).collect();
        // Each output row reads the rows above and below from `src`.
        z.par_chunks_mut(width).enumerate().for_each(|(row, out)| {
            let r = (k.len() / 2) as isize;
            let (lo, hi) = (row as isize - r, row as isize + r);
            if lo >= 0
                && hi < height as isize
                && !row_has_nan[lo as usize..=hi as usize].contains(&true)
            {
                // Whole kernel inside and no NaN: a weighted sum of rows.
                out.fill(0.0);
                for (j, &w) in (lo..=hi).zip(&kn) {
                    let line = &src[j as usize * width..(j as usize + 1) * width];
                    for (o, v) in out.iter_mut().zip(line) {
                        *o += w * v;
                    }
                }
                return;
            }
            for (col, o) in out.iter_mut().enumerate() {
                let centre = src[row * width + col];
                if centre.is_nan() {
                    continue;
                }
                let (mut s, mut w) = (0.0, 0.0);
                let lo = (row as isize - r).max(0);
                let hi = (row as isize + r).min(height as isize - 1);
                for j in lo..=hi {
                    let v = src[j as usize * width + col];
                    if !v.is_nan() {
                        let kw = k[(j - row as isize + r) as usize];
                        s += kw * v;
                        w += kw;
                    }
                }
                *o = s / w;
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planes_stay_planes_away_from_the_edges_and_nodata_stays() {
        let (w, h) = (20, 15);
        let mut z: Vec<f64> = (0..w * h)
            .map(|i| 3.0 + 0.25 * (i % w) as f64 - 0.5 * (i / w) as f64)
            .collect();
        let plane = z.clone();
        z[7 * w + 7] = f64::NAN;
        gaussian_smooth(&mut z, w, h, 0.8, 1.3);
        assert!(z[7 * w + 7].is_nan());
        // Interior cells whose kernel sees no NaN and no edge (radius 3
        // and 4 cells) are the plane.
        for r in 4..h - 4 {
            for c in 3..w - 3 {
                if (r as isize - 7).abs() <= 4 && (c as isize - 7).abs() <= 3 {
                    continue;
                }
                assert!((z[r * w + c] - plane[r * w + c]).abs() < 1e-9, "{r} {c}");
            }
        }
    }

    #[test]
    fn a_spike_is_spread_and_its_mass_kept_in_the_interior() {
        let (w, h) = (21, 21);
        let mut z = vec![0.0; w * h];
        z[10 * w + 10] = 1.0;
        gaussian_smooth(&mut z, w, h, 1.0, 1.0);
        let total: f64 = z.iter().sum();
        assert!((total - 1.0).abs() < 1e-9, "{total}");
        assert!(z[10 * w + 10] < 0.2 && z[10 * w + 11] > 0.05);
    }
}
