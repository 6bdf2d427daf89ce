//! Corridor scans: the flat-capped buffer of a centre line (the corridor's
//! area) and its lanes, offset curves of the line at the survey's spacing,
//! cut by the free space and grouped into cells flown back and forth.
//!
//! A lane is a polyline; it is flown as consecutive [`Lane`]s that join end
//! to start with no link points (a *run*, see [`CellPlan::runs`]), so every
//! later stage (links, tours, splitting, missions, coverage) works on
//! straight segments as it does for areas.

use geo::algorithm::buffer::{Buffer, BufferStyle, LineCap, LineJoin};
use geo::{Area, BooleanOps, Simplify};
use geo_types::{Coord, LineString, MultiLineString, MultiPolygon, Polygon};

use super::links::LinkRouter;
use super::region::{FreeSpace, Region, closest_on_segment, dist};
use super::{CellPlan, Lane};

/// Step of the round joins of the corridor polygon, radians (as
/// `L / R`, i_overlay's measure): 0.1 follows an arc within 0.13 % of its
/// radius, about shapely's default of 16 segments per quarter circle.
pub const POLYGON_ARC_STEP_RAD: f64 = 0.1;
/// Step of the arcs lanes fly round outer bends: coarser (20°) to keep the
/// waypoints few; a chord falls 1.5 % of the offset inside its arc, well
/// within the footprint's overlap.
const LANE_ARC_STEP_RAD: f64 = 0.35;
/// Lane pieces shorter than this (m) are not flown: slivers cut off by a
/// no-fly zone's corner.
const MIN_PIECE_M: f64 = 0.1;
/// Lanes are drawn with vertices dropped while they stay this close (m)
/// to the offset curve (Ramer–Douglas–Peucker): a road digitised every few
/// metres would otherwise give a waypoint (and a camera trigger) for each.
const LANE_SIMPLIFY_M: f64 = 0.25;
/// Buffer parts and holes smaller than this (m²) are overlay slivers.
const SLIVER_M2: f64 = 1e-3;
/// Lane vertices closer than this (m) are merged.
const MIN_SEGMENT_M: f64 = 0.01;
/// Gaps shorter than this (m) between two pieces of one lane are flown
/// through: where a lane grazes the round keep-out area of a no-fly zone,
/// the overlay cuts it for a few millimetres (as deep as a micrometre),
/// which would otherwise become two cells and a transit of millimetres.
const GRAZE_GAP_M: f64 = 0.005;
/// Most lanes across one corridor (width / spacing).
pub const MAX_CORRIDOR_LANES: usize = 2000;

/// Why a corridor's lanes cannot be laid.
#[derive(Debug, thiserror::Error)]
pub enum CorridorError {
    #[error(
        "the line bends back on itself within the corridor width ({width_m} m): its offset \
         at {offset_m:.1} m is not one curve from end to end; widen the bends or narrow the \
         corridor"
    )]
    TooTight { width_m: f64, offset_m: f64 },
    #[error("the corridor needs {0} lanes across, more than {MAX_CORRIDOR_LANES}")]
    TooManyLanes(usize),
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
}

/// The corridor's area: `centre` buffered by `width_m / 2` with flat
/// (butt) caps at both ends and round joins at the bends. The buffer is
/// computed by i_overlay, which resolves the overlaps at inner bends, so
/// the outline never crosses itself.
pub fn corridor_polygon(centre: &LineString<f64>, width_m: f64) -> MultiPolygon<f64> {
    stroke(centre, width_m / 2.0, POLYGON_ARC_STEP_RAD)
}

fn stroke(line: &LineString<f64>, half_width: f64, arc_step: f64) -> MultiPolygon<f64> {
    let raw = line.buffer_with_style(
        BufferStyle::new(half_width)
            .line_cap(LineCap::Butt)
            .line_join(LineJoin::Round(arc_step)),
    );
    // The overlay leaves slivers of a few square micrometres where nearly
    // collinear segments meet (a road of thousands of vertices): not area.
    let real =
        |ring: &LineString<f64>| Polygon::new(ring.clone(), vec![]).unsigned_area() > SLIVER_M2;
    MultiPolygon(
        raw.0
            .into_iter()
            .filter(|p| real(p.exterior()))
            .map(|p| {
                let (exterior, holes) = p.into_inner();
                Polygon::new(exterior, holes.into_iter().filter(|h| real(h)).collect())
            })
            .collect(),
    )
}

/// Signed offsets of the lanes across a corridor `width_m` wide (positive
/// to the left of the line's direction): as few lanes as keep them at most
/// `spacing_m` apart, spread evenly so that each covers an equal band and
/// the outermost lie half a band inside the edges.
pub fn lane_offsets(width_m: f64, spacing_m: f64) -> Vec<f64> {
    let n = lane_count(width_m, spacing_m);
    let band = width_m / n as f64;
    (0..n)
        .map(|k| -width_m / 2.0 + (k as f64 + 0.5) * band)
        .collect()
}

fn lane_count(width_m: f64, spacing_m: f64) -> usize {
    // A width of exactly k spacings, after rounding, needs k lanes.
    ((width_m / spacing_m - 1e-9).ceil() as usize).max(1)
}

/// The offset curve of `centre` at `offset` metres (positive: left), from
/// the start cap to the end cap: the points at that distance on that side,
/// found as one side of the line's flat-capped buffer at `|offset|`.
/// `None` when that side is not one curve (the line comes back within
/// `2·|offset|` of itself, closing the buffer round a hole or over a cap).
pub fn offset_curve(centre: &LineString<f64>, offset: f64) -> Option<LineString<f64>> {
    let line = &centre.0;
    if line.len() < 2 {
        return None;
    }
    if offset.abs() < 1e-9 {
        return Some(centre.clone());
    }
    let d = offset.abs();
    let buffer = stroke(centre, d, LANE_ARC_STEP_RAD);
    let [poly] = buffer.0.as_slice() else {
        return None;
    };
    if !poly.interiors().is_empty() {
        return None;
    }
    let mut ring = poly.exterior().0.clone();
    ring.pop(); // closed: the last repeats the first
    let extent = ring
        .iter()
        .fold(0.0f64, |m, c| m.max(c.x.abs()).max(c.y.abs()));
    let tol = (extent * 1e-9).max(1e-4);
    let n = line.len();
    let caps = [(line[0], unit(line[1] - line[0])), {
        let t = unit(line[n - 1] - line[n - 2]);
        (line[n - 1], t)
    }];
    let on_cap = |v: Coord<f64>, (p, t): (Coord<f64>, Coord<f64>)| {
        let r = v - p;
        dot(r, t).abs() <= tol && dist(v, p) <= d + tol
    };
    let is_cap_edge =
        |a: Coord<f64>, b: Coord<f64>| caps.iter().any(|&cap| on_cap(a, cap) && on_cap(b, cap));
    let m = ring.len();
    let cut = (0..m).find(|&i| is_cap_edge(ring[i], ring[(i + 1) % m]))?;
    // Walk the ring from just after a cap edge, splitting at cap edges.
    let mut chains: Vec<Vec<Coord<f64>>> = Vec::new();
    let mut current = vec![ring[(cut + 1) % m]];
    for k in 1..=m {
        let a = ring[(cut + k) % m];
        let b = ring[(cut + k + 1) % m];
        if is_cap_edge(a, b) {
            if current.len() > 1 {
                chains.push(std::mem::take(&mut current));
            }
            current = vec![b];
        } else {
            current.push(b);
        }
    }
    if chains.len() != 2 {
        return None;
    }
    let (p0, t0) = caps[0];
    let want_left = offset > 0.0;
    let mut found = None;
    for mut chain in chains {
        // From the start cap to the end cap.
        let (first, last) = (chain[0], chain[chain.len() - 1]);
        if !on_cap(first, caps[0]) {
            if !on_cap(last, caps[0]) {
                return None;
            }
            chain.reverse();
        }
        let left = cross(t0, chain[0] - p0) > 0.0;
        if left == want_left {
            found = Some(LineString::new(chain));
        }
    }
    found
}

fn unit(v: Coord<f64>) -> Coord<f64> {
    let len = v.x.hypot(v.y);
    if len > 0.0 { v / len } else { v }
}

fn dot(a: Coord<f64>, b: Coord<f64>) -> f64 {
    a.x * b.x + a.y * b.y
}

fn cross(a: Coord<f64>, b: Coord<f64>) -> f64 {
    a.x * b.y - a.y * b.x
}

/// The parts of `line` inside `region`, in the line's direction.
fn clip_polyline(line: &[Coord<f64>], region: &Region) -> Vec<Vec<Coord<f64>>> {
    let mut pieces: Vec<Vec<Coord<f64>>> = Vec::new();
    let mut open = false;
    for w in line.windows(2) {
        let len = dist(w[0], w[1]);
        if len <= 0.0 {
            continue;
        }
        let d = (w[1] - w[0]) / len;
        let intervals = region.intervals(w[0], d, 0.0, len);
        for (k, &(a, b)) in intervals.iter().enumerate() {
            let (pa, pb) = (w[0] + d * a, w[0] + d * b);
            let continues = open && k == 0 && a <= 1e-6;
            let grazed = pieces
                .last()
                .and_then(|p| p.last())
                .is_some_and(|&end| dist(end, pa) < GRAZE_GAP_M);
            match pieces.last_mut() {
                Some(piece) if continues => piece.push(pb),
                Some(piece) if grazed => {
                    // Within one segment the piece's end is no vertex: the
                    // lane goes straight on through the graze.
                    if k > 0 {
                        piece.pop();
                    }
                    piece.push(pb);
                }
                _ => pieces.push(vec![pa, pb]),
            }
        }
        open = intervals.last().is_some_and(|&(_, b)| b >= len - 1e-6);
    }
    for piece in &mut pieces {
        // Vertices a centimetre apart are one waypoint (the missions
        // write one), so one segment of the lane.
        let last = piece[piece.len() - 1];
        piece.dedup_by(|b, a| dist(*a, *b) < MIN_SEGMENT_M);
        if piece.len() > 1 && dist(piece[piece.len() - 1], last) > 0.0 {
            let n = piece.len();
            piece[n - 1] = last;
        }
    }
    pieces.retain(|p| p.windows(2).map(|w| dist(w[0], w[1])).sum::<f64>() >= MIN_PIECE_M);
    pieces
}

/// Position along the centre line (m from its start) of the point of the
/// line closest to `p`.
fn station(centre: &[Coord<f64>], cumulative: &[f64], p: Coord<f64>) -> f64 {
    let mut best = (f64::INFINITY, 0.0);
    for (i, w) in centre.windows(2).enumerate() {
        let (q, _) = closest_on_segment(p, w[0], w[1]);
        let d = dist(p, q);
        if d < best.0 {
            best = (d, cumulative[i] + dist(w[0], q));
        }
    }
    best.1
}

/// One stretch of one lane inside the free space.
#[derive(Clone, Debug)]
struct Piece {
    points: Vec<Coord<f64>>,
    /// Stations of its ends along the centre line, `from <= to`.
    from: f64,
    to: f64,
}

impl Piece {
    fn overlaps(&self, other: &Piece) -> bool {
        self.from.max(other.from) < self.to.min(other.to)
    }
}

/// A corridor's cells and the back-and-forth plan of each (`plans[i]`
/// covers `cells[i]`).
pub struct CorridorCells {
    pub cells: Vec<Polygon<f64>>,
    pub plans: Vec<CellPlan>,
}

/// The corridor along `centre`, `width_m` wide, laid with lanes at most
/// `spacing_m` apart inside `free` (the flyable space, prepared as
/// `free_space`), grouped into cells: a cell takes the pieces of
/// neighbouring lanes that overlap one another alone along the line, the
/// boustrophedon rule in the corridor's own frame (along, across), so
/// every cell is flown back and forth from its first lane to its last.
pub fn corridor_cells(
    centre: &LineString<f64>,
    width_m: f64,
    spacing_m: f64,
    free: &MultiPolygon<f64>,
    free_space: &FreeSpace,
) -> Result<CorridorCells, CorridorError> {
    let n = lane_count(width_m, spacing_m);
    if n > MAX_CORRIDOR_LANES {
        return Err(CorridorError::TooManyLanes(n));
    }
    let line = &centre.0;
    let mut cumulative = vec![0.0];
    for w in line.windows(2) {
        cumulative.push(cumulative.last().copied().unwrap_or(0.0) + dist(w[0], w[1]));
    }
    let mut lanes: Vec<Vec<Piece>> = Vec::with_capacity(n);
    for offset in lane_offsets(width_m, spacing_m) {
        crate::cancel::check()?;
        let curve = offset_curve(centre, offset)
            .ok_or(CorridorError::TooTight {
                width_m,
                offset_m: offset,
            })?
            .simplify(LANE_SIMPLIFY_M);
        let mut pieces: Vec<Piece> = clip_polyline(&curve.0, free_space.region())
            .into_iter()
            .map(|points| {
                let a = station(line, &cumulative, points[0]);
                let b = station(line, &cumulative, points[points.len() - 1]);
                Piece {
                    points,
                    from: a.min(b),
                    to: a.max(b),
                }
            })
            .collect();
        pieces.sort_by(|a, b| a.from.total_cmp(&b.from));
        lanes.push(pieces);
    }
    let groups = group_pieces(&lanes);
    let band = width_m / n as f64;
    let bearing = {
        let (a, b) = (line[0], line[line.len() - 1]);
        (b.x - a.x).atan2(b.y - a.y).to_degrees().rem_euclid(180.0)
    };
    let mut out = CorridorCells {
        cells: Vec::new(),
        plans: Vec::new(),
    };
    for group in groups {
        crate::cancel::check()?;
        let pieces: Vec<&Piece> = group.iter().map(|&(k, i)| &lanes[k][i]).collect();
        let Some(cell) = cell_polygon(&pieces, band, free) else {
            continue;
        };
        let index = out.cells.len();
        let lanes = flight_lanes(&pieces);
        let links = LinkRouter::new(&cell, free_space).links(&lanes);
        crate::cancel::check()?;
        out.cells.push(cell);
        out.plans.push(CellPlan {
            cell_index: index,
            direction_deg: if bearing >= 180.0 - 1e-9 {
                0.0
            } else {
                bearing
            },
            lanes,
            links,
        });
    }
    Ok(out)
}

/// Cells as lists of (lane, piece) in lane order: a piece continues the
/// cell of the piece before it across when each is the other's only
/// overlapping neighbour; otherwise (the corridor splits or joins round a
/// no-fly zone) it starts a cell.
fn group_pieces(lanes: &[Vec<Piece>]) -> Vec<Vec<(usize, usize)>> {
    let mut groups: Vec<Vec<(usize, usize)>> = Vec::new();
    let mut group_of: Vec<Vec<usize>> = lanes.iter().map(|l| vec![0; l.len()]).collect();
    for k in 0..lanes.len() {
        for i in 0..lanes[k].len() {
            let p = &lanes[k][i];
            let joined = k.checked_sub(1).and_then(|prev| {
                let below: Vec<usize> = (0..lanes[prev].len())
                    .filter(|&j| lanes[prev][j].overlaps(p))
                    .collect();
                let &[j] = below.as_slice() else {
                    return None;
                };
                let q = &lanes[prev][j];
                let alone = lanes[k].iter().filter(|o| o.overlaps(q)).count() == 1;
                alone.then_some(group_of[prev][j])
            });
            let g = joined.unwrap_or_else(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[g].push((k, i));
            group_of[k][i] = g;
        }
    }
    groups
}

/// The cell a group of pieces covers: each piece's band (`band` wide, a
/// little more so that neighbouring bands overlap) within the free space;
/// the largest part when the free space cuts it.
fn cell_polygon(pieces: &[&Piece], band: f64, free: &MultiPolygon<f64>) -> Option<Polygon<f64>> {
    let strips: MultiPolygon<f64> = MultiPolygon(
        pieces
            .iter()
            .flat_map(|p| {
                stroke(
                    &LineString::new(p.points.clone()),
                    band * 0.51,
                    LANE_ARC_STEP_RAD,
                )
                .0
            })
            .collect(),
    );
    let united = crate::overlay::unary_union(strips.0.iter());
    united
        .intersection(free)
        .0
        .into_iter()
        .max_by(|a, b| a.unsigned_area().total_cmp(&b.unsigned_area()))
}

/// The segments flown, back and forth: the first piece from its start
/// station to its end, the next the other way, and so on.
fn flight_lanes(pieces: &[&Piece]) -> Vec<Lane> {
    let mut lanes = Vec::new();
    let mut forward = true;
    for p in pieces {
        let mut pts = p.points.clone();
        // Pieces come in their lane's direction, which runs with the line.
        if !forward {
            pts.reverse();
        }
        lanes.extend(pts.windows(2).filter(|w| w[0] != w[1]).map(|w| Lane {
            start: w[0],
            end: w[1],
        }));
        forward = !forward;
    }
    lanes
}

/// Every lane of `centre`'s corridor clipped to `free`, as lines: what
/// the cells' plans fly, for checks.
pub fn corridor_lane_lines(
    centre: &LineString<f64>,
    width_m: f64,
    spacing_m: f64,
    free: &MultiPolygon<f64>,
) -> Option<MultiLineString<f64>> {
    let region = FreeSpace::new(free);
    let mut out = Vec::new();
    for offset in lane_offsets(width_m, spacing_m) {
        let curve = offset_curve(centre, offset)?.simplify(LANE_SIMPLIFY_M);
        out.extend(
            clip_polyline(&curve.0, region.region())
                .into_iter()
                .map(LineString::new),
        );
    }
    Some(MultiLineString(out))
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::{coord, line_string, polygon};

    fn l_line() -> LineString<f64> {
        // Along x for 300 m, then a right-angle bend up for 200 m.
        line_string![(x: 0.0, y: 0.0), (x: 300.0, y: 0.0), (x: 300.0, y: 200.0)]
    }

    fn min_dist_to_line(p: Coord<f64>, line: &LineString<f64>) -> f64 {
        line.0
            .windows(2)
            .map(|w| dist(p, closest_on_segment(p, w[0], w[1]).0))
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn polygon_is_the_flat_capped_buffer() {
        let p = corridor_polygon(&l_line(), 40.0);
        assert_eq!(p.0.len(), 1);
        // Straight parts 20 m each side, a quarter disc of radius 20 at
        // the outer corner, the inner corner's overlap counted once:
        // 300·40 + 200·40 − 20·20 (double counted square) + π·20²/4.
        let want = 300.0 * 40.0 + 200.0 * 40.0 - 400.0 + std::f64::consts::PI * 100.0;
        let got = p.unsigned_area();
        // The arc's chords cut 0.1 % of the quarter disc at most.
        assert!((got - want).abs() < 1.0, "{got} vs {want}");
        // Flat caps: nothing beyond x < 0 or y > 200.
        for c in p.0[0].exterior().0.iter() {
            assert!(c.x >= -1e-6 && c.y <= 200.0 + 1e-6, "{c:?}");
        }
    }

    #[test]
    fn a_long_wiggly_road_gives_one_curve_per_offset() {
        // 20 km along x, 2 000 vertices on a sine 222 m high (bends of
        // 765 m radius): the overlay's slivers at the nearly straight joins
        // must not count as parts of the buffer.
        let line = LineString::new(
            (0..2000)
                .map(|i| coord! {x: i as f64 * 10.3, y: 222.0 * (i as f64 / 40.0).sin()})
                .collect(),
        );
        let p = corridor_polygon(&line, 200.0);
        assert_eq!(p.0.len(), 1);
        assert!(p.0[0].interiors().is_empty());
        for o in lane_offsets(200.0, 25.0) {
            let c = offset_curve(&line, o).unwrap_or_else(|| panic!("offset {o}"));
            assert!(c.0.len() >= 2000 / 2, "{o}: {} vertices", c.0.len());
        }
    }

    #[test]
    fn a_lane_grazing_a_zone_by_millimetres_is_not_cut() {
        let line = [coord! {x: 0.0, y: 0.0}, coord! {x: 100.0, y: 0.0}];
        let free_with_tip = |tip_y: f64| {
            let field = polygon![(x: -10.0, y: -10.0), (x: 110.0, y: -10.0), (x: 110.0, y: 10.0), (x: -10.0, y: 10.0)];
            let zone = polygon![(x: 45.0, y: 5.0), (x: 50.0, y: tip_y), (x: 55.0, y: 5.0)];
            let free = MultiPolygon(vec![field]).difference(&MultiPolygon(vec![zone]));
            Region::from_multi_polygon(&free)
        };
        // The zone's tip 1 mm across the lane: a 2 mm gap, flown through.
        let pieces = clip_polyline(&line, &free_with_tip(-0.001));
        assert_eq!(pieces.len(), 1, "{pieces:?}");
        assert_eq!(pieces[0].len(), 2, "no vertex at the graze: {pieces:?}");
        // 1 m across: a gap of 5/6·2 m, two pieces that stop at the zone.
        let pieces = clip_polyline(&line, &free_with_tip(-1.0));
        assert_eq!(pieces.len(), 2, "{pieces:?}");
        let gap = (pieces[0][1].x, pieces[1][0].x);
        assert!((gap.0 - (50.0 - 5.0 / 6.0)).abs() < 1e-6, "{gap:?}");
        assert!((gap.1 - (50.0 + 5.0 / 6.0)).abs() < 1e-6, "{gap:?}");
    }

    #[test]
    fn offsets_split_the_width_evenly() {
        let o = lane_offsets(100.0, 30.0);
        assert_eq!(o.len(), 4);
        assert!((o[0] + 37.5).abs() < 1e-9 && (o[3] - 37.5).abs() < 1e-9);
        assert_eq!(lane_offsets(90.0, 30.0).len(), 3);
        assert_eq!(lane_offsets(10.0, 30.0), vec![0.0]);
    }

    #[test]
    fn offset_curves_keep_their_distance_and_run_cap_to_cap() {
        let line = l_line();
        for offset in [-15.0, -5.0, 5.0, 15.0] {
            let c = offset_curve(&line, offset).unwrap();
            // Every vertex at |offset| from the line (1 mm: the overlay's grid).
            for &v in &c.0 {
                let d = min_dist_to_line(v, &line);
                assert!((d - offset.abs()).abs() < 1e-3, "{offset}: {v:?} at {d}");
            }
            // Starts on the start cap on its side, ends on the end cap.
            let (a, b) = (c.0[0], c.0[c.0.len() - 1]);
            assert!(a.x.abs() < 1e-3 && (a.y - offset).abs() < 1e-3, "{a:?}");
            assert!(
                (b.y - 200.0).abs() < 1e-3 && (b.x - (300.0 - offset)).abs() < 1e-3,
                "{b:?}"
            );
        }
        // The left (inner) side of the right-hand bend is cut at the
        // corner: one vertex there, (300 − 15, 15).
        let c = offset_curve(&line, 15.0).unwrap();
        assert!(
            c.0.iter()
                .any(|v| dist(*v, coord! {x: 285.0, y: 15.0}) < 1e-3)
        );
        // A hairpin narrower than the offsets: no single curve.
        let hairpin = line_string![(x: 0.0, y: 0.0), (x: 300.0, y: 0.0), (x: 300.0, y: 10.0), (x: 0.0, y: 10.0)];
        assert!(offset_curve(&hairpin, 20.0).is_none());
    }

    #[test]
    fn lanes_cover_the_corridor_and_split_round_a_crossing_zone() {
        let line = l_line();
        let width = 60.0;
        let area = corridor_polygon(&line, width);
        // A zone right across the first leg, x in [100, 140].
        let nfz = polygon![(x: 100.0, y: -50.0), (x: 140.0, y: -50.0), (x: 140.0, y: 50.0), (x: 100.0, y: 50.0)];
        let free = area.difference(&MultiPolygon(vec![nfz]));
        let fs = FreeSpace::new(&free);
        let c = corridor_cells(&line, width, 25.0, &free, &fs).unwrap();
        // Three lanes across; the zone cuts every lane: two cells.
        assert_eq!(c.cells.len(), 2, "{:?}", c.cells);
        let swath = 30.0; // a footprint wider than the spacing
        let lanes: Vec<Lane> = c.plans.iter().flat_map(|p| p.lanes.clone()).collect();
        let ratio = crate::coverage::coverage_ratio(&lanes, swath, &free);
        assert!(ratio > 0.995, "{ratio}");
        for plan in &c.plans {
            // Three runs of lanes, one per lane piece, back and forth.
            assert_eq!(plan.runs().len(), 3);
            for lane in &plan.lanes {
                for p in [lane.start, lane.end] {
                    assert!(
                        !(p.x > 100.0 + 1e-6 && p.x < 140.0 - 1e-6 && p.y < 50.0),
                        "{p:?}"
                    );
                }
            }
            // Links between runs are straight, across the cut or the cap.
            assert!(plan.links.iter().all(Vec::is_empty));
        }
        // A zone on one side only: the far lanes go on, the near one is cut.
        let side = polygon![(x: 100.0, y: -50.0), (x: 140.0, y: -50.0), (x: 140.0, y: -5.0), (x: 100.0, y: -5.0)];
        let free = area.difference(&MultiPolygon(vec![side]));
        let fs = FreeSpace::new(&free);
        let c = corridor_cells(&line, width, 25.0, &free, &fs).unwrap();
        assert_eq!(c.cells.len(), 3, "{:?}", c.plans);
        let lines = corridor_lane_lines(&line, width, 25.0, &free).unwrap();
        assert_eq!(lines.0.len(), 4);
    }
}
