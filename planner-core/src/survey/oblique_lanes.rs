//! Lanes of an oblique survey lengthened at both ends by the footprint's
//! offset ahead of the camera: a camera pitched forward first sees the
//! ground that far beyond the lane's start, so the camera is started that
//! much earlier (and, as the flock may fly a cell either way, stopped that
//! much later), wherever the keep-out area round the no-fly zones allows.

use geo_types::Coord;

use super::cells::Decomposition;
use super::request::SurveyParams;
use crate::coverage::{self, CellPlan, Lane};
use crate::flock::ObstacleMap;

/// Shares of the offset tried, longest first, where the whole would come
/// too close to a no-fly zone.
const SHARES: [f64; 4] = [1.0, 0.75, 0.5, 0.25];

/// How far ahead of the camera the footprint of `params`' camera starts at
/// `altitude_m` over level ground, m (0 or less when it reaches behind).
pub(super) fn near_offset_m(params: &SurveyParams, altitude_m: f64) -> f64 {
    match params.camera_pitch_deg {
        Some(pitch) if pitch > coverage::NADIR_PITCH_DEG => {
            coverage::footprint_corners(&params.camera(), altitude_m, pitch)
                .map_or(0.0, |c| c[0][1].min(c[1][1]))
        }
        _ => 0.0,
    }
}

/// Lengthens the ends of every run of lanes of `d` by up to `offset_m`
/// (the footprint's near edge ahead of the camera), each end only as far
/// as the segment out to it stays clear of `obstacles`; the links between
/// lengthened lanes go straight where that is clear, else back along the
/// added stretch and the link as it was. Nothing changes for an offset of
/// 0 or less (a nadir camera, or a pitch whose image reaches behind it).
pub(super) fn lengthen_lanes(d: &mut Decomposition, offset_m: f64, obstacles: &ObstacleMap) {
    if offset_m <= 0.0 || !offset_m.is_finite() {
        return;
    }
    for plan in &mut d.plans {
        lengthen_plan(plan, offset_m, obstacles);
    }
}

fn lengthen_plan(plan: &mut CellPlan, offset_m: f64, obstacles: &ObstacleMap) {
    let old: Vec<Lane> = plan.lanes.clone();
    for run in plan.runs() {
        let (first, last) = (run.start, run.end - 1);
        let f = plan.lanes[first];
        plan.lanes[first].start = extended(f.start, f.end, offset_m, obstacles);
        let l = plan.lanes[last];
        plan.lanes[last].end = extended(l.end, l.start, offset_m, obstacles);
    }
    for (k, link) in plan.links.iter_mut().enumerate() {
        let (from, to) = (plan.lanes[k].end, plan.lanes[k + 1].start);
        let (old_from, old_to) = (old[k].end, old[k + 1].start);
        if (from, to) == (old_from, old_to) {
            continue;
        }
        if obstacles.is_clear(from, to) {
            link.clear();
            continue;
        }
        let mut path = Vec::with_capacity(link.len() + 2);
        path.push(old_from);
        path.append(link);
        path.push(old_to);
        path.dedup();
        path.retain(|&p| p != from && p != to);
        *link = path;
    }
}

/// `end` moved away from `other` (the lane's other end) by the longest of
/// the [`SHARES`] of `by` whose added stretch keeps clear of `obstacles`.
fn extended(end: Coord<f64>, other: Coord<f64>, by: f64, obstacles: &ObstacleMap) -> Coord<f64> {
    let d = end - other;
    let len = d.x.hypot(d.y);
    if len <= 0.0 {
        return end;
    }
    let u = d / len;
    SHARES
        .iter()
        .map(|s| end + u * (s * by))
        .find(|&p| obstacles.is_clear(end, p) && !obstacles.contains_point(p))
        .unwrap_or(end)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::{LineString, Polygon, coord};

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Polygon<f64> {
        Polygon::new(
            LineString::from(vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]),
            vec![],
        )
    }

    #[test]
    fn ends_grow_until_a_zone_and_links_stay_clear() {
        // Two lanes north and back; a zone 6 m beyond the first lane's
        // start, none elsewhere.
        let zone = square(-5.0, -20.0, 5.0, -6.0);
        let obstacles = ObstacleMap::new(&geo_types::MultiPolygon(vec![zone]), 0.0);
        let mut plan = CellPlan {
            cell_index: 0,
            direction_deg: 0.0,
            lanes: vec![
                Lane {
                    start: coord! {x: 0.0, y: 0.0},
                    end: coord! {x: 0.0, y: 100.0},
                },
                Lane {
                    start: coord! {x: 30.0, y: 100.0},
                    end: coord! {x: 30.0, y: 0.0},
                },
            ],
            links: vec![vec![]],
        };
        lengthen_plan(&mut plan, 10.0, &obstacles);
        // The first start: only half of the 10 m keeps clear of the zone.
        assert_eq!(plan.lanes[0].start, coord! {x: 0.0, y: -5.0});
        assert_eq!(plan.lanes[0].end, coord! {x: 0.0, y: 110.0});
        assert_eq!(plan.lanes[1].start, coord! {x: 30.0, y: 110.0});
        assert_eq!(plan.lanes[1].end, coord! {x: 30.0, y: -10.0});
        assert!(plan.links[0].is_empty());
    }
}
