//! Grey-scale dilation (moving maximum over a disk), used to fly a survey at
//! a height above the highest terrain within half a footprint (SPEC §3.3).
//!
//! The disk is measured in metres: for a projected DEM the cell size is the
//! length of the geotransform's column and row vectors; for a geographic
//! DEM those vectors (degrees) are converted with the local metres per
//! degree of the WGS84 ellipsoid at the latitude of the *output* row, so the
//! disk is an ellipse in pixel space whose width in columns grows towards
//! the poles. Degrees are never taken as metres.
//!
//! A cell belongs to the disk of an output cell when the distance between
//! the two cell centres is at most the radius.
//!
//! Algorithm: the disk is decomposed into rows; row offset `dy` covers the
//! columns `[c − w(dy), c + w(dy)]`. For every source row a sparse table of
//! maxima over windows of 2^j cells is built, so the maximum over any
//! window is that of two overlapping power-of-two windows (Urbach &
//! Wilkinson style). Work is O(W·H·(2R + 1)) for a disk R cells tall plus
//! O(W·H·log R) for the tables, with memory bounded independently of the
//! raster (the image is processed in tiles of rows × columns that stay in
//! cache), spread over the available cores.

use super::cell_size::cell_size_m;
use super::{Dem, GeoTransform};
use crate::cancel::{CancelToken, Cancelled};

/// Whether the cell `dx` columns and `dy` rows away (cells of `sx`×`sy`
/// metres) has its centre within √`r2` metres. Monotone in |dx| and |dy|.
#[inline]
fn in_disk(dx: usize, dy: usize, sx: f64, sy: f64, r2: f64) -> bool {
    let a = dx as f64 * sx;
    let b = dy as f64 * sy;
    a * a + b * b <= r2
}

/// Largest `k` ≤ `max` with `ok(k)`, starting from the estimate `est`
/// (`ok` is monotone: true up to some k, and `ok(0)` is assumed).
fn largest(est: f64, max: usize, ok: impl Fn(usize) -> bool) -> usize {
    let mut k = if est >= max as f64 {
        max
    } else if est >= 0.0 {
        est as usize
    } else {
        0 // also NaN
    };
    while k < max && ok(k + 1) {
        k += 1;
    }
    while k > 0 && !ok(k) {
        k -= 1;
    }
    k
}

/// The disk's geometry.
struct Disk {
    radius: f64,
    r2: f64,
    geographic: bool,
    transform: GeoTransform,
    width: usize,
    height: usize,
    /// Most rows above/below and columns left/right over all output rows.
    ry_max: usize,
    w_max: usize,
}

impl Disk {
    fn new(dem: &Dem, radius: f64) -> Option<Disk> {
        let mut d = Disk {
            radius,
            r2: radius * radius,
            geographic: dem.crs.geographic,
            transform: dem.transform,
            width: dem.width,
            height: dem.height,
            ry_max: 0,
            w_max: 0,
        };
        let rows = if d.geographic { dem.height } else { 1 };
        for r in 0..rows {
            let [sx, sy] = d.cell(r);
            if !(sx.is_finite() && sy.is_finite()) {
                return None;
            }
            let (ry, w0) = d.extent(sx, sy);
            d.ry_max = d.ry_max.max(ry);
            d.w_max = d.w_max.max(w0);
        }
        Some(d)
    }

    fn cell(&self, row: usize) -> [f64; 2] {
        cell_size_m(
            &self.transform,
            self.geographic,
            self.width as f64 / 2.0,
            row as f64 + 0.5,
        )
    }

    /// (rows above/below, columns left/right on the centre row), clipped to
    /// the raster.
    fn extent(&self, sx: f64, sy: f64) -> (usize, usize) {
        let ry = largest(self.radius / sy, self.height - 1, |k| {
            in_disk(0, k, sx, sy, self.r2)
        });
        let w0 = largest(self.radius / sx, self.width - 1, |k| {
            in_disk(k, 0, sx, sy, self.r2)
        });
        (ry, w0)
    }

    /// Appends the half-widths w(0), …, w(ry) of output row `row`'s disk.
    fn half_widths(&self, row: usize, out: &mut Vec<usize>) {
        let [sx, sy] = if self.geographic {
            self.cell(row)
        } else {
            self.cell(0)
        };
        let (ry, _) = self.extent(sx, sy);
        for k in 0..=ry {
            let b = k as f64 * sy;
            let est = (self.r2 - b * b).max(0.0).sqrt() / sx;
            out.push(largest(est, self.width - 1, |dx| {
                in_disk(dx, k, sx, sy, self.r2)
            }));
        }
    }
}

/// Grey-scale dilation: each valid cell takes the highest valid height
/// within `radius_m` metres (a disk, see the module documentation); nodata
/// cells stay nodata. A radius that reaches no neighbour (smaller than the
/// cell size), or that is not a positive number, returns a copy. Checks the
/// current thread's cancellation token ([`crate::cancel`]) every tile.
pub fn dilate(dem: &Dem, radius_m: f64) -> Result<Dem, Cancelled> {
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(8);
    dilate_with(dem, radius_m, threads, None, 4e6)
}

/// Tile sizes (columns, rows); `None` picks them from the disk size.
type Tiles = Option<(usize, usize)>;

/// `threads` are used only when the work (cells × disk rows) is at least
/// `min_parallel_work`.
fn dilate_with(
    dem: &Dem,
    radius_m: f64,
    threads: usize,
    tiles: Tiles,
    min_parallel_work: f64,
) -> Result<Dem, Cancelled> {
    let mut out = dem.clone();
    let (w, h) = (dem.width, dem.height);
    if w == 0 || h == 0 || dem.values.len() != w * h || radius_m.is_nan() || radius_m <= 0.0 {
        return Ok(out);
    }
    let Some(disk) = Disk::new(dem, radius_m) else {
        return Ok(out);
    };
    if disk.ry_max == 0 && disk.w_max == 0 {
        return Ok(out);
    }
    // Taken along to the band threads, which have no token of their own.
    let token = crate::cancel::current();
    let work = (w * h) as f64 * (2 * disk.ry_max + 1) as f64;
    let threads = if work < min_parallel_work {
        1
    } else {
        threads.clamp(1, h.div_ceil(16))
    };
    if threads == 1 {
        dilate_band(dem, &disk, 0, &mut out.values, tiles, &token)?;
    } else {
        let rows_per = h.div_ceil(threads);
        let (disk, token) = (&disk, &token);
        std::thread::scope(|sc| {
            let bands: Vec<_> = out
                .values
                .chunks_mut(rows_per * w)
                .enumerate()
                .map(|(i, band)| {
                    sc.spawn(move || dilate_band(dem, disk, i * rows_per, band, tiles, token))
                })
                .collect();
            bands.into_iter().try_for_each(|b| {
                b.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
        })?;
    }
    Ok(out)
}

#[inline]
fn floor_log2(n: usize) -> usize {
    debug_assert!(n > 0);
    (usize::BITS - 1 - n.leading_zeros()) as usize
}

/// Dilates output rows `b0 ..` (as many as `out` holds) into `out`,
/// checking `token` every tile.
fn dilate_band(
    dem: &Dem,
    disk: &Disk,
    b0: usize,
    out: &mut [f64],
    tiles: Tiles,
    token: &CancelToken,
) -> Result<(), Cancelled> {
    let (w, h) = (dem.width, dem.height);
    let src = &dem.values[..];
    let b1 = b0 + out.len() / w;
    let (strip, chunk) = tiles.unwrap_or_else(|| {
        let strip = disk.w_max.max(256);
        // Keep the accumulator tile ≤ 2^20 cells (8 MB) even for huge disks.
        let chunk = disk.ry_max.max(128).min((1 << 20) / strip.min(w)).max(16);
        (strip, chunk)
    });
    let strip = strip.clamp(1, w);
    let chunk = chunk.clamp(1, (b1 - b0).max(1));
    let k_max = floor_log2((2 * disk.w_max + 1).min(w));
    let sw_max = (strip + 2 * disk.w_max).min(w);
    let mut table = vec![f64::NEG_INFINITY; (k_max + 1) * sw_max];
    let mut acc = vec![f64::NEG_INFINITY; chunk * strip];
    let mut hw: Vec<usize> = Vec::new();
    let mut starts: Vec<usize> = Vec::with_capacity(chunk + 1);
    for c0 in (0..w).step_by(strip) {
        let c1 = (c0 + strip).min(w);
        let ncols = c1 - c0;
        let sc0 = c0.saturating_sub(disk.w_max);
        let sc1 = (c1 + disk.w_max).min(w);
        let sw = sc1 - sc0;
        for r0 in (b0..b1).step_by(chunk) {
            token.check()?;
            let r1 = (r0 + chunk).min(b1);
            hw.clear();
            starts.clear();
            for r in r0..r1 {
                starts.push(hw.len());
                disk.half_widths(r, &mut hw);
            }
            starts.push(hw.len());
            acc[..(r1 - r0) * ncols].fill(f64::NEG_INFINITY);
            let s_lo = r0.saturating_sub(disk.ry_max);
            let s_hi = (r1 - 1 + disk.ry_max).min(h - 1);
            for s in s_lo..=s_hi {
                let rr_lo = s.saturating_sub(disk.ry_max).max(r0);
                let rr_hi = (s + disk.ry_max + 1).min(r1);
                build_table(&src[s * w + sc0..s * w + sc1], &mut table, k_max);
                for r in rr_lo..rr_hi {
                    let k = r.abs_diff(s);
                    let row_hw = &hw[starts[r - r0]..starts[r - r0 + 1]];
                    if let Some(&half) = row_hw.get(k) {
                        let a = &mut acc[(r - r0) * ncols..(r - r0 + 1) * ncols];
                        window_max(a, &table[..(k_max + 1) * sw], sw, c0, sc0, half, w);
                    }
                }
            }
            for r in r0..r1 {
                let o = &mut out[(r - b0) * w + c0..(r - b0) * w + c1];
                let s = &src[r * w + c0..r * w + c1];
                let a = &acc[(r - r0) * ncols..(r - r0 + 1) * ncols];
                for ((o, &s), &a) in o.iter_mut().zip(s).zip(a) {
                    *o = if s.is_nan() { f64::NAN } else { a };
                }
            }
        }
    }
    Ok(())
}

/// Sparse table of one source row (`row`, NaN read as −∞): level j holds at
/// index i the maximum of `row[i .. i + 2^j]` (clipped at the row's end).
/// Levels are stored one after another, `row.len()` apart.
fn build_table(row: &[f64], table: &mut [f64], k_max: usize) {
    let sw = row.len();
    for (t, &v) in table[..sw].iter_mut().zip(row) {
        *t = if v.is_nan() { f64::NEG_INFINITY } else { v };
    }
    for j in 1..=k_max {
        let half = 1usize << (j - 1);
        let (lower, upper) = table.split_at_mut(j * sw);
        let prev = &lower[(j - 1) * sw..];
        let cur = &mut upper[..sw];
        if half >= sw {
            cur.copy_from_slice(prev);
            continue;
        }
        let n = sw - half;
        for ((c, &a), &b) in cur[..n].iter_mut().zip(&prev[..n]).zip(&prev[half..]) {
            *c = if a > b { a } else { b };
        }
        cur[n..].copy_from_slice(&prev[n..]);
    }
}

/// `acc[c − c0] = max(acc[c − c0], max of the row over [c − half, c + half])`
/// for the strip's output columns, the window clipped to the raster's
/// `width` columns; `table` is the row's sparse table over the source
/// columns `sc0 .. sc0 + sw`.
fn window_max(
    acc: &mut [f64],
    table: &[f64],
    sw: usize,
    c0: usize,
    sc0: usize,
    half: usize,
    width: usize,
) {
    let c1 = c0 + acc.len();
    // Interior: the whole window is inside the raster, same length.
    let lo = c0.max(half).min(c1);
    let hi = c1.min(width.saturating_sub(half)).max(lo);
    if lo < hi {
        let j = floor_log2(2 * half + 1);
        let p = 1usize << j;
        let t = &table[j * sw..(j + 1) * sw];
        let n = hi - lo;
        let a0 = lo - half - sc0;
        let b0 = lo + half + 1 - p - sc0;
        for ((o, &x), &y) in acc[lo - c0..hi - c0]
            .iter_mut()
            .zip(&t[a0..a0 + n])
            .zip(&t[b0..b0 + n])
        {
            let m = if x > y { x } else { y };
            *o = if m > *o { m } else { *o };
        }
    }
    // Near the raster's left and right edges the window is clipped.
    let edge = |acc: &mut [f64], c: usize| {
        let a = c.saturating_sub(half);
        let b = (c + half).min(width - 1);
        let j = floor_log2(b - a + 1);
        let p = 1usize << j;
        let t = &table[j * sw..(j + 1) * sw];
        let x = t[a - sc0];
        let y = t[b + 1 - p - sc0];
        let m = if x > y { x } else { y };
        let o = &mut acc[c - c0];
        *o = if m > *o { m } else { *o };
    };
    for c in (c0..lo).chain(hi..c1) {
        edge(acc, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::test_support::{dem, north_up};

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            // xorshift64*
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn random_dem(rng: &mut Rng, w: usize, h: usize, nan: f64, t: GeoTransform, geo: bool) -> Dem {
        let values = (0..w * h)
            .map(|_| {
                if rng.next() < nan {
                    f64::NAN
                } else {
                    (rng.next() * 1000.0).round() / 10.0 - 20.0
                }
            })
            .collect();
        dem(w, h, values, t, geo)
    }

    /// Straight from the definition: max over valid cells whose centre is
    /// within the radius, with the output row's cell size.
    fn brute(d: &Dem, radius: f64) -> Vec<f64> {
        let (w, h) = (d.width, d.height);
        let mut out = d.values.clone();
        if radius.is_nan() || radius <= 0.0 {
            return out;
        }
        for r in 0..h {
            let [sx, sy] = cell_size_m(
                &d.transform,
                d.crs.geographic,
                w as f64 / 2.0,
                r as f64 + 0.5,
            );
            for c in 0..w {
                if d.values[r * w + c].is_nan() {
                    continue;
                }
                let mut m = f64::NEG_INFINITY;
                for rr in 0..h {
                    for cc in 0..w {
                        let v = d.values[rr * w + cc];
                        if !v.is_nan()
                            && in_disk(c.abs_diff(cc), r.abs_diff(rr), sx, sy, radius * radius)
                        {
                            m = m.max(v);
                        }
                    }
                }
                out[r * w + c] = m;
            }
        }
        out
    }

    fn same(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(x, y)| (x.is_nan() && y.is_nan()) || x == y)
    }

    fn check_against_brute(d: &Dem, radii: &[f64]) {
        for &radius in radii {
            let expected = brute(d, radius);
            // Default tiling, one and several threads, and tiny tiles so that
            // strips, row chunks and their seams are exercised.
            for (threads, tiles) in [(1, None), (3, None), (1, Some((5, 4))), (2, Some((3, 1)))] {
                let got = dilate_with(d, radius, threads, tiles, 0.0).unwrap();
                assert!(
                    same(&got.values, &expected),
                    "{}×{} radius {radius} threads {threads} tiles {tiles:?}",
                    d.width,
                    d.height
                );
                assert_eq!(got.width, d.width);
                assert_eq!(got.transform, d.transform);
            }
        }
        assert!(same(
            &dilate(d, radii[0]).unwrap().values,
            &brute(d, radii[0])
        ));
    }

    #[test]
    fn matches_brute_force_projected() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        for (w, h) in [(23, 17), (1, 19), (19, 1), (2, 2), (40, 9)] {
            // Square and anisotropic cells.
            for (sx, sy) in [(1.0, 1.0), (2.0, 3.5)] {
                let d = random_dem(&mut rng, w, h, 0.2, north_up(500.0, 900.0, sx, sy), false);
                check_against_brute(&d, &[0.3, 1.0, 2.0, 2.5, 3.7, 6.0, 11.3, 1e9]);
                // The comparison is not vacuous: dilation changes the raster.
                if w * h > 100 {
                    assert!(!same(&dilate(&d, 6.0).unwrap().values, &d.values));
                }
            }
        }
    }

    #[test]
    fn matches_brute_force_geographic() {
        let mut rng = Rng(42);
        // 0.0001° cells at 60°N (about 5.6 m × 11.1 m) and near the equator,
        // and a tall raster spanning 55°–65° whose disk width varies by row.
        for (w, h, lat0, deg_x, deg_y) in [
            (21, 15, 60.0, 1e-4, 1e-4),
            (18, 13, 0.5, 1e-4, 1e-4),
            (9, 40, 65.0, 1e-4, 0.25),
            (13, 11, -45.0, 2e-4, 1e-4),
        ] {
            let d = random_dem(
                &mut rng,
                w,
                h,
                0.15,
                north_up(10.0, lat0, deg_x, deg_y),
                true,
            );
            check_against_brute(&d, &[3.0, 12.0, 25.0, 40.0, 30_000.0]);
        }
    }

    #[test]
    fn geographic_disk_is_measured_in_metres() {
        // A spike at 60°N on 0.001° cells: about 55.8 m east–west and
        // 111.4 m north–south. A 120 m disk reaches two columns and one row.
        let (w, h) = (9, 9);
        let mut values = vec![0.0; w * h];
        values[4 * w + 4] = 10.0;
        let d = dem(w, h, values, north_up(10.0, 60.0045, 0.001, 0.001), true);
        let [sx, sy] = cell_size_m(&d.transform, true, 4.5, 4.5);
        assert!(
            (sx - 55.8).abs() < 0.5 && (sy - 111.4).abs() < 0.5,
            "{sx} {sy}"
        );
        let got = dilate(&d, 120.0).unwrap();
        for r in 0..h {
            for c in 0..w {
                let (dx, dy) = (c.abs_diff(4) as f64 * sx, r.abs_diff(4) as f64 * sy);
                let expected = if dx * dx + dy * dy <= 120.0 * 120.0 {
                    10.0
                } else {
                    0.0
                };
                assert_eq!(got.values[r * w + c], expected, "({c}, {r})");
            }
        }
        assert_eq!(got.values[4 * w + 2], 10.0);
        assert_eq!(got.values[4 * w + 1], 0.0);
        assert_eq!(got.values[3 * w + 4], 10.0);
        assert_eq!(got.values[2 * w + 4], 0.0);
    }

    #[test]
    fn monotone_and_keeps_nodata() {
        let mut rng = Rng(7);
        let d = random_dem(&mut rng, 64, 48, 0.3, north_up(0.0, 0.0, 1.0, 1.0), false);
        let got = dilate(&d, 4.5).unwrap();
        for (a, b) in d.values.iter().zip(&got.values) {
            assert_eq!(a.is_nan(), b.is_nan());
            if !a.is_nan() {
                assert!(b >= a);
            }
        }
        // A larger radius dilates at least as much.
        let more = dilate(&d, 9.0).unwrap();
        for (a, b) in got.values.iter().zip(&more.values) {
            assert!(a.is_nan() || b >= a);
        }
    }

    #[test]
    fn flat_stays_flat_and_small_radius_copies() {
        let d = dem(
            30,
            20,
            vec![123.25; 600],
            north_up(0.0, 0.0, 5.0, 5.0),
            false,
        );
        assert_eq!(dilate(&d, 17.0).unwrap(), d);
        let mut rng = Rng(3);
        let d = random_dem(&mut rng, 12, 10, 0.2, north_up(0.0, 0.0, 5.0, 5.0), false);
        for r in [0.0, 2.4, 4.99, -3.0, f64::NAN] {
            assert_eq!(dilate(&d, r).unwrap().values.len(), 120);
            assert!(
                same(&dilate(&d, r).unwrap().values, &d.values),
                "radius {r}"
            );
        }
        // Infinite radius: every valid cell takes the global maximum.
        let max = d
            .values
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f64::MIN, f64::max);
        let got = dilate(&d, f64::INFINITY).unwrap();
        for (a, b) in d.values.iter().zip(&got.values) {
            assert!(if a.is_nan() { b.is_nan() } else { *b == max });
        }
    }

    #[test]
    fn all_nodata_and_empty() {
        let d = dem(
            5,
            4,
            vec![f64::NAN; 20],
            north_up(0.0, 0.0, 1.0, 1.0),
            false,
        );
        assert!(dilate(&d, 3.0).unwrap().values.iter().all(|v| v.is_nan()));
        let d = dem(0, 0, vec![], north_up(0.0, 0.0, 1.0, 1.0), false);
        assert_eq!(dilate(&d, 3.0).unwrap(), d);
        // Singular or non-finite geotransform: copy.
        let mut t = north_up(0.0, 0.0, 1.0, 1.0);
        t.pixel_width = f64::NAN;
        let d = dem(3, 3, vec![1.0; 9], t, false);
        assert!(same(&dilate(&d, 3.0).unwrap().values, &d.values));
    }

    /// `cargo test -p planner-core --release --lib terrain::dilate -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn timing_4000x4000() {
        let mut rng = Rng(11);
        let n = 4000;
        let d = random_dem(&mut rng, n, n, 0.01, north_up(0.0, 0.0, 1.0, 1.0), false);
        for (radius, threads) in [(30.0, 1), (30.0, 2), (100.0, 2)] {
            let t0 = std::time::Instant::now();
            let got = dilate_with(&d, radius, threads, None, 0.0).unwrap();
            eprintln!(
                "dilate {n}×{n}, radius {radius} cells, {threads} thread(s): {:?}",
                t0.elapsed()
            );
            assert_eq!(got.values.len(), n * n);
        }
    }
}
