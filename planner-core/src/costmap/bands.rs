//! One pass over the working grid, band by band of rows: step heights,
//! the normals of the smoothed heights and each cell's class from both
//! (SPEC §4.2 steps 2–4 and the union of step 5), so that neither the
//! step heights (unless kept as a layer) nor the smoothed heights are
//! ever held whole, and each band's heights are read while in cache.

use rayon::prelude::*;

use super::normals::{NormalsJob, NormalsScratch};
use super::progress::Ticker;
use super::steps::{StepScratch, clean_rows, rows_with_unknown, step_row};
use super::{Class, CostmapError, StepMode};

/// Rows per parallel task.
const BAND_ROWS: usize = 32;

/// What the pass leaves, row-major.
pub(super) struct Surface {
    /// |n_z| of the surface normal.
    pub zcomp: Vec<f32>,
    /// Plane-fit residual, when asked for.
    pub roughness: Option<Vec<f32>>,
    /// Step heights, when kept as a layer.
    pub step: Option<Vec<f32>>,
    /// Step > slope > roughness ("other"); unknown where the step or the
    /// normal is.
    pub class: Vec<u8>,
    /// The cells without a height.
    pub holes: Holes,
}

/// A set of cells, one bit each, rows starting on a new word (so that
/// bands of rows own their words).
pub(super) struct Holes {
    words_per_row: usize,
    bits: Vec<u64>,
}

impl Holes {
    fn new(width: usize, height: usize) -> Holes {
        let words_per_row = width.div_ceil(64);
        Holes {
            words_per_row,
            bits: vec![0; words_per_row * height],
        }
    }

    /// Row `r`'s cells: true where in the set.
    pub(super) fn row_into(&self, r: usize, out: &mut [bool]) {
        let words = &self.bits[r * self.words_per_row..(r + 1) * self.words_per_row];
        for (cells, &word) in out.chunks_mut(64).zip(words) {
            for (k, o) in cells.iter_mut().enumerate() {
                *o = word >> k & 1 == 1;
            }
        }
    }
}

/// The unknown heights of `z_row` into `words`.
fn mark_holes(z_row: &[f64], words: &mut [u64]) {
    for (word, cells) in words.iter_mut().zip(z_row.chunks(64)) {
        *word = cells
            .iter()
            .enumerate()
            .fold(0, |w, (k, v)| w | u64::from(v.is_nan()) << k);
    }
}

/// What a cell may be and still be traversable.
#[derive(Clone, Copy)]
pub(super) struct Limits {
    pub max_step_m: f64,
    /// cos(max_slope): Zcomp at or below is too steep.
    pub cos_max: f64,
    /// Roughness above is an "other" obstacle (with the roughness layer).
    pub max_roughness_m: Option<f64>,
}

/// One band's share of the output grids.
struct BandOut<'a> {
    r0: usize,
    zcomp: &'a mut [f32],
    class: &'a mut [u8],
    holes: &'a mut [u64],
    rough: Option<&'a mut [f32]>,
    step: Option<&'a mut [f32]>,
}

/// The steps (by `mode`), normals (by `normals`, which holds the heights)
/// and classes of every cell, a tick of `ticker` per row.
pub(super) fn surface(
    normals: &NormalsJob<'_>,
    mode: StepMode,
    limits: Limits,
    keep_step: bool,
    ticker: &Ticker,
) -> Result<Surface, CostmapError> {
    let (z, width, height) = (normals.z(), normals.width(), normals.height());
    let n = width * height;
    let mut zcomp = crate::buffer::filled(n, f32::NAN);
    let mut roughness = limits
        .max_roughness_m
        .map(|_| crate::buffer::filled(n, f32::NAN));
    let mut step = keep_step.then(|| crate::buffer::filled(n, f32::NAN));
    let mut class = crate::buffer::filled(n, Class::Unknown as u8);
    let mut holes = Holes::new(width, height);
    if n == 0 {
        return Ok(Surface {
            zcomp,
            roughness,
            step,
            class,
            holes,
        });
    }
    let band = BAND_ROWS * width;
    let bands = height.div_ceil(BAND_ROWS);
    fn optional(v: Option<&mut Vec<f32>>, band: usize, bands: usize) -> Vec<Option<&mut [f32]>> {
        match v {
            Some(v) => v.chunks_mut(band).map(Some).collect(),
            None => (0..bands).map(|_| None).collect(),
        }
    }
    let outs: Vec<BandOut<'_>> = zcomp
        .chunks_mut(band)
        .zip(
            class
                .chunks_mut(band)
                .zip(holes.bits.chunks_mut(BAND_ROWS * holes.words_per_row)),
        )
        .zip(optional(roughness.as_mut(), band, bands))
        .zip(optional(step.as_mut(), band, bands))
        .enumerate()
        .map(|(b, (((zcomp, (class, holes)), rough), step))| BandOut {
            r0: b * BAND_ROWS,
            zcomp,
            class,
            holes,
            rough,
            step,
        })
        .collect();
    outs.into_par_iter()
        .for_each_init(BandScratch::default, |scratch, out| {
            band_job(
                z,
                [width, height],
                normals,
                mode,
                limits,
                out,
                scratch,
                ticker,
            )
        });
    if ticker.cancelled() {
        return Err(CostmapError::Cancelled);
    }
    Ok(Surface {
        zcomp,
        roughness,
        step,
        class,
        holes,
    })
}

/// What a band reuses from the previous one.
#[derive(Default)]
struct BandScratch {
    step: Vec<f32>,
    steps: StepScratch,
    normals: NormalsScratch,
}

#[allow(clippy::too_many_arguments)]
fn band_job(
    z: &[f64],
    [width, height]: [usize; 2],
    normals: &NormalsJob<'_>,
    mode: StepMode,
    limits: Limits,
    out: BandOut<'_>,
    scratch: &mut BandScratch,
    ticker: &Ticker,
) {
    let BandOut {
        r0,
        zcomp,
        class,
        holes,
        mut rough,
        step,
    } = out;
    let rows = zcomp.len() / width;
    let words = holes.len() / rows;
    for (k, w) in holes.chunks_mut(words).enumerate() {
        let r = r0 + k;
        mark_holes(&z[r * width..(r + 1) * width], w);
    }
    // The step tests read two rows either side.
    let first = r0.saturating_sub(2);
    let unknown = rows_with_unknown(z, width, first..(r0 + rows + 2).min(height));
    let step = match step {
        Some(s) => s,
        None => {
            scratch.step.resize(rows * width, f32::NAN);
            &mut scratch.step[..]
        }
    };
    for (k, row) in step.chunks_mut(width).enumerate() {
        let r = r0 + k;
        let clean = clean_rows(&unknown, first, r);
        step_row(z, width, height, r, mode, clean, row, &mut scratch.steps);
    }
    normals.band(
        r0,
        zcomp,
        rough.as_deref_mut(),
        &mut scratch.normals,
        ticker,
    );
    if ticker.cancelled() {
        return;
    }
    for (k, (class_row, (step_row, zc_row))) in class
        .chunks_mut(width)
        .zip(step.chunks(width).zip(zcomp.chunks(width)))
        .enumerate()
    {
        classify_row(class_row, step_row, zc_row, limits);
        if let (Some(r), Some(max)) = (rough.as_deref(), limits.max_roughness_m) {
            let rough_row = &r[k * width..(k + 1) * width];
            for (c, &v) in class_row.iter_mut().zip(rough_row) {
                if *c == Class::Traversable as u8 && f64::from(v) > max {
                    *c = Class::Other as u8;
                }
            }
        }
    }
}

/// Each cell's class from its step height and Zcomp (NaN: unknown).
/// Precedence: step > slope.
#[inline]
fn classify_row(class: &mut [u8], step: &[f32], zcomp: &[f32], limits: Limits) {
    for ((k, &s), &zc) in class.iter_mut().zip(step).zip(zcomp) {
        let (s, zc) = (f64::from(s), f64::from(zc));
        *k = if s.is_nan() || zc.is_nan() {
            Class::Unknown
        } else if s > limits.max_step_m {
            Class::Step
        } else if zc <= limits.cos_max {
            Class::Slope
        } else {
            Class::Traversable
        } as u8;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::normals::normals;
    use crate::costmap::smooth::Smoother;
    use crate::costmap::steps::step_heights;
    use crate::costmap::{Progress, Stage};
    use crate::test_rng::Lcg;

    #[test]
    fn the_one_pass_equals_the_stages_run_over_whole_grids() {
        let p = |_: Stage, _: f64| true;
        let p = &p as &dyn Progress;
        // More rows than a band, rough ground with ledges, unknown heights
        // scattered and a whole unknown row.
        let (w, h) = (37, 3 * BAND_ROWS + 5);
        let mut s = Lcg(41);
        let z: Vec<f64> = (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                let noise = s.next();
                if i % 89 == 7 || r == 40 {
                    f64::NAN
                } else {
                    300.0 + 0.05 * c as f64 + 0.3 * f64::from(u8::from(c > 20)) + 0.02 * noise
                }
            })
            .collect();
        let rows = vec![[0.2, 0.25]; h];
        let smoother = Smoother::new(0.6, 0.5, 3.0);
        for (mode, rough, keep) in [
            (StepMode::Residual, None, false),
            (StepMode::Neighbours, Some(0.004), true),
        ] {
            let limits = Limits {
                max_step_m: 0.1,
                cos_max: 0.98,
                max_roughness_m: rough,
            };
            let t = Ticker::new(p, Stage::Normals, h);
            let job = NormalsJob::new(&z, w, h, &rows, 0.3, smoother.as_ref());
            let got = surface(&job, mode, limits, keep, &t).unwrap();
            let step = step_heights(&z, w, h, mode, &t).unwrap();
            let (zc, r) =
                normals(&z, w, h, &rows, 0.3, smoother.as_ref(), rough.is_some(), &t).unwrap();
            let bits =
                |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(bits(&got.zcomp, &zc));
            assert_eq!(got.roughness.is_some(), rough.is_some());
            if let (Some(a), Some(b)) = (&got.roughness, &r) {
                assert!(bits(a, b));
            }
            assert_eq!(got.step.is_some(), keep);
            if let Some(a) = &got.step {
                assert!(bits(a, &step));
            }
            let mut seen = [0; 6];
            for i in 0..w * h {
                let mut want = [0u8];
                classify_row(&mut want, &step[i..=i], &zc[i..=i], limits);
                if let (Some(r), Some(max)) = (&r, rough)
                    && want[0] == Class::Traversable as u8
                    && f64::from(r[i]) > max
                {
                    want[0] = Class::Other as u8;
                }
                assert_eq!(got.class[i], want[0], "cell {i}");
                seen[usize::from(want[0])] += 1;
            }
            // Every class but "enclosed" (a later stage's) is there.
            let other = usize::from(rough.is_some());
            assert!(
                seen[0] > 0 && seen[1] > 0 && seen[2] > 0 && seen[3] > 0,
                "{seen:?}"
            );
            assert!(seen[5] >= other, "{seen:?}");
        }
    }
}
