//! Test support: a small seeded RNG, random grids, and an independent plain
//! Dijkstra written from the rules (8-connected, no corner cutting, the
//! same step lengths and arc costs) without the planners' code.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use super::{ArcCost, Cell, CostGrid};

/// SplitMix64: deterministic and dependency-free.
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Rng {
        Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ 0xd1b5_4a32_d192_ed03)
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [0, n).
    pub(crate) fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n.max(1)
    }

    pub(crate) fn range_f32(&mut self, lo: f32, hi: f32) -> f32 {
        (f64::from(lo) + self.unit() * f64::from(hi - lo)) as f32
    }
}

/// The thesis arc rule with a random d_max in [1, 16) when `thesis`
/// (drawing one number from `rng`), else the integrated one.
pub(crate) fn random_arc(rng: &mut Rng, thesis: bool) -> ArcCost {
    if thesis {
        ArcCost::Thesis {
            d_max: 1.0 + 15.0 * rng.unit(),
        }
    } else {
        ArcCost::Integrated
    }
}

/// A random w × h grid: costs of several styles (independent per cell,
/// smooth, a few levels, sub-unit costs), obstacles (scattered and in
/// blobs) covering about `density`, and with `varied_cells` non-square
/// cells whose width changes from row to row.
pub(crate) fn random_grid(
    rng: &mut Rng,
    width: usize,
    height: usize,
    density: f64,
    varied_cells: bool,
) -> CostGrid {
    let n = width * height;
    let style = rng.below(4);
    let mut costs: Vec<f32> = match style {
        0 => (0..n).map(|_| rng.range_f32(1.0, 20.0)).collect(),
        1 => {
            // Smooth: a few sine waves.
            let (a, b, p, q) = (
                rng.unit() * 0.5,
                rng.unit() * 0.5,
                rng.unit() * 6.0,
                rng.unit() * 6.0,
            );
            (0..n)
                .map(|i| {
                    let (r, c) = ((i / width) as f64, (i % width) as f64);
                    let v = ((a * r + p).sin() + (b * c + q).cos() + 2.0) / 4.0;
                    (1.0 + 19.0 * v) as f32
                })
                .collect()
        }
        2 => {
            let levels = [1.0f32, 2.0, 5.0, 20.0];
            (0..n).map(|_| levels[rng.below(4) as usize]).collect()
        }
        _ => (0..n).map(|_| rng.range_f32(0.2, 3.0)).collect(),
    };
    // Half the obstacles scattered, half in small blobs.
    let scattered = (density * 0.5 * n as f64) as usize;
    for _ in 0..scattered {
        costs[rng.below(n as u64) as usize] = f32::NAN;
    }
    let mut blob_cells = 0;
    while (blob_cells as f64) < density * 0.5 * n as f64 {
        let (r0, c0) = (
            rng.below(height as u64) as usize,
            rng.below(width as u64) as usize,
        );
        let (bh, bw) = (1 + rng.below(4) as usize, 1 + rng.below(4) as usize);
        for r in r0..(r0 + bh).min(height) {
            for c in c0..(c0 + bw).min(width) {
                costs[r * width + c] = if rng.below(2) == 0 {
                    f32::INFINITY
                } else {
                    f32::NAN
                };
                blob_cells += 1;
            }
        }
    }
    let (dx, dy) = if varied_cells {
        let base = 0.3 + 3.0 * rng.unit();
        let dy = 0.3 + 3.0 * rng.unit();
        let dx = (0..height)
            .map(|_| base * (0.6 + 0.8 * rng.unit()))
            .collect();
        (dx, dy)
    } else {
        (vec![1.0; height], 1.0)
    };
    CostGrid::new(width, height, costs, dx, dy).unwrap()
}

/// Value noise in [0, 1] at a few scales, w × h.
fn value_noise(rng: &mut Rng, width: usize, height: usize) -> Vec<f32> {
    let mut field = vec![0.0f32; width * height];
    for (scale, weight) in [(256usize, 0.5f32), (64, 0.3), (16, 0.2)] {
        let (gw, gh) = (width / scale + 2, height / scale + 2);
        let lattice: Vec<f32> = (0..gw * gh).map(|_| rng.unit() as f32).collect();
        for r in 0..height {
            let (fy, y0) = ((r % scale) as f32 / scale as f32, r / scale);
            for c in 0..width {
                let (fx, x0) = ((c % scale) as f32 / scale as f32, c / scale);
                let v = |y: usize, x: usize| lattice[y * gw + x];
                let top = v(y0, x0) * (1.0 - fx) + v(y0, x0 + 1) * fx;
                let bottom = v(y0 + 1, x0) * (1.0 - fx) + v(y0 + 1, x0 + 1) * fx;
                field[r * width + c] += weight * (top * (1.0 - fy) + bottom * fy);
            }
        }
    }
    field
}

/// The value below which a `fraction` of the field lies.
fn quantile(field: &[f32], fraction: f64) -> f32 {
    let mut sample: Vec<f32> = field.iter().copied().step_by(97).collect();
    sample.sort_by(f32::total_cmp);
    sample[(fraction * (sample.len() - 1) as f64) as usize]
}

/// A smooth costmap with costs spread over all of [1, 20] and obstacle
/// blobs (`obstacles` of the cells), 0.1 m cells: a hard case for A*,
/// whose heuristic (octile × least cost) then prunes little.
pub(crate) fn smooth_costmap(
    rng: &mut Rng,
    width: usize,
    height: usize,
    obstacles: f64,
) -> CostGrid {
    let field = value_noise(rng, width, height);
    let threshold = quantile(&field, 1.0 - obstacles);
    let costs = field
        .iter()
        .map(|&v| {
            if v > threshold {
                f32::NAN
            } else {
                1.0 + 19.0 * v.clamp(0.0, 1.0)
            }
        })
        .collect();
    CostGrid::with_cell_size(width, height, costs, 0.1, 0.1).unwrap()
}

/// A costmap shaped like SPEC §4.2's: mostly easy ground at cost 1, slopes
/// rising to 10 on the steeper half, `obstacles` of the cells blocked on
/// the steepest ground and an inflation band of up to +10 around them.
pub(crate) fn terrain_costmap(
    rng: &mut Rng,
    width: usize,
    height: usize,
    obstacles: f64,
) -> CostGrid {
    let field = value_noise(rng, width, height);
    let easy = quantile(&field, 0.5);
    let blocked = quantile(&field, 1.0 - obstacles);
    let band = 0.03f32;
    let costs = field
        .iter()
        .map(|&v| {
            if v > blocked {
                f32::NAN
            } else {
                let slope = 1.0 + 9.0 * ((v - easy) / (blocked - easy)).clamp(0.0, 1.0);
                let inflation = 10.0 * (1.0 - (blocked - v) / band).clamp(0.0, 1.0);
                slope + inflation
            }
        })
        .collect();
    CostGrid::with_cell_size(width, height, costs, 0.1, 0.1).unwrap()
}

/// CPU time of the calling thread in seconds (Linux; 0 elsewhere), so that
/// timings on a busy machine can be compared.
pub(crate) fn thread_cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/thread-self/stat") else {
        return 0.0;
    };
    let fields: Vec<&str> = stat
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|f| f.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime, in clock ticks of 1/100 s.
    (ticks(11) + ticks(12)) / 100.0
}

/// Grid sizes for the timing tests: `ROUTE_SIZES=2000,4000` (the default).
pub(crate) fn sizes_from_env() -> Vec<usize> {
    std::env::var("ROUTE_SIZES")
        .unwrap_or_else(|_| "2000,4000".into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect()
}

/// The timing tests' maps, built one at a time: for each size from
/// `ROUTE_SIZES`, a "smooth" and a "terrain" costmap with 5 % obstacles.
pub(crate) fn timing_costmaps() -> impl Iterator<Item = (usize, &'static str, CostGrid)> {
    sizes_from_env().into_iter().flat_map(|size| {
        ["smooth", "terrain"].into_iter().map(move |kind| {
            let mut rng = Rng::new(1);
            let grid = if kind == "smooth" {
                smooth_costmap(&mut rng, size, size, 0.05)
            } else {
                terrain_costmap(&mut rng, size, size, 0.05)
            };
            (size, kind, grid)
        })
    })
}

/// The traversable cells nearest the top-left and bottom-right corners.
pub(crate) fn far_corners(grid: &CostGrid) -> (Cell, Cell) {
    let nearest = |from: Cell| {
        (0..grid.cell_count())
            .map(|i| grid.cell(i).unwrap())
            .filter(|&c| grid.is_traversable(c))
            .min_by_key(|&(r, c)| r.abs_diff(from.0).max(c.abs_diff(from.1)))
            .unwrap()
    };
    (
        nearest((0, 0)),
        nearest((grid.height() - 1, grid.width() - 1)),
    )
}

/// Two random traversable cells (possibly equal), if there are any.
pub(crate) fn random_endpoints(rng: &mut Rng, grid: &CostGrid) -> Option<(Cell, Cell)> {
    let mut pick = || {
        (0..200).find_map(|_| {
            let c = (
                rng.below(grid.height() as u64) as usize,
                rng.below(grid.width() as u64) as usize,
            );
            grid.is_traversable(c).then_some(c)
        })
    };
    Some((pick()?, pick()?))
}

#[derive(PartialEq)]
struct Key(f64);
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Key {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}

fn free(grid: &CostGrid, r: isize, c: isize) -> bool {
    r >= 0 && c >= 0 && grid.is_traversable((r as usize, c as usize))
}

/// Plain Dijkstra from `start`; the optimal cost to `goal` or `None`.
pub(crate) fn dijkstra(grid: &CostGrid, start: Cell, goal: Cell, arc: ArcCost) -> Option<f64> {
    let (w, h) = (grid.width(), grid.height());
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &c in grid.costs() {
        if c.is_finite() {
            lo = lo.min(f64::from(c));
            hi = hi.max(f64::from(c));
        }
    }
    let arc_cost = |a: f64, b: f64, len: f64| match arc {
        ArcCost::Integrated => len * (a + b) / 2.0,
        ArcCost::Thesis { d_max } => {
            let norm = if hi > lo {
                (b - a + (hi - lo)) / (2.0 * (hi - lo))
            } else {
                0.5
            };
            len * (1.0 + (d_max - 1.0) * norm)
        }
    };
    if !grid.is_traversable(start) || !grid.is_traversable(goal) {
        return None;
    }
    let mut dist = vec![f64::INFINITY; w * h];
    let mut heap = BinaryHeap::new();
    dist[start.0 * w + start.1] = 0.0;
    heap.push(Reverse((Key(0.0), start.0, start.1)));
    while let Some(Reverse((Key(d), r, c))) = heap.pop() {
        if (r, c) == goal {
            return Some(d);
        }
        if d > dist[r * w + c] {
            continue;
        }
        for dr in -1isize..=1 {
            for dc in -1isize..=1 {
                if dr == 0 && dc == 0 {
                    continue;
                }
                let (nr, nc) = (r as isize + dr, c as isize + dc);
                if nr >= h as isize || nc >= w as isize || !free(grid, nr, nc) {
                    continue;
                }
                if dr != 0
                    && dc != 0
                    && !(free(grid, r as isize + dr, c as isize)
                        && free(grid, r as isize, c as isize + dc))
                {
                    continue;
                }
                let (nr, nc) = (nr as usize, nc as usize);
                let len = if dr == 0 {
                    grid.dx(r)
                } else if dc == 0 {
                    grid.dy()
                } else {
                    let mean_dx = (grid.dx(r) + grid.dx(nr)) / 2.0;
                    (mean_dx * mean_dx + grid.dy() * grid.dy()).sqrt()
                };
                let a = f64::from(grid.cost((r, c)).unwrap());
                let b = f64::from(grid.cost((nr, nc)).unwrap());
                let nd = d + arc_cost(a, b, len);
                if nd < dist[nr * w + nc] {
                    dist[nr * w + nc] = nd;
                    heap.push(Reverse((Key(nd), nr, nc)));
                }
            }
        }
    }
    None
}

/// Does the straight segment between two cell centres touch the closed
/// square of any blocked cell? Exact, in doubled integer coordinates:
/// bounding boxes overlap and the square's corners are not all strictly on
/// one side of the line. Touching a blocked cell only at its corner counts,
/// which is exactly corner cutting.
pub(crate) fn segment_touches_blocked(grid: &CostGrid, a: Cell, b: Cell) -> bool {
    let (x0, y0) = (2 * a.1 as i64 + 1, 2 * a.0 as i64 + 1);
    let (x1, y1) = (2 * b.1 as i64 + 1, 2 * b.0 as i64 + 1);
    let (rmin, rmax) = (
        a.0.min(b.0).saturating_sub(1),
        (a.0.max(b.0) + 1).min(grid.height() - 1),
    );
    let (cmin, cmax) = (
        a.1.min(b.1).saturating_sub(1),
        (a.1.max(b.1) + 1).min(grid.width() - 1),
    );
    for r in rmin..=rmax {
        for c in cmin..=cmax {
            if grid.is_traversable((r, c)) {
                continue;
            }
            let (sx0, sy0, sx1, sy1) = (
                2 * c as i64,
                2 * r as i64,
                2 * c as i64 + 2,
                2 * r as i64 + 2,
            );
            if x0.max(x1) < sx0 || x0.min(x1) > sx1 || y0.max(y1) < sy0 || y0.min(y1) > sy1 {
                continue;
            }
            let side = |x: i64, y: i64| ((x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)).signum();
            let sides = [
                side(sx0, sy0),
                side(sx1, sy0),
                side(sx0, sy1),
                side(sx1, sy1),
            ];
            if sides.iter().all(|&s| s > 0) || sides.iter().all(|&s| s < 0) {
                continue;
            }
            return true;
        }
    }
    false
}

/// A cell path must step between 8-neighbours over traversable cells
/// without cutting a blocked corner.
pub(crate) fn assert_path_valid(grid: &CostGrid, cells: &[Cell]) {
    for &c in cells {
        assert!(grid.is_traversable(c), "{c:?} is blocked");
    }
    for p in cells.windows(2) {
        let (dr, dc) = (p[0].0.abs_diff(p[1].0), p[0].1.abs_diff(p[1].1));
        assert!(
            dr <= 1 && dc <= 1 && dr + dc > 0,
            "{:?} → {:?} is not a step",
            p[0],
            p[1]
        );
        assert!(
            !segment_touches_blocked(grid, p[0], p[1]),
            "{:?} → {:?} cuts a blocked corner",
            p[0],
            p[1]
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocked_square_test_is_exact() {
        const X: f32 = f32::NAN;
        #[rustfmt::skip]
        let g = CostGrid::with_cell_size(4, 4, vec![
            1.0, 1.0, 1.0, 1.0,
            1.0, X,   1.0, 1.0,
            1.0, 1.0, 1.0, 1.0,
            1.0, 1.0, 1.0, 1.0,
        ], 1.0, 1.0).unwrap();
        assert!(
            segment_touches_blocked(&g, (0, 0), (2, 2)),
            "through the blocked cell"
        );
        assert!(
            segment_touches_blocked(&g, (0, 1), (1, 2)),
            "diagonal past its corner"
        );
        assert!(segment_touches_blocked(&g, (0, 2), (1, 1)), "ends in it");
        assert!(
            segment_touches_blocked(&g, (0, 0), (1, 2))
                == segment_touches_blocked(&g, (1, 2), (0, 0))
        );
        assert!(
            segment_touches_blocked(&g, (2, 1), (1, 2)),
            "diagonal past its corner"
        );
        assert!(!segment_touches_blocked(&g, (2, 0), (3, 1)));
        assert!(!segment_touches_blocked(&g, (0, 2), (3, 3)));
        // Centre (0.5, 0.5) → (2.5, 1.5): over the blocked column [1, 2]
        // y ∈ [0.75, 1.25], which overlaps the cell's [1, 2].
        assert!(segment_touches_blocked(&g, (0, 0), (1, 2)));
        assert!(!segment_touches_blocked(&g, (0, 0), (0, 3)));
    }

    #[test]
    fn reference_dijkstra_on_a_tiny_grid() {
        let g = CostGrid::with_cell_size(3, 1, vec![1.0, 3.0, 5.0], 2.0, 1.0).unwrap();
        assert_eq!(
            dijkstra(&g, (0, 0), (0, 2), ArcCost::Integrated),
            Some(2.0 * 2.0 + 2.0 * 4.0)
        );
        // Thesis with costs 1..5: δ = +2 twice, c = 1 + 9·(2 + 4)/8.
        let c = 1.0 + 9.0 * 6.0 / 8.0;
        let got = dijkstra(&g, (0, 0), (0, 2), ArcCost::thesis()).unwrap();
        assert!((got - 4.0 * c).abs() < 1e-12);
    }
}
