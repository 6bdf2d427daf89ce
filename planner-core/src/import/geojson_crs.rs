//! GeoJSON with a legacy (2008) `crs` member naming another CRS, e.g.
//! `urn:ogc:def:crs:EPSG::28992`: the geometries reprojected to WGS84.

use geo_types::{Coord, Geometry, LineString, MultiLineString, MultiPolygon, Point, Polygon};
use serde_json::{Map, Value};

use super::{ImportError, Imported, ToWgs84};

/// The CRS a GeoJSON document's legacy `crs` member names, if it names
/// one other than WGS84 lon/lat (RFC 7946's only CRS).
pub fn named_crs(doc: &Value) -> Option<&str> {
    let name = doc.get("crs")?.get("properties")?.get("name")?.as_str()?;
    // EPSG:4326 in GeoJSON files is lon/lat in practice (GDAL writes it so).
    let wgs84 = [
        "urn:ogc:def:crs:OGC:1.3:CRS84",
        "urn:ogc:def:crs:OGC::CRS84",
        "urn:ogc:def:crs:EPSG::4326",
        "EPSG:4326",
    ];
    (!wgs84.iter().any(|w| w.eq_ignore_ascii_case(name))).then_some(name)
}

/// The polygons and lines of the GeoJSON document `bytes`, reprojected
/// from the CRS its `crs` member names.
pub(super) fn read_geojson(bytes: &[u8]) -> Result<Imported, ImportError> {
    let doc: Value = serde_json::from_slice(bytes)
        .map_err(|e| ImportError::Malformed(format!("not valid JSON: {e}")))?;
    let to_wgs84 = match named_crs(&doc) {
        Some(name) => ToWgs84::from_definition(name)?,
        None => ToWgs84::identity(),
    };
    let mut out = Imported::default();
    match doc.get("type").and_then(Value::as_str) {
        Some("FeatureCollection") => {
            let Some(features) = doc.get("features").and_then(Value::as_array) else {
                return Err(ImportError::Malformed(
                    "/features: a FeatureCollection needs a features array".into(),
                ));
            };
            for (i, f) in features.iter().enumerate() {
                feature(f, &format!("/features/{i}"), &to_wgs84, &mut out);
            }
        }
        Some("Feature") => feature(&doc, "", &to_wgs84, &mut out),
        Some(_) => match geometry(&doc) {
            Ok(g) => out.push("the geometry", to_wgs84.geometry(g), Map::new()),
            Err(m) => out.messages.push(format!("the geometry skipped: {m}")),
        },
        None => {
            return Err(ImportError::Malformed(
                "/type: not a GeoJSON object (no \"type\")".into(),
            ));
        }
    }
    Ok(out)
}

fn feature(f: &Value, pointer: &str, to_wgs84: &ToWgs84, out: &mut Imported) {
    let label = format!("feature {pointer}");
    let properties = f
        .get("properties")
        .and_then(Value::as_object)
        .cloned()
        .unwrap_or_default();
    match f.get("geometry").map(geometry) {
        Some(Ok(g)) => out.push(&label, to_wgs84.geometry(g), properties),
        Some(Err(m)) => out.messages.push(format!("{label} skipped: {m}")),
        None => out.messages.push(format!("{label} skipped: no geometry")),
    }
}

fn position(v: &Value) -> Result<Coord<f64>, String> {
    match v.as_array().map(Vec::as_slice) {
        Some([x, y, ..]) => match (x.as_f64(), y.as_f64()) {
            (Some(x), Some(y)) => Ok(Coord { x, y }),
            _ => Err(format!("position {v} is not numbers")),
        },
        _ => Err(format!("position {v} is not [x, y]")),
    }
}

fn array(v: &Value) -> Result<&Vec<Value>, String> {
    v.as_array()
        .ok_or_else(|| "coordinates are not nested arrays".to_string())
}

fn line(v: &Value) -> Result<LineString<f64>, String> {
    array(v)?.iter().map(position).collect()
}

fn polygon(v: &Value) -> Result<Polygon<f64>, String> {
    let rings = array(v)?.iter().map(line).collect::<Result<Vec<_>, _>>()?;
    let mut rings = rings.into_iter();
    let outer = rings.next().ok_or("a polygon without rings")?;
    Ok(Polygon::new(outer, rings.collect()))
}

/// A GeoJSON geometry object as geo-types (any type; which are kept is
/// decided by [`Imported::push`]).
fn geometry(g: &Value) -> Result<Geometry<f64>, String> {
    if g.is_null() {
        return Err("no geometry".into());
    }
    let c = g.get("coordinates").unwrap_or(&Value::Null);
    Ok(match g.get("type").and_then(Value::as_str) {
        Some("Polygon") => polygon(c)?.into(),
        Some("MultiPolygon") => {
            MultiPolygon(array(c)?.iter().map(polygon).collect::<Result<_, _>>()?).into()
        }
        Some("LineString") => line(c)?.into(),
        Some("MultiLineString") => {
            MultiLineString(array(c)?.iter().map(line).collect::<Result<_, _>>()?).into()
        }
        Some("Point") => Point(position(c)?).into(),
        Some(other) => return Err(format!("{other} geometries are not imported")),
        None => return Err("a geometry without \"type\"".into()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::Area;
    use serde_json::json;

    #[test]
    fn reprojects_from_a_named_crs() {
        let doc = json!({
            "type": "FeatureCollection",
            "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::28992"}},
            "features": [
                {"type": "Feature", "properties": {"n": 1}, "geometry": {"type": "Polygon",
                  "coordinates": [[[155000, 463000], [155100, 463000], [155100, 463100], [155000, 463000]]]}},
                {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [1, 2]}},
                {"type": "Feature", "properties": {}, "geometry": null}
            ]
        });
        assert_eq!(named_crs(&doc), Some("urn:ogc:def:crs:EPSG::28992"));
        let imp = read_geojson(doc.to_string().as_bytes()).unwrap();
        assert_eq!(imp.features.len(), 1);
        assert_eq!(imp.features[0].properties["n"], 1);
        let Geometry::Polygon(p) = &imp.features[0].geometry else {
            panic!("a polygon stays a polygon");
        };
        let c = p.exterior().0[0];
        // The RD origin (see reproject.rs), within PROJ's Helmert shift.
        assert!((c.x - 5.387_206_21).abs() < 5e-6 && (c.y - 52.155_174_40).abs() < 5e-6);
        // A 100 m right triangle in degrees: about 5000 m² at 52°N.
        let deg2 = p.unsigned_area();
        let m2 = deg2 * 111_320.0 * 111_320.0 * 52.155f64.to_radians().cos();
        assert!((m2 - 5000.0).abs() < 50.0, "{m2}");
        assert_eq!(imp.messages.len(), 2, "{:?}", imp.messages);
        assert!(imp.messages[0].contains("/features/1 skipped: Point"));
    }

    #[test]
    fn wgs84_names_and_faults() {
        let plain = json!({"type": "Polygon", "crs": {"type": "name",
            "properties": {"name": "urn:ogc:def:crs:OGC:1.3:CRS84"}}, "coordinates": []});
        assert_eq!(named_crs(&plain), None);
        let e = read_geojson(b"{\"type\": \"FeatureCollection\"").unwrap_err();
        assert!(e.to_string().starts_with("not valid JSON"), "{e}");
        let bad = json!({"type": "Feature", "crs": {"type": "name",
            "properties": {"name": "EPSG:0"}}, "geometry": null});
        let e = read_geojson(bad.to_string().as_bytes()).unwrap_err();
        assert!(e.to_string().contains("unknown CRS \"EPSG:0\""), "{e}");
    }
}
