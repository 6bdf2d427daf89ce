//! Height discontinuities (thesis §3.4, SPEC §4.2 step 4), and ditches.
//!
//! `neighbours` is the thesis' test: a cell is a step when any of its 8
//! neighbours differs from it by more than max_step. On an even slope
//! neighbours differ by cell·tan(slope), so at coarse resolution every
//! allowed slope trips it (at 1 m and 25°, anything steeper than ~6°).
//!
//! `residual` measures each neighbour's difference against the local
//! surface instead: along the line through the cell and the neighbour, the
//! slope on the cell's side (the cell minus the one behind it) and on the
//! neighbour's side (the one beyond minus the neighbour) bound what a
//! continuous surface can do in between — a slope between the two, if it
//! bends there. The step is how far the difference falls outside those
//! bounds. The same is measured across two cells, centred on the cell,
//! against twice the outer slopes: a step that falls inside a cell (or is
//! averaged into one by resampling) leaves an intermediate height, 0, a,
//! h, which no one-cell difference shows but the two-cell one does. So an
//! even slope or a change of slope leaves nothing at any resolution; a
//! step of height h leaves h on the cells beside it (on the cell it
//! splits, if it splits one), on any slope; a one-cell wall or pit of
//! height h leaves h.
//!
//! Cells on the border ring, or next to unknown heights, cannot be judged
//! and are unknown.

use rayon::prelude::*;

use super::progress::Ticker;
use super::{CostmapError, StepMode};

/// The 8 neighbour offsets (column, row).
const DIRECTIONS: [(isize, isize); 8] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
];

/// Largest step (m) from each cell to its neighbours, by `mode`; NaN where
/// the cell cannot be judged.
pub fn step_heights(
    z: &[f64],
    width: usize,
    height: usize,
    mode: StepMode,
    ticker: &Ticker,
) -> Result<Vec<f32>, CostmapError> {
    let mut out = crate::buffer::filled(width * height, f32::NAN);
    let unknown = rows_with_unknown(z, width, 0..height);
    out.par_chunks_mut(width.max(1)).enumerate().for_each_init(
        StepScratch::default,
        |scratch, (r, row)| {
            if ticker.tick() {
                let clean = clean_rows(&unknown, 0, r);
                step_row(z, width, height, r, mode, clean, row, scratch);
            }
        },
    );
    if ticker.cancelled() {
        return Err(CostmapError::Cancelled);
    }
    Ok(out)
}

/// For each row of `rows`, whether it holds an unknown height.
pub(super) fn rows_with_unknown(
    z: &[f64],
    width: usize,
    rows: std::ops::Range<usize>,
) -> Vec<bool> {
    // A fold, not `any`: branch-free, so it vectorises.
    rows.map(|r| {
        z[r * width..(r + 1) * width]
            .iter()
            .fold(false, |a, v| a | v.is_nan())
    })
    .collect()
}

/// Whether rows r − 2 … r + 2 are all known, given `unknown` for the rows
/// from `first`; false where they are not all listed.
pub(super) fn clean_rows(unknown: &[bool], first: usize, r: usize) -> bool {
    r >= first + 2
        && unknown
            .get(r - first - 2..r - first + 3)
            .is_some_and(|u| !u.contains(&true))
}

/// What [`step_row`] reuses from row to row.
#[derive(Default)]
pub(super) struct StepScratch {
    worst: Vec<f64>,
    probe: Vec<f64>,
}

/// Step heights of row `r` of the `width`×`height` heights `z` into `row`
/// (all of it: NaN where a cell cannot be judged). `clean`: rows r − 2 …
/// r + 2 hold no unknown height, so the whole-line passes need not look
/// for one.
#[allow(clippy::too_many_arguments)]
pub(super) fn step_row(
    z: &[f64],
    width: usize,
    height: usize,
    r: usize,
    mode: StepMode,
    clean: bool,
    row: &mut [f32],
    scratch: &mut StepScratch,
) {
    row.fill(f32::NAN);
    if r == 0 || r + 1 >= height {
        return;
    }
    let at = |c: isize, r: isize| -> f64 {
        if c < 0 || r < 0 || c >= width as isize || r >= height as isize {
            f64::NAN
        } else {
            z[r as usize * width + c as usize]
        }
    };
    let w = width as isize;
    let mut offsets = [0isize; 8];
    for (o, &(dc, dr)) in offsets.iter_mut().zip(&DIRECTIONS) {
        *o = dr * w + dc;
    }
    // Rows and columns 2 cells in, where every cell the residual looks at
    // exists: no bounds checks.
    let inner_row = r >= 2 && r + 2 < height;
    let ri = r as isize;
    let last = width.saturating_sub(1);
    let lines = inner_row && width >= 5;
    let clean = clean && lines;
    if lines {
        // Whole lines at once; unless the rows are clean, the cells whose
        // tests met an unknown height (a NaN probe) are done again one by
        // one below.
        clean_row(z, width, r, mode, !clean, scratch);
        let out = row[2..width - 2].iter_mut().zip(&scratch.worst);
        if clean {
            out.for_each(|(o, &v)| *o = v as f32);
        } else {
            for ((o, &v), &p) in out.zip(&scratch.probe) {
                *o = if p.is_nan() { f32::NAN } else { v as f32 };
            }
        }
    }
    // Clean rows leave only the columns one in from the edges.
    let mut edges = [1, width.saturating_sub(2)].into_iter();
    let mut all = 1..last;
    let cells: &mut dyn Iterator<Item = usize> = if clean { &mut edges } else { &mut all };
    for c in cells {
        if lines && c >= 2 && c + 2 < width && !scratch.probe[c - 2].is_nan() {
            continue;
        }
        let out = &mut row[c];
        let i = r * width + c;
        let zc = z[i];
        if zc.is_nan() {
            continue;
        }
        if inner_row && c >= 2 && c + 2 < width {
            let worst = inner_step(z, i, zc, &offsets, mode);
            if !worst.is_nan() {
                *out = worst as f32;
            }
            continue;
        }
        let ci = c as isize;
        let mut worst = 0.0f64;
        let mut known = true;
        for (dc, dr) in DIRECTIONS {
            let zn = at(ci + dc, ri + dr);
            if zn.is_nan() {
                known = false;
                break;
            }
            let d0 = zn - zc;
            let s = match mode {
                StepMode::Neighbours => d0.abs(),
                StepMode::Residual => residual(
                    d0,
                    zc - at(ci - dc, ri - dr),
                    at(ci + 2 * dc, ri + 2 * dr) - zn,
                ),
            };
            worst = worst.max(s);
        }
        if known {
            *out = worst as f32;
        }
    }
}

/// Largest step of every cell 2 columns in of row `r` (into
/// `scratch.worst`, from column 2): the same tests as [`inner_step`], one
/// line direction at a time over whole rows. With `check`,
/// `scratch.probe` gets the sum of the heights each cell's tests read: NaN
/// exactly where one of them is unknown, and there `worst` is
/// meaningless.
fn clean_row(
    z: &[f64],
    width: usize,
    r: usize,
    mode: StepMode,
    check: bool,
    scratch: &mut StepScratch,
) {
    let n = width - 4;
    let StepScratch { worst, probe } = scratch;
    worst.clear();
    worst.resize(n, 0.0);
    probe.clear();
    if check {
        probe.resize(n, 0.0);
    }
    clean_row_lines(z, width, r, mode, worst, probe);
}

/// The loops of [`clean_row`], compiled also for AVX2 and picked at run
/// time (the same bits on every target). Plain comparisons stand in for
/// the NaN-aware `max`/`min`: cells that read a NaN are redone anyway.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512vl+avx512bw+avx512dq+avx2+fma",
    "x86_64+avx2+fma",
    "x86_64+avx"
))]
fn clean_row_lines(
    z: &[f64],
    width: usize,
    r: usize,
    mode: StepMode,
    worst: &mut [f64],
    probe: &mut [f64],
) {
    let n = worst.len();
    let max = |a: f64, b: f64| if a > b { a } else { b };
    let min = |a: f64, b: f64| if a < b { a } else { b };
    let excess = |d0: f64, s1: f64, s2: f64| max(max(d0 - max(s1, s2), min(s1, s2) - d0), 0.0);
    let base = (r * width + 2) as isize;
    // One direction per line; each cell's two neighbours on it are the
    // forward edge and (as the previous cell's forward edge) the backward.
    for (dc, dr) in [(1isize, 0isize), (0, 1), (1, 1), (1, -1)] {
        let o = dr * width as isize + dc;
        let line = |k: isize| {
            let start = (base + k * o) as usize;
            &z[start..start + n]
        };
        let (m2, m1, c0, p1, p2) = (line(-2), line(-1), line(0), line(1), line(2));
        // (Empty when the rows are known to be clean.)
        for (((((p, &a), &b), &c), &d), &e) in
            probe.iter_mut().zip(m2).zip(m1).zip(c0).zip(p1).zip(p2)
        {
            *p += ((a + b) + c) + (d + e);
        }
        let cells = worst.iter_mut().zip(m2).zip(m1).zip(c0).zip(p1).zip(p2);
        match mode {
            StepMode::Residual => {
                for (((((w, &a), &b), &c), &d), &e) in cells {
                    let forward = excess(d - c, c - b, e - d);
                    let backward = excess(c - b, b - a, d - c);
                    let across = excess(d - b, 2.0 * (b - a), 2.0 * (e - d));
                    *w = max(max(*w, forward), max(backward, across));
                }
            }
            StepMode::Neighbours => {
                for (((((w, _), &b), &c), &d), _) in cells {
                    *w = max(max(*w, (d - c).abs()), (c - b).abs());
                }
            }
        }
    }
}

/// The step in a height difference `d0` given the slopes on either side
/// over the same distance, `behind` and `beyond`: how far `d0` lies
/// outside the range between them. A side that is NaN (no cell there)
/// drops out; with neither, the raw difference.
#[inline]
fn residual(d0: f64, behind: f64, beyond: f64) -> f64 {
    let (lo, hi) = match (behind.is_nan(), beyond.is_nan()) {
        (false, false) => (behind.min(beyond), behind.max(beyond)),
        (false, true) => (behind, behind),
        (true, false) => (beyond, beyond),
        (true, true) => (0.0, 0.0),
    };
    if d0 < lo {
        lo - d0
    } else if d0 > hi {
        d0 - hi
    } else {
        0.0
    }
}

/// Largest step of inner cell `i` (2 cells from every edge); NaN when a
/// neighbour is unknown.
#[inline]
fn inner_step(z: &[f64], i: usize, zc: f64, offsets: &[isize], mode: StepMode) -> f64 {
    let mut worst = 0.0f64;
    if mode == StepMode::Residual {
        // Across two cells centred here, one direction per line (the
        // offsets come in opposite pairs). Cells one in from the unknown
        // border ring only get the one-cell test.
        for &o in offsets.iter().step_by(2) {
            let at = |k: isize| z[(i as isize + k * o) as usize];
            let (before, after) = (at(-1), at(1));
            if before.is_nan() || after.is_nan() {
                return f64::NAN;
            }
            let s = residual(
                after - before,
                2.0 * (before - at(-2)),
                2.0 * (at(2) - after),
            );
            worst = worst.max(s);
        }
    }
    for &o in offsets {
        let zn = z[(i as isize + o) as usize];
        if zn.is_nan() {
            return f64::NAN;
        }
        let d0 = zn - zc;
        let s = match mode {
            StepMode::Neighbours => d0.abs(),
            StepMode::Residual => residual(
                d0,
                zc - z[(i as isize - o) as usize],
                z[(i as isize + 2 * o) as usize] - zn,
            ),
        };
        worst = worst.max(s);
    }
    worst
}

/// Depth (m) of each cell below the least-squares plane through the valid
/// cells within `radius_m` around it (the cell itself left out, so a hole
/// does not pull its own plane down); negative above it, NaN where fewer
/// than 3 cells not on one line surround it.
pub fn depth_below_plane(
    z: &[f64],
    width: usize,
    height: usize,
    row_size_m: &[[f64; 2]],
    radius_m: f64,
    ticker: &Ticker,
) -> Result<Vec<f32>, CostmapError> {
    let mut out = crate::buffer::filled(width * height, f32::NAN);
    out.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(r, row)| {
            if !ticker.tick() {
                return;
            }
            let [sx, sy] = row_size_m[r];
            let hood = super::normals::neighbourhood(radius_m, sx, sy);
            for (c, o) in row.iter_mut().enumerate() {
                let zc = z[r * width + c];
                if zc.is_nan() {
                    continue;
                }
                // Normal equations of h = a + b·x + c·y, h relative to zc.
                let mut m = [[0.0f64; 3]; 3];
                let mut v = [0.0f64; 3];
                for &(dc, dr, x, y) in &hood {
                    let (rr, cc) = (r as isize + dr, c as isize + dc);
                    if rr < 0 || cc < 0 || rr >= height as isize || cc >= width as isize {
                        continue;
                    }
                    let h = z[rr as usize * width + cc as usize] - zc;
                    if h.is_nan() {
                        continue;
                    }
                    let p = [1.0, x, y];
                    for i in 0..3 {
                        for j in 0..3 {
                            m[i][j] += p[i] * p[j];
                        }
                        v[i] += p[i] * h;
                    }
                }
                if let Some(a) = solve3(m, v) {
                    *o = a as f32;
                }
            }
        });
    if ticker.cancelled() {
        return Err(CostmapError::Cancelled);
    }
    Ok(out)
}

/// First unknown of the symmetric system m·x = v (Cramer's rule); `None`
/// when it is (nearly) singular.
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<f64> {
    let det3 = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det3(m);
    let scale = m[0][0] * m[1][1] * m[2][2];
    if m[0][0] < 3.0 || d.is_nan() || d.abs() <= 1e-9 * scale.abs() {
        return None;
    }
    let mut a = m;
    for (row, &vi) in a.iter_mut().zip(&v) {
        row[0] = vi;
    }
    Some(det3(a) / d)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::{Progress, Stage};
    use crate::test_rng::Lcg;

    fn run(z: &[f64], w: usize, h: usize, mode: StepMode) -> Vec<f32> {
        let p = |_: Stage, _: f64| true;
        let t = Ticker::new(&p as &dyn Progress, Stage::Steps, h);
        step_heights(z, w, h, mode, &t).unwrap()
    }

    fn plane(w: usize, h: usize, cell: f64, slope_deg: f64) -> Vec<f64> {
        let g = slope_deg.to_radians().tan();
        (0..w * h)
            .map(|i| 700.0 + g * cell * ((i % w) as f64 + 0.3 * (i / w) as f64))
            .collect()
    }

    #[test]
    fn an_even_slope_is_never_a_step_in_residual_mode() {
        for cell in [0.1, 1.0, 5.0] {
            let z = plane(12, 10, cell, 20.0);
            let s = run(&z, 12, 10, StepMode::Residual);
            assert!(
                s.iter().filter(|v| !v.is_nan()).all(|&v| v < 1e-6),
                "{cell}"
            );
            // The literal test sees cell·tan(20°)·… everywhere.
            let n = run(&z, 12, 10, StepMode::Neighbours);
            let want = 20f64.to_radians().tan() * cell * 1.3;
            assert!((f64::from(n[5 * 12 + 5]) - want).abs() < 1e-4, "{cell}");
        }
    }

    #[test]
    fn a_step_on_a_slope_is_its_own_height_on_both_sides() {
        let (w, h) = (14, 8);
        let mut z = plane(w, h, 1.0, 10.0);
        for (i, v) in z.iter_mut().enumerate() {
            if i % w >= 7 {
                *v += 0.2;
            }
        }
        let s = run(&z, w, h, StepMode::Residual);
        for r in 1..h - 1 {
            for c in 1..w - 1 {
                let v = f64::from(s[r * w + c]);
                if c == 6 || c == 7 {
                    assert!((v - 0.2).abs() < 1e-5, "{r} {c}: {v}");
                } else {
                    assert!(v < 1e-5, "{r} {c}: {v}");
                }
            }
        }
        // Border ring unknown.
        assert!(s[0].is_nan() && s[w - 1].is_nan() && s[(h - 1) * w + 3].is_nan());
    }

    #[test]
    fn a_step_inside_a_cell_is_seen_on_the_cell_it_splits() {
        // 0, a, h along the rows: the step falls inside column 7, whose
        // height is somewhere between (as a DEM cell or a resampled block
        // straddling a kerb has). Every one-cell difference (a and h − a)
        // may be below max_step; the two-cell one is h.
        let (w, h) = (16, 8);
        for (slope, a) in [(0.0, 0.2), (0.0, 0.5), (12.0, 0.3), (12.0, 0.05)] {
            let mut z = plane(w, h, 1.0, slope);
            let rise = 0.4;
            for (i, v) in z.iter_mut().enumerate() {
                match i % w {
                    7 => *v += a * rise,
                    c if c > 7 => *v += rise,
                    _ => {}
                }
            }
            let s = run(&z, w, h, StepMode::Residual);
            for r in 2..h - 2 {
                let mid = f64::from(s[r * w + 7]);
                assert!((mid - rise).abs() < 1e-5, "{slope}° a={a}: {mid}");
                for c in (2..5).chain(10..w - 2) {
                    assert!(f64::from(s[r * w + c]) < 1e-5, "{slope}° a={a} col {c}");
                }
            }
        }
    }

    #[test]
    fn whole_row_passes_equal_the_cell_by_cell_test() {
        let (w, h) = (23, 17);
        let mut s = Lcg(7);
        let z: Vec<f64> = (0..w * h).map(|_| s.next() * 0.6).collect();
        let offsets: Vec<isize> = DIRECTIONS
            .iter()
            .map(|&(dc, dr)| dr * w as isize + dc)
            .collect();
        // Also with unknown heights scattered through every row, which
        // send the cells whose tests read them to the cell-by-cell path.
        let mut holes = z.clone();
        for i in (5..w * h).step_by(37) {
            holes[i] = f64::NAN;
        }
        for z in [&z, &holes] {
            for mode in [StepMode::Residual, StepMode::Neighbours] {
                let got = run(z, w, h, mode);
                for r in 2..h - 2 {
                    for c in 2..w - 2 {
                        let i = r * w + c;
                        let want = if z[i].is_nan() {
                            f64::NAN
                        } else {
                            inner_step(z, i, z[i], &offsets, mode)
                        };
                        let got = f64::from(got[i]);
                        assert!(
                            (got - want).abs() < 1e-6 || (got.is_nan() && want.is_nan()),
                            "{mode:?} {r} {c}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn curved_ground_is_not_a_step() {
        // A valley z = k·x² (curvature, no discontinuity) of 2 m cells:
        // slopes change by 4k per cell, yet nothing is a step.
        let (w, h) = (30, 8);
        let z: Vec<f64> = (0..w * h)
            .map(|i| 0.01 * ((i % w) as f64 * 2.0 - 30.0).powi(2))
            .collect();
        let s = run(&z, w, h, StepMode::Residual);
        // Inner cells: next to the unknown border only one side's slope is
        // known, and its straight continuation misses the curvature.
        for r in 2..h - 2 {
            for c in 2..w - 2 {
                assert!(s[r * w + c] < 1e-9, "{c}: {}", s[r * w + c]);
            }
        }
    }

    #[test]
    fn walls_and_pits_of_one_cell() {
        let (w, h) = (9, 9);
        for height in [0.5, -0.5] {
            let mut z = vec![10.0; w * h];
            z[4 * w + 4] += height;
            let s = run(&z, w, h, StepMode::Residual);
            assert!((f64::from(s[4 * w + 4]) - 0.5).abs() < 1e-6);
            assert!((f64::from(s[4 * w + 3]) - 0.5).abs() < 1e-6);
            assert!((f64::from(s[3 * w + 3]) - 0.5).abs() < 1e-6);
            assert_eq!(s[2 * w + 2], 0.0);
        }
    }

    #[test]
    fn ditches_lie_below_their_surroundings_plane() {
        let (w, h) = (15, 15);
        let mut z = plane(w, h, 0.5, 15.0);
        for r in 0..h {
            z[r * w + 7] -= 0.4;
        }
        let p = |_: Stage, _: f64| true;
        let t = Ticker::new(&p as &dyn Progress, Stage::Layers, h);
        let d = depth_below_plane(&z, w, h, &vec![[0.5, 0.5]; h], 1.6, &t).unwrap();
        let bottom = f64::from(d[7 * w + 7]);
        assert!(bottom > 0.25 && bottom < 0.4, "{bottom}");
        assert!(f64::from(d[7 * w + 2]).abs() < 1e-6);
    }
}
