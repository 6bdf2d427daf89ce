//! The DEMs resource's reads: list, fetch, delete, the hillshade preview
//! and heights at WGS84 points.

use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use geo_types::Coord;
use planner_core::geo::{Issue, escape_pointer_token};
use planner_core::terrain::{
    Dem, DemFormat, DemWindows, RasterGrid, RasterWindows, TerrainError, TerrainSampler,
    hillshade_png,
};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::model::{BinaryFile, DemList, DemResponse, response, stored_info, visible_dem};
use crate::api::access::{ProjectFilter, list_visible};
use crate::api::immutable::Immutable;
use crate::api::json_body::JsonBody;
use crate::api::paging::ListQuery;
use crate::auth::{Caller, Role};
use crate::db::DemMetaRow;
use crate::error::{ApiError, Problem, deleted};
use crate::memory::{Reservation, hillshade_bytes};
use crate::state::dem_store::tiles::{self, StoredTiles, TileSet};
use crate::state::{AppState, Work};

/// Most points in one `POST …/elevation`.
const MAX_ELEVATION_POINTS: usize = 10_000;
const HILLSHADE_DEFAULT_SIDE: i64 = 1024;
const HILLSHADE_MIN_SIDE: i64 = 16;
const HILLSHADE_MAX_SIDE: i64 = 4096;

/// Stored DEMs, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/api/v1/dems",
    tag = "dems",
    params(ListQuery, ProjectFilter),
    responses(
        (status = 200, description = "A page of the DEMs of the caller's projects", body = DemList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No project `project_id` (of the caller's)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_dems(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<ProjectFilter>, QueryRejection>,
) -> Result<Json<DemList>, ApiError> {
    let db = &state.db;
    let user = caller.user_id.as_str();
    let page = list_visible(
        db,
        &caller,
        query,
        filter,
        |project, limit, offset| async move {
            db.list_dems(user, project.as_deref(), limit, offset).await
        },
        |r| Ok(response(r, stored_info(r)?)),
    )
    .await?;
    Ok(Json(page.into()))
}

/// A stored DEM's metadata.
#[utoipa::path(
    get,
    path = "/api/v1/dems/{id}",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id")),
    responses(
        (status = 200, description = "The DEM's metadata", body = DemResponse),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get_dem(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<DemResponse>, ApiError> {
    let row = visible_dem(&state, &caller, &id, Role::Viewer).await?;
    let info = stored_info(&row)?;
    Ok(Json(response(&row, info)))
}

/// Delete a DEM.
#[utoipa::path(
    delete,
    path = "/api/v1/dems/{id}",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 403, description = "The caller is a viewer of the DEM's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_dem(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    visible_dem(&state, &caller, &id, Role::Editor).await?;
    let gone = state.db.delete_dem(&id).await?;
    state.dems.cache.evict(&id);
    deleted(gone, "DEM", &id)
}

/// A hillshade preview of the DEM as a PNG, at most `max_side` pixels on
/// its longer side. DEMs never change, so the image may be cached for good.
#[utoipa::path(
    get,
    path = "/api/v1/dems/{id}/hillshade.png",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id"), HillshadeQuery),
    responses(
        (status = 200, description = "The hillshade", content_type = "image/png", body = BinaryFile,
            headers(
                ("ETag" = String, description = "Stable per DEM and size"),
                ("Cache-Control" = String, description = "Immutable"),
            )),
        (status = 304, description = "Not modified (If-None-Match)"),
        (status = 400, description = "max_side out of range", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Reading the DEM and shading it need more than the server's memory budget", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner or the memory budget is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn hillshade(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    query: Result<Query<HillshadeQuery>, QueryRejection>,
    request_headers: HeaderMap,
) -> Result<Response, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let max_side = q.max_side.unwrap_or(HILLSHADE_DEFAULT_SIDE);
    if !(HILLSHADE_MIN_SIDE..=HILLSHADE_MAX_SIDE).contains(&max_side) {
        return Err(ApiError::BadRequest(format!(
            "max_side {max_side} is outside [{HILLSHADE_MIN_SIDE}, {HILLSHADE_MAX_SIDE}]"
        )));
    }
    let answer = Immutable::new(format!("\"{id}-hillshade-{max_side}\""));
    // 404 or 304 without reading the DEM.
    visible_dem(&state, &caller, &id, Role::Viewer).await?;
    if answer.matches(&request_headers) {
        return Ok(answer.not_modified());
    }
    let side = max_side as u64;
    let (dem, room) = match overview_for(&state, &id, side).await? {
        Some(found) => found,
        None => {
            state
                .load_dem_for(&id, "a hillshade", |w, h| hillshade_bytes(w, h, side))
                .await?
        }
    };
    let png = state
        .run_planner(Work::Dem, move |_| hillshade_png(&dem, max_side as usize))
        .await??;
    drop(room);
    let mut res = png.into_response();
    res.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
    answer.apply(&mut res);
    Ok(res)
}

/// DEMs of more cells than this are previewed from an overview level
/// of their tiles rather than read whole (smaller ones exactly as before).
const BIG_DEM_PIXELS: u64 = 64_000_000;

/// The stored tiles of DEM `id` and its level-0 grid, when it has them.
async fn tile_source(
    state: &AppState,
    id: &str,
) -> Result<Option<(TileSet, RasterGrid, DemMetaRow)>, ApiError> {
    let meta = state
        .db
        .get_dem_meta(id)
        .await?
        .ok_or_else(|| crate::error::not_found("DEM", id))?;
    let info = stored_info(&meta)?;
    Ok(tiles::stored_set(&state.db, id, &info)
        .await?
        .map(|(set, grid)| (set, grid, meta)))
}

/// A big DEM's hillshade source: the smallest overview level at least
/// `side` cells on its longer side, read whole (with room for it and the
/// shading); `None` for a DEM of at most [`BIG_DEM_PIXELS`] or without
/// tiles.
async fn overview_for(
    state: &AppState,
    id: &str,
    side: u64,
) -> Result<Option<(Arc<Dem>, Reservation)>, ApiError> {
    let Some((set, grid, _)) = tile_source(state, id).await? else {
        return Ok(None);
    };
    if (set.width as u64).saturating_mul(set.height as u64) <= BIG_DEM_PIXELS {
        return Ok(None);
    }
    let level = (0..set.levels)
        .rev()
        .find(|&l| {
            let (w, h) = set.level_size(l);
            w.max(h) as u64 >= side
        })
        .unwrap_or(0);
    let (w, h) = set.level_size(level);
    let (w, h) = (w as u64, h as u64);
    let need = w
        .saturating_mul(h)
        .saturating_mul(8)
        .saturating_add(hillshade_bytes(w, h, side));
    let room = state
        .memory
        .reserve(
            need,
            &format!("a hillshade of DEM {id} (overview {w} × {h})"),
        )
        .await?;
    let src = StoredTiles::new(
        state.db.clone(),
        tokio::runtime::Handle::current(),
        id,
        set,
        level,
        &grid,
    );
    let dem = state
        .run_planner(Work::Dem, move |_| src.read_whole(DemFormat::GeoTiff))
        .await?
        .map_err(|e| ApiError::Internal(format!("stored DEM {id} does not read again: {e}")))?;
    Ok(Some((Arc::new(dem), room)))
}

/// Most cells one window request answers (32 MiB of f64).
const MAX_WINDOW_CELLS: u64 = 4 << 20;

/// The cells of a window of a stored DEM (or of one of its overview
/// levels), read from its tiles: `width × height` little-endian f64,
/// row by row from the top, NaN for nodata.
#[utoipa::path(
    get,
    path = "/api/v1/dems/{id}/window",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id"), WindowQuery),
    responses(
        (status = 200, description = "The window's cells, f64 little-endian, row-major", content_type = "application/octet-stream", body = BinaryFile),
        (status = 400, description = "A window outside the raster (or level), or too many cells", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner or the memory budget is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn window(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    query: Result<Query<WindowQuery>, QueryRejection>,
) -> Result<Response, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let cells = q.width.saturating_mul(q.height);
    if cells > MAX_WINDOW_CELLS {
        return Err(ApiError::BadRequest(format!(
            "a window of {} × {} cells is over the limit of {MAX_WINDOW_CELLS} cells",
            q.width, q.height
        )));
    }
    visible_dem(&state, &caller, &id, Role::Viewer).await?;
    let level = q.level.unwrap_or(0);
    let room = state
        .memory
        .reserve(cells.saturating_mul(16) + (8 << 20), "a window of a DEM")
        .await?;
    let (c0, r0, w, h) = (
        q.col as usize,
        q.row as usize,
        q.width as usize,
        q.height as usize,
    );
    let cells = match tile_source(&state, &id).await? {
        Some((set, grid, _)) => {
            if level as usize >= set.levels {
                return Err(ApiError::BadRequest(format!(
                    "level {level} does not exist: DEM {id} has levels 0 to {}",
                    set.levels - 1
                )));
            }
            let src = StoredTiles::new(
                state.db.clone(),
                tokio::runtime::Handle::current(),
                &id,
                set,
                level as usize,
                &grid,
            );
            state
                .run_planner(Work::Dem, move |_| {
                    let mut out = vec![0.0; w * h];
                    src.read_window(c0, r0, w, h, &mut out).map(|_| out)
                })
                .await?
        }
        None if level > 0 => {
            return Err(ApiError::BadRequest(format!(
                "DEM {id} was stored before tiles: it has level 0 only"
            )));
        }
        None => {
            let (dem, _room) = state.load_dem_for(&id, "", |_, _| 0).await?;
            state
                .run_planner(Work::Dem, move |_| {
                    let mut out = vec![0.0; w * h];
                    DemWindows::new(&dem)
                        .read_window(c0, r0, w, h, &mut out)
                        .map(|_| out)
                })
                .await?
        }
    }
    .map_err(|e| ApiError::BadRequest(e.to_string()))?;
    let mut body = Vec::with_capacity(cells.len() * 8);
    for v in cells {
        body.extend_from_slice(&v.to_le_bytes());
    }
    drop(room);
    let mut res = body.into_response();
    res.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/octet-stream"),
    );
    Ok(res)
}

fn check_lon_lat(lon: f64, lat: f64) -> Result<(), String> {
    if !(-180.0..=180.0).contains(&lon) {
        return Err(format!(
            "longitude {} is outside [-180, 180]",
            planner_core::num::readable(lon)
        ));
    }
    if !(-90.0..=90.0).contains(&lat) {
        return Err(format!(
            "latitude {} is outside [-90, 90]",
            planner_core::num::readable(lat)
        ));
    }
    Ok(())
}

/// Heights of `points` (lon, lat) on `dem`, off the async runtime.
async fn heights(
    state: &AppState,
    dem: Arc<Dem>,
    points: Vec<(f64, f64)>,
) -> Result<Vec<Option<f64>>, ApiError> {
    state
        .run_planner(Work::Dem, move |_| {
            let sampler = TerrainSampler::new(&dem, 4326)?;
            Ok::<_, TerrainError>(
                points
                    .iter()
                    .map(|&(x, y)| sampler.height(Coord { x, y }).filter(|h| h.is_finite()))
                    .collect(),
            )
        })
        .await?
        .map_err(|e| ApiError::Internal(format!("cannot sample the DEM: {e}")))
}

/// The height at a WGS84 point (bilinear between cell centres, in the
/// DEM's own CRS).
#[utoipa::path(
    get,
    path = "/api/v1/dems/{id}/elevation",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id"), PointQuery),
    responses(
        (status = 200, description = "The height, or null outside the DEM or on nodata", body = Elevation),
        (status = 400, description = "lon/lat missing or out of range", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Reading the DEM needs more than the server's memory budget", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner or the memory budget is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn elevation(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    query: Result<Query<PointQuery>, QueryRejection>,
) -> Result<Json<Elevation>, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    check_lon_lat(q.lon, q.lat).map_err(ApiError::BadRequest)?;
    // Checked before the DEM cache is asked: it is keyed by id alone.
    visible_dem(&state, &caller, &id, Role::Viewer).await?;
    let (dem, _room) = state.load_dem_for(&id, "", |_, _| 0).await?;
    let h = heights(&state, dem, vec![(q.lon, q.lat)]).await?;
    Ok(Json(Elevation {
        elevation: h.first().copied().flatten(),
    }))
}

/// Read the `points` of an elevations request, reporting every fault by
/// JSON pointer (at most 100).
fn parse_points(doc: &Value) -> Result<Vec<(f64, f64)>, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with \"points\"",
        )]));
    };
    let mut issues = Vec::new();
    for key in obj.keys().filter(|k| k.as_str() != "points") {
        issues.push(Issue::new(
            &format!("/{}", escape_pointer_token(key)),
            &format!("unknown field {key:?}: expected \"points\""),
        ));
    }
    let list = match obj.get("points") {
        None => {
            issues.push(Issue::new(
                "/points",
                "required: a list of [lon, lat] pairs",
            ));
            return Err(ApiError::Validation(issues));
        }
        Some(Value::Array(list)) => list,
        Some(_) => {
            issues.push(Issue::new("/points", "must be a list of [lon, lat] pairs"));
            return Err(ApiError::Validation(issues));
        }
    };
    if list.len() > MAX_ELEVATION_POINTS {
        issues.push(Issue::new(
            "/points",
            &format!(
                "{} points is over the limit of {MAX_ELEVATION_POINTS}",
                list.len()
            ),
        ));
        return Err(ApiError::Validation(issues));
    }
    let mut points = Vec::with_capacity(list.len());
    for (i, p) in list.iter().enumerate() {
        if issues.len() >= 100 {
            break;
        }
        let ptr = format!("/points/{i}");
        let pair = match p.as_array() {
            Some(a) if (2..=3).contains(&a.len()) => a,
            _ => {
                issues.push(Issue::new(&ptr, "must be a [lon, lat] pair"));
                continue;
            }
        };
        let (Some(lon), Some(lat)) = (pair[0].as_f64(), pair[1].as_f64()) else {
            issues.push(Issue::new(&ptr, "lon and lat must be numbers"));
            continue;
        };
        match check_lon_lat(lon, lat) {
            Ok(()) => points.push((lon, lat)),
            Err(m) => issues.push(Issue::new(&ptr, &m)),
        }
    }
    if issues.is_empty() {
        Ok(points)
    } else {
        Err(ApiError::Validation(issues))
    }
}

/// Heights at many WGS84 points at once (at most 10000).
#[utoipa::path(
    post,
    path = "/api/v1/dems/{id}/elevation",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id")),
    request_body(content = ElevationsRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "One height (or null) per point, in order", body = Elevations),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid points: `errors` names each by JSON pointer; or reading the DEM needs more than the server's memory budget", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn elevations(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Json<Elevations>, ApiError> {
    let points = parse_points(&doc)?;
    visible_dem(&state, &caller, &id, Role::Viewer).await?;
    let (dem, _room) = state.load_dem_for(&id, "", |_, _| 0).await?;
    let elevations = heights(&state, dem, points).await?;
    Ok(Json(Elevations { elevations }))
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct WindowQuery {
    /// The window's first column (0 is the left).
    col: u64,
    /// The window's first row (0 is the top).
    row: u64,
    /// Columns, at least 0.
    width: u64,
    /// Rows, at least 0.
    height: u64,
    /// The level: 0 the DEM itself, k its k-th overview (2^k times
    /// coarser, each cell the mean of the cells below it).
    level: Option<u64>,
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct HillshadeQuery {
    /// Most pixels on the image's longer side (the DEM's aspect ratio is kept).
    #[param(minimum = 16, maximum = 4096, default = 1024)]
    max_side: Option<i64>,
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PointQuery {
    /// Longitude, degrees (WGS84).
    #[param(minimum = -180.0, maximum = 180.0)]
    lon: f64,
    /// Latitude, degrees (WGS84).
    #[param(minimum = -90.0, maximum = 90.0)]
    lat: f64,
}

/// The height at one point.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct Elevation {
    /// Height in the DEM's vertical datum, metres (bilinear between cell
    /// centres); `null` outside the raster or where it touches nodata.
    elevation: Option<f64>,
}

/// Points to read heights at.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the body for the OpenAPI schema
pub struct ElevationsRequest {
    /// `[lon, lat]` pairs in degrees (WGS84); a third member (altitude) is
    /// ignored.
    #[schema(max_items = 10000, value_type = Vec<Vec<f64>>)]
    points: Vec<[f64; 2]>,
}

/// Heights at the requested points, in their order.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct Elevations {
    /// Height per point (see `Elevation`); `null` outside or on nodata.
    elevations: Vec<Option<f64>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points() {
        let ok = parse_points(&serde_json::json!({"points": [[5.0, 45.0], [6.0, 46.0, 100.0]]}))
            .unwrap();
        assert_eq!(ok, vec![(5.0, 45.0), (6.0, 46.0)]);
        let Err(ApiError::Validation(issues)) =
            parse_points(&serde_json::json!({"points": [[5.0, 95.0], "x"], "extra": 1}))
        else {
            panic!("expected issues");
        };
        let ptrs: Vec<&str> = issues.iter().map(|i| i.pointer.as_str()).collect();
        assert_eq!(ptrs, ["/extra", "/points/0", "/points/1"]);
    }
}
