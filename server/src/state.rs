//! The state every handler shares: the database, the request limits, the
//! planner slots, the stored DEMs, the costmap jobs, the route searches,
//! the web page and the memory budget.

pub mod dem_store;
pub mod planners;
pub mod route_store;

use std::sync::Arc;

use planner_core::cancel::CancelToken;
use planner_core::geo::Limits;
use planner_core::terrain::Dem;

pub use self::dem_store::{DemLoader, DemStore};
pub use self::planners::{Planners, Work, off_runtime};
pub use self::route_store::RouteStore;
use crate::config::ServeConfig;
use crate::db::Db;
use crate::error::ApiError;
use crate::jobs::CostmapJobs;
use crate::memory::{MemoryBudget, Reservation};
use crate::quota::Quotas;
use crate::rate_limit::RateLimits;
use crate::web_ui::WebUi;

#[derive(Clone)]
pub struct AppState {
    pub db: Db,
    pub limits: Limits,
    /// Bounds the plans computed at once, so a burst of heavy requests
    /// queues instead of exhausting the blocking pool and memory.
    pub planner: Arc<Planners>,
    /// DEM limits and the cache of parsed DEMs.
    pub dems: Arc<DemStore>,
    /// The costmap jobs this process holds, and their live progress.
    pub costmaps: Arc<CostmapJobs>,
    /// The route searches kept for replanning.
    pub routes: Arc<RouteStore>,
    /// The browser front end, served outside `/api`.
    pub web: Arc<WebUi>,
    /// Memory for heavy work (`--memory-budget-mb`): DEM reads,
    /// hillshades, costmap builds and route searches reserve their
    /// estimated peak here first, and wait while it is taken.
    pub memory: Arc<MemoryBudget>,
    /// Sign-in and planning rate limits.
    pub rates: Arc<RateLimits>,
    /// Storage and queued-job quotas of every project.
    pub quotas: Quotas,
    /// `--cookie-secure`: the session cookie is always `Secure`.
    pub cookie_secure: bool,
    /// `--vehicle-links`: the vehicles uploads may reach, and those in use.
    pub vehicle_links: Arc<crate::vehicle_link::VehicleLinks>,
}

impl AppState {
    /// The state of a server on `db` configured by `config`.
    pub fn from_config(config: &ServeConfig, db: Db) -> AppState {
        let planner = Arc::new(Planners::from_config(config));
        let dems = Arc::new(DemStore::from_config(config));
        let memory = Arc::new(MemoryBudget::new(config.memory_budget_mb));
        let loader = DemLoader {
            db: db.clone(),
            store: dems.clone(),
            memory: memory.clone(),
            planner: planner.clone(),
        };
        let jobs = usize::try_from(config.costmap_jobs).unwrap_or(usize::MAX);
        AppState {
            db,
            limits: config.limits(),
            planner,
            dems,
            costmaps: Arc::new(CostmapJobs::new(
                jobs,
                loader,
                config.job_lease(),
                config.tile_settings(),
            )),
            routes: Arc::new(RouteStore::from_config(config)),
            web: Arc::new(WebUi::new(&config.web_dir)),
            memory,
            quotas: Quotas::new(config.project_quota_mb, config.project_queued_jobs),
            rates: Arc::new(RateLimits::new(
                config.sign_in_per_minute,
                config.planning_per_minute,
            )),
            cookie_secure: config.cookie_secure,
            vehicle_links: Arc::new(crate::vehicle_link::VehicleLinks::new(
                config.vehicle_links.clone(),
            )),
        }
    }

    /// Reads stored DEMs for this state's handlers.
    pub fn dem_loader(&self) -> DemLoader {
        DemLoader {
            db: self.db.clone(),
            store: self.dems.clone(),
            memory: self.memory.clone(),
            planner: self.planner.clone(),
        }
    }

    /// See [`Planners::run`].
    pub async fn run_planner<T: Send + 'static>(
        &self,
        work: Work,
        job: impl FnOnce(&CancelToken) -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        self.planner.run(work, job).await
    }

    /// See [`DemLoader::load`].
    pub async fn load_dem(&self, id: &str) -> Result<Arc<Dem>, ApiError> {
        self.dem_loader().load(id).await
    }

    /// See [`DemLoader::load_for`].
    pub async fn load_dem_for(
        &self,
        id: &str,
        what: &str,
        work: impl FnOnce(u64, u64) -> u64,
    ) -> Result<(Arc<Dem>, Reservation), ApiError> {
        self.dem_loader().load_for(id, what, work).await
    }
}
