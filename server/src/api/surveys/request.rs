//! The survey request document as the service takes it: the planner's
//! document (area, no-fly zones, parameters) plus `dem_id`, the id of a
//! DEM stored in the service, which the planner does not know: it is read
//! here, and the handler resolves it into the DEM the planner takes.

use planner_core::geo::{Issue, MAX_ISSUES};
use planner_core::survey::{
    DEM_POINTER, NO_FLY_POINTER, PlanError, ROI_POINTER, SurveyParams, SurveyRequest,
};
use serde_json::Value;
use utoipa::PartialSchema;
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{Object, ObjectBuilder, Schema, SchemaType, Type};

/// The member naming a stored DEM.
const DEM_ID: &str = "dem_id";
/// The planning parameter `dem_id` follows in the request's schema, and
/// in the list of known members an unknown one is answered with.
const DEM_ID_AFTER: &str = "fence_margin_m";
/// Longest DEM id, in bytes.
const DEM_ID_MAX_LEN: usize = 64;

/// Read a survey request document (the body of `POST /api/v1/surveys`, or
/// what the CLI assembles from its files): the planner's request and the
/// id of the DEM to follow, if any. `doc` is left as it was given.
pub fn read_document(doc: &mut Value) -> Result<(SurveyRequest, Option<String>), PlanError> {
    let dem_id = doc.as_object_mut().and_then(|o| o.remove(DEM_ID));
    let read = SurveyRequest::from_document(doc);
    let checked = dem_id.as_ref().map_or(Ok(None), check_dem_id);
    let params_read = || {
        let mut params = doc.as_object().cloned().unwrap_or_default();
        params.remove("roi");
        params.remove("no_fly_zones");
        params.remove("corridor");
        serde_json::from_value::<SurveyParams>(Value::Object(params)).is_ok()
    };
    let result = match (read, checked) {
        (Ok(req), Ok(id)) => Ok((req, id)),
        (Ok(_), Err((fault, _))) => Err(PlanError::Invalid(vec![fault])),
        (Err(PlanError::Invalid(mut issues)), checked) => {
            for issue in &mut issues {
                list_dem_id(issue);
            }
            // A list the planner capped already says how many more.
            if let Err((fault, stage)) = checked
                && issues.len() < MAX_ISSUES
            {
                place(&mut issues, fault, stage, params_read());
            }
            Err(PlanError::Invalid(issues))
        }
        (Err(other), _) => Err(other),
    };
    // Members are kept sorted by name: put back, it is where it was.
    if let (Some(id), Some(obj)) = (dem_id, doc.as_object_mut()) {
        obj.insert(DEM_ID.into(), id);
    }
    result
}

/// Which of the planner's checks a fault of `dem_id` belongs with: the
/// types of the members (where only the first fault, by member name, is
/// reported), or the ranges of their values (all reported, in schema order).
#[derive(Clone, Copy, PartialEq)]
enum Stage {
    Types,
    Ranges,
}

/// `dem_id`: a string of 1 to 64 bytes, or null (none).
fn check_dem_id(v: &Value) -> Result<Option<String>, (Issue, Stage)> {
    let id: Option<String> = serde_json::from_value(v.clone())
        .map_err(|e| (Issue::new(DEM_POINTER, &e.to_string()), Stage::Types))?;
    match id {
        Some(id) if id.is_empty() || id.len() > DEM_ID_MAX_LEN => Err((
            Issue::new(DEM_POINTER, "a DEM id has 1 to 64 characters"),
            Stage::Ranges,
        )),
        id => Ok(id),
    }
}

/// Put the `dem_id` fault among the planner's `issues` where it would be
/// were `dem_id` one of the parameters: after the faults of the area and
/// the no-fly zones; with the type faults, only the first by member name;
/// with the range faults (listed when the types are all right,
/// `params_read`), before those of the members after it in the schema.
fn place(issues: &mut Vec<Issue>, fault: Issue, stage: Stage, params_read: bool) {
    let first_param = issues
        .iter()
        .position(|i| {
            let corridor = i.pointer == "/corridor" || i.pointer.starts_with("/corridor/");
            !i.pointer.starts_with(ROI_POINTER)
                && !i.pointer.starts_with(NO_FLY_POINTER)
                && !corridor
        })
        .unwrap_or(issues.len());
    let member = |i: &Issue| i.pointer.split('/').nth(1).unwrap_or("").to_string();
    match (stage, params_read) {
        // The planner's list holds its first type fault: the earlier stays.
        (Stage::Types, false) => {
            if issues
                .get(first_param)
                .is_some_and(|i| member(i).as_str() > DEM_ID)
            {
                issues[first_param] = fault;
            }
        }
        // Range faults are not looked for once a type is wrong.
        (Stage::Types, true) => {
            issues.truncate(first_param);
            issues.push(fault);
        }
        (Stage::Ranges, false) => {}
        (Stage::Ranges, true) => {
            let after = listed_after_dem_id();
            let at = issues[first_param..]
                .iter()
                .position(|i| after.contains(&member(i)))
                .map_or(issues.len(), |k| first_param + k);
            issues.insert(at, fault);
        }
    }
}

/// The parameters listed after `dem_id` in the request's schema.
fn listed_after_dem_id() -> Vec<String> {
    match SurveyParams::schema() {
        RefOr::T(Schema::Object(o)) => o
            .properties
            .keys()
            .skip_while(|k| k.as_str() != DEM_ID_AFTER)
            .skip(1)
            .cloned()
            .collect(),
        _ => Vec::new(),
    }
}

/// The planner's "unknown field" fault at the top of the document lists
/// the members it knows; the service knows `dem_id` too.
fn list_dem_id(issue: &mut Issue) {
    let known = format!("`{DEM_ID_AFTER}`, ");
    if issue.message.starts_with("unknown field `") && issue.message.contains(&known) {
        issue.message = issue
            .message
            .replacen(&known, &format!("{known}`{DEM_ID}`, "), 1);
    }
}

/// Add `dem_id` to the schema of the request body, after the parameter it
/// follows.
pub fn add_dem_id_schema(body: &mut Object) {
    let schema = ObjectBuilder::new()
        .schema_type(SchemaType::from_iter([Type::String, Type::Null]))
        .description(Some(
            "A stored DEM (`POST /api/v1/dems`) to follow the terrain over;\nwithout one the \
             survey is flown flat at `altitude_m` above home.",
        ))
        .default(Some(Value::Null))
        .build();
    let at = body
        .properties
        .get_index_of(DEM_ID_AFTER)
        .map_or(body.properties.len(), |i| i + 1);
    body.properties
        .shift_insert(at, DEM_ID.to_string(), schema.into());
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn roi() -> Value {
        json!({"type": "Polygon", "coordinates": [[[5.0, 52.0], [5.004, 52.0], [5.004, 52.003], [5.0, 52.003]]]})
    }

    fn faults(mut doc: Value) -> Vec<Issue> {
        match read_document(&mut doc) {
            Err(PlanError::Invalid(issues)) => issues,
            other => panic!("{doc} must be refused, got {:?}", other.map(|r| r.1)),
        }
    }

    #[test]
    fn dem_id_is_read_here_and_the_document_kept() {
        let mut doc = json!({"roi": roi(), "dem_id": "abc", "altitude_m": 40});
        let before = doc.to_string();
        let (req, id) = read_document(&mut doc).unwrap();
        assert_eq!(id.as_deref(), Some("abc"));
        assert_eq!(req.params.altitude_m, Some(40.0));
        assert_eq!(doc.to_string(), before);
        let (_, id) = read_document(&mut json!({"roi": roi(), "dem_id": null})).unwrap();
        assert_eq!(id, None);
    }

    #[test]
    fn dem_id_faults_are_named_at_its_pointer() {
        let e = faults(json!({"roi": roi(), "dem_id": 5}));
        assert_eq!(e.len(), 1);
        assert_eq!(e[0].pointer, "/dem_id");
        assert_eq!(e[0].message, "invalid type: integer `5`, expected a string");
        let e = faults(json!({"roi": roi(), "dem_id": ""}));
        assert_eq!(e[0].pointer, "/dem_id");
        assert_eq!(e[0].message, "a DEM id has 1 to 64 characters");
        let e = faults(json!({"roi": roi(), "dem_id": "x".repeat(65)}));
        assert_eq!(e[0].message, "a DEM id has 1 to 64 characters");
        // Among other faults, where it was when dem_id was a parameter.
        let at =
            |doc: Value| -> Vec<String> { faults(doc).into_iter().map(|i| i.pointer).collect() };
        let ranges = json!({"roi": 1, "dem_id": "", "speed_m_s": -1, "agl_tolerance_m": 0});
        assert_eq!(
            at(ranges),
            ["/roi", "/speed_m_s", "/dem_id", "/agl_tolerance_m"]
        );
        // Only the first wrong type (by name) is said, and then no range.
        assert_eq!(
            at(json!({"roi": 1, "dem_id": 5, "zzz": 1})),
            ["/roi", "/dem_id"]
        );
        assert_eq!(
            at(json!({"roi": roi(), "dem_id": 5, "camera": 1})),
            ["/camera"]
        );
        assert_eq!(
            at(json!({"roi": roi(), "dem_id": 5, "speed_m_s": -1})),
            ["/dem_id"]
        );
        assert_eq!(at(json!({"roi": roi(), "dem_id": "", "zzz": 1})), ["/zzz"]);
    }

    #[test]
    fn an_unknown_member_is_answered_with_dem_id_among_the_known() {
        let e = faults(json!({"roi": roi(), "altitude": 50}));
        assert_eq!(e[0].pointer, "/altitude");
        assert!(
            e[0].message
                .contains("`nfz_clearance_m`, `fence_margin_m`, `dem_id`, `agl_tolerance_m`, "),
            "{}",
            e[0].message
        );
        // Members of nested objects have their own lists.
        let e = faults(json!({"roi": roi(), "uavs": [{"id": "a", "start": [5.0, 52.0], "x": 1}]}));
        assert!(!e[0].message.contains("dem_id"), "{}", e[0].message);
    }

    #[test]
    fn the_schema_lists_dem_id_after_fence_margin_m() {
        let mut body = ObjectBuilder::new()
            .property("fence_margin_m", ObjectBuilder::new())
            .property("agl_tolerance_m", ObjectBuilder::new())
            .build();
        add_dem_id_schema(&mut body);
        let names: Vec<&str> = body.properties.keys().map(String::as_str).collect();
        assert_eq!(names, ["fence_margin_m", "dem_id", "agl_tolerance_m"]);
    }
}
