//! GeoJSON (RFC 7946) output: the flown route in 3D and the cells.
//!
//! The third coordinate of a position is its height above the WGS 84
//! ellipsoid (RFC 7946 §4): the height above mean sea level plus the EGM96
//! geoid undulation. Where no height above mean sea level is known (a
//! survey without a DEM) positions are 2D. The mission's own altitudes
//! stay in the feature's properties (see [`route_feature`]).

use geo_types::{Coord, LineString, Polygon};
use serde_json::{Map, Value, json};

use super::geoid::egm96_undulation_m;
use super::mission::{AltitudeFrame, GeoPoint, Mission};

/// `height_reference` of a feature with 3D positions.
pub const ELLIPSOIDAL_HEIGHTS: &str =
    "WGS 84 ellipsoid (RFC 7946): height above mean sea level plus the EGM96 geoid undulation";
/// `height_reference` of a feature with 2D positions.
pub const NO_HEIGHTS: &str =
    "none: 2D positions, the height above mean sea level is unknown without a DEM";

/// Positions closer than this (degrees, 0.1 mm) are the same point.
const SAME_POSITION_DEG: f64 = 1e-9;

/// A height in metres to the millimetre, as written: finer digits mean
/// nothing, and a plan read back from storage (whose floats may come back
/// one unit in the last place off) still gives the same file.
pub(crate) fn mm(h: f64) -> f64 {
    (h * 1000.0).round() / 1000.0
}

/// A LineString feature through `positions` ([lon, lat]) with the heights
/// above mean sea level `amsl_m` (one per position) turned into
/// ellipsoidal heights, or 2D without them; adds `height_reference` and,
/// with heights, `heights_amsl_m` and `egm96_undulations_m` (aligned with
/// the coordinates) to `properties`. Heights are written to the millimetre.
pub fn line_feature(
    positions: &[[f64; 2]],
    amsl_m: Option<&[f64]>,
    mut properties: Map<String, Value>,
) -> Value {
    let coords: Vec<Value> = match amsl_m {
        Some(amsl) => {
            let undulations: Vec<f64> = positions
                .iter()
                .map(|p| egm96_undulation_m(p[0], p[1]))
                .collect();
            let coords = positions
                .iter()
                .zip(amsl)
                .zip(&undulations)
                .map(|((p, h), n)| json!([p[0], p[1], mm(h + n)]))
                .collect();
            let amsl: Vec<f64> = amsl.iter().copied().map(mm).collect();
            let undulations: Vec<f64> = undulations.into_iter().map(mm).collect();
            properties.insert("height_reference".into(), json!(ELLIPSOIDAL_HEIGHTS));
            properties.insert("heights_amsl_m".into(), json!(amsl));
            properties.insert("egm96_undulations_m".into(), json!(undulations));
            coords
        }
        None => {
            properties.insert("height_reference".into(), json!(NO_HEIGHTS));
            positions.iter().map(|p| json!([p[0], p[1]])).collect()
        }
    };
    json!({
        "type": "Feature",
        "properties": properties,
        "geometry": { "type": "LineString", "coordinates": coords },
    })
}

/// The flown route as a Feature with a LineString: home, every waypoint,
/// home again. Heights above the ellipsoid where the mission was planned
/// over a DEM, else 2D positions. `flown_amsl` are the points flown in
/// order as [lon, lat, height above mean sea level] (the terrain legs of
/// the plan): the terrain frame's waypoints take their heights from them;
/// the other frames convert their altitudes. Properties added (unless
/// given): `altitude_frame`, `mission_altitudes_m` (the altitude written in
/// the mission, in that frame, per position; 0 at home except in the
/// `amsl` frame), and those of [`line_feature`].
pub fn route_feature(
    mission: &Mission,
    flown_amsl: &[[f64; 3]],
    mut properties: Map<String, Value>,
) -> Value {
    let home = mission.home;
    let waypoints: Vec<GeoPoint> = mission.waypoints().copied().collect();
    let home_alt = if mission.frame == AltitudeFrame::Amsl {
        home.alt
    } else {
        0.0
    };
    let mut positions = vec![[home.lon, home.lat]];
    positions.extend(waypoints.iter().map(|p| [p.lon, p.lat]));
    positions.push([home.lon, home.lat]);
    let mut mission_alts = vec![mm(home_alt)];
    mission_alts.extend(waypoints.iter().map(|p| mm(p.alt)));
    mission_alts.push(mm(home_alt));
    let amsl = waypoints_amsl(mission, &waypoints, flown_amsl).map(|w| {
        let mut all = vec![home.alt];
        all.extend(w);
        all.push(home.alt);
        all
    });
    properties
        .entry("altitude_frame")
        .or_insert(json!(mission.frame));
    properties.insert("mission_altitudes_m".into(), json!(mission_alts));
    line_feature(&positions, amsl.as_deref(), properties)
}

/// Heights above mean sea level of the mission's waypoints, `None` without
/// a DEM (then neither home's ground nor the terrain is known).
fn waypoints_amsl(
    mission: &Mission,
    waypoints: &[GeoPoint],
    flown_amsl: &[[f64; 3]],
) -> Option<Vec<f64>> {
    if !mission.over_terrain {
        return None;
    }
    match mission.frame {
        AltitudeFrame::Amsl => Some(waypoints.iter().map(|p| p.alt).collect()),
        AltitudeFrame::Relative => {
            Some(waypoints.iter().map(|p| p.alt + mission.home.alt).collect())
        }
        AltitudeFrame::Terrain => match_flown(waypoints, flown_amsl),
    }
}

/// The heights of `flown` at the waypoints, matched in flight order by
/// position: every waypoint is one of the flown points (consecutive ones
/// within 1 cm are written once, and the first is reached by the take-off,
/// not written). `None` if a waypoint is not found.
fn match_flown(waypoints: &[GeoPoint], flown: &[[f64; 3]]) -> Option<Vec<f64>> {
    let mut next = 1;
    let mut out = Vec::with_capacity(waypoints.len());
    for w in waypoints {
        let k = next
            + flown.get(next..)?.iter().position(|p| {
                (p[0] - w.lon).abs() <= SAME_POSITION_DEG
                    && (p[1] - w.lat).abs() <= SAME_POSITION_DEG
            })?;
        out.push(flown[k][2]);
        next = k + 1;
    }
    Some(out)
}

/// A polygon (lon/lat) as a GeoJSON Polygon geometry; exteriors are written
/// counter-clockwise and holes clockwise (RFC 7946 §3.1.6).
pub fn polygon_geometry(p: &Polygon<f64>) -> Value {
    use geo::{Orient, orient::Direction};
    let p = p.orient(Direction::Default);
    let ring =
        |ls: &LineString<f64>| -> Vec<[f64; 2]> { ls.0.iter().map(|c| [c.x, c.y]).collect() };
    let mut rings = vec![ring(p.exterior())];
    rings.extend(p.interiors().iter().map(ring));
    json!({ "type": "Polygon", "coordinates": rings })
}

/// A lon/lat polyline as a GeoJSON LineString geometry.
pub fn line_geometry(coords: &[Coord<f64>]) -> Value {
    json!({ "type": "LineString", "coordinates": coords.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::mission::{MissionItem, sample_mission};
    use geo_types::polygon;

    fn coords(f: &Value) -> Vec<Vec<f64>> {
        f["geometry"]["coordinates"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                p.as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect()
            })
            .collect()
    }

    fn floats(v: &Value) -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    }

    /// A mission planned over a DEM near Grenoble: home at 210 m AMSL, two
    /// waypoints, `alts` in `frame`.
    fn dem_mission(frame: AltitudeFrame, alts: [f64; 2]) -> Mission {
        let mut m = sample_mission(GeoPoint {
            lon: 5.71,
            lat: 45.18,
            alt: alts[0],
        });
        m.frame = frame;
        m.over_terrain = true;
        m.home = GeoPoint {
            lon: 5.70,
            lat: 45.17,
            alt: 210.0,
        };
        m.items.insert(
            2,
            MissionItem::Waypoint(GeoPoint {
                lon: 5.72,
                lat: 45.19,
                alt: alts[1],
            }),
        );
        m
    }

    #[test]
    fn without_a_dem_positions_are_2d_and_altitudes_are_properties() {
        let m = sample_mission(GeoPoint {
            lon: 1.1,
            lat: 2.1,
            alt: 30.0,
        });
        let mut props = Map::new();
        props.insert("uav".into(), json!("a"));
        let f = route_feature(&m, &[], props);
        let c = coords(&f);
        assert_eq!(c, vec![vec![1.0, 2.0], vec![1.1, 2.1], vec![1.0, 2.0]]);
        let p = &f["properties"];
        assert_eq!(p["uav"], "a");
        assert_eq!(p["altitude_frame"], "relative");
        assert_eq!(p["mission_altitudes_m"], json!([0.0, 30.0, 0.0]));
        assert_eq!(p["height_reference"], NO_HEIGHTS);
        assert!(p.get("heights_amsl_m").is_none());
    }

    #[test]
    fn relative_and_amsl_altitudes_become_ellipsoidal_heights() {
        // The same flight: 250 and 260 m AMSL, written in both frames.
        let relative = route_feature(
            &dem_mission(AltitudeFrame::Relative, [40.0, 50.0]),
            &[],
            Map::new(),
        );
        let amsl = route_feature(
            &dem_mission(AltitudeFrame::Amsl, [250.0, 260.0]),
            &[],
            Map::new(),
        );
        assert_eq!(coords(&relative), coords(&amsl));
        let p = &relative["properties"];
        assert_eq!(p["mission_altitudes_m"], json!([0.0, 40.0, 50.0, 0.0]));
        assert_eq!(
            amsl["properties"]["mission_altitudes_m"],
            json!([210.0, 250.0, 260.0, 210.0])
        );
        assert_eq!(p["heights_amsl_m"], json!([210.0, 250.0, 260.0, 210.0]));
        assert_eq!(p["height_reference"], ELLIPSOIDAL_HEIGHTS);
        let n = floats(&p["egm96_undulations_m"]);
        for (c, (h, n)) in coords(&relative)
            .iter()
            .zip(floats(&p["heights_amsl_m"]).iter().zip(&n))
        {
            assert_eq!(c.len(), 3);
            // Each to the millimetre.
            assert!((c[2] - (h + n)).abs() <= 0.0015, "{c:?}");
            assert!((n - egm96_undulation_m(c[0], c[1])).abs() <= 0.0005);
            assert_eq!(c[2], (c[2] * 1000.0).round() / 1000.0);
        }
        // EGM96 near Grenoble: PROJ with NGA's 15′ grid gives 50.85 m at home.
        assert!((n[0] - 50.85).abs() < 0.1, "{n:?}");
    }

    #[test]
    fn terrain_frame_heights_come_from_the_flown_points() {
        // Above terrain: 40 and 50 m over ground at 215 and 208 m.
        let m = dem_mission(AltitudeFrame::Terrain, [40.0, 50.0]);
        let flown = [
            [5.70, 45.17, 250.0], // the take-off's point: not a waypoint
            [5.71, 45.18, 255.0],
            [5.71, 45.18, 255.0], // the same point ending one leg and starting the next
            [5.72, 45.19, 258.0],
        ];
        let f = route_feature(&m, &flown, Map::new());
        let p = &f["properties"];
        assert_eq!(p["heights_amsl_m"], json!([210.0, 255.0, 258.0, 210.0]));
        assert_eq!(p["mission_altitudes_m"], json!([0.0, 40.0, 50.0, 0.0]));
        assert_eq!(coords(&f)[1].len(), 3);
        // A waypoint that is not flown: the heights are not known.
        let f = route_feature(&m, &flown[..2], Map::new());
        assert_eq!(f["properties"]["height_reference"], NO_HEIGHTS);
        assert_eq!(coords(&f)[2].len(), 2);
    }

    #[test]
    fn polygons_are_written_ccw() {
        let cw = polygon![(x: 0.0, y: 0.0), (x: 0.0, y: 1.0), (x: 1.0, y: 1.0), (x: 1.0, y: 0.0)];
        let g = polygon_geometry(&cw);
        let ring = g["coordinates"][0].as_array().unwrap();
        let pts: Vec<(f64, f64)> = ring
            .iter()
            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect();
        let twice_area: f64 = pts
            .windows(2)
            .map(|w| w[0].0 * w[1].1 - w[1].0 * w[0].1)
            .sum();
        assert!(twice_area > 0.0);
    }
}
