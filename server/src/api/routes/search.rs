//! Route searches on planner threads: the costmap as a route map, a new
//! route by A*, the D* Lite search built for its replans, and a replan
//! (repairing the parent's search or from scratch) with the rules of
//! [`planner_core::route::changes`]; their faults named by JSON pointer.
//!
//! A costmap of more cells than `--route-coarse-cells`, or whose search in
//! memory would not fit the memory budget, is planned coarse to fine
//! instead ([`planner_core::route::WindowedMap`]): its GeoTIFF read a
//! window at a time from the stored chunks ([`StoredFileReader`]), memory
//! reserved for the corridor the budget allows, never 16 bytes a cell of
//! the map. Such routes are not replanned (no map in memory to change):
//! a replan on such a costmap is a 422 naming why.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use geo_types::Polygon;
use planner_core::cancel::{CancelToken, Cancelled};
use planner_core::geo::Issue;
use planner_core::route::changes::{self, BlockedEnd, CellChanges, ChangeError, ChangedArea};
use planner_core::route::{
    AveragedHeights, BigRouteError, Cell, CoarseToFineOptions, CostGrid, DStarLite, Endpoint,
    MapRoute, MapRouteError, Position, Route, RouteError, RouteMap, WindowedMap,
    WindowedRouteError, astar,
};
use planner_core::terrain::{Dem, DemLimits, GeoTiffWindows, RasterWindows};
use serde::Deserialize;

use super::model::{Changes, Planner, SearchOptions, SearchReport, stored};
use super::request::{Area, stored_polygon};
use super::stored_file::{CACHED_CHUNKS, StoredFileReader};
use crate::db::{CHUNK_BYTES, CostmapRow, StoredFile};
use crate::error::{ApiError, not_found};
use crate::jobs::COSTMAP_TIF;
use crate::state::AppState;
use crate::state::dem_store::tiles::{StoredTiles, TILE_CACHE_BYTES, stored_set};

/// Most cells of a coarse-to-fine corridor (its search state: about 21
/// bytes a cell, 4.2 GB), as `terraplan route --max-corridor-cells`; the
/// memory budget may allow fewer.
const MAX_CORRIDOR_CELLS: u64 = 200_000_000;

/// What a search needs from storage, gathered on the async side.
pub(super) struct MapSource {
    costmap_id: String,
    map: Source,
    /// Room in the memory budget for the search (and a D* Lite search
    /// built after it), held as long as the source.
    _room: crate::memory::Reservation,
}

enum Source {
    /// The costmap's GeoTIFF read whole, and its DEM (for heights; `None`
    /// when the DEM has been deleted): plain A*, D* Lite for replans.
    Whole { tif: Vec<u8>, dem: Option<Arc<Dem>> },
    /// The costmap read a window at a time: coarse to fine.
    Windowed(Box<Windowed>),
}

struct Windowed {
    tif: Arc<StoredFileReader>,
    cells: u64,
    c2f: CoarseToFineOptions,
    /// The DEM's stored tiles, for heights (`None` when the DEM is gone or
    /// was stored before tiles).
    dem: Option<StoredTiles>,
}

impl MapSource {
    /// True for a costmap planned coarse to fine.
    pub(super) fn is_windowed(&self) -> bool {
        matches!(self.map, Source::Windowed(_))
    }
}

/// How a costmap of `cells` cells in a `file_bytes` file is searched: in
/// memory when it has at most `--route-coarse-cells` cells and the search
/// (with reading its DEM, `dem_read` bytes) fits the memory budget, else
/// coarse to fine.
fn coarse_to_fine_for(state: &AppState, cells: u64, file_bytes: u64, dem_read: u64) -> bool {
    cells > state.routes.coarse_cells
        || crate::memory::route_search_bytes(cells, file_bytes).saturating_add(dem_read)
            > state.memory.total()
}

/// The memory reading costmap `costmap`'s DEM whole takes (its estimate
/// at upload; 0 when it is gone). Counted whether or not the DEM is in the
/// cache now, so that a costmap is always searched the same way.
async fn dem_read_bytes(state: &AppState, costmap: &CostmapRow) -> Result<u64, ApiError> {
    let Some(meta) = state.db.get_dem_meta(&costmap.dem_id).await? else {
        return Ok(0);
    };
    Ok(match meta.read_bytes.and_then(|b| u64::try_from(b).ok()) {
        Some(b) => b,
        None => {
            let (w, h) = crate::state::dem_store::stored_size(&meta)?;
            let pixels = w.saturating_mul(h);
            let file = u64::try_from(meta.size_bytes).unwrap_or(0);
            crate::memory::dem_read_bytes(pixels, pixels.saturating_mul(8), file)
        }
    })
}

/// The costmap's GeoTIFF and its DEM (for heights; `None` when the DEM
/// has been deleted), once there is room in the memory budget for a
/// search on it (a 422 when it alone needs more than the budget); or, for
/// a costmap to plan coarse to fine, its stored file to read by windows.
pub(super) async fn map_source(
    state: &AppState,
    costmap: &CostmapRow,
) -> Result<MapSource, ApiError> {
    #[derive(Deserialize)]
    struct Size {
        width: u64,
        height: u64,
    }
    let meta = state
        .db
        .costmap_file_meta(&costmap.id, COSTMAP_TIF)
        .await?
        .ok_or_else(|| not_found("costmap", &costmap.id))?;
    let size: Size = stored(
        &costmap.id,
        "result",
        costmap.result.as_deref().unwrap_or(""),
    )?;
    let cells = size.width.saturating_mul(size.height);
    let file_bytes = u64::try_from(meta.size_bytes).unwrap_or(0);
    let what = format!(
        "a route search (costmap {}, {} × {} cells)",
        costmap.id, size.width, size.height
    );
    let dem_read = dem_read_bytes(state, costmap).await?;
    if coarse_to_fine_for(state, cells, file_bytes, dem_read) {
        return windowed_source(state, costmap, (size.width, size.height), file_bytes, &what).await;
    }
    let need = crate::memory::route_search_bytes(cells, file_bytes);
    let (dem, room) = match state
        .load_dem_for(&costmap.dem_id, &what, |_, _| need)
        .await
    {
        Ok((dem, room)) => (Some(dem), room),
        Err(ApiError::NotFound(_)) => (None, state.memory.reserve(need, &what).await?),
        Err(e) => return Err(e),
    };
    let file = state
        .db
        .get_costmap_file(&costmap.id, COSTMAP_TIF)
        .await?
        .ok_or_else(|| not_found("costmap", &costmap.id))?;
    Ok(MapSource {
        costmap_id: costmap.id.clone(),
        map: Source::Whole {
            tif: file.data,
            dem,
        },
        _room: room,
    })
}

/// DEM `id`'s level-0 tiles, read by windows; `None` when it is gone or
/// was stored before tiles.
async fn dem_tiles(state: &AppState, id: &str) -> Result<Option<StoredTiles>, ApiError> {
    let Some(meta) = state.db.get_dem_meta(id).await? else {
        return Ok(None);
    };
    let info = crate::api::dems::stored_dem_info(&meta)?;
    Ok(stored_set(&state.db, id, &info).await?.map(|(set, grid)| {
        StoredTiles::new(
            state.db.clone(),
            tokio::runtime::Handle::current(),
            id,
            set,
            0,
            &grid,
        )
    }))
}

/// The stored costmap file to read by windows, with room in the budget
/// for a coarse-to-fine search: the caches of what it reads and a
/// corridor as large as the rest of the budget allows (at most
/// [`MAX_CORRIDOR_CELLS`] and the map's cells).
async fn windowed_source(
    state: &AppState,
    costmap: &CostmapRow,
    (width, height): (u64, u64),
    file_bytes: u64,
    what: &str,
) -> Result<MapSource, ApiError> {
    let cells = width.saturating_mul(height);
    let (w, h) = (
        usize::try_from(width).unwrap_or(usize::MAX),
        usize::try_from(height).unwrap_or(usize::MAX),
    );
    let dem = dem_tiles(state, &costmap.dem_id).await?;
    let dem_cells = dem.as_ref().map_or(0, |d| {
        (d.grid().width as u64).saturating_mul(d.grid().height as u64)
    });
    let sources = |search: u64| {
        crate::memory::route_coarse_to_fine_bytes(
            search,
            (cells, GeoTiffWindows::<std::fs::File>::CACHE_BYTES as u64),
            (file_bytes, (CACHED_CHUNKS * CHUNK_BYTES) as u64),
            (dem_cells, TILE_CACHE_BYTES as u64),
        )
    };
    let no_corridor = CoarseToFineOptions {
        max_corridor_cells: 0,
        ..CoarseToFineOptions::default()
    };
    let fixed = sources(no_corridor.estimated_bytes(w, h));
    let room_for_corridor = state.memory.total().saturating_sub(fixed);
    let c2f = CoarseToFineOptions {
        max_corridor_cells: (room_for_corridor / CoarseToFineOptions::CORRIDOR_BYTES_PER_CELL)
            .min(MAX_CORRIDOR_CELLS)
            .min(cells),
        ..CoarseToFineOptions::default()
    };
    let need = sources(c2f.estimated_bytes(w, h));
    let what = format!("{what} coarse to fine");
    let room = state.memory.reserve(need, &what).await?;
    let file = StoredFile::Costmap(costmap.id.clone(), COSTMAP_TIF.to_string());
    let tif = StoredFileReader::open(state.db.clone(), file, file_bytes, CACHED_CHUNKS)
        .await
        .map_err(|e| match e {
            super::stored_file::StoredFileError::Db(e) => ApiError::from(e),
            other => ApiError::Internal(format!("costmap {}: {other}", costmap.id)),
        })?;
    Ok(MapSource {
        costmap_id: costmap.id.clone(),
        map: Source::Windowed(Box::new(Windowed {
            tif: Arc::new(tif),
            cells,
            c2f,
            dem,
        })),
        _room: room,
    })
}

/// The route map (on a planner thread: it holds PROJ objects, which
/// stay on the thread that made them).
fn build_map(src: &MapSource) -> Result<RouteMap, ApiError> {
    let Source::Whole { tif, dem } = &src.map else {
        return Err(not_in_memory(src));
    };
    let built = match RouteMap::from_costmap_geotiff(tif, dem.as_deref(), &ANY_SIZE) {
        Err(MapRouteError::DemMismatch(why)) => {
            tracing::warn!(costmap = %src.costmap_id, %why, "the DEM does not fit the costmap: planning without heights");
            RouteMap::from_costmap_geotiff(tif, None, &ANY_SIZE)
        }
        other => other,
    };
    built.map_err(|e| match e {
        MapRouteError::Grid(_) | MapRouteError::RotatedGrid => ApiError::Conflict(format!(
            "no route can be planned on costmap {}: {e}",
            src.costmap_id
        )),
        other => ApiError::Internal(format!(
            "costmap {} as a route map: {other}",
            src.costmap_id
        )),
    })
}

/// Costmaps are written by this server: the limits of the day need not
/// hold again.
const ANY_SIZE: DemLimits = DemLimits {
    max_pixels: u64::MAX,
    max_side: u32::MAX,
};

/// The answer to a replan on a costmap planned coarse to fine.
pub(super) fn not_in_memory(src: &MapSource) -> ApiError {
    let cells = match &src.map {
        Source::Windowed(w) => w.cells,
        Source::Whole { .. } => 0,
    };
    ApiError::Validation(vec![Issue::new(
        "",
        &format!(
            "routes on costmap {} ({cells} cells) are planned coarse to fine, a window at a \
             time: it has more cells than the server's --route-coarse-cells or its search in \
             memory would not fit the memory budget, and such routes cannot be replanned with \
             blocked areas or cost changes; plan a new route from the position instead",
            src.costmap_id
        ),
    )])
}

/// Which request the search serves, for naming the members at fault.
#[derive(Clone, Copy)]
enum Ends {
    Create,
    /// `blocking`: the replan blocks areas.
    Replan {
        blocking: bool,
    },
}

impl Ends {
    fn pointer(self, end: Endpoint) -> &'static str {
        match (self, end) {
            (Ends::Create, Endpoint::Start) => "/start",
            (Ends::Create, Endpoint::Goal) => "/goal",
            (Ends::Replan { .. }, Endpoint::Start) => "/position",
            // The parent's goal: not a member of a replan.
            (Ends::Replan { .. }, Endpoint::Goal) => "",
        }
    }
}

/// A fault of the start or goal position, named by pointer.
fn endpoint_issue(e: &MapRouteError, ends: Ends) -> Option<Issue> {
    let end = match e {
        MapRouteError::Outside { end, .. }
        | MapRouteError::Blocked { end, .. }
        | MapRouteError::InvalidPosition { end, .. } => *end,
        _ => return None,
    };
    let mut message = e.to_string();
    if let Ends::Replan { .. } = ends
        && let Some(rest) = message.strip_prefix("the start")
    {
        message = format!("the position{rest}");
    }
    Some(Issue::new(ends.pointer(end), &message))
}

fn from_search(e: RouteError) -> MapRouteError {
    match e {
        RouteError::Unreachable => MapRouteError::Unreachable,
        other => MapRouteError::Search(other),
    }
}

/// The answer to a failed search.
fn search_fault(e: MapRouteError, ends: Ends, stop: &CancelToken) -> ApiError {
    if let Some(issue) = endpoint_issue(&e, ends) {
        return ApiError::Validation(vec![issue]);
    }
    let at =
        |pointer: &str, message: &str| ApiError::Validation(vec![Issue::new(pointer, message)]);
    match e {
        MapRouteError::Unreachable => match ends {
            Ends::Create => at("/goal", &e.to_string()),
            Ends::Replan { blocking } => at(
                if blocking { "/blocked" } else { "/position" },
                "the goal cannot be reached from the position: obstacles and blocked areas \
                 separate them (they are in different traversable regions of the changed costmap)",
            ),
        },
        MapRouteError::Search(RouteError::Cancelled) => match stop.check() {
            Err(Cancelled::TimedOut { limit }) => ApiError::Unavailable(format!(
                "the route search took too long: it was stopped after the limit of {} s \
                 (--route-timeout-s)",
                limit.as_secs_f64()
            )),
            _ => {
                // Nobody reads this answer.
                tracing::info!("route search cancelled: the client went away");
                ApiError::Unavailable("the route search was cancelled: the client went away".into())
            }
        },
        MapRouteError::Search(
            RouteError::StartBlocked { .. } | RouteError::StartOutside { .. },
        ) => at(ends.pointer(Endpoint::Start), &e.to_string()),
        MapRouteError::Search(RouteError::GoalBlocked { .. } | RouteError::GoalOutside { .. }) => {
            at(ends.pointer(Endpoint::Goal), &e.to_string())
        }
        MapRouteError::Search(e) => e.into(),
        other => ApiError::Internal(format!("route search: {other}")),
    }
}

/// The cell of a position, or its fault added to `issues`.
fn locate(
    map: &RouteMap,
    p: &Position,
    end: Endpoint,
    ends: Ends,
    issues: &mut Vec<Issue>,
) -> Result<Option<Cell>, ApiError> {
    match map.locate(p, end) {
        Ok(cell) => Ok(Some(cell)),
        Err(e) => match endpoint_issue(&e, ends) {
            Some(issue) => {
                issues.push(issue);
                Ok(None)
            }
            None => Err(ApiError::Internal(format!("locating the {end}: {e}"))),
        },
    }
}

/// A route found, and the D* Lite search that found it (a replan's).
pub(super) struct Planned {
    pub(super) route: MapRoute,
    pub(super) planner: Planner,
    pub(super) reused_search: bool,
    pub(super) search: Option<DStarLite>,
    /// A new route's D* Lite search, its first search to be completed
    /// for its replans (it has the route's A* as its landmark).
    pub(super) warm: Option<DStarLite>,
    /// How a coarse-to-fine search ended.
    pub(super) report: Option<SearchReport>,
}

/// A new route, on a planner thread.
pub(super) fn plan_route(
    src: &MapSource,
    start: &Position,
    goal: &Position,
    options: &SearchOptions,
    stop: &CancelToken,
) -> Result<Planned, ApiError> {
    if let Source::Windowed(windowed) = &src.map {
        return plan_coarse_to_fine(src, windowed, start, goal, options, stop);
    }
    let map = build_map(src)?;
    let ends = Ends::Create;
    let mut issues = Vec::new();
    let s = locate(&map, start, Endpoint::Start, ends, &mut issues)?;
    let g = locate(&map, goal, Endpoint::Goal, ends, &mut issues)?;
    let (Some(s), Some(g)) = (s, g) else {
        return Err(ApiError::Validation(issues));
    };
    let opts = options.route_options(map.grid().cell_count());
    let fault = |e: RouteError| search_fault(from_search(e), ends, stop);
    let check = || stop.is_cancelled();
    // A* answers at once. With replans by D* Lite, that A* is run by the
    // route's D* Lite search (its landmark), whose first search is then
    // completed in the background: the walk back along the route and a
    // settled band around it, about a quarter of A*'s time.
    let began = Instant::now();
    let (route, warm) = if options.planner() == Planner::DstarLite {
        let mut search = DStarLite::new(map.grid().clone(), s, g, opts.clone()).map_err(fault)?;
        (search.plan_with_astar(&check).map_err(fault)?, Some(search))
    } else {
        (astar(map.grid(), s, g, &opts, &check).map_err(fault)?, None)
    };
    Ok(Planned {
        route: describe(&map, &route, began)?,
        planner: Planner::Astar,
        reused_search: false,
        search: None,
        warm,
        report: None,
    })
}

/// A new route coarse to fine, the costmap read by windows from its
/// stored chunks (blocking this planner thread on the database).
fn plan_coarse_to_fine(
    src: &MapSource,
    windowed: &Windowed,
    start: &Position,
    goal: &Position,
    options: &SearchOptions,
    stop: &CancelToken,
) -> Result<Planned, ApiError> {
    if options.epsilon != 1.0 {
        return Err(ApiError::Validation(vec![Issue::new(
            "/epsilon",
            &format!(
                "costmap {} ({} cells) is planned coarse to fine, which finds the optimum \
                 (or says how far from it the route may be): epsilon must be 1",
                src.costmap_id, windowed.cells
            ),
        )]));
    }
    let unreadable = |e: planner_core::terrain::TerrainError| {
        ApiError::Internal(format!("costmap {} read by windows: {e}", src.costmap_id))
    };
    let costs = GeoTiffWindows::open_band(Arc::clone(&windowed.tif), 1, 1, None, &ANY_SIZE)
        .map_err(unreadable)?;
    // The class codes name what a blocked endpoint is on: page 2, or band
    // 2 of costmaps written before the class page.
    let classes = GeoTiffWindows::open_band(Arc::clone(&windowed.tif), 2, 1, None, &ANY_SIZE)
        .or_else(|_| GeoTiffWindows::open_band(Arc::clone(&windowed.tif), 1, 2, None, &ANY_SIZE))
        .ok();
    let heights = windowed
        .dem
        .as_ref()
        .map(|dem| AveragedHeights::new(dem, costs.grid()))
        .transpose()
        .unwrap_or_else(|why| {
            tracing::warn!(costmap = %src.costmap_id, %why, "the DEM does not fit the costmap: planning without heights");
            None
        });
    let map = WindowedMap::new(&costs, classes.as_ref().map(|c| c as &dyn RasterWindows))
        .and_then(|map| match &heights {
            Some(h) => map.with_heights(h),
            None => Ok(map),
        })
        .map_err(|e| match e {
            MapRouteError::Grid(_) | MapRouteError::RotatedGrid => ApiError::Conflict(format!(
                "no route can be planned on costmap {}: {e}",
                src.costmap_id
            )),
            other => ApiError::Internal(format!(
                "costmap {} as a route map: {other}",
                src.costmap_id
            )),
        })?;
    let ends = Ends::Create;
    let mut issues = Vec::new();
    for (p, end) in [(start, Endpoint::Start), (goal, Endpoint::Goal)] {
        if let Err(e) = map.locate(p, end) {
            match endpoint_issue(&e, ends) {
                Some(issue) => issues.push(issue),
                None => return Err(ApiError::Internal(format!("locating the {end}: {e}"))),
            }
        }
    }
    if !issues.is_empty() {
        return Err(ApiError::Validation(issues));
    }
    let opts = options.route_options(usize::try_from(windowed.cells).unwrap_or(usize::MAX));
    let (route, found) = map
        .plan(start, goal, &opts, &windowed.c2f, &|| stop.is_cancelled())
        .map_err(|e| match e {
            WindowedRouteError::Map(e) => search_fault(e, ends, stop),
            WindowedRouteError::Search(BigRouteError::Route(e)) => {
                search_fault(from_search(e), ends, stop)
            }
            WindowedRouteError::Search(BigRouteError::Source(e)) => {
                ApiError::Internal(format!("costmap {} read by windows: {e}", src.costmap_id))
            }
            WindowedRouteError::Search(e @ BigRouteError::CorridorLimit { .. }) => {
                ApiError::Validation(vec![Issue::new(
                    "",
                    &format!(
                        "{e} (the corridor is bounded by the server's memory budget: at most \
                         {} cells)",
                        windowed.c2f.max_corridor_cells
                    ),
                )])
            }
        })?;
    Ok(Planned {
        route,
        planner: Planner::CoarseToFine,
        reused_search: false,
        search: None,
        warm: None,
        report: Some(SearchReport::of(&found)),
    })
}

/// The rest of a new route's D* Lite search, for its replans (on a
/// planner thread, in the background).
pub(super) fn warm_search(mut search: DStarLite, stop: &CancelToken) -> Result<DStarLite, String> {
    search
        .plan(&|| stop.is_cancelled())
        .map_err(|e| e.to_string())?;
    Ok(search)
}

/// A route found by a search begun at `began`, described.
fn describe(map: &RouteMap, route: &Route, began: Instant) -> Result<MapRoute, ApiError> {
    map.describe(route, began.elapsed().as_secs_f64() * 1e3)
        .map_err(|e| ApiError::Internal(format!("describing a route: {e}")))
}

/// What a replan needs.
pub(super) struct ReplanInput {
    pub(super) src: MapSource,
    pub(super) position: Position,
    pub(super) goal: Position,
    pub(super) options: SearchOptions,
    /// The parent's changes.
    pub(super) previous: Changes,
    pub(super) blocked: Vec<Area>,
    pub(super) cost_changes: Vec<(Area, f64)>,
}

impl ReplanInput {
    /// The request member of a changed area.
    fn pointer(&self, area: ChangedArea) -> &str {
        match area {
            ChangedArea::Cost(i) => &self.cost_changes[i].0.pointer,
            ChangedArea::Blocked(i) => &self.blocked[i].pointer,
        }
    }

    fn blocked_polygons(&self) -> Vec<&Polygon<f64>> {
        self.blocked.iter().map(|a| &a.polygon).collect()
    }
}

/// A replan that failed, and the parent's search to keep if there is one.
pub(super) struct Failure {
    pub(super) error: ApiError,
    pub(super) kept: Option<Box<DStarLite>>,
}

fn failed(error: ApiError, kept: Option<DStarLite>) -> Failure {
    Failure {
        error,
        kept: kept.map(Box::new),
    }
}

/// A replan's ends on the map, and its changes as cells.
struct Checked {
    ends: Ends,
    position: Cell,
    goal: Cell,
    changes: CellChanges,
}

/// The ends and areas of a replan on the map, their faults by pointer.
fn check_replan(map: &RouteMap, input: &ReplanInput) -> Result<Checked, ApiError> {
    let ends = Ends::Replan {
        blocking: !input.blocked.is_empty(),
    };
    let mut issues = Vec::new();
    let position = locate(map, &input.position, Endpoint::Start, ends, &mut issues)?;
    let goal = locate(map, &input.goal, Endpoint::Goal, ends, &mut issues)?;
    let cost_areas: Vec<(&Polygon<f64>, f64)> = input
        .cost_changes
        .iter()
        .map(|(a, c)| (&a.polygon, *c))
        .collect();
    let changes = match CellChanges::rasterise(map, &cost_areas, &input.blocked_polygons()) {
        Ok(changes) => Some(changes),
        Err(ChangeError::Areas(faults)) => {
            issues.extend(
                faults
                    .iter()
                    .map(|f| Issue::new(input.pointer(f.area), &f.reason)),
            );
            None
        }
        Err(ChangeError::Map(e)) => {
            return Err(ApiError::Internal(format!("cells of an area: {e}")));
        }
    };
    match (position, goal, changes) {
        (Some(position), Some(goal), Some(changes)) if issues.is_empty() => Ok(Checked {
            ends,
            position,
            goal,
            changes,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// The costmap with the changes of the replans before this one, for a
/// search from scratch (their areas were checked when they were made).
fn previous_grid(map: &RouteMap, previous: &Changes) -> Result<CostGrid, ApiError> {
    let costs = previous
        .cost_changes
        .iter()
        .map(|c| Ok((stored_polygon(&c.area)?, c.cost)))
        .collect::<Result<Vec<_>, ApiError>>()?;
    let blocked = previous
        .blocked
        .iter()
        .map(stored_polygon)
        .collect::<Result<Vec<_>, _>>()?;
    let cost_areas: Vec<(&Polygon<f64>, f64)> = costs.iter().map(|(a, c)| (a, *c)).collect();
    let blocked: Vec<&Polygon<f64>> = blocked.iter().collect();
    let changes = CellChanges::rasterise(map, &cost_areas, &blocked).map_err(|e| match e {
        ChangeError::Areas(faults) => ApiError::Internal(format!(
            "stored areas no longer fit the costmap: {faults:?}"
        )),
        ChangeError::Map(e) => ApiError::Internal(format!("cells of an area: {e}")),
    })?;
    changes
        .apply_to(map.grid().clone())
        .map_err(|e| ApiError::Internal(format!("changed cost grid: {e}")))
}

/// Neither end may end up blocked: `costs` before this replan's changes,
/// `changed` what they make of them.
fn ends_free(
    map: &RouteMap,
    input: &ReplanInput,
    checked: &Checked,
    costs: &[f32],
    changed: &BTreeMap<usize, f32>,
) -> Result<(), ApiError> {
    let blocked = input.blocked_polygons();
    changes::check_ends(
        map,
        &blocked,
        costs,
        changed,
        checked.position,
        checked.goal,
    )
    .map_err(|e| {
        let pointer = match &e {
            BlockedEnd::Start | BlockedEnd::StartEarlier => "/position",
            BlockedEnd::Goal { area } => {
                area.map_or("/blocked", |i| input.blocked[i].pointer.as_str())
            }
        };
        ApiError::Validation(vec![Issue::new(pointer, &e.to_string())])
    })
}

/// A replan, on a planner thread, from the parent's search `cached` when
/// it is held (else rebuilt). On failure, the parent's search when there
/// is one to keep.
pub(super) fn replan(
    input: &ReplanInput,
    cached: Option<DStarLite>,
    stop: &CancelToken,
) -> Result<Planned, Failure> {
    let checked = build_map(&input.src).and_then(|map| Ok((check_replan(&map, input)?, map)));
    let (checked, map) = match checked {
        Ok(checked) => checked,
        Err(e) => return Err(failed(e, cached)),
    };
    match input.options.planner() {
        Planner::DstarLite => replan_dstar_lite(&map, input, &checked, cached, stop),
        // (A map in memory is never planned coarse to fine.)
        Planner::Astar | Planner::CoarseToFine => {
            replan_astar(&map, input, &checked, stop).map_err(|e| failed(e, None))
        }
    }
}

/// A replan by D* Lite: the parent's search repaired, or rebuilt.
fn replan_dstar_lite(
    map: &RouteMap,
    input: &ReplanInput,
    checked: &Checked,
    cached: Option<DStarLite>,
    stop: &CancelToken,
) -> Result<Planned, Failure> {
    let cells = map.grid().cell_count();
    let fault = |e: RouteError| search_fault(from_search(e), checked.ends, stop);
    let (mut search, reused) = match cached {
        Some(s) if changes::can_repair(&s, checked.goal, cells) => (s, true),
        _ => {
            let opts = input.options.route_options(cells);
            let rebuilt = previous_grid(map, &input.previous).and_then(|grid| {
                DStarLite::new(grid, checked.position, checked.goal, opts).map_err(fault)
            });
            match rebuilt {
                Ok(s) => (s, false),
                Err(e) => return Err(failed(e, None)),
            }
        }
    };
    let changed = checked.changes.on(search.grid().costs());
    if let Err(e) = ends_free(map, input, checked, search.grid().costs(), &changed) {
        // A search rebuilt just now has not searched yet: nothing worth
        // keeping.
        return Err(failed(e, reused.then_some(search)));
    }
    let began = Instant::now();
    let route = match changes::repair(&mut search, &changed, checked.position, &|| {
        stop.is_cancelled()
    }) {
        Ok(route) => route,
        // Unreachable, cancelled, over its limit: with this replan's
        // changes undone the search is the parent's again, kept.
        Err(f) => {
            let kept = f.restored.then_some(search);
            return Err(failed(fault(f.error), kept));
        }
    };
    Ok(Planned {
        route: describe(map, &route, began).map_err(|e| failed(e, None))?,
        planner: Planner::DstarLite,
        reused_search: reused,
        search: Some(search),
        warm: None,
        report: None,
    })
}

/// A replan by (weighted) A*, from scratch on the changed costmap.
fn replan_astar(
    map: &RouteMap,
    input: &ReplanInput,
    checked: &Checked,
    stop: &CancelToken,
) -> Result<Planned, ApiError> {
    let grid = previous_grid(map, &input.previous)?;
    let changed = checked.changes.on(grid.costs());
    ends_free(map, input, checked, grid.costs(), &changed)?;
    let grid = changes::with_changes(grid, &changed)
        .map_err(|e| ApiError::Internal(format!("changed cost grid: {e}")))?;
    let opts = input.options.route_options(grid.cell_count());
    let began = Instant::now();
    let route = astar(&grid, checked.position, checked.goal, &opts, &|| {
        stop.is_cancelled()
    })
    .map_err(|e| search_fault(from_search(e), checked.ends, stop))?;
    Ok(Planned {
        route: describe(map, &route, began)?,
        planner: Planner::Astar,
        reused_search: false,
        search: None,
        warm: None,
        report: None,
    })
}
