//! The route resource's shapes: the options and results stored with each
//! route (as JSON), the bodies documented in the OpenAPI document, and the
//! answer built from a stored route.

use planner_core::export::ground_route::route_feature;
use planner_core::route::{
    ArcCost, CoarseToFine, CoarseToFineStats, MapRoute, Position, RouteOptions,
};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};
use utoipa::{IntoParams, ToSchema};

use crate::api::access::answered_project;
use crate::api::costmaps::costmap_url;
use crate::clock::rfc3339;
use crate::db::RouteRow;
use crate::error::ApiError;

/// Cells a search may expand per cell of the costmap: A* expands a cell
/// once, D* Lite at most twice per plan; beyond that something is wrong.
const EXPANSIONS_PER_CELL: u64 = 4;

/// Which search planned a route.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Planner {
    /// D* Lite (replans with `epsilon` = 1): the optimum, repairing the
    /// parent route's search.
    DstarLite,
    /// A*: every new route (the optimum with `epsilon` = 1, while its D*
    /// Lite search is built in the background for replans), and replans
    /// with `epsilon` > 1 (at most `epsilon` × the optimum, from scratch).
    Astar,
    /// Coarse to fine, on a costmap too big for A* in memory (more cells
    /// than `--route-coarse-cells`, or over the memory budget): A* on block
    /// minima, then A* in a corridor around that route, widened until the
    /// route is proven optimal or a limit stops it (see `search`).
    CoarseToFine,
}

/// How a coarse-to-fine search ended: whether the route is proven
/// optimal for the whole costmap, else how far from the optimum it may be.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SearchReport {
    /// `coarse_to_fine`.
    pub(super) method: String,
    /// True when `path_cost` is proven the optimum of the whole costmap
    /// (up to floating-point rounding).
    pub(super) proven_optimal: bool,
    /// A lower bound on the optimum: `path_cost` when proven, else the
    /// optimum lies between it and `path_cost`.
    pub(super) lower_bound: f64,
    /// (`path_cost` − `lower_bound`) / `path_cost`: 0 when proven.
    pub(super) gap: f64,
    /// The search's figures: corridors searched, the last one's half-width
    /// (blocks) and cells, cells touched and expanded, tiles read, bytes of
    /// search state at the peak, milliseconds of each phase.
    pub(super) stats: CoarseToFineStats,
}

impl SearchReport {
    pub(super) fn of(found: &CoarseToFine) -> SearchReport {
        SearchReport {
            method: "coarse_to_fine".into(),
            proven_optimal: found.proven_optimal,
            lower_bound: found.lower_bound,
            gap: found.gap(),
            stats: found.stats.clone(),
        }
    }
}

/// How a route is searched (a replan keeps its parent's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SearchOptions {
    /// Arc cost rule.
    pub(super) arc_cost: ArcCost,
    /// Heuristic weight in [1, 10]: the route costs at most `epsilon` ×
    /// the optimum.
    pub(super) epsilon: f64,
    /// Whether the waypoints are smoothed (shortcuts taken only where
    /// they cost no more), or are the turning points of the cell path.
    pub(super) smooth: bool,
}

impl SearchOptions {
    /// The planner's options for a costmap of `cells` cells.
    pub(super) fn route_options(&self, cells: usize) -> RouteOptions {
        RouteOptions {
            arc_cost: self.arc_cost,
            epsilon: self.epsilon,
            smooth: self.smooth,
            max_expansions: Some((cells as u64).saturating_mul(EXPANSIONS_PER_CELL).max(1)),
        }
    }

    pub(super) fn planner(&self) -> Planner {
        if self.epsilon == 1.0 {
            Planner::DstarLite
        } else {
            Planner::Astar
        }
    }
}

/// A change of cost over an area.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CostChange {
    /// The area: a GeoJSON Polygon (WGS84 lon/lat).
    #[schema(value_type = Object)]
    pub(super) area: Value,
    /// The new cost of its traversable cells, in (0, 1e6] (costmaps use
    /// [1, 20]).
    #[schema(exclusive_minimum = 0, maximum = 1000000)]
    pub(super) cost: f64,
}

/// What a route was asked for, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct StoredRequest {
    pub(super) start: Position,
    pub(super) goal: Position,
    pub(super) options: SearchOptions,
    pub(super) speed_m_s: Option<f64>,
}

/// Every change of the costmap made so far along a chain of replans,
/// stored as JSON: GeoJSON Polygons (CCW exteriors).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct Changes {
    pub(super) blocked: Vec<Value>,
    pub(super) cost_changes: Vec<CostChange>,
}

/// The planned route, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(super) struct StoredResult {
    pub(super) planner: Planner,
    pub(super) reused_search: bool,
    #[serde(flatten)]
    pub(super) route: MapRoute,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) search: Option<SearchReport>,
}

/// Body of `POST /api/v1/costmaps/{id}/routes`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the body for the OpenAPI schema
pub struct CreateRoute {
    /// Where the vehicle starts: `[lon, lat]` (WGS84 degrees) or
    /// `{"utm": [easting, northing]}` in the route's UTM zone (the zone of
    /// the costmap's centre, reported as `utm_zone`).
    start: Position,
    /// Where it goes, in the same forms.
    goal: Position,
    /// Arc cost rule: `{"mode": "integrated"}` (default: step length × the
    /// mean cost of the two cells) or `{"mode": "thesis", "d_max": 10}`
    /// (the thesis' Algorithm 1, d_max in [1, 1000]).
    arc_cost: Option<ArcCost>,
    /// Heuristic weight in [1, 10], default 1 (the optimum; a D* Lite
    /// search is kept for fast replanning); above 1 weighted A*, whose
    /// route costs at most `epsilon` × the optimum and is found faster on
    /// large maps.
    #[schema(minimum = 1, maximum = 10, default = 1)]
    epsilon: Option<f64>,
    /// Smooth the waypoints (default true).
    #[schema(default = true)]
    smooth: Option<bool>,
    /// Ground speed for the rover mission (a DO_CHANGE_SPEED item), m/s in
    /// (0, 50]; none by default.
    #[schema(exclusive_minimum = 0, maximum = 50)]
    speed_m_s: Option<f64>,
    /// A label for the route.
    #[schema(max_length = 200)]
    name: Option<String>,
}

/// Body of `POST /api/v1/routes/{id}/replan`.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the body for the OpenAPI schema
pub struct ReplanRoute {
    /// Where the vehicle is now (the new route's start), in the forms of
    /// `start`.
    position: Position,
    /// Areas found impassable: GeoJSON Polygons (or MultiPolygons, or
    /// Features of them), WGS84. Every cell an area covers or touches is
    /// blocked, in addition to those blocked by earlier replans.
    #[schema(value_type = Vec<Object>)]
    blocked: Option<Vec<Value>>,
    /// Areas whose traversable cells get a new cost (later entries win
    /// where they overlap; obstacles stay obstacles).
    cost_changes: Option<Vec<CostChange>>,
    /// A label for the new route; the parent's by default.
    #[schema(max_length = 200)]
    name: Option<String>,
}

/// Where to fetch a route and its files.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct RouteUrls {
    /// This route.
    #[serde(rename = "self")]
    pub(super) this: String,
    /// The costmap it was planned on.
    pub(super) costmap: String,
    /// The route as a GeoJSON FeatureCollection of one Feature (a
    /// LineString at heights above the WGS 84 ellipsoid).
    pub(super) geojson: String,
    /// The waypoints as CSV: `index,easting,northing,zone,height`.
    pub(super) csv: String,
    /// An ArduPilot Rover mission (QGC WPL 110).
    pub(super) waypoints: String,
    /// POST here to replan from this route.
    pub(super) replan: String,
    /// The route it was replanned from.
    pub(super) parent: Option<String>,
}

/// A planned route.
#[derive(Serialize, ToSchema)]
pub struct RouteResponse {
    id: String,
    name: Option<String>,
    /// The project it belongs to: its costmap's.
    project_id: String,
    /// The costmap it was planned on.
    costmap_id: String,
    /// The route it was replanned from (it may have been deleted since);
    /// null for a route planned from scratch.
    parent_id: Option<String>,
    /// Creation time, RFC 3339 (UTC).
    created_at: String,
    /// The start as given (for a replan, its `position`).
    start: Position,
    /// The goal as given.
    goal: Position,
    options: SearchOptions,
    /// Ground speed of the rover mission, m/s.
    speed_m_s: Option<f64>,
    /// The search that planned it.
    planner: Planner,
    /// For a replan by D* Lite: true when the parent's search was still in
    /// memory and was repaired, false when it was rebuilt from the costmap.
    reused_search: bool,
    #[serde(flatten)]
    route: MapRoute,
    /// Only for a route planned coarse to fine (`planner` is
    /// `coarse_to_fine`): the proof of optimality, or the bound achieved.
    #[serde(skip_serializing_if = "Option::is_none")]
    search: Option<SearchReport>,
    /// The route as a GeoJSON LineString, `[lon, lat, height]` when every
    /// waypoint's terrain height is known, else `[lon, lat]`; the height is
    /// above the WGS 84 ellipsoid (RFC 7946): the DEM's height plus the
    /// EGM96 geoid undulation.
    #[schema(value_type = Object)]
    geometry: Value,
    /// Every area blocked so far (this replan's and its ancestors'), as
    /// GeoJSON Polygons.
    #[schema(value_type = Vec<Object>)]
    blocked: Vec<Value>,
    /// Every cost change so far, in the order applied.
    cost_changes: Vec<CostChange>,
    pub(super) urls: RouteUrls,
}

/// A page of routes, newest first.
#[derive(Serialize, ToSchema)]
pub struct RouteList {
    pub(super) items: Vec<RouteResponse>,
    /// Routes stored in all (on the costmap, when filtered).
    pub(super) total: i64,
    pub(super) limit: i64,
    pub(super) offset: i64,
}

crate::api::paging::listing!(RouteList, RouteResponse);

/// The listing's filter.
#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RouteFilter {
    /// Only the routes planned on this costmap.
    pub(super) costmap_id: Option<String>,
}

pub fn route_url(id: &str) -> String {
    format!("/api/v1/routes/{id}")
}

pub(super) fn to_json<T: Serialize>(value: &T) -> Result<String, ApiError> {
    serde_json::to_string(value).map_err(|e| ApiError::Internal(e.to_string()))
}

pub(super) fn stored<T: serde::de::DeserializeOwned>(
    id: &str,
    what: &str,
    json: &str,
) -> Result<T, ApiError> {
    serde_json::from_str(json)
        .map_err(|e| ApiError::Internal(format!("stored {what} of route {id} unreadable: {e}")))
}

/// The route as GeoJSON geometry.
fn geometry(route: &MapRoute) -> Value {
    route_feature(route, Map::new())["geometry"].take()
}

pub(super) fn response(row: &RouteRow) -> Result<RouteResponse, ApiError> {
    let id = &row.id;
    let request: StoredRequest = stored(id, "request", &row.request)?;
    let changes: Changes = stored(id, "changes", &row.changes)?;
    let result: StoredResult = stored(id, "result", &row.result)?;
    let base = route_url(id);
    Ok(RouteResponse {
        id: id.clone(),
        name: row.name.clone(),
        project_id: answered_project(&row.project_id),
        costmap_id: row.costmap_id.clone(),
        parent_id: row.parent_id.clone(),
        created_at: rfc3339(row.created_at),
        start: request.start,
        goal: request.goal,
        options: request.options,
        speed_m_s: request.speed_m_s,
        planner: result.planner,
        reused_search: result.reused_search,
        geometry: geometry(&result.route),
        route: result.route,
        search: result.search,
        blocked: changes.blocked,
        cost_changes: changes.cost_changes,
        urls: RouteUrls {
            costmap: costmap_url(&row.costmap_id),
            geojson: format!("{base}/route.geojson"),
            csv: format!("{base}/route.csv"),
            waypoints: format!("{base}/mission.waypoints"),
            replan: format!("{base}/replan"),
            parent: row.parent_id.as_deref().map(route_url),
            this: base,
        },
    })
}
