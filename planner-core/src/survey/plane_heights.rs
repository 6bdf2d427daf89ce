//! The heights of a plane's waypoints over a DEM: each leg at least its
//! height above the highest (dilated) terrain under it, lanes split so
//! that they follow the ground, and no climb or descent steeper than the
//! plane's climb angle (raised where needed, never lowered).

use geo_types::Coord;

use super::terrain_flight::FlightRules;
use crate::coverage::arcs::{Mark, Waypoint};
use crate::terrain::TerrainModel;

/// Lanes are split into legs of at most this length, m, to follow the
/// ground (their ends turn by nothing, so the turn rule is untouched).
const LANE_STEP_M: f64 = 20.0;

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

/// Lane legs (from a lane's start to its end) split every [`LANE_STEP_M`].
pub(super) fn split_lanes(wps: &[Waypoint]) -> Vec<Waypoint> {
    let mut out = Vec::with_capacity(wps.len());
    let mut in_lane = false;
    for (i, w) in wps.iter().enumerate() {
        if in_lane && let Some(prev) = i.checked_sub(1).map(|k| wps[k]) {
            let len = dist(prev.at, w.at);
            let n = (len / LANE_STEP_M).ceil() as usize;
            for k in 1..n {
                out.push(Waypoint {
                    at: prev.at + (w.at - prev.at) * (k as f64 / n as f64),
                    mark: Mark::Point,
                });
            }
        }
        out.push(*w);
        match w.mark {
            Mark::LaneStart => in_lane = true,
            Mark::LaneEnd => in_lane = false,
            Mark::Point | Mark::Corner => {}
        }
    }
    out
}

/// Heights (in the DEM's datum) of `wps`, whose first and last are home
/// at `home_amsl` (kept on the ground). Lane legs are flown
/// `rules.agl_m` above the dilated terrain, the others at least
/// `rules.transit_clearance_m`; slopes at most `tan_climb`. `landing`:
/// the last leg is a plane's descent to home (not held above the
/// terrain, but within the climb angle: `Err` with the slope needed when
/// the terrain forbids it).
pub(super) fn heights(
    wps: &[Waypoint],
    model: &TerrainModel,
    rules: &FlightRules,
    home_amsl: f64,
    tan_climb: f64,
    landing: bool,
) -> Result<Vec<f64>, f64> {
    let n = wps.len();
    let mut z = vec![home_amsl; n];
    if n < 3 {
        return Ok(z);
    }
    let mut in_lane = false;
    let mut floors = Vec::with_capacity(n - 1);
    for k in 0..n - 1 {
        in_lane = match wps[k].mark {
            Mark::LaneStart => true,
            Mark::LaneEnd => false,
            Mark::Point | Mark::Corner => in_lane,
        };
        let ground = model
            .densify(&[wps[k].at, wps[k + 1].at])
            .into_iter()
            .map(|(_, p)| {
                model
                    .safe_terrain(p)
                    .or_else(|| model.terrain(p))
                    .unwrap_or(home_amsl)
            })
            .fold(f64::NEG_INFINITY, f64::max);
        let offset = if in_lane {
            rules.agl_m
        } else {
            rules
                .transit_clearance_m
                .max(rules.agl_m - rules.tolerance_m)
        };
        floors.push(ground + offset);
    }
    // The climb after take-off ends at the first waypoint, the landing
    // starts at the last: their legs hold those waypoints up (a VTOL
    // flies the last leg level before it descends).
    let last = n - 2;
    for i in 1..=last {
        let after = if i == last && landing {
            f64::NEG_INFINITY
        } else {
            floors[i]
        };
        z[i] = floors[i - 1].max(after);
    }
    let legs: Vec<f64> = (0..n - 1).map(|k| dist(wps[k].at, wps[k + 1].at)).collect();
    for i in (1..last).rev() {
        z[i] = z[i].max(z[i + 1] - tan_climb * legs[i]);
    }
    for i in 1..last {
        z[i + 1] = z[i + 1].max(z[i] - tan_climb * legs[i]);
    }
    if landing {
        let slope = (z[last] - home_amsl) / legs[last].max(1e-9);
        if slope > tan_climb + 1e-9 {
            return Err(slope);
        }
    }
    Ok(z)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wp(x: f64, mark: Mark) -> Waypoint {
        Waypoint {
            at: Coord { x, y: 0.0 },
            mark,
        }
    }

    #[test]
    fn lanes_are_split_and_nothing_else() {
        let wps = [
            wp(0.0, Mark::Point),
            wp(10.0, Mark::Corner),
            wp(20.0, Mark::LaneStart),
            wp(85.0, Mark::LaneEnd),
            wp(200.0, Mark::Point),
        ];
        let out = split_lanes(&wps);
        let xs: Vec<f64> = out.iter().map(|w| w.at.x).collect();
        assert_eq!(xs, [0.0, 10.0, 20.0, 36.25, 52.5, 68.75, 85.0, 200.0]);
        assert_eq!(out[3].mark, Mark::Point);
        assert_eq!(out[6].mark, Mark::LaneEnd);
    }
}
