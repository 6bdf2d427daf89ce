//! The surveys resource: plan, store, list, fetch, delete, and download the
//! mission files of each UAV.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderName, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use planner_core::cancel::Cancelled;
use planner_core::export::{AltitudeFrame, FencePolygon};
use planner_core::flock::Piece;
use planner_core::geo::Issue;
use planner_core::survey::{
    DEM_POINTER, PlanError, SurveyParams, SurveyPlan, SurveyStats, UavStats, UavTerrain,
    plan_survey_over,
};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use utoipa::ToSchema;

use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::access::{
    PROJECT_POINTER, ProjectFilter, answered_project, list_visible, read_project_id, visible,
};
use super::dems::{dem_fault, visible_dem};
use super::json_body::JsonBody;
use super::names::{NAME_MAX_CHARS, read_name};
use super::paging::ListQuery;
use super::short_id;
use crate::auth::{Caller, Role, new_resource_project};
use crate::clock::{now_millis, rfc3339};
use crate::db::{SurveyRow, SurveySummaryRow};
use crate::error::{ApiError, Problem, deleted};
use crate::state::{AppState, Work, off_runtime};

mod request;
pub use request::read_document;

/// Body of `POST /api/v1/surveys`: the area, the no-fly zones and the
/// planning parameters (the fields of the CLI's params file) in one object.
/// The handler reads the body as JSON so that every fault is reported by
/// pointer; this type only carries its OpenAPI schema: the
/// [`SurveyParams`] object with `name`, `project_id`, `roi`,
/// `no_fly_zones` and `dem_id` added.
pub struct CreateSurvey;

impl utoipa::PartialSchema for CreateSurvey {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::RefOr;
        use utoipa::openapi::schema::{
            ArrayBuilder, Object, ObjectBuilder, Schema, SchemaType, Type,
        };
        let mut body = match SurveyParams::schema() {
            RefOr::T(Schema::Object(o)) => o,
            _ => Object::new(),
        };
        request::add_dem_id_schema(&mut body);
        let geojson = |d: &str| {
            ObjectBuilder::new()
                .schema_type(Type::Object)
                .description(Some(d.to_string()))
                .build()
        };
        body.properties.insert(
            "name".into(),
            ObjectBuilder::new()
                .schema_type(Type::String)
                .max_length(Some(NAME_MAX_CHARS))
                .description(Some("A label for the survey."))
                .into(),
        );
        body.properties.insert(
            "project_id".into(),
            ObjectBuilder::new()
                .schema_type(SchemaType::from_iter([Type::String, Type::Null]))
                .description(Some(
                    "The project to store the survey in (the caller must be an editor there); \
                     the caller's personal project by default.",
                ))
                .into(),
        );
        body.properties.insert(
            "roi".into(),
            geojson(
                "Region of interest: GeoJSON (RFC 7946, WGS84 lon/lat) Polygon, MultiPolygon, \
                 Feature, FeatureCollection or GeometryCollection of areas.",
            )
            .into(),
        );
        body.properties.insert(
            "corridor".into(),
            geojson(
                "A corridor's centre line instead of `roi`: a GeoJSON (RFC 7946, WGS84 lon/lat) \
                 LineString (or a Feature or one-feature FeatureCollection of one). The area \
                 surveyed is its flat-capped buffer `corridor_width_m` wide, flown in lanes along \
                 the line. Give exactly one of `roi` and `corridor`.",
            )
            .into(),
        );
        body.properties.insert(
            "no_fly_zones".into(),
            ArrayBuilder::new()
                .items(geojson("A no-fly zone: any GeoJSON area."))
                .description(Some(
                    "No-fly zones; they may overlap each other, cross the ROI border or lie outside it.",
                ))
                .into(),
        );
        // `roi` or `corridor`, exactly one: the planner answers 422 at both
        // pointers otherwise (a schema of this object lists no alternatives).
        body.description = Some(
            "A survey request: area (`roi`, or `corridor` with `corridor_width_m`), no-fly zones \
             and planning parameters."
                .into(),
        );
        RefOr::T(Schema::Object(body))
    }
}

impl ToSchema for CreateSurvey {
    fn schemas(
        schemas: &mut Vec<(
            String,
            utoipa::openapi::RefOr<utoipa::openapi::schema::Schema>,
        )>,
    ) {
        // The body inlines SurveyParams' properties, so it references what they reference.
        <SurveyParams as ToSchema>::schemas(schemas);
    }
}

/// Download links of one sortie's files (and its UAV's fence).
#[derive(Serialize, Deserialize, ToSchema)]
pub struct UavFiles {
    /// `QGC WPL 110` mission.
    waypoints: String,
    /// QGroundControl `.plan` with geofences.
    plan: String,
    /// GeoJSON of the flown route (3D).
    route: String,
    /// Fence mission (commands 5001/5002).
    fence: String,
    /// Rally points (command 5100, altitude above home), when the survey
    /// has rally points.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    rally: Option<String>,
    /// KML of the route and the UAV's cells, for Google Earth.
    kml: String,
    /// GeoJSON of the sortie's planned photos (footprints on the ground);
    /// without `?sortie=` the UAV's photos of every sortie.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    photos: Option<String>,
    /// DJI WPML mission (KMZ) for the survey's `dji_aircraft`, when DJI
    /// can fly the sortie (a multirotor's, at 1-15 m/s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    dji_kmz: Option<String>,
    /// Litchi mission(s) (CSV): one file, or one per 99 waypoints, each
    /// starting where the one before ended.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    litchi: Vec<String>,
}

/// One flight of a UAV, from take-off to landing at its start.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct SortieResponse {
    /// 1, 2, … in flight order.
    number: usize,
    /// Cell ids in the order flown.
    cells: Vec<usize>,
    /// The parts of cells flown, in order.
    pieces: Vec<Piece>,
    stats: UavStats,
    /// GeoJSON LineString of home, the waypoints and home again:
    /// [lon, lat, height above the WGS 84 ellipsoid] (RFC 7946) when the
    /// survey follows a DEM, [lon, lat] without one; the same geometry as
    /// the `route.geojson` file.
    #[schema(value_type = Object)]
    route: Value,
    /// The mission's altitude at each position of `route`, m, in the
    /// survey's `altitude_frame` (0 at home except in the `amsl` frame).
    #[schema(value_type = Vec<f64>)]
    mission_altitudes_m: Value,
    /// The flight over the DEM (legs in 3D, altitude profile, heights
    /// above the terrain), for surveys planned with `dem_id`.
    #[serde(skip_serializing_if = "Option::is_none")]
    terrain: Option<UavTerrain>,
    files: UavFiles,
}

#[derive(Serialize, Deserialize, ToSchema)]
pub struct UavResponse {
    id: String,
    /// Take-off and landing point [lon, lat].
    start: [f64; 2],
    /// Cruise speed, m/s.
    speed_m_s: f64,
    /// Battery endurance given for this UAV, s.
    #[serde(skip_serializing_if = "Option::is_none")]
    max_flight_time_s: Option<f64>,
    /// Cell ids in the order flown.
    cells: Vec<usize>,
    /// The parts of cells flown, in order (whole cells, or halves when
    /// there are more UAVs than cells or a battery is too small).
    pieces: Vec<Piece>,
    /// Totals over the sorties.
    stats: UavStats,
    /// One mission each; several when the battery needs them.
    sorties: Vec<SortieResponse>,
}

#[derive(Serialize, Deserialize, ToSchema)]
pub struct SurveyFiles {
    /// GeoJSON of the cells.
    cells: String,
}

/// A planned survey.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct SurveyResponse {
    id: String,
    name: Option<String>,
    /// The project it belongs to.
    project_id: String,
    /// Creation time, RFC 3339 (UTC).
    created_at: String,
    /// The UTM zone the plan was made in.
    utm_epsg: u32,
    altitude_frame: AltitudeFrame,
    stats: SurveyStats,
    /// GeoJSON FeatureCollection of the decomposition cells.
    #[schema(value_type = Object)]
    cells: Value,
    uavs: Vec<UavResponse>,
    /// Inclusion fence, then every no-fly zone.
    fences: Vec<FencePolygon>,
    warnings: Vec<String>,
    files: SurveyFiles,
    /// The request as it was made, without `name` and `project_id` (roi,
    /// no_fly_zones, dem_id and the parameters), so a client can reopen and edit it.
    #[schema(value_type = Object)]
    request: Value,
}

#[derive(Serialize, Deserialize, ToSchema)]
pub struct SurveySummary {
    id: String,
    name: Option<String>,
    /// The project it belongs to.
    project_id: String,
    created_at: String,
    cell_count: u64,
    uav_count: u64,
    area_m2: f64,
    /// Flight time summed over the flock, s.
    flight_time_s: f64,
    /// The longest UAV mission, s (the whole survey's duration).
    makespan_s: f64,
    /// URL of the full survey.
    url: String,
}

/// A page of surveys, newest first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct SurveyList {
    items: Vec<SurveySummary>,
    /// Surveys stored in all.
    total: i64,
    limit: i64,
    offset: i64,
}

crate::api::paging::listing!(SurveyList, SurveySummary);

fn survey_url(id: &str) -> String {
    format!("/api/v1/surveys/{id}")
}

fn parse_plan(row_plan: &str) -> Result<SurveyPlan, ApiError> {
    serde_json::from_str(row_plan)
        .map_err(|e| ApiError::Internal(format!("stored plan unreadable: {e}")))
}

/// The API view of a stored survey; `row.plan` is `plan` serialized, so a
/// freshly planned survey is answered without parsing it back.
fn response(row: &SurveyRow, plan: SurveyPlan) -> SurveyResponse {
    let base = survey_url(&row.id);
    let uavs = plan
        .uavs
        .iter()
        .map(|u| {
            let several = u.sorties.len() > 1;
            let sorties = u
                .sorties
                .iter()
                .enumerate()
                .map(|(k, s)| {
                    let query = if several {
                        format!("?sortie={}", k + 1)
                    } else {
                        String::new()
                    };
                    let f = |name: &str| format!("{base}/uavs/{}/{name}{query}", u.id);
                    let dji = plan.dji_suffixes(u, s);
                    let mut route = s.route_feature(Map::new());
                    SortieResponse {
                        number: k + 1,
                        cells: s.cells.clone(),
                        pieces: s.pieces.clone(),
                        stats: s.stats.clone(),
                        route: route["geometry"].take(),
                        mission_altitudes_m: route["properties"]["mission_altitudes_m"].take(),
                        terrain: s.terrain.clone(),
                        files: UavFiles {
                            waypoints: f("mission.waypoints"),
                            plan: f("mission.plan"),
                            route: f("route.geojson"),
                            fence: format!("{base}/uavs/{}/fence.waypoints", u.id),
                            rally: (!plan.rally_points.is_empty())
                                .then(|| format!("{base}/uavs/{}/rally.waypoints", u.id)),
                            kml: f("route.kml"),
                            photos: s.photos.is_some().then(|| f("photos.geojson")),
                            dji_kmz: dji.iter().any(|x| x == "kmz").then(|| f("mission.kmz")),
                            litchi: dji
                                .iter()
                                .filter(|x| x.ends_with(".csv"))
                                .map(|x| f(&format!("mission.{x}")))
                                .collect(),
                        },
                    }
                })
                .collect();
            UavResponse {
                id: u.id.clone(),
                start: u.start,
                speed_m_s: u.speed_m_s,
                max_flight_time_s: u.max_flight_time_s,
                cells: u.cells.clone(),
                pieces: u.pieces.clone(),
                stats: u.stats.clone(),
                sorties,
            }
        })
        .collect();
    let cells = plan.cells_geojson();
    SurveyResponse {
        id: row.id.clone(),
        name: row.name.clone(),
        project_id: answered_project(&row.project_id),
        created_at: rfc3339(row.created_at),
        utm_epsg: plan.utm_epsg,
        altitude_frame: plan.altitude_frame,
        stats: plan.stats,
        cells,
        uavs,
        fences: plan.fences,
        warnings: plan.warnings,
        files: SurveyFiles {
            cells: format!("{base}/cells.geojson"),
        },
        request: serde_json::from_str(&row.request).unwrap_or(Value::Null),
    }
}

/// Take `name` and `project_id` out of the request document, checking
/// them.
fn take_labels(doc: &mut Value) -> Result<(Option<String>, Option<String>), ApiError> {
    let Some(obj) = doc.as_object_mut() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object",
        )]));
    };
    let name = read_name(obj.remove("name").as_ref());
    let project = read_project_id(obj.remove("project_id").as_ref());
    match (name, project) {
        (Ok(name), Ok(project)) => Ok((name, project)),
        (name, project) => Err(ApiError::Validation(
            [name.err(), project.err()].into_iter().flatten().collect(),
        )),
    }
}

/// How a survey that could not be planned is answered; one that ran out
/// of `--survey-timeout-s` is a 503 saying so.
fn survey_fault(e: PlanError) -> ApiError {
    match e {
        PlanError::Cancelled(Cancelled::TimedOut { limit }) => ApiError::Unavailable(format!(
            "the survey took longer than {} s (the service's --survey-timeout-s) and was \
             stopped: survey a smaller area, with fewer vertices or no-fly zones or a wider line \
             spacing, or retry when the service is less busy",
            limit.as_secs_f64()
        )),
        other => other.into(),
    }
}

/// Plan a survey and store it.
#[utoipa::path(
    post,
    path = "/api/v1/surveys",
    tag = "surveys",
    request_body(content = CreateSurvey, content_type = "application/json"),
    responses(
        (status = 201, description = "Planned and stored", body = SurveyResponse,
            headers(("Location" = String, description = "URL of the new survey"))),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The caller is a viewer of the project `project_id`", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request: `errors` names each fault by JSON pointer (`/project_id` when there is no such project of the caller's, `/dem_id` when there is no such DEM the caller can see)", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner is busy, or the survey took longer than `--survey-timeout-s`", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_survey(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(mut doc): JsonBody,
) -> Result<Response, ApiError> {
    let (name, project_id) = take_labels(&mut doc)?;
    let project_id =
        new_resource_project(&state.db, &caller, project_id.as_deref(), PROJECT_POINTER).await?;
    // Reading the request checks every member: off the runtime threads.
    let ((req, dem_id), doc) =
        off_runtime(move || read_document(&mut doc).map(|r| (r, doc))).await??;
    let dem = match &dem_id {
        None => None,
        Some(id) => {
            // A DEM the caller cannot see is one that is not there, and
            // is checked before the DEM cache (keyed by id alone) is asked.
            visible_dem(&state, &caller, id, Role::Viewer)
                .await
                .map_err(|e| dem_fault(e, DEM_POINTER, id))?;
            Some(
                state
                    .load_dem(id)
                    .await
                    .map_err(|e| dem_fault(e, DEM_POINTER, id))?,
            )
        }
    };
    let limits = state.limits.clone();
    let started = std::time::Instant::now();
    let planned = state
        .run_planner(Work::Survey, move |token| {
            let t = std::time::Instant::now();
            let plan = token.settle(plan_survey_over(&req, &limits, dem.as_deref()))?;
            let stored =
                serde_json::to_string(&plan).map_err(|e| PlanError::Internal(e.to_string()));
            Ok::<_, PlanError>((plan, stored?, doc.to_string(), t.elapsed()))
        })
        .await?;
    let (plan, stored_plan, request, planning) = planned.map_err(survey_fault)?;
    let waited = started.elapsed().saturating_sub(planning);
    let row = SurveyRow {
        id: uuid::Uuid::now_v7().to_string(),
        name,
        created_at: now_millis(),
        request,
        plan: stored_plan,
        project_id: Some(project_id),
    };
    state.db.insert_survey(&row).await?;
    let body = response(&row, plan);
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&survey_url(&row.id)) {
        headers.insert(header::LOCATION, v);
    }
    // Planner time and queueing time, for clients and load tests.
    let timing = format!(
        "plan;dur={:.3}, queue;dur={:.3}",
        planning.as_secs_f64() * 1e3,
        waited.as_secs_f64() * 1e3
    );
    if let Ok(v) = HeaderValue::from_str(&timing) {
        headers.insert(HeaderName::from_static("server-timing"), v);
    }
    Ok((StatusCode::CREATED, headers, Json(body)).into_response())
}

/// A stored survey.
#[utoipa::path(
    get,
    path = "/api/v1/surveys/{id}",
    tag = "surveys",
    params(("id" = String, Path, description = "Survey id")),
    responses(
        (status = 200, description = "The survey", body = SurveyResponse),
        (status = 404, description = "No such survey", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get_survey(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<SurveyResponse>, ApiError> {
    let row = visible_survey(&state, &caller, &id, Role::Viewer).await?;
    let plan = parse_plan(&row.plan)?;
    Ok(Json(response(&row, plan)))
}

/// Stored surveys, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/api/v1/surveys",
    tag = "surveys",
    params(ListQuery, ProjectFilter),
    responses(
        (status = 200, description = "A page of the surveys of the caller's projects", body = SurveyList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No project `project_id` (of the caller's)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_surveys(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<ProjectFilter>, QueryRejection>,
) -> Result<Json<SurveyList>, ApiError> {
    let (db, user) = (&state.db, caller.user_id.as_str());
    let page = list_visible(
        db,
        &caller,
        query,
        filter,
        |project, limit, offset| async move {
            db.list_surveys(user, project.as_deref(), limit, offset)
                .await
        },
        summary,
    )
    .await?;
    Ok(Json(page.into()))
}

fn summary(row: &SurveySummaryRow) -> Result<SurveySummary, ApiError> {
    let plan: Value =
        serde_json::from_str(&row.plan).map_err(|e| ApiError::Internal(e.to_string()))?;
    let stats = &plan["stats"];
    Ok(SurveySummary {
        id: row.id.clone(),
        name: row.name.clone(),
        project_id: answered_project(&row.project_id),
        created_at: rfc3339(row.created_at),
        cell_count: stats["cell_count"].as_u64().unwrap_or(0),
        uav_count: plan["uavs"].as_array().map_or(0, |a| a.len() as u64),
        area_m2: stats["area_m2"].as_f64().unwrap_or(0.0),
        flight_time_s: stats["flight_time_s"].as_f64().unwrap_or(0.0),
        // Plans stored before flocks had one UAV: its time is the makespan.
        makespan_s: stats["makespan_s"]
            .as_f64()
            .or_else(|| stats["flight_time_s"].as_f64())
            .unwrap_or(0.0),
        url: survey_url(&row.id),
    })
}

/// The stored survey `id` when the caller has at least `need` in its
/// project; one of another project is the 404 of a missing one.
async fn visible_survey(
    state: &AppState,
    caller: &Caller,
    id: &str,
    need: Role,
) -> Result<SurveyRow, ApiError> {
    let row = state.db.get_survey(id).await?;
    visible(&state.db, caller, row, "survey", id, need).await
}

/// Delete a survey and its files.
#[utoipa::path(
    delete,
    path = "/api/v1/surveys/{id}",
    tag = "surveys",
    params(("id" = String, Path, description = "Survey id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 403, description = "The caller is a viewer of the survey's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such survey", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_survey(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    visible_survey(&state, &caller, &id, Role::Editor).await?;
    deleted(state.db.delete_survey(&id).await?, "survey", &id)
}

/// Serve one rendered file of a stored plan as a download.
/// `missing` describes what is absent when the survey exists but the file does not.
async fn download(
    state: &AppState,
    caller: &Caller,
    id: &str,
    file_name: &str,
    download_name: &str,
    missing: impl FnOnce() -> String,
) -> Result<Response, ApiError> {
    let row = visible_survey(state, caller, id, Role::Viewer).await?;
    // Rendering a big mission is work: off the runtime threads.
    let name = file_name.to_string();
    // A stored plan keeps no limit of photo features: the server's own.
    let max_photo_features = state.limits.max_photo_features;
    let file = off_runtime(move || {
        parse_plan(&row.plan).map(|mut plan| {
            plan.max_photo_features = max_photo_features;
            plan.file(&name)
        })
    })
    .await??
    .ok_or_else(|| ApiError::NotFound(missing()))?;
    let disposition = format!("attachment; filename=\"{download_name}\"");
    let mut res = file.content.into_response();
    let headers = res.headers_mut();
    headers.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(file.content_type),
    );
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        headers.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(res)
}

/// Which sortie of a UAV a file belongs to.
#[derive(Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct SortieQuery {
    /// Sortie number (1, 2, …); needed for a UAV that flies several.
    #[param(minimum = 1)]
    sortie: Option<usize>,
}

/// A file of one UAV: `mission.waypoints` (QGC WPL 110), `mission.plan`
/// (QGroundControl), `route.geojson`, `route.kml`, `fence.waypoints` or
/// `rally.waypoints` (a survey with rally points), `photos.geojson` (the
/// planned photos' footprints; every sortie's without `?sortie=`),
/// `mission.kmz` (DJI WPML, for `dji_aircraft`) or `mission.litchi.csv`
/// (Litchi; past 99 waypoints `mission.part1.litchi.csv`, `part2`, …), the
/// DJI files of a multirotor sortie DJI can fly.
/// A UAV whose battery needs several sorties has one mission per sortie,
/// chosen with `?sortie=k`.
#[utoipa::path(
    get,
    path = "/api/v1/surveys/{id}/uavs/{uav}/{file}",
    tag = "surveys",
    params(
        ("id" = String, Path, description = "Survey id"),
        ("uav" = String, Path, description = "UAV id"),
        ("file" = String, Path, description = "One of mission.waypoints, mission.plan, route.geojson, route.kml, fence.waypoints, rally.waypoints, photos.geojson, mission.kmz, mission.litchi.csv, mission.part<k>.litchi.csv"),
        SortieQuery,
    ),
    responses(
        (status = 200, description = "The file, as an attachment", content(
            (String = "text/plain"),
            (Object = "application/json"),
            (Object = "application/geo+json"),
            (String = "application/vnd.google-earth.kml+xml"),
            (crate::api::dems::BinaryFile = "application/vnd.google-earth.kmz"),
            (String = "text/csv"),
        )),
        (status = 400, description = "Malformed sortie number", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such survey, UAV, sortie or file", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn uav_file(
    State(state): State<AppState>,
    caller: Caller,
    Path((id, uav, file)): Path<(String, String, String)>,
    query: Result<Query<SortieQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(SortieQuery { sortie }) = query.map_err(|e| {
        ApiError::BadRequest(format!(
            "sortie must be a whole number from 1: {}",
            e.body_text()
        ))
    })?;
    if sortie == Some(0) {
        return Err(ApiError::BadRequest(
            "sortie must be a whole number from 1".into(),
        ));
    }
    // UAV ids never hold a dot; file stems of sorties do.
    if uav.contains('.') {
        return Err(ApiError::NotFound(format!(
            "survey {id} has no UAV {uav:?}"
        )));
    }
    let (suffix, ext) = match file.as_str() {
        "mission.waypoints" => ("waypoints", "waypoints"),
        "mission.plan" => ("plan", "plan"),
        "route.geojson" => ("route.geojson", "route.geojson"),
        "fence.waypoints" => ("fence.waypoints", "fence.waypoints"),
        "rally.waypoints" => ("rally.waypoints", "rally.waypoints"),
        "route.kml" => ("kml", "kml"),
        "photos.geojson" => ("photos.geojson", "photos.geojson"),
        "mission.kmz" => ("kmz", "kmz"),
        "mission.litchi.csv" => ("litchi.csv", "litchi.csv"),
        // A Litchi mission past 99 waypoints: `part<k>.litchi.csv`.
        other if litchi_part(other).is_some() => {
            let suffix = litchi_part(other).unwrap_or_default();
            (suffix, suffix)
        }
        other => {
            return Err(ApiError::NotFound(format!(
                "unknown file {other:?}: one of mission.waypoints, mission.plan, route.geojson, route.kml, \
                 fence.waypoints, rally.waypoints, photos.geojson, mission.kmz, mission.litchi.csv, \
                 mission.part<k>.litchi.csv"
            )));
        }
    };
    // Per-sortie files are named `<uav>.sortie<k>.<suffix>` in the plan
    // when the UAV flies several sorties; the fence is the UAV's.
    let stem = match sortie {
        Some(k) => format!("{uav}.sortie{k}"),
        None => uav.clone(),
    };
    let download_name = format!("terraplan-{}-{stem}.{ext}", short_id(&id));
    download(
        &state,
        &caller,
        &id,
        &format!("{stem}.{suffix}"),
        &download_name,
        || match sortie {
            _ if file == "rally.waypoints" => {
                format!("survey {id} has no rally points (rally_points), or no UAV {uav:?}")
            }
            _ if file.ends_with(".kmz") || file.ends_with(".litchi.csv") => format!(
                "survey {id} has no {file} of UAV {uav:?} (or no such UAV or sortie): DJI and Litchi \
                 missions are made for multirotor sorties DJI can fly (the survey's warnings say why \
                 one has none), and a Litchi mission past 99 waypoints is split into \
                 mission.part1.litchi.csv, mission.part2.litchi.csv, …"
            ),
            _ if file == "photos.geojson" => format!(
                "survey {id} has no planned photos of UAV {uav:?} (or no such UAV or sortie): \
                 surveys planned before photos were kept them in no plan"
            ),
            Some(k) => format!(
                "survey {id} has no sortie {k} of UAV {uav:?} (a UAV flying one sortie takes no \
                 sortie number)"
            ),
            None => format!(
                "survey {id} has no UAV {uav:?}, or that UAV flies several sorties: add \
                 ?sortie=1, 2, …"
            ),
        },
    )
    .await
}

/// `part<k>.litchi.csv` of a `mission.part<k>.litchi.csv` (k a whole
/// number from 1), the file suffix of a Litchi mission's part k.
fn litchi_part(file: &str) -> Option<&str> {
    let suffix = file.strip_prefix("mission.")?;
    let k = suffix.strip_prefix("part")?.strip_suffix(".litchi.csv")?;
    (!k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) && !k.starts_with('0'))
        .then_some(suffix)
}

/// The decomposition cells as GeoJSON.
#[utoipa::path(
    get,
    path = "/api/v1/surveys/{id}/cells.geojson",
    tag = "surveys",
    params(("id" = String, Path, description = "Survey id")),
    responses(
        (status = 200, description = "GeoJSON FeatureCollection of the cells", content_type = "application/geo+json", body = Object),
        (status = 404, description = "No such survey", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn cells_file(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let name = format!("terraplan-{}-cells.geojson", short_id(&id));
    download(&state, &caller, &id, "cells.geojson", &name, || {
        format!("survey {id} has no cells file")
    })
    .await
}

/// The survey endpoints.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_survey, list_surveys))
        .routes(routes!(get_survey, delete_survey))
        .routes(routes!(uav_file))
        .routes(routes!(cells_file))
}
