//! GeoJSON (RFC 7946) output: the flown route in 3D and the cells.

use geo_types::{Coord, LineString, Polygon};
use serde_json::{Map, Value, json};

use super::mission::Mission;

/// The flown route as a Feature with a 3D LineString: home, every waypoint
/// (altitude in the mission's frame), home again (at its AMSL height in the
/// `amsl` frame, else 0).
pub fn route_feature(mission: &Mission, properties: Map<String, Value>) -> Value {
    let home = mission.home;
    let home_z = if mission.frame == super::mission::AltitudeFrame::Amsl {
        home.alt
    } else {
        0.0
    };
    let mut coords: Vec<Value> = vec![json!([home.lon, home.lat, home_z])];
    coords.extend(mission.waypoints().map(|p| json!([p.lon, p.lat, p.alt])));
    coords.push(json!([home.lon, home.lat, home_z]));
    json!({
        "type": "Feature",
        "properties": properties,
        "geometry": { "type": "LineString", "coordinates": coords },
    })
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

/// A FeatureCollection from (geometry, properties) pairs.
pub fn feature_collection(
    features: impl IntoIterator<Item = (Value, Map<String, Value>)>,
) -> Value {
    let features: Vec<Value> = features
        .into_iter()
        .map(|(geometry, properties)| json!({"type": "Feature", "properties": properties, "geometry": geometry}))
        .collect();
    json!({ "type": "FeatureCollection", "features": features })
}

/// A lon/lat polyline as a GeoJSON LineString geometry.
pub fn line_geometry(coords: &[Coord<f64>]) -> Value {
    json!({ "type": "LineString", "coordinates": coords.iter().map(|c| [c.x, c.y]).collect::<Vec<_>>() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::mission::{GeoPoint, sample_mission};
    use geo_types::polygon;

    #[test]
    fn route_is_3d_and_closed_at_home() {
        let m = sample_mission(GeoPoint {
            lon: 1.1,
            lat: 2.1,
            alt: 30.0,
        });
        let f = route_feature(&m, Map::new());
        let c = f["geometry"]["coordinates"].as_array().unwrap();
        assert_eq!(c.len(), 3);
        assert_eq!(c[1], json!([1.1, 2.1, 30.0]));
        assert_eq!(c[0], c[2]);
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
