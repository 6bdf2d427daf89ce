//! The costmaps resource: ask for a traversability costmap of an uploaded
//! DEM for a ground vehicle (built in the background, see
//! [`crate::costmap_jobs`]), follow its progress (polling or Server-Sent
//! Events), list, fetch, delete, and download its files: the GeoTIFF
//! (Float32 cost page, Byte class page), a PNG preview with its SVG legend,
//! and the per-layer GeoTIFFs asked for.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::Stream;
use planner_core::costmap::pipeline::check_against_dem;
use planner_core::costmap::{
    CostmapOptions, CostmapStats, Layer, ResolvedParams, Stage, Vehicle, VehicleSpec,
};
use planner_core::geo::Issue;
use planner_core::terrain::{Crs, Dem, TerrainSampler};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use tokio::sync::mpsc;
use utoipa::ToSchema;

use super::dems::BinaryFile;
use super::json_body::JsonBody;
use super::paging::{ListQuery, page};
use super::{rfc3339, short_id};
use crate::app::AppState;
use crate::costmap_jobs::{
    COSTMAP_TIF, CostmapResult, JobStatus, LEASE_MS, LEGEND_SVG, Live, PREVIEW_PNG, StoredRequest,
    layer_file, now_millis, parse_stage,
};
use crate::db::{CostmapRow, StoredFile};
use crate::error::{ApiError, Problem};
use crate::memory::costmap_build_bytes;

const NAME_MAX_CHARS: usize = 200;
/// Fields of `POST /api/v1/costmaps`.
const FIELDS: [&str; 4] = ["name", "dem_id", "vehicle", "options"];
/// How often an event stream looks at a job another server runs.
const EVENTS_POLL: Duration = Duration::from_secs(1);
/// Least time between two progress events.
const EVENTS_MIN_GAP: Duration = Duration::from_millis(100);

/// Body of `POST /api/v1/costmaps`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the body for the OpenAPI schema
pub struct CreateCostmap {
    /// A label for the costmap.
    #[schema(max_length = 200)]
    name: Option<String>,
    /// The id of an uploaded DEM (`POST /api/v1/dems`).
    dem_id: String,
    /// The ground vehicle: a preset (default `u-go`, the thesis robot:
    /// max step 0.15 m, max slope 25°, w_infl 10, w_slope 1) with any
    /// number overridden.
    vehicle: Option<VehicleSpec>,
    /// Pipeline parameters; every one has a default. For the service,
    /// `landcover.source` is the id of another uploaded DEM holding the
    /// class codes.
    options: Option<CostmapOptions>,
}

/// Where to fetch a costmap and its files.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct CostmapUrls {
    /// This costmap.
    #[serde(rename = "self")]
    this: String,
    /// Its progress as Server-Sent Events.
    events: String,
    /// The costmap: a GeoTIFF in the DEM's CRS, page 1 the cost (Float32,
    /// unit `cost`, NaN where not traversable), page 2 (GDAL's
    /// `GTIFF_DIR:2:`) the class code (Byte, nodata 0 = unknown).
    costmap_tif: String,
    /// A colour preview (PNG).
    preview_png: String,
    /// The preview's legend (SVG).
    legend_svg: String,
    /// One Float32 GeoTIFF per kept layer, by layer name (its unit on the
    /// band: `deg`, `m`, `cost` or `1`).
    layers: BTreeMap<String, String>,
}

/// A costmap job and, once done, what it found.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct CostmapResponse {
    id: String,
    name: Option<String>,
    /// The DEM it is built from.
    dem_id: String,
    /// Creation time, RFC 3339 (UTC).
    created_at: String,
    /// Last change of status or stage, RFC 3339 (UTC).
    updated_at: String,
    status: JobStatus,
    /// Share of the work done, [0, 1].
    progress: f64,
    /// The pipeline stage running (or last run); null before the first.
    stage: Option<Stage>,
    /// The vehicle profile, resolved from the request.
    vehicle: Vehicle,
    /// The options as requested (defaults not filled in; see `params`).
    options: CostmapOptions,
    /// The parameters the costmap was built with (defaults filled in),
    /// once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    params: Option<ResolvedParams>,
    /// Class fractions and cost statistics, once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    stats: Option<CostmapStats>,
    /// What the caller should know about the result (e.g. a DEM too
    /// coarse for the vehicle).
    warnings: Vec<String>,
    /// Why the job failed, with status `failed`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
    /// Working grid size, cells, once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    width: Option<usize>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    height: Option<usize>,
    /// CRS of the costmap (the DEM's), once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    crs: Option<Crs>,
    /// [min x, min y, max x, max y] of the costmap's cells in `crs` (the
    /// extent of `preview.png` and `costmap.tif`), once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bounds: Option<[f64; 4]>,
    /// The same extent in WGS84 [west, south, east, north], once done.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    bounds_wgs84: Option<[f64; 4]>,
    /// The per-layer rasters kept (once done) or to be kept.
    layers: Vec<Layer>,
    urls: CostmapUrls,
}

/// A page of costmaps, newest first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct CostmapList {
    items: Vec<CostmapResponse>,
    /// Costmaps stored in all.
    total: i64,
    limit: i64,
    offset: i64,
}

/// The data of an event of `GET /api/v1/costmaps/{id}/events`.
#[derive(Serialize, Deserialize, ToSchema, Clone, PartialEq, Debug)]
pub struct JobEvent {
    status: JobStatus,
    /// [0, 1].
    progress: f64,
    stage: Option<Stage>,
    /// Why the job failed (event `failed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

pub fn costmap_url(id: &str) -> String {
    format!("/api/v1/costmaps/{id}")
}

fn not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("there is no costmap with id {id:?}"))
}

fn to_json<T: Serialize>(value: &T) -> Result<String, ApiError> {
    serde_json::to_string(value).map_err(|e| ApiError::Internal(e.to_string()))
}

fn escape_pointer(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

/// Deserialize `value`, a fault reported at its JSON pointer under `prefix`.
pub fn deserialize_at<T: DeserializeOwned>(value: &Value, prefix: &str) -> Result<T, Issue> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        use serde_path_to_error::Segment;
        let mut pointer = prefix.to_string();
        for segment in e.path().iter() {
            match segment {
                Segment::Seq { index } => pointer.push_str(&format!("/{index}")),
                Segment::Map { key } => {
                    pointer.push('/');
                    pointer.push_str(&escape_pointer(key));
                }
                Segment::Enum { variant } => {
                    pointer.push('/');
                    pointer.push_str(&escape_pointer(variant));
                }
                Segment::Unknown => {}
            }
        }
        Issue::new(&pointer, &e.into_inner().to_string())
    })
}

/// A checked `POST /api/v1/costmaps` body.
struct CostmapRequest {
    name: Option<String>,
    dem_id: String,
    /// The vehicle as given (`null` for the default).
    vehicle_spec: Value,
    vehicle: Vehicle,
    options: CostmapOptions,
}

/// Read a request body, reporting every fault that needs no DEM by JSON
/// pointer.
fn parse_request(doc: &Value) -> Result<CostmapRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with dem_id (and optionally name, vehicle, options)",
        )]));
    };
    let mut issues = Vec::new();
    for key in obj.keys().filter(|k| !FIELDS.contains(&k.as_str())) {
        issues.push(Issue::new(
            &format!("/{}", escape_pointer(key)),
            &format!("unknown field {key:?}: expected name, dem_id, vehicle or options"),
        ));
    }
    let name = match obj.get("name") {
        None | Some(Value::Null) => None,
        Some(Value::String(s))
            if let Some(issue) =
                crate::api::names::control_character_issue("/name", "the name", s) =>
        {
            issues.push(issue);
            None
        }
        Some(Value::String(s)) if s.chars().count() <= NAME_MAX_CHARS => Some(s.clone()),
        Some(Value::String(_)) => {
            issues.push(Issue::new(
                "/name",
                &format!("the name is longer than {NAME_MAX_CHARS} characters"),
            ));
            None
        }
        Some(_) => {
            issues.push(Issue::new("/name", "the name must be a string"));
            None
        }
    };
    let dem_id = match obj.get("dem_id") {
        Some(Value::String(s))
            if let Some(issue) =
                crate::api::names::control_character_issue("/dem_id", "the DEM id", s) =>
        {
            issues.push(issue);
            String::new()
        }
        Some(Value::String(s)) if !s.is_empty() => s.clone(),
        None | Some(Value::Null) => {
            issues.push(Issue::new(
                "/dem_id",
                "required: the id of an uploaded DEM (POST /api/v1/dems)",
            ));
            String::new()
        }
        Some(_) => {
            issues.push(Issue::new(
                "/dem_id",
                "must be the id (a non-empty string) of an uploaded DEM",
            ));
            String::new()
        }
    };
    let vehicle_spec = obj.get("vehicle").cloned().unwrap_or(Value::Null);
    let vehicle = if vehicle_spec.is_null() {
        VehicleSpec::default().resolve("/vehicle")
    } else {
        deserialize_at::<VehicleSpec>(&vehicle_spec, "/vehicle")
            .map_err(|i| vec![i])
            .and_then(|spec| spec.resolve("/vehicle"))
    };
    let vehicle = match vehicle {
        Ok(v) => Some(v),
        Err(mut v) => {
            issues.append(&mut v);
            None
        }
    };
    let options = match obj.get("options") {
        None | Some(Value::Null) => Some(CostmapOptions::default()),
        Some(v) => match deserialize_at::<CostmapOptions>(v, "/options") {
            Ok(o) => {
                issues.extend(o.validate("/options"));
                Some(o)
            }
            Err(i) => {
                issues.push(i);
                None
            }
        },
    };
    match (vehicle, options) {
        (Some(vehicle), Some(options)) if issues.is_empty() => Ok(CostmapRequest {
            name,
            dem_id,
            vehicle_spec,
            vehicle,
            options,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// The layers in `Layer::ALL` order, once each.
fn ordered_layers(layers: &[Layer]) -> Vec<Layer> {
    Layer::ALL
        .into_iter()
        .filter(|l| layers.contains(l))
        .collect()
}

fn internal(id: &str, what: &str, e: impl std::fmt::Display) -> ApiError {
    ApiError::Internal(format!("stored {what} of costmap {id} unreadable: {e}"))
}

/// A stored job's state, with this process' live progress over it while
/// the job is unfinished.
struct JobState {
    status: JobStatus,
    progress: f64,
    stage: Option<Stage>,
}

fn job_state(row: &CostmapRow, live: Option<Live>) -> Result<JobState, ApiError> {
    let status =
        JobStatus::parse(&row.status).ok_or_else(|| internal(&row.id, "status", &row.status))?;
    let stored = JobState {
        status,
        progress: row.progress,
        stage: row.stage.as_deref().and_then(parse_stage),
    };
    Ok(match live {
        Some(l) if !status.is_finished() => JobState {
            status: l.status,
            progress: l.progress,
            stage: l.stage.or(stored.stage),
        },
        _ => stored,
    })
}

fn response(row: &CostmapRow, live: Option<Live>) -> Result<CostmapResponse, ApiError> {
    let id = &row.id;
    let request: StoredRequest =
        serde_json::from_str(&row.request).map_err(|e| internal(id, "request", e))?;
    let vehicle: Vehicle =
        serde_json::from_str(&row.vehicle).map_err(|e| internal(id, "vehicle", e))?;
    let result: Option<CostmapResult> = row
        .result
        .as_deref()
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| internal(id, "result", e))?;
    let state = job_state(row, live)?;
    let base = costmap_url(id);
    let layers = match &result {
        Some(r) => r.layers.clone(),
        None => ordered_layers(&request.options.layers),
    };
    let urls = CostmapUrls {
        events: format!("{base}/events"),
        costmap_tif: format!("{base}/{COSTMAP_TIF}"),
        preview_png: format!("{base}/{PREVIEW_PNG}"),
        legend_svg: format!("{base}/{LEGEND_SVG}"),
        layers: layers
            .iter()
            .map(|l| (l.name().to_string(), format!("{base}/{}", layer_file(*l))))
            .collect(),
        this: base,
    };
    let (params, stats, warnings, width, height, crs, bounds, bounds_wgs84) = match result {
        Some(mut r) => {
            // Stored before `crs.proj4` existed.
            r.crs.fill_proj4();
            (
                Some(r.params),
                Some(r.stats),
                r.warnings,
                Some(r.width),
                Some(r.height),
                Some(r.crs),
                r.bounds,
                r.bounds_wgs84,
            )
        }
        None => (None, None, Vec::new(), None, None, None, None, None),
    };
    Ok(CostmapResponse {
        id: id.clone(),
        name: row.name.clone(),
        dem_id: row.dem_id.clone(),
        created_at: rfc3339(row.created_at),
        updated_at: rfc3339(row.updated_at),
        status: state.status,
        progress: state.progress,
        stage: state.stage,
        vehicle,
        options: request.options,
        params,
        stats,
        warnings,
        error: row.error.clone(),
        width,
        height,
        crs,
        bounds,
        bounds_wgs84,
        layers,
        urls,
    })
}

/// In a costmap request an unknown DEM is a fault of the request.
fn dem_fault(e: ApiError, pointer: &str, id: &str) -> ApiError {
    match e {
        ApiError::NotFound(_) => ApiError::Validation(vec![Issue::new(
            pointer,
            &format!("no DEM with id {id:?}: upload it with POST /api/v1/dems first"),
        )]),
        other => other,
    }
}

/// A fault at `/options/landcover/source` when PROJ cannot relate the
/// land-cover raster's CRS to the DEM's (the job samples the raster at
/// each costmap cell, given in the DEM's CRS).
async fn landcover_crs_fault(
    dem: &Arc<Dem>,
    landcover: Arc<Dem>,
) -> Result<Option<Issue>, ApiError> {
    let dem_crs = dem.crs.clone();
    // Building a PROJ transformation reads PROJ's database: off the
    // async runtime (and the sampler, holding it, is not `Send`).
    let fault = tokio::task::spawn_blocking(move || {
        TerrainSampler::new(&landcover, dem_crs.epsg)
            .err()
            .map(|e| (landcover.crs.clone(), e))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("land-cover CRS check failed: {e}")))?;
    Ok(fault.map(|(landcover_crs, e)| {
        Issue::new(
            "/options/landcover/source",
            &format!(
                "the land-cover raster's CRS EPSG:{} ({}) cannot be related to the DEM's CRS \
                 EPSG:{} ({}): {e}; upload the land-cover raster in the DEM's CRS",
                landcover_crs.epsg, landcover_crs.name, dem.crs.epsg, dem.crs.name
            ),
        )
    }))
}

/// Ask for a costmap of an uploaded DEM: checked at once (every fault by
/// JSON pointer, including those that depend on the DEM, such as a
/// working resolution finer than its cells), then built in the background
/// (`202 Accepted`). Follow it at `urls.self` (poll `status`) or
/// `urls.events` (Server-Sent Events); its files can be downloaded once
/// `status` is `done`.
#[utoipa::path(
    post,
    path = "/api/v1/costmaps",
    tag = "costmaps",
    request_body(content = CreateCostmap, content_type = "application/json"),
    responses(
        (status = 202, description = "Accepted and queued", body = CostmapResponse,
            headers(("Location" = String, description = "URL of the new costmap"))),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request (unknown DEM, vehicle or options out of range, options that do not fit the DEM, a build needing more than the memory budget): `errors` names each fault by JSON pointer", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The DEM (or land-cover raster) had to be read again from storage and no planner thread became free in time, or the service is shutting down; retry (see Retry-After)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_costmap(
    State(state): State<AppState>,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    let req = parse_request(&doc)?;
    let dem = state
        .load_dem(&req.dem_id)
        .await
        .map_err(|e| dem_fault(e, "/dem_id", &req.dem_id))?;
    let mut issues = Vec::new();
    if let Some(l) = &req.options.landcover {
        // Loaded (and cached for the job) to check its CRS against the
        // DEM's now rather than fail the job later.
        match state.load_dem(&l.source).await {
            Ok(landcover) => issues.extend(landcover_crs_fault(&dem, landcover).await?),
            Err(ApiError::NotFound(_)) => issues.push(Issue::new(
                "/options/landcover/source",
                &format!(
                    "no DEM with id {:?}: upload the land-cover raster with POST /api/v1/dems \
                     and give its id",
                    l.source
                ),
            )),
            Err(e) => return Err(e),
        }
    }
    // Faults of the DEM itself (too small a grid, cells near a pole) come
    // named at /dem_id, the rest under /options: passed on as they are.
    issues.extend(check_against_dem(
        &dem,
        &req.vehicle,
        &req.options,
        "/options",
    ));
    // A build that alone needs more than the memory budget never runs.
    let layers = req.options.layers.len() as u64 + u64::from(req.options.landcover.is_some());
    let (w, h) = (dem.width as u64, dem.height as u64);
    let what = format!("a costmap of DEM {} ({w} × {h} pixels)", req.dem_id);
    if let Err(e) = state
        .memory
        .check(costmap_build_bytes(w.saturating_mul(h), layers), &what)
    {
        issues.push(Issue::new("/dem_id", &e.to_string()));
    }
    if !issues.is_empty() {
        return Err(ApiError::Validation(issues));
    }

    let now = now_millis();
    let stored = StoredRequest {
        vehicle: req.vehicle_spec,
        options: req.options,
    };
    let row = CostmapRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: req.name,
        dem_id: req.dem_id,
        created_at: now,
        updated_at: now,
        request: to_json(&stored)?,
        vehicle: to_json(&req.vehicle)?,
        status: JobStatus::Queued.as_str().to_string(),
        progress: 0.0,
        stage: None,
        result: None,
        error: None,
        attempts: 0,
    };
    let jobs = &state.costmaps;
    state
        .db
        .insert_costmap(&row, jobs.instance(), now + LEASE_MS)
        .await?;
    jobs.enqueue(&state, &row.id);
    let body = response(&row, None)?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&body.urls.this) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::ACCEPTED, headers, Json(body)).into_response())
}

/// Costmaps, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/api/v1/costmaps",
    tag = "costmaps",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of costmaps", body = CostmapList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_costmaps(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<CostmapList>, ApiError> {
    let (limit, offset) = page(query)?;
    let (rows, total) = state.db.list_costmaps(limit, offset).await?;
    let items = rows
        .iter()
        .map(|r| response(r, state.costmaps.live(&r.id)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Json(CostmapList {
        items,
        total,
        limit,
        offset,
    }))
}

/// A costmap: its status and progress, and once done its parameters,
/// statistics, warnings and file URLs.
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "The costmap", body = CostmapResponse),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get_costmap(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<CostmapResponse>, ApiError> {
    let row = state
        .db
        .get_costmap(&id)
        .await?
        .ok_or_else(|| not_found(&id))?;
    Ok(Json(response(&row, state.costmaps.live(&id))?))
}

/// Delete a costmap and its files; a queued or running job is cancelled.
#[utoipa::path(
    delete,
    path = "/api/v1/costmaps/{id}",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 204, description = "Deleted (and cancelled if unfinished)"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_costmap(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let deleted = state.db.delete_costmap(&id).await?;
    // A run elsewhere (another server on the same database) notices the
    // row is gone at its next stage and stops.
    state.costmaps.cancel(&id);
    if deleted {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(not_found(&id))
    }
}

fn event_of(state: &JobState, error: Option<String>) -> JobEvent {
    JobEvent {
        status: state.status,
        progress: state.progress,
        stage: state.stage,
        error,
    }
}

fn sse_event(data: &JobEvent) -> Event {
    let kind = match data.status {
        JobStatus::Done => "done",
        JobStatus::Failed => "failed",
        JobStatus::Queued | JobStatus::Running => "progress",
    };
    Event::default()
        .event(kind)
        .json_data(data)
        .unwrap_or_else(|_| Event::default().event(kind))
}

/// Feed the events of job `id` to `tx` until the job ends, the client
/// goes, or the server shuts down.
async fn follow(state: AppState, id: String, tx: mpsc::Sender<Event>) {
    let jobs = state.costmaps.clone();
    let mut last: Option<JobEvent> = None;
    // Send `ev` unless it repeats the last one; false once the client is gone.
    let send = |ev: JobEvent, last: &mut Option<JobEvent>| {
        let tx = tx.clone();
        let repeat = last.as_ref() == Some(&ev);
        *last = Some(ev.clone());
        async move { repeat || tx.send(sse_event(&ev)).await.is_ok() }
    };
    loop {
        // A job this process runs: follow its live progress until its
        // outcome is stored (the channel closes).
        if let Some(mut rx) = jobs.subscribe(&id) {
            loop {
                let live = *rx.borrow_and_update();
                let ev = JobEvent {
                    status: live.status,
                    progress: live.progress,
                    stage: live.stage,
                    error: None,
                };
                if !send(ev, &mut last).await {
                    return;
                }
                tokio::select! {
                    changed = rx.changed() => if changed.is_err() { break },
                    () = jobs.shutdown_signal() => return,
                    () = tx.closed() => return,
                }
                tokio::time::sleep(EVENTS_MIN_GAP).await;
            }
        }
        let row = match state.db.get_costmap(&id).await {
            Ok(Some(row)) => row,
            Ok(None) => {
                let ev = JobEvent {
                    status: JobStatus::Failed,
                    progress: last.as_ref().map_or(0.0, |l| l.progress),
                    stage: None,
                    error: Some("the costmap was deleted".into()),
                };
                send(ev, &mut last).await;
                return;
            }
            Err(e) => {
                tracing::warn!(costmap = %id, error = %e, "event stream cannot read the job");
                return;
            }
        };
        let Ok(state_now) = job_state(&row, jobs.live(&id)) else {
            return;
        };
        let finished = state_now.status.is_finished();
        if !send(event_of(&state_now, row.error.clone()), &mut last).await || finished {
            return;
        }
        // Queued or running on another server, or between two states
        // here: look again shortly.
        tokio::select! {
            () = tokio::time::sleep(EVENTS_POLL) => {},
            () = jobs.shutdown_signal() => return,
            () = tx.closed() => return,
        }
    }
}

/// The job's progress as Server-Sent Events: `progress` events (data
/// `{status, progress, stage}`) while it is queued or running, then one
/// `done` or `failed` (with `error`) event, and the stream ends. For a
/// finished job only the last event is sent. Comments keep the connection
/// alive.
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/events",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "An event stream: `event: progress|done|failed`, `data:` a JobEvent as JSON",
            content_type = "text/event-stream", body = JobEvent),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn costmap_events(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Sse<impl Stream<Item = Result<Event, Infallible>>>, ApiError> {
    if state.db.get_costmap(&id).await?.is_none() {
        return Err(not_found(&id));
    }
    let (tx, rx) = mpsc::channel(16);
    tokio::spawn(follow(state, id, tx));
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        rx.recv().await.map(|ev| (Ok(ev), rx))
    });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}

/// 409 for the files of a job that is not done.
fn not_ready(state: &JobState, error: Option<&str>) -> ApiError {
    let percent = (state.progress * 100.0).round() as i64;
    let stage = state
        .stage
        .map(crate::costmap_jobs::stage_name)
        .unwrap_or_else(|| "starting".into());
    ApiError::Conflict(match state.status {
        JobStatus::Queued => {
            "the costmap is queued: its files are ready once its status is done".to_string()
        }
        JobStatus::Running => {
            format!("the costmap is still running (stage {stage}, {percent} %)")
        }
        JobStatus::Failed => format!(
            "the costmap failed, so it has no files: {}",
            error.unwrap_or("no reason recorded")
        ),
        JobStatus::Done => "the costmap is done".to_string(),
    })
}

/// The stored job `id`: 404 when there is none.
async fn stored(state: &AppState, id: &str) -> Result<CostmapRow, ApiError> {
    state.db.get_costmap(id).await?.ok_or_else(|| not_found(id))
}

/// Serve a stored file of a finished costmap; 409 while it is not done.
async fn download(
    state: &AppState,
    row: &CostmapRow,
    file: &str,
    attachment: Option<String>,
    request_headers: &HeaderMap,
) -> Result<Response, ApiError> {
    let job = job_state(row, state.costmaps.live(&row.id))?;
    if job.status != JobStatus::Done {
        return Err(not_ready(&job, row.error.as_deref()));
    }
    let etag = format!("\"{}-{}\"", row.id, file.replace('/', "-"));
    let cache_headers = |res: &mut Response| {
        let h = res.headers_mut();
        if let Ok(v) = HeaderValue::from_str(&etag) {
            h.insert(header::ETAG, v);
        }
        // A finished costmap never changes.
        h.insert(
            header::CACHE_CONTROL,
            HeaderValue::from_static("public, max-age=31536000, immutable"),
        );
    };
    let matches = request_headers
        .get_all(header::IF_NONE_MATCH)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|t| t.trim() == etag || t.trim() == "*");
    if matches {
        let mut res = StatusCode::NOT_MODIFIED.into_response();
        cache_headers(&mut res);
        return Ok(res);
    }
    let stored = state
        .db
        .costmap_file_meta(&row.id, file)
        .await?
        .ok_or_else(|| {
            // Deleted since the row was read, or a bug.
            ApiError::NotFound(format!("costmap {} has no file {file}", row.id))
        })?;
    // Streamed a stored chunk at a time: a download holds one chunk, not
    // the file (should the file go meanwhile, the body ends short of its
    // Content-Length and the client sees the transfer fail).
    let chunks = state.db.file_chunks(
        StoredFile::Costmap(row.id.clone(), file.to_string()),
        stored.size_bytes,
    );
    let mut res = axum::body::Body::from_stream(chunks).into_response();
    if let Ok(v) = HeaderValue::from_str(&stored.content_type) {
        res.headers_mut().insert(header::CONTENT_TYPE, v);
    }
    res.headers_mut()
        .insert(header::CONTENT_LENGTH, HeaderValue::from(stored.size_bytes));
    if let Some(name) = attachment
        && let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{name}\""))
    {
        res.headers_mut().insert(header::CONTENT_DISPOSITION, v);
    }
    cache_headers(&mut res);
    Ok(res)
}

/// The costmap as a GeoTIFF in the DEM's CRS (on the working grid), in two
/// pages: page 1 (what GDAL opens) the cost (Float32, unit type `cost`, NaN
/// nodata on obstacles and unknown cells), page 2 (`GTIFF_DIR:2:file`) the
/// class code (Byte, nodata 0; 0 unknown, 1 traversable, 2 slope, 3 step,
/// 4 enclosed, 5 other).
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/costmap.tif",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "The GeoTIFF", content_type = "image/tiff", body = BinaryFile),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not done yet (queued, running or failed)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn costmap_tif(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &id).await?;
    let name = format!("terraplan-{}-costmap.tif", short_id(&id));
    download(&state, &row, COSTMAP_TIF, Some(name), &headers).await
}

/// A colour preview of the costmap (PNG, at most 1024 pixels on its
/// longer side).
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/preview.png",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "The preview", content_type = "image/png", body = BinaryFile),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not done yet (queued, running or failed)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn preview(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &id).await?;
    download(&state, &row, PREVIEW_PNG, None, &headers).await
}

/// The legend of the preview's colours (SVG).
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/legend.svg",
    tag = "costmaps",
    params(("id" = String, Path, description = "Costmap id")),
    responses(
        (status = 200, description = "The legend", content_type = "image/svg+xml", body = String),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not done yet (queued, running or failed)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn legend(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &id).await?;
    download(&state, &row, LEGEND_SVG, None, &headers).await
}

/// One kept layer as a Float32 GeoTIFF on the costmap's grid (NaN nodata,
/// its unit as the band's unit type), e.g. `slope.tif` in degrees (layers
/// are asked for with `options.layers`).
#[utoipa::path(
    get,
    path = "/api/v1/costmaps/{id}/layers/{file}",
    tag = "costmaps",
    params(
        ("id" = String, Path, description = "Costmap id"),
        ("file" = String, Path, description = "`<layer>.tif`: slope, zcomp, step, inflation, roughness, negative_step or landcover", example = "slope.tif"),
    ),
    responses(
        (status = 200, description = "The layer", content_type = "image/tiff", body = BinaryFile),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 404, description = "No such costmap, or the layer was not kept (the detail lists those that were)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Not done yet (queued, running or failed)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn layer(
    State(state): State<AppState>,
    Path((id, file)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &id).await?;
    let kept: Vec<Layer> = match row.result.as_deref() {
        Some(r) => {
            serde_json::from_str::<CostmapResult>(r)
                .map_err(|e| internal(&id, "result", e))?
                .layers
        }
        None => {
            let request: StoredRequest =
                serde_json::from_str(&row.request).map_err(|e| internal(&id, "request", e))?;
            ordered_layers(&request.options.layers)
        }
    };
    let layer = file
        .strip_suffix(".tif")
        .and_then(Layer::from_name)
        .filter(|l| kept.contains(l));
    let Some(layer) = layer else {
        let names: Vec<&str> = kept.iter().map(|l| l.name()).collect();
        let list = if names.is_empty() {
            "it keeps no layers (ask for them with options.layers)".to_string()
        } else {
            format!(
                "its layers are {}",
                names
                    .iter()
                    .map(|n| format!("{n}.tif"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        return Err(ApiError::NotFound(format!(
            "costmap {id} has no layer file {file:?}: {list}"
        )));
    };
    let name = format!("terraplan-{}-{}.tif", short_id(&id), layer.name());
    download(&state, &row, &layer_file(layer), Some(name), &headers).await
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn pointers(r: Result<CostmapRequest, ApiError>) -> Vec<String> {
        match r {
            Err(ApiError::Validation(issues)) => issues.into_iter().map(|i| i.pointer).collect(),
            Err(e) => panic!("expected issues, got {e}"),
            Ok(_) => panic!("expected issues"),
        }
    }

    #[test]
    fn minimal_request() {
        let r = parse_request(&json!({"dem_id": "abc"})).unwrap();
        assert_eq!(r.dem_id, "abc");
        assert_eq!(r.vehicle.name, "u-go");
        assert_eq!(r.options, CostmapOptions::default());
        assert!(r.vehicle_spec.is_null());
    }

    #[test]
    fn faults_are_named_by_pointer() {
        let p = pointers(parse_request(&json!({
            "dem_id": 5,
            "name": 1,
            "colour": "red",
            "vehicle": {"max_slope_deg": 95},
            "options": {"resolution_m": -1},
        })));
        assert_eq!(
            p,
            [
                "/colour",
                "/name",
                "/dem_id",
                "/vehicle/max_slope_deg",
                "/options/resolution_m"
            ]
        );
        let p = pointers(parse_request(
            &json!({"dem_id": "a", "options": {"layers": ["slope", "nope"]}}),
        ));
        assert_eq!(p, ["/options/layers/1"]);
        let p = pointers(parse_request(
            &json!({"dem_id": "a", "vehicle": {"wheels": 4}}),
        ));
        assert_eq!(p, ["/vehicle/wheels"]);
        let p = pointers(parse_request(&json!({"vehicle": {"preset": "tank"}})));
        assert_eq!(p, ["/dem_id", "/vehicle/preset"]);
        assert_eq!(pointers(parse_request(&json!([1]))), [""]);
    }

    /// A 2 × 2 raster in `EPSG:epsg` (the CRS is not looked up).
    fn raster(epsg: u32) -> Arc<Dem> {
        Arc::new(Dem {
            width: 2,
            height: 2,
            values: vec![1.0; 4],
            nodata: None,
            transform: planner_core::terrain::GeoTransform {
                origin_x: 500_000.0,
                pixel_width: 1.0,
                row_rotation: 0.0,
                origin_y: 5_000_000.0,
                col_rotation: 0.0,
                pixel_height: -1.0,
            },
            crs: Crs {
                epsg,
                name: format!("test CRS {epsg}"),
                geographic: false,
                proj4: String::new(),
            },
            format: planner_core::terrain::DemFormat::Asc,
        })
    }

    // Every pair of CRSs a raster can be uploaded in (PROJ relates each to
    // WGS84 at upload) is related by PROJ, if only by a ballpark
    // transformation; so a land-cover raster whose CRS PROJ cannot relate
    // to the DEM's is made here, with a code PROJ does not know.
    #[tokio::test]
    async fn landcover_crs_is_checked_against_the_dem() {
        let dem = raster(32633);
        let fault = landcover_crs_fault(&dem, raster(999_999))
            .await
            .unwrap()
            .expect("a fault");
        assert_eq!(fault.pointer, "/options/landcover/source");
        let says = fault.to_string();
        assert!(
            says.contains("EPSG:999999 (test CRS 999999)")
                && says.contains("EPSG:32633 (test CRS 32633)"),
            "{says}"
        );
        for related in [32633, 4326, 26918] {
            assert!(
                landcover_crs_fault(&dem, raster(related))
                    .await
                    .unwrap()
                    .is_none(),
                "EPSG:{related}"
            );
        }
    }

    #[test]
    fn layer_order() {
        assert_eq!(
            ordered_layers(&[Layer::Step, Layer::Slope, Layer::Step]),
            [Layer::Slope, Layer::Step]
        );
    }
}
