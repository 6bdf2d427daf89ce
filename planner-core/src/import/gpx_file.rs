//! GPX files: tracks (their segments) and routes as corridor lines, in
//! WGS84 as GPX always is; waypoints are listed as skipped.

use geo_types::{Geometry, LineString, MultiLineString};
use serde_json::{Map, Value};

use super::{ImportError, Imported};

/// The tracks and routes of the GPX document `bytes`.
pub(super) fn read_gpx(bytes: &[u8]) -> Result<Imported, ImportError> {
    let gpx = gpx::read(bytes)
        .map_err(|e| ImportError::Malformed(format!("not a readable GPX document: {e}")))?;
    let mut out = Imported::default();
    let named = |kind: &str, name: &Option<String>| {
        let mut p = Map::new();
        p.insert("gpx_type".into(), Value::from(kind));
        if let Some(n) = name {
            p.insert("name".into(), Value::from(n.as_str()));
        }
        p
    };
    for (i, track) in gpx.tracks.iter().enumerate() {
        let lines: Vec<LineString<f64>> = track
            .segments
            .iter()
            .filter(|s| !s.points.is_empty())
            .map(|s| s.points.iter().map(|w| w.point().0).collect())
            .collect();
        let label = format!("track {i}");
        let geometry = match <[LineString<f64>; 1]>::try_from(lines) {
            Ok([one]) => Geometry::LineString(one),
            Err(lines) => Geometry::MultiLineString(MultiLineString(lines)),
        };
        out.push(&label, geometry, named("track", &track.name));
    }
    for (i, route) in gpx.routes.iter().enumerate() {
        let line: LineString<f64> = route.points.iter().map(|w| w.point().0).collect();
        out.push(
            &format!("route {i}"),
            line.into(),
            named("route", &route.name),
        );
    }
    if !gpx.waypoints.is_empty() {
        out.messages.push(format!(
            "{} waypoints skipped: points are not imported (only tracks and routes)",
            gpx.waypoints.len()
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GPX: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<gpx version="1.1" creator="test" xmlns="http://www.topografix.com/GPX/1/1">
  <wpt lat="52.0" lon="5.0"><name>start</name></wpt>
  <rte><name>power line</name>
    <rtept lat="52.0" lon="5.0"/><rtept lat="52.01" lon="5.02"/>
  </rte>
  <trk><name>river</name>
    <trkseg><trkpt lat="52.1" lon="5.1"/><trkpt lat="52.11" lon="5.12"/><trkpt lat="52.12" lon="5.13"/></trkseg>
  </trk>
</gpx>"#;

    #[test]
    fn tracks_and_routes_become_lines() {
        let imp = read_gpx(GPX.as_bytes()).unwrap();
        assert_eq!(imp.features.len(), 2);
        let Geometry::LineString(track) = &imp.features[0].geometry else {
            panic!("one segment gives a LineString");
        };
        assert_eq!(track.0.len(), 3);
        assert_eq!((track.0[1].x, track.0[1].y), (5.12, 52.11));
        assert_eq!(imp.features[0].properties["name"], "river");
        assert_eq!(imp.features[1].properties["gpx_type"], "route");
        assert_eq!(imp.messages.len(), 1, "{:?}", imp.messages);
        assert!(imp.messages[0].starts_with("1 waypoints skipped"));
    }

    #[test]
    fn truncations_are_errors_not_panics() {
        for cut in 0..GPX.len() - 8 {
            let r = read_gpx(&GPX.as_bytes()[..cut]);
            assert!(r.is_err(), "cut {cut} read as {r:?}");
        }
    }
}
