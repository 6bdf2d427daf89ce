//! Corridor input: the centre line (a GeoJSON LineString in WGS84 lon/lat)
//! read and checked with precise pointers, and the corridor polygon (its
//! flat-capped buffer) made the survey area in UTM metres.

use geo::{Centroid, Orient, orient::Direction};
use geo_types::{Coord, Line, LineString, MultiPolygon, Point, Polygon};
use rstar::{AABB, RTree, RTreeObject};
use serde_json::Value;

use super::{
    GeoError, Issue, Limits, ParsedPolygon, SurveyArea, UtmProjection, check_area, limit_issues,
    polygon_issues_all, zone_width_issues,
};
use crate::coverage::corridor_polygon;

/// A corridor's centre line as given, with the JSON pointer of its
/// `coordinates`: consecutive repeated positions are dropped (as in ROI
/// rings), so every segment has a length.
#[derive(Clone, Debug, PartialEq)]
pub struct ParsedLine {
    pub line: LineString<f64>,
    pub pointer: String,
}

/// The centre line read from a GeoJSON `LineString`, or a `Feature` or
/// one-feature `FeatureCollection` holding one, at `pointer`.
pub fn parse_line(value: &Value, pointer: &str) -> Result<ParsedLine, Vec<Issue>> {
    let fault = |p: &str, m: &str| Err(vec![Issue::new(p, m)]);
    let Some(obj) = value.as_object() else {
        return fault(pointer, "must be a GeoJSON LineString object");
    };
    match obj.get("type").and_then(Value::as_str) {
        Some("LineString") => {}
        Some("Feature") => {
            return match obj.get("geometry") {
                Some(g) if g.is_object() => parse_line(g, &format!("{pointer}/geometry")),
                _ => fault(
                    &format!("{pointer}/geometry"),
                    "Feature has no LineString geometry",
                ),
            };
        }
        Some("FeatureCollection") => {
            return match obj.get("features").and_then(Value::as_array) {
                Some(f) if f.len() == 1 => parse_line(&f[0], &format!("{pointer}/features/0")),
                _ => fault(
                    &format!("{pointer}/features"),
                    "a corridor is one LineString: give a FeatureCollection with exactly one \
                     feature, or the LineString itself",
                ),
            };
        }
        Some(other) => {
            return fault(
                &format!("{pointer}/type"),
                &format!("geometry type {other:?} is not a line: expected LineString"),
            );
        }
        None => {
            return fault(
                &format!("{pointer}/type"),
                "missing GeoJSON \"type\" member",
            );
        }
    }
    let ptr = format!("{pointer}/coordinates");
    let Some(positions) = obj.get("coordinates").and_then(Value::as_array) else {
        return fault(&ptr, "must be an array of [lon, lat] positions");
    };
    let mut issues = Vec::new();
    let mut coords: Vec<Coord<f64>> = Vec::with_capacity(positions.len());
    for (i, p) in positions.iter().enumerate() {
        if let Some(c) = super::geojson_input::position(p, &format!("{ptr}/{i}"), &mut issues) {
            coords.push(c);
        }
    }
    if !issues.is_empty() {
        return Err(issues);
    }
    coords.dedup();
    if coords.len() < 2 {
        return fault(
            &ptr,
            &format!(
                "the line has {} distinct position(s): a corridor's centre line needs at least 2 \
                 (a line of no length has no direction to lay lanes along)",
                coords.len()
            ),
        );
    }
    let line = LineString::new(coords);
    if let Some(issue) = crossing_issue(&line, &ptr) {
        return Err(vec![issue]);
    }
    Ok(ParsedLine { line, pointer: ptr })
}

struct Segment {
    index: usize,
    line: Line<f64>,
}

impl RTreeObject for Segment {
    type Envelope = AABB<[f64; 2]>;
    fn envelope(&self) -> Self::Envelope {
        AABB::from_corners(
            [self.line.start.x, self.line.start.y],
            [self.line.end.x, self.line.end.y],
        )
    }
}

/// The first place where the line crosses or touches itself (apart from
/// neighbouring segments sharing their vertex): its corridor would cover
/// the same ground twice, in lanes that cross.
fn crossing_issue(line: &LineString<f64>, pointer: &str) -> Option<Issue> {
    use geo::line_intersection::{LineIntersection, line_intersection};
    let tree = RTree::bulk_load(
        line.lines()
            .enumerate()
            .map(|(index, line)| Segment { index, line })
            .collect(),
    );
    for a in tree.iter() {
        for b in tree.locate_in_envelope_intersecting(&a.envelope()) {
            if b.index <= a.index {
                continue;
            }
            let hit = match line_intersection(a.line, b.line)? {
                LineIntersection::SinglePoint { intersection, .. } => {
                    if b.index == a.index + 1 && intersection == a.line.end {
                        continue;
                    }
                    intersection
                }
                LineIntersection::Collinear { intersection } => intersection.start,
            };
            return Some(Issue::new(
                pointer,
                &format!(
                    "the line crosses itself at ({:.8}, {:.8}): segment {} meets segment {}; a \
                     corridor would cover that ground twice (split it into two corridors)",
                    hit.x, hit.y, a.index, b.index
                ),
            ));
        }
    }
    None
}

/// The corridor as a survey area: the line projected to the UTM zone of
/// its centroid, its flat-capped buffer `width_m` wide as the ROI, and the
/// no-fly zones checked and projected as for an area. The buffer is made
/// here, not given, so only the line and the zones are checked (a buffer
/// taken back to lon/lat may touch itself by rounding where arcs meet).
/// Faults of the line or of the corridor (too large, too wide for a UTM
/// zone) are reported at the line's pointer. Returns the area and the
/// centre line in its UTM metres.
pub fn prepare_corridor(
    centre: &ParsedLine,
    width_m: f64,
    no_fly: &[ParsedPolygon],
    no_fly_pointer: &str,
    limits: &Limits,
) -> Result<(SurveyArea, LineString<f64>), GeoError> {
    let ptr = &centre.pointer;
    let as_roi = ParsedPolygon {
        // Only its vertices are looked at: the count and the zone width.
        polygon: Polygon::new(centre.line.clone(), vec![]),
        pointer: ptr.clone(),
    };
    let roi = std::slice::from_ref(&as_roi);
    let mut issues = limit_issues(roi, no_fly, ptr, no_fly_pointer, limits);
    if issues.is_empty() {
        issues.extend(polygon_issues_all(&[], no_fly)?);
    }
    let centroid = centre.line.centroid().unwrap_or(Point(centre.line.0[0]));
    let projection = UtmProjection::for_lonlat(centroid.0).map_err(|e| match e {
        GeoError::OutsideUtm { .. } => GeoError::Invalid(vec![Issue::new(ptr, &e.to_string())]),
        other => other,
    })?;
    issues.extend(zone_width_issues(roi, &projection));
    if !issues.is_empty() {
        return Err(GeoError::Invalid(issues));
    }
    let line = project_line(&centre.line, &projection)?;
    if line.0.len() < 2 {
        return Err(GeoError::Invalid(vec![Issue::new(
            ptr,
            "the line is shorter than a millimetre",
        )]));
    }
    // Exteriors counter-clockwise, holes clockwise, as SurveyArea promises.
    let corridor = corridor_polygon(&line, width_m).orient(Direction::Default);
    check_area(&corridor, ptr, limits)?;
    let no_fly_wgs84: Vec<Polygon<f64>> = no_fly
        .iter()
        .map(|p| p.polygon.orient(Direction::Default))
        .collect();
    let no_fly_utm = no_fly_wgs84
        .iter()
        .map(|p| projection.polygon_to_utm(p))
        .collect::<Result<Vec<_>, _>>()?;
    let roi_wgs84 = MultiPolygon(
        corridor
            .0
            .iter()
            .map(|p| projection.polygon_to_wgs84(p))
            .collect::<Result<Vec<_>, _>>()?,
    );
    let area = SurveyArea {
        projection,
        roi_wgs84,
        no_fly_wgs84,
        roi: corridor,
        no_fly: no_fly_utm,
    };
    Ok((area, line))
}

fn project_line(line: &LineString<f64>, proj: &UtmProjection) -> Result<LineString<f64>, GeoError> {
    let mut pts: Vec<Coord<f64>> = line
        .0
        .iter()
        .map(|&c| proj.to_utm(c))
        .collect::<Result<_, _>>()?;
    // Positions a millimetre apart are one: a segment needs a direction.
    pts.dedup_by(|b, a| (b.x - a.x).hypot(b.y - a.y) < 1e-3);
    Ok(LineString::new(pts))
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::Area;
    use serde_json::json;

    #[test]
    fn reads_lines_and_names_faults() {
        let l = json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.0, 52.0], [5.01, 52.0, 3.0]]});
        let p = parse_line(&l, "/corridor").unwrap();
        assert_eq!(p.line.0.len(), 2, "the repeated position is dropped");
        assert_eq!(p.pointer, "/corridor/coordinates");
        let f = json!({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, "geometry": l}]});
        assert_eq!(
            parse_line(&f, "/corridor").unwrap().pointer,
            "/corridor/features/0/geometry/coordinates"
        );
        let e = parse_line(
            &json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.0, 52.0]]}),
            "/corridor",
        )
        .unwrap_err();
        assert_eq!(e[0].pointer, "/corridor/coordinates");
        assert!(e[0].message.contains("1 distinct position"), "{e:?}");
        let e = parse_line(
            &json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.0, 95.0]]}),
            "/corridor",
        )
        .unwrap_err();
        assert_eq!(e[0].pointer, "/corridor/coordinates/1/1");
        let e =
            parse_line(&json!({"type": "Polygon", "coordinates": []}), "/corridor").unwrap_err();
        assert_eq!(e[0].pointer, "/corridor/type");
        let bow = json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.01, 52.01], [5.01, 52.0], [5.0, 52.01]]});
        let e = parse_line(&bow, "/corridor").unwrap_err();
        assert!(e[0].message.contains("crosses itself"), "{e:?}");
    }

    #[test]
    fn corridor_area_is_the_buffer_in_utm() {
        // About 686 m east at 52°N, 100 m wide.
        let l = json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.01, 52.0]]});
        let p = parse_line(&l, "/corridor").unwrap();
        let (area, line) =
            prepare_corridor(&p, 100.0, &[], "/no_fly_zones", &Limits::default()).unwrap();
        assert_eq!(area.projection.epsg(), 32631);
        let len = (line.0[1].x - line.0[0].x).hypot(line.0[1].y - line.0[0].y);
        let a = area.roi.unsigned_area();
        assert!((a - 100.0 * len).abs() < 1.0, "{a} vs {}", 100.0 * len);
        assert!(area.roi.0[0].signed_area() > 0.0, "counter-clockwise");
        let limits = Limits {
            max_roi_area_km2: 0.01,
            ..Limits::default()
        };
        let GeoError::Invalid(e) = prepare_corridor(&p, 100.0, &[], "/nfz", &limits).unwrap_err()
        else {
            panic!("too large must be refused");
        };
        assert_eq!(e[0].pointer, "/corridor/coordinates");
        assert!(e[0].message.contains("too large"), "{e:?}");
    }
}
