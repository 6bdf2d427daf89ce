//! A ground robot's route as files: GeoJSON (a LineString at the terrain's
//! heights above the WGS 84 ellipsoid), CSV of UTM waypoints (what the
//! thesis hands to the rover), and an ArduPilot Rover mission.

use std::fmt::Write;

use serde_json::{Map, Value, json};

use super::geojson::{line_feature, mm};
use super::mission::{AltitudeFrame, GeoPoint, Mission, MissionItem};
use crate::route::MapRoute;

/// The route as a GeoJSON Feature: a LineString through the waypoints,
/// `[lon, lat, height above the WGS 84 ellipsoid]` when every waypoint's
/// terrain height is known (the DEM's height, taken as above mean sea
/// level, plus the EGM96 undulation), else `[lon, lat]`; `properties`
/// plus the route's figures, `terrain_heights_m` (the DEM's to the
/// millimetre, `null` where unknown) and the height properties of [`line_feature`]. A route whose
/// start is its goal has one waypoint, given twice (a LineString needs two
/// positions, RFC 7946 §3.1.4).
pub fn route_feature(route: &MapRoute, mut properties: Map<String, Value>) -> Value {
    let mut positions: Vec<[f64; 2]> = route.waypoints.iter().map(|p| [p.lon, p.lat]).collect();
    let mut heights: Vec<Option<f64>> = route.waypoints.iter().map(|p| p.height_m).collect();
    if positions.len() == 1 {
        positions.push(positions[0]);
        heights.push(heights[0]);
    }
    let amsl: Option<Vec<f64>> = heights.iter().copied().collect();
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
    let terrain: Vec<Option<f64>> = heights.iter().map(|h| h.map(mm)).collect();
    properties.insert("terrain_heights_m".into(), json!(terrain));
    line_feature(&positions, amsl.as_deref(), properties)
}

/// The route as a GeoJSON FeatureCollection of its one [`route_feature`],
/// like a survey's route files.
pub fn route_geojson(route: &MapRoute, properties: Map<String, Value>) -> Value {
    json!({ "type": "FeatureCollection", "features": [route_feature(route, properties)] })
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
    use crate::export::geoid::egm96_undulation_m;
    use crate::export::geojson::{ELLIPSOIDAL_HEIGHTS, NO_HEIGHTS};
    use crate::export::write_waypoints;
    use crate::route::RoutePoint;

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
    fn geojson_has_ellipsoidal_heights_only_when_all_are_known() {
        let g = route_geojson(&sample_route(true), Map::new());
        assert_eq!(g["type"], "FeatureCollection");
        let f = &g["features"][0];
        assert_eq!(f["type"], "Feature");
        let c = &f["geometry"]["coordinates"][2];
        let n = egm96_undulation_m(-74.998, 38.8);
        // EGM96 off Delaware: PROJ with NGA's 15′ grid gives −36.80 m.
        assert!((n + 36.80).abs() < 0.1, "{n}");
        assert_eq!(c[0], -74.998);
        assert!((c[2].as_f64().unwrap() - (12.0 + n)).abs() <= 0.0005, "{c}");
        let p = &f["properties"];
        assert_eq!(p["utm_zone"], "18N");
        assert_eq!(p["terrain_heights_m"], json!([10.0, 11.0, 12.0]));
        assert_eq!(p["heights_amsl_m"], json!([10.0, 11.0, 12.0]));
        assert_eq!(p["height_reference"], ELLIPSOIDAL_HEIGHTS);

        let f = route_feature(&sample_route(false), Map::new());
        assert_eq!(f["geometry"]["coordinates"][0], json!([-75.0, 38.8]));
        assert_eq!(
            f["properties"]["terrain_heights_m"],
            json!([null, null, null])
        );
        assert_eq!(f["properties"]["height_reference"], NO_HEIGHTS);
        // One height missing: 2D, the known ones kept as properties.
        let mut partial = sample_route(true);
        partial.waypoints[1].height_m = None;
        let f = route_feature(&partial, Map::new());
        assert_eq!(f["geometry"]["coordinates"][2], json!([-74.998, 38.8]));
        assert_eq!(
            f["properties"]["terrain_heights_m"],
            json!([10.0, null, 12.0])
        );

        let mut one = sample_route(true);
        one.waypoints.truncate(1);
        let f = route_feature(&one, Map::new());
        let c = f["geometry"]["coordinates"].as_array().unwrap();
        assert_eq!(c.len(), 2);
        assert_eq!(c[0], c[1]);
        assert_eq!(c[0].as_array().unwrap().len(), 3);
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
