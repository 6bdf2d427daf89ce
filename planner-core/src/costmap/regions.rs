//! Region filling (thesis §3.3–3.4, SPEC §4.2 step 5): a traversable
//! pocket fully enclosed by obstacles cannot be reached, so when it is
//! smaller than a minimum area it becomes an obstacle too.
//!
//! Pockets are 4-connected: the route planner does not cut corners past
//! obstacle cells, so two traversable cells touching only at a corner
//! between obstacles are not connected for it either. A region touching
//! the grid's edge or an unknown cell may continue beyond what is known,
//! so it is never filled.

use rayon::prelude::*;

use super::Class;

/// Rows per band: bands are scanned and joined up in parallel.
const BAND_ROWS: usize = 64;

/// Marks every enclosed traversable region of fewer than `min_cells`
/// cells as [`Class::Enclosed`]; returns how many regions were filled.
///
/// Works on horizontal runs of traversable cells rather than on cells: a
/// DEM has far fewer runs than cells. Bands of rows are scanned for runs,
/// and runs overlapping between adjacent rows joined with a union-find, in
/// parallel; then the bands are joined where they meet.
pub fn fill_enclosed(class: &mut [u8], width: usize, height: usize, min_cells: f64) -> usize {
    assert_eq!(class.len(), width * height, "grid size");
    if class.is_empty() {
        return 0;
    }
    // Run indices, positions and region sizes are u32.
    if u32::try_from(class.len()).is_err() {
        return fill_enclosed_flood(class, width, height, min_cells);
    }
    // Most rows have no unknown cell: their neighbours' runs need not look.
    let unknown_rows: Vec<bool> = class
        .par_chunks(width)
        .map(|row| row.contains(&(Class::Unknown as u8)))
        .collect();
    let bands: Vec<Runs> = (0..height.div_ceil(BAND_ROWS))
        .into_par_iter()
        .map(|b| Runs::scan(class, width, &unknown_rows, b * BAND_ROWS))
        .collect();
    // One forest over all runs, numbered band by band; per run, its
    // region's size and openness once it is a root.
    let n: usize = bands.iter().map(|b| b.span.len()).sum();
    let mut parent = vec![0u32; n];
    let mut size = vec![0u32; n];
    let mut open = vec![false; n];
    let mut base = Vec::with_capacity(bands.len());
    {
        let mut parts = Vec::with_capacity(bands.len());
        let (mut p, mut s, mut o) = (&mut parent[..], &mut size[..], &mut open[..]);
        let mut start = 0u32;
        for band in &bands {
            let k = band.span.len();
            let (p0, p1) = p.split_at_mut(k);
            let (s0, s1) = s.split_at_mut(k);
            let (o0, o1) = o.split_at_mut(k);
            parts.push((band, start, p0, s0, o0));
            base.push(start);
            (p, s, o) = (p1, s1, o1);
            start += k as u32;
        }
        parts
            .into_par_iter()
            .for_each(|(band, start, p, s, o)| band.join(start, p, s, o));
    }
    // Where bands meet. Only the roots of the runs there can stop being
    // roots, handing their size and openness on.
    let mut met = Vec::new();
    let mut forest = Forest {
        parent: &mut parent,
        start: 0,
    };
    for b in 1..bands.len() {
        let (above, below) = (bands[b - 1].row(BAND_ROWS - 1), bands[b].row(0));
        let (a0, b0) = (base[b - 1] + above.start as u32, base[b]);
        let (above, below) = (&bands[b - 1].span[above], &bands[b].span[below]);
        let roots = |first: u32, k: usize| first as usize..first as usize + k;
        met.extend_from_slice(&forest.parent[roots(a0, above.len())]);
        met.extend_from_slice(&forest.parent[roots(b0, below.len())]);
        forest.join_rows((a0, above), (b0, below));
    }
    for r in met {
        let root = forest.find(r);
        if root != r {
            size[root as usize] += std::mem::take(&mut size[r as usize]);
            open[root as usize] |= open[r as usize];
        }
    }
    let fill = |r: u32| !open[r as usize] && f64::from(size[r as usize]) < min_cells;
    let parent = &parent;
    class
        .par_chunks_mut(BAND_ROWS * width)
        .zip(&bands)
        .zip(&base)
        .map(|((rows, band), &start)| {
            let mut filled = 0;
            for (r, row) in rows.chunks_exact_mut(width).enumerate() {
                for i in band.row(r) {
                    let g = start + i as u32;
                    let mut root = parent[g as usize];
                    while parent[root as usize] != root {
                        root = parent[root as usize];
                    }
                    if fill(root) {
                        let (s, e) = band.span[i];
                        row[s as usize..e as usize].fill(Class::Enclosed as u8);
                        filled += usize::from(root == g);
                    }
                }
            }
            filled
        })
        .sum()
}

/// The traversable runs of a band of rows.
struct Runs {
    /// [start, end) columns of each run, row by row.
    span: Vec<(u32, u32)>,
    /// The run touches the grid's edge or an unknown cell.
    open: Vec<bool>,
    /// For each row, the index in `span` just past its last run.
    row_end: Vec<u32>,
}

impl Runs {
    /// The runs of the band of rows from `y0`.
    fn scan(class: &[u8], width: usize, unknown_rows: &[bool], y0: usize) -> Runs {
        let height = unknown_rows.len();
        let (trav, unknown) = (Class::Traversable as u8, Class::Unknown as u8);
        let y1 = (y0 + BAND_ROWS).min(height);
        let mut runs = Runs {
            span: Vec::new(),
            open: Vec::new(),
            row_end: Vec::with_capacity(y1 - y0),
        };
        let line = |y: usize| &class[y * width..(y + 1) * width];
        for y in y0..y1 {
            let row = line(y);
            let edge_row = y == 0 || y + 1 == height;
            // Rows beside this one that hold an unknown cell.
            let above = (!edge_row && unknown_rows[y - 1]).then(|| line(y - 1));
            let below = (!edge_row && unknown_rows[y + 1]).then(|| line(y + 1));
            let mut x = 0;
            loop {
                let s = find_byte(row, x, trav, true);
                if s == width {
                    break;
                }
                let e = find_byte(row, s, trav, false);
                let has_unknown =
                    |line: Option<&[u8]>| line.is_some_and(|l| l[s..e].contains(&unknown));
                let open = edge_row
                    || s == 0
                    || e == width
                    || row[s - 1] == unknown
                    || row[e] == unknown
                    || has_unknown(above)
                    || has_unknown(below);
                runs.span.push((s as u32, e as u32));
                runs.open.push(open);
                x = e;
            }
            runs.row_end.push(runs.span.len() as u32);
        }
        runs
    }

    /// Indices of the runs of the band's row `r`.
    fn row(&self, r: usize) -> std::ops::Range<usize> {
        let start = if r == 0 { 0 } else { self.row_end[r - 1] };
        start as usize..self.row_end[r] as usize
    }

    /// Joins the band's runs into regions: `parent`, `size` and `open` are
    /// this band's part of the forest, whose first run is `start`. Leaves
    /// every run pointing at its root, which holds the region's size and
    /// openness.
    fn join(&self, start: u32, parent: &mut [u32], size: &mut [u32], open: &mut [bool]) {
        // Indices are global in `parent`'s values, local in its positions.
        let mut forest = Forest { parent, start };
        for (i, p) in forest.parent.iter_mut().enumerate() {
            *p = start + i as u32;
        }
        for r in 1..self.row_end.len() {
            let (above, below) = (self.row(r - 1), self.row(r));
            forest.join_rows(
                (start + above.start as u32, &self.span[above]),
                (start + below.start as u32, &self.span[below]),
            );
        }
        // Roots are their region's smallest index (see `union`), so one
        // pass in order points every run at its root and sums into it.
        for i in 0..self.span.len() {
            let root = (forest.parent[forest.parent[i] as usize - start as usize] - start) as usize;
            forest.parent[i] = start + root as u32;
            let (s, e) = self.span[i];
            size[root] += e - s;
            open[root] |= self.open[i];
        }
    }
}

/// A union-find over runs numbered from `start` (`parent[i]` is run
/// `start + i`'s parent).
struct Forest<'a> {
    parent: &'a mut [u32],
    start: u32,
}

impl Forest<'_> {
    fn find(&mut self, mut i: u32) -> u32 {
        let at = |i: u32| (i - self.start) as usize;
        while self.parent[at(i)] != i {
            // Path halving.
            let p = self.parent[at(self.parent[at(i)])];
            self.parent[at(i)] = p;
            i = p;
        }
        i
    }

    /// Links the larger root under the smaller, so that a root is its
    /// region's smallest index.
    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[(ra.max(rb) - self.start) as usize] = ra.min(rb);
        }
    }

    /// Joins the runs of two adjacent rows (index of the first run, runs)
    /// that share a column: 4-connectivity.
    fn join_rows(&mut self, (a0, a): (u32, &[(u32, u32)]), (b0, b): (u32, &[(u32, u32)])) {
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            let ((sa, ea), (sb, eb)) = (a[i], b[j]);
            if sa < eb && sb < ea {
                self.union(a0 + i as u32, b0 + j as u32);
            }
            if ea <= eb {
                i += 1;
            } else {
                j += 1;
            }
        }
    }
}

/// The first index ≥ `from` where `row` equals `byte` (`equal`) or differs
/// from it (`!equal`); `row.len()` if none. Eight bytes at a time, since
/// runs are mostly long.
fn find_byte(row: &[u8], from: usize, byte: u8, equal: bool) -> usize {
    const LOW: u64 = u64::from_ne_bytes([0x01; 8]);
    const HIGH: u64 = u64::from_ne_bytes([0x80; 8]);
    let pattern = LOW * u64::from(byte);
    let mut i = from;
    while let Some(word) = row.get(i..i + 8) {
        // Zero bytes of `v` are the bytes equal to `byte`.
        let v = u64::from_le_bytes(word.try_into().unwrap()) ^ pattern;
        // High bit set on the bytes that match (exact for the lowest one,
        // which is all trailing_zeros looks at).
        let hits = if equal {
            v.wrapping_sub(LOW) & !v & HIGH
        } else {
            v
        };
        if hits != 0 {
            return i + (hits.trailing_zeros() / 8) as usize;
        }
        i += 8;
    }
    i + row[i..]
        .iter()
        .position(|&b| (b == byte) == equal)
        .unwrap_or(row.len() - i)
}

/// [`fill_enclosed`] by a flood fill from each cell: for grids of more
/// than `u32::MAX` cells, and the reference in tests.
fn fill_enclosed_flood(class: &mut [u8], width: usize, height: usize, min_cells: f64) -> usize {
    const SEEN: u8 = 0x80;
    let trav = Class::Traversable as u8;
    let mut stack: Vec<usize> = Vec::new();
    let mut region: Vec<usize> = Vec::new();
    let mut filled = 0;
    for start in 0..class.len() {
        if class[start] != trav {
            continue;
        }
        // Flood the region, noting whether it escapes.
        class[start] |= SEEN;
        stack.push(start);
        region.clear();
        let mut open = false;
        while let Some(i) = stack.pop() {
            // Only regions that may be filled need their cells listed.
            if !open {
                region.push(i);
            }
            let (c, r) = (i % width, i / width);
            if c == 0 || r == 0 || c + 1 == width || r + 1 == height {
                open = true;
            }
            let mut visit = |j: usize| {
                let k = class[j];
                if k == trav {
                    class[j] |= SEEN;
                    stack.push(j);
                } else if k == Class::Unknown as u8 {
                    open = true;
                }
            };
            if c > 0 {
                visit(i - 1);
            }
            if c + 1 < width {
                visit(i + 1);
            }
            if r > 0 {
                visit(i - width);
            }
            if r + 1 < height {
                visit(i + width);
            }
        }
        if !open && (region.len() as f64) < min_cells {
            for &i in &region {
                class[i] = Class::Enclosed as u8 | SEEN;
            }
            filled += 1;
        }
    }
    for k in class.iter_mut() {
        *k &= !SEEN;
    }
    filled
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_rng::Lcg;

    /// A grid from rows of '.', '#' (slope obstacle) and '?' (unknown).
    fn grid(rows: &[&str]) -> (Vec<u8>, usize, usize) {
        let w = rows[0].len();
        let cells = rows
            .iter()
            .flat_map(|r| r.chars())
            .map(|ch| match ch {
                '.' => Class::Traversable as u8,
                '#' => Class::Slope as u8,
                _ => Class::Unknown as u8,
            })
            .collect();
        (cells, w, rows.len())
    }

    #[test]
    fn small_enclosed_pockets_are_filled_and_large_or_open_ones_kept() {
        let (mut g, w, h) = grid(&[
            "..........",
            ".####.###.",
            ".#..#.#.#.",
            ".####.###.",
            "..........",
            "#####.....",
            "#...#.....",
            "#...#..#?#",
            "#####..#.#",
            ".......###",
        ]);
        // Pockets: 2 cells (row 2, cols 2–3), 1 cell (row 2, col 7),
        // 6 cells (rows 6–7, cols 1–3), and one cell (row 8, col 8)
        // touching an unknown cell.
        let filled = fill_enclosed(&mut g, w, h, 3.0);
        assert_eq!(filled, 2);
        let at = |g: &[u8], r: usize, c: usize| Class::from_code(g[r * w + c]).unwrap();
        assert_eq!(at(&g, 2, 2), Class::Enclosed);
        assert_eq!(at(&g, 2, 3), Class::Enclosed);
        assert_eq!(at(&g, 2, 7), Class::Enclosed);
        assert_eq!(at(&g, 6, 1), Class::Traversable, "6 cells ≥ 3");
        assert_eq!(at(&g, 8, 8), Class::Traversable, "touches unknown");
        assert_eq!(at(&g, 0, 0), Class::Traversable);
        // A larger limit fills the 6-cell pocket too.
        let filled = fill_enclosed(&mut g, w, h, 7.0);
        assert_eq!(filled, 1);
        assert_eq!(at(&g, 7, 3), Class::Enclosed);
    }

    #[test]
    fn corner_contact_does_not_connect() {
        let (mut g, w, h) = grid(&["....", ".##.", ".#.#", "..#."]);
        // (2,2) touches the open area only diagonally: enclosed; (3,3) is
        // on the edge.
        assert_eq!(fill_enclosed(&mut g, w, h, 2.0), 1);
        assert_eq!(g[2 * w + 2], Class::Enclosed as u8);
        assert_eq!(g[3 * w + 3], Class::Traversable as u8);
    }

    /// Random classes: obstacles in the given share, a few unknown cells.
    fn random_grid(next: &mut impl FnMut() -> f64, w: usize, h: usize, obstacles: f64) -> Vec<u8> {
        (0..w * h)
            .map(|_| {
                let u = next();
                if u < obstacles {
                    [Class::Slope, Class::Step, Class::Enclosed, Class::Other]
                        [(u * 1e6) as usize % 4]
                } else if u < obstacles + 0.01 {
                    Class::Unknown
                } else {
                    Class::Traversable
                }
            } as u8)
            .collect()
    }

    #[test]
    fn runs_equal_the_flood_fill_on_random_grids() {
        let mut state = Lcg(0x2e91_u64);
        let mut next = || state.next();
        let mut cases = 0;
        // Tiny grids, and grids taller than a band (bands meet inside).
        let mut sizes = vec![(1, 1), (1, 3), (3, 1), (2, 2), (3, 3), (2, 7), (9, 2)];
        sizes
            .extend((0..40).map(|_| (1 + (next() * 40.0) as usize, 1 + (next() * 200.0) as usize)));
        for (w, h) in sizes {
            for obstacles in [0.0, 0.2, 0.45, 0.6, 1.0] {
                let g = random_grid(&mut next, w, h, obstacles);
                for min_cells in [0.0, 1.5, 4.0, 50.0, 1e9] {
                    let (mut a, mut b) = (g.clone(), g.clone());
                    let na = fill_enclosed(&mut a, w, h, min_cells);
                    let nb = fill_enclosed_flood(&mut b, w, h, min_cells);
                    assert_eq!((na, &a), (nb, &b), "{w}×{h}, {obstacles}, {min_cells}");
                    cases += usize::from(na > 0);
                }
            }
        }
        assert!(cases > 50, "too few grids with filled pockets: {cases}");
    }

    #[test]
    fn uniform_grids() {
        for (w, h) in [(1, 1), (3, 2), (70, 130)] {
            for k in Class::ALL {
                let mut g = vec![k as u8; w * h];
                assert_eq!(fill_enclosed(&mut g, w, h, 1e9), 0);
                assert!(g.iter().all(|&c| c == k as u8));
            }
        }
        assert_eq!(fill_enclosed(&mut [], 0, 5, 10.0), 0);
    }

    #[test]
    fn pockets_spanning_bands_are_one_region() {
        // A 1-column pocket 150 rows tall inside a wall, crossing bands.
        let (w, h) = (5, 160);
        let mut g: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let inside = x == 2 && (5..155).contains(&y);
                (if inside || x == 0 || x == 4 {
                    Class::Traversable
                } else {
                    Class::Slope
                }) as u8
            })
            .collect();
        assert_eq!(fill_enclosed(&mut g.clone(), w, h, 150.0), 0, "150 cells");
        assert_eq!(fill_enclosed(&mut g, w, h, 151.0), 1);
        assert_eq!(
            g.iter().filter(|&&c| c == Class::Enclosed as u8).count(),
            150
        );
    }

    #[test]
    fn runs_equal_the_flood_fill_on_mazes_spanning_bands() {
        // Random walls cut the grid into rooms of all sizes, many spanning
        // band boundaries, some reaching the edge or an unknown cell.
        let mut state = 0x4d41_5a45_u64;
        let mut next = |n: usize| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 33) as usize) % n
        };
        let mut filled = 0;
        for _ in 0..20 {
            let (w, h) = (2 + next(80), 2 + next(400));
            let mut g = vec![Class::Traversable as u8; w * h];
            for _ in 0..next(60) {
                let (x, y, len) = (next(w), next(h), next(200));
                let horizontal = next(2) == 0;
                for k in 0..len {
                    let (x, y) = if horizontal { (x + k, y) } else { (x, y + k) };
                    if x < w && y < h {
                        g[y * w + x] = Class::Step as u8;
                    }
                }
            }
            for _ in 0..next(3) {
                g[next(w * h)] = Class::Unknown as u8;
            }
            for min_cells in [10.0, 300.0, 1e9] {
                let (mut a, mut b) = (g.clone(), g.clone());
                let na = fill_enclosed(&mut a, w, h, min_cells);
                assert_eq!((na, &a), (fill_enclosed_flood(&mut b, w, h, min_cells), &b));
                filled += na;
            }
        }
        assert!(filled > 20, "{filled}");
    }
}
