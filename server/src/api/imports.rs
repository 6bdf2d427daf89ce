//! `POST /api/v1/imports`: a GIS file (zipped Shapefile, GeoPackage, KML, KMZ, GPX,
//! GeoJSON in any named CRS) read into WGS84 GeoJSON for an ROI, no-fly
//! zones or corridor lines, with a message per feature skipped. Nothing is
//! stored.

use axum::Json;
use axum::extract::{DefaultBodyLimit, Multipart, State};
use axum::http::StatusCode;
use planner_core::geo::Issue;

use super::dems::{multipart_error, too_large};
use planner_core::import::{ImportError, import_bytes};
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::router::{OpenApiRouter, UtoipaMethodRouterExt};
use utoipa_axum::routes;

use crate::auth::Caller;
use crate::error::{ApiError, Problem};
use crate::state::{AppState, Work};

/// The import endpoint; its body limit is the DEM uploads' (`--max-dem-mb`).
pub fn routes(max_upload_bytes: usize) -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(import_file).layer(DefaultBodyLimit::max(max_upload_bytes)))
}

/// `multipart/form-data` upload: the file in the part `file`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the form for the OpenAPI schema
pub struct ImportUpload {
    /// The GIS file; the part's filename must end in `.zip` (a zipped
    /// Shapefile: `.shp`, `.dbf`, `.prj`), `.gpkg`, `.kml`, `.kmz`, `.gpx`,
    /// `.geojson` or `.json`, which chooses the reader.
    #[schema(value_type = String, format = Binary, content_media_type = "application/octet-stream")]
    file: Vec<u8>,
}

/// What an import gives.
#[derive(Serialize, ToSchema)]
pub struct ImportResponse {
    /// The polygons and lines read, as a GeoJSON FeatureCollection in
    /// WGS84 lon/lat, with the file's attributes as properties.
    #[schema(value_type = Object)]
    features: serde_json::Value,
    /// One message per feature (or group of features) skipped: points,
    /// empty or degenerate rings, coordinates that do not reproject.
    messages: Vec<String>,
}

fn file_fault(message: &str) -> ApiError {
    ApiError::Validation(vec![Issue::new("/file", message)])
}

/// The part `file` of the form: its filename and bytes, at most `limit`.
async fn read_file_part(mut form: Multipart, limit: usize) -> Result<(String, Vec<u8>), ApiError> {
    let mut found: Option<(String, Vec<u8>)> = None;
    while let Some(mut field) = form
        .next_field()
        .await
        .map_err(|e| multipart_error(e, "file", limit))?
    {
        let name = field.name().unwrap_or("").to_string();
        if name != "file" {
            return Err(ApiError::Validation(vec![Issue::new(
                &format!("/{}", planner_core::geo::escape_pointer_token(&name)),
                &format!("unknown form field {name:?}: expected file"),
            )]));
        }
        if found.is_some() {
            return Err(file_fault(
                "the form has more than one part named \"file\": send one file per request",
            ));
        }
        let Some(file_name) = field.file_name().map(str::to_string) else {
            return Err(file_fault(
                "the part \"file\" has no filename: its extension (.zip, .kml, .kmz, .gpx, \
                 .geojson) chooses the reader",
            ));
        };
        let mut bytes = Vec::new();
        while let Some(chunk) = field
            .chunk()
            .await
            .map_err(|e| multipart_error(e, "file", limit))?
        {
            if bytes.len() + chunk.len() > limit {
                return Err(too_large("file", limit));
            }
            bytes.extend_from_slice(&chunk);
        }
        found = Some((file_name, bytes));
    }
    found.ok_or_else(|| file_fault("the form has no part named \"file\" holding the GIS file"))
}

/// A GeoPackage upload read from a spool file (SQLite reads files), which
/// is removed afterwards.
async fn read_gpkg_upload(
    state: &AppState,
    bytes: Vec<u8>,
) -> Result<Result<planner_core::import::Imported, ImportError>, ApiError> {
    let dir = state.dems.spool_dir.clone();
    let path = dir.join(format!("{}.gpkg", uuid::Uuid::new_v4()));
    let at = path.clone();
    tokio::task::spawn_blocking(move || {
        std::fs::create_dir_all(&dir)?;
        std::fs::write(&at, bytes)
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?
    .map_err(|e| ApiError::Internal(format!("cannot spool the upload: {e}")))?;
    let result = crate::imports::gpkg::read_gpkg(&path).await;
    let _ = tokio::fs::remove_file(&path).await;
    Ok(result)
}

/// Import a GIS file: its polygons and lines in WGS84 GeoJSON, to use as a
/// survey's `roi`, `no_fly_zones` or `corridor`. Formats (by the part's
/// filename): a zipped ESRI Shapefile (`.shp`, `.dbf`, `.prj` in any CRS),
/// GeoPackage (`.gpkg`: every feature table), KML, KMZ, GPX (tracks and routes as lines) and GeoJSON whose legacy
/// `crs` member names another CRS; all reprojected with PROJ. Points and
/// unusable features are skipped and listed in `messages`.
#[utoipa::path(
    post,
    path = "/api/v1/imports",
    tag = "imports",
    request_body(
        description = "The file as the form part `file`",
        content((ImportUpload = "multipart/form-data"))
    ),
    responses(
        (status = 200, description = "The features read and the messages about those skipped", body = ImportResponse),
        (status = 400, description = "Malformed multipart body", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "File over the size limit (--max-dem-mb)", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Not multipart/form-data", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "No part `file`, an unsupported file type, a malformed file (truncated zip, bad XML, …), a Shapefile without its .prj or a CRS PROJ does not know; `errors[0].pointer` is `/file`", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "The planner is busy; retry", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn import_file(
    State(state): State<AppState>,
    _caller: Caller,
    form: Result<Multipart, axum::extract::multipart::MultipartRejection>,
) -> Result<Json<ImportResponse>, ApiError> {
    let form = form.map_err(|e| {
        if e.status() == StatusCode::UNSUPPORTED_MEDIA_TYPE {
            ApiError::UnsupportedMediaType(
                "send the file as the part \"file\" of multipart/form-data".into(),
            )
        } else {
            ApiError::BadRequest(format!("malformed multipart body: {}", e.body_text()))
        }
    })?;
    let limit = state.dems.max_upload_bytes;
    let (file_name, bytes) = read_file_part(form, limit).await?;
    let imported = if crate::imports::is_gpkg(&file_name) {
        read_gpkg_upload(&state, bytes).await?
    } else {
        state
            .run_planner(Work::Dem, move |_| import_bytes(&file_name, &bytes))
            .await?
    }
    .map_err(|e: ImportError| file_fault(&e.to_string()))?;
    let reply = crate::imports::reply(&imported);
    Ok(Json(ImportResponse {
        features: reply["features"].clone(),
        messages: imported.messages,
    }))
}
