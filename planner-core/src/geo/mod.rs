//! Geometry input: GeoJSON parsing, validation with precise messages, and
//! projection to the UTM zone of the ROI centroid (SPEC §2).

mod clearance;
mod corridor;
mod geojson_input;
mod utm;
mod validate;

pub use clearance::{distance_to_zones, fill_enclosed, keep_out_area};
pub use corridor::{ParsedLine, parse_line, prepare_corridor};
pub use geojson_input::{ParsedPolygon, parse_polygons};
pub use utm::{MAX_OFFSET_FROM_CENTRAL_MERIDIAN_DEG, UtmProjection};
pub use validate::polygon_issues;

use geo::{Area, Centroid, CoordsIter, Orient, orient::Direction};
use geo_types::{MultiPolygon, Polygon};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use serde_path_to_error::Segment;

/// One fault in the input: the JSON pointer of the member at fault and what
/// is wrong with it (the `{pointer, message}` entries of SPEC §2).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Issue {
    pub pointer: String,
    pub message: String,
}

impl Issue {
    pub fn new(pointer: &str, message: &str) -> Self {
        Issue {
            pointer: pointer.to_string(),
            message: message.to_string(),
        }
    }
}

/// `token` escaped as one reference token of a JSON pointer (RFC 6901:
/// `~` as `~0`, then `/` as `~1`).
pub fn escape_pointer_token(token: &str) -> String {
    token.replace('~', "~0").replace('/', "~1")
}

/// `value` deserialized as a `T`; a fault (unknown field, wrong type,
/// missing member) is an [`Issue`] at the JSON pointer of the member at
/// fault, under `prefix` (e.g. `"/options"`; `""` for the document).
pub fn deserialize_at<T: DeserializeOwned>(value: &Value, prefix: &str) -> Result<T, Issue> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let mut pointer = prefix.to_string();
        for segment in e.path().iter() {
            match segment {
                Segment::Seq { index } => pointer.push_str(&format!("/{index}")),
                Segment::Map { key } | Segment::Enum { variant: key } => {
                    pointer.push('/');
                    pointer.push_str(&escape_pointer_token(key));
                }
                Segment::Unknown => {}
            }
        }
        Issue::new(&pointer, &e.into_inner().to_string())
    })
}

/// Most faults listed for one request: a request with thousands of bad
/// members gets the first ones and a count, not a body as large as itself.
pub const MAX_ISSUES: usize = 100;

/// `issues` cut to [`MAX_ISSUES`]: the first `MAX_ISSUES - 1` and one more
/// saying how many were left out.
pub fn cap_issues(mut issues: Vec<Issue>) -> Vec<Issue> {
    if issues.len() > MAX_ISSUES {
        let left_out = issues.len() - (MAX_ISSUES - 1);
        issues.truncate(MAX_ISSUES - 1);
        issues.push(Issue::new(
            "",
            &format!(
                "and {left_out} more problems (only the first {} are listed)",
                MAX_ISSUES - 1
            ),
        ));
    }
    issues
}

impl std::fmt::Display for Issue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.pointer.is_empty() {
            f.write_str(&self.message)
        } else {
            write!(f, "{}: {}", self.pointer, self.message)
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GeoError {
    #[error("{}", join_issues(.0))]
    Invalid(Vec<Issue>),
    #[error("latitude {} is outside UTM coverage (80°S to 84°N)", crate::num::readable(*.lat))]
    OutsideUtm { lat: f64 },
    #[error("coordinate transformation failed: {0}")]
    Projection(String),
    /// Stopped by its cancellation token (see [`crate::cancel`]).
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
}

pub(crate) fn join_issues(issues: &[Issue]) -> String {
    issues
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("; ")
}

/// Size limits on input geometry; all configurable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Limits {
    /// Largest ROI area accepted, km².
    pub max_roi_area_km2: f64,
    /// Most vertices accepted over the ROI and all NFZs together.
    pub max_vertices: usize,
    /// Most no-fly zones accepted.
    pub max_no_fly_zones: usize,
    /// Most survey-lane kilometres (free area / line spacing) one plan may
    /// need: bounds the planner's time and memory for tiny spacings.
    pub max_lane_km: f64,
    /// Most Features one `photos.geojson` holds; beyond it every k-th
    /// photo is written (the file says so).
    pub max_photo_features: usize,
}

/// Most Features one `photos.geojson` holds by default (about 400 bytes
/// each: some 20 MB).
pub const DEFAULT_MAX_PHOTO_FEATURES: usize = 50_000;

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_roi_area_km2: 100.0,
            max_vertices: 50_000,
            max_no_fly_zones: 5_000,
            max_lane_km: 10_000.0,
            max_photo_features: DEFAULT_MAX_PHOTO_FEATURES,
        }
    }
}

/// The validated survey area, in WGS84 and projected to UTM metres. All
/// exteriors are counter-clockwise, holes clockwise.
#[derive(Debug)]
pub struct SurveyArea {
    pub projection: UtmProjection,
    pub roi_wgs84: MultiPolygon<f64>,
    pub no_fly_wgs84: Vec<Polygon<f64>>,
    pub roi: MultiPolygon<f64>,
    pub no_fly: Vec<Polygon<f64>>,
}

/// Validate an ROI and its no-fly zones and project them to the UTM zone of
/// the ROI centroid. Every fault found is reported, each with its pointer.
pub fn prepare_area(
    roi: &[ParsedPolygon],
    no_fly: &[ParsedPolygon],
    roi_pointer: &str,
    no_fly_pointer: &str,
    limits: &Limits,
) -> Result<SurveyArea, GeoError> {
    let mut issues = limit_issues(roi, no_fly, roi_pointer, no_fly_pointer, limits);
    if !issues.is_empty() {
        return Err(GeoError::Invalid(issues));
    }
    issues.extend(polygon_issues_all(roi, no_fly)?);
    if !issues.is_empty() {
        return Err(GeoError::Invalid(issues));
    }

    let roi_wgs84 = MultiPolygon(
        roi.iter()
            .map(|p| p.polygon.orient(Direction::Default))
            .collect::<Vec<_>>(),
    );
    let no_fly_wgs84: Vec<Polygon<f64>> = no_fly
        .iter()
        .map(|p| p.polygon.orient(Direction::Default))
        .collect();
    let centroid = roi_wgs84
        .centroid()
        .ok_or_else(|| GeoError::Invalid(vec![Issue::new(roi_pointer, "the ROI has no area")]))?;
    let projection = UtmProjection::for_lonlat(centroid.0)?;

    issues.extend(zone_width_issues(roi, &projection));
    if !issues.is_empty() {
        return Err(GeoError::Invalid(issues));
    }

    let roi_utm = MultiPolygon(
        roi_wgs84
            .0
            .iter()
            .map(|p| projection.polygon_to_utm(p))
            .collect::<Result<Vec<_>, _>>()?,
    );
    let no_fly_utm = no_fly_wgs84
        .iter()
        .map(|p| projection.polygon_to_utm(p))
        .collect::<Result<Vec<_>, _>>()?;

    check_area(&roi_utm, roi_pointer, limits)?;
    Ok(SurveyArea {
        projection,
        roi_wgs84,
        no_fly_wgs84,
        roi: roi_utm,
        no_fly: no_fly_utm,
    })
}

/// The request-size limits: an ROI polygon at all, the number of no-fly
/// zones and the vertex count.
fn limit_issues(
    roi: &[ParsedPolygon],
    no_fly: &[ParsedPolygon],
    roi_pointer: &str,
    no_fly_pointer: &str,
    limits: &Limits,
) -> Vec<Issue> {
    let mut issues = Vec::new();
    if roi.is_empty() {
        issues.push(Issue::new(
            roi_pointer,
            "the region of interest has no polygon",
        ));
    }
    if no_fly.len() > limits.max_no_fly_zones {
        issues.push(Issue::new(
            no_fly_pointer,
            &format!(
                "{} no-fly zones exceed the limit of {}",
                no_fly.len(),
                limits.max_no_fly_zones
            ),
        ));
    }
    let vertices: usize = roi
        .iter()
        .chain(no_fly)
        .map(|p| p.polygon.coords_count())
        .sum();
    if vertices > limits.max_vertices {
        issues.push(Issue::new(
            roi_pointer,
            &format!(
                "{vertices} vertices in the ROI and no-fly zones exceed the limit of {}",
                limits.max_vertices
            ),
        ));
    }
    issues
}

/// The faults of every ROI and no-fly polygon, checking for cancellation
/// before each polygon and after the last.
fn polygon_issues_all(
    roi: &[ParsedPolygon],
    no_fly: &[ParsedPolygon],
) -> Result<Vec<Issue>, GeoError> {
    let mut issues = Vec::new();
    for p in roi.iter().chain(no_fly) {
        crate::cancel::check()?;
        issues.extend(polygon_issues(&p.polygon, &p.pointer));
    }
    crate::cancel::check()?;
    Ok(issues)
}

/// ROI vertices too far from the central meridian of `projection` for one
/// UTM zone, one issue per polygon.
fn zone_width_issues(roi: &[ParsedPolygon], projection: &UtmProjection) -> Vec<Issue> {
    let mut issues = Vec::new();
    let cm = projection.central_meridian();
    for p in roi {
        if let Some(c) = p.polygon.exterior().0.iter().find(|c| {
            let mut d = (c.x - cm).abs();
            if d > 180.0 {
                d = 360.0 - d;
            }
            d > MAX_OFFSET_FROM_CENTRAL_MERIDIAN_DEG
        }) {
            issues.push(Issue::new(
                &p.pointer,
                &format!(
                    "the ROI is too wide for one UTM zone: longitude {:.6} is more than {}° from \
                     the central meridian {}° of zone {} (EPSG:{}); split the area",
                    c.x,
                    MAX_OFFSET_FROM_CENTRAL_MERIDIAN_DEG,
                    cm,
                    projection.zone(),
                    projection.epsg()
                ),
            ));
        }
    }
    issues
}

/// The projected ROI's area must be positive and within the limit.
fn check_area(
    roi_utm: &MultiPolygon<f64>,
    roi_pointer: &str,
    limits: &Limits,
) -> Result<(), GeoError> {
    let area_km2 = roi_utm.unsigned_area() / 1e6;
    if area_km2 > limits.max_roi_area_km2 {
        return Err(GeoError::Invalid(vec![Issue::new(
            roi_pointer,
            &format!(
                "the ROI is too large: {area_km2:.2} km² exceeds the limit of {} km²",
                limits.max_roi_area_km2
            ),
        )]));
    }
    if area_km2 <= 0.0 {
        return Err(GeoError::Invalid(vec![Issue::new(
            roi_pointer,
            "the ROI has no area",
        )]));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn parsed(v: serde_json::Value, ptr: &str) -> Vec<ParsedPolygon> {
        parse_polygons(&v, ptr).unwrap()
    }

    #[test]
    fn projects_and_orients() {
        // Clockwise ring in, CCW out.
        let roi = parsed(
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.0, 52.01], [5.01, 52.01], [5.01, 52.0]]]}),
            "/roi",
        );
        let area = prepare_area(&roi, &[], "/roi", "/no_fly", &Limits::default()).unwrap();
        assert_eq!(area.projection.epsg(), 32631);
        let a = area.roi.unsigned_area();
        // 0.01° × 0.01° at 52°N ≈ 686 m × 1113 m.
        assert!((a - 763_600.0).abs() / a < 0.01, "{a}");
        assert!(area.roi.0[0].signed_area() > 0.0);
    }

    #[test]
    fn rejects_large_and_wide_rois() {
        let big = parsed(
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.2, 52.0], [5.2, 52.2], [5.0, 52.2]]]}),
            "/roi",
        );
        let e = prepare_area(&big, &[], "/roi", "/no_fly", &Limits::default()).unwrap_err();
        assert!(e.to_string().contains("too large"), "{e}");
        let limits = Limits {
            max_roi_area_km2: 1e6,
            ..Limits::default()
        };
        let wide = parsed(
            json!({"type": "Polygon", "coordinates": [[[0.5, 10.0], [9.5, 10.0], [9.5, 10.001], [0.5, 10.001]]]}),
            "/roi",
        );
        let e = prepare_area(&wide, &[], "/roi", "/no_fly", &limits).unwrap_err();
        assert!(e.to_string().contains("too wide for one UTM zone"), "{e}");
    }

    #[test]
    fn rejects_self_intersection_with_pointer() {
        let roi = parsed(
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.01, 52.01], [5.01, 52.0], [5.0, 52.01]]]}),
            "/roi",
        );
        let GeoError::Invalid(issues) =
            prepare_area(&roi, &[], "/roi", "/no_fly", &Limits::default()).unwrap_err()
        else {
            panic!("expected validation issues");
        };
        assert_eq!(issues[0].pointer, "/roi/coordinates/0");
        assert!(issues[0].message.contains("self-intersects"));
    }

    #[test]
    fn serde_faults_are_named_by_escaped_pointers() {
        use std::collections::BTreeMap;

        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Inner {
            speed: f64,
        }
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        #[allow(dead_code)]
        struct Outer {
            items: Vec<Inner>,
            #[serde(default)]
            named: BTreeMap<String, Inner>,
        }
        let fault =
            |v: serde_json::Value, prefix: &str| deserialize_at::<Outer>(&v, prefix).unwrap_err();
        // Plain names: the same pointer a path joined with '/' gives.
        let e = fault(json!({"items": [{"speed": 1}, {"speed": "x"}]}), "/options");
        assert_eq!(e.pointer, "/options/items/1/speed");
        assert!(e.message.contains("invalid type"), "{}", e.message);
        let e = fault(json!({"items": [], "extra": 1}), "");
        // An unknown member is named by its own pointer.
        assert_eq!(e.pointer, "/extra", "{e:?}");
        assert!(e.message.contains("unknown field `extra`"), "{}", e.message);
        // RFC 6901: '~' and '/' in a member name are escaped, '~' first.
        let e = fault(
            json!({"items": [], "named": {"a/b~c": {"speed": true}}}),
            "/o",
        );
        assert_eq!(e.pointer, "/o/named/a~1b~0c/speed");
        assert_eq!(escape_pointer_token("~1/"), "~01~1");
        assert_eq!(escape_pointer_token("plain"), "plain");
        assert!(deserialize_at::<Outer>(&json!({"items": []}), "/x").is_ok());
    }
}
