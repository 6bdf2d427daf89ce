//! One run of a costmap job: load its DEMs, build the costmap on a
//! blocking thread while its stage is recorded, and encode its files.

use std::io::Cursor;
use std::sync::Arc;

use planner_core::costmap::{
    Costmap, CostmapError, CostmapOptions, Stage, TilePlan, Vehicle, build_costmap, legend_svg,
    preview_png,
};
use planner_core::terrain::Dem;

use super::feed::{Feed, JobNote};
use super::live::{JobHandle, Live};
use super::record::{
    COSTMAP_TIF, CostmapResult, JobStatus, LEGEND_SVG, PREVIEW_MAX_SIDE, PREVIEW_PNG,
    StoredRequest, layer_file, stage_name,
};
use super::tiles::TileSettings;
use super::tiles::context::dem_source;
use crate::clock::now_millis;
use crate::db::{CostmapFileRow, CostmapRow, Db};
use crate::error::ApiError;
use crate::memory::{Reservation, costmap_build_bytes};
use crate::state::dem_store::DemLoader;

/// Longest time between two writes of a running job's progress to its
/// row (a new stage is written at once): what `GET` on another server
/// and an event stream without notes show.
const PROGRESS_WRITE_EVERY: std::time::Duration = std::time::Duration::from_secs(1);
/// Longest time between two progress notes to the other processes (a
/// new stage is noted at once).
const PROGRESS_NOTE_EVERY: std::time::Duration = std::time::Duration::from_millis(200);

/// How a run ended.
pub(super) enum Outcome {
    Built(Box<Built>),
    /// Planned as this many tiles, built by the tile jobs
    /// ([`super::tiles`]).
    Tiled(usize),
    /// Cancelled: deleted, taken over, or shutdown.
    Cancelled,
    Failed(String),
}

/// A finished costmap, encoded for storage.
pub(super) struct Built {
    pub(super) result: String,
    pub(super) files: Vec<CostmapFileRow>,
    /// The build's room in the memory budget, held until the files are
    /// stored.
    room: Option<Reservation>,
}

/// What a run needs of its runner.
pub(super) struct Run<'a, S> {
    pub(super) dems: &'a DemLoader,
    /// Where its progress is noted for the other processes.
    pub(super) feed: &'a Arc<Feed>,
    /// This process' name as a job holder.
    pub(super) owner: &'a str,
    /// Resolves when the server begins to shut down.
    pub(super) shutdown: S,
    /// When a costmap is built as tiles instead.
    pub(super) tiles: TileSettings,
}

/// The DEM a job needs, or why the job cannot run.
async fn job_dem(dems: &DemLoader, id: &str, what: &str) -> Result<Arc<Dem>, String> {
    dems.load(id).await.map_err(|e| dem_load_error(e, id, what))
}

/// Why the job cannot run when its DEM (`what`, DEM `id`) cannot be had.
pub(super) fn dem_load_error(e: ApiError, id: &str, what: &str) -> String {
    match e {
        ApiError::NotFound(_) => format!(
            "the {what} (DEM {id:?}) was deleted before the costmap was built: upload it again \
             and ask for a new costmap"
        ),
        ApiError::Internal(m) => format!("the {what} (DEM {id:?}) cannot be read: {m}"),
        // Over the memory budget.
        ApiError::Validation(issues) => format!(
            "the costmap cannot be built on this server: {}",
            issues
                .iter()
                .map(|i| i.message.clone())
                .collect::<Vec<_>>()
                .join("; ")
        ),
        other => format!("the {what} (DEM {id:?}) cannot be loaded: {other}"),
    }
}

/// Build job `row`'s costmap.
pub(super) async fn build<S: Future<Output = ()>>(
    run: Run<'_, S>,
    row: &CostmapRow,
    handle: &Arc<JobHandle>,
) -> Outcome {
    let request: StoredRequest = match serde_json::from_str(&row.request) {
        Ok(r) => r,
        Err(e) => return Outcome::Failed(format!("the stored request is unreadable: {e}")),
    };
    let vehicle: Vehicle = match serde_json::from_str(&row.vehicle) {
        Ok(v) => v,
        Err(e) => return Outcome::Failed(format!("the stored vehicle is unreadable: {e}")),
    };
    let options = request.options;
    let landcover = match &options.landcover {
        None => None,
        Some(l) => match job_dem(run.dems, &l.source, "land-cover raster").await {
            Ok(d) => Some(d),
            Err(m) => return Outcome::Failed(m),
        },
    };
    if handle.is_cancelled() {
        return Outcome::Cancelled;
    }
    match plan_tiles(&run, row, &vehicle, &options, landcover.as_deref()).await {
        Ok(Some(tiles)) => return Outcome::Tiled(tiles),
        Ok(None) => {}
        Err(outcome) => return outcome,
    }
    // The DEM with room in the memory budget for the build (and for
    // reading the DEM, when it is not cached), held until the files are
    // stored; a job waits for room as long as it takes.
    let layers = options.layers.len() as u64 + u64::from(landcover.is_some());
    let loading = run.dems.load_within(
        &row.dem_id,
        "a costmap build",
        |w, h| costmap_build_bytes(w.saturating_mul(h), layers),
        None,
    );
    let (dem, room) = tokio::select! {
        loaded = loading => match loaded {
            Ok(l) => l,
            Err(e) => return Outcome::Failed(dem_load_error(e, &row.dem_id, "DEM")),
        },
        () = handle.cancelled.notified() => return Outcome::Cancelled,
        () = run.shutdown => return Outcome::Cancelled,
    };
    if handle.is_cancelled() {
        return Outcome::Cancelled;
    }
    let monitor = record_progress(
        run.dems.db.clone(),
        run.feed.clone(),
        &row.id,
        run.owner,
        handle,
    );
    let job = Job {
        dem,
        vehicle,
        options,
        landcover,
    };
    let outcome = match run_build(job, handle).await {
        Outcome::Built(mut built) => {
            built.room = Some(room);
            Outcome::Built(built)
        }
        outcome => outcome,
    };
    monitor.abort();
    outcome
}

/// A costmap of more working cells than `--costmap-tile-cells` is planned
/// as tile jobs (see [`super::tiles`]): the number of tiles; `None` for
/// one built whole here (a request the plan refuses too: the whole build
/// says why).
async fn plan_tiles<S>(
    run: &Run<'_, S>,
    row: &CostmapRow,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<&Dem>,
) -> Result<Option<usize>, Outcome> {
    let src = dem_source(run.dems, &row.dem_id)
        .await
        .map_err(|e| Outcome::Failed(dem_load_error(e, &row.dem_id, "DEM")))?;
    let side = run.tiles.side;
    let Ok(plan) = TilePlan::new(src.grid(), vehicle, options, landcover, side) else {
        return Ok(None);
    };
    let layout = plan.layout();
    let cells = (layout.width as u64).saturating_mul(layout.height as u64);
    if cells <= run.tiles.cells {
        return Ok(None);
    }
    let tiles = plan.tile_count();
    match run
        .dems
        .db
        .plan_costmap_tiles(&row.id, run.owner, side as i64, tiles as i64, now_millis())
        .await
    {
        Ok(true) => Ok(Some(tiles)),
        // Deleted or taken over meanwhile.
        Ok(false) => Err(Outcome::Cancelled),
        Err(e) => Err(Outcome::Failed(format!(
            "the costmap could not be planned as tiles: {e}"
        ))),
    }
}

/// The message of a request the costmap builder refuses.
pub(super) fn invalid_request(issues: &[planner_core::geo::Issue]) -> String {
    format!(
        "the costmap cannot be built with these parameters: {}",
        issues
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join("; ")
    )
}

/// While the build runs: write its progress to the job's row (each new
/// stage, and the progress at most every [`PROGRESS_WRITE_EVERY`]) and
/// note it to the other processes (at most every
/// [`PROGRESS_NOTE_EVERY`]); a job deleted or taken over meanwhile is
/// cancelled.
fn record_progress(
    db: Db,
    feed: Arc<Feed>,
    id: &str,
    owner: &str,
    handle: &Arc<JobHandle>,
) -> tokio::task::JoinHandle<()> {
    use tokio::time::Instant;
    let id = id.to_string();
    let owner = owner.to_string();
    let mut rx = handle.live.subscribe();
    let handle = handle.clone();
    tokio::spawn(async move {
        let mut stored: Option<(Option<Stage>, f64)> = None;
        let mut written_at = Instant::now();
        let mut noted: Option<(Option<Stage>, f64)> = None;
        let mut noted_at = Instant::now();
        while rx.changed().await.is_ok() {
            let live = *rx.borrow_and_update();
            if live.stage.is_none() {
                continue;
            }
            let now = (live.stage, live.progress);
            let new_stage = |last: Option<(Option<Stage>, f64)>| last.is_none_or(|l| l.0 != now.0);
            if new_stage(noted) || (noted != Some(now) && noted_at.elapsed() >= PROGRESS_NOTE_EVERY)
            {
                noted = Some(now);
                noted_at = Instant::now();
                feed.publish(JobNote {
                    id: id.clone(),
                    status: JobStatus::Running,
                    progress: live.progress,
                    stage: live.stage,
                })
                .await;
            }
            if !new_stage(stored)
                && (stored == Some(now) || written_at.elapsed() < PROGRESS_WRITE_EVERY)
            {
                continue;
            }
            stored = Some(now);
            written_at = Instant::now();
            let stage = live.stage.map(stage_name);
            match db
                .set_costmap_progress(&id, &owner, live.progress, stage.as_deref(), now_millis())
                .await
            {
                Ok(true) => {}
                // Deleted, or taken over by another server: stop.
                Ok(false) => handle.cancel(),
                Err(e) => {
                    tracing::warn!(costmap = %id, error = %e, "cannot record a costmap job's progress")
                }
            }
        }
    })
}

/// The inputs of a build.
struct Job {
    dem: Arc<Dem>,
    vehicle: Vehicle,
    options: CostmapOptions,
    landcover: Option<Arc<Dem>>,
}

/// Build and encode the costmap on a blocking thread, reporting progress
/// to `handle` and stopping when it is cancelled.
async fn run_build(job: Job, handle: &Arc<JobHandle>) -> Outcome {
    let reporter = handle.clone();
    let task = tokio::task::spawn_blocking(move || {
        let progress = move |stage: Stage, done: f64| -> bool {
            if reporter.is_cancelled() {
                return false;
            }
            let done = if done.is_finite() {
                done.clamp(0.0, 1.0)
            } else {
                0.0
            };
            reporter.live.send_if_modified(|l: &mut Live| {
                let changed = l.stage != Some(stage) || (done - l.progress).abs() >= 0.005;
                if changed {
                    l.stage = Some(stage);
                    l.progress = done;
                }
                changed
            });
            true
        };
        let Job {
            dem,
            vehicle,
            options,
            landcover,
        } = job;
        let costmap = build_costmap(&dem, &vehicle, &options, landcover.as_deref(), &progress);
        match costmap {
            Ok(c) => encode(&c).map(|b| Outcome::Built(Box::new(b))),
            Err(CostmapError::Cancelled) => Ok(Outcome::Cancelled),
            Err(CostmapError::Invalid(issues)) => Ok(Outcome::Failed(invalid_request(&issues))),
        }
    });
    match task.await {
        Ok(Ok(outcome)) => outcome,
        Ok(Err(e)) => Outcome::Failed(format!("the costmap files could not be written: {e}")),
        Err(e) if e.is_panic() => {
            let payload = e.into_panic();
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".to_string());
            Outcome::Failed(format!(
                "internal error: the costmap builder panicked ({what}); this is a bug, please \
                 report it"
            ))
        }
        Err(_) => Outcome::Cancelled,
    }
}

/// The files and the result document of a finished costmap.
fn encode(costmap: &Costmap) -> std::io::Result<Built> {
    let mut files = Vec::new();
    let mut tif = Cursor::new(Vec::new());
    costmap.write_geotiff(&mut tif)?;
    files.push(CostmapFileRow {
        name: COSTMAP_TIF.to_string(),
        content_type: "image/tiff".to_string(),
        data: tif.into_inner(),
    });
    files.push(CostmapFileRow {
        name: PREVIEW_PNG.to_string(),
        content_type: "image/png".to_string(),
        data: preview_png(costmap, PREVIEW_MAX_SIDE),
    });
    files.push(CostmapFileRow {
        name: LEGEND_SVG.to_string(),
        content_type: "image/svg+xml".to_string(),
        data: legend_svg(costmap).into_bytes(),
    });
    let mut layers = Vec::new();
    for (layer, _) in &costmap.layers {
        let mut tif = Cursor::new(Vec::new());
        if costmap.write_layer_geotiff(*layer, &mut tif)? {
            layers.push(*layer);
            files.push(CostmapFileRow {
                name: layer_file(*layer),
                content_type: "image/tiff".to_string(),
                data: tif.into_inner(),
            });
        }
    }
    let (bounds, bounds_wgs84) = planner_core::terrain::raster_bounds(
        &costmap.transform,
        costmap.width,
        costmap.height,
        &costmap.crs,
    )
    .map_err(std::io::Error::other)?;
    let result = CostmapResult {
        bounds: Some(bounds),
        bounds_wgs84: Some(bounds_wgs84),
        vehicle: costmap.vehicle.clone(),
        params: costmap.params.clone(),
        stats: costmap.stats.clone(),
        warnings: costmap.warnings.clone(),
        width: costmap.width,
        height: costmap.height,
        crs: costmap.crs.clone(),
        layers,
    };
    let result = serde_json::to_string(&result).map_err(std::io::Error::other)?;
    Ok(Built {
        result,
        files,
        room: None,
    })
}
