//! Back-and-forth (boustrophedon) lanes in one cell (SPEC §3.3, thesis §5.4).
//!
//! Candidate lane directions are parallel and perpendicular to every cell
//! edge, plus the slice direction (along which the decomposition guarantees
//! the cell is monotone, so at least one candidate is always valid). For each
//! direction the cell is looked at in a frame where lanes run along `u` and
//! are stacked along `v`; the direction with the fewest turns, then the
//! shortest flown length, wins.

use geo::Area;
use geo_types::{Coord, MultiPolygon, Polygon};

use super::grid::LaneGrid;
use super::links::LinkRouter;
use super::region::{EPS, FreeSpace, Region, dot, is_positive};
use super::{CellPlan, Lane};

/// More lanes than this in one cell means the spacing is absurdly small for
/// the cell; such a direction is not planned (memory would explode).
pub(super) const MAX_ROWS: usize = 100_000;

/// Plans the lanes of `cell` (index `cell_index` in the decomposition) with
/// lanes at most `line_spacing_m` apart. `free` is the free space (ROI minus
/// NFZs) that contains the cell: lanes are extended through it to cover
/// slanted boundaries but never leave it, and links avoid its exterior.
///
/// Returns `None` for a degenerate cell (fewer than three distinct vertices,
/// no area, non-finite coordinates) or a spacing that is not a positive
/// number (or so small that the cell would need more than 100 000 lanes).
///
/// Prepares `free` on every call; to plan many cells in the same free space,
/// prepare it once and use [`plan_cell_in`].
pub fn plan_cell(
    cell_index: usize,
    cell: &Polygon<f64>,
    free: &MultiPolygon<f64>,
    line_spacing_m: f64,
    slice_angle_deg: f64,
) -> Option<CellPlan> {
    plan_cell_in(
        cell_index,
        cell,
        &FreeSpace::new(free),
        line_spacing_m,
        slice_angle_deg,
    )
}

/// [`plan_cell`] against free space prepared once ([`FreeSpace::new`]):
/// the same plan, but each query only looks at the free-space edges near it.
pub fn plan_cell_in(
    cell_index: usize,
    cell: &Polygon<f64>,
    free: &FreeSpace,
    line_spacing_m: f64,
    slice_angle_deg: f64,
) -> Option<CellPlan> {
    CellLayouts::new(cell_index, cell, line_spacing_m, slice_angle_deg)?.best_plan(cell, free)
}

/// Every lane layout of `cell` with the fewest turns (one per candidate
/// direction that reaches that count), for callers that break the tie by
/// another length than the 2D one (e.g. the 3D length over terrain).
/// `None` where [`plan_cell_in`] gives `None`.
pub fn plan_cell_candidates_in(
    cell_index: usize,
    cell: &Polygon<f64>,
    free: &FreeSpace,
    line_spacing_m: f64,
    slice_angle_deg: f64,
) -> Option<Vec<CellPlan>> {
    let layouts = CellLayouts::new(cell_index, cell, line_spacing_m, slice_angle_deg)?;
    let router = LinkRouter::new(cell, free);
    let plans: Vec<CellPlan> = layouts
        .all_finalists()
        .iter()
        .filter_map(|layout| {
            crate::cancel::check().ok()?;
            layouts.plan(layout, free.region(), &router)
        })
        .collect();
    (!plans.is_empty()).then_some(plans)
}

/// The lane layouts of one cell that reach its fewest turns, before their
/// lanes are extended through free space and linked: the turn count of a
/// cell is known at this stage, and the costly rest is only done for the
/// layouts (and slice angles) that may win.
pub struct CellLayouts {
    cell_index: usize,
    ring: Vec<Coord<f64>>,
    cell_region: Region,
    /// Each with [`CellLayouts::lanes`] lanes, in candidate order.
    finalists: Vec<Layout>,
    /// Candidates after the finalists, of the same row count, not looked at
    /// yet: with one row, the first monotone layout already tells the lane
    /// count (one), and most cells among many small NFZs have one row.
    pending: Vec<(Frame, Vec<RowOffset>)>,
    lanes: usize,
}

impl CellLayouts {
    /// Ranks the candidate directions of `cell` (see [`plan_cell`] for the
    /// arguments and when there is no plan).
    pub fn new(
        cell_index: usize,
        cell: &Polygon<f64>,
        line_spacing_m: f64,
        slice_angle_deg: f64,
    ) -> Option<CellLayouts> {
        Self::with_bearings(cell_index, cell, line_spacing_m, |ring| {
            candidate_bearings(ring, slice_angle_deg)
        })
    }

    /// The layout of `cell` with lanes of bearing `bearing_deg` only: for a
    /// cell joined from several ([`crate::decompose::decompose_merged`]),
    /// whose lanes across the slice cover it whole, where another layout of
    /// as many lanes could leave a corner out.
    pub fn along(
        cell_index: usize,
        cell: &Polygon<f64>,
        line_spacing_m: f64,
        bearing_deg: f64,
    ) -> Option<CellLayouts> {
        let b = bearing_deg.rem_euclid(180.0);
        Self::with_bearings(cell_index, cell, line_spacing_m, |_| vec![b])
    }

    /// The layout of `cell` with its lanes on `grid`, the lane lines one
    /// grid lays across the whole free space `free` (see [`LaneGrid`]):
    /// cells side by side across the slice share lane lines, so a strip
    /// that straddles the line between two cells is flown once. `None`
    /// where [`CellLayouts::new`] gives `None`. `flown(p)` tells whether
    /// the grid line through `p`, outside the cell, is flown there (by the
    /// cell holding `p`, on the same grid): only then is a sliver of the
    /// cell left to that line's strip.
    pub fn on_grid(
        cell_index: usize,
        cell: &Polygon<f64>,
        grid: &LaneGrid,
        free: &FreeSpace,
        flown: &dyn Fn(Coord<f64>) -> bool,
    ) -> Option<CellLayouts> {
        let ring = clean_ring(cell);
        if ring.len() < 3
            || ring.iter().any(|c| !c.x.is_finite() || !c.y.is_finite())
            || cell.unsigned_area() <= EPS * EPS
        {
            return None;
        }
        let cell_region = Region::from_polygon(cell).indexed();
        let frame = Frame::new(grid.bearing(), &ring);
        let offsets = grid.rows(&frame, &ring, free.region(), flown)?;
        let layout = Layout::new(frame, &offsets, &cell_region);
        let lanes = layout.lane_count();
        (lanes > 0).then(|| CellLayouts {
            cell_index,
            ring,
            cell_region,
            finalists: vec![layout],
            pending: Vec::new(),
            lanes,
        })
    }

    fn with_bearings(
        cell_index: usize,
        cell: &Polygon<f64>,
        line_spacing_m: f64,
        bearings: impl FnOnce(&[Coord<f64>]) -> Vec<f64>,
    ) -> Option<CellLayouts> {
        if !is_positive(line_spacing_m) {
            return None;
        }
        let ring = clean_ring(cell);
        if ring.len() < 3
            || ring.iter().any(|c| !c.x.is_finite() || !c.y.is_finite())
            || cell.unsigned_area() <= EPS * EPS
        {
            return None;
        }
        // Indexed: every lane line of every candidate is clipped against it.
        let cell_region = Region::from_polygon(cell).indexed();
        // Rank cheaply before building lanes: the lane count of a direction
        // only needs the cell's extent across it. Directions are tried by
        // increasing lane count (turns are 2 per lane change) and the first
        // count with a monotone direction wins; only those finalists get
        // their free-space clipping and links computed. Cells with a curved
        // outline have hundreds of candidate directions, so this matters.
        let mut candidates: Vec<(Frame, Vec<RowOffset>)> = bearings(&ring)
            .into_iter()
            .filter_map(|b| {
                // Cancelled: no more candidates; checked again below.
                crate::cancel::check().ok()?;
                let frame = Frame::new(b, &ring);
                let offsets = row_offsets(frame.v, line_spacing_m)?;
                Some((frame, offsets))
            })
            .collect();
        candidates.sort_by_key(|(_, offsets)| offsets.len());
        let mut finalists: Vec<Layout> = Vec::new();
        let mut rejected: Vec<Layout> = Vec::new();
        let mut pending = Vec::new();
        for group in candidates.chunk_by(|a, b| a.1.len() == b.1.len()) {
            for (k, (frame, offsets)) in group.iter().enumerate() {
                // Cancelled: no plan; the caller checks again and reports it.
                crate::cancel::check().ok()?;
                let layout = Layout::new(*frame, offsets, &cell_region);
                if layout.is_monotone() {
                    finalists.push(layout);
                    if offsets.len() == 1 {
                        pending = group[k + 1..].to_vec();
                        break;
                    }
                } else {
                    rejected.push(layout);
                }
            }
            if !finalists.is_empty() {
                break;
            }
        }
        if finalists.is_empty() {
            // The cell is not monotone along any candidate (not a cell from
            // the decomposition): fly every piece of every line, fewest
            // pieces first.
            finalists = rejected;
        }
        // Every segment of a row becomes one lane: the turns are known.
        finalists.retain(|l| l.lane_count() > 0);
        let lanes = finalists.iter().map(Layout::lane_count).min()?;
        finalists.retain(|l| l.lane_count() == lanes);
        Some(CellLayouts {
            cell_index,
            ring,
            cell_region,
            finalists,
            pending,
            lanes,
        })
    }

    /// Every finalist, the pending ones laid out now.
    fn all_finalists(&self) -> Vec<std::borrow::Cow<'_, Layout>> {
        let mut all: Vec<std::borrow::Cow<'_, Layout>> = self
            .finalists
            .iter()
            .map(std::borrow::Cow::Borrowed)
            .collect();
        for (frame, offsets) in &self.pending {
            if crate::cancel::check().is_err() {
                break; // the caller checks again
            }
            let layout = Layout::new(*frame, offsets, &self.cell_region);
            if layout.is_monotone() && layout.lane_count() == self.lanes {
                all.push(std::borrow::Cow::Owned(layout));
            }
        }
        all
    }

    /// Turns of the cell's plans (2 per lane change).
    pub fn turns(&self) -> usize {
        2 * self.lanes.saturating_sub(1)
    }

    /// Lanes of the cell's plans.
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    /// No plan of the cell is shorter: the least of the finalists' lower
    /// bounds (their lanes contain the cell's part of every lane line).
    pub fn length_lower_bound(&self) -> f64 {
        self.all_finalists()
            .iter()
            .map(|l| l.length_lower_bound())
            .fold(f64::INFINITY, f64::min)
    }

    /// The shortest plan (lanes and links) among the finalists; the first
    /// in candidate order among equally long ones. Finalists are planned by
    /// increasing lower bound (the cell's own part of every lane: the flown
    /// lanes contain it) and the search stops once the bound passes the best
    /// length, so a small cell with dozens of equally good directions plans
    /// two or three of them.
    pub fn best_plan(&self, cell: &Polygon<f64>, free: &FreeSpace) -> Option<CellPlan> {
        let finalists = self.all_finalists();
        let mut order: Vec<(f64, usize)> = finalists
            .iter()
            .enumerate()
            .map(|(i, layout)| (layout.length_lower_bound(), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let router = LinkRouter::new(cell, free);
        let mut best: Option<(f64, usize, CellPlan)> = None;
        for (bound, i) in order {
            crate::cancel::check().ok()?;
            if let Some((length, _, _)) = &best
                && bound > length * (1.0 + 1e-12)
            {
                break;
            }
            let Some(plan) = self.plan(&finalists[i], free.region(), &router) else {
                continue;
            };
            let length = plan.length_m();
            let better = match &best {
                None => true,
                Some((b, j, _)) => {
                    length < b * (1.0 - 1e-12) || (length <= b * (1.0 + 1e-12) && i < *j)
                }
            };
            if better {
                best = Some((length, i, plan));
            }
        }
        best.map(|(_, _, plan)| plan)
    }

    /// The plan of one finalist: lanes extended through free space, linked.
    fn plan(&self, layout: &Layout, free: &Region, router: &LinkRouter) -> Option<CellPlan> {
        let lanes = layout.lanes(&self.ring, free);
        (!lanes.is_empty()).then(|| CellPlan {
            cell_index: self.cell_index,
            direction_deg: layout.frame.bearing,
            links: router.links(&lanes),
            lanes,
        })
    }
}

/// Exterior ring without repeated points or the closing point.
fn clean_ring(cell: &Polygon<f64>) -> Vec<Coord<f64>> {
    let mut ring: Vec<Coord<f64>> = cell.exterior().0.clone();
    ring.dedup();
    while ring.len() > 1 && ring.first() == ring.last() {
        ring.pop();
    }
    ring
}

/// A bearing in [0, 180), 180 − 10⁻⁹ and beyond counting as 0.
fn normal_bearing(b: f64) -> f64 {
    let b = b.rem_euclid(180.0);
    if b >= 180.0 - 1e-9 { 0.0 } else { b }
}

/// Whether `cell` is at most one lane wide across the slice: then laid
/// along the slice (a cell of the decomposition meets every slice line in
/// one segment) it is flown as one lane, so [`CellLayouts::new`] finds it
/// no turn whichever layout it keeps. Lets the `auto` angle count turns
/// without laying out the thousands of one-lane cells among many NFZs.
pub fn is_one_lane(cell: &Polygon<f64>, line_spacing_m: f64, slice_angle_deg: f64) -> bool {
    let ring = clean_ring(cell);
    if ring.len() < 3 || !slice_angle_deg.is_finite() {
        return false;
    }
    let frame = Frame::new(normal_bearing(slice_angle_deg), &ring);
    row_offsets(frame.v, line_spacing_m).is_some_and(|rows| rows.len() == 1)
}

/// Most candidate lane directions tried per cell. A cell with more distinct
/// edge bearings (a curved or densely digitised outline) keeps those of its
/// longest edges: each candidate costs a pass over the ring, so trying all
/// of them would be quadratic in the vertex count.
const MAX_BEARINGS: usize = 48;

/// Lane bearings in [0, 180): the slice direction first, then parallel and
/// perpendicular to each edge, without duplicates, in order of first
/// appearance. Beyond [`MAX_BEARINGS`], the bearings with the most edge
/// length along or across them are kept (the slice direction always).
fn candidate_bearings(ring: &[Coord<f64>], slice_angle_deg: f64) -> Vec<f64> {
    let normal = normal_bearing;
    // (bearing, weight, first appearance)
    let mut all: Vec<(f64, f64, usize)> = Vec::with_capacity(2 * ring.len() + 1);
    if slice_angle_deg.is_finite() {
        all.push((normal(slice_angle_deg), f64::INFINITY, 0));
    }
    for k in 0..ring.len() {
        if crate::cancel::check().is_err() {
            break; // the caller checks again and drops the cell
        }
        let e = ring[(k + 1) % ring.len()] - ring[k];
        if e.x == 0.0 && e.y == 0.0 {
            continue;
        }
        let bearing = e.x.atan2(e.y).to_degrees();
        let length = e.x.hypot(e.y);
        if bearing.is_finite() && length.is_finite() {
            all.push((normal(bearing), length, all.len()));
            all.push((normal(bearing + 90.0), length, all.len()));
        }
    }
    // Merge equal bearings (1e-9°) in one sorted pass, also across 0/180.
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut merged: Vec<(f64, f64, usize)> = Vec::with_capacity(all.len());
    for (b, w, first) in all {
        match merged.last_mut() {
            Some(m) if b - m.0 < 1e-9 => {
                m.1 += w;
                if first < m.2 {
                    m.2 = first;
                    m.0 = b;
                }
            }
            _ => merged.push((b, w, first)),
        }
    }
    if merged.len() > 1 {
        let (head, last) = (merged[0], merged[merged.len() - 1]);
        if head.0 + 180.0 - last.0 < 1e-9 {
            let keep = if last.2 < head.2 { last } else { head };
            merged[0] = (keep.0, head.1 + last.1, keep.2);
            merged.pop();
        }
    }
    if merged.len() > MAX_BEARINGS {
        merged.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.2.cmp(&b.2)));
        merged.truncate(MAX_BEARINGS);
    }
    merged.sort_by_key(|m| m.2);
    merged.into_iter().map(|m| m.0).collect()
}

/// The frame of one candidate direction: lanes run along `u` and are
/// stacked along `v`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Frame {
    pub(super) bearing: f64,
    /// Origin of the local frame.
    pub(super) origin: Coord<f64>,
    /// Unit vector along the lanes (bearing `bearing`).
    pub(super) d: Coord<f64>,
    /// Unit normal: lanes are stacked along it.
    pub(super) n: Coord<f64>,
    /// Extent of the cell along `d`.
    pub(super) u: (f64, f64),
    /// Extent of the cell along `n`.
    pub(super) v: (f64, f64),
}

/// The unit vectors of lanes of bearing `bearing`: along them (`d`) and
/// the normal they are stacked along (`n`).
pub(super) fn axes(bearing: f64) -> (Coord<f64>, Coord<f64>) {
    let rad = bearing.to_radians();
    let d = Coord {
        x: rad.sin(),
        y: rad.cos(),
    };
    // Stack the lanes eastwards (northwards for east–west lanes), as the
    // decomposition sweeps its slices.
    let n = if bearing < 90.0 {
        Coord { x: d.y, y: -d.x }
    } else {
        Coord { x: -d.y, y: d.x }
    };
    (d, n)
}

impl Frame {
    pub(super) fn new(bearing: f64, ring: &[Coord<f64>]) -> Frame {
        let (d, n) = axes(bearing);
        let origin = ring[0];
        let (mut u, mut v) = (
            (f64::INFINITY, f64::NEG_INFINITY),
            (f64::INFINITY, f64::NEG_INFINITY),
        );
        for &c in ring {
            let (cu, cv) = (dot(c - origin, d), dot(c - origin, n));
            u = (u.0.min(cu), u.1.max(cu));
            v = (v.0.min(cv), v.1.max(cv));
        }
        Frame {
            bearing,
            origin,
            d,
            n,
            u,
            v,
        }
    }

    pub(super) fn point(&self, u: f64, v: f64) -> Coord<f64> {
        self.origin + self.d * u + self.n * v
    }
}

/// A lane line's offset `v` and the band of `v` its strip must cover.
pub(super) type RowOffset = (f64, (f64, f64));

/// Lane offsets across an extent `(vmin, vmax)`: one lane in the middle of a
/// narrow cell; otherwise the first and last half a spacing inside and the
/// others evenly spread in between (so never more than `spacing` apart).
/// `None` for an empty extent or more than [`MAX_ROWS`] lanes.
fn row_offsets((vmin, vmax): (f64, f64), spacing: f64) -> Option<Vec<RowOffset>> {
    let h = vmax - vmin;
    if h.is_nan() || h <= EPS {
        return None;
    }
    if h <= spacing + EPS {
        return Some(vec![((vmin + vmax) / 2.0, (vmin, vmax))]);
    }
    // The tolerance keeps an exact multiple from gaining a lane by rounding.
    let gaps = ((h - spacing) / spacing - 1e-9).ceil().max(1.0);
    if gaps.is_nan() || gaps >= MAX_ROWS as f64 {
        return None;
    }
    let gaps = gaps as usize;
    let actual = (h - spacing) / gaps as f64;
    Some(
        (0..=gaps)
            .map(|i| {
                let v = vmin + spacing / 2.0 + i as f64 * actual;
                // The outer lanes also answer for the half spacing between
                // them and the cell's extent.
                let lo = if i == 0 { vmin } else { v - actual / 2.0 };
                let hi = if i == gaps { vmax } else { v + actual / 2.0 };
                (v, (lo, hi))
            })
            .collect(),
    )
}

/// Lane rows of one candidate direction.
#[derive(Clone)]
struct Layout {
    frame: Frame,
    rows: Vec<Row>,
}

#[derive(Clone)]
struct Row {
    /// Offset of the lane line along `n`.
    v: f64,
    /// The strip of the cell this lane must cover, along `n`.
    band: (f64, f64),
    /// Parts of the lane line inside the cell, as `u` ranges, ascending.
    segments: Vec<(f64, f64)>,
}

impl Layout {
    fn new(frame: Frame, offsets: &[RowOffset], cell: &Region) -> Layout {
        let (umin, umax) = frame.u;
        let rows = offsets
            .iter()
            .filter_map(|&(v, band)| {
                // Cancelled: rows left out; the caller checks again.
                crate::cancel::check().ok()?;
                let start = frame.point(umin - 1.0, v);
                let segments: Vec<(f64, f64)> = cell
                    .intervals(start, frame.d, 0.0, umax - umin + 2.0)
                    .into_iter()
                    .map(|(s, e)| (s + umin - 1.0, e + umin - 1.0))
                    .collect();
                // Only a grazing line (rounding at a vertex) finds nothing.
                (!segments.is_empty()).then_some(Row { v, band, segments })
            })
            .collect();
        Layout { frame, rows }
    }

    /// Every lane line meets the cell in one segment.
    fn is_monotone(&self) -> bool {
        !self.rows.is_empty() && self.rows.iter().all(|r| r.segments.len() == 1)
    }

    fn lane_count(&self) -> usize {
        self.rows.iter().map(|r| r.segments.len()).sum()
    }

    /// No plan of this layout is shorter: its lanes contain these segments
    /// (up to the tolerance at each end).
    fn length_lower_bound(&self) -> f64 {
        self.rows
            .iter()
            .flat_map(|r| &r.segments)
            .map(|&(a, b)| (b - a - 2.0 * EPS).max(0.0))
            .sum()
    }

    fn point(&self, u: f64, v: f64) -> Coord<f64> {
        self.frame.point(u, v)
    }

    /// The lanes in flight order, alternating direction row by row.
    fn lanes(&self, ring: &[Coord<f64>], free: &Region) -> Vec<Lane> {
        let mut lanes = Vec::with_capacity(self.rows.len());
        let extents = self.band_extents(ring);
        for (k, row) in self.rows.iter().enumerate() {
            if crate::cancel::check().is_err() {
                // The caller checks again and drops these lanes.
                break;
            }
            let forward = k % 2 == 0;
            let (bu0, bu1) = extents[k];
            let count = row.segments.len();
            let mut row_lanes: Vec<Lane> = row
                .segments
                .iter()
                .enumerate()
                .map(|(i, &(a, b))| {
                    // Extend the row's outer ends so the strip reaches the
                    // farthest cell point in its band (slanted boundaries).
                    let lo = if i == 0 { bu0.min(a) } else { a };
                    let hi = if i + 1 == count { bu1.max(b) } else { b };
                    let (u0, u1) = self.clip_to_free(free, row.v, (lo, hi), (a, b));
                    let (p, q) = (self.point(u0, row.v), self.point(u1, row.v));
                    if forward {
                        Lane { start: p, end: q }
                    } else {
                        Lane { start: q, end: p }
                    }
                })
                .collect();
            if !forward {
                row_lanes.reverse();
            }
            lanes.extend(row_lanes);
        }
        lanes
    }

    /// For every row, the `u` range of the part of the cell within its band
    /// (along `n`). One pass over the ring: each edge only visits the rows
    /// whose bands its `v` range meets (rows are in increasing `v`), so the
    /// cost is the ring plus the rows, not their product.
    fn band_extents(&self, ring: &[Coord<f64>]) -> Vec<(f64, f64)> {
        let mut out = vec![(f64::INFINITY, f64::NEG_INFINITY); self.rows.len()];
        let m = ring.len();
        for k in 0..m {
            let (p, q) = (
                ring[k] - self.frame.origin,
                ring[(k + 1) % m] - self.frame.origin,
            );
            let (u1, v1, u2, v2) = (
                dot(p, self.frame.d),
                dot(p, self.frame.n),
                dot(q, self.frame.d),
                dot(q, self.frame.n),
            );
            let (vlo, vhi) = (v1.min(v2), v1.max(v2));
            let first = self.rows.partition_point(|r| r.band.1 + EPS < vlo);
            for (row, extent) in self.rows[first..].iter().zip(&mut out[first..]) {
                let (lo, hi) = row.band;
                if lo - EPS > vhi {
                    break;
                }
                let mut take = |u: f64| {
                    extent.0 = extent.0.min(u);
                    extent.1 = extent.1.max(u);
                };
                if (v2 - v1).abs() <= f64::EPSILON * (v1.abs() + v2.abs()) {
                    if v1 >= lo - EPS && v1 <= hi + EPS {
                        take(u1);
                        take(u2);
                    }
                    continue;
                }
                // Part of the edge whose v lies in the band.
                let ta = ((lo - v1) / (v2 - v1)).clamp(0.0, 1.0);
                let tb = ((hi - v1) / (v2 - v1)).clamp(0.0, 1.0);
                let (t0, t1) = (ta.min(tb), ta.max(tb));
                let v_at = |t: f64| v1 + (v2 - v1) * t;
                if v_at(t0) < lo - EPS || v_at(t0) > hi + EPS {
                    continue; // the edge misses the band
                }
                take(u1 + (u2 - u1) * t0);
                take(u1 + (u2 - u1) * t1);
            }
        }
        out
    }

    /// Clips the wanted lane `(lo, hi)` to the stretch of its line that lies
    /// in free space and contains the lane's part in the cell `(a, b)`.
    fn clip_to_free(
        &self,
        free: &Region,
        v: f64,
        (lo, hi): (f64, f64),
        (a, b): (f64, f64),
    ) -> (f64, f64) {
        let start = self.point(lo, v);
        let mid = (a + b) / 2.0 - lo;
        free.interval_around(start, self.frame.d, (0.0, hi - lo), mid)
            .map(|(s, e)| (lo + s, lo + e))
            // The cell is not in free space (inconsistent input): fly only
            // the part in the cell.
            .unwrap_or((a, b))
    }
}

#[cfg(test)]
mod tests {
    use super::super::coverage_ratio;
    use super::*;
    use approx::assert_abs_diff_eq;
    use geo::{BooleanOps, Buffer, Covers, Intersects};
    use geo_types::{Line, LineString, coord};

    const X0: f64 = 480_000.0;
    const Y0: f64 = 5_200_000.0;

    /// A polygon from coordinates relative to a UTM-like origin.
    fn poly(pts: &[(f64, f64)]) -> Polygon<f64> {
        Polygon::new(
            LineString(
                pts.iter()
                    .map(|&(x, y)| coord! { x: X0 + x, y: Y0 + y })
                    .collect(),
            ),
            vec![],
        )
    }

    fn local(c: Coord<f64>) -> (f64, f64) {
        (c.x - X0, c.y - Y0)
    }

    /// A 100 m square with a thin wedge cut into its east side, its tip at
    /// (30, 20): between the first two east–west lanes at spacing 20.
    fn wedge_cell() -> Polygon<f64> {
        poly(&[
            (0., 0.),
            (100., 0.),
            (100., 15.),
            (30., 20.),
            (100., 25.),
            (100., 100.),
            (0., 100.),
        ])
    }

    /// A 300 × 100 m block with a notch 100 m wide and 60 m deep cut from
    /// the north (x = 100 … 200, down to y = 40) and, if `east_notch`, one
    /// 50 m deep cut from the east (y = 40 … 60, in to x = 250).
    fn notched_cell(east_notch: bool) -> Polygon<f64> {
        let mut pts = vec![(0., 0.), (300., 0.)];
        if east_notch {
            pts.extend([(300., 40.), (250., 40.), (250., 60.), (300., 60.)]);
        }
        pts.extend([
            (300., 100.),
            (200., 100.),
            (200., 40.),
            (100., 40.),
            (100., 100.),
            (0., 100.),
        ]);
        poly(&pts)
    }

    /// Every flown segment (lanes and links) stays in `free`, checked with
    /// geo's exact predicates against free space grown by a micrometre.
    fn assert_flown_in_free(plan: &CellPlan, free: &MultiPolygon<f64>) {
        let grown = free.buffer(1e-6);
        for w in plan.path().windows(2) {
            assert!(
                grown.covers(&Line::new(w[0], w[1])),
                "{:?} leaves free space",
                w
            );
        }
        for lane in &plan.lanes {
            assert!(grown.covers(&Line::new(lane.start, lane.end)), "{lane:?}");
        }
    }

    fn assert_boustrophedon(plan: &CellPlan) {
        let rad = plan.direction_deg.to_radians();
        let d = coord! { x: rad.sin(), y: rad.cos() };
        for (i, lane) in plan.lanes.iter().enumerate() {
            let along = dot(lane.end - lane.start, d);
            assert!(along.abs() > 0.0);
            if i > 0 {
                let prev = dot(plan.lanes[i - 1].end - plan.lanes[i - 1].start, d);
                assert!(
                    along * prev < 0.0,
                    "lanes {} and {i} fly the same way",
                    i - 1
                );
            }
            // Lanes are straight along the chosen direction.
            let across = super::super::region::cross(d, lane.end - lane.start);
            assert!(across.abs() < 1e-6);
        }
        assert_eq!(plan.links.len(), plan.lanes.len() - 1);
    }

    #[test]
    fn rectangle_lanes_along_long_side() {
        let cell = poly(&[(0., 0.), (200., 0.), (200., 100.), (0., 100.)]);
        let free = MultiPolygon(vec![cell.clone()]);
        // North–south slices; lanes still go east–west along the long side.
        let plan = plan_cell(7, &cell, &free, 20.0, 0.0).unwrap();
        assert_eq!(plan.cell_index, 7);
        assert_abs_diff_eq!(plan.direction_deg, 90.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 5);
        assert_eq!(plan.turns(), 8);
        for (i, lane) in plan.lanes.iter().enumerate() {
            let (sx, sy) = local(lane.start);
            let (ex, ey) = local(lane.end);
            let y = 10.0 + 20.0 * i as f64;
            assert_abs_diff_eq!(sy, y, epsilon = 1e-6);
            assert_abs_diff_eq!(ey, y, epsilon = 1e-6);
            let (from, to) = if i % 2 == 0 {
                (0.0, 200.0)
            } else {
                (200.0, 0.0)
            };
            assert_abs_diff_eq!(sx, from, epsilon = 1e-6);
            assert_abs_diff_eq!(ex, to, epsilon = 1e-6);
        }
        assert!(plan.links.iter().all(Vec::is_empty));
        assert_abs_diff_eq!(plan.length_m(), 5.0 * 200.0 + 4.0 * 20.0, epsilon = 1e-6);
        assert_boustrophedon(&plan);
    }

    /// The lower bound is never above the best plan's length, and equals
    /// the lanes' length where lanes end on the cell's sides.
    #[test]
    fn length_lower_bound_bounds_the_best_plan() {
        let rect = poly(&[(0., 0.), (200., 0.), (200., 100.), (0., 100.)]);
        let layouts = CellLayouts::new(0, &rect, 20.0, 0.0).unwrap();
        assert_eq!(layouts.lanes(), 5);
        assert_abs_diff_eq!(layouts.length_lower_bound(), 1000.0, epsilon = 1e-4);
        let free = FreeSpace::new(&MultiPolygon(vec![rect.clone()]));
        let plan = layouts.best_plan(&rect, &free).unwrap();
        assert!(layouts.length_lower_bound() <= plan.length_m() + 1e-9);
        // A trapezoid: lanes reach past the slanted side, the bound does not.
        let trap = poly(&[(0., 0.), (200., 0.), (150., 100.), (0., 100.)]);
        let layouts = CellLayouts::new(0, &trap, 20.0, 0.0).unwrap();
        let free = FreeSpace::new(&MultiPolygon(vec![trap.clone()]));
        let plan = layouts.best_plan(&trap, &free).unwrap();
        let lanes: f64 = plan
            .lanes
            .iter()
            .map(|l| (l.end - l.start).x.hypot((l.end - l.start).y))
            .sum();
        assert!(layouts.length_lower_bound() <= lanes + 1e-9);
        assert!(layouts.length_lower_bound() > 0.8 * lanes);
    }

    #[test]
    fn spacing_is_never_exceeded() {
        // Height 110 with spacing 20: ceil(90/20) + 1 = 6 lanes, 18 m apart,
        // the outer ones 10 m inside.
        let cell = poly(&[(0., 0.), (300., 0.), (300., 110.), (0., 110.)]);
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 90.0).unwrap();
        let ys: Vec<f64> = plan.lanes.iter().map(|l| local(l.start).1).collect();
        assert_eq!(ys.len(), 6);
        for (i, y) in ys.iter().enumerate() {
            assert_abs_diff_eq!(*y, 10.0 + 18.0 * i as f64, epsilon = 1e-6);
        }
        // A cell narrower than the spacing gets one lane in the middle.
        let thin = poly(&[(0., 0.), (300., 0.), (300., 12.), (0., 12.)]);
        let plan = plan_cell(0, &thin, &MultiPolygon(vec![thin.clone()]), 20.0, 0.0).unwrap();
        assert_eq!(plan.lanes.len(), 1);
        assert_abs_diff_eq!(local(plan.lanes[0].start).1, 6.0, epsilon = 1e-6);
        assert_eq!(plan.turns(), 0);
        assert!(plan.links.is_empty());
    }

    #[test]
    fn rotated_rectangle_follows_its_edges() {
        // 300 × 90 rectangle turned 30° from the axes.
        let (s, c) = 30f64.to_radians().sin_cos();
        let pts: Vec<(f64, f64)> = [(0., 0.), (300., 0.), (300., 90.), (0., 90.)]
            .iter()
            .map(|&(x, y)| (x * c - y * s, x * s + y * c))
            .collect();
        let cell = poly(&pts);
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 0.0).unwrap();
        // The long side has bearing 90° − 30° = 60°.
        assert_abs_diff_eq!(plan.direction_deg, 60.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 5); // ceil(70/20) + 1
        for lane in &plan.lanes {
            assert_abs_diff_eq!(
                (lane.end.x - lane.start.x).hypot(lane.end.y - lane.start.y),
                300.0,
                epsilon = 1e-6
            );
        }
        assert_boustrophedon(&plan);
        assert_flown_in_free(&plan, &free);
    }

    #[test]
    fn slanted_boundaries_are_fully_covered() {
        // Cells inside a larger free area: lanes may reach past the slanted
        // edges so that their strips cover the corners.
        let roi = poly(&[(-200., -200.), (800., -200.), (800., 600.), (-200., 600.)]);
        let free = MultiPolygon(vec![roi]);
        let cells = [
            poly(&[(0., 0.), (400., 0.), (500., 300.), (100., 300.)]), // parallelogram
            poly(&[(0., 0.), (500., 40.), (180., 350.)]),              // triangle
            poly(&[(0., 0.), (450., 0.), (350., 200.), (60., 220.)]),  // trapezoid
        ];
        for (i, cell) in cells.iter().enumerate() {
            for slice in [0.0, 90.0] {
                let plan = plan_cell(i, cell, &free, 25.0, slice).unwrap();
                let ratio = coverage_ratio(&plan.lanes, 25.0, &MultiPolygon(vec![cell.clone()]));
                assert!(ratio >= 0.995, "cell {i}: coverage {ratio}");
                assert_boustrophedon(&plan);
                assert_flown_in_free(&plan, &free);
            }
        }
        // Without free space around them the lanes stop at the slanted
        // edges and the corners of each strip are missed.
        for cell in &cells[1..] {
            let own = MultiPolygon(vec![cell.clone()]);
            let plan = plan_cell(0, cell, &own, 25.0, 0.0).unwrap();
            let ratio = coverage_ratio(&plan.lanes, 25.0, &own);
            assert!(ratio < 0.99, "{ratio}");
            assert_flown_in_free(&plan, &own);
        }
    }

    #[test]
    fn lanes_stop_at_free_space_boundary() {
        // Triangle cell whose west leg borders an NFZ and whose south leg is
        // the ROI border: lanes parallel to the hypotenuse may reach past
        // neither, so the corners there stay uncovered, but nothing leaves
        // free space.
        let roi = poly(&[(0., 100.), (400., 100.), (400., 400.), (0., 400.)]);
        let nfz = poly(&[(0., 100.), (100., 100.), (100., 300.), (0., 300.)]);
        let free = MultiPolygon(vec![roi]).difference(&MultiPolygon(vec![nfz.clone()]));
        let cell = poly(&[(100., 100.), (300., 100.), (100., 300.)]);
        let plan = plan_cell(0, &cell, &free, 20.0, 0.0).unwrap();
        assert_abs_diff_eq!(plan.direction_deg, 135.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 8); // ceil((141.42 − 20)/20) + 1
        assert_flown_in_free(&plan, &free);
        let shrunk = nfz.buffer(-1e-6);
        for lane in &plan.lanes {
            assert!(
                !shrunk.intersects(&Line::new(lane.start, lane.end)),
                "{lane:?}"
            );
        }
        // Lanes end on the legs, so each lane end misses a small triangle.
        let ratio = coverage_ratio(&plan.lanes, 20.0, &MultiPolygon(vec![cell.clone()]));
        assert!(ratio < 0.99 && ratio > 0.9, "{ratio}");
    }

    #[test]
    fn lanes_extend_into_neighbouring_free_space() {
        // Same triangle, but west of it is free: west ends reach past the
        // leg (x < 100), south ends still stop at the ROI border (y = 100).
        let roi = poly(&[(0., 100.), (400., 100.), (400., 400.), (0., 400.)]);
        let free = MultiPolygon(vec![roi]);
        let cell = poly(&[(100., 100.), (300., 100.), (100., 300.)]);
        let plan = plan_cell(0, &cell, &free, 20.0, 0.0).unwrap();
        assert_flown_in_free(&plan, &free);
        let min_x = plan
            .lanes
            .iter()
            .flat_map(|l| [l.start, l.end])
            .map(|c| local(c).0);
        assert!(min_x.fold(f64::INFINITY, f64::min) < 100.0 - 1.0);
        for c in plan.lanes.iter().flat_map(|l| [l.start, l.end]) {
            assert!(local(c).1 >= 100.0 - 1e-6);
        }
    }

    #[test]
    fn concave_monotone_cell_gets_safe_links() {
        // Every east–west line meets the cell once, but the straight link
        // between the east ends of the first two lanes would cross the wedge.
        let cell = wedge_cell();
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 90.0).unwrap();
        assert_abs_diff_eq!(plan.direction_deg, 90.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 5);
        assert_eq!(plan.links[0].len(), 1);
        let (x, y) = local(plan.links[0][0]);
        assert_abs_diff_eq!(x, 30.0, epsilon = 1e-6);
        assert_abs_diff_eq!(y, 20.0, epsilon = 1e-6);
        assert!(plan.links[1..].iter().all(Vec::is_empty));
        assert_flown_in_free(&plan, &free);
        // The straight link would indeed have left the cell.
        let straight = Line::new(plan.lanes[0].end, plan.lanes[1].start);
        assert!(!free.buffer(1e-6).covers(&straight));
    }

    #[test]
    fn reoriented_variants_keep_lanes_and_stay_safe() {
        let cell = wedge_cell();
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 90.0).unwrap();
        assert_eq!(plan.reoriented(false, false, &cell, &free), plan);
        let key = |l: &Lane| {
            let (a, b) = (local(l.start), local(l.end));
            let (a, b) = if a < b { (a, b) } else { (b, a) };
            [a.0, a.1, b.0, b.1].map(|v| (v * 1e6).round() as i64)
        };
        let mut original: Vec<_> = plan.lanes.iter().map(key).collect();
        original.sort();
        let mut entries = Vec::new();
        for (rev, flip) in [(false, false), (false, true), (true, false), (true, true)] {
            let r = plan.reoriented(rev, flip, &cell, &free);
            let mut lanes: Vec<_> = r.lanes.iter().map(key).collect();
            lanes.sort();
            assert_eq!(lanes, original);
            assert_eq!(r.direction_deg, plan.direction_deg);
            assert_boustrophedon(&r);
            assert_flown_in_free(&r, &free);
            let flown = |p: &CellPlan| -> f64 {
                p.lanes
                    .iter()
                    .map(|l| (l.end.x - l.start.x).hypot(l.end.y - l.start.y))
                    .sum()
            };
            assert_abs_diff_eq!(flown(&r), flown(&plan), epsilon = 1e-6);
            entries.push(r.entry().unwrap());
        }
        // Four different entry points: both ends of the first and last lane.
        for i in 0..4 {
            for j in i + 1..4 {
                assert!((entries[i].x - entries[j].x).hypot(entries[i].y - entries[j].y) > 1.0);
            }
        }
        // Reversed and flipped is the original path backwards.
        let back = plan.reoriented(true, true, &cell, &free);
        let mut path = back.path();
        path.reverse();
        let orig = plan.path();
        assert_eq!(path.len(), orig.len());
        for (p, q) in path.iter().zip(&orig) {
            assert_abs_diff_eq!(p.x, q.x, epsilon = 1e-6);
            assert_abs_diff_eq!(p.y, q.y, epsilon = 1e-6);
        }
    }

    #[test]
    fn non_monotone_direction_is_rejected() {
        // A notch cut from the north: north–south lines (the slices) meet the
        // cell once, east–west lines through the notch meet it twice.
        let cell = notched_cell(false);
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 0.0).unwrap();
        // East–west would need only 5 lanes, but 15 north–south ones are
        // the fewest among the monotone directions.
        assert_abs_diff_eq!(plan.direction_deg, 0.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 15);
        assert_boustrophedon(&plan);
        assert_flown_in_free(&plan, &free);
        // Lanes under the notch stop at its floor.
        for lane in &plan.lanes[5..10] {
            assert_abs_diff_eq!(
                local(lane.start).1.max(local(lane.end).1),
                40.0,
                epsilon = 1e-6
            );
        }
        // From x = 90 (flown north) to x = 110 the link goes round the
        // notch's corner instead of cutting through it.
        assert_eq!(plan.links[4].len(), 1);
        let (x, y) = local(plan.links[4][0]);
        assert_abs_diff_eq!(x, 100.0, epsilon = 1e-6);
        assert_abs_diff_eq!(y, 40.0, epsilon = 1e-6);
        let ratio = coverage_ratio(&plan.lanes, 20.0, &free);
        assert!(ratio > 0.999, "{ratio}");
    }

    #[test]
    fn non_monotone_cell_still_gets_a_safe_plan() {
        // Notches from the north and from the east: no candidate direction
        // is monotone, so every piece of every line becomes a lane.
        let cell = notched_cell(true);
        let free = MultiPolygon(vec![cell.clone()]);
        let plan = plan_cell(0, &cell, &free, 20.0, 0.0).unwrap();
        // East–west rows at y = 10 … 90: one piece each at 10 and 30, two
        // at 50, 70, 90 → 8 lanes, against 15 + 2 north–south (the east
        // notch cuts x = 270 and 290).
        assert_abs_diff_eq!(plan.direction_deg, 90.0, epsilon = 1e-9);
        assert_eq!(plan.lanes.len(), 8);
        assert_eq!(plan.links.len(), 7);
        assert_flown_in_free(&plan, &free);
        let ratio = coverage_ratio(&plan.lanes, 20.0, &free);
        assert!(ratio > 0.999, "{ratio}");
    }

    #[test]
    fn curved_cell_with_many_edges() {
        // A 256-gon (128 distinct candidate directions) of radius 500 m
        // inside a free area whose own outline has 1024 vertices.
        let ngon = |r: f64, k: usize| -> Vec<(f64, f64)> {
            (0..k)
                .map(|i| {
                    let a = std::f64::consts::TAU * i as f64 / k as f64;
                    (r * a.cos(), r * a.sin())
                })
                .collect()
        };
        let cell = poly(&ngon(500.0, 256));
        let free = MultiPolygon(vec![poly(&ngon(700.0, 1024))]);
        let t = std::time::Instant::now();
        let plan = plan_cell(0, &cell, &free, 30.0, 0.0).unwrap();
        assert!(t.elapsed().as_secs_f64() < 10.0, "{:?}", t.elapsed());
        assert_eq!(plan.lanes.len(), 34); // ceil((1000 − 30)/30) + 1
        assert_boustrophedon(&plan);
        assert_flown_in_free(&plan, &free);
        let ratio = coverage_ratio(&plan.lanes, 30.0, &MultiPolygon(vec![cell.clone()]));
        assert!(ratio >= 0.995, "{ratio}");
    }

    #[test]
    fn degenerate_input_gives_none() {
        let free = MultiPolygon(vec![poly(&[(0., 0.), (10., 0.), (10., 10.), (0., 10.)])]);
        let line = poly(&[(0., 0.), (10., 0.), (5., 0.)]);
        assert!(plan_cell(0, &line, &free, 5.0, 0.0).is_none());
        let two = poly(&[(0., 0.), (10., 0.), (10., 0.)]);
        assert!(plan_cell(0, &two, &free, 5.0, 0.0).is_none());
        let empty = Polygon::new(LineString(vec![]), vec![]);
        assert!(plan_cell(0, &empty, &free, 5.0, 0.0).is_none());
        let nan = poly(&[(0., 0.), (f64::NAN, 0.), (10., 10.)]);
        assert!(plan_cell(0, &nan, &free, 5.0, 0.0).is_none());
        let cell = poly(&[(0., 0.), (10., 0.), (10., 10.)]);
        assert!(plan_cell(0, &cell, &free, 0.0, 0.0).is_none());
        assert!(plan_cell(0, &cell, &free, f64::NAN, 0.0).is_none());
        assert!(plan_cell(0, &cell, &free, 1e-9, 0.0).is_none());
        // A non-finite slice angle only drops that candidate.
        assert!(plan_cell(0, &cell, &free, 5.0, f64::NAN).is_some());
        // An implicitly closed ring works like a closed one.
        let open = Polygon::new(
            LineString(vec![
                coord! { x: 0., y: 0. },
                coord! { x: 10., y: 0. },
                coord! { x: 10., y: 10. },
            ]),
            vec![],
        );
        assert!(plan_cell(0, &open, &free, 5.0, 0.0).is_some());
    }

    #[test]
    fn candidates_are_deduplicated() {
        let ring = [
            coord! { x: 0., y: 0. },
            coord! { x: 10., y: 0. },
            coord! { x: 10., y: 10. },
            coord! { x: 0., y: 10. },
        ];
        assert_eq!(candidate_bearings(&ring, 0.0), vec![0.0, 90.0]);
        assert_eq!(candidate_bearings(&ring, 180.0), vec![0.0, 90.0]);
        let tri = [
            coord! { x: 0., y: 0. },
            coord! { x: 10., y: 10. },
            coord! { x: 0., y: 10. },
        ];
        let b = candidate_bearings(&tri, -30.0);
        assert_eq!(b.len(), 5);
        assert_abs_diff_eq!(b[0], 150.0, epsilon = 1e-9);
        assert!(b.iter().all(|x| (0.0..180.0).contains(x)));
    }

    #[test]
    fn many_edge_bearings_keep_the_longest_edges() {
        // A half disc of 2 000 short edges closed by one long diameter at
        // 30°: the slice direction, the diameter and its normal are kept,
        // and no more than MAX_BEARINGS in all.
        let (s, c) = 30f64.to_radians().sin_cos();
        let ring: Vec<Coord<f64>> = (0..=2000)
            .map(|k| {
                let a = std::f64::consts::PI * f64::from(k) / 2000.0;
                let (x, y) = (500.0 * a.cos(), 500.0 * a.sin());
                coord! { x: x * s - y * c, y: x * c + y * s }
            })
            .collect();
        let b = candidate_bearings(&ring, 7.0);
        assert_eq!(b.len(), MAX_BEARINGS);
        assert_abs_diff_eq!(b[0], 7.0, epsilon = 1e-9);
        for want in [30.0, 120.0] {
            assert!(b.iter().any(|x| (x - want).abs() < 1e-6), "{want} in {b:?}");
        }
        let plan = plan_cell(
            0,
            &Polygon::new(LineString(ring.clone()), vec![]),
            &MultiPolygon(vec![Polygon::new(LineString(ring), vec![])]),
            25.0,
            7.0,
        )
        .expect("a plan");
        assert!(!plan.lanes.is_empty());
    }

    #[test]
    fn indexed_free_space_gives_identical_plans() {
        // Many NFZs (some overlapping each other or the ROI border): every
        // cell's plan and every re-orientation must be exactly the same
        // with the R-tree as with a scan over all free-space edges.
        let free = super::super::region::tests::field_with_nfzs(120);
        let indexed = FreeSpace::new(&free);
        let plain = FreeSpace::unindexed(&free);
        let (mut plans, mut routed) = (0, 0);
        for angle in [0.0, 37.0, 90.0] {
            let cells = crate::decompose::decompose(&free, angle).unwrap();
            assert!(cells.len() > 100, "{}", cells.len());
            for (i, cell) in cells.iter().enumerate() {
                for spacing in [9.0, 27.0] {
                    let want = plan_cell_in(i, cell, &plain, spacing, angle);
                    let got = plan_cell_in(i, cell, &indexed, spacing, angle);
                    assert_eq!(got, want, "cell {i} at {angle}°, spacing {spacing}");
                    let Some(plan) = want else { continue };
                    plans += 1;
                    routed += plan.links.iter().filter(|l| !l.is_empty()).count();
                    for (rev, flip) in [(false, true), (true, false), (true, true)] {
                        assert_eq!(
                            plan.reoriented_in(rev, flip, cell, &indexed),
                            plan.reoriented_in(rev, flip, cell, &plain),
                            "cell {i} at {angle}°: {rev} {flip}"
                        );
                    }
                }
            }
        }
        // The field exercises the interesting paths: many plans, and links
        // that had to be routed round something.
        assert!(
            plans > 500 && routed > 10,
            "{plans} plans, {routed} routed links"
        );
        // The convenience entry point agrees too.
        let cells = crate::decompose::decompose(&free, 0.0).unwrap();
        for (i, cell) in cells.iter().enumerate().step_by(17) {
            assert_eq!(
                plan_cell(i, cell, &free, 27.0, 0.0),
                plan_cell_in(i, cell, &indexed, 27.0, 0.0)
            );
        }
    }

    /// Every one-lane cell of a decomposition among many small NFZs, at
    /// several slice angles, is laid out with no turn (the shortcut the
    /// `auto` angle takes is exact), and wider cells are not taken for one.
    #[test]
    fn one_lane_cells_need_no_turn() {
        let square = poly(&[(0.0, 0.0), (600.0, 0.0), (600.0, 600.0), (0.0, 600.0)]);
        let mut rng = crate::test_rng::Lcg(7);
        let mut next = || rng.next();
        let zones: Vec<Polygon<f64>> = (0..60)
            .map(|_| {
                let (cx, cy, r) = (
                    40.0 + 520.0 * next(),
                    40.0 + 520.0 * next(),
                    2.0 + 8.0 * next(),
                );
                let ring: Vec<(f64, f64)> = (0..6)
                    .map(|k| {
                        let t = std::f64::consts::PI * k as f64 / 3.0;
                        (cx + r * t.cos(), cy + r * t.sin())
                    })
                    .collect();
                poly(&ring)
            })
            .collect();
        let free = crate::decompose::free_space(&square, &zones);
        let (mut one, mut wide) = (0, 0);
        for angle in [0.0, 15.0, 90.0, 137.0] {
            for spacing in [30.0, 80.0] {
                let cells = crate::decompose::decompose(&free, angle).unwrap();
                for (i, c) in cells.iter().enumerate() {
                    let turns = CellLayouts::new(i, c, spacing, angle).map_or(0, |l| l.turns());
                    if is_one_lane(c, spacing, angle) {
                        one += 1;
                        assert_eq!(turns, 0, "cell {i} at {angle}° and {spacing} m");
                    } else {
                        wide += 1;
                    }
                }
            }
        }
        assert!(one > 100 && wide > 10, "{one} one-lane cells, {wide} wider");
    }
}
