//! The costmaps resource's handlers: ask for a costmap (checked at once,
//! built in the background by [`crate::jobs`]), list, fetch and delete.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use planner_core::costmap::pipeline::check_against_dem;
use planner_core::geo::Issue;
use planner_core::terrain::Dem;
use serde::Serialize;
use std::sync::Arc;

use super::model::{CostmapList, CostmapResponse, CreateCostmap, response};
use super::request::{landcover_crs_fault, parse_request};
use crate::api::access::{PROJECT_POINTER, ProjectFilter, list_visible, visible};
use crate::api::dems::{dem_fault, visible_dem};
use crate::api::json_body::JsonBody;
use crate::api::paging::ListQuery;
use crate::auth::{Caller, Role, new_resource_project};
use crate::clock::now_millis;
use crate::db::CostmapRow;
use crate::error::{ApiError, Problem, deleted};
use crate::jobs::{JobStatus, StoredRequest};
use crate::memory::costmap_build_bytes;
use crate::quota::costmap_file_bytes;
use crate::state::AppState;

fn to_json<T: Serialize>(value: &T) -> Result<String, ApiError> {
    serde_json::to_string(value).map_err(|e| ApiError::Internal(e.to_string()))
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
        (status = 403, description = "The caller is a viewer of the project `project_id`", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large, or the costmap's files would take the project past its storage quota (--project-quota-mb)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many planning requests, or the project has as many costmap jobs queued or running as it may (--project-queued-jobs); see Retry-After", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request (no project `project_id` the caller may add to, unknown DEM, vehicle or options out of range, options that do not fit the DEM, a build needing more than the memory budget): `errors` names each fault by JSON pointer", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The DEM (or land-cover raster) had to be read again from storage and no planner thread became free in time, or the service is shutting down; retry (see Retry-After)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_costmap(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    let req = parse_request(&doc)?;
    let project_id = new_resource_project(
        &state.db,
        &caller,
        req.project_id.as_deref(),
        PROJECT_POINTER,
    )
    .await?;
    // A DEM the caller cannot see is one that is not there, and is
    // checked before the DEM cache (keyed by id alone) is asked.
    visible_dem(&state, &caller, &req.dem_id, Role::Viewer)
        .await
        .map_err(|e| dem_fault(e, "/dem_id", &req.dem_id))?;
    // The DEM's grid, never its heights: a DEM stored as tiles is not
    // read here (a 30 000² DEM's heights are 7 GB), the checks need only
    // its size, georeferencing and CRS.
    let source = crate::jobs::dem_source(&state.dem_loader(), &req.dem_id)
        .await
        .map_err(|e| dem_fault(e, "/dem_id", &req.dem_id))?;
    let dem = Arc::new(grid_shell(source.grid()));
    let mut issues = Vec::new();
    let mut landcover = None;
    if let Some(l) = &req.options.landcover {
        // Loaded (and cached for the job) to check its CRS against the
        // DEM's now rather than fail the job later.
        let loaded = match visible_dem(&state, &caller, &l.source, Role::Viewer).await {
            Ok(_) => state.load_dem(&l.source).await,
            Err(e) => Err(e),
        };
        match loaded {
            Ok(raster) => {
                issues.extend(landcover_crs_fault(&dem, raster.clone()).await?);
                landcover = Some(raster);
            }
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
    // A build that alone needs more than the memory budget never runs; a
    // costmap built as tiles needs a tile's room at a time (each tile job
    // checks its own), so only a whole build is checked here.
    let layers = req.options.layers.len() as u64 + u64::from(req.options.landcover.is_some());
    let (w, h) = (dem.width as u64, dem.height as u64);
    let what = format!("a costmap of DEM {} ({w} × {h} pixels)", req.dem_id);
    let tiles = state.costmaps.tile_settings();
    let tiled = planner_core::costmap::TilePlan::new(
        source.grid(),
        &req.vehicle,
        &req.options,
        landcover.as_deref(),
        tiles.side,
    )
    .is_ok_and(|plan| {
        let layout = plan.layout();
        (layout.width as u64).saturating_mul(layout.height as u64) > tiles.cells
    });
    if !tiled
        && let Err(e) = state
            .memory
            .check(costmap_build_bytes(w.saturating_mul(h), layers), &what)
    {
        issues.push(Issue::new("/dem_id", &e.to_string()));
    }
    if !issues.is_empty() {
        return Err(ApiError::Validation(issues));
    }
    // One reading of the project's use for both of its quotas.
    let usage = state.quotas.usage(&state.db, &project_id).await?;
    usage.check_jobs(&project_id)?;
    usage.check_bytes(
        &project_id,
        costmap_file_bytes(w.saturating_mul(h), layers),
        &format!("the files of {what}"),
    )?;

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
        project_id: Some(project_id),
    };
    let jobs = &state.costmaps;
    state
        .db
        .insert_costmap(&row, jobs.instance(), now + jobs.lease_ms())
        .await?;
    jobs.enqueue(&row.id);
    let body = response(&row, None)?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&body.urls.this) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::ACCEPTED, headers, Json(body)).into_response())
}

/// The stored costmap `id` when the caller has at least `need` in its
/// project; one of another project is the 404 of a missing one.
pub async fn visible_costmap(
    state: &AppState,
    caller: &Caller,
    id: &str,
    need: Role,
) -> Result<CostmapRow, ApiError> {
    let row = state.db.get_costmap(id).await?;
    visible(&state.db, caller, row, "costmap", id, need).await
}

/// Costmaps, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/api/v1/costmaps",
    tag = "costmaps",
    params(ListQuery, ProjectFilter),
    responses(
        (status = 200, description = "A page of the costmaps of the caller's projects", body = CostmapList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No project `project_id` (of the caller's)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_costmaps(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<ProjectFilter>, QueryRejection>,
) -> Result<Json<CostmapList>, ApiError> {
    let db = &state.db;
    let user = caller.user_id.as_str();
    let page = list_visible(
        db,
        &caller,
        query,
        filter,
        |project, limit, offset| async move {
            db.list_costmaps(user, project.as_deref(), limit, offset)
                .await
        },
        |r| response(r, state.costmaps.live(&r.id)),
    )
    .await?;
    Ok(Json(page.into()))
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
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<CostmapResponse>, ApiError> {
    let row = visible_costmap(&state, &caller, &id, Role::Viewer).await?;
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
        (status = 403, description = "The caller is a viewer of the costmap's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_costmap(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    visible_costmap(&state, &caller, &id, Role::Editor).await?;
    let gone = state.db.delete_costmap(&id).await?;
    // A run elsewhere (another server on the same database) notices the
    // row is gone at its next stage and stops.
    state.costmaps.cancel(&id);
    deleted(gone, "costmap", &id)
}

/// A [`Dem`] of `grid`'s size and georeferencing without heights: what the
/// request's checks read.
fn grid_shell(grid: &planner_core::terrain::RasterGrid) -> Dem {
    Dem {
        width: grid.width,
        height: grid.height,
        values: Vec::new(),
        nodata: grid.nodata,
        transform: grid.transform,
        crs: grid.crs.clone(),
        format: planner_core::terrain::DemFormat::GeoTiff,
    }
}
