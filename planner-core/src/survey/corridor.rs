//! Corridor surveys: the `corridor` member read next to `roi` (exclusive
//! with it), `corridor_width_m` checked, and the corridor's cells and lanes
//! laid in place of an area's decomposition.

use geo_types::{Coord, LineString, MultiPolygon, Polygon};
use serde_json::{Map, Value};

use super::cells::Decomposition;
use super::request::{
    NO_FLY_POINTER, PlanError, ROI_POINTER, SurveyParams, SurveyRequest, check_range,
};
use crate::coverage::{self, CorridorError};
use crate::geo::{
    Issue, Limits, ParsedLine, ParsedPolygon, SurveyArea, parse_line, prepare_area,
    prepare_corridor,
};

/// JSON pointer of the corridor's centre line in a request document.
pub const CORRIDOR_POINTER: &str = "/corridor";
/// Allowed corridor widths, m.
pub const CORRIDOR_WIDTH_RANGE_M: (f64, f64) = (1.0, 2000.0);

/// The `corridor` member of a request document, if given, and the faults
/// of the choice between it and `roi`: exactly one of them is required.
pub(super) fn read_corridor(
    obj: &Map<String, Value>,
    issues: &mut Vec<Issue>,
) -> Option<ParsedLine> {
    let corridor = obj.get("corridor").filter(|v| !v.is_null());
    let width = obj.get("corridor_width_m").filter(|v| !v.is_null());
    match (obj.contains_key("roi"), corridor.is_some()) {
        (true, true) => {
            let m = "give roi (an area) or corridor (a line), not both";
            issues.push(Issue::new(ROI_POINTER, m));
            issues.push(Issue::new(CORRIDOR_POINTER, m));
            return None;
        }
        (false, false) => {
            issues.push(Issue::new(
                ROI_POINTER,
                "missing: the region of interest (GeoJSON) is required, or a corridor",
            ));
            issues.push(Issue::new(
                CORRIDOR_POINTER,
                "missing: give roi (a GeoJSON area) or corridor (a GeoJSON LineString) with \
                 corridor_width_m",
            ));
            return None;
        }
        _ => {}
    }
    match (corridor, width) {
        (Some(_), None) => issues.push(Issue::new(
            "/corridor_width_m",
            "missing: a corridor needs its width in metres",
        )),
        (None, Some(_)) => issues.push(Issue::new(
            "/corridor_width_m",
            "a width is only for a corridor: give corridor, or leave corridor_width_m out",
        )),
        _ => {}
    }
    let line = corridor?;
    parse_line(line, CORRIDOR_POINTER)
        .map_err(|e| issues.extend(e))
        .ok()
}

impl SurveyParams {
    /// `corridor_width_m` within [`CORRIDOR_WIDTH_RANGE_M`].
    pub(super) fn check_corridor(&self, issues: &mut Vec<Issue>, p: &dyn Fn(&str) -> String) {
        if let Some(w) = self.corridor_width_m {
            let (lo, hi) = CORRIDOR_WIDTH_RANGE_M;
            check_range(issues, &p("corridor_width_m"), w, lo, hi, false);
        }
    }
}

/// A request's area: its ROI; or its corridor's polygon, with the centre
/// line (UTM) and width to lay the lanes along, and the request with that
/// polygon as its ROI for the stages that read the ROI as given.
pub(super) struct Prepared {
    pub area: SurveyArea,
    pub centre: Option<(LineString<f64>, f64)>,
    pub as_area: Option<SurveyRequest>,
}

pub(super) fn prepare(req: &SurveyRequest, limits: &Limits) -> Result<Prepared, PlanError> {
    let Some(line) = &req.corridor else {
        let area = prepare_area(&req.roi, &req.no_fly, ROI_POINTER, NO_FLY_POINTER, limits)?;
        return Ok(Prepared {
            area,
            centre: None,
            as_area: None,
        });
    };
    let width = req.params.corridor_width_m.ok_or_else(|| {
        PlanError::Invalid(vec![Issue::new(
            "/corridor_width_m",
            "missing: a corridor needs its width in metres",
        )])
    })?;
    let (area, centre) = prepare_corridor(line, width, &req.no_fly, NO_FLY_POINTER, limits)?;
    // A UAV given no start takes off at the ROI's first vertex: here a
    // corner of the corridor's start, not wherever the buffer's ring begins.
    let roi = area
        .roi_wgs84
        .0
        .iter()
        .map(|p| ParsedPolygon {
            polygon: starting_near(p, line.line.0[0]),
            pointer: line.pointer.clone(),
        })
        .collect();
    let as_area = SurveyRequest {
        roi,
        corridor: None,
        no_fly: req.no_fly.clone(),
        params: req.params.clone(),
    };
    Ok(Prepared {
        area,
        centre: Some((centre, width)),
        as_area: Some(as_area),
    })
}

/// `p` with its exterior ring starting at its vertex nearest `at`.
fn starting_near(p: &Polygon<f64>, at: Coord<f64>) -> Polygon<f64> {
    let ring = &p.exterior().0;
    let open = &ring[..ring.len().saturating_sub(1)];
    let d = |c: &Coord<f64>| (c.x - at.x).hypot(c.y - at.y);
    let Some(i) = (0..open.len()).min_by(|&a, &b| d(&open[a]).total_cmp(&d(&open[b]))) else {
        return p.clone();
    };
    let mut rotated: Vec<Coord<f64>> = open[i..].iter().chain(&open[..i]).copied().collect();
    rotated.push(rotated[0]);
    Polygon::new(LineString::new(rotated), p.interiors().to_vec())
}

/// The corridor's cells and lanes: lanes along `centre` (UTM) across
/// `width_m`, inside `flyable`, at most `spacing_m` apart.
pub(super) fn lay_corridor(
    centre: &LineString<f64>,
    width_m: f64,
    flyable: &MultiPolygon<f64>,
    spacing_m: f64,
) -> Result<Decomposition, PlanError> {
    let free_space = coverage::FreeSpace::new(flyable);
    let laid = coverage::corridor_cells(centre, width_m, spacing_m, flyable, &free_space).map_err(
        |e| match e {
            CorridorError::Cancelled(c) => PlanError::Cancelled(c),
            other => PlanError::Invalid(vec![Issue::new(CORRIDOR_POINTER, &other.to_string())]),
        },
    )?;
    if laid.plans.iter().all(|p| p.lanes.is_empty()) {
        return Err(PlanError::Invalid(vec![Issue::new(
            CORRIDOR_POINTER,
            "no lane of the corridor lies clear of the no-fly zones: nothing to survey",
        )]));
    }
    let direction = laid.plans.first().map_or(0.0, |p| p.direction_deg);
    Ok(Decomposition {
        slice_angle_deg: direction,
        joined: vec![false; laid.cells.len()],
        cells: laid.cells,
        plans: laid.plans,
        along_line: true,
        on_grid: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::Limits;
    use crate::survey::{SurveyRequest, plan_survey};
    use serde_json::json;

    fn line() -> Value {
        // About 700 m east, then 400 m north-east, at 52°N.
        json!({"type": "LineString", "coordinates": [[5.0, 52.0], [5.01, 52.0], [5.014, 52.0025]]})
    }

    fn pointers(doc: Value) -> Vec<String> {
        match SurveyRequest::from_document(&doc) {
            Err(PlanError::Invalid(i)) => i.into_iter().map(|i| i.pointer).collect(),
            other => panic!("expected a fault, got {other:?}"),
        }
    }

    #[test]
    fn corridor_and_roi_are_exclusive_and_the_width_checked() {
        let roi =
            json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.01, 52.0], [5.01, 52.01]]]});
        assert_eq!(
            pointers(json!({"roi": roi, "corridor": line(), "corridor_width_m": 50})),
            ["/roi", "/corridor"]
        );
        assert_eq!(pointers(json!({"altitude_m": 50})), ["/roi", "/corridor"]);
        assert_eq!(pointers(json!({"corridor": line()})), ["/corridor_width_m"]);
        assert_eq!(
            pointers(json!({"roi": roi, "corridor_width_m": 50})),
            ["/corridor_width_m"]
        );
        assert_eq!(
            pointers(json!({"corridor": line(), "corridor_width_m": 0.5})),
            ["/corridor_width_m"]
        );
        let bad = json!({"type": "LineString", "coordinates": [[5.0, 52.0]]});
        assert_eq!(
            pointers(json!({"corridor": bad, "corridor_width_m": 50})),
            ["/corridor/coordinates"]
        );
    }

    /// Planes fly corridors: the 34° bend of the line rounded on an arc
    /// of the turn radius with the camera off, every lane entered straight.
    #[test]
    fn planes_fly_a_corridor_round_its_bend() {
        for plane in ["fixed_wing", "vtol"] {
            let doc = json!({"corridor": line(), "corridor_width_m": 120, "altitude_m": 80,
                "aircraft": {"type": plane}});
            let req = SurveyRequest::from_document(&doc).unwrap();
            let plan = plan_survey(&req, &Limits::default()).unwrap();
            let s = &plan.stats;
            // 120 m at a spacing of 36 m: 4 lanes of two legs each (the
            // outer ones' round outsides a chord more where it fits a camera
            // stretch), every leg flown (no zones to pull back from).
            assert!((8..=12).contains(&s.lane_count), "{plane}: {s:?}");
            // The camera is off round the bend (the strips of the legs
            // beside it, flat-ended, leave a wedge there; measured 94.6 %
            // at the VTOL's 60 m radius).
            assert!(s.coverage_ratio > 0.93, "{plane}: {s:?}");
            let lanes = plan.uavs[0].stats.survey_length_m;
            assert!(s.length_m > lanes * 1.2, "{plane}: {s:?}");
        }
    }

    #[test]
    fn plans_a_corridor_round_a_crossing_zone() {
        // A zone right across the first leg, 200 m wide along it.
        let nfz = json!({"type": "Polygon", "coordinates": [[[5.004, 51.999], [5.007, 51.999], [5.007, 52.001], [5.004, 52.001]]]});
        let mut doc = json!({"corridor": line(), "corridor_width_m": 80, "altitude_m": 50,
            "no_fly_zones": [nfz], "uavs": [{"id": "a", "start": [5.0, 52.0]}, {"id": "b", "start": [5.014, 52.0025]}]});
        let req = SurveyRequest::from_document(&doc).unwrap();
        let plan = plan_survey(&req, &Limits::default()).unwrap();
        // The lanes stop nfz_clearance_m short of the zone: the swaths
        // miss those strips (80 m × 5 m on each side) and no more.
        let s = &plan.stats;
        let strips = 2.0 * 80.0 * 5.0 / s.free_area_m2;
        assert!(s.coverage_ratio > 0.998 - strips, "{s:?}");
        // Without the clearance they reach the zone: all covered.
        doc["nfz_clearance_m"] = json!(0);
        let req = SurveyRequest::from_document(&doc).unwrap();
        let plan = plan_survey(&req, &Limits::default()).unwrap();
        assert!(plan.stats.coverage_ratio > 0.998, "{:?}", plan.stats);
        // The corridor split in two, one on each side of the zone.
        assert_eq!(plan.cells.len(), 2, "{:?}", plan.cells);
        // Corridor area: about 80 m × 1 km, minus nothing (the zone is
        // subtracted from the free area only).
        let a = plan.stats.area_m2;
        assert!(a > 80.0 * 1000.0 && a < 80.0 * 1200.0, "{a}");
        assert!(plan.stats.free_area_m2 < a - 80.0 * 190.0);
        assert!(plan.uavs.iter().all(|u| !u.sorties.is_empty()));
        // No UAV given: one takes off at a corner of the corridor's start,
        // 40 m (half the width) from the line's first point.
        doc.as_object_mut().unwrap().remove("uavs");
        let req = SurveyRequest::from_document(&doc).unwrap();
        let plan = plan_survey(&req, &Limits::default()).unwrap();
        let [lon, lat] = plan.uavs[0].start;
        let m =
            ((lon - 5.0) * 111_320.0 * 52f64.to_radians().cos()).hypot((lat - 52.0) * 111_250.0);
        assert!((m - 40.0).abs() < 1.0, "{m} m from the line's start");
    }
}
