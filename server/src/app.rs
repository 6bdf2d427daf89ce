//! The application: shared state, the router with its middleware, and the
//! OpenAPI document generated from the handlers.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::extract::Request;
use axum::http::{HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use planner_core::cancel::CancelToken;
use planner_core::geo::Limits;
use planner_core::route::DStarLite;
use planner_core::terrain::{Dem, DemLimits, read_dem};
use tokio::sync::Semaphore;
use tower_http::LatencyUnit;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use utoipa::OpenApi;
use utoipa_axum::router::{OpenApiRouter, UtoipaMethodRouterExt};
use utoipa_axum::routes;
use utoipa_swagger_ui::SwaggerUi;

use crate::api::routes as route_api;
use crate::api::{cameras, costmaps, dems, health, surveys, vehicles};
use crate::config::ServeConfig;
use crate::costmap_jobs::CostmapJobs;
use crate::db::Db;
use crate::error::ApiError;

/// How long a request waits for a free planner before a 503.
const PLANNER_QUEUE_TIMEOUT: Duration = Duration::from_secs(120);

/// The kinds of planning work, each with its own `--planner-threads`
/// slots: a slow survey never holds up a DEM upload, a hillshade or a
/// route search, and the other way round (at most three times
/// `--planner-threads` threads plan at once).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// Survey planning: stopped after `--survey-timeout-s`.
    Survey,
    /// Route searches: stopped after `--route-timeout-s`.
    Route,
    /// Reading DEMs, hillshades and height sampling: bounded by the DEM
    /// size limits.
    Dem,
}

/// The planner slots of each kind of work, and the survey time limit.
pub struct Planners {
    surveys: Arc<Semaphore>,
    routes: Arc<Semaphore>,
    dems: Arc<Semaphore>,
    /// Longest a survey may plan (`--survey-timeout-s`).
    pub survey_timeout: Duration,
}

/// `--survey-timeout-s` by default.
pub const SURVEY_TIMEOUT: Duration = Duration::from_secs(60);

impl Planners {
    /// `threads` slots for each kind of work.
    pub fn new(threads: usize, survey_timeout: Duration) -> Planners {
        let slots = || Arc::new(Semaphore::new(threads.max(1)));
        Planners {
            surveys: slots(),
            routes: slots(),
            dems: slots(),
            survey_timeout,
        }
    }

    pub fn from_config(config: &ServeConfig) -> Planners {
        Planners::new(
            config.planner_threads,
            Duration::from_secs_f64(config.survey_timeout_s),
        )
    }

    fn slots(&self, work: Work) -> &Arc<Semaphore> {
        match work {
            Work::Survey => &self.surveys,
            Work::Route => &self.routes,
            Work::Dem => &self.dems,
        }
    }
}

impl Default for Planners {
    fn default() -> Self {
        Planners::new(1, SURVEY_TIMEOUT)
    }
}

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
    /// Route search limits and the searches kept for replanning.
    pub routes: Arc<RouteStore>,
    /// The browser front end, served outside `/api`.
    pub web: Arc<crate::web_ui::WebUi>,
    /// Memory for heavy work (`--memory-budget-mb`): DEM reads,
    /// hillshades, costmap builds and route searches reserve their
    /// estimated peak here first, and wait while it is taken.
    pub memory: Arc<crate::memory::MemoryBudget>,
}

/// DEM upload limits and the parsed DEMs kept ready for sampling.
pub struct DemStore {
    /// Pixel limits checked from a raster's header at upload.
    pub limits: DemLimits,
    /// Largest DEM file accepted, bytes.
    pub max_upload_bytes: usize,
    pub cache: DemCache,
    /// Where uploads are written as they arrive, before they are read.
    pub spool_dir: std::path::PathBuf,
}

impl DemStore {
    pub fn new(limits: DemLimits, max_upload_bytes: usize, cache_bytes: usize) -> DemStore {
        DemStore {
            limits,
            max_upload_bytes,
            cache: DemCache::new(DEM_CACHE_ENTRIES, cache_bytes),
            spool_dir: std::env::temp_dir(),
        }
    }

    pub fn from_config(config: &ServeConfig) -> DemStore {
        let cache_bytes = config.dem_cache_mb.saturating_mul(1024 * 1024);
        DemStore {
            spool_dir: crate::api::dems::spool_dir(&config.data_dir),
            ..DemStore::new(
                config.dem_limits(),
                config.max_dem_bytes(),
                usize::try_from(cache_bytes).unwrap_or(usize::MAX),
            )
        }
    }
}

/// Route searches: how long one may run, and the D* Lite searches kept
/// in memory so that a replan repairs the previous search instead of
/// starting over.
pub struct RouteStore {
    /// Longest a search may run (`--route-timeout-s`).
    pub timeout: Duration,
    pub searches: SearchCache,
    /// Routes whose D* Lite search is being built in the background: a
    /// receiver that turns true when it is done (or dropped if it failed).
    warming: Mutex<HashMap<String, tokio::sync::watch::Receiver<bool>>>,
}

/// Marks route `id`'s search as being built until dropped.
pub struct Warming {
    store: Arc<RouteStore>,
    id: String,
    done: tokio::sync::watch::Sender<bool>,
}

impl Drop for Warming {
    fn drop(&mut self) {
        let _ = self.done.send(true);
        lock(&self.store.warming).remove(&self.id);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // The maps guard no invariant a panic could break half-way.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// `--route-timeout-s` and `--route-cache-mb` by default.
const ROUTE_TIMEOUT: Duration = Duration::from_secs(120);
const ROUTE_CACHE_BYTES: usize = 512 * 1024 * 1024;

impl RouteStore {
    pub fn new(timeout: Duration, cache_bytes: usize) -> RouteStore {
        RouteStore {
            timeout,
            searches: SearchCache::new(cache_bytes),
            warming: Mutex::new(HashMap::new()),
        }
    }

    /// Route `id`'s search is being built: replans of `id` wait for it
    /// (see [`warmed`](Self::warmed)) until the returned guard is dropped.
    pub fn begin_warming(self: &Arc<Self>, id: &str) -> Warming {
        let (done, rx) = tokio::sync::watch::channel(false);
        lock(&self.warming).insert(id.to_string(), rx);
        Warming {
            store: self.clone(),
            id: id.to_string(),
            done,
        }
    }

    /// Wait until no search of route `id` is being built. The one being
    /// built started earlier than a rebuild would, so it is never slower
    /// to wait for it.
    pub async fn warmed(&self, id: &str) {
        let rx = lock(&self.warming).get(id).cloned();
        if let Some(mut rx) = rx {
            let _ = rx.wait_for(|done| *done).await;
        }
    }

    pub fn from_config(config: &ServeConfig) -> RouteStore {
        RouteStore::new(
            Duration::from_secs_f64(config.route_timeout_s),
            config.route_cache_bytes(),
        )
    }
}

impl Default for RouteStore {
    fn default() -> Self {
        RouteStore::new(ROUTE_TIMEOUT, ROUTE_CACHE_BYTES)
    }
}

/// The D* Lite search of each recent route (its grid with every change
/// applied so far, its g values and queue), by route id: an LRU bounded
/// by an estimate of the memory held. A replan takes its parent's search
/// out (so two replans of one route never share it), repairs it and puts
/// it back under the new route's id.
pub struct SearchCache {
    /// Most recently used first: (route id, search, estimated bytes).
    entries: Mutex<Vec<(String, DStarLite, usize)>>,
    max_bytes: usize,
}

impl SearchCache {
    pub fn new(max_bytes: usize) -> SearchCache {
        SearchCache {
            entries: Mutex::new(Vec::new()),
            max_bytes,
        }
    }

    /// Estimated memory of a search: 13 bytes per cell (cost, g, state
    /// byte) plus 4 for its open list and slack, and the per-row cell
    /// widths.
    pub fn estimate_bytes(search: &DStarLite) -> usize {
        let grid = search.grid();
        grid.cell_count()
            .saturating_mul(17)
            .saturating_add(grid.height() * 8)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(String, DStarLite, usize)>> {
        // The list guards no invariant a panic could break half-way.
        self.entries.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Take the search of route `id` out of the cache.
    pub fn take(&self, id: &str) -> Option<DStarLite> {
        let mut entries = self.lock();
        let i = entries.iter().position(|(k, _, _)| k == id)?;
        Some(entries.remove(i).1)
    }

    /// Keep `search` as route `id`'s, the most recently used, evicting the
    /// least recently used beyond the memory budget; a search alone over
    /// the budget is not kept.
    pub fn put(&self, id: &str, search: DStarLite) {
        let size = Self::estimate_bytes(&search);
        if size > self.max_bytes {
            return;
        }
        let mut entries = self.lock();
        entries.retain(|(k, _, _)| k != id);
        entries.insert(0, (id.to_string(), search, size));
        let mut total = 0usize;
        let keep = entries
            .iter()
            .take_while(|(_, _, bytes)| {
                total = total.saturating_add(*bytes);
                total <= self.max_bytes
            })
            .count();
        entries.truncate(keep);
    }

    /// Forget route `id`'s search.
    pub fn remove(&self, id: &str) {
        self.lock().retain(|(k, _, _)| k != id);
    }

    /// Searches held, and their estimated bytes.
    #[cfg(test)]
    pub fn usage(&self) -> (usize, usize) {
        let entries = self.lock();
        (entries.len(), entries.iter().map(|(_, _, b)| b).sum())
    }
}

/// Parsed DEMs kept at once, at most.
const DEM_CACHE_ENTRIES: usize = 4;

/// A small LRU of parsed DEMs, bounded by count and by the memory of
/// their heights.
pub struct DemCache {
    inner: Mutex<CacheInner>,
    max_entries: usize,
    max_bytes: usize,
}

struct CacheInner {
    /// Most recently used first.
    entries: Vec<(String, Arc<Dem>)>,
    /// Bumped by every eviction, so a load that raced a delete does not
    /// put the deleted DEM back.
    epoch: u64,
}

fn dem_bytes(dem: &Dem) -> usize {
    dem.values.len() * std::mem::size_of::<f64>()
}

impl DemCache {
    pub fn new(max_entries: usize, max_bytes: usize) -> DemCache {
        DemCache {
            inner: Mutex::new(CacheInner {
                entries: Vec::new(),
                epoch: 0,
            }),
            max_entries,
            max_bytes,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, CacheInner> {
        // The lock guards no invariant a panic could break half-way.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn get(&self, id: &str) -> Option<Arc<Dem>> {
        let mut inner = self.lock();
        let i = inner.entries.iter().position(|(k, _)| k == id)?;
        let entry = inner.entries.remove(i);
        let dem = entry.1.clone();
        inner.entries.insert(0, entry);
        Some(dem)
    }

    /// The current eviction count, to pass to [`DemCache::insert`].
    pub fn epoch(&self) -> u64 {
        self.lock().epoch
    }

    /// Keep `dem` as the most recently used, unless something was evicted
    /// since `epoch` (when given) or it alone is over the memory budget.
    pub fn insert(&self, id: &str, dem: Arc<Dem>, epoch: Option<u64>) {
        let size = dem_bytes(&dem);
        let mut inner = self.lock();
        if epoch.is_some_and(|e| e != inner.epoch) || size > self.max_bytes || self.max_entries == 0
        {
            return;
        }
        inner.entries.retain(|(k, _)| k != id);
        inner.entries.insert(0, (id.to_string(), dem));
        let mut total = 0usize;
        let mut keep = 0;
        for (_, d) in &inner.entries {
            let next = total.saturating_add(dem_bytes(d));
            if keep == self.max_entries || next > self.max_bytes {
                break;
            }
            total = next;
            keep += 1;
        }
        inner.entries.truncate(keep);
    }

    pub fn evict(&self, id: &str) {
        let mut inner = self.lock();
        inner.entries.retain(|(k, _)| k != id);
        inner.epoch += 1;
    }
}

/// Run `job` on a blocking thread, without waiting for a planner slot: for
/// request checks whose work grows with the request (bounded by the body
/// limit), which must not hold up the runtime threads.
pub async fn off_runtime<T: Send + 'static>(
    job: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(job)
        .await
        .map_err(|e| ApiError::Internal(format!("request check failed: {e}")))
}

impl AppState {
    /// Run CPU-heavy planning off the async runtime, at most
    /// `planner_threads` jobs of each kind of `work` at a time; a job waits
    /// up to 2 minutes for its slot (then 503).
    ///
    /// The job gets a cancellation token, also set as its thread's
    /// ([`planner_core::cancel::check`]): it is cancelled when the
    /// returned future is dropped (the client went away) and runs out
    /// after the time limit of the kind of work, counted from the job's
    /// start. A job seeing it cancelled returns early, which frees its slot.
    pub async fn run_planner<T: Send + 'static>(
        &self,
        work: Work,
        job: impl FnOnce(&CancelToken) -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let slots = self.planner.slots(work).clone();
        let permit = tokio::time::timeout(PLANNER_QUEUE_TIMEOUT, slots.acquire_owned())
            .await
            .map_err(|_| ApiError::Unavailable("the planner is busy: retry in a moment".into()))?
            .map_err(|_| ApiError::Unavailable("the service is shutting down".into()))?;
        let token = match work {
            Work::Survey => CancelToken::with_limit(self.planner.survey_timeout),
            Work::Route => CancelToken::with_limit(self.routes.timeout),
            Work::Dem => CancelToken::new(),
        };
        // Dropped with this future when the client goes away.
        let _cancel = token.cancel_on_drop();
        let span = tracing::Span::current();
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            let _span = span.enter();
            let began = std::time::Instant::now();
            let out = token.scope(|| job(&token));
            if let Err(why) = token.check() {
                tracing::info!(
                    work = ?work,
                    after_ms = began.elapsed().as_millis() as u64,
                    "planning stopped: {why}"
                );
            }
            out
        })
        .await
        .map_err(|e| ApiError::Internal(format!("planner task failed: {e}")))
    }

    /// A stored DEM, parsed (from the cache when it is there); 404 when
    /// there is no DEM `id`.
    pub async fn load_dem(&self, id: &str) -> Result<Arc<Dem>, ApiError> {
        Ok(self.load_dem_for(id, "", |_, _| 0).await?.0)
    }

    /// [`AppState::load_dem`], holding room in the memory budget for
    /// `work` bytes of work on the DEM (given its width and height) as
    /// well, and, when the DEM is not in the cache, for reading it; the
    /// room is held until the returned reservation is dropped. `what`
    /// names the work in a refusal (a 422 when it alone needs more than
    /// the budget).
    pub async fn load_dem_for(
        &self,
        id: &str,
        what: &str,
        work: impl FnOnce(u64, u64) -> u64,
    ) -> Result<(Arc<Dem>, crate::memory::Reservation), ApiError> {
        self.load_dem_within(id, what, work, Some(crate::memory::QUEUE_TIMEOUT))
            .await
    }

    /// [`AppState::load_dem_for`] waiting for room in the budget at most
    /// `timeout` (`None`: as long as it takes, for background jobs).
    pub async fn load_dem_within(
        &self,
        id: &str,
        what: &str,
        work: impl FnOnce(u64, u64) -> u64,
        timeout: Option<Duration>,
    ) -> Result<(Arc<Dem>, crate::memory::Reservation), ApiError> {
        let doing = |w: u64, h: u64| {
            let on = format!("DEM {id} ({w} × {h} pixels)");
            if what.is_empty() {
                format!("reading {on}")
            } else {
                format!("{what} on {on}")
            }
        };
        if let Some(dem) = self.dems.cache.get(id) {
            let (w, h) = (dem.width as u64, dem.height as u64);
            let room = self
                .memory
                .reserve_within(work(w, h), &doing(w, h), timeout)
                .await?;
            return Ok((dem, room));
        }
        let epoch = self.dems.cache.epoch();
        let meta = self
            .db
            .get_dem_meta(id)
            .await?
            .ok_or_else(|| dems::not_found(id))?;
        let (w, h) = dems::stored_size(&meta)?;
        let size = u64::try_from(meta.size_bytes).unwrap_or(0);
        let read = match meta.read_bytes.and_then(|b| u64::try_from(b).ok()) {
            Some(b) => b,
            // Stored before the estimate was kept: the whole image as one
            // Float64 chunk at worst.
            None => {
                let pixels = w.saturating_mul(h);
                crate::memory::dem_read_bytes(pixels, pixels.saturating_mul(8), size)
            }
        };
        let work_bytes = work(w, h);
        let need = read.saturating_add(work_bytes);
        let room = self
            .memory
            .reserve_within(need, &doing(w, h), timeout)
            .await?;
        let row = self
            .db
            .get_dem_data(id)
            .await?
            .ok_or_else(|| dems::not_found(id))?;
        let crs = row
            .crs_override
            .map(u32::try_from)
            .transpose()
            .map_err(|e| ApiError::Internal(format!("stored CRS of DEM {id}: {e}")))?;
        // It was read once at upload: the limits of the day need not hold again.
        let limits = DemLimits {
            max_pixels: u64::MAX,
            max_side: u32::MAX,
        };
        let dem = self
            .run_planner(Work::Dem, move |_| {
                read_dem(&row.data, row.file_name.as_deref(), crs, &limits)
            })
            .await?
            .map_err(|e| ApiError::Internal(format!("stored DEM {id} does not read again: {e}")))?;
        let dem = Arc::new(dem);
        self.dems.cache.insert(id, dem.clone(), Some(epoch));
        let mut room = room;
        if self
            .dems
            .cache
            .get(id)
            .is_some_and(|d| Arc::ptr_eq(&d, &dem))
        {
            // Kept in the cache, whose memory is its own: only the work's
            // room is still needed.
            room.shrink_to(work_bytes);
        }
        Ok((dem, room))
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "terraplan",
        description = "Mission planning for UAV survey flocks and ground robots. Geometry is GeoJSON \
                       (RFC 7946, WGS84 lon/lat); units are metres, seconds, degrees and m/s. Errors \
                       are RFC 9457 application/problem+json."
    ),
    tags(
        (name = "surveys", description = "Photo-survey planning: decomposition, lawnmower paths, missions"),
        (name = "dems", description = "Digital elevation models: upload (GeoTIFF, ESRI ASCII grid, SRTM .hgt), metadata, hillshade preview, heights at points"),
        (name = "costmaps", description = "Traversability costmaps of a DEM for a ground vehicle: background jobs with progress events, GeoTIFF, preview and per-layer files"),
        (name = "routes", description = "UGV routes across a finished costmap: the cheapest safe path (A* or D* Lite), incremental replanning around blocked areas, GeoJSON, CSV (UTM) and ArduPilot Rover missions"),
        (name = "service", description = "Health"),
    ),
    components(schemas(crate::error::Problem, crate::error::IssueSchema))
)]
struct ApiDoc;

/// The OpenAPI document and the router it describes.
pub fn router(state: AppState, cors_origins: &[String], max_body_bytes: usize) -> Router {
    let max_dem_bytes = state.dems.max_upload_bytes;
    let (api, openapi) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(health::healthz))
        .routes(routes!(surveys::create_survey, surveys::list_surveys))
        .routes(routes!(surveys::get_survey, surveys::delete_survey))
        .routes(routes!(surveys::uav_file))
        .routes(routes!(surveys::cells_file))
        // DEM files have their own, larger, body limit.
        .routes(
            routes!(dems::upload_dem, dems::list_dems).layer(DefaultBodyLimit::max(max_dem_bytes)),
        )
        .routes(routes!(dems::get_dem, dems::delete_dem))
        .routes(routes!(dems::hillshade))
        .routes(routes!(dems::elevation, dems::elevations))
        .routes(routes!(costmaps::create_costmap, costmaps::list_costmaps))
        .routes(routes!(costmaps::get_costmap, costmaps::delete_costmap))
        .routes(routes!(costmaps::costmap_events))
        .routes(routes!(costmaps::costmap_tif))
        .routes(routes!(costmaps::preview))
        .routes(routes!(costmaps::legend))
        .routes(routes!(costmaps::layer))
        .routes(routes!(vehicles::list_vehicles))
        .routes(routes!(cameras::list_cameras))
        .routes(routes!(route_api::create_route))
        .routes(routes!(route_api::list_routes))
        .routes(routes!(route_api::get_route, route_api::delete_route))
        .routes(routes!(route_api::replan_route))
        .routes(routes!(route_api::route_geojson_file))
        .routes(routes!(route_api::route_csv_file))
        .routes(routes!(route_api::mission_waypoints))
        .split_for_parts();
    let openapi = Arc::new(openapi);
    let doc = openapi.clone();
    let request_id = HeaderName::from_static("x-request-id");

    let mut app = api
        .route(
            "/api/v1/openapi.json",
            axum::routing::get(move || {
                let doc = doc.clone();
                async move { axum::Json(doc.as_ref().clone()) }
            }),
        )
        .merge(SwaggerUi::new("/api/docs").url("/api/v1/openapi-ui.json", openapi.as_ref().clone()))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(state)
        .layer(DefaultBodyLimit::max(max_body_bytes))
        .layer(middleware::from_fn(move |req: Request, next: Next| {
            let limit = if is_dem_upload(&req) {
                max_dem_bytes
            } else {
                max_body_bytes
            };
            early_answers(req, next, limit)
        }))
        .layer(CompressionLayer::new())
        .layer(CatchPanicLayer::custom(panic_response))
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &Request| {
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %id)
            })
            .on_response(DefaultOnResponse::new().level(tracing::Level::INFO).latency_unit(LatencyUnit::Millis)),
        )
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid));
    if let Some(cors) = cors_layer(cors_origins) {
        app = app.layer(cors);
    }
    app
}

fn cors_layer(origins: &[String]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    let layer = CorsLayer::new()
        .allow_methods([Method::GET, Method::POST, Method::DELETE])
        .allow_headers(Any)
        .expose_headers([
            axum::http::header::LOCATION,
            axum::http::header::CONTENT_DISPOSITION,
        ]);
    Some(if origins.iter().any(|o| o == "*") {
        layer.allow_origin(Any)
    } else {
        let list: Vec<HeaderValue> = origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        layer.allow_origin(AllowOrigin::list(list))
    })
}

fn is_dem_upload(req: &Request) -> bool {
    req.method() == Method::POST && req.uri().path() == "/api/v1/dems"
}

/// Bodies declared this small (Content-Length) are read whole before the
/// handler runs.
const SMALL_BODY_BYTES: u64 = 64 * 1024;

/// Request bodies and answers given before them.
///
/// - A body whose declared Content-Length is over `limit` is refused at
///   once (DefaultBodyLimit alone only notices once that much has
///   arrived), with `Connection: close`: none of it is read.
/// - A small body is read first, so that a handler answering without it
///   (a 415 from the Content-Type, a 400 from the query) leaves nothing
///   unread and the connection stays open for the client's next request.
/// - A larger or chunked body streams to the handler; when the answer
///   comes before its end, hyper closes the connection after the answer,
///   and the answer says so (`Connection: close`). The rest of the body
///   is then read and discarded by the lingering close (`crate::linger`),
///   so the client gets the answer rather than a reset.
async fn early_answers(req: Request, next: Next, limit: usize) -> Response {
    use axum::body::{Body, HttpBody};
    let declared = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if let Some(n) = declared.filter(|&n| n > limit as u64) {
        return closing(
            ApiError::PayloadTooLarge(format!(
                "the request body is too large: {n} bytes declared, the limit is {limit} bytes"
            ))
            .into_response(),
        );
    }
    if req.body().is_end_stream() {
        return next.run(req).await;
    }
    let (parts, body) = req.into_parts();
    if let Some(n) = declared.filter(|&n| n <= SMALL_BODY_BYTES) {
        return match axum::body::to_bytes(body, n as usize).await {
            Ok(bytes) => {
                next.run(Request::from_parts(parts, Body::from(bytes)))
                    .await
            }
            Err(e) => closing(
                ApiError::BadRequest(format!("cannot read the request body: {e}")).into_response(),
            ),
        };
    }
    let ended = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let seen = ended.clone();
    let mut data = body.into_data_stream();
    let tracked = futures_util::stream::poll_fn(move |cx| {
        let next = futures_util::StreamExt::poll_next_unpin(&mut data, cx);
        if let std::task::Poll::Ready(None) = next {
            seen.store(true, std::sync::atomic::Ordering::Release);
        }
        next
    });
    let res = next
        .run(Request::from_parts(parts, Body::from_stream(tracked)))
        .await;
    if ended.load(std::sync::atomic::Ordering::Acquire) {
        res
    } else {
        closing(res)
    }
}

/// `res` with `Connection: close`: hyper closes the connection after it.
fn closing(mut res: Response) -> Response {
    res.headers_mut().insert(
        axum::http::header::CONNECTION,
        HeaderValue::from_static("close"),
    );
    res
}

/// Unknown `/api` paths are problem+json 404s; every other path is the
/// web page's.
async fn not_found(
    axum::extract::State(state): axum::extract::State<AppState>,
    req: Request,
) -> Response {
    let path = req.uri().path();
    if path == "/api" || path.starts_with("/api/") {
        return ApiError::NotFound(format!("there is no resource at {} {}", req.method(), path))
            .into_response();
    }
    state.web.serve(req).await
}

async fn method_not_allowed(req: Request) -> ApiError {
    ApiError::MethodNotAllowed(format!(
        "{} is not allowed on {}",
        req.method(),
        req.uri().path()
    ))
}

fn panic_response(_: Box<dyn std::any::Any + Send + 'static>) -> Response {
    let e = ApiError::Internal("a handler panicked".into());
    let mut res = e.into_response();
    *res.status_mut() = StatusCode::INTERNAL_SERVER_ERROR;
    res
}

#[cfg(test)]
mod tests {
    use planner_core::terrain::{Crs, DemFormat, GeoTransform};

    use super::*;

    fn dem(pixels: usize) -> Arc<Dem> {
        Arc::new(Dem {
            width: pixels,
            height: 1,
            values: vec![1.0; pixels],
            nodata: None,
            transform: GeoTransform {
                origin_x: 0.0,
                pixel_width: 1.0,
                row_rotation: 0.0,
                origin_y: 0.0,
                col_rotation: 0.0,
                pixel_height: -1.0,
            },
            crs: Crs {
                epsg: 32633,
                name: "WGS 84 / UTM zone 33N".into(),
                geographic: false,
                proj4: String::new(),
            },
            format: DemFormat::Asc,
        })
    }

    #[test]
    fn dem_cache_is_lru_by_count_and_bytes() {
        let cache = DemCache::new(2, 8 * 100);
        cache.insert("a", dem(10), None);
        cache.insert("b", dem(10), None);
        assert!(cache.get("a").is_some()); // a is now the most recent
        cache.insert("c", dem(10), None);
        assert!(cache.get("b").is_none(), "least recently used goes first");
        assert!(cache.get("a").is_some() && cache.get("c").is_some());
        // Bytes: 90 + 10 pixels fit, 91 + 10 do not.
        cache.insert("big", dem(90), None);
        assert!(cache.get("big").is_some() && cache.get("c").is_some());
        cache.insert("bigger", dem(91), None);
        assert!(cache.get("bigger").is_some());
        assert!(cache.get("big").is_none());
        // Alone over the budget: not kept.
        cache.insert("huge", dem(101), None);
        assert!(cache.get("huge").is_none());
    }

    /// A D* Lite search on a `cells`-cell strip.
    fn search(cells: usize) -> DStarLite {
        let grid =
            planner_core::route::CostGrid::with_cell_size(cells, 1, vec![1.0; cells], 1.0, 1.0)
                .unwrap();
        DStarLite::new(grid, (0, 0), (0, cells - 1), Default::default()).unwrap()
    }

    #[test]
    fn search_cache_is_lru_by_estimated_bytes() {
        // 17 bytes a cell and 8 a row: 100 cells are 1708 bytes.
        assert_eq!(SearchCache::estimate_bytes(&search(100)), 1708);
        let cache = SearchCache::new(3 * 1708);
        for id in ["a", "b", "c"] {
            cache.put(id, search(100));
        }
        assert_eq!(cache.usage(), (3, 3 * 1708));
        let a = cache.take("a").expect("held");
        assert_eq!(a.grid().cell_count(), 100);
        assert!(cache.take("a").is_none(), "taken out");
        cache.put("d", a); // a's search, moved to d
        cache.put("e", search(100)); // b, the least recently used, goes
        assert!(cache.take("b").is_none());
        assert!(cache.take("c").is_some() && cache.take("d").is_some());
        // A search alone over the budget is not kept.
        cache.put("huge", search(400));
        assert!(cache.take("huge").is_none());
        cache.remove("e");
        assert_eq!(cache.usage(), (0, 0));
        let none = SearchCache::new(0);
        none.put("a", search(10));
        assert!(none.take("a").is_none());
    }

    #[test]
    fn eviction_beats_a_racing_load() {
        let cache = DemCache::new(4, usize::MAX);
        let epoch = cache.epoch();
        cache.evict("a"); // deleted while being loaded
        cache.insert("a", dem(1), Some(epoch));
        assert!(cache.get("a").is_none());
        cache.insert("a", dem(1), Some(cache.epoch()));
        assert!(cache.get("a").is_some());
        cache.evict("a");
        assert!(cache.get("a").is_none());
    }
}
