//! What every job of one tiled costmap needs, built once per process and
//! kept while its jobs run here: the stage plan (rebuilt from the stored
//! request and the costmap's tile side, the same on every process), the
//! DEM read a window at a time and the land-cover raster.

use std::sync::Arc;

use planner_core::costmap::{CostmapError, TilePlan, Vehicle};
use planner_core::terrain::{Dem, RasterWindows};

use super::super::build::{dem_load_error, invalid_request};
use super::super::record::{PREVIEW_MAX_SIDE, StoredRequest};
use crate::db::Db;
use crate::error::ApiError;
use crate::state::dem_store::DemLoader;
use crate::state::dem_store::tiles::{SharedDem, StoredTiles, stored_set};

/// A DEM read a window at a time, shared by the jobs of its costmaps.
pub type DemSource = Arc<dyn RasterWindows + Send + Sync>;

/// One tiled costmap's plan and inputs.
pub struct CostmapContext {
    pub plan: TilePlan,
    pub dem: DemSource,
    pub landcover: Option<Arc<Dem>>,
}

/// Why a costmap's context cannot be had.
#[derive(Debug)]
pub enum ContextError {
    /// The costmap is no longer being built (deleted, failed, done).
    Gone,
    /// It can never be built (its DEM was deleted, its request is
    /// invalid): the costmap fails with this.
    Fatal(String),
    /// A fault that may pass (storage): the job is tried again.
    Fault(String),
}

/// Stored DEM `id` read a window at a time: from its tiles when it has
/// them, else read whole (a DEM stored before tiles, or not tiled).
pub async fn dem_source(dems: &DemLoader, id: &str) -> Result<DemSource, ApiError> {
    let meta = dems
        .db
        .get_dem_meta(id)
        .await?
        .ok_or_else(|| ApiError::NotFound(format!("no DEM {id:?}")))?;
    let info = crate::api::dems::stored_dem_info(&meta)?;
    if let Some((set, grid)) = stored_set(&dems.db, id, &info).await? {
        return Ok(Arc::new(StoredTiles::new(
            dems.db.clone(),
            tokio::runtime::Handle::current(),
            id,
            set,
            0,
            &grid,
        )));
    }
    Ok(Arc::new(SharedDem::new(dems.load(id).await?)))
}

/// The plan of costmap `id`'s tiles, whose side `tile` is stored with it.
pub async fn load(dems: &DemLoader, id: &str) -> Result<CostmapContext, ContextError> {
    let db: &Db = &dems.db;
    let fault = |e: sqlx::Error| ContextError::Fault(format!("the costmap cannot be read: {e}"));
    let Some(tile) = db.costmap_tile_side(id).await.map_err(fault)? else {
        return Err(ContextError::Gone);
    };
    let Some(row) = db.get_costmap(id).await.map_err(fault)? else {
        return Err(ContextError::Gone);
    };
    let request: StoredRequest = serde_json::from_str(&row.request)
        .map_err(|e| ContextError::Fatal(format!("the stored request is unreadable: {e}")))?;
    let vehicle: Vehicle = serde_json::from_str(&row.vehicle)
        .map_err(|e| ContextError::Fatal(format!("the stored vehicle is unreadable: {e}")))?;
    let options = request.options;
    let load_error = |e: ApiError, dem: &str, what: &str| match e {
        ApiError::Internal(_) => ContextError::Fault(dem_load_error(e, dem, what)),
        e => ContextError::Fatal(dem_load_error(e, dem, what)),
    };
    let landcover = match &options.landcover {
        None => None,
        Some(l) => Some(
            dems.load(&l.source)
                .await
                .map_err(|e| load_error(e, &l.source, "land-cover raster"))?,
        ),
    };
    let dem = dem_source(dems, &row.dem_id)
        .await
        .map_err(|e| load_error(e, &row.dem_id, "DEM"))?;
    let plan = TilePlan::new(
        dem.grid(),
        &vehicle,
        &options,
        landcover.as_deref(),
        usize::try_from(tile).unwrap_or(usize::MAX),
    )
    .map_err(|e| match e {
        CostmapError::Invalid(issues) => ContextError::Fatal(invalid_request(&issues)),
        CostmapError::Cancelled => ContextError::Gone,
    })?
    .with_preview_max_side(PREVIEW_MAX_SIDE);
    Ok(CostmapContext {
        plan,
        dem,
        landcover,
    })
}
