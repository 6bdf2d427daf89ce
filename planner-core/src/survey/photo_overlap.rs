//! The overlap and GSD the photos achieve on the ground, per cell: front
//! overlap between consecutive photos of a lane, side overlap with the
//! photos of the neighbouring lanes, each measured on the footprints along
//! a line through the photo's centre; so a pilot sees where the terrain
//! (or a cell's shape) lets the overlap drop below the requested one.

use std::collections::HashMap;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::result::{CellOut, UavPlan};

/// Lanes whose bearings differ by less than this belong to one set
/// (a crosshatch's two sets are told apart by it), degrees.
const SAME_DIRECTION_DEG: f64 = 1.0;
/// At most this many photos of a cell are measured for side overlap (a
/// regular subset beyond): a survey of a million photos stays quick.
const MAX_SIDE_PHOTOS: usize = 20_000;

/// The overlaps and GSD a cell's photos achieve on the ground. Overlaps
/// are fractions; `None` where there is nothing to measure (a lane of one
/// photo has no front overlap, a cell of one lane no side overlap).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellPhotos {
    /// Photos taken over the cell (by every UAV flying it).
    pub photos: usize,
    pub front_overlap_min: Option<f64>,
    pub front_overlap_median: Option<f64>,
    pub side_overlap_min: Option<f64>,
    pub side_overlap_median: Option<f64>,
    /// Ground sample distance at the image centres, cm/px.
    pub gsd_cm_px_min: f64,
    pub gsd_cm_px_median: f64,
}

impl CellPhotos {
    /// The figures as GeoJSON properties (of the cell's Feature).
    pub(super) fn add_properties(&self, props: &mut serde_json::Map<String, serde_json::Value>) {
        let mut put = |k: &str, v: serde_json::Value| {
            props.insert(k.to_string(), v);
        };
        put("photos", self.photos.into());
        put("front_overlap_min", self.front_overlap_min.into());
        put("front_overlap_median", self.front_overlap_median.into());
        put("side_overlap_min", self.side_overlap_min.into());
        put("side_overlap_median", self.side_overlap_median.into());
        put("gsd_cm_px_min", self.gsd_cm_px_min.into());
        put("gsd_cm_px_median", self.gsd_cm_px_median.into());
    }
}

/// A photo as the measures need it: its footprint on the ground (2D) and
/// the GSD at its centre.
struct Shot {
    centre: [f64; 2],
    quad: [[f64; 2]; 4],
    gsd: f64,
}

/// The photos of one lane, with the lane's unit direction.
struct LaneShots {
    dir: [f64; 2],
    shots: Vec<Shot>,
}

/// Fills in each cell's [`CellPhotos`] from the photos the `uavs` take.
pub(super) fn fill(cells: &mut [CellOut], uavs: &[UavPlan]) {
    let mut by_cell: HashMap<usize, Vec<LaneShots>> = HashMap::new();
    for s in uavs.iter().flat_map(|u| &u.sorties) {
        let Some(photos) = &s.photos else {
            continue;
        };
        let mut lane: Option<(usize, usize, LaneShots)> = None;
        for p in photos.photos() {
            if lane.as_ref().is_none_or(|(i, _, _)| *i != p.lane) {
                if let Some((_, cell, shots)) = lane.take() {
                    by_cell.entry(cell).or_default().push(shots);
                }
                let h = p.heading_deg.to_radians();
                lane = Some((
                    p.lane,
                    p.cell,
                    LaneShots {
                        dir: [h.sin(), h.cos()],
                        shots: Vec::new(),
                    },
                ));
            }
            if let Some((_, _, l)) = lane.as_mut() {
                l.shots.push(Shot {
                    centre: [p.centre[0], p.centre[1]],
                    quad: p.corners.map(|c| [c[0], c[1]]),
                    gsd: p.gsd_cm_px(&photos.camera),
                });
            }
        }
        if let Some((_, cell, shots)) = lane {
            by_cell.entry(cell).or_default().push(shots);
        }
    }
    let figures: Vec<(usize, CellPhotos)> = by_cell
        .into_par_iter()
        .filter_map(|(cell, lanes)| Some((cell, measure(&lanes)?)))
        .collect();
    for (cell, f) in figures {
        // Cell ids are their indices.
        if let Some(c) = cells.get_mut(cell).filter(|c| c.id == cell) {
            c.photos = Some(f);
        }
    }
}

/// The figures of one cell's lanes; `None` without photos.
fn measure(lanes: &[LaneShots]) -> Option<CellPhotos> {
    let mut gsd: Vec<f64> = lanes
        .iter()
        .flat_map(|l| l.shots.iter().map(|s| s.gsd))
        .collect();
    if gsd.is_empty() {
        return None;
    }
    let mut front = Vec::new();
    for l in lanes {
        for w in l.shots.windows(2) {
            let Some((lo, hi)) = interval(&w[0].quad, w[0].centre, l.dir) else {
                continue;
            };
            let next = interval(&w[1].quad, w[0].centre, l.dir);
            let shared = next.map_or(0.0, |(a, b)| (hi.min(b) - lo.max(a)).max(0.0));
            front.push(ratio(shared, hi - lo));
        }
    }
    let side = side_overlaps(lanes);
    let (front_overlap_min, front_overlap_median) = min_median(front);
    let (side_overlap_min, side_overlap_median) = min_median(side);
    let photos = gsd.len();
    let (gsd_min, gsd_median) = min_median(std::mem::take(&mut gsd));
    Some(CellPhotos {
        photos,
        front_overlap_min,
        front_overlap_median,
        side_overlap_min,
        side_overlap_median,
        gsd_cm_px_min: gsd_min.unwrap_or(0.0),
        gsd_cm_px_median: gsd_median.unwrap_or(0.0),
    })
}

/// A lane of one set, placed across and along the set's direction.
struct Placed<'a> {
    lane: &'a LaneShots,
    /// Mean offset of its footprints' centres across the set's direction.
    offset: f64,
    /// Its shots' positions along the set's direction, sorted, with their
    /// indices.
    along: Vec<(f64, usize)>,
    /// The longest along-track reach of a footprint from its centre.
    reach: f64,
    /// The farthest a footprint reaches across from its centre.
    half_width: f64,
}

/// Side overlap samples: for every photo and each side with a
/// neighbouring lane's photo abeam (its footprint crossed by the line
/// through this photo's centre, across the lanes), the share of this
/// footprint's width on that line that the nearest such lanes' footprints
/// cover. In a cell of more than [`MAX_SIDE_PHOTOS`] photos only every
/// k-th photo (in flight order, k the least that keeps within it) is
/// measured.
fn side_overlaps(lanes: &[LaneShots]) -> Vec<f64> {
    let total: usize = lanes.iter().map(|l| l.shots.len()).sum();
    let stride = total.div_ceil(MAX_SIDE_PHOTOS).max(1);
    let mut first = Vec::with_capacity(lanes.len());
    let mut count = 0;
    for l in lanes {
        first.push(count);
        count += l.shots.len();
    }
    let mut out = Vec::new();
    let mut sets: Vec<([f64; 2], Vec<usize>)> = Vec::new();
    for (k, l) in lanes.iter().enumerate() {
        // Directions modulo 180°: a lane flown back is of the same set.
        match sets.iter_mut().find(|(d, _)| {
            let cos = (d[0] * l.dir[0] + d[1] * l.dir[1]).abs();
            cos >= SAME_DIRECTION_DEG.to_radians().cos()
        }) {
            Some((_, members)) => members.push(k),
            None => sets.push((l.dir, vec![k])),
        }
    }
    for (dir, members) in sets {
        let placed: Vec<Placed> = members
            .iter()
            .map(|&k| Placed::new(&lanes[k], dir))
            .collect();
        // The lanes by their place across: each photo looks only at the
        // lanes within reach of its footprint's width.
        let mut order: Vec<usize> = (0..placed.len()).collect();
        order.sort_by(|&a, &b| placed[a].offset.total_cmp(&placed[b].offset));
        let offsets: Vec<f64> = order.iter().map(|&k| placed[k].offset).collect();
        for (i, me) in placed.iter().enumerate() {
            let reach = 4.0 * me.half_width;
            let from = offsets.partition_point(|&o| o < me.offset - reach);
            let to = offsets.partition_point(|&o| o <= me.offset + reach);
            let near: Vec<&Placed> = order[from..to]
                .iter()
                .filter(|&&j| j != i)
                .map(|&j| &placed[j])
                .collect();
            for (n, shot) in me.lane.shots.iter().enumerate() {
                if (first[members[i]] + n) % stride == 0 {
                    out.extend(shot_side_overlaps(shot, me.offset, &near, dir));
                }
            }
        }
    }
    out
}

/// The side overlap samples of one photo (of a lane placed at `offset`)
/// with the lanes `near` it, at most one per side: the lanes on that side
/// (farther across than 5 % of its width, within twice it) up to a quarter
/// of its width beyond the nearest, when one of them has a photo abeam.
/// The window is anchored at the nearest lane even when that lane does
/// not reach abeam: a joined cell can wrap around a no-fly zone, and the
/// lane past the zone is not this photo's neighbour (no sample there, as
/// at the cell's edge).
fn shot_side_overlaps(shot: &Shot, offset: f64, near: &[&Placed], dir: [f64; 2]) -> Vec<f64> {
    let across = [-dir[1], dir[0]];
    let Some((lo, hi)) = interval(&shot.quad, shot.centre, across) else {
        return Vec::new();
    };
    let width = hi - lo;
    let a = dot(shot.centre, dir);
    let mut out = Vec::with_capacity(2);
    for sign in [1.0, -1.0] {
        let mut side: Vec<(f64, &Placed)> = near
            .iter()
            .map(|o| (sign * (o.offset - offset), *o))
            .filter(|(gap, _)| *gap > 0.05 * width && *gap <= 2.0 * width)
            .collect();
        side.sort_by(|x, y| x.0.total_cmp(&y.0));
        let mut covered: Vec<(f64, f64)> = Vec::new();
        let nearest = side.first().map(|s| s.0);
        let mut abeam = false;
        for (gap, other) in side {
            if nearest.is_some_and(|g| gap > g + 0.25 * width) {
                break;
            }
            let from = other.along.partition_point(|p| p.0 < a - other.reach);
            for &(b, k) in &other.along[from..] {
                if b > a + other.reach {
                    break;
                }
                let q = &other.lane.shots[k].quad;
                if let Some((s, e)) = interval(q, shot.centre, across) {
                    abeam = true;
                    if e.min(hi) > s.max(lo) {
                        covered.push((s.max(lo), e.min(hi)));
                    }
                }
            }
        }
        if abeam {
            out.push(ratio(union_length(&mut covered), width));
        }
    }
    out
}

impl<'a> Placed<'a> {
    /// `lane` placed across and along the unit direction `dir`.
    fn new(lane: &'a LaneShots, dir: [f64; 2]) -> Placed<'a> {
        let across = [-dir[1], dir[0]];
        let n = lane.shots.len().max(1) as f64;
        let offset = lane
            .shots
            .iter()
            .map(|s| dot(s.centre, across))
            .sum::<f64>()
            / n;
        let mut along: Vec<(f64, usize)> = lane
            .shots
            .iter()
            .enumerate()
            .map(|(i, s)| (dot(s.centre, dir), i))
            .collect();
        along.sort_by(|a, b| a.0.total_cmp(&b.0));
        let extent = |axis: [f64; 2]| {
            lane.shots
                .iter()
                .flat_map(|s| {
                    s.quad
                        .iter()
                        .map(move |q| dot(sub(*q, s.centre), axis).abs())
                })
                .fold(0.0, f64::max)
        };
        Placed {
            lane,
            offset,
            along,
            reach: extent(dir),
            half_width: extent(across),
        }
    }
}

/// Where the line through `origin` along the unit `dir` crosses `quad`: its
/// first and last points, as distances from `origin` along `dir`.
fn interval(quad: &[[f64; 2]; 4], origin: [f64; 2], dir: [f64; 2]) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for k in 0..4 {
        let (p, q) = (quad[k], quad[(k + 1) % 4]);
        let e = sub(q, p);
        let denom = cross(dir, e);
        if denom.abs() < 1e-12 {
            continue;
        }
        let w = sub(p, origin);
        let s = cross(w, dir) / denom;
        if (-1e-9..=1.0 + 1e-9).contains(&s) {
            let t = cross(w, e) / denom;
            lo = lo.min(t);
            hi = hi.max(t);
        }
    }
    (hi > lo).then_some((lo, hi))
}

/// Total length of the union of `pieces` (sorted in place).
fn union_length(pieces: &mut [(f64, f64)]) -> f64 {
    pieces.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut total = 0.0;
    let mut end = f64::NEG_INFINITY;
    for &(s, e) in pieces.iter() {
        let s = s.max(end);
        if e > s {
            total += e - s;
        }
        end = end.max(e);
    }
    total
}

fn ratio(part: f64, whole: f64) -> f64 {
    if whole > 0.0 {
        (part / whole).clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Least value and median (the mean of the middle two for an even count),
/// rounded to 1e-4.
fn min_median(mut v: Vec<f64>) -> (Option<f64>, Option<f64>) {
    if v.is_empty() {
        return (None, None);
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    };
    let r = |x: f64| (x * 1e4).round() / 1e4;
    (Some(r(v[0])), Some(r(median)))
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A nadir footprint `side` × `front` centred at (x, y), lanes north.
    fn shot(x: f64, y: f64, side: f64, front: f64) -> Shot {
        let (w, h) = (side / 2.0, front / 2.0);
        Shot {
            centre: [x, y],
            quad: [
                [x - w, y - h],
                [x + w, y - h],
                [x + w, y + h],
                [x - w, y + h],
            ],
            gsd: 2.0,
        }
    }

    #[test]
    fn a_regular_grid_has_its_nominal_overlaps() {
        // 150 × 100 m footprints, photos every 20 m, lanes 45 m apart:
        // 80 % front and 70 % side overlap; the middle lane flown back.
        let lanes: Vec<LaneShots> = (0..3)
            .map(|k| {
                let x = 45.0 * k as f64;
                let mut shots: Vec<Shot> = (0..10)
                    .map(|i| shot(x, 20.0 * i as f64, 150.0, 100.0))
                    .collect();
                let mut dir = [0.0, 1.0];
                if k == 1 {
                    shots.reverse();
                    dir = [0.0, -1.0];
                }
                LaneShots { dir, shots }
            })
            .collect();
        let f = measure(&lanes).unwrap();
        assert_eq!(f.photos, 30);
        assert_eq!(f.front_overlap_min, Some(0.8));
        assert_eq!(f.front_overlap_median, Some(0.8));
        assert_eq!(f.side_overlap_min, Some(0.7));
        assert_eq!(f.side_overlap_median, Some(0.7));
        assert_eq!(f.gsd_cm_px_min, 2.0);
        // A lane shifted 30 m further: 50 % side overlap on that side.
        let mut lanes = lanes;
        for s in &mut lanes[2].shots {
            for c in s.quad.iter_mut().chain(std::iter::once(&mut s.centre)) {
                c[0] += 30.0;
            }
        }
        let f = measure(&lanes).unwrap();
        // Samples: 0.7 on both sides of the first gap, 0.5 on both of the
        // second.
        assert_eq!(f.side_overlap_min, Some(0.5));
        assert_eq!(f.side_overlap_median, Some(0.6));
    }

    /// A cell wrapping around a no-fly zone: lanes 0–1 pass west of it,
    /// lanes 2–4 stop short of it (south), lanes 5–6 pass east. The
    /// photos of lane 1 beside the zone see lane 5 abeam 180 m away, but
    /// lane 2 is their neighbour and reaches no further: no side sample
    /// there (as at the cell's edge), not a sample of 0.
    #[test]
    fn a_lane_past_a_no_fly_zone_is_no_neighbour() {
        let lane = |k: usize, rows: std::ops::Range<usize>| LaneShots {
            dir: [0.0, 1.0],
            shots: rows
                .map(|i| shot(45.0 * k as f64, 20.0 * i as f64, 150.0, 100.0))
                .collect(),
        };
        let lanes: Vec<LaneShots> = (0..7)
            .map(|k| lane(k, if (2..5).contains(&k) { 0..3 } else { 0..12 }))
            .collect();
        let f = measure(&lanes).unwrap();
        assert_eq!(f.side_overlap_min, Some(0.7), "{f:?}");
        // Without the short lanes the cell is two strips 180 m apart,
        // each photo's footprint 150 m wide: no neighbour within reach
        // that overlaps, and lanes 1 and 5 are each other's nearest.
        let apart: Vec<LaneShots> = [0, 1, 5, 6].into_iter().map(|k| lane(k, 0..12)).collect();
        let f = measure(&apart).unwrap();
        assert_eq!(f.side_overlap_min, Some(0.0), "{f:?}");
    }

    #[test]
    fn intervals_and_unions() {
        let q = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]];
        assert_eq!(interval(&q, [1.0, 0.5], [1.0, 0.0]), Some((-1.0, 1.0)));
        assert_eq!(interval(&q, [5.0, 5.0], [1.0, 0.0]), None);
        assert_eq!(union_length(&mut [(0.0, 1.0), (0.5, 2.0), (3.0, 4.0)]), 3.0);
        assert_eq!(min_median(vec![3.0, 1.0, 2.0, 4.0]), (Some(1.0), Some(2.5)));
    }
}
