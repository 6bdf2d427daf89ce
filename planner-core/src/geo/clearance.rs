//! The keep-out area around no-fly zones: every point closer than the
//! clearance to an NFZ (SPEC §3.3). The NFZs are exported as exclusion
//! fences, so a vehicle flying on their edge breaches the fence with
//! ordinary GPS error; lanes, links and transits are planned outside this
//! area instead of outside the bare NFZs.

use geo::algorithm::buffer::{Buffer, BufferStyle, LineJoin};
use geo::{Area, Contains, Distance, Euclidean};
use geo_types::{Coord, MultiPolygon, Point, Polygon};

/// Slack added to the clearance, metres: the offset polygon's vertices are
/// snapped to i_overlay's integer grid (micrometres at survey scale), and
/// the flown path touches its edges; a millimetre keeps every flown point at
/// the full clearance after that rounding and the lon/lat round trip.
const SLACK_M: f64 = 1e-3;

/// Smallest corner angle that is still mitered rather than cut (radians).
/// A limited miter extends both offset edges by `clearance / tan(angle/2)`
/// (64 × the clearance here) before joining them, so only needle-like NFZ
/// tips are cut, and the cut lies far beyond the clearance.
const MITER_MIN_ANGLE: f64 = 0.01 * std::f64::consts::PI;

/// Half the width of the narrowest gap left open between offset zones,
/// metres (see [`keep_out_area`]): well above the transit planner's 1 cm
/// side probe, far below anything a vehicle could fly through.
const CLOSING_M: f64 = 0.05;

/// Every point within `clearance_m` of `zones` (UTM metres), as polygons
/// whose boundary is at least `clearance_m` from every zone.
///
/// Mitered corners rather than round ones: a round join is approximated by
/// chords inside the true arc, which would bring the boundary closer than
/// the clearance, and it adds a dozen vertices per corner (decomposition
/// events and visibility nodes); a miter contains the arc and keeps one
/// vertex per convex corner. Returns `zones` unchanged for a clearance of 0.
pub fn keep_out_area(zones: &MultiPolygon<f64>, clearance_m: f64) -> MultiPolygon<f64> {
    if zones.0.is_empty() || clearance_m.is_nan() || clearance_m <= 0.0 {
        return zones.clone();
    }
    let style =
        |distance: f64| BufferStyle::new(distance).line_join(LineJoin::Miter(MITER_MIN_ANGLE));
    // Grown a little further and shrunk back (a morphological closing):
    // gaps and notches narrower than twice `CLOSING_M` between the offset
    // zones are filled. Nothing flies through a gap of centimetres, and the
    // transit planner treats such slits as closed, so a lane must not end
    // in one. Closing only adds area: the clearance still holds.
    zones
        .buffer_with_style(style(clearance_m + SLACK_M + CLOSING_M))
        .buffer_with_style(style(-CLOSING_M))
}

/// The holes of `area` (regions enclosed by it) that hold none of `keep`,
/// filled: a vehicle outside cannot reach them without crossing `area`.
/// Returns the filled area and its size in m².
pub fn fill_enclosed(area: &MultiPolygon<f64>, keep: &[Coord<f64>]) -> (MultiPolygon<f64>, f64) {
    let mut filled = 0.0;
    let polygons = area
        .0
        .iter()
        .map(|p| {
            let (kept, dropped): (Vec<_>, Vec<_>) =
                p.interiors().iter().cloned().partition(|ring| {
                    let hole = Polygon::new(ring.clone(), vec![]);
                    keep.iter().any(|&c| hole.contains(&Point(c)))
                });
            filled += dropped
                .into_iter()
                .map(|ring| Polygon::new(ring, vec![]).unsigned_area())
                .sum::<f64>();
            Polygon::new(p.exterior().clone(), kept)
        })
        .collect();
    (MultiPolygon(polygons), filled)
}

/// Distance from `p` to the nearest of `zones` (0 inside one), metres.
pub fn distance_to_zones(p: Coord<f64>, zones: &[Polygon<f64>]) -> f64 {
    zones
        .iter()
        .map(|z| Euclidean.distance(&Point(p), z))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::{BooleanOps, Intersects};
    use geo_types::{LineString, polygon};

    fn boundary_points(area: &MultiPolygon<f64>, step: f64) -> Vec<Coord<f64>> {
        let mut out = Vec::new();
        for p in area {
            for ring in std::iter::once(p.exterior()).chain(p.interiors()) {
                for l in ring.lines() {
                    let d = l.end - l.start;
                    let n = ((d.x.hypot(d.y)) / step).ceil().max(1.0) as usize;
                    for k in 0..=n {
                        out.push(l.start + d * (k as f64 / n as f64));
                    }
                }
            }
        }
        out
    }

    /// Regular-ish star polygons with sharp and reflex corners.
    fn star(cx: f64, cy: f64, spikes: usize, r_in: f64, r_out: f64) -> Polygon<f64> {
        let n = 2 * spikes;
        let ring: Vec<Coord<f64>> = (0..n)
            .map(|i| {
                let t = i as f64 * std::f64::consts::TAU / n as f64;
                let r = if i % 2 == 0 { r_out } else { r_in };
                Coord {
                    x: cx + r * t.cos(),
                    y: cy + r * t.sin(),
                }
            })
            .collect();
        Polygon::new(LineString(ring), vec![])
    }

    #[test]
    fn boundary_keeps_the_clearance_and_no_more_than_needed_on_edges() {
        let zones = MultiPolygon(vec![
            star(0.0, 0.0, 5, 20.0, 80.0),
            star(300.0, 40.0, 12, 30.0, 45.0),
            polygon![(x: -200.0, y: 200.0), (x: -100.0, y: 200.0), (x: -100.0, y: 260.0), (x: -200.0, y: 260.0)],
        ]);
        let list: Vec<Polygon<f64>> = zones.0.clone();
        for clearance in [0.5, 5.0, 20.0] {
            let keep_out = keep_out_area(&zones, clearance);
            assert!(keep_out.unsigned_area() > zones.unsigned_area());
            let pts = boundary_points(&keep_out, 0.25);
            let min = pts
                .iter()
                .map(|&c| distance_to_zones(c, &list))
                .fold(f64::INFINITY, f64::min);
            // Never closer than the clearance (1 µm for the grid snapping)...
            assert!(min >= clearance - 1e-6, "clearance {clearance}: {min}");
            // ...and along straight edges exactly at it (plus the slack).
            assert!(
                min <= clearance + 2.0 * SLACK_M,
                "clearance {clearance}: {min}"
            );
            // Every zone is inside the keep-out area.
            assert!(keep_out.contains(&zones));
        }
    }

    #[test]
    fn zero_clearance_is_the_zones_themselves() {
        let zones = MultiPolygon(vec![star(0.0, 0.0, 4, 10.0, 30.0)]);
        assert_eq!(keep_out_area(&zones, 0.0), zones);
        assert!(keep_out_area(&MultiPolygon(vec![]), 5.0).0.is_empty());
    }

    #[test]
    fn zones_closer_than_twice_the_clearance_merge_and_enclosed_pockets_fill() {
        // A ring of four bars with 6 m gaps: at 5 m clearance the gaps close
        // and the courtyard is cut off.
        let bar = |x0: f64, y0: f64, x1: f64, y1: f64| polygon![(x: x0, y: y0), (x: x1, y: y0), (x: x1, y: y1), (x: x0, y: y1)];
        let zones = MultiPolygon(vec![
            bar(0.0, 0.0, 94.0, 10.0),
            bar(100.0, 0.0, 110.0, 94.0),
            bar(16.0, 100.0, 110.0, 110.0),
            bar(0.0, 16.0, 10.0, 110.0),
        ]);
        let keep_out = keep_out_area(&zones, 5.0);
        assert_eq!(keep_out.0.len(), 1, "gaps of 6 m close at 5 m clearance");
        assert_eq!(keep_out.0[0].interiors().len(), 1);
        let courtyard = Coord { x: 55.0, y: 55.0 };
        assert!(!keep_out.intersects(&Point(courtyard)));

        let (filled, area) = fill_enclosed(&keep_out, &[]);
        assert!(filled.0[0].interiors().is_empty());
        // The courtyard is 90 × 90 m less 5 m all round (mitered corners).
        assert!((area - 80.0 * 80.0).abs() < 1.0, "{area}");
        // A home in the courtyard keeps it open.
        let (kept, area) = fill_enclosed(&keep_out, &[courtyard]);
        assert_eq!(kept.0[0].interiors().len(), 1);
        assert_eq!(area, 0.0);

        // At 2 m the gaps stay open: one polygon per bar, nothing enclosed.
        let open = keep_out_area(&zones, 2.0);
        assert_eq!(open.0.len(), 4);
        assert!(open.difference(&zones).unsigned_area() > 0.0);
    }

    #[test]
    fn slits_between_offset_zones_are_closed_wider_gaps_stay() {
        // Two squares 10.05 m apart at 5 m clearance: the offset squares
        // leave a slit of about 5 cm, which nothing can fly through and the
        // transit planner treats as closed, so it is filled. At 20 cm the
        // gap stays open.
        let square = |x0: f64| polygon![(x: x0, y: 0.0), (x: x0 + 20.0, y: 0.0), (x: x0 + 20.0, y: 20.0), (x: x0, y: 20.0)];
        for (gap, merged) in [(10.05, true), (10.2, false)] {
            let zones = MultiPolygon(vec![square(0.0), square(20.0 + gap)]);
            let keep_out = keep_out_area(&zones, 5.0);
            assert_eq!(keep_out.0.len() == 1, merged, "gap {gap}: {keep_out:?}");
            let middle = Point(Coord {
                x: 20.0 + gap / 2.0,
                y: 10.0,
            });
            assert_eq!(keep_out.intersects(&middle), merged, "gap {gap}");
            // Closing adds area only in the slit: the outer edges stay at
            // the clearance (plus the slack).
            let width = keep_out
                .0
                .iter()
                .flat_map(|p| p.exterior().0.iter())
                .map(|c| c.x)
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (width - (40.0 + gap + 5.0 + SLACK_M)).abs() < 1e-4,
                "{width}"
            );
        }
    }

    #[test]
    fn distance_is_zero_inside_and_euclidean_outside() {
        let zones = vec![
            polygon![(x: 0.0, y: 0.0), (x: 10.0, y: 0.0), (x: 10.0, y: 10.0), (x: 0.0, y: 10.0)],
        ];
        assert_eq!(distance_to_zones(Coord { x: 5.0, y: 5.0 }, &zones), 0.0);
        assert!((distance_to_zones(Coord { x: 13.0, y: 14.0 }, &zones) - 5.0).abs() < 1e-12);
        assert_eq!(
            distance_to_zones(Coord { x: 0.0, y: 0.0 }, &[]),
            f64::INFINITY
        );
    }
}
