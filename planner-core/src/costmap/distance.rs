//! Exact Euclidean distance transform in linear time (Felzenszwalb and
//! Huttenlocher, "Distance Transforms of Sampled Functions", 2012): for
//! every cell, the distance in metres to the nearest obstacle cell centre.
//!
//! Cells may be rectangles (`dx` × `dy` metres, as a geographic DEM's cells
//! are once converted to local metres), so the transform runs as two 1D
//! passes of the lower envelope of parabolas, columns then rows, each with
//! its own spacing. Inflation by exp(−d²/2σ²) of this distance treats a
//! one-cell wall like a thick one, which blurring the binary grid does not;
//! [`map_squared_distance_f32`] computes such a fall-off directly, looking
//! only as far from each cell as the fall-off is not 0.

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

/// Most (column, row) offsets [`map_squared_distance_f32`] tabulates f at;
/// beyond that it evaluates f per cell.
const MAX_OFFSETS: usize = 1 << 20;

/// Widest reach (columns) up to which a row is done by taking, for each
/// cell, the largest f of the obstacles within reach, rather than by the
/// lower envelope: cheaper while the reach is short.
const WINDOW_MAX: usize = 48;

/// Rows per band of [`map_squared_distance_f32`] (at least).
const BAND_ROWS: usize = 64;

/// `f(d²)` for every cell, d² as [`squared_distance_f32`] gives it, for an
/// f ≥ 0 that does not increase with d² and is 0 at ∞, such as a Gaussian
/// fall-off cut to 0 a few σ out.
///
/// When f reaches 0 within a short distance (the usual case), only the
/// obstacles that near each cell are looked at, f is evaluated once per
/// (column, row) offset instead of once per cell, and there is no full-size
/// intermediate grid: rows run in parallel bands, the column pass being the
/// row distance to the nearest obstacle by a sweep down and one up. Results
/// equal f of [`squared_distance_f32`], but for f32 rounding where two
/// obstacles are (nearly) equally near.
///
/// Otherwise (f never 0 within [`MAX_OFFSETS`] offsets, or not at ∞) it
/// maps [`squared_distance_f32`] cell by cell.
pub fn map_squared_distance_f32(
    obstacle: &[bool],
    width: usize,
    height: usize,
    dx: f64,
    dy: f64,
    f: impl Fn(f32) -> f32 + Sync,
) -> Vec<f32> {
    assert_eq!(obstacle.len(), width * height, "grid size");
    assert!(dx > 0.0 && dy > 0.0, "cell size must be positive");
    if obstacle.is_empty() {
        return Vec::new();
    }
    match Falloff::new(width, height, dx, dy, &f) {
        Some(table) => map_with_table(obstacle, width, height, dx, &table),
        None => {
            let mut sq = squared_distance_f32(obstacle, width, height, dx, dy);
            sq.par_chunks_mut(1 << 16)
                .for_each(|chunk| chunk.iter_mut().for_each(|v| *v = f(*v)));
            sq
        }
    }
}

/// [`map_squared_distance_f32`] from f's table, in bands of rows.
fn map_with_table(
    obstacle: &[bool],
    width: usize,
    height: usize,
    dx: f64,
    table: &Falloff,
) -> Vec<f32> {
    // Zeroed, so that only cells near an obstacle are written.
    let mut out = crate::buffer::filled(width * height, 0.0f32);
    // Row distances saturate at `reach`: no obstacle near enough.
    let reach = table.rows.len();
    if reach == 0 {
        return out;
    }
    let band = BAND_ROWS.max(2 * reach);
    out.par_chunks_mut(band * width).enumerate().for_each_init(
        || BandScratch::new(width, band, table),
        |env, (b, out)| env.band(obstacle, height, b * band, table, dx, out),
    );
    out
}

/// One row of a sweep: rows since the last obstacle, saturating at `s`.
/// i16, not u16: SSE2 has a signed 16-bit min only; and a mask rather than
/// a branch, so that it vectorises.
#[inline(always)]
fn sweep_cell(prev: i16, obstacle: bool, s: i16) -> i16 {
    (prev + 1).min(s) & (i16::from(obstacle) - 1)
}

// The sweeps and row kernels below are functions of their own, not
// inlined, so that LLVM knows their slices do not overlap and vectorises.

#[inline(never)]
fn sweep_step(cur: &mut [i16], obstacle: &[bool], s: i16) {
    let obstacle = &obstacle[..cur.len()];
    for (c, &o) in cur.iter_mut().zip(obstacle) {
        *c = sweep_cell(*c, o, s);
    }
}

#[inline(never)]
fn sweep_into(prev: &[i16], obstacle: &[bool], s: i16, next: &mut [i16]) {
    let (prev, obstacle) = (&prev[..next.len()], &obstacle[..next.len()]);
    for ((n, &p), &o) in next.iter_mut().zip(prev).zip(obstacle) {
        *n = sweep_cell(p, o, s);
    }
}

/// A step of the upward sweep `up`, and `down` lowered to it.
#[inline(never)]
fn sweep_up(up: &mut [i16], obstacle: &[bool], s: i16, down: &mut [i16]) {
    let (obstacle, down) = (&obstacle[..up.len()], &mut down[..up.len()]);
    for ((u, &o), d) in up.iter_mut().zip(obstacle).zip(down) {
        *u = sweep_cell(*u, o, s);
        *d = (*d).min(*u);
    }
}

/// The row pass for a short reach: each site raises the cells of `acc`
/// within its reach (`acc` is padded by the window radius on both sides)
/// to its f there. f does not increase with d², so the largest is f at the
/// least d². False if there is no site.
#[inline(never)]
fn raise_row(g: &[i16], table: &Falloff, acc: &mut [f32]) -> bool {
    let k = table.window.len() / table.rows.len();
    acc.fill(0.0);
    let mut any = false;
    for_each_site(g, table.rows.len() as i16, |p, gp| {
        let w = &table.window[gp as usize * k..][..k];
        for (a, &v) in acc[p..p + k].iter_mut().zip(w) {
            // A select, not a conditional store: maxps.
            *a = if v > *a { v } else { *a };
        }
        any = true;
    });
    any
}

/// Calls `f(x, g[x])` for each x with `g[x] < reach`, in order.
#[inline(always)]
fn for_each_site(g: &[i16], reach: i16, mut f: impl FnMut(usize, i16)) {
    // Most cells are beyond reach: skip them 16 at a time.
    const CHUNK: usize = 16;
    let chunks = g.chunks_exact(CHUNK);
    let tail = g.len() - chunks.remainder().len();
    for (c, chunk) in chunks.enumerate() {
        if chunk.iter().fold(i16::MAX, |m, &v| m.min(v)) >= reach {
            continue;
        }
        for (k, &gx) in chunk.iter().enumerate() {
            if gx < reach {
                f(c * CHUNK + k, gx);
            }
        }
    }
    for (x, &gx) in g.iter().enumerate().skip(tail) {
        if gx < reach {
            f(x, gx);
        }
    }
}

/// f(d²) at each (column, row) offset where it is not 0, with d² rounded as
/// [`squared_distance_f32`] rounds it.
#[derive(Clone)]
struct Falloff {
    /// Per row offset, the range of `values` holding column offsets 0, 1, …
    /// up to the first where f is 0 (f does not increase with d²).
    rows: Vec<std::ops::Range<usize>>,
    values: Vec<f32>,
    /// Squared row offsets, m², as the column pass stores them (f32).
    col_sq: Vec<f64>,
    /// When f reaches 0 within [`WINDOW_MAX`] columns: per row offset,
    /// f at column offsets −r..=r (0 past its reach), r the widest reach.
    window: Vec<f32>,
}

impl Falloff {
    /// None when f does not reach 0 within [`MAX_OFFSETS`] offsets, or row
    /// distances would not fit the i16 sweeps, or f(∞) is not 0.
    fn new(width: usize, height: usize, dx: f64, dy: f64, f: impl Fn(f32) -> f32) -> Option<Self> {
        if f(f32::INFINITY) != 0.0 {
            return None;
        }
        let mut table = Falloff {
            rows: Vec::new(),
            values: Vec::new(),
            col_sq: Vec::new(),
            window: Vec::new(),
        };
        for j in 0..height {
            let d = j as f64 * dy;
            let col = f64::from((d * d) as f32);
            let start = table.values.len();
            for i in 0..width {
                let d = i as f64 * dx;
                let v = f((d * d + col) as f32);
                if v <= 0.0 || v.is_nan() {
                    break;
                }
                if table.values.len() == MAX_OFFSETS {
                    return None;
                }
                table.values.push(v);
            }
            if table.values.len() == start {
                break;
            }
            if j + 1 >= i16::MAX as usize {
                return None;
            }
            table.rows.push(start..table.values.len());
            table.col_sq.push(col);
        }
        let r = table.rows.first().map_or(0, |first| first.len() - 1);
        if r <= WINDOW_MAX {
            for row in &table.rows {
                let vals = &table.values[row.clone()];
                let at = |o: usize| vals.get(o.abs_diff(r)).copied().unwrap_or(0.0);
                table.window.extend((0..=2 * r).map(at));
            }
        }
        Some(table)
    }

    /// The widest reach in columns, if within [`WINDOW_MAX`].
    fn window_radius(&self) -> Option<usize> {
        (!self.window.is_empty()).then(|| self.window.len() / self.rows.len() / 2)
    }
}

/// Buffers of [`map_squared_distance_f32`], reused from band to band.
struct BandScratch {
    /// Row distances (cells) to the nearest obstacle, per row of the band.
    down: Vec<i16>,
    /// The sweep's current row.
    cur: Vec<i16>,
    up: Vec<i16>,
    /// Sites of the lower envelope's parabolas, their heights at 0
    /// (f + s²p²), and where each begins (index units).
    v: Vec<usize>,
    h: Vec<f64>,
    z: Vec<f64>,
    /// A row padded by the window radius on both sides.
    acc: Vec<f32>,
}

impl BandScratch {
    fn new(width: usize, band: usize, table: &Falloff) -> Self {
        BandScratch {
            acc: vec![0.0; table.window_radius().map_or(0, |r| width + 2 * r)],
            down: vec![0; width * band],
            cur: vec![0; width],
            up: vec![0; width],
            v: vec![0; width],
            h: vec![0.0; width],
            z: vec![0.0; width],
        }
    }

    /// f(d²) into the band of rows `out` (zeroed) starting at row `y0`.
    fn band(
        &mut self,
        obstacle: &[bool],
        height: usize,
        y0: usize,
        table: &Falloff,
        dx: f64,
        out: &mut [f32],
    ) {
        let width = self.cur.len();
        let y1 = y0 + out.len() / width;
        let reach = table.rows.len();
        let s = reach as i16;
        let obstacle_row = |y: usize| &obstacle[y * width..(y + 1) * width];
        let BandScratch { down, cur, up, .. } = self;
        // Rows down from the nearest obstacle above; those more than
        // `reach` rows above the band do not matter…
        cur.fill(s);
        for y in y0.saturating_sub(reach)..y0 {
            sweep_step(cur, obstacle_row(y), s);
        }
        let mut prev: &[i16] = cur;
        for (y, row) in (y0..y1).zip(down.chunks_exact_mut(width)) {
            sweep_into(prev, obstacle_row(y), s, row);
            prev = row;
        }
        // …then up from the nearest below, doing each row while its
        // distances are at hand.
        up.fill(s);
        for y in (y1..(y1 + reach).min(height)).rev() {
            sweep_step(up, obstacle_row(y), s);
        }
        for y in (y0..y1).rev() {
            let r = (y - y0) * width;
            sweep_up(
                &mut self.up,
                obstacle_row(y),
                s,
                &mut self.down[r..r + width],
            );
            let out = &mut out[r..r + width];
            match table.window_radius() {
                Some(radius) => {
                    if raise_row(&self.down[r..r + width], table, &mut self.acc) {
                        out.copy_from_slice(&self.acc[radius..radius + width]);
                    }
                }
                None => self.row(table, r, dx, out),
            }
        }
    }

    /// The row pass of [`Scratch::transform`] over the row distances
    /// `down[r..r + width]`, writing f(d²) into the non-zero cells of `out`
    /// (zeroed). Sites beyond reach are left out: f is 0 wherever they
    /// would be nearest.
    fn row(&mut self, table: &Falloff, r: usize, s: f64, out: &mut [f32]) {
        let width = out.len();
        let g = &self.down[r..r + width];
        let s2 = s * s;
        let reach = table.rows.len() as i16;
        let mut n = 0;
        let mut push = |q: usize, gq: i16| {
            let qf = q as f64;
            let hq = table.col_sq[gq as usize] + s2 * qf * qf;
            // Where this parabola meets the last one kept.
            let mut meet = f64::NEG_INFINITY;
            while n > 0 {
                meet = (hq - self.h[n - 1]) / (2.0 * s2 * (qf - self.v[n - 1] as f64));
                if meet > self.z[n - 1] {
                    break;
                }
                n -= 1;
                meet = f64::NEG_INFINITY;
            }
            self.z[n] = meet;
            self.v[n] = q;
            self.h[n] = hq;
            n += 1;
        };
        for_each_site(g, reach, &mut push);
        // Cells up to z[j + 1] (inclusive) are nearest to site j.
        let mut a = 0;
        for j in 0..n {
            let e = if j + 1 < n {
                // ⌊z⌋ + 1 without a call to floor (SSE2 has none).
                let z = self.z[j + 1];
                if z < 0.0 {
                    a
                } else {
                    (z as usize).saturating_add(1).clamp(a, width)
                }
            } else {
                width
            };
            let p = self.v[j];
            let vals = &table.values[table.rows[g[p] as usize].clone()];
            let lo = a.max((p + 1).saturating_sub(vals.len()));
            let hi = e.min(p + vals.len());
            if lo < hi {
                let mid = p.clamp(lo, hi);
                for (o, &v) in out[lo..mid]
                    .iter_mut()
                    .rev()
                    .zip(&vals[(p + 1).saturating_sub(mid)..])
                {
                    *o = v;
                }
                for (o, &v) in out[mid..hi].iter_mut().zip(&vals[mid.saturating_sub(p)..]) {
                    *o = v;
                }
            }
            a = e;
        }
    }
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
    use crate::test_rng::Lcg;

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
        let mut state = Lcg(0x5eed_u64);
        let mut next = || state.next();
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

    /// The Gaussian fall-off inflation uses, for σ in metres.
    fn gaussian(sigma: f64) -> impl Fn(f32) -> f32 + Sync {
        let k = 1.0 / (2.0 * sigma * sigma);
        move |d2| {
            let x = f64::from(d2) * k;
            if x > 40.0 { 0.0 } else { (-x).exp() as f32 }
        }
    }

    #[test]
    fn the_mapped_transform_equals_f_of_the_squares() {
        let mut state = Lcg(0x0bad_cafe_u64);
        let mut next = || state.next();
        let mut sizes = vec![(1, 1), (1, 2), (2, 1), (3, 3), (1, 150), (150, 1), (3, 140)];
        sizes
            .extend((0..30).map(|_| (1 + (next() * 60.0) as usize, 1 + (next() * 300.0) as usize)));
        for (case, (w, h)) in sizes.into_iter().enumerate() {
            let (dx, dy) = (0.3 + next() * 2.0, 0.3 + next() * 2.0);
            for density in [0.0, 0.002, 0.03, 0.3, 1.0] {
                let obstacle: Vec<bool> = (0..w * h).map(|_| next() < density).collect();
                let sq = squared_distance_f32(&obstacle, w, h, dx, dy);
                // σ from a fraction of a cell to past the band height and
                // the grid; the last is beyond MAX_OFFSETS at 60×300.
                for sigma in [0.1, 0.6, 2.0, 9.0, 40.0, 500.0] {
                    let f = gaussian(sigma);
                    let got = map_squared_distance_f32(&obstacle, w, h, dx, dy, &f);
                    for (i, (g, &d2)) in got.iter().zip(&sq).enumerate() {
                        let want = f(d2);
                        assert!(
                            (g - want).abs() <= 1e-6,
                            "case {case} {w}×{h} σ {sigma} cell {i}: {g} vs {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn a_fall_off_that_never_reaches_zero_is_mapped_per_cell() {
        let (w, h) = (9, 7);
        let obstacle: Vec<bool> = (0..w * h).map(|i| i % 11 == 4).collect();
        let f = |d2: f32| 1.0 / (1.0 + d2);
        let sq = squared_distance_f32(&obstacle, w, h, 0.5, 0.8);
        let got = map_squared_distance_f32(&obstacle, w, h, 0.5, 0.8, f);
        assert!(got.iter().zip(&sq).all(|(&g, &d2)| g == f(d2)));
        // f(∞) ≠ 0 with no obstacle at all.
        let none = map_squared_distance_f32(&[false; 6], 3, 2, 1.0, 1.0, |d2| {
            (d2 < 1.0) as u8 as f32 + 0.5
        });
        assert_eq!(none, vec![0.5; 6]);
        assert!(map_squared_distance_f32(&[], 0, 4, 1.0, 1.0, f).is_empty());
        // More distinct offsets within reach than MAX_OFFSETS.
        let (w, h) = (1100, 1000);
        let obstacle: Vec<bool> = (0..w * h).map(|i| i % 7919 == 0).collect();
        let f = gaussian(1e4);
        let sq = squared_distance_f32(&obstacle, w, h, 1.0, 1.0);
        let got = map_squared_distance_f32(&obstacle, w, h, 1.0, 1.0, &f);
        assert!(got.iter().zip(&sq).all(|(&g, &d2)| g == f(d2)));
    }

    #[test]
    fn the_window_and_the_envelope_row_passes_agree() {
        let mut state = Lcg(0x3141_5926_u64);
        let mut next = || state.next();
        let mut compared = 0;
        for case in 0..40 {
            let (w, h) = (1 + (next() * 120.0) as usize, 1 + (next() * 150.0) as usize);
            let (dx, dy) = (0.3 + next() * 2.0, 0.3 + next() * 2.0);
            let density = [0.0, 0.005, 0.05, 0.5, 1.0][case % 5];
            let obstacle: Vec<bool> = (0..w * h).map(|_| next() < density).collect();
            let f = gaussian(0.2 + next() * 4.0);
            let window = Falloff::new(w, h, dx, dy, &f).unwrap();
            if window.window_radius().is_none() {
                continue;
            }
            let envelope = Falloff {
                window: Vec::new(),
                ..window.clone()
            };
            let a = map_with_table(&obstacle, w, h, dx, &window);
            let b = map_with_table(&obstacle, w, h, dx, &envelope);
            for (i, (x, y)) in a.iter().zip(&b).enumerate() {
                assert!((x - y).abs() <= 1e-6, "case {case} cell {i}: {x} vs {y}");
            }
            compared += 1;
        }
        assert!(compared >= 20, "{compared}");
    }
}
