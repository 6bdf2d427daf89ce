//! A ground robot's route as files: GeoJSON (a LineString with terrain
//! heights), CSV of UTM waypoints (what the thesis hands to the rover),
//! and an ArduPilot Rover mission.

use std::fmt::Write;

use serde_json::{Map, Value, json};

use super::mission::{AltitudeFrame, GeoPoint, Mission, MissionItem};
use crate::route::on_map::MapRoute;

/// The route as a GeoJSON Feature: a LineString through the waypoints,
/// `[lon, lat, height]` when every waypoint's height is known, else
/// `[lon, lat]`; `properties` plus the route's figures. A route whose
/// start is its goal has one waypoint, given twice (a LineString needs two
/// positions, RFC 7946 §3.1.4).
pub fn route_geojson(route: &MapRoute, mut properties: Map<String, Value>) -> Value {
    let with_height = route.waypoints.iter().all(|p| p.height_m.is_some());
    let mut coords: Vec<Value> = route
        .waypoints
        .iter()
        .map(|p| match p.height_m {
            Some(h) if with_height => json!([p.lon, p.lat, h]),
            _ => json!([p.lon, p.lat]),
        })
        .collect();
    if coords.len() == 1 {
        coords.push(coords[0].clone());
    }
    let figures = [
        ("length_2d_m", json!(route.length_2d_m)),
        ("length_3d_m", json!(route.length_3d_m)),
        ("cost", json!(route.cost)),
        ("path_cost", json!(route.path_cost)),
        ("max_slope_deg", json!(route.max_slope_deg)),
        ("mean_slope_deg", json!(route.mean_slope_deg)),
        ("utm_zone", json!(route.utm_zone)),
    ];
    for (k, v) in figures {
        properties.entry(k).or_insert(v);
    }
    json!({
        "type": "Feature",
        "properties": properties,
        "geometry": { "type": "LineString", "coordinates": coords },
    })
}

/// The waypoints as CSV: `index,easting,northing,zone,height` (metres,
/// millimetre precision; height empty where unknown).
pub fn route_csv(route: &MapRoute) -> String {
    let mut out = String::from("index,easting,northing,zone,height\n");
    for (i, p) in route.waypoints.iter().enumerate() {
        let height = p.height_m.map(|h| format!("{h:.3}")).unwrap_or_default();
        let _ = writeln!(
            out,
            "{i},{:.3},{:.3},{},{height}",
            p.easting, p.northing, route.utm_zone
        );
    }
    out
}

/// An ArduPilot Rover mission: home at the start (its terrain height, 0
/// when unknown), an optional ground-speed change, then one NAV_WAYPOINT
/// per waypoint after the start, the goal last. A rover ignores waypoint
/// altitudes; they are written as 0 above home.
pub fn rover_mission(route: &MapRoute, speed_m_s: Option<f64>) -> Mission {
    let start = &route.waypoints[0];
    let mut items = Vec::with_capacity(route.waypoints.len() + 1);
    if let Some(speed_m_s) = speed_m_s {
        items.push(MissionItem::ChangeSpeed { speed_m_s });
    }
    items.extend(route.waypoints.iter().skip(1).map(|p| {
        MissionItem::Waypoint(GeoPoint {
            lon: p.lon,
            lat: p.lat,
            alt: 0.0,
        })
    }));
    Mission {
        home: GeoPoint {
            lon: start.lon,
            lat: start.lat,
            alt: start.height_m.unwrap_or(0.0),
        },
        frame: AltitudeFrame::Relative,
        cruise_speed_m_s: speed_m_s.unwrap_or(0.0),
        items,
        over_terrain: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::write_waypoints;
    use crate::route::on_map::RoutePoint;

    fn sample_route(heights: bool) -> MapRoute {
        let point = |i: usize| RoutePoint {
            lon: -75.0 + i as f64 * 1e-3,
            lat: 38.8,
            easting: 500_000.0 + i as f64 * 86.7,
            northing: 4_294_000.0,
            height_m: heights.then_some(10.0 + i as f64),
            row: 5,
            col: 5 + i,
        };
        MapRoute {
            utm_zone: "18N".into(),
            utm_epsg: 32618,
            waypoints: (0..3).map(point).collect(),
            length_2d_m: 173.4,
            length_3d_m: heights.then_some(173.5),
            cost: 200.0,
            path_cost: 201.0,
            path_length_m: 173.4,
            path_cells: 88,
            max_slope_deg: None,
            mean_slope_deg: None,
            max_grade_deg: None,
            climb_m: None,
            descent_m: None,
            expanded: 100,
            search_ms: 0.1,
        }
    }

    #[test]
    fn geojson_has_heights_only_when_all_are_known() {
        let g = route_geojson(&sample_route(true), Map::new());
        assert_eq!(
            g["geometry"]["coordinates"][2],
            json!([-74.998, 38.8, 12.0])
        );
        assert_eq!(g["properties"]["utm_zone"], "18N");
        let g = route_geojson(&sample_route(false), Map::new());
        assert_eq!(g["geometry"]["coordinates"][0], json!([-75.0, 38.8]));
        let mut one = sample_route(true);
        one.waypoints.truncate(1);
        let g = route_geojson(&one, Map::new());
        assert_eq!(
            g["geometry"]["coordinates"],
            json!([[-75.0, 38.8, 10.0], [-75.0, 38.8, 10.0]])
        );
    }

    #[test]
    fn csv_rows() {
        let csv = route_csv(&sample_route(true));
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines[0], "index,easting,northing,zone,height");
        assert_eq!(lines[2], "1,500086.700,4294000.000,18N,11.000");
        assert_eq!(lines.len(), 4);
        let csv = route_csv(&sample_route(false));
        assert!(csv.lines().nth(1).unwrap().ends_with(",18N,"));
    }

    #[test]
    fn rover_mission_items() {
        let m = rover_mission(&sample_route(true), Some(1.5));
        assert_eq!(m.home.alt, 10.0);
        assert_eq!(m.items.len(), 3);
        assert_eq!(m.items[0], MissionItem::ChangeSpeed { speed_m_s: 1.5 });
        let wpl = write_waypoints(&m);
        let rows: Vec<&str> = wpl.lines().collect();
        assert_eq!(rows[0], "QGC WPL 110");
        // Home, speed, two waypoints.
        assert_eq!(rows.len(), 5);
        assert!(rows[4].contains("\t16\t"), "{}", rows[4]);
    }
}
