//! Boustrophedon cells by a plane sweep in the slice frame, where slice lines
//! are vertical (`x = const`) and the sweep runs towards `+x`.
//!
//! Conceptually this is the trapezoidal decomposition at every distinct vertex
//! x, followed by merging the trapezoids of neighbouring slabs whenever the
//! left one has exactly one right neighbour and that one has exactly one left
//! neighbour (neighbours = the shared vertical side overlaps with positive
//! length). The merged chains are the boustrophedon cells: a cell ends only
//! where the slice's connectivity changes (a Morse critical point: a run of
//! the slice splits, merges, appears or vanishes), never at a mere bend.
//!
//! Rather than building every trapezoid, the sweep keeps the active edges
//! sorted bottom to top, each with the winding number just above it, and one
//! open cell per maximal free run of the slice (winding > 0). At an event x
//! only the runs around the vertices at x (a "window") are rebuilt and
//! matched; all other runs continue and their cells get no vertex. The cost is
//! O(n log n) for sorting and searching, plus the windows (small unless many
//! unrelated vertices share a slice line) and one memmove of the active list
//! per event.
//!
//! The winding rule (rather than even–odd) makes overlapping or nested
//! polygons of a multipolygon count as their union. Edges that cross are
//! detected (Shamos–Hoey: every pair that becomes adjacent is checked) and
//! reported as a failure instead of producing wrong cells.
//!
//! Tolerance: `eps` (a length, chosen by the caller relative to the size of
//! the geometry) is used for "vertex on edge" (vertically), "zero-height run"
//! and "overlap of positive length". It must dwarf the rounding error of the
//! coordinates. Events are exact x values: the caller is expected to have
//! merged nearly coincident vertices and made touches explicit (see
//! [`super::touch`]), so that vertical distances are never ill-conditioned.

use std::ops::Range;

use geo_types::Coord;

const NO_CELL: u32 = u32::MAX;
const NO_EDGE: u32 = u32::MAX;

/// Why the sweep gave up; both mean the input is not a valid polygon set.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SweepFailure {
    /// Two boundary edges cross.
    Crossing,
    /// The rings do not bound a region under the winding rule as seen by the
    /// sweep (only possible with invalid input or rounding beyond `eps`).
    Inconsistent,
}

/// One boustrophedon cell in the slice frame: the boundary below and above,
/// both from left to right, starting and ending on the cell's vertical sides.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Cell {
    pub(crate) lower: Vec<Coord<f64>>,
    pub(crate) upper: Vec<Coord<f64>>,
}

impl Cell {
    /// The boundary as an open CCW ring (lower chain, then the upper one
    /// backwards); it may still contain duplicate or collinear vertices.
    pub(crate) fn ring(&self) -> Vec<Coord<f64>> {
        let mut ring = Vec::with_capacity(self.lower.len() + self.upper.len());
        ring.extend_from_slice(&self.lower);
        ring.extend(self.upper.iter().rev());
        ring
    }
}

/// A non-vertical boundary edge, stored left to right.
#[derive(Debug, Clone, Copy)]
struct Edge {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    slope: f64,
    /// Change of the winding number when crossing the edge upwards: +1 if the
    /// ring runs left to right here (interior above), −1 otherwise.
    wind: i32,
}

impl Edge {
    fn y_at(&self, x: f64) -> f64 {
        // Exact at the endpoints, which the sweep relies on for vertices.
        if x <= self.x0 {
            self.y0
        } else if x >= self.x1 {
            self.y1
        } else {
            self.y0 + (self.y1 - self.y0) * ((x - self.x0) / (self.x1 - self.x0))
        }
    }
}

/// An active edge with the winding number just above it and, if it is the
/// lower boundary of a free run, that run's open cell.
#[derive(Debug, Clone, Copy)]
struct Slot {
    edge: u32,
    wind: i32,
    cell: u32,
}

/// Vertices at one event x whose y values lie within `eps` of each other.
#[derive(Debug, Clone)]
struct Cluster {
    ylo: f64,
    yhi: f64,
    /// Sum of the winding changes of the edges ending and starting here.
    net: i32,
    /// Its change points.
    points: Range<usize>,
    /// Old active slots passing within `eps` of it.
    slots: Range<usize>,
}

/// A stretch of the active list rebuilt at an event: from a non-free gap to a
/// non-free gap, containing some clusters, with zero net winding change.
#[derive(Debug, Clone)]
struct Window {
    slots: Range<usize>,
    clusters: Range<usize>,
    net: i32,
}

/// A maximal free run of the slice within a window.
#[derive(Debug, Clone, Copy)]
struct Run {
    /// Index (within the window) of the slot below and above the run.
    lower: usize,
    upper: usize,
    ylo: f64,
    yhi: f64,
    cell: u32,
}

/// Decomposes the region bounded by `rings` into boustrophedon cells for
/// vertical slice lines. Rings are open or closed vertex lists with the
/// interior on their left (exteriors CCW, holes CW); where rings overlap, the
/// region is the set of points with a positive winding number.
#[cfg(test)]
pub(crate) fn sweep(rings: &[Vec<Coord<f64>>], eps: f64) -> Result<Vec<Cell>, SweepFailure> {
    sweep_linked(rings, eps).map(|s| s.cells)
}

/// Two cells that meet on a slice line, the first ending there and the
/// second starting there, sharing a segment of positive length.
pub(crate) type Link = (u32, u32);

/// The cells of a sweep and where they meet.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct Swept {
    /// In the order they open, i.e. by where they start along the sweep.
    pub(crate) cells: Vec<Cell>,
    /// Every pair of cells meeting across a slice line, by the left one's id.
    pub(crate) links: Vec<Link>,
}

/// [`sweep`], also telling which cells meet across each slice line.
pub(crate) fn sweep_linked(rings: &[Vec<Coord<f64>>], eps: f64) -> Result<Swept, SweepFailure> {
    let edges = build_edges(rings);
    let mut by_start: Vec<u32> = (0..edges.len() as u32).collect();
    by_start.sort_by(|&a, &b| edges[a as usize].x0.total_cmp(&edges[b as usize].x0));
    let mut by_end = by_start.clone();
    by_end.sort_by(|&a, &b| edges[a as usize].x1.total_cmp(&edges[b as usize].x1));

    let mut state = Sweep {
        edges: &edges,
        eps,
        slots: Vec::new(),
        cells: Vec::new(),
        links: Vec::new(),
        scratch: Scratch::default(),
    };
    let (mut i, mut j) = (0, 0);
    while i < by_start.len() || j < by_end.len() {
        let next_start = by_start
            .get(i)
            .map_or(f64::INFINITY, |&e| edges[e as usize].x0);
        let next_end = by_end
            .get(j)
            .map_or(f64::INFINITY, |&e| edges[e as usize].x1);
        let x = next_start.min(next_end);
        let (i0, j0) = (i, j);
        while i < by_start.len() && edges[by_start[i] as usize].x0 == x {
            i += 1;
        }
        while j < by_end.len() && edges[by_end[j] as usize].x1 == x {
            j += 1;
        }
        state.event(x, &by_start[i0..i], &by_end[j0..j])?;
    }
    if !state.slots.is_empty() {
        return Err(SweepFailure::Inconsistent);
    }
    Ok(Swept {
        cells: state.cells,
        links: state.links,
    })
}

/// The non-vertical edges of all rings. Edges parallel to the slice bound no
/// slab: their ends are vertices on the same slice line, and the runs on
/// either side of them are matched across it.
fn build_edges(rings: &[Vec<Coord<f64>>]) -> Vec<Edge> {
    let mut edges = Vec::new();
    for ring in rings {
        let mut ring = ring.as_slice();
        if ring.len() > 1 && ring[0] == ring[ring.len() - 1] {
            ring = &ring[..ring.len() - 1];
        }
        if ring.len() < 3 {
            continue;
        }
        for (k, &p) in ring.iter().enumerate() {
            let q = ring[(k + 1) % ring.len()];
            let (x0, y0, x1, y1, wind) = if p.x < q.x {
                (p.x, p.y, q.x, q.y, 1)
            } else if p.x > q.x {
                (q.x, q.y, p.x, p.y, -1)
            } else {
                continue;
            };
            edges.push(Edge {
                x0,
                y0,
                x1,
                y1,
                slope: (y1 - y0) / (x1 - x0),
                wind,
            });
        }
    }
    edges
}

struct Sweep<'a> {
    edges: &'a [Edge],
    eps: f64,
    /// Active edges, bottom to top, valid just right of the last event.
    slots: Vec<Slot>,
    cells: Vec<Cell>,
    links: Vec<Link>,
    scratch: Scratch,
}

/// Work lists of one event, kept from event to event: a sweep has an
/// event per vertex, and allocating them anew took a third of its time.
#[derive(Default)]
struct Scratch {
    points: Vec<(f64, i32, u32)>,
    clusters: Vec<Cluster>,
    grouped: Vec<Window>,
    windows: Vec<Window>,
    /// The new slots of each window.
    rebuilt: Vec<Vec<Slot>>,
    new_ranges: Vec<Range<usize>>,
    window: WindowScratch,
}

/// Work lists of rebuilding one window.
#[derive(Default)]
struct WindowScratch {
    order: Vec<(usize, f64, u32)>,
    old_runs: Vec<Run>,
    new_runs: Vec<Run>,
    live: Vec<bool>,
    right: Links,
    left: Links,
    pairs: Vec<(usize, usize)>,
}

impl Sweep<'_> {
    fn edge(&self, id: u32) -> &Edge {
        &self.edges[id as usize]
    }

    /// Processes all vertices on the slice line `x`: removes the edges
    /// ending there, inserts those starting there and updates the cells.
    fn event(&mut self, x: f64, starting: &[u32], ending: &[u32]) -> Result<(), SweepFailure> {
        // Taken out for the event and put back (a failed sweep ends anyway).
        let mut sc = std::mem::take(&mut self.scratch);
        self.event_with(x, starting, ending, &mut sc)?;
        self.scratch = sc;
        Ok(())
    }

    fn event_with(
        &mut self,
        x: f64,
        starting: &[u32],
        ending: &[u32],
        sc: &mut Scratch,
    ) -> Result<(), SweepFailure> {
        let eps = self.eps;

        // Change points (y, winding change, starting edge or NO_EDGE), sorted
        // along the slice line and grouped into clusters of coincident vertices.
        let points = &mut sc.points;
        points.clear();
        points.extend(
            ending
                .iter()
                .map(|&e| (self.edge(e).y1, -self.edge(e).wind, NO_EDGE)),
        );
        points.extend(
            starting
                .iter()
                .map(|&e| (self.edge(e).y0, self.edge(e).wind, e)),
        );
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let clusters = &mut sc.clusters;
        clusters.clear();
        for (k, &(y, dw, _)) in points.iter().enumerate() {
            match clusters.last_mut() {
                Some(c) if y - c.yhi <= eps => {
                    c.yhi = y;
                    c.net += dw;
                    c.points.end = k + 1;
                }
                _ => clusters.push(Cluster {
                    ylo: y,
                    yhi: y,
                    net: dw,
                    points: k..k + 1,
                    slots: 0..0,
                }),
            }
        }
        for c in clusters.iter_mut() {
            let a = self
                .slots
                .partition_point(|s| self.edges[s.edge as usize].y_at(x) < c.ylo - eps);
            let b = self
                .slots
                .partition_point(|s| self.edges[s.edge as usize].y_at(x) <= c.yhi + eps);
            c.slots = a..b.max(a);
        }

        self.windows(&sc.clusters, &mut sc.grouped, &mut sc.windows)?;
        let windows = &sc.windows;

        // Every ending edge must be inside a window, or it would linger.
        let found: usize = windows
            .iter()
            .map(|w| {
                self.slots[w.slots.clone()]
                    .iter()
                    .filter(|s| self.edge(s.edge).x1 <= x)
                    .count()
            })
            .sum();
        if found != ending.len() {
            return Err(SweepFailure::Inconsistent);
        }

        if sc.rebuilt.len() < windows.len() {
            sc.rebuilt.resize_with(windows.len(), Vec::new);
        }
        for (w, new_slots) in windows.iter().zip(sc.rebuilt.iter_mut()) {
            self.rebuild(x, w, &sc.clusters, &sc.points, new_slots, &mut sc.window)?;
        }
        // Splice from the top so the lower windows' indices stay valid.
        let new_ranges = &mut sc.new_ranges;
        new_ranges.clear();
        let mut shift = 0isize;
        for (w, new_slots) in windows.iter().zip(&sc.rebuilt) {
            let start = w.slots.start.wrapping_add_signed(shift);
            new_ranges.push(start..start + new_slots.len());
            shift += new_slots.len() as isize - w.slots.len() as isize;
        }
        for (w, new_slots) in windows.iter().zip(sc.rebuilt.iter_mut()).rev() {
            self.slots.splice(w.slots.clone(), new_slots.drain(..));
        }
        for r in new_ranges.iter() {
            self.check_order(x, r.start.saturating_sub(1), r.end + 1)?;
        }
        Ok(())
    }

    /// Groups clusters into windows: stretches of the active list bounded by
    /// non-free gaps, so that runs outside them are untouched. Clusters are
    /// joined while the winding change so far is non-zero (e.g. the two ends
    /// of a wall parallel to the slice) or when their slots overlap.
    fn windows(
        &self,
        clusters: &[Cluster],
        grouped: &mut Vec<Window>,
        windows: &mut Vec<Window>,
    ) -> Result<(), SweepFailure> {
        grouped.clear();
        for (ci, c) in clusters.iter().enumerate() {
            match grouped.last_mut() {
                Some(w) if w.net != 0 || c.slots.start <= w.slots.end => {
                    w.slots.end = w.slots.end.max(c.slots.end);
                    w.clusters.end = ci + 1;
                    w.net += c.net;
                }
                _ => grouped.push(Window {
                    slots: c.slots.clone(),
                    clusters: ci..ci + 1,
                    net: c.net,
                }),
            }
        }
        let n = self.slots.len();
        windows.clear();
        for mut w in grouped.drain(..) {
            // Grow to the enclosing free runs: stop where the gap is not free.
            while w.slots.start > 0 && self.slots[w.slots.start - 1].wind > 0 {
                w.slots.start -= 1;
            }
            while w.slots.end > 0 && w.slots.end < n && self.slots[w.slots.end - 1].wind > 0 {
                w.slots.end += 1;
            }
            match windows.last_mut() {
                Some(last) if w.slots.start < last.slots.end => {
                    last.slots.end = last.slots.end.max(w.slots.end);
                    last.clusters.end = w.clusters.end;
                    last.net += w.net;
                }
                _ => windows.push(w),
            }
        }
        if windows.iter().any(|w| w.net != 0) {
            return Err(SweepFailure::Inconsistent);
        }
        Ok(())
    }

    /// Rebuilds one window: the new slot order right of `x`, the windings,
    /// and the cells of its free runs (continued, closed or opened).
    fn rebuild(
        &mut self,
        x: f64,
        w: &Window,
        clusters: &[Cluster],
        points: &[(f64, i32, u32)],
        new_slots: &mut Vec<Slot>,
        sc: &mut WindowScratch,
    ) -> Result<(), SweepFailure> {
        let eps = self.eps;
        let cl = &clusters[w.clusters.clone()];
        let old = &self.slots[w.slots.clone()];
        self.order_right_of(x, cl, old, points, &mut sc.order);

        let base = match w.slots.start {
            0 => 0,
            a => self.slots[a - 1].wind,
        };
        self.wound_slots(&sc.order, old, base, new_slots)?;

        self.runs(old, base, x, &mut sc.old_runs)?;
        self.runs(new_slots, base, x, &mut sc.new_runs)?;
        self.live_runs(&sc.new_runs, new_slots, &mut sc.live);
        neighbours(
            &sc.old_runs,
            &sc.new_runs,
            &sc.live,
            eps,
            (&mut sc.right, &mut sc.left, &mut sc.pairs),
        );
        let (old_runs, new_runs, live) = (&sc.old_runs, &sc.new_runs, &sc.live);
        let (right, left, pairs) = (&sc.right, &sc.left, &sc.pairs);

        for (i, o) in old_runs.iter().enumerate() {
            if o.cell == NO_CELL {
                continue;
            }
            let cell = &mut self.cells[o.cell as usize];
            let (count, j) = right[i];
            if count == 1 && left[j].0 == 1 {
                // Same connectivity on both sides: the cell goes on. Record
                // only where its lower or upper boundary changes edge.
                let n = &new_runs[j];
                if old[o.lower].edge != new_slots[n.lower].edge {
                    push_vertical(&mut cell.lower, x, o.ylo, n.ylo);
                }
                if old[o.upper].edge != new_slots[n.upper].edge {
                    push_vertical(&mut cell.upper, x, o.yhi, n.yhi);
                }
                new_slots[n.lower].cell = o.cell;
            } else {
                cell.lower.push(Coord { x, y: o.ylo });
                cell.upper.push(Coord { x, y: o.yhi });
            }
        }
        for (j, n) in new_runs.iter().enumerate() {
            if live[j] && new_slots[n.lower].cell == NO_CELL {
                new_slots[n.lower].cell = self.cells.len() as u32;
                self.cells.push(Cell {
                    lower: vec![Coord { x, y: n.ylo }],
                    upper: vec![Coord { x, y: n.yhi }],
                });
            }
        }
        for &(i, j) in pairs {
            let (a, b) = (old_runs[i].cell, new_slots[new_runs[j].lower].cell);
            if a != NO_CELL && b != NO_CELL && a != b {
                self.links.push((a, b));
            }
        }
        Ok(())
    }

    /// The edges of a window right of `x` in their new order: kept edges
    /// (still crossing past `x`) and the edges starting at the clusters'
    /// vertices, as (rank, slope, edge id).
    fn order_right_of(
        &self,
        x: f64,
        cl: &[Cluster],
        old: &[Slot],
        points: &[(f64, i32, u32)],
        order: &mut Vec<(usize, f64, u32)>,
    ) {
        let eps = self.eps;
        // Right of x, edges through the same vertex are ordered by slope;
        // edges between clusters keep their (still valid) old order, which the
        // stable sort preserves. Kept edges are listed before new ones so that
        // coincident edges keep a stable order too.
        let rank = |y: f64| -> usize {
            let i = cl.partition_point(|c| c.yhi + eps < y);
            if i < cl.len() && y >= cl[i].ylo - eps {
                2 * i + 1
            } else {
                2 * i
            }
        };
        order.clear();
        for s in old {
            let e = self.edge(s.edge);
            if e.x1 > x {
                let r = rank(e.y_at(x));
                order.push((r, if r % 2 == 1 { e.slope } else { 0.0 }, s.edge));
            }
        }
        for c in cl {
            for &(_, _, id) in &points[c.points.clone()] {
                if id != NO_EDGE {
                    let e = self.edge(id);
                    let r = rank(e.y0);
                    order.push((r, if r % 2 == 1 { e.slope } else { 0.0 }, id));
                }
            }
        }
        order.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    }

    /// The window's new slots in `order`, with their windings counted up
    /// from `base`; the winding above the window must be unchanged.
    fn wound_slots(
        &self,
        order: &[(usize, f64, u32)],
        old: &[Slot],
        base: i32,
        new_slots: &mut Vec<Slot>,
    ) -> Result<(), SweepFailure> {
        new_slots.clear();
        let mut wind = base;
        for &(_, _, edge) in order {
            wind += self.edge(edge).wind;
            new_slots.push(Slot {
                edge,
                wind,
                cell: NO_CELL,
            });
        }
        let old_top = old.last().map_or(base, |s| s.wind);
        if wind != old_top {
            return Err(SweepFailure::Inconsistent);
        }
        Ok(())
    }

    /// Which new runs enclose something: a run whose edges coincide up to
    /// the next vertex encloses nothing.
    fn live_runs(&self, new_runs: &[Run], new_slots: &[Slot], live: &mut Vec<bool>) {
        let eps = self.eps;
        live.clear();
        live.extend(new_runs.iter().map(|r| {
            let (lo, hi) = (
                self.edge(new_slots[r.lower].edge),
                self.edge(new_slots[r.upper].edge),
            );
            let xr = lo.x1.min(hi.x1);
            r.yhi - r.ylo > eps || hi.y_at(xr) - lo.y_at(xr) > eps
        }));
    }

    /// The free runs (winding > 0) of a window's slots, with their extent on
    /// the line `x`. Windows start and end in non-free gaps, so every run
    /// closes inside.
    fn runs(
        &self,
        slots: &[Slot],
        base: i32,
        x: f64,
        runs: &mut Vec<Run>,
    ) -> Result<(), SweepFailure> {
        runs.clear();
        let mut below = base;
        let mut open = None;
        for (k, s) in slots.iter().enumerate() {
            if below <= 0 && s.wind > 0 {
                open = Some(k);
            } else if below > 0 && s.wind <= 0 {
                let lower = open.take().ok_or(SweepFailure::Inconsistent)?;
                runs.push(Run {
                    lower,
                    upper: k,
                    ylo: self.edge(slots[lower].edge).y_at(x),
                    yhi: self.edge(s.edge).y_at(x),
                    cell: slots[lower].cell,
                });
            }
            below = s.wind;
        }
        if below > 0 || open.is_some() {
            return Err(SweepFailure::Inconsistent);
        }
        Ok(())
    }

    /// Checks that neighbouring active edges in `from..to` are in order at `x`
    /// and still are where the first of them ends: two non-crossing edges
    /// that are ordered at both ends of their common span are ordered on all
    /// of it. By Shamos–Hoey, checking every newly adjacent pair finds a
    /// crossing if there is one.
    fn check_order(&self, x: f64, from: usize, to: usize) -> Result<(), SweepFailure> {
        let to = to.min(self.slots.len());
        for k in from..to.saturating_sub(1) {
            let (p, q) = (
                self.edge(self.slots[k].edge),
                self.edge(self.slots[k + 1].edge),
            );
            let xr = p.x1.min(q.x1);
            if p.y_at(x) > q.y_at(x) + self.eps || p.y_at(xr) > q.y_at(xr) + self.eps {
                return Err(SweepFailure::Crossing);
            }
        }
        Ok(())
    }
}

/// Per run: how many runs across x it overlaps, and the last of them.
type Links = Vec<(u32, usize)>;

/// Neighbours across x: runs whose extents on the line overlap by more than
/// eps. For each old run (`right`) and each live new run (`left`), how many
/// runs on the other side it touches and the last of them; and every
/// overlapping pair (old, new). Both lists are sorted and disjoint, so a
/// merge walk finds all pairs.
fn neighbours(
    old_runs: &[Run],
    new_runs: &[Run],
    live: &[bool],
    eps: f64,
    (right, left, pairs): (&mut Links, &mut Links, &mut Vec<(usize, usize)>),
) {
    right.clear();
    right.resize(old_runs.len(), (0, 0));
    left.clear();
    left.resize(new_runs.len(), (0, 0));
    pairs.clear();
    let (mut i, mut j) = (0, 0);
    while i < old_runs.len() && j < new_runs.len() {
        let (o, n) = (&old_runs[i], &new_runs[j]);
        if o.cell == NO_CELL {
            i += 1;
            continue;
        }
        if !live[j] {
            j += 1;
            continue;
        }
        if o.yhi.min(n.yhi) - o.ylo.max(n.ylo) > eps {
            right[i] = (right[i].0 + 1, j);
            left[j] = (left[j].0 + 1, i);
            pairs.push((i, j));
        }
        if o.yhi < n.yhi {
            i += 1;
        } else {
            j += 1;
        }
    }
}

/// Appends the points of a boundary on the slice line `x` going from `from`
/// to `to` (one point for a bend, two for a step parallel to the slice).
fn push_vertical(chain: &mut Vec<Coord<f64>>, x: f64, from: f64, to: f64) {
    chain.push(Coord { x, y: from });
    if to != from {
        chain.push(Coord { x, y: to });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decompose::ring::{clean_ring, signed_area};

    fn ring(v: &[(f64, f64)]) -> Vec<Coord<f64>> {
        v.iter().map(|&(x, y)| Coord { x, y }).collect()
    }

    fn cleaned(cells: &[Cell]) -> Vec<Vec<Coord<f64>>> {
        cells.iter().map(|c| clean_ring(&c.ring(), 1e-9)).collect()
    }

    fn total_area(cells: &[Cell]) -> f64 {
        cleaned(cells).iter().map(|r| signed_area(r)).sum()
    }

    const SQUARE: &[(f64, f64)] = &[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)];

    #[test]
    fn convex_polygon_is_one_cell() {
        let cells = sweep(
            &[ring(&[(1.0, 0.0), (2.0, 1.0), (1.0, 2.0), (0.0, 1.0)])],
            1e-9,
        )
        .unwrap();
        assert_eq!(cells.len(), 1);
        assert_eq!(
            cleaned(&cells)[0],
            ring(&[(0.0, 1.0), (1.0, 0.0), (2.0, 1.0), (1.0, 2.0)])
        );
    }

    #[test]
    fn square_sides_parallel_to_the_slice() {
        let cells = sweep(&[ring(SQUARE)], 1e-9).unwrap();
        assert_eq!(
            cleaned(&cells),
            vec![ring(&[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)])]
        );
    }

    #[test]
    fn hole_splits_into_four_cells() {
        // Holes must be clockwise (interior on the left).
        let hole = ring(&[(0.5, 1.25), (0.5, 1.75), (1.0, 1.75), (1.0, 1.25)]);
        let cells = sweep(&[ring(SQUARE), hole], 1e-9).unwrap();
        assert_eq!(cells.len(), 4);
        let rings = cleaned(&cells);
        // Left of the hole, below it, above it, right of it.
        assert_eq!(
            rings[0],
            ring(&[(0.0, 0.0), (0.5, 0.0), (0.5, 2.0), (0.0, 2.0)])
        );
        assert_eq!(
            rings[1],
            ring(&[(0.5, 0.0), (1.0, 0.0), (1.0, 1.25), (0.5, 1.25)])
        );
        assert_eq!(
            rings[2],
            ring(&[(0.5, 1.75), (1.0, 1.75), (1.0, 2.0), (0.5, 2.0)])
        );
        assert_eq!(
            rings[3],
            ring(&[(1.0, 0.0), (2.0, 0.0), (2.0, 2.0), (1.0, 2.0)])
        );
        assert!((total_area(&cells) - 3.75).abs() < 1e-12);
    }

    #[test]
    fn bends_do_not_split_cells() {
        // A zig-zag bottom and top: many vertices, no critical point inside.
        let cells = sweep(
            &[ring(&[
                (0.0, 0.0),
                (1.0, -0.5),
                (2.0, 0.3),
                (3.0, 0.0),
                (3.0, 2.0),
                (2.5, 2.5),
                (1.0, 1.7),
                (0.0, 2.0),
            ])],
            1e-9,
        )
        .unwrap();
        assert_eq!(cells.len(), 1);
    }

    #[test]
    fn steps_parallel_to_the_slice_do_not_split_cells() {
        // A staircase: vertical risers are bends, not critical points.
        let stairs = ring(&[
            (0.0, 0.0),
            (3.0, 0.0),
            (3.0, 3.0),
            (2.0, 3.0),
            (2.0, 2.0),
            (1.0, 2.0),
            (1.0, 1.0),
            (0.0, 1.0),
        ]);
        let cells = sweep(&[stairs], 1e-9).unwrap();
        assert_eq!(cells.len(), 1);
        assert!((total_area(&cells) - 6.0).abs() < 1e-12);
        assert_eq!(cleaned(&cells)[0].len(), 8);
    }

    #[test]
    fn reflex_vertex_of_the_outer_ring_splits() {
        // A "C" opening to the right: at x = 1 the slice splits in two.
        let c = ring(&[
            (0.0, 0.0),
            (3.0, 0.0),
            (3.0, 1.0),
            (1.0, 1.0),
            (1.0, 2.0),
            (3.0, 2.0),
            (3.0, 3.0),
            (0.0, 3.0),
        ]);
        let cells = sweep(&[c], 1e-9).unwrap();
        assert_eq!(cells.len(), 3);
        assert!((total_area(&cells) - 7.0).abs() < 1e-12);
    }

    #[test]
    fn overlapping_and_nested_rings_count_as_their_union() {
        let a = ring(&[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]);
        let nested = ring(&[(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5)]);
        let cells = sweep(&[a.clone(), nested], 1e-9).unwrap();
        assert_eq!(cells.len(), 1);
        assert!((total_area(&cells) - 4.0).abs() < 1e-12);
    }

    #[test]
    fn disjoint_and_corner_touching_components() {
        let a = ring(&[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]);
        let b = ring(&[(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)]);
        let c = ring(&[(5.0, 0.0), (6.0, 0.0), (6.0, 1.0), (5.0, 1.0)]);
        let cells = sweep(&[a, b, c], 1e-9).unwrap();
        assert_eq!(cells.len(), 3);
        assert!((total_area(&cells) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn hole_touching_the_outer_ring_at_a_point() {
        // A triangular hole whose bottom vertex lies on the outer bottom edge.
        let outer = ring(&[(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0)]);
        let hole = ring(&[(1.0, 2.0), (3.0, 2.0), (2.0, 0.0)]);
        let cells = sweep(&[outer, hole], 1e-9).unwrap();
        assert!((total_area(&cells) - 14.0).abs() < 1e-12);
        // Left, lower-left triangle, lower-right triangle, above, right.
        assert_eq!(cells.len(), 5);
    }

    #[test]
    fn crossing_edges_are_reported() {
        let bowtie = ring(&[(0.0, 0.0), (2.0, 2.0), (2.0, 0.0), (0.0, 2.0)]);
        assert!(sweep(&[bowtie], 1e-9).is_err());
        // Overlapping diamonds: their slanted edges cross.
        let a = ring(&[(0.0, 1.0), (1.0, 0.0), (2.0, 1.0), (1.0, 2.0)]);
        let b = ring(&[(1.0, 1.0), (2.0, 0.0), (3.0, 1.0), (2.0, 2.0)]);
        assert_eq!(sweep(&[a, b], 1e-9), Err(SweepFailure::Crossing));
    }

    #[test]
    fn overlapping_axis_parallel_squares_give_their_union() {
        // Crossings with edges parallel to the slice are harmless under the
        // winding rule: the L-shaped union comes out as one monotone cell.
        let a = ring(&[(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)]);
        let b = ring(&[(1.0, 1.0), (3.0, 1.0), (3.0, 3.0), (1.0, 3.0)]);
        let cells = sweep(&[a, b], 1e-9).unwrap();
        assert_eq!(cells.len(), 1);
        assert!((total_area(&cells) - 7.0).abs() < 1e-12);
    }

    #[test]
    fn nearly_vertical_sides_do_not_split() {
        // Sides off vertical by 1e-13: thin slabs, but no sliver cells.
        let r = ring(&[(0.0, 0.0), (1.0, 0.0), (1.0 + 1e-13, 1.0), (1e-13, 1.0)]);
        let cells = sweep(&[r], 1e-9).unwrap();
        assert_eq!(cells.len(), 1);
        assert_eq!(cleaned(&cells)[0].len(), 4);
    }

    #[test]
    fn empty_input_gives_no_cells() {
        assert_eq!(sweep(&[], 1e-9), Ok(vec![]));
        assert_eq!(sweep(&[ring(&[(0.0, 0.0), (1.0, 1.0)])], 1e-9), Ok(vec![]));
    }
}
