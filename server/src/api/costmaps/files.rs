//! A finished costmap's files: the GeoTIFF, the preview and its legend,
//! and the per-layer GeoTIFFs.

use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use planner_core::costmap::Layer;

use super::handlers::visible_costmap;
use super::model::{JobState, internal, job_state, ordered_layers};
use crate::api::dems::BinaryFile;
use crate::api::immutable::Immutable;
use crate::api::short_id;
use crate::auth::{Caller, Role};
use crate::db::{CostmapRow, StoredFile};
use crate::error::{ApiError, Problem};
use crate::jobs::{
    COSTMAP_TIF, CostmapResult, JobStatus, LEGEND_SVG, PREVIEW_PNG, StoredRequest, layer_file,
    stage_name,
};
use crate::state::AppState;

/// 409 for the files of a job that is not done.
fn not_ready(state: &JobState, error: Option<&str>) -> ApiError {
    let percent = (state.progress * 100.0).round() as i64;
    let stage = state
        .stage
        .map(stage_name)
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

/// The stored job `id`: 404 when there is none, or when the caller is
/// no member of its project.
async fn stored(state: &AppState, caller: &Caller, id: &str) -> Result<CostmapRow, ApiError> {
    visible_costmap(state, caller, id, Role::Viewer).await
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
    // A finished costmap never changes.
    let answer = Immutable::new(format!("\"{}-{}\"", row.id, file.replace('/', "-")));
    if answer.matches(request_headers) {
        return Ok(answer.not_modified());
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
    answer.apply(&mut res);
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
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &caller, &id).await?;
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
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &caller, &id).await?;
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
    caller: Caller,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &caller, &id).await?;
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
    caller: Caller,
    Path((id, file)): Path<(String, String)>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let row = stored(&state, &caller, &id).await?;
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
