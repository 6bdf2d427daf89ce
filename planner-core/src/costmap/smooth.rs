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

/// out[i] = Σ_j weights[j]·lines[j][i], added in j order (so the same bits
/// as each cell's own dot product), a whole line per weight so it
/// vectorises; compiled also for AVX2 and picked at run time.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx512bw+avx512dq+avx2+fma",
    "x86_64+avx2+fma",
    "x86_64+avx"
))]
fn weighted_lines(out: &mut [f64], lines: &[&[f64]], weights: &[f64]) {
    out.fill(0.0);
    let n = out.len();
    for (line, &w) in lines.iter().zip(weights) {
        for (o, v) in out.iter_mut().zip(&line[..n]) {
            *o += w * v;
        }
    }
}

/// Smooths the `width`×`height` grid `z` in place with a Gaussian of σ =
/// `sigma_x` cells along rows and `sigma_y` cells along columns (0 on
/// an axis leaves it alone).
pub fn gaussian_smooth(z: &mut [f64], width: usize, height: usize, sigma_x: f64, sigma_y: f64) {
    if let Some(s) = Smoother::new(sigma_x, sigma_y, 3.0) {
        s.smooth_grid(z, width, height);
    }
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
    if let Some(s) = Smoother::new(sigma_x, sigma_y, 2.0) {
        s.smooth_grid(z, width, height);
    }
}

/// Rows of a grid per parallel task of [`Smoother::smooth_grid`].
const BAND_ROWS: usize = 32;

/// A kernel and its weights normalised to sum 1.
struct Kernel {
    k: Vec<f64>,
    kn: Vec<f64>,
}

impl Kernel {
    fn new(sigma_cells: f64, reach: f64) -> Option<Kernel> {
        (sigma_cells > 0.0).then(|| {
            let k = kernel(sigma_cells, reach);
            let norm: f64 = k.iter().sum();
            let kn = k.iter().map(|w| w / norm).collect();
            Kernel { k, kn }
        })
    }

    fn radius(&self) -> usize {
        self.k.len() / 2
    }
}

/// The separable smoothing, able to produce any band of rows of the
/// smoothed grid on its own — the same bits as smoothing the whole grid —
/// so a later stage can smooth band by band and never hold a second
/// copy of the grid.
pub struct Smoother {
    x: Option<Kernel>,
    y: Option<Kernel>,
}

impl Smoother {
    /// σ in cells per axis (≤ 0 leaves the axis alone), kernels cut at
    /// ⌈reach·σ⌉ cells; `None` when neither axis is smoothed.
    pub fn new(sigma_x: f64, sigma_y: f64, reach: f64) -> Option<Smoother> {
        let (x, y) = (Kernel::new(sigma_x, reach), Kernel::new(sigma_y, reach));
        (x.is_some() || y.is_some()).then_some(Smoother { x, y })
    }

    /// Rows above and below a band that its smoothing reads.
    pub fn reach_rows(&self) -> usize {
        self.y.as_ref().map_or(0, Kernel::radius)
    }

    /// The whole grid, in place (bands in parallel).
    pub fn smooth_grid(&self, z: &mut [f64], width: usize, height: usize) {
        if width == 0 || height == 0 {
            return;
        }
        let mut out = vec![0.0; z.len()];
        let src: &[f64] = z;
        out.par_chunks_mut(BAND_ROWS * width)
            .enumerate()
            .for_each_init(Vec::new, |scratch, (b, band)| {
                let r0 = b * BAND_ROWS;
                let rows = r0..r0 + band.len() / width;
                self.smooth_rows(src, width, height, rows, band, scratch);
            });
        z.copy_from_slice(&out);
    }

    /// Rows `rows` of the smoothed `width`×`height` grid `z` into `out`
    /// (`rows.len()` × `width`); `scratch` is reused between calls.
    pub fn smooth_rows(
        &self,
        z: &[f64],
        width: usize,
        height: usize,
        rows: std::ops::Range<usize>,
        out: &mut [f64],
        scratch: &mut Vec<f64>,
    ) {
        let ry = self.reach_rows();
        let lo = rows.start.saturating_sub(ry);
        let hi = (rows.end + ry).min(height);
        // Rows lo..hi smoothed along x into `scratch` (every cell written:
        // reused from call to call without clearing).
        scratch.resize((hi - lo) * width, 0.0);
        for (j, line) in scratch.chunks_mut(width).enumerate() {
            let row = &z[(lo + j) * width..(lo + j + 1) * width];
            match &self.x {
                Some(k) => smooth_line(row, k, line),
                None => line.copy_from_slice(row),
            }
        }
        let Some(k) = &self.y else {
            out.copy_from_slice(&scratch[(rows.start - lo) * width..(rows.end - lo) * width]);
            return;
        };
        let r = k.radius() as isize;
        for (row, line) in rows.zip(out.chunks_mut(width)) {
            let (top, bottom) = (row as isize - r, row as isize + r);
            let inside = top >= 0 && bottom < height as isize;
            let at = |j: isize| {
                let j = j as usize - lo;
                &scratch[j * width..(j + 1) * width]
            };
            if inside {
                // Whole kernel inside: a weighted sum of rows, NaN where
                // the kernel meets a NaN (done again below).
                let lines: Vec<&[f64]> = (top..=bottom).map(at).collect();
                weighted_lines(line, &lines, &k.kn);
                if !any_nan(line) {
                    continue;
                }
            }
            let centre_row = at(row as isize);
            for (col, o) in line.iter_mut().enumerate() {
                if inside && !o.is_nan() {
                    continue;
                }
                let centre = centre_row[col];
                if centre.is_nan() {
                    *o = f64::NAN;
                    continue;
                }
                let (mut s, mut w) = (0.0, 0.0);
                let from = top.max(0);
                let to = bottom.min(height as isize - 1);
                for j in from..=to {
                    let v = at(j)[col];
                    if !v.is_nan() {
                        let kw = k.k[(j - top) as usize];
                        s += kw * v;
                        w += kw;
                    }
                }
                *o = s / w;
            }
        }
    }
}

/// Whether `v` holds a NaN: a branch-free scan that vectorises, to skip
/// the cell-by-cell redo of lines without one (most).
fn any_nan(v: &[f64]) -> bool {
    v.iter().fold(false, |a, x| a | x.is_nan())
}

/// One row smoothed along x into `out`: the edges with renormalised
/// weights, the cells whose kernel lies inside the row as one weighted
/// sum; the sum is NaN where the kernel meets a NaN, and those cells are
/// done again with the renormalised weights.
fn smooth_line(row: &[f64], k: &Kernel, out: &mut [f64]) {
    let width = row.len();
    let r = k.radius();
    if width > 2 * r {
        pass_line(row, &k.k, out, 0..r);
        pass_line(row, &k.k, out, width - r..width);
        let lines: Vec<&[f64]> = (0..k.k.len()).map(|j| &row[j..]).collect();
        weighted_lines(&mut out[r..width - r], &lines, &k.kn);
        if !any_nan(&out[r..width - r]) {
            return;
        }
        for c in r..width - r {
            if out[c].is_nan() {
                pass_line(row, &k.k, out, c..c + 1);
            }
        }
    } else {
        pass_line(row, &k.k, out, 0..width);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Lcg;

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
    fn any_band_of_rows_equals_the_whole_grid_smoothed() {
        let (w, h) = (37, 41);
        let mut s = Lcg(5);
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let u = s.next();
                if i % 53 == 7 { f64::NAN } else { 100.0 + u }
            })
            .collect();
        for (sx, sy) in [(0.5, 0.5), (1.3, 0.7), (0.0, 2.0), (1.5, 0.0)] {
            let mut whole = z.clone();
            gaussian_smooth(&mut whole, w, h, sx, sy);
            let smoother = Smoother::new(sx, sy, 3.0).unwrap();
            let mut scratch = Vec::new();
            for (r0, r1) in [(0, 1), (0, 7), (3, 11), (20, 41), (40, 41), (0, 41)] {
                let mut band = vec![0.0; (r1 - r0) * w];
                smoother.smooth_rows(&z, w, h, r0..r1, &mut band, &mut scratch);
                let want = &whole[r0 * w..r1 * w];
                for (i, (a, b)) in band.iter().zip(want).enumerate() {
                    assert!(
                        a.to_bits() == b.to_bits(),
                        "{sx} {sy} rows {r0}..{r1} cell {i}"
                    );
                }
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
