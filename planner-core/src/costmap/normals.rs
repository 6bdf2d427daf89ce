//! Surface normals by PCA (thesis §3.3, SPEC §4.2 step 2): for each cell,
//! the eigenvector of the smallest eigenvalue of the covariance of the
//! cells within a radius; Zcomp = |n_z| = cos(slope). The smallest
//! eigenvalue is the variance of the cells' distances from their fitted
//! plane, so its square root is the roughness (seed 000).
//!
//! Coordinates are taken relative to the centre cell (its x, y and
//! height), never as raw UTM values or heights, which would cost the
//! covariance most of its digits. The eigenpair comes from the closed
//! form for symmetric 3 × 3 matrices; where the two smallest eigenvalues
//! are too close for it to separate the vectors, nalgebra's
//! `SymmetricEigen` decides — and, since that returns them unsorted, the
//! smallest is picked explicitly.

use nalgebra::{Matrix3, SymmetricEigen};
use rayon::prelude::*;

use super::CostmapError;
use super::progress::Ticker;
use super::smooth::Smoother;

/// A cell's neighbourhood within `radius_m`, cells `sx`×`sy` metres:
/// (column offset, row offset, x metres, y metres), the centre excluded.
pub fn neighbourhood(radius_m: f64, sx: f64, sy: f64) -> Vec<(isize, isize, f64, f64)> {
    // Bounded whatever the cells (the checks keep radii far below this;
    // it guards against degenerate cells, e.g. at a pole).
    const MOST: f64 = 4.0 * super::MAX_RADIUS_CELLS;
    let rx = (radius_m / sx).floor().min(MOST) as isize;
    let ry = (radius_m / sy).floor().min(MOST) as isize;
    let mut out = Vec::new();
    for dr in -ry..=ry {
        for dc in -rx..=rx {
            let (x, y) = (dc as f64 * sx, -(dr as f64) * sy);
            if (dc, dr) != (0, 0) && x * x + y * y <= radius_m * radius_m * (1.0 + 1e-12) {
                out.push((dc, dr, x, y));
            }
        }
    }
    out
}

/// Rows per parallel task of [`normals`].
const BAND_ROWS: usize = 32;

/// Zcomp (and roughness, metres, when asked) of every cell of the
/// `width`×`height` heights `z` (NaN = unknown), smoothed first by
/// `smoother` if given — band by band, so the smoothed grid is never held
/// whole. Cells with no valid neighbour are NaN. With fewer than 3 valid
/// neighbours, or neighbours all on one line, no plane is defined: Zcomp
/// is then the cosine of the steepest slope from the centre to a
/// neighbour (a conservative bound) and the roughness 0.
#[allow(clippy::too_many_arguments)]
pub fn normals(
    z: &[f64],
    width: usize,
    height: usize,
    row_size_m: &[[f64; 2]],
    radius_m: f64,
    smoother: Option<&Smoother>,
    want_roughness: bool,
    ticker: &Ticker,
) -> Result<(Vec<f32>, Option<Vec<f32>>), CostmapError> {
    let mut zcomp = crate::buffer::filled(width * height, f32::NAN);
    let mut rough = want_roughness.then(|| crate::buffer::filled(width * height, f32::NAN));
    if width == 0 || height == 0 {
        return Ok((zcomp, rough));
    }
    let job = NormalsJob::new(z, width, height, row_size_m, radius_m, smoother);
    let band = BAND_ROWS * width;
    match rough.as_mut() {
        Some(rough) => zcomp
            .par_chunks_mut(band)
            .zip(rough.par_chunks_mut(band))
            .enumerate()
            .for_each_init(Default::default, |buf, (b, (a, r))| {
                job.band(b * BAND_ROWS, a, Some(r), buf, ticker)
            }),
        None => zcomp
            .par_chunks_mut(band)
            .enumerate()
            .for_each_init(Default::default, |buf, (b, a)| {
                job.band(b * BAND_ROWS, a, None, buf, ticker)
            }),
    }
    if ticker.cancelled() {
        return Err(CostmapError::Cancelled);
    }
    Ok((zcomp, rough))
}

/// The normals of any band of rows of a grid on its own, smoothing the
/// rows it reads first.
pub(super) struct NormalsJob<'a> {
    z: &'a [f64],
    width: usize,
    height: usize,
    row_size_m: &'a [[f64; 2]],
    radius_m: f64,
    smoother: Option<&'a Smoother>,
    /// Rows above and below a row that its neighbourhood reads.
    reach: usize,
}

/// What [`NormalsJob::band`] reuses from band to band: the smoothed rows
/// the smoother's scratch and the row pass's λs.
pub(super) type NormalsScratch = (Vec<f64>, Vec<f64>, Vec<f64>);

impl<'a> NormalsJob<'a> {
    pub(super) fn new(
        z: &'a [f64],
        width: usize,
        height: usize,
        row_size_m: &'a [[f64; 2]],
        radius_m: f64,
        smoother: Option<&'a Smoother>,
    ) -> NormalsJob<'a> {
        let reach = row_size_m
            .iter()
            .map(|&[sx, sy]| {
                neighbourhood(radius_m, sx, sy)
                    .iter()
                    .map(|h| h.1.unsigned_abs())
                    .max()
                    .unwrap_or(0)
            })
            .max()
            .unwrap_or(0);
        NormalsJob {
            z,
            width,
            height,
            row_size_m,
            radius_m,
            smoother,
            reach,
        }
    }

    pub(super) fn z(&self) -> &'a [f64] {
        self.z
    }

    pub(super) fn width(&self) -> usize {
        self.width
    }

    pub(super) fn height(&self) -> usize {
        self.height
    }

    /// Zcomp (and roughness) of the rows from `r0` into `zc_band` (whole
    /// rows, pre-filled with NaN) and `rough_band`, a tick of `ticker` per
    /// row; stops early once it is cancelled.
    pub(super) fn band(
        &self,
        r0: usize,
        zc_band: &mut [f32],
        mut rough_band: Option<&mut [f32]>,
        (smoothed, scratch, settled): &mut NormalsScratch,
        ticker: &Ticker,
    ) {
        let (z, width, height) = (self.z, self.width, self.height);
        let r1 = r0 + zc_band.len() / width;
        // The rows the band's neighbourhoods read, smoothed if asked.
        let (l0, l1) = (r0.saturating_sub(self.reach), (r1 + self.reach).min(height));
        let local: &[f64] = match self.smoother {
            Some(s) => {
                smoothed.resize((l1 - l0) * width, 0.0);
                s.smooth_rows(z, width, height, l0..l1, smoothed, scratch);
                smoothed
            }
            None => &z[l0 * width..l1 * width],
        };
        for (k, zc_row) in zc_band.chunks_mut(width).enumerate() {
            if !ticker.tick() {
                return;
            }
            let rough_row = rough_band
                .as_deref_mut()
                .map(|rb| &mut rb[k * width..(k + 1) * width]);
            let r = r0 + k;
            normal_row(
                local,
                width,
                l1 - l0,
                r - l0,
                self.row_size_m[r],
                self.radius_m,
                zc_row,
                rough_row,
                settled,
            );
        }
    }
}

/// Zcomp (and roughness) of row `r` of the `width`×`height` heights `z`
/// (a band of the grid with the rows its neighbourhoods read).
#[allow(clippy::too_many_arguments)]
fn normal_row(
    z: &[f64],
    width: usize,
    height: usize,
    r: usize,
    [sx, sy]: [f64; 2],
    radius_m: f64,
    zc_row: &mut [f32],
    mut rough_row: Option<&mut [f32]>,
    settled: &mut Vec<f64>,
) {
    let hood = neighbourhood(radius_m, sx, sy);
    let full = FullWindow::new(&hood, width);
    let inner_rows = r >= full.reach_rows && r + full.reach_rows < height;
    // The default 3 × 3 window: the whole row at once, then the cells it
    // could not settle one by one.
    let batched = inner_rows && width >= 3 && full.three_by_three.is_some();
    let mut redo = Vec::new();
    if batched {
        full.row_3x3(z, r, zc_row, rough_row.as_deref_mut(), settled, &mut redo);
        redo.push(0);
        redo.push(width - 1);
    }
    let cells: Box<dyn Iterator<Item = usize>> = if batched {
        Box::new(redo.into_iter())
    } else {
        Box::new(0..width)
    };
    for c in cells {
        let i = r * width + c;
        let zc = z[i];
        if zc.is_nan() {
            continue;
        }
        let inner = inner_rows && c >= full.reach_cols && c + full.reach_cols < width;
        let fast = if inner { full.normal(z, i, zc) } else { None };
        if let Some((n, rms)) = fast.or_else(|| cell_normal(z, width, height, r, c, zc, &hood)) {
            zc_row[c] = n as f32;
            if let Some(rr) = rough_row.as_deref_mut() {
                rr[c] = rms as f32;
            }
        }
    }
}

/// A complete neighbourhood, all of whose cells are inside the grid: its
/// offsets are symmetric about the centre, so Σx = Σy = Σxy = 0 and the
/// covariance is the "arrow" matrix [[a, 0, p], [0, b, q], [p, q, c]].
/// Its smallest eigenvalue is the root below min(a, b) of the secular
/// equation c − λ − p²/(a − λ) − q²/(b − λ) = 0, found by safeguarded
/// Newton steps from λ = 0 (exact for a plane), and the normal is
/// (p/(λ − a), q/(λ − b), 1) normalised. About 4× quicker than the
/// general eigensolver, which takes over where this is ill-conditioned.
struct FullWindow {
    /// Index offsets of the neighbours and their x, y (m).
    offsets: Vec<isize>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    /// Points including the centre.
    n: f64,
    /// Σx²/n and Σy²/n.
    a: f64,
    b: f64,
    reach_cols: usize,
    reach_rows: usize,
    /// Cell size [x, y] when the window is exactly the 8 neighbours.
    three_by_three: Option<[f64; 2]>,
    width: usize,
}

impl FullWindow {
    fn new(hood: &[(isize, isize, f64, f64)], width: usize) -> FullWindow {
        let n = (hood.len() + 1) as f64;
        FullWindow {
            offsets: hood
                .iter()
                .map(|&(dc, dr, _, _)| dr * width as isize + dc)
                .collect(),
            xs: hood.iter().map(|h| h.2).collect(),
            ys: hood.iter().map(|h| h.3).collect(),
            n,
            a: hood.iter().map(|h| h.2 * h.2).sum::<f64>() / n,
            b: hood.iter().map(|h| h.3 * h.3).sum::<f64>() / n,
            reach_cols: hood.iter().map(|h| h.0.unsigned_abs()).max().unwrap_or(0),
            reach_rows: hood.iter().map(|h| h.1.unsigned_abs()).max().unwrap_or(0),
            three_by_three: (hood.len() == 8
                && hood.iter().all(|h| h.0.abs() <= 1 && h.1.abs() <= 1))
            .then(|| {
                let east = hood
                    .iter()
                    .find(|h| (h.0, h.1) == (1, 0))
                    .map_or(0.0, |h| h.2);
                let north = hood
                    .iter()
                    .find(|h| (h.0, h.1) == (0, -1))
                    .map_or(0.0, |h| h.3);
                [east, north]
            }),
            width,
        }
    }

    /// Zcomp (and roughness) of the cells 1 … width − 2 of inner row `r`
    /// with the 3 × 3 window, in one branch-free pass the compiler can
    /// vectorise: a fixed three Newton steps from λ = 0. Columns it cannot
    /// settle (an unknown height, no convergence in three steps, λ near
    /// min(a, b)) are left for [`FullWindow::normal`] and listed in `redo`.
    fn row_3x3(
        &self,
        z: &[f64],
        r: usize,
        zc_out: &mut [f32],
        rough_out: Option<&mut [f32]>,
        settled: &mut Vec<f64>,
        redo: &mut Vec<usize>,
    ) {
        let w = self.width;
        let [sx, sy] = self.three_by_three.expect("a 3 × 3 window");
        let up = &z[(r - 1) * w..r * w];
        let mid = &z[r * w..(r + 1) * w];
        let down = &z[(r + 1) * w..(r + 2) * w];
        let m = w - 2;
        // λ per cell, NaN where the row pass could not settle it (every
        // one written: reused from row to row without clearing).
        settled.resize(m, 0.0);
        settle_row_3x3(
            [up, mid, down],
            [sx, sy],
            [self.a, self.b, self.n],
            &mut zc_out[1..m + 1],
            settled,
        );
        if let Some(rough) = rough_out {
            for (o, &l) in rough[1..m + 1].iter_mut().zip(settled.iter()) {
                *o = if l > 0.0 {
                    l.sqrt() as f32
                } else if l == 0.0 {
                    0.0
                } else {
                    f32::NAN
                };
            }
        }
        redo.extend((0..m).filter(|&k| settled[k].is_nan()).map(|k| k + 1));
    }

    /// (Zcomp, roughness) of the inner cell `i`; `None` when a neighbour
    /// is unknown or the secular equation is ill-conditioned.
    #[inline]
    fn normal(&self, z: &[f64], i: usize, zc: f64) -> Option<(f64, f64)> {
        let (sz, szz, sxz, syz) = if let Some([sx, sy]) = self.three_by_three {
            // The default 3 × 3 window, unrolled.
            let w = self.width;
            let (nw, n, ne) = (z[i - w - 1] - zc, z[i - w] - zc, z[i - w + 1] - zc);
            let (we, ea) = (z[i - 1] - zc, z[i + 1] - zc);
            let (sw, s, se) = (z[i + w - 1] - zc, z[i + w] - zc, z[i + w + 1] - zc);
            (
                nw + n + ne + we + ea + sw + s + se,
                nw * nw + n * n + ne * ne + we * we + ea * ea + sw * sw + s * s + se * se,
                sx * ((ne + ea + se) - (nw + we + sw)),
                sy * ((nw + n + ne) - (sw + s + se)),
            )
        } else {
            if self.offsets.len() < 4 {
                return None;
            }
            let (mut sz, mut szz, mut sxz, mut syz) = (0.0, 0.0, 0.0, 0.0);
            for ((&o, &x), &y) in self.offsets.iter().zip(&self.xs).zip(&self.ys) {
                let h = z[(i as isize + o) as usize] - zc;
                sz += h;
                szz += h * h;
                sxz += x * h;
                syz += y * h;
            }
            (sz, szz, sxz, syz)
        };
        if !(sz + szz).is_finite() {
            return None;
        }
        let (a, b, n) = (self.a, self.b, self.n);
        let mz = sz / n;
        let (p, q) = (sxz / n, syz / n);
        let c = szz / n - mz * mz;
        let (pp, qq) = (p * p, q * q);
        // f(λ), f′(λ) and the reciprocals 1/(a − λ), 1/(b − λ) they share.
        let eval = |l: f64| {
            let (ia, ib) = (1.0 / (a - l), 1.0 / (b - l));
            (
                c - l - pp * ia - qq * ib,
                -1.0 - pp * ia * ia - qq * ib * ib,
                ia,
                ib,
            )
        };
        let hi0 = a.min(b);
        let (mut lo, mut hi) = (0.0, hi0);
        let mut l = 0.0;
        let (mut fl, mut dl, mut ia, mut ib) = eval(0.0);
        let scale = a + b + c.abs();
        if fl > 1e-15 * scale {
            let mut converged = false;
            for _ in 0..30 {
                let mut next = l - fl / dl;
                if !(next > lo && next < hi) {
                    next = 0.5 * (lo + hi);
                }
                let step = (next - l).abs();
                l = next;
                (fl, dl, ia, ib) = eval(l);
                if fl > 0.0 {
                    lo = l;
                } else {
                    hi = l;
                }
                if step <= 1e-11 * scale || fl == 0.0 {
                    converged = true;
                    break;
                }
            }
            if !converged || hi0 - l < 1e-6 * hi0 {
                return None;
            }
        }
        let gx = p * ia;
        let gy = q * ib;
        Some((1.0 / (1.0 + gx * gx + gy * gy).sqrt(), l.max(0.0).sqrt()))
    }
}

/// The row pass of [`FullWindow::row_3x3`]: Zcomp into `zc_out` and λ into
/// `settled` (NaN where not settled) for cells 1 … width − 2 of the rows
/// `up`, `mid`, `down`. Compiled also for AVX2 and picked at run time;
/// without `mul_add` the results are the same bits on every target.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx512bw+avx512dq+avx2+fma",
    "x86_64+avx2+fma",
    "x86_64+avx"
))]
fn settle_row_3x3(
    [up, mid, down]: [&[f64]; 3],
    [sx, sy]: [f64; 2],
    [a, b, n]: [f64; 3],
    zc_out: &mut [f32],
    settled: &mut [f64],
) {
    let m = settled.len();
    let (ia0, ib0) = (1.0 / a, 1.0 / b);
    let hi0 = a.min(b);
    let inv_n = 1.0 / n;
    // Slices of one length, indexed alike, so the loop has no bounds
    // checks or branches and vectorises; column k is cell k + 1.
    let (u0, u1, u2) = (&up[..m], &up[1..m + 1], &up[2..m + 2]);
    let (m0, m1, m2) = (&mid[..m], &mid[1..m + 1], &mid[2..m + 2]);
    let (d0_, d1_, d2_) = (&down[..m], &down[1..m + 1], &down[2..m + 2]);
    let zc_out = &mut zc_out[..m];
    for k in 0..m {
        let zc = m1[k];
        let (nw, no, ne) = (u0[k] - zc, u1[k] - zc, u2[k] - zc);
        let (we, ea) = (m0[k] - zc, m2[k] - zc);
        let (sw, so, se) = (d0_[k] - zc, d1_[k] - zc, d2_[k] - zc);
        let sz = nw + no + ne + we + ea + sw + so + se;
        let szz = nw * nw + no * no + ne * ne + we * we + ea * ea + sw * sw + so * so + se * se;
        let p = sx * ((ne + ea + se) - (nw + we + sw)) * inv_n;
        let q = sy * ((nw + no + ne) - (sw + so + se)) * inv_n;
        let mz = sz * inv_n;
        let cv = szz * inv_n - mz * mz;
        let (pp, qq) = (p * p, q * q);
        let scale = a + b + cv.abs();
        // f(λ) = cv − λ − p²/(a − λ) − q²/(b − λ) is concave and falls,
        // so from f(0) > 0 the first step lands at or past the root and
        // the next ones come back to it monotonically.
        let f0 = cv - pp * ia0 - qq * ib0;
        let df0 = -1.0 - pp * ia0 * ia0 - qq * ib0 * ib0;
        let plane = f0 <= 1e-15 * scale;
        let l1 = -f0 / df0;
        let (ia1, ib1) = reciprocals(a - l1, b - l1);
        let f1 = cv - l1 - pp * ia1 - qq * ib1;
        let df1 = -1.0 - pp * ia1 * ia1 - qq * ib1 * ib1;
        let l2 = l1 - f1 / df1;
        let (ia2, ib2) = reciprocals(a - l2, b - l2);
        let f2 = cv - l2 - pp * ia2 - qq * ib2;
        let df2 = -1.0 - pp * ia2 * ia2 - qq * ib2 * ib2;
        let l3 = l2 - f2 / df2;
        let (ia3, ib3) = reciprocals(a - l3, b - l3);
        // `&`, not `&&`: no branches. NaN heights fail every test.
        let good =
            ((l3 - l2).abs() <= 1e-11 * scale) & (l1 < hi0) & (l3 > 0.0) & (hi0 - l3 >= 1e-6 * hi0);
        let ok = plane | good;
        let l = if plane { 0.0 } else { l3 };
        let ia = if plane { ia0 } else { ia3 };
        let ib = if plane { ib0 } else { ib3 };
        let (gx, gy) = (p * ia, q * ib);
        let zcomp = 1.0 / (1.0 + gx * gx + gy * gy).sqrt();
        zc_out[k] = if ok { zcomp as f32 } else { f32::NAN };
        settled[k] = if ok { l } else { f64::NAN };
    }
}

/// (1/x, 1/y) with one division: dividing is most of the row pass's time.
#[inline(always)]
fn reciprocals(x: f64, y: f64) -> (f64, f64) {
    let inv = 1.0 / (x * y);
    (y * inv, x * inv)
}

/// (Zcomp, roughness) of cell (r, c) with height `zc`.
fn cell_normal(
    z: &[f64],
    width: usize,
    height: usize,
    r: usize,
    c: usize,
    zc: f64,
    hood: &[(isize, isize, f64, f64)],
) -> Option<(f64, f64)> {
    // Sums over the centre (all zero) and its valid neighbours.
    let (mut n, mut sx, mut sy, mut sz) = (1.0f64, 0.0, 0.0, 0.0);
    let (mut sxx, mut syy, mut szz, mut sxy, mut sxz, mut syz) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0);
    let mut steepest: f64 = 0.0;
    let mut neighbours = 0usize;
    for &(dc, dr, x, y) in hood {
        let (rr, cc) = (r as isize + dr, c as isize + dc);
        if rr < 0 || cc < 0 || rr >= height as isize || cc >= width as isize {
            continue;
        }
        let v = z[rr as usize * width + cc as usize];
        if v.is_nan() {
            continue;
        }
        let h = v - zc;
        neighbours += 1;
        n += 1.0;
        sx += x;
        sy += y;
        sz += h;
        sxx += x * x;
        syy += y * y;
        szz += h * h;
        sxy += x * y;
        sxz += x * h;
        syz += y * h;
        steepest = steepest.max(h.abs() / x.hypot(y));
    }
    if neighbours == 0 {
        return None;
    }
    let (mx, my, mz) = (sx / n, sy / n, sz / n);
    let cxx = sxx / n - mx * mx;
    let cyy = syy / n - my * my;
    let cxy = sxy / n - mx * my;
    let fallback = Some((1.0 / steepest.hypot(1.0), 0.0));
    // A plane needs 3 neighbours not on one line (xy covariance of full rank).
    if neighbours < 3 || cxx * cyy - cxy * cxy <= 1e-9 * (cxx + cyy) * (cxx + cyy) {
        return fallback;
    }
    let cov = [
        [cxx, cxy, sxz / n - mx * mz],
        [cxy, cyy, syz / n - my * mz],
        [sxz / n - mx * mz, syz / n - my * mz, szz / n - mz * mz],
    ];
    let (lambda, normal) = smallest_eigenpair(&cov);
    Some((normal[2].abs().min(1.0), lambda.max(0.0).sqrt()))
}

/// The smallest eigenvalue of the symmetric matrix `a` and a unit
/// eigenvector of it.
pub fn smallest_eigenpair(a: &[[f64; 3]; 3]) -> (f64, [f64; 3]) {
    let p1 = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let p2 = (a[0][0] - q).powi(2) + (a[1][1] - q).powi(2) + (a[2][2] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if p > 0.0 && p.is_finite() {
        // Closed form (Smith 1961): eigenvalues q + 2p·cos(φ + 2πk/3).
        let b = |i: usize, j: usize| (a[i][j] - if i == j { q } else { 0.0 }) / p;
        let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(2, 1))
            - b(0, 1) * (b(1, 0) * b(2, 2) - b(1, 2) * b(2, 0))
            + b(0, 2) * (b(1, 0) * b(2, 1) - b(1, 1) * b(2, 0));
        let phi = (det / 2.0).clamp(-1.0, 1.0).acos() / 3.0;
        let lambda = q + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
        // The eigenvector is orthogonal to the rows of A − λI: the largest
        // cross product of two rows.
        let row = |i: usize| {
            let mut v = a[i];
            v[i] -= lambda;
            v
        };
        let (r0, r1, r2) = (row(0), row(1), row(2));
        let mut best = [0.0; 3];
        let mut best_norm = 0.0;
        for v in [cross(r0, r1), cross(r0, r2), cross(r1, r2)] {
            let norm = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if norm > best_norm {
                best = v;
                best_norm = norm;
            }
        }
        // Well separated from the middle eigenvalue: the cross product is
        // of the order of p²; near a double eigenvalue it vanishes.
        if best_norm > 1e-12 * p2 * p2 {
            let s = best_norm.sqrt();
            return (lambda, [best[0] / s, best[1] / s, best[2] / s]);
        }
    }
    let m = Matrix3::from_fn(|i, j| a[i][j]);
    let eig = SymmetricEigen::new(m);
    let (k, &lambda) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|x, y| x.1.total_cmp(y.1))
        .expect("three eigenvalues");
    let v = eig.eigenvectors.column(k);
    (lambda, [v[0], v[1], v[2]])
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::progress::Ticker;
    use crate::costmap::{Progress, Stage};
    use crate::test_rng::Lcg;

    fn quiet() -> impl Progress {
        |_: Stage, _: f64| true
    }

    /// z = x·tan(slope) along `azimuth` on a `w`×`h` grid of `cell` m.
    fn tilted(w: usize, h: usize, cell: f64, slope_deg: f64, azimuth_deg: f64) -> Vec<f64> {
        let g = slope_deg.to_radians().tan();
        let (ux, uy) = (
            azimuth_deg.to_radians().sin(),
            azimuth_deg.to_radians().cos(),
        );
        (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f64 * cell, -((i / w) as f64) * cell);
                1500.0 + g * (x * ux + y * uy)
            })
            .collect()
    }

    #[test]
    fn tilted_planes_give_cos_slope_exactly() {
        let p = quiet();
        for &(slope, az, cell, radius) in &[
            (0.0, 0.0, 1.0, 1.5),
            (10.0, 30.0, 0.1, 0.15),
            (24.99, 200.0, 5.0, 7.5),
            (25.01, 95.0, 2.0, 5.0),
            (45.0, 0.0, 1.0, 3.0),
            (70.0, 310.0, 0.5, 0.75),
        ] {
            let (w, h) = (9, 8);
            let z = tilted(w, h, cell, slope, az);
            let t = Ticker::new(&p, Stage::Normals, h);
            let (zc, rough) =
                normals(&z, w, h, &vec![[cell, cell]; h], radius, None, true, &t).unwrap();
            let want = f64::to_radians(slope).cos();
            for (i, (&got, &rms)) in zc.iter().zip(rough.as_ref().unwrap()).enumerate() {
                assert!(
                    (f64::from(got) - want).abs() < 1e-6,
                    "slope {slope} cell {i}: {got} vs {want}"
                );
                assert!(rms < 1e-4, "{rms}");
            }
        }
    }

    #[test]
    fn eigenpairs_match_nalgebra_on_random_matrices() {
        let mut s = Lcg(12345u64);
        let mut rnd = || s.next() * 2.0 - 1.0;
        for _ in 0..2000 {
            let m = [
                [rnd(), rnd(), rnd()],
                [0.0, rnd(), rnd()],
                [0.0, 0.0, rnd()],
            ];
            let a = [
                [m[0][0], m[0][1], m[0][2]],
                [m[0][1], m[1][1], m[1][2]],
                [m[0][2], m[1][2], m[2][2]],
            ];
            let (lambda, v) = smallest_eigenpair(&a);
            let eig = SymmetricEigen::new(Matrix3::from_fn(|i, j| a[i][j]));
            let want = eig.eigenvalues.min();
            assert!((lambda - want).abs() < 1e-9, "{lambda} vs {want}");
            // A·v = λ·v.
            for (i, row) in a.iter().enumerate() {
                let av = row[0] * v[0] + row[1] * v[1] + row[2] * v[2];
                assert!((av - lambda * v[i]).abs() < 1e-6, "{a:?}");
            }
        }
        // Repeated eigenvalues go to nalgebra and still give the smallest.
        let (lambda, v) = smallest_eigenpair(&[[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        assert_eq!(lambda, 1.0);
        assert!(v[0].abs() < 1e-12);
    }

    #[test]
    fn the_fast_window_agrees_with_the_general_eigensolver() {
        let mut s = Lcg(99u64);
        let mut rnd = || s.next();
        let (w, h) = (9, 9);
        for case in 0..500 {
            let roughness = [0.0, 0.01, 0.3, 3.0][case % 4];
            let (gx, gy) = (rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0);
            let z: Vec<f64> = (0..w * h)
                .map(|i| gx * (i % w) as f64 + gy * (i / w) as f64 + roughness * rnd())
                .collect();
            let radius = [1.5, 1.3, 2.3, 1.6, 1.7][case % 5];
            let hood = neighbourhood(radius, 1.0, 1.2);
            let full = FullWindow::new(&hood, w);
            let i = 4 * w + 4;
            let general = cell_normal(&z, w, h, 4, 4, z[i], &hood).unwrap();
            if let Some(fast) = full.normal(&z, i, z[i]) {
                assert!(
                    (fast.0 - general.0).abs() < 1e-9,
                    "{case}: {fast:?} {general:?}"
                );
                assert!(
                    (fast.1 - general.1).abs() < 1e-7,
                    "{case}: {fast:?} {general:?}"
                );
            } else {
                assert!(
                    roughness >= 0.3,
                    "{case}: the fast path gave up on a smooth window"
                );
            }
        }
    }

    #[test]
    fn smoothing_band_by_band_equals_smoothing_the_whole_grid_first() {
        let p = quiet();
        let (w, h) = (45, 101);
        let mut s = Lcg(3);
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let noise = s.next();
                if i % 97 == 11 {
                    f64::NAN
                } else {
                    800.0 + 0.3 * (i % w) as f64 + 0.5 * noise
                }
            })
            .collect();
        let rows = vec![[0.5, 0.6]; h];
        for radius in [0.9, 1.5, 2.3] {
            let smoother = Smoother::new(0.8, 1.1, 3.0).unwrap();
            let t = Ticker::new(&p, Stage::Normals, h);
            let (banded, rough_banded) =
                normals(&z, w, h, &rows, radius, Some(&smoother), true, &t).unwrap();
            let mut smoothed = z.clone();
            smoother.smooth_grid(&mut smoothed, w, h);
            let (whole, rough_whole) =
                normals(&smoothed, w, h, &rows, radius, None, true, &t).unwrap();
            let same =
                |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same(&banded, &whole), "radius {radius}");
            assert!(same(&rough_banded.unwrap(), &rough_whole.unwrap()));
        }
    }

    #[test]
    fn the_row_pass_equals_the_cell_by_cell_window() {
        // Rough, tilted ground: the row pass settles most cells; each must
        // agree with the safeguarded one-cell solver.
        let p = quiet();
        let (w, h) = (60, 5);
        let mut s = Lcg(17);
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let noise = s.next();
                let roughness = [0.0, 0.01, 0.1, 1.0][(i % w) / 15];
                1200.0 + 0.4 * (i % w) as f64 - 0.7 * (i / w) as f64 + roughness * noise
            })
            .collect();
        let t = Ticker::new(&p, Stage::Normals, h);
        let (zc, rough) = normals(&z, w, h, &[[1.0, 1.2]; 5], 1.6, None, true, &t).unwrap();
        let hood = neighbourhood(1.6, 1.0, 1.2);
        let full = FullWindow::new(&hood, w);
        for r in 1..h - 1 {
            for c in 1..w - 1 {
                let i = r * w + c;
                let (want, want_rms) = full
                    .normal(&z, i, z[i])
                    .or_else(|| cell_normal(&z, w, h, r, c, z[i], &hood))
                    .unwrap();
                assert!((f64::from(zc[i]) - want).abs() < 1e-7, "{r} {c}");
                let rms = f64::from(rough.as_ref().unwrap()[i]);
                assert!((rms - want_rms).abs() < 1e-6 * (1.0 + want_rms), "{r} {c}");
            }
        }
    }

    #[test]
    fn few_neighbours_fall_back_to_the_steepest_slope() {
        let p = quiet();
        // A 3×3 grid with only the centre, one east neighbour (rise 1 m in
        // 1 m: 45°) and one north neighbour (flat) valid.
        let n = f64::NAN;
        #[rustfmt::skip]
        let z = vec![
            n, 5.0, n,
            n, 5.0, 6.0,
            n, n, n,
        ];
        let t = Ticker::new(&p, Stage::Normals, 3);
        let (zc, _) = normals(&z, 3, 3, &[[1.0, 1.0]; 3], 1.5, None, false, &t).unwrap();
        assert!((f64::from(zc[4]) - 45f64.to_radians().cos()).abs() < 1e-6);
        // A lone cell has no normal.
        let z = vec![n, n, n, n, 1.0, n, n, n, n];
        let (zc, _) = normals(&z, 3, 3, &[[1.0, 1.0]; 3], 1.5, None, false, &t).unwrap();
        assert!(zc[4].is_nan());
    }

    #[test]
    fn neighbourhoods_are_disks_in_metres() {
        assert_eq!(neighbourhood(1.5, 1.0, 1.0).len(), 8);
        assert_eq!(neighbourhood(1.0, 1.0, 1.0).len(), 4);
        assert_eq!(neighbourhood(2.0, 1.0, 1.0).len(), 12);
        // Rectangular cells: 2 m wide, 1 m tall, radius 2 m.
        let h = neighbourhood(2.0, 2.0, 1.0);
        assert!(h.iter().all(|&(_, _, x, y)| x * x + y * y <= 4.0 + 1e-9));
        assert_eq!(h.len(), 6);
    }
}
