//! A stored route as files: GeoJSON, CSV of UTM waypoints, an ArduPilot
//! Rover mission.

use axum::extract::{Path, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use planner_core::export::ground_route::{route_csv, route_geojson, rover_mission};
use planner_core::export::write_waypoints;
use serde_json::{Map, json};

use super::handlers::visible_route;
use super::model::{StoredRequest, StoredResult, stored, to_json};
use crate::api::short_id;
use crate::auth::{Caller, Role};
use crate::db::RouteRow;
use crate::error::{ApiError, Problem};
use crate::state::AppState;

/// A file rendered from a stored route, as an attachment.
async fn route_file(
    state: &AppState,
    caller: &Caller,
    id: &str,
    extension: &str,
    content_type: &'static str,
    render: impl FnOnce(&RouteRow, &StoredRequest, &StoredResult) -> Result<String, ApiError>,
) -> Result<Response, ApiError> {
    let row = visible_route(state, caller, id, Role::Viewer).await?;
    let request: StoredRequest = stored(id, "request", &row.request)?;
    let result: StoredResult = stored(id, "result", &row.result)?;
    let body = render(&row, &request, &result)?;
    let mut res = body.into_response();
    let headers = res.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    let disposition = format!(
        "attachment; filename=\"terraplan-route-{}.{extension}\"",
        short_id(id)
    );
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        headers.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(res)
}

/// The route as a GeoJSON FeatureCollection of one Feature: a LineString
/// through the waypoints (`[lon, lat, height above the WGS 84 ellipsoid]`
/// when every terrain height is known), with the route's figures, the
/// terrain heights and the EGM96 undulations as properties.
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/route.geojson",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The route, as an attachment", content_type = "application/geo+json", body = Object),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn route_geojson_file(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &caller,
        &id,
        "geojson",
        "application/geo+json",
        |row, _, result| {
            let mut properties = Map::new();
            properties.insert("id".into(), json!(row.id));
            properties.insert("name".into(), json!(row.name));
            properties.insert("costmap_id".into(), json!(row.costmap_id));
            properties.insert("parent_id".into(), json!(row.parent_id));
            properties.insert("planner".into(), json!(result.planner));
            to_json(&route_geojson(&result.route, properties))
        },
    )
    .await
}

/// The waypoints as CSV: `index,easting,northing,zone,height` (UTM metres
/// in the route's zone; height empty where unknown).
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/route.csv",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The waypoints, as an attachment", content_type = "text/csv", body = String),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn route_csv_file(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &caller,
        &id,
        "csv",
        "text/csv; charset=utf-8",
        |_, _, result| Ok(route_csv(&result.route)),
    )
    .await
}

/// An ArduPilot Rover mission (QGC WPL 110): home at the start, a
/// DO_CHANGE_SPEED when the route has a speed, then one NAV_WAYPOINT per
/// waypoint, the goal last.
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/mission.waypoints",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The mission, as an attachment", content_type = "text/plain", body = String),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn mission_waypoints(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &caller,
        &id,
        "waypoints",
        "text/plain; charset=utf-8",
        |_, request, result| {
            Ok(write_waypoints(&rover_mission(
                &result.route,
                request.speed_m_s,
            )))
        },
    )
    .await
}
