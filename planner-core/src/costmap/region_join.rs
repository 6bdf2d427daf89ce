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
use super::tile_bytes::{ByteReader, ByteWriter, PieceError};

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

/// One tile's edge facts for the join: the labels along its four edges
/// and the cells and openness of each label found on them (what a tile
/// tells the join; never a label per cell).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileEdges {
    width: usize,
    height: usize,
    top: Vec<u32>,
    bottom: Vec<u32>,
    left: Vec<u32>,
    right: Vec<u32>,
    /// The labels found on the edges, ascending, and per label its cells
    /// in the tile and whether it is open there.
    on_edge: Vec<u32>,
    size: Vec<u64>,
    open: Vec<bool>,
}

/// The labels on the four edges of a `w`×`h` core, ascending, without 0.
fn edge_labels(top: &[u32], bottom: &[u32], left: &[u32], right: &[u32]) -> Vec<u32> {
    let mut on_edge: Vec<u32> = top
        .iter()
        .chain(bottom)
        .chain(left)
        .chain(right)
        .copied()
        .filter(|&x| x != 0)
        .collect();
    on_edge.sort_unstable();
    on_edge.dedup();
    on_edge
}

/// A digest of the labels along the four edges (FNV-1a, 64 bits): the
/// fill checks with it that a tile is labelled as when its edges were
/// joined.
fn edges_digest(top: &[u32], bottom: &[u32], left: &[u32], right: &[u32]) -> u64 {
    let mut d: u64 = 0xcbf2_9ce4_8422_2325;
    for &x in top.iter().chain(bottom).chain(left).chain(right) {
        for b in x.to_le_bytes() {
            d = (d ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    d
}

/// The labels on the edges of a `w`×`h` tile's core, ascending, and the
/// digest of its edges.
fn labels_on_edges(labels: &[u32], w: usize, h: usize) -> (Vec<u32>, u64) {
    let top = &labels[..w];
    let bottom = &labels[(h - 1) * w..];
    let left: Vec<u32> = (0..h).map(|r| labels[r * w]).collect();
    let right: Vec<u32> = (0..h).map(|r| labels[r * w + w - 1]).collect();
    (
        edge_labels(top, bottom, &left, &right),
        edges_digest(top, bottom, &left, &right),
    )
}

impl TileEdges {
    /// The edges of `tile`'s core, labelled as `labels`.
    pub fn of(tile: &TileWindow, labels: &TileLabels) -> TileEdges {
        let (w, h) = (tile.width, tile.height);
        let l = &labels.labels;
        let top = l[..w].to_vec();
        let bottom = l[(h - 1) * w..].to_vec();
        let left: Vec<u32> = (0..h).map(|r| l[r * w]).collect();
        let right: Vec<u32> = (0..h).map(|r| l[r * w + w - 1]).collect();
        let on_edge = edge_labels(&top, &bottom, &left, &right);
        let size = on_edge.iter().map(|&x| labels.size[x as usize]).collect();
        let open = on_edge.iter().map(|&x| labels.open[x as usize]).collect();
        TileEdges {
            width: w,
            height: h,
            top,
            bottom,
            left,
            right,
            on_edge,
            size,
            open,
        }
    }

    /// The core's [width, height].
    pub fn size(&self) -> [usize; 2] {
        [self.width, self.height]
    }

    /// The index of a local label among the labels on the edges.
    fn index(&self, label: u32) -> Option<usize> {
        self.on_edge.binary_search(&label).ok()
    }

    /// Kind byte of the byte form.
    const KIND: u8 = b'E';
    const WHAT: &'static str = "tile edges";

    /// The byte form: the core's size, the four edges' labels, then each
    /// edge label's cells and openness.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = ByteWriter::new(Self::KIND);
        b.len32(self.width);
        b.len32(self.height);
        for edge in [&self.top, &self.bottom, &self.left, &self.right] {
            b.u32s(edge);
        }
        b.len32(self.on_edge.len());
        for (&size, &open) in self.size.iter().zip(&self.open) {
            b.u64(size);
            b.u8(u8::from(open));
        }
        b.finish()
    }

    /// Reads [`TileEdges::to_bytes`], checking that the edges agree at
    /// the corners and that the facts are those of the edges' labels.
    pub fn from_bytes(bytes: &[u8]) -> Result<TileEdges, PieceError> {
        let mut r = ByteReader::new(bytes, Self::KIND, Self::WHAT)?;
        let width = r.u32()? as usize;
        let height = r.u32()? as usize;
        if width == 0 || height == 0 {
            return Err(r.fault(format!("an empty {width}×{height} core")));
        }
        let cells = (width as u64) * (height as u64);
        r.expect_items(2 * (width + height), 4)?;
        let top = r.u32s(width)?;
        let bottom = r.u32s(width)?;
        let left = r.u32s(height)?;
        let right = r.u32s(height)?;
        let corners = [
            (top[0], left[0]),
            (top[width - 1], right[0]),
            (bottom[0], left[height - 1]),
            (bottom[width - 1], right[height - 1]),
        ];
        if corners.iter().any(|(a, b)| a != b)
            || (height == 1 && top != bottom)
            || (width == 1 && left != right)
        {
            return Err(r.fault("the edges disagree where they meet".to_string()));
        }
        if [&top, &bottom, &left, &right]
            .iter()
            .any(|e| e.iter().any(|&x| u64::from(x) > cells))
        {
            return Err(r.fault(format!("a label beyond the {cells} cells of the core")));
        }
        let on_edge = edge_labels(&top, &bottom, &left, &right);
        let n = r.u32()? as usize;
        if n != on_edge.len() {
            return Err(r.fault(format!(
                "facts of {n} labels, but {} labels are on the edges",
                on_edge.len()
            )));
        }
        r.expect_items(n, 9)?;
        let mut size = Vec::with_capacity(n);
        let mut open = Vec::with_capacity(n);
        let mut total = 0u64;
        for _ in 0..n {
            let s = r.u64()?;
            total = total.saturating_add(s);
            if s == 0 || total > cells {
                return Err(r.fault(format!(
                    "regions of more cells than the {cells} of the core"
                )));
            }
            size.push(s);
            open.push(r.bool()?);
        }
        r.end()?;
        Ok(TileEdges {
            width,
            height,
            top,
            bottom,
            left,
            right,
            on_edge,
            size,
            open,
        })
    }
}

/// Which of one tile's regions on its edges are filled, as the join
/// decided; the regions inside the tile are decided from the tile alone.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileFill {
    /// How many labels the tile had on its edges and the digest of its
    /// edges' labels (checked when applied: the labels must be those the
    /// join saw).
    edge_labels: u32,
    digest: u64,
    /// The local labels on the edges that are filled, ascending.
    filled: Vec<u32>,
}

impl TileFill {
    const KIND: u8 = b'F';
    const WHAT: &'static str = "tile fill";

    /// Fills the tile's enclosed regions in `core` (its classes, labelled
    /// as `labels` by [`label_tile`] from the same classes the join's
    /// edges came from): the edge regions the join chose, and the regions
    /// inside the tile that are closed and smaller than `min_cells`.
    /// Returns the cells filled; an error when the labels are not those
    /// the join saw.
    pub fn apply(
        &self,
        tile: &TileWindow,
        labels: &TileLabels,
        min_cells: f64,
        core: &mut [u8],
    ) -> Result<usize, JoinError> {
        if labels.labels.len() != tile.width * tile.height {
            return Err(JoinError::Labels {
                tx: tile.tx,
                ty: tile.ty,
            });
        }
        let (on_edge, digest) = labels_on_edges(&labels.labels, tile.width, tile.height);
        if on_edge.len() != self.edge_labels as usize
            || digest != self.digest
            || self
                .filled
                .iter()
                .any(|l| on_edge.binary_search(l).is_err())
        {
            return Err(JoinError::Labels {
                tx: tile.tx,
                ty: tile.ty,
            });
        }
        let decide: Vec<bool> = (0..labels.size.len())
            .map(|l| {
                let l32 = l as u32;
                if l == 0 {
                    false
                } else if on_edge.binary_search(&l32).is_ok() {
                    self.filled.binary_search(&l32).is_ok()
                } else {
                    !labels.open[l] && (labels.size[l] as f64) < min_cells
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
        Ok(filled)
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = ByteWriter::new(Self::KIND);
        b.u32(self.edge_labels);
        b.u64(self.digest);
        b.len32(self.filled.len());
        b.u32s(&self.filled);
        b.finish()
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<TileFill, PieceError> {
        let mut r = ByteReader::new(bytes, Self::KIND, Self::WHAT)?;
        let edge_labels = r.u32()?;
        let digest = r.u64()?;
        let n = r.u32()? as usize;
        if n > edge_labels as usize {
            return Err(r.fault(format!("{n} filled regions of {edge_labels} on the edges")));
        }
        let filled = r.u32s(n)?;
        if filled.windows(2).any(|p| p[0] >= p[1]) || filled.first() == Some(&0) {
            return Err(r.fault("the filled labels are not ascending labels".to_string()));
        }
        r.end()?;
        Ok(TileFill {
            edge_labels,
            digest,
            filled,
        })
    }
}

/// The join's decision for every tile, in tile order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RegionFill {
    tiles: Vec<TileFill>,
}

impl RegionFill {
    const KIND: u8 = b'R';
    const WHAT: &'static str = "region fill";

    /// Tile `k`'s part.
    pub fn tile(&self, k: usize) -> Option<&TileFill> {
        self.tiles.get(k)
    }

    /// The parts, in tile order (e.g. to store one per tile).
    pub fn into_tiles(self) -> Vec<TileFill> {
        self.tiles
    }

    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// The byte form: the tile count, then each tile's part's bytes after
    /// their length.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = ByteWriter::new(Self::KIND);
        b.len32(self.tiles.len());
        for t in &self.tiles {
            let bytes = t.to_bytes();
            b.len32(bytes.len());
            b.bytes(&bytes);
        }
        b.finish()
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<RegionFill, PieceError> {
        let mut r = ByteReader::new(bytes, Self::KIND, Self::WHAT)?;
        let n = r.u32()? as usize;
        // Each part takes at least its length and 18 bytes.
        r.expect_items(n, 22)?;
        let mut tiles = Vec::with_capacity(n);
        for _ in 0..n {
            let len = r.u32()? as usize;
            tiles.push(TileFill::from_bytes(r.take(len)?)?);
        }
        r.end()?;
        Ok(RegionFill { tiles })
    }
}

/// The regions crossing tile borders, gathered tile by tile (in any
/// order), then joined.
pub struct RegionJoin {
    layout: TileLayout,
    min_cells: f64,
    tiles: Vec<Option<TileEdges>>,
    /// Per tile: the global id of its first edge label.
    first: Vec<u32>,
    /// Per global id: union–find parent, cells and openness (summed into
    /// the roots by [`RegionJoin::join`]).
    parent: Vec<u32>,
    size: Vec<u64>,
    open: Vec<bool>,
}

/// Why the labels of the tiles could not be joined.
#[derive(Debug, thiserror::Error)]
pub enum JoinError {
    #[error("tile {0} was not labelled before the join")]
    Missing(usize),
    #[error("tile {0} was given to the join twice")]
    Twice(usize),
    #[error("tile {k} is not one of the {count} tiles")]
    NoSuchTile { k: usize, count: usize },
    #[error("the edges given for tile {k} are of a {got:?} core, the tile is {want:?}")]
    WrongSize {
        k: usize,
        got: [usize; 2],
        want: [usize; 2],
    },
    #[error("more regions cross tile borders than 2^32")]
    TooMany,
    #[error(
        "tile ({tx}, {ty}) is not labelled as when its edges were joined (its classes before \
         the fill changed, or the fill is another tile's)"
    )]
    Labels { tx: usize, ty: usize },
}

impl RegionJoin {
    /// Regions of fewer than `min_cells` cells are filled.
    pub fn new(layout: TileLayout, min_cells: f64) -> RegionJoin {
        RegionJoin {
            layout,
            min_cells,
            tiles: (0..layout.count()).map(|_| None).collect(),
            first: vec![0; layout.count()],
            parent: Vec::new(),
            size: Vec::new(),
            open: Vec::new(),
        }
    }

    /// Keeps tile `k`'s edges and the facts of their labels.
    pub fn add(&mut self, k: usize, edges: TileEdges) -> Result<(), JoinError> {
        let count = self.tiles.len();
        let slot = self
            .tiles
            .get(k)
            .ok_or(JoinError::NoSuchTile { k, count })?;
        if slot.is_some() {
            return Err(JoinError::Twice(k));
        }
        let t = self.layout.tile(k);
        if edges.size() != [t.width, t.height] {
            return Err(JoinError::WrongSize {
                k,
                got: edges.size(),
                want: [t.width, t.height],
            });
        }
        let first = u32::try_from(self.parent.len()).map_err(|_| JoinError::TooMany)?;
        u32::try_from(self.parent.len() + edges.on_edge.len()).map_err(|_| JoinError::TooMany)?;
        for i in 0..edges.on_edge.len() {
            self.parent.push(first + i as u32);
        }
        self.size.extend_from_slice(&edges.size);
        self.open.extend_from_slice(&edges.open);
        self.first[k] = first;
        self.tiles[k] = Some(edges);
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

    /// The global id of tile `k`'s edge label `label`.
    fn global(&self, k: usize, label: u32) -> Option<u32> {
        let edges = self.tiles[k].as_ref()?;
        edges.index(label).map(|i| self.first[k] + i as u32)
    }

    /// Joins the regions across every tile border and decides which are
    /// filled: the same decisions whatever order the tiles came in.
    pub fn join(mut self) -> Result<RegionFill, JoinError> {
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
                            pairs.push((self.global(k, a), self.global(k + 1, b)));
                        }
                    }
                }
                if ty + 1 < ny {
                    let south = self.tiles[k + nx].as_ref().expect("checked above");
                    for (&a, &b) in here.bottom.iter().zip(&south.top) {
                        if a != 0 && b != 0 {
                            pairs.push((self.global(k, a), self.global(k + nx, b)));
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
        let mut tiles = Vec::with_capacity(self.tiles.len());
        for k in 0..self.tiles.len() {
            let edges = self.tiles[k].take().expect("checked above");
            let mut filled = Vec::new();
            for (i, &label) in edges.on_edge.iter().enumerate() {
                let root = self.find(self.first[k] + i as u32) as usize;
                if !self.open[root] && (self.size[root] as f64) < self.min_cells {
                    filled.push(label);
                }
            }
            tiles.push(TileFill {
                edge_labels: edges.on_edge.len() as u32,
                digest: edges_digest(&edges.top, &edges.bottom, &edges.left, &edges.right),
                filled,
            });
        }
        Ok(RegionFill { tiles })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::costmap::regions::fill_enclosed;
    use crate::test_rng::Lcg;

    /// The fill of `class` tile by tile (tiles of `tile` cells), the
    /// tiles' edges joined in an order drawn from `seed`.
    fn tiled_fill(
        class: &[u8],
        w: usize,
        h: usize,
        tile: usize,
        min_cells: f64,
        seed: u64,
    ) -> Vec<u8> {
        let layout = TileLayout::new(w, h, tile);
        let mut order: Vec<usize> = (0..layout.count()).collect();
        let mut s = Lcg(seed);
        for i in (1..order.len()).rev() {
            order.swap(i, ((s.next() * (i + 1) as f64) as usize).min(i));
        }
        let mut join = RegionJoin::new(layout, min_cells);
        let window_of = |t: &TileWindow| {
            let p = t.padded([1, 1], w, h);
            let mut win = Vec::new();
            for r in p.row0..p.row0 + p.height {
                win.extend_from_slice(&class[r * w + p.col0..r * w + p.col0 + p.width]);
            }
            (win, p)
        };
        for &k in &order {
            let t = layout.tile(k);
            let (win, p) = window_of(&t);
            let labels = label_tile(&win, p.width, [p.dx, p.dy], &t, [w, h]);
            let edges = TileEdges::of(&t, &labels);
            // Through the byte form, as between processes.
            let edges = TileEdges::from_bytes(&edges.to_bytes()).unwrap();
            join.add(k, edges).unwrap();
        }
        let fill = join.join().unwrap();
        let fill = RegionFill::from_bytes(&fill.to_bytes()).unwrap();
        let mut out = class.to_vec();
        for k in 0..layout.count() {
            let t = layout.tile(k);
            let (win, p) = window_of(&t);
            let labels = label_tile(&win, p.width, [p.dx, p.dy], &t, [w, h]);
            let mut core = Vec::new();
            crate::costmap::halo::crop(&win, p.width, [p.dx, p.dy], [t.width, t.height], &mut core);
            let part = TileFill::from_bytes(&fill.tile(k).unwrap().to_bytes()).unwrap();
            part.apply(&t, &labels, min_cells, &mut core).unwrap();
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
                    tiled_fill(&class, w, h, tile, min, tile as u64),
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
                tiled_fill(&class, w, h, tile, min, tile as u64),
                want,
                "case {case}: {w}×{h} tile {tile} min {min}"
            );
        }
    }

    #[test]
    fn damaged_edges_and_fills_are_refused() {
        let (w, h) = (12, 9);
        let mut s = Lcg(0xed9e);
        let class: Vec<u8> = (0..w * h)
            .map(|_| {
                if s.next() < 0.6 {
                    Class::Traversable as u8
                } else {
                    Class::Step as u8
                }
            })
            .collect();
        let layout = TileLayout::new(w, h, 5);
        let mut join = RegionJoin::new(layout, 4.0);
        let mut all_edges = Vec::new();
        for k in 0..layout.count() {
            let t = layout.tile(k);
            let p = t.padded([1, 1], w, h);
            let mut win = Vec::new();
            for r in p.row0..p.row0 + p.height {
                win.extend_from_slice(&class[r * w + p.col0..r * w + p.col0 + p.width]);
            }
            let labels = label_tile(&win, p.width, [p.dx, p.dy], &t, [w, h]);
            let edges = TileEdges::of(&t, &labels);
            all_edges.push(edges.to_bytes());
            join.add(k, edges).unwrap();
        }
        let fill = join.join().unwrap();
        use crate::costmap::tile_bytes::testing::assert_refuses_damage;
        assert_refuses_damage(&all_edges[4], TileEdges::from_bytes, 1);
        let part = fill.tile(4).unwrap().to_bytes();
        assert_refuses_damage(&part, TileFill::from_bytes, 2);
        assert_refuses_damage(&fill.to_bytes(), RegionFill::from_bytes, 3);
        // A core of 2^32 × 2^32 cells announced in a few bytes.
        let mut huge = all_edges[0][..2].to_vec();
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        huge.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(TileEdges::from_bytes(&huge).is_err());
        // Edges that disagree at a corner.
        let mut e = TileEdges::from_bytes(&all_edges[0]).unwrap();
        e.top[0] = e.top[0].wrapping_add(1);
        assert!(TileEdges::from_bytes(&e.to_bytes()).is_err());
    }
}
