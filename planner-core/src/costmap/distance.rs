//! Exact Euclidean distance transform in linear time (Felzenszwalb and
//! Huttenlocher, "Distance Transforms of Sampled Functions", 2012): for
//! every cell, the distance in metres to the nearest obstacle cell centre.
//!
//! Cells may be rectangles (`dx` × `dy` metres, as a geographic DEM's cells
//! are once converted to local metres), so the transform runs as two 1D
//! passes of the lower envelope of parabolas, columns then rows, each with
//! its own spacing. Inflation by exp(−d²/2σ²) of this distance treats a
//! one-cell wall like a thick one, which blurring the binary grid does not.

use rayon::prelude::*;

/// Distance (m) from each cell of a `width` × `height` row-major grid to the
/// nearest cell where `obstacle` is true; `f64::INFINITY` everywhere when
/// there is none. `dx`, `dy`: cell width and height in metres (> 0).
pub fn distance_transform(
    obstacle: &[bool],
    width: usize,
    height: usize,
    dx: f64,
    dy: f64,
) -> Vec<f64> {
    let mut sq: Vec<f64> = obstacle
        .iter()
        .map(|&o| if o { 0.0 } else { f64::INFINITY })
        .collect();
    passes(&mut sq, width, height, dx, dy, |v| v, |v| v);
    sq.into_iter().map(f64::sqrt).collect()
}

/// [`distance_transform`] squared, in `f32` (half the memory, for large
/// grids; squared distances keep 7 significant digits). Rows run in
/// parallel.
pub fn squared_distance_f32(
    obstacle: &[bool],
    width: usize,
    height: usize,
    dx: f64,
    dy: f64,
) -> Vec<f32> {
    let mut sq: Vec<f32> = obstacle
        .iter()
        .map(|&o| if o { 0.0 } else { f32::INFINITY })
        .collect();
    passes(&mut sq, width, height, dx, dy, f64::from, |v| v as f32);
    sq
}

/// Columns per block of the column pass: read row by row, so the pass
/// walks memory in order, and blocks run in parallel.
const COLUMN_BLOCK: usize = 16;

/// The two 1D passes over squared distances (0 at obstacles, ∞ elsewhere):
/// columns (spacing dy), then rows (spacing dx).
fn passes<T: Copy + Send + Sync>(
    sq: &mut [T],
    width: usize,
    height: usize,
    dx: f64,
    dy: f64,
    to_f64: impl Fn(T) -> f64 + Sync,
    from_f64: impl Fn(f64) -> T + Sync,
) {
    assert_eq!(sq.len(), width * height, "grid size");
    assert!(dx > 0.0 && dy > 0.0, "cell size must be positive");
    if width == 0 || height == 0 {
        return;
    }
    // Column pass, blocks of columns in parallel; each block's result is
    // kept block-major (row by row, COLUMN_BLOCK wide) for the row pass.
    let src: &[T] = sq;
    let blocks: Vec<Vec<T>> = (0..width)
        .step_by(COLUMN_BLOCK)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|x0| {
            let n = COLUMN_BLOCK.min(width - x0);
            let mut scratch = Scratch::new(height);
            let mut lines = vec![vec![0.0; height]; n];
            for y in 0..height {
                for (k, line) in lines.iter_mut().enumerate() {
                    line[y] = to_f64(src[y * width + x0 + k]);
                }
            }
            for line in lines.iter_mut() {
                scratch.transform(line, dy);
                line.copy_from_slice(&scratch.out[..height]);
            }
            let mut block = Vec::with_capacity(n * height);
            for y in 0..height {
                block.extend(lines.iter().map(|line| from_f64(line[y])));
            }
            block
        })
        .collect();
    sq.par_chunks_mut(width).enumerate().for_each_init(
        || (Scratch::new(width), vec![0.0; width]),
        |(scratch, line), (y, row)| {
            for (b, block) in blocks.iter().enumerate() {
                let n = block.len() / height;
                for (k, &v) in block[y * n..(y + 1) * n].iter().enumerate() {
                    line[b * COLUMN_BLOCK + k] = to_f64(v);
                }
            }
            scratch.transform(line, dx);
            for (v, &o) in row.iter_mut().zip(&scratch.out[..width]) {
                *v = from_f64(o);
            }
        },
    );
}

/// Buffers of the 1D transform, reused across lines.
struct Scratch {
    /// Sites (indices) of the parabolas in the lower envelope.
    v: Vec<usize>,
    /// Boundaries between envelope parabolas, in index units.
    z: Vec<f64>,
    out: Vec<f64>,
}

impl Scratch {
    fn new(n: usize) -> Self {
        Scratch {
            v: vec![0; n],
            z: vec![0.0; n + 1],
            out: vec![0.0; n],
        }
    }

    /// out[q] = min_p ((q − p)·s)² + f[p], for f with 0 and ∞ values and
    /// squared distances from the previous pass.
    fn transform(&mut self, f: &[f64], s: f64) {
        let n = f.len();
        let s2 = s * s;
        // Only finite sites carry parabolas.
        let mut k: isize = -1;
        for q in 0..n {
            if !f[q].is_finite() {
                continue;
            }
            loop {
                if k < 0 {
                    k = 0;
                    self.v[0] = q;
                    self.z[0] = f64::NEG_INFINITY;
                    self.z[1] = f64::INFINITY;
                    break;
                }
                let p = self.v[k as usize];
                // Where the parabolas of p and q meet.
                let (qf, pf) = (q as f64, p as f64);
                let meet = ((f[q] + s2 * qf * qf) - (f[p] + s2 * pf * pf)) / (2.0 * s2 * (qf - pf));
                if meet <= self.z[k as usize] {
                    k -= 1;
                    continue;
                }
                k += 1;
                self.v[k as usize] = q;
                self.z[k as usize] = meet;
                self.z[k as usize + 1] = f64::INFINITY;
                break;
            }
        }
        if k < 0 {
            self.out[..n].fill(f64::INFINITY);
            return;
        }
        let mut j = 0usize;
        for q in 0..n {
            while self.z[j + 1] < q as f64 {
                j += 1;
            }
            let p = self.v[j];
            let d = (q as f64 - p as f64) * s;
            self.out[q] = d * d + f[p];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The distance to the nearest obstacle centre, by brute force.
    fn brute(obstacle: &[bool], w: usize, h: usize, dx: f64, dy: f64) -> Vec<f64> {
        (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                (0..w * h)
                    .filter(|&j| obstacle[j])
                    .map(|j| {
                        let (ox, oy) = (j % w, j / w);
                        ((x as f64 - ox as f64) * dx).hypot((y as f64 - oy as f64) * dy)
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    #[test]
    fn equals_brute_force_on_random_grids_with_rectangular_cells() {
        let mut state = 0x5eed_u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..60 {
            let (w, h) = (1 + (next() * 23.0) as usize, 1 + (next() * 17.0) as usize);
            let density = [0.0, 0.01, 0.1, 0.5, 0.95][case % 5];
            let obstacle: Vec<bool> = (0..w * h).map(|_| next() < density).collect();
            let (dx, dy) = (0.5 + next() * 3.0, 0.5 + next() * 3.0);
            let got = distance_transform(&obstacle, w, h, dx, dy);
            let want = brute(&obstacle, w, h, dx, dy);
            for (i, (g, e)) in got.iter().zip(&want).enumerate() {
                if e.is_infinite() {
                    assert!(g.is_infinite(), "case {case} cell {i}: {g} vs none");
                } else {
                    assert!(
                        (g - e).abs() <= 1e-9 * e.max(1.0),
                        "case {case} cell {i}: {g} vs {e}"
                    );
                }
            }
        }
    }

    #[test]
    fn the_f32_squares_agree_with_the_f64_distances() {
        let (w, h) = (37, 29);
        let obstacle: Vec<bool> = (0..w * h).map(|i| (i * 7919) % 97 == 3).collect();
        let d = distance_transform(&obstacle, w, h, 0.7, 1.3);
        let sq = squared_distance_f32(&obstacle, w, h, 0.7, 1.3);
        for (a, b) in d.iter().zip(&sq) {
            assert!(
                (a * a - f64::from(*b)).abs() <= 1e-6 * (a * a).max(1.0),
                "{a} {b}"
            );
        }
    }

    #[test]
    fn a_one_cell_wall_is_as_near_as_a_thick_one() {
        // Beside a wall, the distance does not depend on its thickness.
        let (w, h) = (21, 5);
        let thin: Vec<bool> = (0..w * h).map(|i| i % w == 10).collect();
        let thick: Vec<bool> = (0..w * h).map(|i| (8..=10).contains(&(i % w))).collect();
        let (a, b) = (
            distance_transform(&thin, w, h, 1.0, 1.0),
            distance_transform(&thick, w, h, 1.0, 1.0),
        );
        for y in 0..h {
            for x in 11..w {
                assert_eq!(a[y * w + x], b[y * w + x]);
                assert_eq!(a[y * w + x], (x - 10) as f64);
            }
        }
    }
}
