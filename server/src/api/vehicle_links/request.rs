//! The body of `POST /api/v1/surveys/{id}/uavs/{uav}/upload`, and the
//! lists it sends, taken from the stored plan's files: the sortie's
//! `.waypoints` (the mission, home first, as `terraplan upload` sends the
//! file) and, when asked, its `.plan`'s geoFence (polygons, circles and the
//! breach return point) and rallyPoints.

use std::time::Duration;

use planner_core::geo::{Issue, deserialize_at};
use planner_core::survey::SurveyPlan;
use serde::Deserialize;
use serde_json::Value;
use utoipa::ToSchema;

use crate::error::ApiError;
use crate::vehicle_link::exchange::item_message;
use crate::vehicle_link::mission_file::{read_plan, read_wpl};
use crate::vehicle_link::{ItemList, MissionKind, Options};

/// Longest wait for one answer the service allows (the CLI allows 60 s):
/// with at most [`MAX_RETRIES`] a dead link ends an upload within 3.5 min.
const MAX_TIMEOUT_MS: u64 = 10_000;
const MIN_TIMEOUT_MS: u64 = 10;
const MAX_RETRIES: u32 = 20;

/// Send a stored survey's mission to a vehicle.
#[derive(Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UploadRequest {
    /// The vehicle: one of the service's vehicle links
    /// (`GET /api/v1/vehicle-links`), e.g. `udpout:192.168.1.10:14550`.
    pub to: String,
    /// Send the UAV's fence too (the inclusion fence, the no-fly zones and
    /// the breach return point, as in its `.plan`).
    #[serde(default)]
    pub fence: bool,
    /// Send the survey's rally points too (a survey planned with
    /// `rally_points`).
    #[serde(default)]
    pub rally: bool,
    /// The sortie to send (1, 2, …); needed for a UAV that flies several.
    #[schema(minimum = 1)]
    pub sortie: Option<u64>,
    /// Wait this long for each answer of the vehicle, ms (10 to 10000;
    /// default 1500).
    #[schema(minimum = 10, maximum = 10000)]
    pub timeout_ms: Option<u64>,
    /// Send a message again this many times before giving up (0 to 20;
    /// default 5).
    #[schema(minimum = 0, maximum = 20)]
    pub retries: Option<u32>,
    /// The vehicle's MAVLink system id (default 1).
    #[schema(minimum = 1, maximum = 255)]
    pub target_system: Option<u8>,
    /// The vehicle's MAVLink component id (default 1, the autopilot).
    #[schema(minimum = 0, maximum = 255)]
    pub target_component: Option<u8>,
}

/// The request, its faults each at its pointer.
pub fn read_request(body: &Value) -> Result<(UploadRequest, Options), ApiError> {
    if !body.is_object() {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with `to`",
        )]));
    }
    let req: UploadRequest = deserialize_at(body, "").map_err(|i| ApiError::Validation(vec![i]))?;
    let mut issues = Vec::new();
    if req.sortie == Some(0) {
        issues.push(Issue::new("/sortie", "sortie numbers start at 1"));
    }
    let timeout_ms = req.timeout_ms.unwrap_or(1500);
    if !(MIN_TIMEOUT_MS..=MAX_TIMEOUT_MS).contains(&timeout_ms) {
        issues.push(Issue::new(
            "/timeout_ms",
            &format!("must be from {MIN_TIMEOUT_MS} to {MAX_TIMEOUT_MS} ms"),
        ));
    }
    let retries = req.retries.unwrap_or(5);
    if retries > MAX_RETRIES {
        issues.push(Issue::new(
            "/retries",
            &format!("must be from 0 to {MAX_RETRIES}"),
        ));
    }
    if req.target_system == Some(0) {
        issues.push(Issue::new(
            "/target_system",
            "MAVLink system ids are 1 to 255",
        ));
    }
    if !issues.is_empty() {
        return Err(ApiError::Validation(issues));
    }
    let opts = Options {
        timeout: Duration::from_millis(timeout_ms),
        retries,
        target_system: req.target_system.unwrap_or(1),
        target_component: req.target_component.unwrap_or(1),
    };
    Ok((req, opts))
}

/// The lists to send, in order mission, fence, rally, from the stored plan
/// (`plan_json`) of survey `id`.
pub fn lists_of(
    plan_json: &str,
    id: &str,
    uav: &str,
    req: &UploadRequest,
    opts: &Options,
) -> Result<Vec<ItemList>, ApiError> {
    let plan: SurveyPlan = serde_json::from_str(plan_json)
        .map_err(|e| ApiError::Internal(format!("stored plan unreadable: {e}")))?;
    let u = plan
        .uavs
        .iter()
        .find(|u| u.id == uav)
        .ok_or_else(|| ApiError::NotFound(format!("survey {id} has no UAV {uav:?}")))?;
    let n = u.sorties.len();
    let k = match (req.sortie, n) {
        (_, 0) => {
            return Err(ApiError::NotFound(format!(
                "UAV {uav:?} of survey {id} has no mission (it was given nothing to fly)"
            )));
        }
        (None, 1) => 0,
        (None, _) => {
            return Err(ApiError::Validation(vec![Issue::new(
                "/sortie",
                &format!("UAV {uav:?} flies {n} sorties: name the one to send (1 to {n})"),
            )]));
        }
        (Some(k), _) if k >= 1 && k <= n as u64 => (k - 1) as usize,
        (Some(k), _) => {
            return Err(ApiError::Validation(vec![Issue::new(
                "/sortie",
                &format!("UAV {uav:?} flies {n} sortie(s): there is no sortie {k}"),
            )]));
        }
    };
    if req.rally && plan.rally_points.is_empty() {
        return Err(ApiError::Validation(vec![Issue::new(
            "/rally",
            &format!("survey {id} has no rally points (plan it with `rally_points`)"),
        )]));
    }
    let stem = &u.sorties[k].file_stem;
    let text = |name: &str| {
        plan.file(name)
            .map(|f| f.text().to_string())
            .ok_or_else(|| ApiError::Internal(format!("the plan has no file {name}")))
    };
    let unreadable = |name: &str, e: &dyn std::fmt::Display| {
        ApiError::Internal(format!("the plan's {name} cannot be sent: {e}"))
    };
    let waypoints = format!("{stem}.waypoints");
    let mission = read_wpl(&text(&waypoints)?, MissionKind::Mission)
        .map_err(|e| unreadable(&waypoints, &e))?;
    let mut lists = vec![mission];
    if req.fence || req.rally {
        let name = format!("{stem}.plan");
        let sides = read_plan(&text(&name)?).map_err(|e| unreadable(&name, &e))?;
        if req.fence {
            lists.push(sides.fence);
        }
        if req.rally {
            lists.push(sides.rally);
        }
    }
    // An item the wire cannot carry is found before the vehicle's lists
    // are touched (none of terraplan's: a stored plan from a newer build).
    for list in &lists {
        for (seq, item) in list.items.iter().enumerate() {
            item_message(opts, list.kind, seq as u16, item).map_err(|why| {
                ApiError::Validation(vec![Issue::new(
                    "",
                    &format!("the {} list cannot be sent: {why}", list.kind.name()),
                )])
            })?;
        }
    }
    Ok(lists)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn faults(body: Value) -> Vec<String> {
        match read_request(&body) {
            Err(ApiError::Validation(issues)) => issues
                .into_iter()
                .map(|i| format!("{} {}", i.pointer, i.message))
                .collect(),
            Err(e) => vec![format!("other error {e}")],
            Ok(_) => vec![],
        }
    }

    #[test]
    fn defaults_and_faults_at_their_pointers() {
        let (req, opts) = read_request(&json!({"to": "udpout:127.0.0.1:14550"})).unwrap();
        assert!(!req.fence && !req.rally && req.sortie.is_none());
        assert_eq!(opts.timeout, Duration::from_millis(1500));
        assert_eq!((opts.retries, opts.target_system), (5, 1));
        assert!(faults(json!({}))[0].contains("to"));
        assert!(faults(json!({"to": 5}))[0].starts_with("/to"));
        assert!(faults(json!({"to": "x", "speed": 1}))[0].contains("speed"));
        assert!(faults(json!([1]))[0].contains("JSON object"));
        let f = faults(json!({"to": "x", "sortie": 0, "timeout_ms": 5, "retries": 21}));
        assert_eq!(f.len(), 3, "{f:?}");
        assert!(f[0].starts_with("/sortie"), "{f:?}");
        assert!(f[1].starts_with("/timeout_ms"), "{f:?}");
        assert!(f[2].starts_with("/retries"), "{f:?}");
    }
}
