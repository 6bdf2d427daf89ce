//! The DEMs resource: upload an elevation raster (GeoTIFF, ESRI ASCII grid
//! or SRTM `.hgt`), list, fetch its metadata, delete, render a hillshade
//! preview and read heights at WGS84 points.
//!
//! The uploaded file is stored as it came (with the CRS the uploader gave,
//! if any) and parsed again on demand; parsed rasters are kept in the
//! state's small cache ([`AppState::load_dem`]).
//!
//! An upload is written to a spool file in the data directory as it
//! arrives (a slow or large upload holds no more than a buffer of
//! memory), its header is read for the raster's declared size, and only
//! then, with room for it in the memory budget, is it read; a raster
//! whose reading alone needs more than the budget (a small compressed
//! file declaring huge pixel counts) is refused before anything of that
//! size is allocated. It is stored a chunk at a time.

use std::io::Write;
use std::path::{Path as FsPath, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use axum::Json;
use axum::extract::multipart::MultipartError;
use axum::extract::{
    FromRequest, Multipart, Path, Query, Request, State, rejection::QueryRejection,
};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use geo_types::Coord;
use planner_core::geo::Issue;
use planner_core::terrain::{Dem, DemInfo, TerrainError, TerrainSampler, hillshade_png, read_dem};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::dem_header;
use super::json_body::{JsonBody, media_type};
use super::paging::{ListQuery, page};
use super::rfc3339;
use crate::app::AppState;
use crate::costmap_jobs::now_millis;
use crate::db::{CHUNK_BYTES, DemMetaRow};
use crate::error::{ApiError, Problem};
use crate::memory::{dem_read_bytes, hillshade_bytes, mib};

const NAME_MAX_CHARS: usize = 200;
const FILE_NAME_MAX_CHARS: usize = 255;
/// Most points in one `POST …/elevation`.
pub const MAX_ELEVATION_POINTS: usize = 10_000;
const HILLSHADE_DEFAULT_SIDE: i64 = 1024;
const HILLSHADE_MIN_SIDE: i64 = 16;
const HILLSHADE_MAX_SIDE: i64 = 4096;

/// Media types taken as the raw DEM file.
const RAW_TYPES: [&str; 3] = ["image/tiff", "application/octet-stream", "text/plain"];

/// A stored DEM: who it is and what the raster holds.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct DemResponse {
    id: String,
    name: Option<String>,
    /// The uploaded file's name, when one was given.
    file_name: Option<String>,
    /// Upload time, RFC 3339 (UTC).
    created_at: String,
    /// Size of the uploaded file, bytes.
    size_bytes: i64,
    #[serde(flatten)]
    info: DemInfo,
    /// URL of this DEM.
    url: String,
    /// URL of its hillshade preview (PNG).
    hillshade: String,
}

/// A page of DEMs, newest first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct DemList {
    items: Vec<DemResponse>,
    /// DEMs stored in all.
    total: i64,
    limit: i64,
    offset: i64,
}

/// A file's bytes.
#[derive(ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)] // documents binary bodies for the OpenAPI schema
pub struct BinaryFile(Vec<u8>);

/// `multipart/form-data` upload: the file in the part `file`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the form for the OpenAPI schema
pub struct DemUpload {
    /// The DEM file (GeoTIFF, ESRI ASCII grid or SRTM `.hgt`); the part's
    /// filename is kept, and gives an `.hgt` file its extent.
    #[schema(value_type = String, format = Binary, content_media_type = "application/octet-stream")]
    file: Vec<u8>,
    /// A label (the `name` query parameter wins when both are given).
    #[schema(max_length = 200)]
    name: Option<String>,
    /// The CRS, like the `crs` query parameter.
    #[schema(example = "EPSG:32633")]
    crs: Option<String>,
}

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct UploadQuery {
    /// A label for the DEM.
    #[param(max_length = 200)]
    name: Option<String>,
    /// EPSG code of the raster's horizontal CRS, as `EPSG:32633` or
    /// `32633`. Needed when the file does not say (ESRI ASCII grids,
    /// GeoTIFFs without GeoKeys or with a local engineering CRS); when
    /// given it overrides the file's.
    #[param(example = "EPSG:32633")]
    crs: Option<String>,
    /// The file's name, for a raw body (a multipart part carries its own):
    /// an SRTM `.hgt` file's extent is in its name, e.g. `N45E006.hgt`.
    #[param(max_length = 255, example = "N45E006.hgt")]
    file_name: Option<String>,
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

pub fn dem_url(id: &str) -> String {
    format!("/api/v1/dems/{id}")
}

pub fn not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("there is no DEM with id {id:?}"))
}

/// An EPSG code from `EPSG:32633` (any case) or `32633`.
pub fn parse_epsg(text: &str) -> Result<u32, String> {
    let t = text.trim();
    let digits = match t.get(..5) {
        Some(p) if p.eq_ignore_ascii_case("epsg:") => t[5..].trim(),
        _ => t,
    };
    match digits.parse::<u32>() {
        Ok(code) if code > 0 && digits.bytes().all(|b| b.is_ascii_digit()) => Ok(code),
        _ => Err(format!(
            "the CRS must be an EPSG code such as EPSG:32633 or 32633, got {text:?}"
        )),
    }
}

/// The last component of a client's file name (browsers may send a path).
fn base_name(name: &str) -> Option<String> {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name).trim();
    (!base.is_empty()).then(|| base.to_string())
}

/// How a failure to read an uploaded raster is answered.
pub fn terrain_error(e: TerrainError) -> ApiError {
    let invalid = |m: String| ApiError::Validation(vec![Issue::new("", &m)]);
    match e {
        TerrainError::TooLarge { .. } => {
            ApiError::PayloadTooLarge(format!("the DEM is too large: {e}"))
        }
        TerrainError::UnknownCrs(why) => invalid(format!(
            "the raster's coordinate reference system cannot be determined ({why}): give it \
             in the query string, e.g. ?crs=EPSG:32633"
        )),
        TerrainError::Invalid(m) => invalid(format!("the file cannot be read as a DEM: {m}")),
        TerrainError::Unsupported(m) => invalid(format!(
            "the DEM uses a feature terraplan does not read: {m}"
        )),
        TerrainError::Crs(m) => invalid(format!("coordinate reference system: {m}")),
        TerrainError::Cancelled(c) => c.into(),
    }
}

/// A stored DEM's width and height, from its stored info.
pub fn stored_size(row: &DemMetaRow) -> Result<(u64, u64), ApiError> {
    #[derive(Deserialize)]
    struct Size {
        width: u64,
        height: u64,
    }
    let size: Size = serde_json::from_str(&row.info).map_err(|e| {
        ApiError::Internal(format!("stored DEM info of {} unreadable: {e}", row.id))
    })?;
    Ok((size.width, size.height))
}

fn stored_info(row: &DemMetaRow) -> Result<DemInfo, ApiError> {
    let mut info: DemInfo = serde_json::from_str(&row.info).map_err(|e| {
        ApiError::Internal(format!("stored DEM info of {} unreadable: {e}", row.id))
    })?;
    // Stored before `crs.proj4` existed.
    info.crs.fill_proj4();
    Ok(info)
}

fn response(row: &DemMetaRow, info: DemInfo) -> DemResponse {
    let url = dem_url(&row.id);
    DemResponse {
        id: row.id.clone(),
        name: row.name.clone(),
        file_name: row.file_name.clone(),
        created_at: rfc3339(row.created_at),
        size_bytes: row.size_bytes,
        info,
        hillshade: format!("{url}/hillshade.png"),
        url,
    }
}

fn too_large(limit: usize) -> ApiError {
    ApiError::PayloadTooLarge(format!(
        "the DEM file is too large: the limit is {limit} bytes ({} MiB, --max-dem-mb)",
        limit / (1024 * 1024)
    ))
}

fn multipart_error(e: MultipartError, limit: usize) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        too_large(limit)
    } else {
        ApiError::BadRequest(format!("malformed multipart body: {}", e.body_text()))
    }
}

/// Spool files untouched for this long belong to no upload in progress
/// (the server stopped during it): removed at start-up.
const STALE_SPOOL: Duration = Duration::from_secs(3600);

/// Where uploads are spooled under `data_dir`, with the files left behind
/// by a server that stopped during an upload removed.
pub fn spool_dir(data_dir: &FsPath) -> PathBuf {
    let dir = data_dir.join("uploads");
    if let Ok(entries) = std::fs::read_dir(&dir) {
        for entry in entries.flatten() {
            let stale = entry
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t.elapsed().is_ok_and(|age| age > STALE_SPOOL));
            if stale && entry.path().extension().is_some_and(|e| e == "part") {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    dir
}

/// An upload spooled to a file, removed when dropped.
struct Spool {
    path: PathBuf,
    len: u64,
}

impl Drop for Spool {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Writes an upload to its spool file as it arrives, a buffer at a time.
struct SpoolWriter {
    spool: Spool,
    file: Option<std::fs::File>,
    buf: Vec<u8>,
    limit: usize,
}

fn spool_error(e: impl std::fmt::Display) -> ApiError {
    ApiError::Internal(format!("cannot spool the upload: {e}"))
}

impl SpoolWriter {
    async fn create(dir: &FsPath, limit: usize) -> Result<SpoolWriter, ApiError> {
        let dir = dir.to_path_buf();
        let path = dir.join(format!("{}.part", uuid::Uuid::new_v4()));
        let spool = Spool { path, len: 0 };
        let at = spool.path.clone();
        let file = tokio::task::spawn_blocking(move || {
            std::fs::create_dir_all(&dir)?;
            std::fs::File::create(&at)
        })
        .await
        .map_err(spool_error)?
        .map_err(spool_error)?;
        Ok(SpoolWriter {
            spool,
            file: Some(file),
            buf: Vec::new(),
            limit,
        })
    }

    /// Append `bytes`; 413 once more than the limit has arrived.
    async fn push(&mut self, bytes: &[u8]) -> Result<(), ApiError> {
        self.spool.len += bytes.len() as u64;
        if self.spool.len > self.limit as u64 {
            return Err(too_large(self.limit));
        }
        self.buf.extend_from_slice(bytes);
        if self.buf.len() >= CHUNK_BYTES {
            self.flush().await?;
        }
        Ok(())
    }

    async fn flush(&mut self) -> Result<(), ApiError> {
        let (Some(mut file), buf) = (self.file.take(), std::mem::take(&mut self.buf)) else {
            return Err(spool_error("the spool file is closed"));
        };
        let (file, mut buf, written) = tokio::task::spawn_blocking(move || {
            let written = file.write_all(&buf);
            (file, buf, written)
        })
        .await
        .map_err(spool_error)?;
        written.map_err(spool_error)?;
        buf.clear();
        self.file = Some(file);
        self.buf = buf;
        Ok(())
    }

    async fn finish(mut self) -> Result<Spool, ApiError> {
        self.flush().await?;
        Ok(self.spool)
    }
}

/// A raw request body, spooled.
async fn spool_body(req: Request, dir: &FsPath, limit: usize) -> Result<Spool, ApiError> {
    use futures_util::StreamExt;
    let mut writer = SpoolWriter::create(dir, limit).await?;
    let mut body = req.into_body().into_data_stream();
    while let Some(bytes) = body.next().await {
        let bytes = bytes
            .map_err(|e| ApiError::BadRequest(format!("cannot read the request body: {e}")))?;
        writer.push(&bytes).await?;
    }
    writer.finish().await
}

/// The uploaded file and what the form may add to the query.
struct Upload {
    file: Option<Spool>,
    file_name: Option<String>,
    name: Option<String>,
    crs: Option<String>,
}

async fn read_multipart(req: Request, state: &AppState, limit: usize) -> Result<Upload, ApiError> {
    let mut form = Multipart::from_request(req, state).await.map_err(|e| {
        ApiError::BadRequest(format!("malformed multipart body: {}", e.body_text()))
    })?;
    let mut upload = Upload {
        file: None,
        file_name: None,
        name: None,
        crs: None,
    };
    let mut have_file = false;
    while let Some(mut field) = form
        .next_field()
        .await
        .map_err(|e| multipart_error(e, limit))?
    {
        let field_name = field.name().unwrap_or("").to_string();
        match field_name.as_str() {
            "file" => {
                if have_file {
                    return Err(ApiError::Validation(vec![Issue::new(
                        "/file",
                        "the form has more than one part named \"file\": send one DEM per request",
                    )]));
                }
                have_file = true;
                upload.file_name = field.file_name().and_then(base_name);
                let mut writer = SpoolWriter::create(&state.dems.spool_dir, limit).await?;
                while let Some(bytes) =
                    field.chunk().await.map_err(|e| multipart_error(e, limit))?
                {
                    writer.push(&bytes).await?;
                }
                upload.file = Some(writer.finish().await?);
            }
            "name" | "crs" => {
                let text = field.text().await.map_err(|e| multipart_error(e, limit))?;
                let slot = if field_name == "name" {
                    &mut upload.name
                } else {
                    &mut upload.crs
                };
                *slot = Some(text);
            }
            other => {
                return Err(ApiError::Validation(vec![Issue::new(
                    &format!("/{other}"),
                    &format!("unknown form field {other:?}: expected file, name or crs"),
                )]));
            }
        }
    }
    if !have_file {
        return Err(ApiError::Validation(vec![Issue::new(
            "/file",
            "the form has no part named \"file\" holding the DEM",
        )]));
    }
    Ok(upload)
}

/// Upload a DEM: the file as the body (`image/tiff`, `application/octet-stream`,
/// `text/plain` for an ESRI ASCII grid) or as the part `file` of a
/// `multipart/form-data` form. Formats: GeoTIFF (Int16, UInt16, Int32,
/// Float32, Float64; strips or tiles; none, LZW, Deflate, PackBits),
/// ESRI ASCII grid, SRTM `.hgt` (give its file name). The CRS comes from
/// the file's GeoKeys unless `crs` is given; a file without one is
/// rejected until it is.
#[utoipa::path(
    post,
    path = "/api/v1/dems",
    tag = "dems",
    params(UploadQuery),
    request_body(
        description = "The DEM file, raw or as the form part `file`",
        content(
            (BinaryFile = "image/tiff"),
            (BinaryFile = "application/octet-stream"),
            (String = "text/plain"),
            (DemUpload = "multipart/form-data"),
        )
    ),
    responses(
        (status = 201, description = "Read and stored", body = DemResponse,
            headers(("Location" = String, description = "URL of the new DEM"))),
        (status = 400, description = "Empty body, malformed form or query", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "File over the size limit, raster over the pixel limit, or a raster whose declared size needs more than the memory budget to read", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported Content-Type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Not a readable DEM, or its CRS is unknown (give `crs`)", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn upload_dem(
    State(state): State<AppState>,
    query: Result<Query<UploadQuery>, QueryRejection>,
    req: Request,
) -> Result<Response, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let limit = state.dems.max_upload_bytes;
    let (content_type, essence) = media_type(req.headers());
    let upload = if essence == "multipart/form-data" {
        read_multipart(req, &state, limit).await?
    } else if RAW_TYPES.contains(&essence.as_str()) {
        Upload {
            file: Some(spool_body(req, &state.dems.spool_dir, limit).await?),
            file_name: None,
            name: None,
            crs: None,
        }
    } else {
        let accepted = "send the file as image/tiff, application/octet-stream or text/plain, \
                        or as the part \"file\" of multipart/form-data";
        return Err(ApiError::UnsupportedMediaType(if content_type.is_empty() {
            format!("the request has no Content-Type: {accepted}")
        } else {
            format!("Content-Type {content_type:?} is not supported: {accepted}")
        }));
    };

    let name = q.name.or(upload.name);
    if let Some(n) = &name
        && n.chars().count() > NAME_MAX_CHARS
    {
        return Err(ApiError::BadRequest(format!(
            "the name is longer than {NAME_MAX_CHARS} characters"
        )));
    }
    let file_name = match q.file_name {
        Some(f) if f.chars().count() > FILE_NAME_MAX_CHARS => {
            return Err(ApiError::BadRequest(format!(
                "file_name is longer than {FILE_NAME_MAX_CHARS} characters"
            )));
        }
        Some(f) => base_name(&f),
        None => upload.file_name,
    };
    let faults: Vec<Issue> = [
        name.as_deref()
            .and_then(|n| crate::api::names::control_character_issue("/name", "the name", n)),
        file_name.as_deref().and_then(|f| {
            crate::api::names::control_character_issue("/file_name", "the file name", f)
        }),
    ]
    .into_iter()
    .flatten()
    .collect();
    if !faults.is_empty() {
        return Err(ApiError::Validation(faults));
    }
    let crs = q
        .crs
        .or(upload.crs)
        .map(|c| parse_epsg(&c))
        .transpose()
        .map_err(ApiError::BadRequest)?;
    let Some(spool) = upload.file.filter(|f| f.len > 0) else {
        return Err(ApiError::BadRequest(
            "the DEM file is empty: send a GeoTIFF, ESRI ASCII grid or SRTM .hgt file".into(),
        ));
    };

    // The raster's declared size, from its header, before it is read.
    let (at, len, probe_name) = (spool.path.clone(), spool.len, file_name.clone());
    let declared = tokio::task::spawn_blocking(move || {
        let mut f = std::fs::File::open(at).ok()?;
        dem_header::declared(&mut f, len, probe_name.as_deref())
    })
    .await
    .map_err(spool_error)?;
    let limits = state.dems.limits.clone();
    let need = match &declared {
        Some(d) => {
            let over_side = d.width.max(d.height) > u64::from(limits.max_side);
            if over_side || d.pixels() > limits.max_pixels {
                // The same refusal the full read gives, before it.
                return Err(terrain_error(TerrainError::TooLarge {
                    width: d.width,
                    height: d.height,
                    limit: if over_side {
                        format!("{} pixels per side", limits.max_side)
                    } else {
                        format!("{} pixels", limits.max_pixels)
                    },
                }));
            }
            dem_read_bytes(d.pixels(), d.chunk_bytes, len)
        }
        // Not a raster whose header says its size: the full read refuses
        // it without allocating much.
        None => dem_read_bytes(0, 0, len),
    };
    let budget = state.memory.total();
    if need > budget {
        let what = match &declared {
            Some(d) => format!(
                "it declares {} × {} {} pixels ({} in all)",
                d.width,
                d.height,
                d.sample,
                d.pixels()
            ),
            None => format!("the file is {len} bytes"),
        };
        return Err(ApiError::PayloadTooLarge(format!(
            "the DEM is too large for this server's memory: {what}, and reading it needs \
             about {}, more than the memory budget of {} (--memory-budget-mb)",
            mib(need),
            mib(budget)
        )));
    }
    let _room = state
        .memory
        .reserve(need, "reading the uploaded DEM")
        .await?;
    let path = spool.path.clone();
    let data = tokio::fs::read(&path).await.map_err(spool_error)?;
    let data = Arc::new(data);
    drop(spool);

    let parse_name = file_name.clone();
    let parse_data = data.clone();
    let (dem, info) = state
        .run_planner(crate::app::Work::Dem, move |_| {
            let dem = read_dem(&parse_data, parse_name.as_deref(), crs, &limits)?;
            let info = dem.info()?;
            Ok::<_, TerrainError>((dem, info))
        })
        .await?
        .map_err(terrain_error)?;

    let row = DemMetaRow {
        id: uuid::Uuid::now_v7().to_string(),
        name,
        created_at: now_millis(),
        file_name,
        crs_override: crs.map(i64::from),
        info: serde_json::to_string(&info).map_err(|e| ApiError::Internal(e.to_string()))?,
        size_bytes: data.len() as i64,
        read_bytes: i64::try_from(need).ok(),
    };
    state.db.insert_dem(&row, &data).await?;
    state.dems.cache.insert(&row.id, Arc::new(dem), None);
    let body = response(&row, info);
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&body.url) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::CREATED, headers, Json(body)).into_response())
}

/// Stored DEMs, newest first, a page at a time.
#[utoipa::path(
    get,
    path = "/api/v1/dems",
    tag = "dems",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of DEMs", body = DemList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_dems(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<DemList>, ApiError> {
    let (limit, offset) = page(query)?;
    let (rows, total) = state.db.list_dems(limit, offset).await?;
    let items = rows
        .iter()
        .map(|r| Ok(response(r, stored_info(r)?)))
        .collect::<Result<Vec<_>, ApiError>>()?;
    Ok(Json(DemList {
        items,
        total,
        limit,
        offset,
    }))
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
    Path(id): Path<String>,
) -> Result<Json<DemResponse>, ApiError> {
    let row = state
        .db
        .get_dem_meta(&id)
        .await?
        .ok_or_else(|| not_found(&id))?;
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
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_dem(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let deleted = state.db.delete_dem(&id).await?;
    state.dems.cache.evict(&id);
    if deleted {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(not_found(&id))
    }
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
    let etag = format!("\"{id}-hillshade-{max_side}\"");
    let cache_headers = |res: &mut Response| {
        let h = res.headers_mut();
        if let Ok(v) = HeaderValue::from_str(&etag) {
            h.insert(header::ETAG, v);
        }
        h.insert(
            header::CACHE_CONTROL,
            HeaderValue::from_static("public, max-age=31536000, immutable"),
        );
    };
    // 404 or 304 without reading the DEM.
    state
        .db
        .get_dem_meta(&id)
        .await?
        .ok_or_else(|| not_found(&id))?;
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
    let side = max_side as u64;
    let (dem, room) = state
        .load_dem_for(&id, "a hillshade", |w, h| hillshade_bytes(w, h, side))
        .await?;
    let png = state
        .run_planner(crate::app::Work::Dem, move |_| {
            hillshade_png(&dem, max_side as usize)
        })
        .await??;
    drop(room);
    let mut res = png.into_response();
    res.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("image/png"));
    cache_headers(&mut res);
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
        .run_planner(crate::app::Work::Dem, move |_| {
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
    Path(id): Path<String>,
    query: Result<Query<PointQuery>, QueryRejection>,
) -> Result<Json<Elevation>, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    check_lon_lat(q.lon, q.lat).map_err(ApiError::BadRequest)?;
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
            &format!("/{}", key.replace('~', "~0").replace('/', "~1")),
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
    Path(id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Json<Elevations>, ApiError> {
    let points = parse_points(&doc)?;
    let (dem, _room) = state.load_dem_for(&id, "", |_, _| 0).await?;
    let elevations = heights(&state, dem, points).await?;
    Ok(Json(Elevations { elevations }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_forms() {
        assert_eq!(parse_epsg("EPSG:32633"), Ok(32633));
        assert_eq!(parse_epsg("epsg:4326"), Ok(4326));
        assert_eq!(parse_epsg(" 26918 "), Ok(26918));
        assert!(parse_epsg("EPSG:").is_err());
        assert!(parse_epsg("+32633").is_err());
        assert!(parse_epsg("0").is_err());
        assert!(parse_epsg("EPSG:abc").is_err());
        assert!(parse_epsg("ÉPSG:1").is_err());
    }

    /// A DEM stored before `crs.proj4` existed is returned with it.
    #[test]
    fn stored_info_gains_proj4() {
        let row = DemMetaRow {
            id: "d1".into(),
            name: None,
            created_at: 0,
            file_name: None,
            crs_override: None,
            info: r#"{"format":"geotiff","width":2,"height":2,
                "crs":{"epsg":27700,"name":"OSGB36 / British National Grid","geographic":false},
                "resolution_m":[1.0,1.0],"resolution":[1.0,1.0],
                "bounds":[0.0,0.0,2.0,2.0],"bounds_wgs84":[-7.5,49.7,-7.5,49.7],
                "min":1.0,"max":2.0,"nodata_value":null,"nodata_fraction":0.0}"#
                .into(),
            size_bytes: 1,
            read_bytes: None,
        };
        let info = stored_info(&row).unwrap();
        assert!(
            info.crs.proj4.starts_with("+proj=tmerc") && info.crs.proj4.contains("+towgs84="),
            "{}",
            info.crs.proj4
        );
    }

    #[test]
    fn base_names() {
        assert_eq!(
            base_name("C:\\dems\\N45E006.hgt").as_deref(),
            Some("N45E006.hgt")
        );
        assert_eq!(
            base_name("../x/N45E006.hgt").as_deref(),
            Some("N45E006.hgt")
        );
        assert_eq!(base_name("dir/"), None);
    }

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
