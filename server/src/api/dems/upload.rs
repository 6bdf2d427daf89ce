//! `POST /api/v1/dems`: upload an elevation raster (GeoTIFF, ESRI ASCII
//! grid or SRTM `.hgt`).
//!
//! A GeoTIFF is read from its spool file a band of rows at a time and
//! stored as tiles with overviews (`state::dem_store::tiles`), never held
//! whole; an ESRI ASCII grid or `.hgt` tile is read whole and stored both
//! as its file and as tiles. The CRS the uploader gave, if any, is kept;
//! parsed rasters are kept in the state's small cache
//! ([`crate::state::DemLoader`]).
//!
//! An upload is written to a spool file in the data directory as it
//! arrives (a slow or large upload holds no more than a buffer of
//! memory), its header is read for the raster's declared size, and only
//! then, with room in the memory budget for what its reading holds (a
//! band of tiles for a GeoTIFF, the whole raster otherwise), is it read;
//! a raster whose reading alone needs more than the budget (a small
//! compressed file declaring huge pixel counts) is refused before
//! anything of that size is allocated.

use std::io::Write;
use std::path::{Path as FsPath, PathBuf};
use std::sync::Arc;

use axum::Json;
use axum::extract::multipart::MultipartError;
use axum::extract::{FromRequest, Multipart, Query, Request, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use planner_core::geo::Issue;
use planner_core::terrain::{
    DemFormat, DemInfo, GeoTiffWindows, RasterWindows, TerrainError, read_dem,
};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};

use super::header::{self as dem_header, Declared};
use super::model::{BinaryFile, DemResponse, parse_epsg, response};
use crate::api::json_body::{declared_length, media_type};
use crate::api::names::{NAME_MAX_CHARS, control_character_issue};
use crate::auth::{Caller, new_resource_project};
use crate::clock::now_millis;
use crate::db::{CHUNK_BYTES, DemMetaRow};
use crate::error::{ApiError, Problem};
use crate::memory::{Reservation, dem_read_bytes, mib};
use crate::state::dem_store::tiles;
use crate::state::dem_store::uploads::{self, UploadLease};
use crate::state::{AppState, Work};

/// What the upload limits' messages call a DEM upload.
const DEM_FILE: &str = "DEM file";

const FILE_NAME_MAX_CHARS: usize = 255;

/// Media types taken as the raw DEM file.
const RAW_TYPES: [&str; 3] = ["image/tiff", "application/octet-stream", "text/plain"];

/// 413 for an upload over `limit` bytes; `what` names it ("DEM file").
pub(crate) fn too_large(what: &str, limit: usize) -> ApiError {
    ApiError::PayloadTooLarge(format!(
        "the {what} is too large: the limit is {limit} bytes ({} MiB, --max-dem-mb)",
        limit / (1024 * 1024)
    ))
}

/// A multipart body's fault: 413 past `limit` (see [`too_large`]), else 400.
pub(crate) fn multipart_error(e: MultipartError, what: &str, limit: usize) -> ApiError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        too_large(what, limit)
    } else {
        ApiError::BadRequest(format!("malformed multipart body: {}", e.body_text()))
    }
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
            return Err(too_large(DEM_FILE, self.limit));
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
        .map_err(|e| multipart_error(e, DEM_FILE, limit))?
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
                while let Some(bytes) = field
                    .chunk()
                    .await
                    .map_err(|e| multipart_error(e, DEM_FILE, limit))?
                {
                    writer.push(&bytes).await?;
                }
                upload.file = Some(writer.finish().await?);
            }
            "name" | "crs" => {
                let text = field
                    .text()
                    .await
                    .map_err(|e| multipart_error(e, DEM_FILE, limit))?;
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
        (status = 413, description = "File over the size limit, raster over the pixel limit, a raster whose declared size needs more than the memory budget to read, or a file or its tiles that would take the project past its storage quota (--project-quota-mb; the tiles are checked as they are stored, and nothing of the upload is kept)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Unsupported Content-Type", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Not a readable DEM, its CRS is unknown (give `crs`), or no project `project_id` the caller may add to", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner is busy, or the upload's lease ran out while the database was unreachable (what it stored was swept); retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn upload_dem(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<UploadQuery>, QueryRejection>,
    req: Request,
) -> Result<Response, ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let limit = state.dems.max_upload_bytes;
    let (content_type, essence) = media_type(req.headers());
    let multipart = essence == "multipart/form-data";
    if !multipart && !RAW_TYPES.contains(&essence.as_str()) {
        let accepted = "send the file as image/tiff, application/octet-stream or text/plain, \
                        or as the part \"file\" of multipart/form-data";
        return Err(ApiError::UnsupportedMediaType(if content_type.is_empty() {
            format!("the request has no Content-Type: {accepted}")
        } else {
            format!("Content-Type {content_type:?} is not supported: {accepted}")
        }));
    }
    // Before the body is read: nothing is taken in for a project the
    // caller may not add to.
    let project_id =
        new_resource_project(&state.db, &caller, q.project_id.as_deref(), "/project_id").await?;
    // A declared size over the project's quota is refused before any of
    // the body is read; the size received is checked again below.
    if let Some(declared) = declared_length(req.headers()) {
        let usage = state.quotas.usage(&state.db, &project_id).await?;
        usage.check_bytes(&project_id, declared, "the upload")?;
    }
    let upload = if multipart {
        read_multipart(req, &state, limit).await?
    } else {
        Upload {
            file: Some(spool_body(req, &state.dems.spool_dir, limit).await?),
            file_name: None,
            name: None,
            crs: None,
        }
    };
    let (labels, spool) = labels(q, upload)?;

    let usage = state.quotas.usage(&state.db, &project_id).await?;
    usage.check_bytes(&project_id, spool.len, "the DEM file")?;
    let id = uuid::Uuid::now_v7().to_string();
    let (row, info) = if spool_is_tiff(&spool).await? {
        store_geotiff(&state, spool, labels, &id, project_id).await?
    } else {
        store_whole(&state, spool, labels, &id, project_id).await?
    };
    let body = response(&row, info);
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&body.url) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::CREATED, headers, Json(body)).into_response())
}

/// Whether the spooled file starts as a TIFF does.
async fn spool_is_tiff(spool: &Spool) -> Result<bool, ApiError> {
    use tokio::io::AsyncReadExt;
    let mut f = tokio::fs::File::open(&spool.path)
        .await
        .map_err(spool_error)?;
    let mut head = [0u8; 4];
    let mut got = 0;
    while got < 4 {
        match f.read(&mut head[got..]).await.map_err(spool_error)? {
            0 => break,
            n => got += n,
        }
    }
    Ok(matches!(
        &head[..got],
        b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+"
    ))
}

/// A GeoTIFF upload, read a window at a time from its spool file and
/// stored as tiles: neither the file nor the raster is held in memory
/// (the memory held is a band of 512 rows, see `tiles::cut_bytes`).
async fn store_geotiff(
    state: &AppState,
    spool: Spool,
    labels: Labels,
    id: &str,
    project_id: String,
) -> Result<(DemMetaRow, DemInfo), ApiError> {
    // The declared size first: a chunk too large to decode within the
    // memory budget is refused before the file is opened as a raster.
    let (at, len) = (spool.path.clone(), spool.len);
    let declared = tokio::task::spawn_blocking(move || {
        let mut f = std::fs::File::open(at).ok()?;
        dem_header::declared(&mut f, len, None)
    })
    .await
    .map_err(spool_error)?;
    if let Some(d) = &declared {
        check_pixels(state, d)?;
        let need = tiles::cut_bytes(d.width).saturating_add(d.chunk_bytes.saturating_mul(3));
        check_budget(state, Some(d), len, need)?;
    }
    let limits = state.dems.limits.clone();
    let (path, crs) = (spool.path.clone(), labels.crs);
    let windows = state
        .run_planner(Work::Dem, move |_| {
            let file = std::fs::File::open(&path)
                .map_err(|e| TerrainError::Invalid(format!("cannot read the upload: {e}")))?;
            GeoTiffWindows::open(file, crs, &limits)
        })
        .await??;
    let (width, height) = (windows.grid().width, windows.grid().height);
    let chunk = declared.as_ref().map_or(0, |d| d.chunk_bytes);
    let need = tiles::cut_bytes(width as u64).saturating_add(chunk.saturating_mul(3));
    let _room = state
        .memory
        .reserve(need, "cutting the uploaded DEM into tiles")
        .await?;
    let exact = windows.exact_in_f32();
    // Its geometry now (a CRS that PROJ cannot transform is refused before
    // any tile is stored); its statistics from the cutting.
    let grid = windows.grid().clone();
    tiles::windows_info(&grid, DemFormat::GeoTiff, &tiles::CellStats::default())?;
    let lease = begin_upload(state, id, &project_id).await?;
    let stored = async {
        let stored =
            tiles::store_tiles(&state.db, &state.planner, &lease, windows, Some(exact)).await?;
        let info = tiles::windows_info(&grid, DemFormat::GeoTiff, &stored.stats)?;
        let pixels = (width as u64).saturating_mul(height as u64);
        let row = DemMetaRow {
            id: id.to_string(),
            name: labels.name,
            created_at: now_millis(),
            file_name: labels.file_name,
            crs_override: crs.map(i64::from),
            info: serde_json::to_string(&info).map_err(|e| ApiError::Internal(e.to_string()))?,
            size_bytes: spool.len as i64,
            // Read whole again from its tiles: the heights and a tile or two.
            read_bytes: i64::try_from(dem_read_bytes(pixels, 4 << 20, 0)).ok(),
            project_id: Some(project_id),
        };
        drop(spool);
        insert_dem(state, &row, &stored.row, &[]).await?;
        Ok::<_, ApiError>((row, info))
    }
    .await;
    settle(lease, stored).await
}

/// Record upload `id` of project `project_id` as held by this process
/// (see `state::dem_store::uploads`).
async fn begin_upload(
    state: &AppState,
    id: &str,
    project_id: &str,
) -> Result<UploadLease, ApiError> {
    let jobs = &state.costmaps;
    UploadLease::begin(
        &state.db,
        id,
        project_id,
        jobs.instance(),
        jobs.lease_ms(),
        state.quotas,
    )
    .await
}

/// Store the DEM of an upload whose tiles are stored; a 503 when the
/// upload was swept meanwhile (see [`uploads::swept_error`]).
async fn insert_dem(
    state: &AppState,
    row: &DemMetaRow,
    set: &crate::db::DemTileSetRow,
    data: &[u8],
) -> Result<(), ApiError> {
    match state.db.insert_dem_tiled(row, set, data).await {
        Err(sqlx::Error::RowNotFound) => Err(uploads::swept_error()),
        other => Ok(other?),
    }
}

/// The upload's end: finished when its DEM was stored, else abandoned,
/// its tiles removed before the answer is sent.
async fn settle<T>(lease: UploadLease, result: Result<T, ApiError>) -> Result<T, ApiError> {
    match result {
        Ok(v) => {
            lease.finished();
            Ok(v)
        }
        Err(e) => {
            lease.abandon().await;
            Err(e)
        }
    }
}

/// Any other upload (an ESRI ASCII grid, an SRTM `.hgt` tile): read whole
/// as before (with room for it in the memory budget), stored as its file
/// and as tiles, and kept in the DEM cache.
async fn store_whole(
    state: &AppState,
    spool: Spool,
    labels: Labels,
    id: &str,
    project_id: String,
) -> Result<(DemMetaRow, DemInfo), ApiError> {
    // The room for reading the raster is held until it is stored.
    let (data, need, _room) = read_spool(state, spool, labels.file_name.clone()).await?;
    let limits = state.dems.limits.clone();
    let (parse_name, parse_data, crs) = (labels.file_name.clone(), data.clone(), labels.crs);
    let (dem, info) = state
        .run_planner(Work::Dem, move |_| {
            let dem = read_dem(&parse_data, parse_name.as_deref(), crs, &limits)?;
            let info = dem.info()?;
            Ok::<_, TerrainError>((dem, info))
        })
        .await??;
    let dem = Arc::new(dem);
    let lease = begin_upload(state, id, &project_id).await?;
    let stored = async {
        let stored = tiles::store_tiles(
            &state.db,
            &state.planner,
            &lease,
            tiles::SharedDem::new(dem.clone()),
            None,
        )
        .await?;
        // The file is kept too: it counts with the tiles.
        lease.check_file_quota(data.len() as u64).await?;
        let row = DemMetaRow {
            id: id.to_string(),
            name: labels.name,
            created_at: now_millis(),
            file_name: labels.file_name,
            crs_override: crs.map(i64::from),
            info: serde_json::to_string(&info).map_err(|e| ApiError::Internal(e.to_string()))?,
            size_bytes: data.len() as i64,
            read_bytes: i64::try_from(need).ok(),
            project_id: Some(project_id),
        };
        insert_dem(state, &row, &stored.row, &data).await?;
        Ok::<_, ApiError>(row)
    }
    .await;
    let row = settle(lease, stored).await?;
    state.dems.cache.insert(&row.id, dem, None);
    Ok((row, info))
}

/// What the uploader says of the file: its label, its file name and its CRS.
struct Labels {
    name: Option<String>,
    file_name: Option<String>,
    crs: Option<u32>,
}

/// The labels of an upload, from the query (first) and the form, checked,
/// and the spooled file: 400 or 422 naming what is wrong.
fn labels(q: UploadQuery, upload: Upload) -> Result<(Labels, Spool), ApiError> {
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
            .and_then(|n| control_character_issue("/name", "the name", n)),
        file_name
            .as_deref()
            .and_then(|f| control_character_issue("/file_name", "the file name", f)),
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
    let labels = Labels {
        name,
        file_name,
        crs,
    };
    Ok((labels, spool))
}

/// The spooled file's bytes, the memory reading them as a raster needs,
/// and that room in the memory budget: a raster over the pixel limits or
/// the budget is refused from its header first.
async fn read_spool(
    state: &AppState,
    spool: Spool,
    file_name: Option<String>,
) -> Result<(Arc<Vec<u8>>, u64, Reservation), ApiError> {
    // The raster's declared size, from its header, before it is read.
    let (at, len) = (spool.path.clone(), spool.len);
    let declared = tokio::task::spawn_blocking(move || {
        let mut f = std::fs::File::open(at).ok()?;
        dem_header::declared(&mut f, len, file_name.as_deref())
    })
    .await
    .map_err(spool_error)?;
    let need = read_bytes(state, declared.as_ref(), len)?;
    let room = state
        .memory
        .reserve(need, "reading the uploaded DEM")
        .await?;
    let path = spool.path.clone();
    let data = tokio::fs::read(&path).await.map_err(spool_error)?;
    let data = Arc::new(data);
    drop(spool);
    Ok((data, need, room))
}

/// The memory reading a raster of `len` bytes declaring `declared` needs;
/// 413 over the pixel limits or the memory budget.
fn read_bytes(state: &AppState, declared: Option<&Declared>, len: u64) -> Result<u64, ApiError> {
    let need = match declared {
        Some(d) => {
            check_pixels(state, d)?;
            dem_read_bytes(d.pixels(), d.chunk_bytes, len)
        }
        // Not a raster whose header says its size: the full read refuses
        // it without allocating much.
        None => dem_read_bytes(0, 0, len),
    };
    check_budget(state, declared, len, need)?;
    Ok(need)
}

/// 413 for a raster over the pixel limits (the refusal the full read
/// gives, before it).
fn check_pixels(state: &AppState, d: &Declared) -> Result<(), ApiError> {
    let limits = &state.dems.limits;
    let over_side = d.width.max(d.height) > u64::from(limits.max_side);
    if over_side || d.pixels() > limits.max_pixels {
        return Err(TerrainError::TooLarge {
            width: d.width,
            height: d.height,
            limit: if over_side {
                format!("{} pixels per side", limits.max_side)
            } else {
                format!("{} pixels (--max-dem-pixels)", limits.max_pixels)
            },
        }
        .into());
    }
    Ok(())
}

/// 413 when reading a raster of `len` bytes declaring `declared` needs
/// `need` bytes, more than the whole memory budget.
fn check_budget(
    state: &AppState,
    declared: Option<&Declared>,
    len: u64,
    need: u64,
) -> Result<(), ApiError> {
    let budget = state.memory.total();
    if need > budget {
        let what = match declared {
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
    Ok(())
}

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
    /// The project to store the DEM in (the caller must be an editor
    /// there); the caller's personal project by default.
    project_id: Option<String>,
}

/// The last component of a client's file name (browsers may send a path).
fn base_name(name: &str) -> Option<String> {
    let base = name.rsplit(['/', '\\']).next().unwrap_or(name).trim();
    (!base.is_empty()).then(|| base.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// Property test of the reader an upload opens a GeoTIFF with
    /// (`GeoTiffWindows`, read a band at a time as the tiles are cut): a
    /// few hundred mutations of a GeoTIFF in strips (bits flipped, bytes
    /// set to 0xFF, cut short) open and read to an error or to cells,
    /// never a panic, and the reading's peak memory stays bounded by what
    /// the upload reserves (a band of tiles and its chunks), not by the
    /// sizes the bytes claim.
    #[test]
    fn mutated_geotiffs_read_to_an_error_or_cells_within_bounded_memory() {
        use planner_core::terrain::geotiff::{Band, BandData, Page, write_geotiff};
        use planner_core::terrain::{Crs, DemLimits, GeoTransform};

        let (w, h) = (700usize, 300usize);
        let values: Vec<f32> = (0..w * h).map(|i| (i % 977) as f32 * 0.25).collect();
        let bands = [Band {
            description: "",
            unit: "",
            metadata: &[],
            data: BandData::F32(&values),
        }];
        let pages = [Page {
            bands: &bands,
            nodata: Some(-9999.0),
        }];
        let crs = Crs {
            epsg: 32633,
            name: "WGS 84 / UTM zone 33N".into(),
            geographic: false,
            proj4: String::new(),
        };
        let transform = GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 2.0,
            row_rotation: 0.0,
            origin_y: 4_000_000.0,
            col_rotation: 0.0,
            pixel_height: -2.0,
        };
        let mut seed = std::io::Cursor::new(Vec::new());
        write_geotiff(&mut seed, w, h, &transform, &crs, &pages).unwrap();
        let seed = seed.into_inner();
        let limits = DemLimits::default();
        let mut state = 0x5EED_0003u64;
        let mut next = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            state.wrapping_mul(0x2545_F491_4F6C_DD1D)
        };
        let _ = std::fs::write("/proc/self/clear_refs", "5");
        let peak = || {
            std::fs::read_to_string("/proc/self/status")
                .unwrap_or_default()
                .lines()
                .find_map(|l| l.strip_prefix("VmHWM:"))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
                .unwrap_or(0)
                * 1024
        };
        let before = peak();
        let (mut read, mut refused) = (0, 0);
        for case in 0..300 {
            let mut bytes = seed.clone();
            let n = bytes.len() as u64;
            match case % 3 {
                0 => {
                    for _ in 0..1 + next() % 8 {
                        // Mostly the header and IFD (the first 512 bytes).
                        let span = if next() % 4 == 0 { n } else { n.min(512) };
                        let i = (next() % span) as usize;
                        bytes[i] ^= 1 << (next() % 8);
                    }
                }
                1 => {
                    let i = (next() % n.min(512)) as usize;
                    for b in bytes.iter_mut().skip(i).take(1 + (next() % 8) as usize) {
                        *b = 0xFF;
                    }
                }
                _ => bytes.truncate((next() % n) as usize),
            }
            let opened = GeoTiffWindows::open(bytes, Some(32633), &limits);
            let Ok(windows) = opened else {
                refused += 1;
                continue;
            };
            match tiles::cell_stats(&windows) {
                Ok(stats) => {
                    let g = windows.grid();
                    assert_eq!(stats.cells, (g.width * g.height) as u64, "case {case}");
                    read += 1;
                }
                Err(_) => refused += 1,
            }
        }
        assert!(read > 10 && refused > 10, "{read} read, {refused} refused");
        // The reader decodes one strip or tile at a time and the cutting
        // holds a band of 512 rows (of this seed: 11 MiB measured).
        let grown = peak().saturating_sub(before);
        eprintln!(
            "{read} read, {refused} refused; peak grew by {} MiB",
            grown >> 20
        );
        assert!(grown < 256 << 20, "reading grew the peak by {grown} bytes");
    }
}
