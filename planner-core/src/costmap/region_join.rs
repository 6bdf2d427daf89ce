//! The enclosed-pocket fill (SPEC §4.2 step 5, [`super::regions`]) over
//! tiles: each tile's traversable cells are labelled on their own
//! (4-connected, as the whole-grid fill), the labels on the tile's four
//! edges are kept with each label's size and openness, and a union–find
//! over the edges' labels joins the regions that cross tile borders. A
//! region is then filled exactly when the whole-grid fill would fill it:
//! not open (touching the grid's edge or an unknown cell) and smaller
//! than the minimum.
//!
//! What is kept between the passes is small: four edges of labels per
//! tile and the facts of the labels on them, never a label per cell.

use super::Class;
use super::halo::{TileLayout, TileWindow};

/// The traversable regions of one tile's core.
pub struct TileLabels {
    /// Per core cell (row-major): 0 off traversable cells, else the
    /// region's label, 1…, numbered in order of first cell.
    pub labels: Vec<u32>,
    /// Per label (index 0 unused): its cells in this tile.
    pub size: Vec<u64>,
    /// Per label: it touches the grid's edge or an unknown cell here.
    pub open: Vec<bool>,
}

/// Labels the traversable cells of `tile`, whose classes are in `window`
/// (row-major, `ww` cells wide, the core at (`dx`, `dy`), holding at
/// least one more cell around the core wherever the grid does):
/// `grid` is the whole grid's [width, height].
pub fn label_tile(
    window: &[u8],
    ww: usize,
    [dx, dy]: [usize; 2],
    tile: &TileWindow,
    [gw, gh]: [usize; 2],
) -> TileLabels {
    let (w, h) = (tile.width, tile.height);
    let wh = window.len() / ww.max(1);
    let (trav, unknown) = (Class::Traversable as u8, Class::Unknown as u8);
    let at = |c: usize, r: usize| window[(dy + r) * ww + dx + c];
    // Union–find over cells, each pointing at a smaller index; a root is
    // its region's first cell.
    let mut parent: Vec<u32> = (0..(w * h) as u32).collect();
    fn find(parent: &mut [u32], mut i: u32) -> u32 {
        while parent[i as usize] != i {
            let up = parent[parent[i as usize] as usize];
            parent[i as usize] = up;
            i = up;
        }
        i
    }
    for r in 0..h {
        for c in 0..w {
            if at(c, r) != trav {
                continue;
            }
            let i = (r * w + c) as u32;
            let join = |j: u32, parent: &mut Vec<u32>| {
                let (a, b) = (find(parent, i), find(parent, j));
                let (lo, hi) = (a.min(b), a.max(b));
                parent[hi as usize] = lo;
            };
            if c > 0 && at(c - 1, r) == trav {
                join(i - 1, &mut parent);
            }
            if r > 0 && at(c, r - 1) == trav {
                join(i - w as u32, &mut parent);
            }
        }
    }
    let mut labels = vec![0u32; w * h];
    let mut size = vec![0u64];
    let mut open = vec![false];
    // A neighbour outside the window is outside the grid.
    let neighbour_unknown = |c: isize, r: isize| -> bool {
        let (wc, wr) = (dx as isize + c, dy as isize + r);
        if wc < 0 || wr < 0 || wc >= ww as isize || wr >= wh as isize {
            return false;
        }
        window[wr as usize * ww + wc as usize] == unknown
    };
    for r in 0..h {
        for c in 0..w {
            if at(c, r) != trav {
                continue;
            }
            let i = r * w + c;
            let root = find(&mut parent, i as u32) as usize;
            let label = if root == i {
                size.push(0);
                open.push(false);
                (size.len() - 1) as u32
            } else {
                labels[root]
            };
            labels[i] = label;
            let l = label as usize;
            size[l] += 1;
            let (gc, gr) = (tile.col0 + c, tile.row0 + r);
            let (ci, ri) = (c as isize, r as isize);
            open[l] |= gc == 0
                || gr == 0
                || gc + 1 == gw
                || gr + 1 == gh
                || neighbour_unknown(ci - 1, ri)
                || neighbour_unknown(ci + 1, ri)
                || neighbour_unknown(ci, ri - 1)
                || neighbour_unknown(ci, ri + 1);
        }
    }
    TileLabels { labels, size, open }
}

/// One tile's edge labels and the global ids of the labels on them.
struct TileEdges {
    top: Vec<u32>,
    bottom: Vec<u32>,
    left: Vec<u32>,
    right: Vec<u32>,
    /// The local labels found on the edges, ascending; the i-th has the
    /// global id `first + i`.
    on_edge: Vec<u32>,
    first: u32,
}

impl TileEdges {
    fn global(&self, label: u32) -> Option<u32> {
        self.on_edge
            .binary_search(&label)
            .ok()
            .map(|i| self.first + i as u32)
    }
}

/// The regions crossing tile borders, gathered tile by tile, then joined.
pub struct RegionJoin {
    layout: TileLayout,
    min_cells: f64,
    tiles: Vec<Option<TileEdges>>,
    /// Per global id: union–find parent, cells and openness (summed into
    /// the roots by [`RegionJoin::join`]).
    parent: Vec<u32>,
    size: Vec<u64>,
    open: Vec<bool>,
    /// Per global id, after the join: the region is filled.
    fill: Vec<bool>,
}

/// Why the labels of the tiles could not be joined.
#[derive(Debug, thiserror::Error)]
pub enum JoinError {
    #[error("tile {0} was not labelled before the join")]
    Missing(usize),
    #[error("more regions cross tile borders than 2^32")]
    TooMany,
}

impl RegionJoin {
    /// Regions of fewer than `min_cells` cells are filled.
    pub fn new(layout: TileLayout, min_cells: f64) -> RegionJoin {
        RegionJoin {
            layout,
            min_cells,
            tiles: (0..layout.count()).map(|_| None).collect(),
            parent: Vec::new(),
            size: Vec::new(),
            open: Vec::new(),
            fill: Vec::new(),
        }
    }

    /// Keeps tile `k`'s edges and the facts of their labels.
    pub fn add(&mut self, k: usize, labels: &TileLabels) -> Result<(), JoinError> {
        let t = self.layout.tile(k);
        let (w, h) = (t.width, t.height);
        let l = &labels.labels;
        let top = l[..w].to_vec();
        let bottom = l[(h - 1) * w..].to_vec();
        let left: Vec<u32> = (0..h).map(|r| l[r * w]).collect();
        let right: Vec<u32> = (0..h).map(|r| l[r * w + w - 1]).collect();
        let mut on_edge: Vec<u32> = top
            .iter()
            .chain(&bottom)
            .chain(&left)
            .chain(&right)
            .copied()
            .filter(|&x| x != 0)
            .collect();
        on_edge.sort_unstable();
        on_edge.dedup();
        let first = u32::try_from(self.parent.len()).map_err(|_| JoinError::TooMany)?;
        u32::try_from(self.parent.len() + on_edge.len()).map_err(|_| JoinError::TooMany)?;
        for (i, &label) in on_edge.iter().enumerate() {
            self.parent.push(first + i as u32);
            self.size.push(labels.size[label as usize]);
            self.open.push(labels.open[label as usize]);
        }
        self.tiles[k] = Some(TileEdges {
            top,
            bottom,
            left,
            right,
            on_edge,
            first,
        });
        Ok(())
    }

    fn find(&mut self, mut i: u32) -> u32 {
        while self.parent[i as usize] != i {
            let up = self.parent[self.parent[i as usize] as usize];
            self.parent[i as usize] = up;
            i = up;
        }
        i
    }

    fn union(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a != b {
            let (lo, hi) = (a.min(b), a.max(b));
            self.parent[hi as usize] = lo;
        }
    }

    /// Joins the regions across every tile border and decides which are
    /// filled; the edges are dropped.
    pub fn join(&mut self) -> Result<(), JoinError> {
        let [nx, ny] = self.layout.tiles();
        if let Some(k) = self.tiles.iter().position(Option::is_none) {
            return Err(JoinError::Missing(k));
        }
        let mut pairs = Vec::new();
        for ty in 0..ny {
            for tx in 0..nx {
                let k = ty * nx + tx;
                let here = self.tiles[k].as_ref().expect("checked above");
                // Traversable cells side by side across the border: one
                // region (4-connected, as the whole-grid fill).
                if tx + 1 < nx {
                    let east = self.tiles[k + 1].as_ref().expect("checked above");
                    for (&a, &b) in here.right.iter().zip(&east.left) {
                        if a != 0 && b != 0 {
                            pairs.push((here.global(a), east.global(b)));
                        }
                    }
                }
                if ty + 1 < ny {
                    let south = self.tiles[k + nx].as_ref().expect("checked above");
                    for (&a, &b) in here.bottom.iter().zip(&south.top) {
                        if a != 0 && b != 0 {
                            pairs.push((here.global(a), south.global(b)));
                        }
                    }
                }
            }
            // Pairs of a row of tiles at a time, to keep the list short.
            for (a, b) in pairs.drain(..) {
                if let (Some(a), Some(b)) = (a, b) {
                    self.union(a, b);
                }
            }
        }
        let n = self.parent.len();
        for i in 0..n as u32 {
            let root = self.find(i);
            if root != i {
                self.size[root as usize] += std::mem::take(&mut self.size[i as usize]);
                let o = self.open[i as usize];
                self.open[root as usize] |= o;
            }
        }
        self.fill = (0..n as u32)
            .map(|i| {
                let root = self.find(i) as usize;
                !self.open[root] && (self.size[root] as f64) < self.min_cells
            })
            .collect();
        for t in self.tiles.iter_mut().flatten() {
            t.top = Vec::new();
            t.bottom = Vec::new();
            t.left = Vec::new();
            t.right = Vec::new();
        }
        self.parent = Vec::new();
        self.size = Vec::new();
        self.open = Vec::new();
        Ok(())
    }

    /// Fills tile `k`'s enclosed regions in `core` (its classes, labelled
    /// as `labels` by [`label_tile`] after [`RegionJoin::join`]); returns
    /// the cells filled.
    pub fn apply(&self, k: usize, labels: &TileLabels, core: &mut [u8]) -> usize {
        let Some(edges) = self.tiles.get(k).and_then(Option::as_ref) else {
            return 0;
        };
        let decide: Vec<bool> = (0..labels.size.len())
            .map(|l| {
                if l == 0 {
                    return false;
                }
                match edges.global(l as u32) {
                    Some(g) => self.fill[g as usize],
                    None => !labels.open[l] && (labels.size[l] as f64) < self.min_cells,
                }
            })
            .collect();
        let mut filled = 0;
        for (c, &l) in core.iter_mut().zip(&labels.labels) {
            if decide[l as usize] {
                *c = Class::Enclosed as u8;
                filled += 1;
            }
        }
        filled
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::regions::fill_enclosed;
    use crate::test_rng::Lcg;

    /// The fill of `class` tile by tile (tiles of `tile` cells).
    fn tiled_fill(class: &[u8], w: usize, h: usize, tile: usize, min_cells: f64) -> Vec<u8> {
        let layout = TileLayout::new(w, h, tile);
        let mut join = RegionJoin::new(layout, min_cells);
        let window_of = |t: &TileWindow| {
            let p = t.padded([1, 1], w, h);
            let mut win = Vec::new();
            for r in p.row0..p.row0 + p.height {
                win.extend_from_slice(&class[r * w + p.col0..r * w + p.col0 + p.width]);
            }
            (win, p)
        };
        for k in 0..layout.count() {
            let t = layout.tile(k);
            let (win, p) = window_of(&t);
            join.add(k, &label_tile(&win, p.width, [p.dx, p.dy], &t, [w, h]))
                .unwrap();
        }
        join.join().unwrap();
        let mut out = class.to_vec();
        for k in 0..layout.count() {
            let t = layout.tile(k);
            let (win, p) = window_of(&t);
            let labels = label_tile(&win, p.width, [p.dx, p.dy], &t, [w, h]);
            let mut core = Vec::new();
            crate::costmap::halo::crop(&win, p.width, [p.dx, p.dy], [t.width, t.height], &mut core);
            join.apply(k, &labels, &mut core);
            for r in 0..t.height {
                out[(t.row0 + r) * w + t.col0..(t.row0 + r) * w + t.col0 + t.width]
                    .copy_from_slice(&core[r * t.width..(r + 1) * t.width]);
            }
        }
        out
    }

    #[test]
    fn a_ring_across_four_tiles_is_filled_like_the_whole_grid_fill() {
        // A 6 × 6 pocket inside a wall, centred on the corner of 4 tiles,
        // and a larger one beside it; unknown cells open a third.
        let (w, h) = (30, 20);
        let (trav, step, unknown) = (
            Class::Traversable as u8,
            Class::Step as u8,
            Class::Unknown as u8,
        );
        let mut class = vec![trav; w * h];
        let wall = |class: &mut Vec<u8>, c0: usize, r0: usize, c1: usize, r1: usize| {
            for r in r0..=r1 {
                for c in c0..=c1 {
                    if r == r0 || r == r1 || c == c0 || c == c1 {
                        class[r * w + c] = step;
                    }
                }
            }
        };
        wall(&mut class, 6, 6, 13, 13);
        wall(&mut class, 15, 2, 28, 18);
        wall(&mut class, 1, 15, 5, 18);
        class[16 * w + 3] = unknown;
        for min in [10.0, 37.0, 36.0, 200.0] {
            let mut want = class.clone();
            fill_enclosed(&mut want, w, h, min);
            for tile in [1, 2, 3, 5, 10, 16, 30] {
                assert_eq!(
                    tiled_fill(&class, w, h, tile, min),
                    want,
                    "tile {tile} min {min}"
                );
            }
        }
    }

    #[test]
    fn random_grids_and_tile_sizes_fill_like_the_whole_grid() {
        let mut s = Lcg(0x5eed_0022);
        for case in 0..60 {
            let w = 1 + (s.next() * 40.0) as usize;
            let h = 1 + (s.next() * 40.0) as usize;
            let density = [0.3, 0.45, 0.55, 0.7][case % 4];
            let class: Vec<u8> = (0..w * h)
                .map(|_| {
                    let x = s.next();
                    if x < density {
                        Class::Traversable as u8
                    } else if x < 0.97 {
                        Class::Slope as u8
                    } else {
                        Class::Unknown as u8
                    }
                })
                .collect();
            let min = 1.0 + s.next() * 30.0;
            let tile = 1 + (s.next() * 12.0) as usize;
            let mut want = class.clone();
            fill_enclosed(&mut want, w, h, min);
            assert_eq!(
                tiled_fill(&class, w, h, tile, min),
                want,
                "case {case}: {w}×{h} tile {tile} min {min}"
            );
        }
    }
}
