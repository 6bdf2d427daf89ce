//! What the costmaps resource answers: a job's state and, once done,
//! its result and file URLs, and the OpenAPI schemas of its bodies.

use std::collections::BTreeMap;

use planner_core::costmap::{
    CostmapOptions, CostmapStats, Layer, ResolvedParams, Stage, Vehicle, VehicleSpec,
};
use planner_core::terrain::Crs;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::access::answered_project;
use crate::clock::rfc3339;
use crate::db::CostmapRow;
use crate::error::ApiError;
use crate::jobs::{
    COSTMAP_TIF, CostmapResult, JobStatus, LEGEND_SVG, Live, PREVIEW_PNG, StoredRequest,
    layer_file, parse_stage,
};

/// Body of `POST /api/v1/costmaps`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the body for the OpenAPI schema
pub struct CreateCostmap {
    /// A label for the costmap.
    #[schema(max_length = 200)]
    name: Option<String>,
    /// The project to store the costmap in (the caller must be an editor
    /// there); the caller's personal project by default.
    project_id: Option<String>,
    /// The id of an uploaded DEM (`POST /api/v1/dems`) the caller can see.
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
    pub(super) this: String,
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
    /// The project it belongs to.
    project_id: String,
    /// The DEM it is built from.
    dem_id: String,
    /// Creation time, RFC 3339 (UTC).
    created_at: String,
    /// Last change of status, stage or progress (written about every
    /// second while the job runs), RFC 3339 (UTC).
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
    pub(super) urls: CostmapUrls,
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
    pub(super) status: JobStatus,
    /// [0, 1].
    pub(super) progress: f64,
    pub(super) stage: Option<Stage>,
    /// Why the job failed (event `failed`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) error: Option<String>,
}

pub fn costmap_url(id: &str) -> String {
    format!("/api/v1/costmaps/{id}")
}

/// The layers in `Layer::ALL` order, once each.
pub(super) fn ordered_layers(layers: &[Layer]) -> Vec<Layer> {
    Layer::ALL
        .into_iter()
        .filter(|l| layers.contains(l))
        .collect()
}

pub(super) fn internal(id: &str, what: &str, e: impl std::fmt::Display) -> ApiError {
    ApiError::Internal(format!("stored {what} of costmap {id} unreadable: {e}"))
}

/// A stored job's state, with this process' live progress over it while
/// the job is unfinished.
pub(super) struct JobState {
    pub(super) status: JobStatus,
    pub(super) progress: f64,
    pub(super) stage: Option<Stage>,
}

pub(super) fn job_state(row: &CostmapRow, live: Option<Live>) -> Result<JobState, ApiError> {
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

pub(super) fn response(row: &CostmapRow, live: Option<Live>) -> Result<CostmapResponse, ApiError> {
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
        project_id: answered_project(&row.project_id),
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

crate::api::paging::listing!(CostmapList, CostmapResponse);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_order() {
        assert_eq!(
            ordered_layers(&[Layer::Step, Layer::Slope, Layer::Step]),
            [Layer::Slope, Layer::Step]
        );
    }
}
