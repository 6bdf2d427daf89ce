//! GeoJSON (RFC 7946) polygon input in WGS84 lon/lat.
//!
//! Parsed by hand from `serde_json::Value` rather than through a GeoJSON
//! crate so that every fault is reported with the JSON pointer of the exact
//! member at fault, which the API returns as `{pointer, message}`.

use geo_types::{Coord, LineString, Polygon};
use serde_json::Value;

use super::Issue;

/// A polygon and the JSON pointer of its `coordinates`, so later checks
/// (self-intersection, area) can name the member at fault.
#[derive(Clone, Debug, PartialEq)]
pub struct ParsedPolygon {
    pub polygon: Polygon<f64>,
    pub pointer: String,
}

/// Polygons read from a GeoJSON value.
///
/// Accepts a `Polygon`, `MultiPolygon`, `Feature` whose geometry is one of
/// those, a `FeatureCollection` of such features, or a `GeometryCollection`.
/// Positions may carry a third (height) element, which is ignored. Rings may
/// be closed or implicitly closed (SPEC §2); either orientation is accepted.
/// Coordinate ranges and ring shape are checked here; topology (self
/// intersection) is checked by [`super::validate`].
pub fn parse_polygons(value: &Value, pointer: &str) -> Result<Vec<ParsedPolygon>, Vec<Issue>> {
    let mut out = Vec::new();
    let mut issues = Vec::new();
    collect(value, pointer, &mut out, &mut issues);
    if out.is_empty() && issues.is_empty() {
        issues.push(Issue::new(pointer, "contains no polygon"));
    }
    if issues.is_empty() {
        Ok(out)
    } else {
        Err(issues)
    }
}

fn collect(value: &Value, pointer: &str, out: &mut Vec<ParsedPolygon>, issues: &mut Vec<Issue>) {
    let Some(obj) = value.as_object() else {
        issues.push(Issue::new(pointer, "must be a GeoJSON object"));
        return;
    };
    let Some(kind) = obj.get("type").and_then(Value::as_str) else {
        issues.push(Issue::new(
            &format!("{pointer}/type"),
            "missing GeoJSON \"type\" member",
        ));
        return;
    };
    match kind {
        "Polygon" => {
            if let Some(coords) = coordinates(obj, pointer, issues) {
                let ptr = format!("{pointer}/coordinates");
                if let Some(polygon) = polygon(coords, &ptr, issues) {
                    out.push(ParsedPolygon {
                        polygon,
                        pointer: ptr,
                    });
                }
            }
        }
        "MultiPolygon" => {
            if let Some(coords) = coordinates(obj, pointer, issues) {
                let ptr = format!("{pointer}/coordinates");
                match coords.as_array() {
                    Some(parts) if !parts.is_empty() => {
                        for (i, part) in parts.iter().enumerate() {
                            let ptr = format!("{ptr}/{i}");
                            if let Some(polygon) = polygon(part, &ptr, issues) {
                                out.push(ParsedPolygon {
                                    polygon,
                                    pointer: ptr,
                                });
                            }
                        }
                    }
                    Some(_) => issues.push(Issue::new(&ptr, "MultiPolygon has no polygons")),
                    None => issues.push(Issue::new(&ptr, "must be an array of polygons")),
                }
            }
        }
        "Feature" => match obj.get("geometry") {
            Some(Value::Null) | None => issues.push(Issue::new(
                &format!("{pointer}/geometry"),
                "Feature has no geometry",
            )),
            Some(g) => collect(g, &format!("{pointer}/geometry"), out, issues),
        },
        "FeatureCollection" => match obj.get("features").and_then(Value::as_array) {
            Some(features) => {
                for (i, f) in features.iter().enumerate() {
                    collect(f, &format!("{pointer}/features/{i}"), out, issues);
                }
            }
            None => issues.push(Issue::new(
                &format!("{pointer}/features"),
                "FeatureCollection needs a \"features\" array",
            )),
        },
        "GeometryCollection" => match obj.get("geometries").and_then(Value::as_array) {
            Some(geoms) => {
                for (i, g) in geoms.iter().enumerate() {
                    collect(g, &format!("{pointer}/geometries/{i}"), out, issues);
                }
            }
            None => issues.push(Issue::new(
                &format!("{pointer}/geometries"),
                "GeometryCollection needs a \"geometries\" array",
            )),
        },
        "Point" | "MultiPoint" | "LineString" | "MultiLineString" => issues.push(Issue::new(
            &format!("{pointer}/type"),
            &format!("geometry type {kind} is not an area: expected Polygon or MultiPolygon"),
        )),
        other => issues.push(Issue::new(
            &format!("{pointer}/type"),
            &format!(
                "unknown GeoJSON type {other:?}: expected Polygon, MultiPolygon, Feature, \
                 FeatureCollection or GeometryCollection"
            ),
        )),
    }
}

fn coordinates<'a>(
    obj: &'a serde_json::Map<String, Value>,
    pointer: &str,
    issues: &mut Vec<Issue>,
) -> Option<&'a Value> {
    let c = obj.get("coordinates");
    if c.is_none() {
        issues.push(Issue::new(
            &format!("{pointer}/coordinates"),
            "missing \"coordinates\" member",
        ));
    }
    c
}

fn polygon(value: &Value, pointer: &str, issues: &mut Vec<Issue>) -> Option<Polygon<f64>> {
    let Some(rings) = value.as_array() else {
        issues.push(Issue::new(pointer, "a polygon must be an array of rings"));
        return None;
    };
    if rings.is_empty() {
        issues.push(Issue::new(pointer, "polygon has no rings (empty polygon)"));
        return None;
    }
    let before = issues.len();
    let parsed: Vec<Option<LineString<f64>>> = rings
        .iter()
        .enumerate()
        .map(|(i, r)| ring(r, &format!("{pointer}/{i}"), issues))
        .collect();
    if issues.len() > before {
        return None;
    }
    let mut parsed = parsed.into_iter().flatten();
    let exterior = parsed.next()?;
    Some(Polygon::new(exterior, parsed.collect()))
}

fn ring(value: &Value, pointer: &str, issues: &mut Vec<Issue>) -> Option<LineString<f64>> {
    let Some(positions) = value.as_array() else {
        issues.push(Issue::new(pointer, "a ring must be an array of positions"));
        return None;
    };
    if positions.is_empty() {
        issues.push(Issue::new(pointer, "ring is empty"));
        return None;
    }
    let mut coords: Vec<Coord<f64>> = Vec::with_capacity(positions.len() + 1);
    let mut ok = true;
    for (i, p) in positions.iter().enumerate() {
        match position(p, &format!("{pointer}/{i}"), issues) {
            Some(c) => coords.push(c),
            None => ok = false,
        }
    }
    if !ok {
        return None;
    }
    // Implicitly closed rings are accepted (SPEC §2): close them here.
    if coords.first() != coords.last() {
        coords.push(coords[0]);
    }
    let mut distinct = coords[..coords.len() - 1].to_vec();
    distinct.dedup();
    if distinct.len() > 1 && distinct.first() == distinct.last() {
        distinct.pop();
    }
    if distinct.len() < 3 {
        issues.push(Issue::new(
            pointer,
            &format!(
                "ring is too short: it has {} distinct position(s), a closed ring needs at least 3 \
                 distinct positions (4 with the closing one)",
                distinct.len()
            ),
        ));
        return None;
    }
    Some(LineString::new(coords))
}

pub(super) fn position(
    value: &Value,
    pointer: &str,
    issues: &mut Vec<Issue>,
) -> Option<Coord<f64>> {
    let Some(items) = value.as_array() else {
        issues.push(Issue::new(
            pointer,
            "a position must be an array [lon, lat]",
        ));
        return None;
    };
    if items.len() < 2 || items.len() > 3 {
        issues.push(Issue::new(
            pointer,
            &format!(
                "a position must have 2 or 3 numbers [lon, lat(, height)], found {}",
                items.len()
            ),
        ));
        return None;
    }
    let mut num = |i: usize, name: &str| -> Option<f64> {
        match &items[i] {
            Value::Number(n) => match n.as_f64() {
                Some(v) if v.is_finite() => Some(v),
                _ => {
                    issues.push(Issue::new(
                        &format!("{pointer}/{i}"),
                        &format!("{name} is not a finite number"),
                    ));
                    None
                }
            },
            other => {
                issues.push(Issue::new(
                    &format!("{pointer}/{i}"),
                    &format!("{name} must be a finite number, found {}", json_kind(other)),
                ));
                None
            }
        }
    };
    let lon = num(0, "longitude");
    let lat = num(1, "latitude");
    if items.len() == 3 {
        num(2, "height");
    }
    let (lon, lat) = (lon?, lat?);
    let mut ok = true;
    if !(-180.0..=180.0).contains(&lon) {
        issues.push(Issue::new(
            &format!("{pointer}/0"),
            &format!(
                "longitude {} is outside [-180, 180]",
                crate::num::readable(lon)
            ),
        ));
        ok = false;
    }
    if !(-90.0..=90.0).contains(&lat) {
        issues.push(Issue::new(
            &format!("{pointer}/1"),
            &format!(
                "latitude {} is outside [-90, 90]",
                crate::num::readable(lat)
            ),
        ));
        ok = false;
    }
    ok.then_some(Coord { x: lon, y: lat })
}

fn json_kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn square() -> Value {
        json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.01, 52.0], [5.01, 52.01], [5.0, 52.01], [5.0, 52.0]]]})
    }

    #[test]
    fn reads_polygon_feature_and_collection() {
        assert_eq!(parse_polygons(&square(), "").unwrap().len(), 1);
        let f = json!({"type": "Feature", "properties": {}, "geometry": square()});
        assert_eq!(parse_polygons(&f, "").unwrap().len(), 1);
        let fc = json!({"type": "FeatureCollection", "features": [f.clone(), f]});
        assert_eq!(parse_polygons(&fc, "").unwrap().len(), 2);
        let mp = json!({"type": "MultiPolygon", "coordinates": [square()["coordinates"], square()["coordinates"]]});
        assert_eq!(parse_polygons(&mp, "").unwrap().len(), 2);
    }

    #[test]
    fn closes_implicitly_closed_rings_and_ignores_heights() {
        let v = json!({"type": "Polygon", "coordinates": [[[0.0, 0.0, 3.0], [1.0, 0.0, 3.0], [1.0, 1.0, 3.0]]]});
        let p = &parse_polygons(&v, "").unwrap()[0].polygon;
        assert_eq!(p.exterior().0.len(), 4);
        assert_eq!(p.exterior().0[0], p.exterior().0[3]);
    }

    #[test]
    fn names_the_faulty_member() {
        let v = json!({"type": "Polygon", "coordinates": [[[0.0, 0.0], [1.0, 95.0], [1.0, 1.0], [0.0, 0.0]]]});
        let e = parse_polygons(&v, "/roi").unwrap_err();
        assert_eq!(e[0].pointer, "/roi/coordinates/0/1/1");
        assert!(e[0].message.contains("latitude 95"), "{e:?}");

        let v = json!({"type": "Polygon", "coordinates": [[[0.0, 0.0], [1.0, "NaN"], [1.0, 1.0]]]});
        let e = parse_polygons(&v, "").unwrap_err();
        assert_eq!(e[0].pointer, "/coordinates/0/1/1");
        assert!(e[0].message.contains("finite number"));

        let v = json!({"type": "Polygon", "coordinates": [[]]});
        assert!(
            parse_polygons(&v, "").unwrap_err()[0]
                .message
                .contains("empty")
        );

        let v = json!({"type": "Polygon", "coordinates": [[[0.0, 0.0], [1.0, 1.0], [0.0, 0.0]]]});
        assert!(
            parse_polygons(&v, "").unwrap_err()[0]
                .message
                .contains("too short")
        );

        let v = json!({"type": "Circle", "coordinates": []});
        let e = parse_polygons(&v, "").unwrap_err();
        assert_eq!(e[0].pointer, "/type");
        assert!(e[0].message.contains("unknown GeoJSON type"));

        let v = json!({"type": "LineString", "coordinates": [[0.0, 0.0], [1.0, 1.0]]});
        assert!(
            parse_polygons(&v, "").unwrap_err()[0]
                .message
                .contains("not an area")
        );
    }
}
