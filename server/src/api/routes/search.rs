//! The routes resource (SPEC §4.3): the cheapest safe route for a ground
//! vehicle across a finished costmap, incremental replanning when areas
//! become blocked or change cost, and the route as files (GeoJSON, CSV of
//! UTM waypoints, an ArduPilot Rover mission).
//!
//! Searches run off the async runtime on a planner thread
//! ([`AppState::run_planner`]) and stop when the client goes away (a drop
//! guard sets their cancel flag) or after `--route-timeout-s` (503);
//! `max_expansions` (4 per costmap cell) bounds them besides.
//!
//! A new route is planned with A*. With `epsilon` = 1 (the default) a
//! D* Lite search for it is then built in the background (its first
//! search runs backwards from the goal and costs several times A*'s) and
//! kept in memory ([`crate::app::SearchCache`]), so that a replan from it
//! repairs that search instead of starting over; a replan arriving while
//! it is being built waits for it, and a replan whose parent's search is
//! no longer held (evicted, or the server restarted) rebuilds it from the
//! costmap with every change made so far. With `epsilon` > 1 routes and
//! their replans are planned from scratch with weighted A*.
//!
//! Changes of the costmap are cumulative over a chain of replans: blocked
//! areas make their cells obstacles, cost changes set their cells' cost.
//! A cost change never makes an obstacle (of the costmap or a blocked
//! area) traversable; among cost changes the later wins.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use geo::{CoordsIter, Orient, orient::Direction};
use geo_types::{LineString, Polygon};
use planner_core::cancel::{CancelToken, Cancelled};
use planner_core::export::ground_route::{route_csv, route_feature, route_geojson, rover_mission};
use planner_core::export::write_waypoints;
use planner_core::geo::{Issue, Limits, MAX_ISSUES, parse_polygons, polygon_issues};
use planner_core::route::{
    ArcCost, Cell, CostGrid, DStarLite, Endpoint, MapRoute, MapRouteError, Position, RouteError,
    RouteMap, RouteOptions, astar,
};
use planner_core::terrain::{Dem, DemLimits};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value, json};
use utoipa::{IntoParams, ToSchema};

use super::costmaps::{costmap_url, deserialize_at};
use super::json_body::JsonBody;
use super::paging::{ListQuery, page};
use super::{rfc3339, short_id};
use crate::app::{AppState, Work, off_runtime};
use crate::costmap_jobs::{COSTMAP_TIF, JobStatus, now_millis};
use crate::db::{CostmapRow, RouteRow};
use crate::error::{ApiError, Problem};

const NAME_MAX_CHARS: usize = 200;
/// Fields of `POST /api/v1/costmaps/{id}/routes`.
const CREATE_FIELDS: [&str; 7] = [
    "name",
    "start",
    "goal",
    "arc_cost",
    "epsilon",
    "smooth",
    "speed_m_s",
];
/// Fields of `POST /api/v1/routes/{id}/replan`.
const REPLAN_FIELDS: [&str; 4] = ["name", "position", "blocked", "cost_changes"];
/// Accepted ground speed, m/s: (0, SPEED_MAX].
const SPEED_MAX: f64 = 50.0;
/// Accepted cost of a cost change: (0, COST_MAX].
const COST_MAX: f64 = 1e6;
/// Cells a search may expand per cell of the costmap: A* expands a cell
/// once, D* Lite at most twice per plan; beyond that something is wrong.
const EXPANSIONS_PER_CELL: u64 = 4;
const POSITION_FORMS: &str =
    "[lon, lat] (WGS84 degrees) or {\"utm\": [easting, northing]} (metres in the route's UTM zone)";

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
}

/// How a route is searched (a replan keeps its parent's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct SearchOptions {
    /// Arc cost rule.
    arc_cost: ArcCost,
    /// Heuristic weight in [1, 10]: the route costs at most `epsilon` ×
    /// the optimum.
    epsilon: f64,
    /// Whether the waypoints are smoothed (shortcuts taken only where
    /// they cost no more), or are the turning points of the cell path.
    smooth: bool,
}

impl SearchOptions {
    /// The planner's options for a costmap of `cells` cells.
    fn route_options(&self, cells: usize) -> RouteOptions {
        RouteOptions {
            arc_cost: self.arc_cost,
            epsilon: self.epsilon,
            smooth: self.smooth,
            max_expansions: Some((cells as u64).saturating_mul(EXPANSIONS_PER_CELL).max(1)),
        }
    }

    fn planner(&self) -> Planner {
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
    area: Value,
    /// The new cost of its traversable cells, in (0, 1e6] (costmaps use
    /// [1, 20]).
    #[schema(exclusive_minimum = 0, maximum = 1000000)]
    cost: f64,
}

/// What a route was asked for, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct StoredRequest {
    start: Position,
    goal: Position,
    options: SearchOptions,
    speed_m_s: Option<f64>,
}

/// Every change of the costmap made so far along a chain of replans,
/// stored as JSON: GeoJSON Polygons (CCW exteriors).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct Changes {
    blocked: Vec<Value>,
    cost_changes: Vec<CostChange>,
}

/// The planned route, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct StoredResult {
    planner: Planner,
    reused_search: bool,
    #[serde(flatten)]
    route: MapRoute,
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
    this: String,
    /// The costmap it was planned on.
    costmap: String,
    /// The route as a GeoJSON FeatureCollection of one Feature (a
    /// LineString at heights above the WGS 84 ellipsoid).
    geojson: String,
    /// The waypoints as CSV: `index,easting,northing,zone,height`.
    csv: String,
    /// An ArduPilot Rover mission (QGC WPL 110).
    waypoints: String,
    /// POST here to replan from this route.
    replan: String,
    /// The route it was replanned from.
    parent: Option<String>,
}

/// A planned route.
#[derive(Serialize, ToSchema)]
pub struct RouteResponse {
    id: String,
    name: Option<String>,
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
    urls: RouteUrls,
}

/// A page of routes, newest first.
#[derive(Serialize, ToSchema)]
pub struct RouteList {
    items: Vec<RouteResponse>,
    /// Routes stored in all (on the costmap, when filtered).
    total: i64,
    limit: i64,
    offset: i64,
}

/// The listing's filter.
#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct RouteFilter {
    /// Only the routes planned on this costmap.
    costmap_id: Option<String>,
}

pub fn route_url(id: &str) -> String {
    format!("/api/v1/routes/{id}")
}

fn not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("there is no route with id {id:?}"))
}

fn costmap_not_found(id: &str) -> ApiError {
    ApiError::NotFound(format!("there is no costmap with id {id:?}"))
}

fn to_json<T: Serialize>(value: &T) -> Result<String, ApiError> {
    serde_json::to_string(value).map_err(|e| ApiError::Internal(e.to_string()))
}

fn stored<T: serde::de::DeserializeOwned>(id: &str, what: &str, json: &str) -> Result<T, ApiError> {
    serde_json::from_str(json)
        .map_err(|e| ApiError::Internal(format!("stored {what} of route {id} unreadable: {e}")))
}

fn escape_pointer(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

// ------------------------------------------------------------- requests

fn unknown_fields(
    obj: &Map<String, Value>,
    allowed: &[&str],
    expected: &str,
    issues: &mut Vec<Issue>,
) {
    for key in obj.keys().filter(|k| !allowed.contains(&k.as_str())) {
        issues.push(Issue::new(
            &format!("/{}", escape_pointer(key)),
            &format!("unknown field {key:?}: expected {expected}"),
        ));
    }
}

fn parse_name(obj: &Map<String, Value>, issues: &mut Vec<Issue>) -> Option<String> {
    match obj.get("name") {
        None | Some(Value::Null) => None,
        Some(Value::String(s))
            if let Some(issue) =
                crate::api::names::control_character_issue("/name", "the name", s) =>
        {
            issues.push(issue);
            None
        }
        Some(Value::String(s)) if s.chars().count() <= NAME_MAX_CHARS => Some(s.clone()),
        Some(Value::String(_)) => {
            issues.push(Issue::new(
                "/name",
                &format!("the name is longer than {NAME_MAX_CHARS} characters"),
            ));
            None
        }
        Some(_) => {
            issues.push(Issue::new("/name", "the name must be a string"));
            None
        }
    }
}

/// An optional number; a fault when it is there but not a number.
fn parse_number(obj: &Map<String, Value>, key: &str, issues: &mut Vec<Issue>) -> Option<f64> {
    match obj.get(key) {
        None | Some(Value::Null) => None,
        Some(v) => v.as_f64().or_else(|| {
            issues.push(Issue::new(
                &format!("/{key}"),
                &format!("{key} must be a number"),
            ));
            None
        }),
    }
}

/// Two numbers.
fn pair(v: &Value) -> Option<[f64; 2]> {
    match v.as_array()?.as_slice() {
        [a, b] => Some([a.as_f64()?, b.as_f64()?]),
        _ => None,
    }
}

fn parse_position(
    value: Option<&Value>,
    pointer: &str,
    issues: &mut Vec<Issue>,
) -> Option<Position> {
    let mut fault = |p: &str, m: &str| {
        issues.push(Issue::new(p, m));
        None
    };
    match value {
        None | Some(Value::Null) => fault(pointer, &format!("required: {POSITION_FORMS}")),
        Some(v @ Value::Array(_)) => match pair(v) {
            Some([lon, lat])
                if (-180.0..=180.0).contains(&lon) && (-90.0..=90.0).contains(&lat) =>
            {
                Some(Position::LonLat([lon, lat]))
            }
            Some([lon, lat]) => fault(
                pointer,
                &format!(
                    "[{}, {}] is not a WGS84 position: lon must be in [-180, 180] and lat in \
                     [-90, 90] degrees",
                    planner_core::num::readable(lon),
                    planner_core::num::readable(lat)
                ),
            ),
            None => fault(pointer, &format!("must be {POSITION_FORMS}: two numbers")),
        },
        Some(Value::Object(o)) => {
            if let Some(key) = o.keys().find(|k| *k != "utm") {
                return fault(
                    &format!("{pointer}/{}", escape_pointer(key)),
                    &format!(
                        "unknown field {key:?}: a UTM position is {{\"utm\": [easting, northing]}}"
                    ),
                );
            }
            match o.get("utm").map(pair) {
                Some(Some(en)) => Some(Position::Utm { utm: en }),
                Some(None) => fault(
                    &format!("{pointer}/utm"),
                    "must be [easting, northing]: two numbers of metres",
                ),
                None => fault(pointer, &format!("must be {POSITION_FORMS}")),
            }
        }
        Some(_) => fault(pointer, &format!("must be {POSITION_FORMS}")),
    }
}

/// A checked `POST /api/v1/costmaps/{id}/routes` body.
struct CreateRequest {
    name: Option<String>,
    start: Position,
    goal: Position,
    options: SearchOptions,
    speed_m_s: Option<f64>,
}

fn parse_create(doc: &Value) -> Result<CreateRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with start and goal (and optionally \
             arc_cost, epsilon, smooth, speed_m_s, name)",
        )]));
    };
    let mut issues = Vec::new();
    unknown_fields(
        obj,
        &CREATE_FIELDS,
        "start, goal, arc_cost, epsilon, smooth, speed_m_s or name",
        &mut issues,
    );
    let name = parse_name(obj, &mut issues);
    let start = parse_position(obj.get("start"), "/start", &mut issues);
    let goal = parse_position(obj.get("goal"), "/goal", &mut issues);
    let arc_cost = match obj.get("arc_cost") {
        None | Some(Value::Null) => ArcCost::default(),
        Some(v) => deserialize_at::<ArcCost>(v, "/arc_cost").unwrap_or_else(|i| {
            issues.push(i);
            ArcCost::default()
        }),
    };
    let epsilon = parse_number(obj, "epsilon", &mut issues).unwrap_or(1.0);
    let smooth = match obj.get("smooth") {
        None | Some(Value::Null) => true,
        Some(Value::Bool(b)) => *b,
        Some(_) => {
            issues.push(Issue::new("/smooth", "smooth must be true or false"));
            true
        }
    };
    let speed_m_s = parse_number(obj, "speed_m_s", &mut issues);
    if let Some(v) = speed_m_s
        && !(v > 0.0 && v <= SPEED_MAX)
    {
        issues.push(Issue::new(
            "/speed_m_s",
            &format!(
                "speed_m_s must be in (0, {SPEED_MAX}] m/s, got {}",
                planner_core::num::readable(v)
            ),
        ));
    }
    let options = SearchOptions {
        arc_cost,
        epsilon,
        smooth,
    };
    issues.extend(options.route_options(1).issues());
    match (start, goal) {
        (Some(start), Some(goal)) if issues.is_empty() => Ok(CreateRequest {
            name,
            start,
            goal,
            options,
            speed_m_s,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// One polygon of a request, with the pointer of the member it came from.
struct Area {
    polygon: Polygon<f64>,
    pointer: String,
}

/// The polygons of one GeoJSON area member, checked (shape, ranges,
/// self-intersection). Their vertices are added to `vertices`; once that
/// is over `max_vertices` they are no longer checked (the caller refuses
/// the request for the count).
fn parse_area(
    value: &Value,
    pointer: &str,
    issues: &mut Vec<Issue>,
    vertices: &mut usize,
    max_vertices: usize,
) -> Vec<Area> {
    match parse_polygons(value, pointer) {
        Ok(parsed) => {
            let mut out = Vec::new();
            for p in parsed {
                *vertices = vertices.saturating_add(p.polygon.coords_count());
                if *vertices > max_vertices {
                    continue;
                }
                let faults = polygon_issues(&p.polygon, &p.pointer);
                if faults.is_empty() {
                    out.push(Area {
                        polygon: p.polygon,
                        pointer: pointer.to_string(),
                    });
                } else {
                    issues.extend(faults);
                }
            }
            out
        }
        Err(faults) => {
            issues.extend(faults);
            Vec::new()
        }
    }
}

/// A checked `POST /api/v1/routes/{id}/replan` body.
struct ReplanRequest {
    name: Option<String>,
    position: Position,
    blocked: Vec<Area>,
    /// In order, each polygon with its cost.
    cost_changes: Vec<(Area, f64)>,
}

/// The areas and vertices of the changes a chain of replans made so far.
#[derive(Clone, Copy, Default)]
struct Earlier {
    areas: usize,
    vertices: usize,
}

/// A replan body, its areas counted against `limits` (with the chain's
/// `earlier` changes) before any of them is checked.
fn parse_replan(doc: &Value, limits: &Limits, earlier: Earlier) -> Result<ReplanRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with position (and optionally blocked, \
             cost_changes, name)",
        )]));
    };
    let mut issues = Vec::new();
    unknown_fields(
        obj,
        &REPLAN_FIELDS,
        "position, blocked, cost_changes or name",
        &mut issues,
    );
    let name = parse_name(obj, &mut issues);
    let position = parse_position(obj.get("position"), "/position", &mut issues);
    // The limits on geometry hold for the changes of a whole chain, and
    // apply before any area is read.
    let count = |key: &str| obj.get(key).and_then(Value::as_array).map_or(0, Vec::len);
    let (new_blocked, new_changes) = (count("blocked"), count("cost_changes"));
    let pointer = if new_blocked == 0 {
        "/cost_changes"
    } else {
        "/blocked"
    };
    let areas = earlier.areas + new_blocked + new_changes;
    if areas > limits.max_no_fly_zones {
        return Err(ApiError::Validation(vec![Issue::new(
            pointer,
            &format!(
                "{areas} areas (blocked and cost changes, with those of the earlier replans) \
                 exceed the limit of {}",
                limits.max_no_fly_zones
            ),
        )]));
    }
    let mut vertices = earlier.vertices;
    let max_vertices = limits.max_vertices;
    let mut blocked = Vec::new();
    match obj.get("blocked") {
        None | Some(Value::Null) => {}
        Some(Value::Array(areas)) => {
            for (i, v) in areas.iter().enumerate() {
                if issues.len() > MAX_ISSUES {
                    break;
                }
                blocked.extend(parse_area(
                    v,
                    &format!("/blocked/{i}"),
                    &mut issues,
                    &mut vertices,
                    max_vertices,
                ));
            }
        }
        Some(_) => issues.push(Issue::new(
            "/blocked",
            "must be an array of GeoJSON Polygons (or Features of them)",
        )),
    }
    let mut cost_changes = Vec::new();
    match obj.get("cost_changes") {
        None | Some(Value::Null) => {}
        Some(Value::Array(changes)) => {
            for (i, v) in changes.iter().enumerate() {
                if issues.len() > MAX_ISSUES {
                    break;
                }
                let pointer = format!("/cost_changes/{i}");
                let Some(change) = v.as_object() else {
                    issues.push(Issue::new(
                        &pointer,
                        "must be an object {\"area\": GeoJSON Polygon, \"cost\": number}",
                    ));
                    continue;
                };
                for key in change
                    .keys()
                    .filter(|k| !["area", "cost"].contains(&k.as_str()))
                {
                    issues.push(Issue::new(
                        &format!("{pointer}/{}", escape_pointer(key)),
                        &format!("unknown field {key:?}: expected area or cost"),
                    ));
                }
                let areas = match change.get("area") {
                    None | Some(Value::Null) => {
                        issues.push(Issue::new(
                            &format!("{pointer}/area"),
                            "required: a GeoJSON Polygon",
                        ));
                        Vec::new()
                    }
                    Some(a) => parse_area(
                        a,
                        &format!("{pointer}/area"),
                        &mut issues,
                        &mut vertices,
                        max_vertices,
                    ),
                };
                let cost = match change.get("cost").and_then(Value::as_f64) {
                    Some(c) if c > 0.0 && c <= COST_MAX => Some(c),
                    Some(c) => {
                        issues.push(Issue::new(
                            &format!("{pointer}/cost"),
                            &format!(
                                "the cost must be a number in (0, {COST_MAX}], got {} (block \
                                 an area with `blocked`)",
                                planner_core::num::readable(c)
                            ),
                        ));
                        None
                    }
                    None => {
                        issues.push(Issue::new(
                            &format!("{pointer}/cost"),
                            &format!("required: a number in (0, {COST_MAX}]"),
                        ));
                        None
                    }
                };
                if let Some(cost) = cost {
                    cost_changes.extend(areas.into_iter().map(|a| (a, cost)));
                }
            }
        }
        Some(_) => issues.push(Issue::new(
            "/cost_changes",
            "must be an array of {\"area\": GeoJSON Polygon, \"cost\": number}",
        )),
    }
    if vertices > max_vertices {
        return Err(ApiError::Validation(vec![Issue::new(
            pointer,
            &format!(
                "{vertices} vertices in the areas (with those of the earlier replans) exceed the \
                 limit of {max_vertices}"
            ),
        )]));
    }
    match position {
        Some(position) if issues.is_empty() => Ok(ReplanRequest {
            name,
            position,
            blocked,
            cost_changes,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// A polygon as GeoJSON, CCW exterior and CW holes (SPEC §2).
fn polygon_geojson(p: &Polygon<f64>) -> Value {
    let p = p.orient(Direction::Default);
    let ring =
        |r: &LineString<f64>| -> Vec<Value> { r.0.iter().map(|c| json!([c.x, c.y])).collect() };
    let mut rings = vec![ring(p.exterior())];
    rings.extend(p.interiors().iter().map(ring));
    json!({"type": "Polygon", "coordinates": rings})
}

/// A stored polygon read back.
fn stored_polygon(v: &Value) -> Result<Polygon<f64>, ApiError> {
    match parse_polygons(v, "").as_deref() {
        Ok([p]) => Ok(p.polygon.clone()),
        _ => Err(ApiError::Internal(format!(
            "a stored area is not one polygon: {v}"
        ))),
    }
}

// ------------------------------------------------------------- searches

/// What a search needs from storage, gathered on the async side.
struct MapSource {
    costmap_id: String,
    tif: Vec<u8>,
    dem: Option<Arc<Dem>>,
    /// Room in the memory budget for the search (and a D* Lite search
    /// built after it), held as long as the source.
    _room: crate::memory::Reservation,
}

/// The costmap's GeoTIFF and its DEM (for heights; `None` when the DEM
/// has been deleted), once there is room in the memory budget for a
/// search on it (a 422 when it alone needs more than the budget).
async fn map_source(state: &AppState, costmap: &CostmapRow) -> Result<MapSource, ApiError> {
    #[derive(Deserialize)]
    struct Size {
        width: u64,
        height: u64,
    }
    let meta = state
        .db
        .costmap_file_meta(&costmap.id, COSTMAP_TIF)
        .await?
        .ok_or_else(|| costmap_not_found(&costmap.id))?;
    let size: Size = stored(
        &costmap.id,
        "result",
        costmap.result.as_deref().unwrap_or(""),
    )?;
    let need = crate::memory::route_search_bytes(
        size.width.saturating_mul(size.height),
        u64::try_from(meta.size_bytes).unwrap_or(0),
    );
    let what = format!(
        "a route search (costmap {}, {} × {} cells)",
        costmap.id, size.width, size.height
    );
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
        .ok_or_else(|| costmap_not_found(&costmap.id))?;
    Ok(MapSource {
        costmap_id: costmap.id.clone(),
        tif: file.data,
        dem,
        _room: room,
    })
}

/// The route map (on a planner thread: it holds PROJ objects, which
/// stay on the thread that made them).
fn build_map(src: &MapSource) -> Result<RouteMap, ApiError> {
    // Written by this server: the limits of the day need not hold again.
    let limits = DemLimits {
        max_pixels: u64::MAX,
        max_side: u32::MAX,
    };
    let built = match RouteMap::from_costmap_geotiff(&src.tif, src.dem.as_deref(), &limits) {
        Err(MapRouteError::DemMismatch(why)) => {
            tracing::warn!(costmap = %src.costmap_id, %why, "the DEM does not fit the costmap: planning without heights");
            RouteMap::from_costmap_geotiff(&src.tif, None, &limits)
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
        MapRouteError::Search(RouteError::InvalidOptions(issues)) => ApiError::Validation(issues),
        MapRouteError::Search(
            RouteError::StartBlocked { .. } | RouteError::StartOutside { .. },
        ) => at(ends.pointer(Endpoint::Start), &e.to_string()),
        MapRouteError::Search(RouteError::GoalBlocked { .. } | RouteError::GoalOutside { .. }) => {
            at(ends.pointer(Endpoint::Goal), &e.to_string())
        }
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
struct Planned {
    route: MapRoute,
    planner: Planner,
    reused_search: bool,
    search: Option<DStarLite>,
    /// A new route's start and goal cells, when a D* Lite search is to be
    /// built for its replans.
    warm: Option<(Cell, Cell)>,
}

/// A new route, on a planner thread.
fn plan_route(
    src: &MapSource,
    start: &Position,
    goal: &Position,
    options: &SearchOptions,
    stop: &CancelToken,
) -> Result<Planned, ApiError> {
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
    // A* answers at once; D* Lite's first search runs backwards from the
    // goal and costs several times as much (about 10× on a 4000² terrain
    // costmap), so it is built afterwards, in the background.
    let began = Instant::now();
    let route = astar(map.grid(), s, g, &opts, &check).map_err(fault)?;
    let ms = began.elapsed().as_secs_f64() * 1e3;
    let route = map
        .describe(&route, ms)
        .map_err(|e| ApiError::Internal(format!("describing a route: {e}")))?;
    Ok(Planned {
        route,
        planner: Planner::Astar,
        reused_search: false,
        search: None,
        warm: (options.planner() == Planner::DstarLite).then_some((s, g)),
    })
}

/// The D* Lite search of a new route, for its replans (on a planner
/// thread, in the background).
fn warm_search(
    src: &MapSource,
    (start, goal): (Cell, Cell),
    options: &SearchOptions,
    stop: &CancelToken,
) -> Result<DStarLite, String> {
    let map = build_map(src).map_err(|e| e.to_string())?;
    let opts = options.route_options(map.grid().cell_count());
    let mut search =
        DStarLite::new(map.grid().clone(), start, goal, opts).map_err(|e| e.to_string())?;
    search
        .plan(&|| stop.is_cancelled())
        .map_err(|e| e.to_string())?;
    Ok(search)
}

/// The cells of `areas` (their union), a fault named at the area's pointer.
fn area_cells(
    map: &RouteMap,
    areas: &[&Area],
    issues: &mut Vec<Issue>,
) -> Result<Vec<usize>, ApiError> {
    let polygons: Vec<Polygon<f64>> = areas.iter().map(|a| a.polygon.clone()).collect();
    match map.cells_in_areas(&polygons) {
        Ok(cells) => Ok(cells),
        Err(MapRouteError::InvalidArea { index, reason }) => {
            issues.push(Issue::new(&areas[index].pointer, &reason));
            Ok(Vec::new())
        }
        Err(e) => Err(ApiError::Internal(format!("cells of an area: {e}"))),
    }
}

/// Cells to change, rasterised: cost changes in runs of equal cost (one
/// pass over the grid per run), then the blocked cells.
struct CellChanges {
    costs: Vec<(Vec<usize>, f32)>,
    blocked: Vec<usize>,
}

impl CellChanges {
    fn of(
        map: &RouteMap,
        cost_areas: &[(&Area, f64)],
        blocked: &[&Area],
        issues: &mut Vec<Issue>,
    ) -> Result<CellChanges, ApiError> {
        let mut costs = Vec::new();
        for run in cost_areas.chunk_by(|a, b| a.1 == b.1) {
            let areas: Vec<&Area> = run.iter().map(|(a, _)| *a).collect();
            costs.push((area_cells(map, &areas, issues)?, run[0].1 as f32));
        }
        let blocked = if blocked.is_empty() {
            Vec::new()
        } else {
            area_cells(map, blocked, issues)?
        };
        Ok(CellChanges { costs, blocked })
    }

    /// The new value of every cell these change on a grid of `costs`: a
    /// cost change sets traversable cells (the later wins), blocking makes
    /// them obstacles; obstacles stay as they are.
    fn on(&self, costs: &[f32]) -> BTreeMap<usize, f32> {
        let mut out = BTreeMap::new();
        for (cells, cost) in &self.costs {
            for &i in cells {
                if costs[i].is_finite() {
                    out.insert(i, *cost);
                }
            }
        }
        for &i in &self.blocked {
            if costs[i].is_finite() {
                out.insert(i, f32::NAN);
            }
        }
        out
    }
}

/// Stored changes, read back: the cost changes in order, and the blocked
/// areas (their pointers are not used: they were checked when made).
struct StoredAreas {
    costs: Vec<(Area, f64)>,
    blocked: Vec<Area>,
}

fn stored_areas(changes: &Changes) -> Result<StoredAreas, ApiError> {
    let area = |v: &Value| -> Result<Area, ApiError> {
        Ok(Area {
            polygon: stored_polygon(v)?,
            pointer: String::new(),
        })
    };
    let costs = changes
        .cost_changes
        .iter()
        .map(|c| Ok((area(&c.area)?, c.cost)))
        .collect::<Result<Vec<_>, ApiError>>()?;
    let blocked = changes.blocked.iter().map(area).collect::<Result<_, _>>()?;
    Ok(StoredAreas { costs, blocked })
}

/// What a replan needs.
struct ReplanInput {
    src: MapSource,
    position: Position,
    goal: Position,
    options: SearchOptions,
    /// The parent's changes.
    previous: Changes,
    blocked: Vec<Area>,
    cost_changes: Vec<(Area, f64)>,
}

/// A replan that failed, and the parent's search to keep if there is one.
struct Failure {
    error: ApiError,
    kept: Option<Box<DStarLite>>,
}

fn failed(error: ApiError, kept: Option<DStarLite>) -> Failure {
    Failure {
        error,
        kept: kept.map(Box::new),
    }
}

/// A replan, on a planner thread, from the parent's search `cached` when
/// it is held (else rebuilt). On failure, the parent's search when there
/// is one to keep.
fn replan(
    input: &ReplanInput,
    cached: Option<DStarLite>,
    stop: &CancelToken,
) -> Result<Planned, Failure> {
    let map = match build_map(&input.src) {
        Ok(map) => map,
        Err(e) => return Err(failed(e, cached)),
    };
    let ends = Ends::Replan {
        blocking: !input.blocked.is_empty(),
    };
    let mut issues = Vec::new();
    let checked = (|| {
        let pos = locate(&map, &input.position, Endpoint::Start, ends, &mut issues)?;
        let goal = locate(&map, &input.goal, Endpoint::Goal, ends, &mut issues)?;
        let cost_areas: Vec<(&Area, f64)> =
            input.cost_changes.iter().map(|(a, c)| (a, *c)).collect();
        let blocked: Vec<&Area> = input.blocked.iter().collect();
        let changes = CellChanges::of(&map, &cost_areas, &blocked, &mut issues)?;
        Ok::<_, ApiError>((pos, goal, changes))
    })();
    let (pos, goal, changes) = match checked {
        Ok((Some(pos), Some(goal), changes)) if issues.is_empty() => (pos, goal, changes),
        Ok(_) => return Err(failed(ApiError::Validation(issues), cached)),
        Err(e) => return Err(failed(e, cached)),
    };
    let grid = map.grid();
    let width = grid.width();
    let opts = input.options.route_options(grid.cell_count());
    // The costmap with the parent's changes, for a search from scratch.
    let previous_costs = || -> Result<Vec<f32>, ApiError> {
        let mut costs = grid.costs().to_vec();
        let stored = stored_areas(&input.previous)?;
        let cost_areas: Vec<(&Area, f64)> = stored.costs.iter().map(|(a, c)| (a, *c)).collect();
        let blocked: Vec<&Area> = stored.blocked.iter().collect();
        let mut faults = Vec::new();
        let previous = CellChanges::of(&map, &cost_areas, &blocked, &mut faults)?;
        if !faults.is_empty() {
            return Err(ApiError::Internal(format!(
                "stored areas no longer fit the costmap: {faults:?}"
            )));
        }
        for (i, c) in previous.on(&costs) {
            costs[i] = c;
        }
        Ok(costs)
    };
    let new_grid = |costs: Vec<f32>| {
        CostGrid::new(
            width,
            grid.height(),
            costs,
            grid.dx_per_row().to_vec(),
            grid.dy(),
        )
        .map_err(|e| ApiError::Internal(format!("changed cost grid: {e}")))
    };
    // Neither end may end up blocked.
    let ends_free = |costs: &[f32], changed: &BTreeMap<usize, f32>| -> Result<(), ApiError> {
        let after = |i: usize| changed.get(&i).copied().unwrap_or(costs[i]);
        let (p, g) = (pos.0 * width + pos.1, goal.0 * width + goal.1);
        if !after(p).is_finite() {
            let message = if costs[p].is_finite() {
                "the position is inside an area this replan blocks"
            } else {
                "the position is inside an area an earlier replan blocked"
            };
            return Err(ApiError::Validation(vec![Issue::new("/position", message)]));
        }
        if !after(g).is_finite() {
            // Only this replan's areas can reach the goal: name the first.
            let mut faults = Vec::new();
            let culprit = input.blocked.iter().find(|a| {
                area_cells(&map, &[a], &mut faults).is_ok_and(|c| c.binary_search(&g).is_ok())
            });
            let pointer = culprit.map_or("/blocked", |a| a.pointer.as_str());
            return Err(ApiError::Validation(vec![Issue::new(
                pointer,
                "this area covers the route's goal: a replan keeps the goal, which cannot be blocked",
            )]));
        }
        Ok(())
    };
    let check = || stop.is_cancelled();
    let fault = |e: RouteError| search_fault(from_search(e), ends, stop);
    let describe = |route, began: Instant| {
        map.describe(&route, began.elapsed().as_secs_f64() * 1e3)
            .map_err(|e| ApiError::Internal(format!("describing a route: {e}")))
    };
    match input.options.planner() {
        Planner::DstarLite => {
            let (mut search, reused) = match cached {
                Some(s) if s.goal() == goal && s.grid().cell_count() == grid.cell_count() => {
                    (s, true)
                }
                _ => {
                    let rebuilt = previous_costs()
                        .and_then(new_grid)
                        .and_then(|g| DStarLite::new(g, pos, goal, opts).map_err(fault));
                    match rebuilt {
                        Ok(s) => (s, false),
                        Err(e) => return Err(failed(e, None)),
                    }
                }
            };
            let changed = changes.on(search.grid().costs());
            if let Err(e) = ends_free(search.grid().costs(), &changed) {
                // A search rebuilt just now has not searched yet: nothing
                // worth keeping.
                return Err(failed(e, reused.then_some(search)));
            }
            let costs = search.grid().costs();
            let undo: Vec<(usize, f32)> = changed.keys().map(|&i| (i, costs[i])).collect();
            let changed: Vec<(usize, f32)> = changed.into_iter().collect();
            let began = Instant::now();
            let planned = search
                .update_cells(&changed)
                .and_then(|()| search.move_start(pos))
                .and_then(|()| search.plan(&check));
            let route = match planned {
                Ok(route) => route,
                // Unreachable, cancelled, over its limit: with this
                // replan's changes undone the search is the parent's
                // again (D* Lite repairs it on its next plan), kept.
                Err(e) => {
                    let kept = search.update_cells(&undo).is_ok().then_some(search);
                    return Err(failed(fault(e), kept));
                }
            };
            Ok(Planned {
                route: describe(route, began).map_err(|e| failed(e, None))?,
                planner: Planner::DstarLite,
                reused_search: reused,
                search: Some(search),
                warm: None,
            })
        }
        Planner::Astar => {
            let attempt = || -> Result<Planned, ApiError> {
                let mut costs = previous_costs()?;
                let changed = changes.on(&costs);
                ends_free(&costs, &changed)?;
                for (i, c) in changed {
                    costs[i] = c;
                }
                let changed_grid = new_grid(costs)?;
                let began = Instant::now();
                let route = astar(&changed_grid, pos, goal, &opts, &check).map_err(fault)?;
                Ok(Planned {
                    route: describe(route, began)?,
                    planner: Planner::Astar,
                    reused_search: false,
                    search: None,
                    warm: None,
                })
            };
            attempt().map_err(|e| failed(e, None))
        }
    }
}

// ------------------------------------------------------------- resources

/// 409 unless the costmap is done.
fn ready(state: &AppState, row: &CostmapRow) -> Result<(), ApiError> {
    let status = JobStatus::parse(&row.status).ok_or_else(|| {
        ApiError::Internal(format!("costmap {} has status {:?}", row.id, row.status))
    })?;
    let id = &row.id;
    Err(ApiError::Conflict(match status {
        JobStatus::Done => return Ok(()),
        JobStatus::Queued => {
            format!("costmap {id} is queued: routes can be planned on it once its status is done")
        }
        JobStatus::Running => {
            let progress = state.costmaps.live(id).map_or(row.progress, |l| l.progress);
            format!(
                "costmap {id} is still running ({:.0} %): routes can be planned on it once its \
                 status is done",
                progress * 100.0
            )
        }
        JobStatus::Failed => format!(
            "costmap {id} failed, so no route can be planned on it: {}",
            row.error.as_deref().unwrap_or("no reason recorded")
        ),
    }))
}

/// The route as GeoJSON geometry.
fn geometry(route: &MapRoute) -> Value {
    route_feature(route, Map::new())["geometry"].take()
}

fn response(row: &RouteRow) -> Result<RouteResponse, ApiError> {
    let id = &row.id;
    let request: StoredRequest = stored(id, "request", &row.request)?;
    let changes: Changes = stored(id, "changes", &row.changes)?;
    let result: StoredResult = stored(id, "result", &row.result)?;
    let base = route_url(id);
    Ok(RouteResponse {
        id: id.clone(),
        name: row.name.clone(),
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

/// Store a new route; 404 when its costmap was deleted meanwhile.
async fn insert(state: &AppState, row: &RouteRow) -> Result<(), ApiError> {
    match state.db.insert_route(row).await {
        Ok(()) => Ok(()),
        Err(e) => match state.db.get_costmap(&row.costmap_id).await {
            Ok(None) => Err(ApiError::NotFound(format!(
                "costmap {} was deleted while the route was planned",
                row.costmap_id
            ))),
            _ => Err(e.into()),
        },
    }
}

fn created(row: &RouteRow) -> Result<Response, ApiError> {
    let body = response(row)?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&body.urls.this) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::CREATED, headers, Json(body)).into_response())
}

/// Plan a route across a finished costmap: the cheapest 8-connected path
/// (no corner cutting past obstacles) from `start` to `goal`, smoothed,
/// with its waypoints in WGS84 and UTM, heights (from the costmap's DEM;
/// null once that DEM is deleted), 2D and 3D length, cost, and the
/// terrain's slope along it. Searches are bounded and cancellable: one
/// running longer than the server's limit is stopped (503).
#[utoipa::path(
    post,
    path = "/api/v1/costmaps/{id}/routes",
    tag = "routes",
    params(("id" = String, Path, description = "Costmap id")),
    request_body(content = CreateRoute, content_type = "application/json"),
    responses(
        (status = 201, description = "Planned", body = RouteResponse,
            headers(("Location" = String, description = "URL of the new route"))),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such costmap", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The costmap is not done (queued, running or failed)", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request: `errors` names each fault by JSON pointer (`/start` or `/goal` outside the costmap or on an obstacle, `/goal` unreachable from the start, options out of range; or, with the pointer \"\", a search needing more than the server's memory budget)", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "No planner thread became free in time, or the search took longer than the server's limit; retry (see Retry-After)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_route(
    State(state): State<AppState>,
    Path(costmap_id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    let costmap = state
        .db
        .get_costmap(&costmap_id)
        .await?
        .ok_or_else(|| costmap_not_found(&costmap_id))?;
    ready(&state, &costmap)?;
    let req = parse_create(&doc)?;
    let src = Arc::new(map_source(&state, &costmap).await?);
    let (start, goal, options) = (req.start, req.goal, req.options.clone());
    let source = src.clone();
    // Stopped when the client goes away or after --route-timeout-s.
    let planned = state
        .run_planner(Work::Route, move |stop| {
            plan_route(&source, &start, &goal, &options, stop)
        })
        .await??;
    let stored_request = StoredRequest {
        start: req.start,
        goal: req.goal,
        options: req.options.clone(),
        speed_m_s: req.speed_m_s,
    };
    let row = RouteRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: req.name,
        costmap_id,
        parent_id: None,
        created_at: now_millis(),
        request: to_json(&stored_request)?,
        changes: to_json(&Changes::default())?,
        result: to_json(&StoredResult {
            planner: planned.planner,
            reused_search: planned.reused_search,
            route: planned.route,
        })?,
    };
    insert(&state, &row).await?;
    if let Some(ends) = planned.warm {
        let warming = state.routes.begin_warming(&row.id);
        let (held, id, options) = (state.clone(), row.id.clone(), req.options.clone());
        tokio::spawn(async move {
            let _warming = warming;
            // Not the client's: stopped only by --route-timeout-s.
            let built = held
                .run_planner(Work::Route, move |stop| {
                    warm_search(&src, ends, &options, stop)
                })
                .await;
            match built {
                Ok(Ok(search)) => held.routes.searches.put(&id, search),
                Ok(Err(e)) => tracing::warn!(route = %id, error = %e, "no D* Lite search kept"),
                Err(e) => tracing::warn!(route = %id, error = %e, "no D* Lite search kept"),
            }
        });
    }
    created(&row)
}

/// Replan from a route: the vehicle is at `position` and has found areas
/// blocked or costlier (or cheaper) than the costmap says. The new route
/// (its `parent_id` is this route's) goes from `position` to the same
/// goal with the same options, around every area blocked so far along
/// this chain of replans. With `epsilon` = 1 it is planned with D* Lite,
/// repairing this route's search when the server still holds it
/// (`reused_search`), at the same cost as a search from scratch.
#[utoipa::path(
    post,
    path = "/api/v1/routes/{id}/replan",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    request_body(content = ReplanRoute, content_type = "application/json"),
    responses(
        (status = 201, description = "Replanned: the new route", body = RouteResponse,
            headers(("Location" = String, description = "URL of the new route"))),
        (status = 400, description = "Malformed JSON", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request: `errors` names each fault by JSON pointer (`/position` outside the costmap or blocked, `/blocked/N` or `/cost_changes/N/area` not a valid polygon or covering the goal, `/cost_changes/N/cost` out of range, the goal cut off; or, with the pointer \"\", a search needing more than the server's memory budget)", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "No planner thread became free in time, or the search took longer than the server's limit; retry (see Retry-After)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn replan_route(
    State(state): State<AppState>,
    Path(id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    let parent = state
        .db
        .get_route(&id)
        .await?
        .ok_or_else(|| not_found(&id))?;
    let request: StoredRequest = stored(&id, "request", &parent.request)?;
    let previous: Changes = stored(&id, "changes", &parent.changes)?;
    let mut earlier = Earlier {
        areas: previous.blocked.len() + previous.cost_changes.len(),
        vertices: 0,
    };
    for v in previous
        .blocked
        .iter()
        .chain(previous.cost_changes.iter().map(|c| &c.area))
    {
        earlier.vertices += stored_polygon(v)?.coords_count();
    }
    // Checking the areas' polygons is work: off the runtime threads.
    let limits = state.limits.clone();
    let req = off_runtime(move || parse_replan(&doc, &limits, earlier)).await??;

    let costmap = state
        .db
        .get_costmap(&parent.costmap_id)
        .await?
        .ok_or_else(|| not_found(&id))?;
    let src = map_source(&state, &costmap).await?;
    let mut changes = previous.clone();
    changes
        .cost_changes
        .extend(req.cost_changes.iter().map(|(a, cost)| CostChange {
            area: polygon_geojson(&a.polygon),
            cost: *cost,
        }));
    changes
        .blocked
        .extend(req.blocked.iter().map(|a| polygon_geojson(&a.polygon)));

    let input = ReplanInput {
        src,
        position: req.position,
        goal: request.goal,
        options: request.options.clone(),
        previous,
        blocked: req.blocked,
        cost_changes: req.cost_changes,
    };
    // A search of the parent still being built is worth waiting for.
    state.routes.warmed(&id).await;
    let held = state.clone();
    let parent_id = id.clone();
    let planned = state
        .run_planner(Work::Route, move |stop| {
            let searches = &held.routes.searches;
            let cached = match input.options.planner() {
                Planner::DstarLite => searches.take(&parent_id),
                Planner::Astar => None,
            };
            tracing::debug!(route = %parent_id, held = cached.is_some(), "replanning");
            replan(&input, cached, stop).map_err(|failure| {
                if let Some(search) = failure.kept {
                    searches.put(&parent_id, *search);
                }
                failure.error
            })
        })
        .await??;

    let stored_request = StoredRequest {
        start: req.position,
        goal: request.goal,
        options: request.options,
        speed_m_s: request.speed_m_s,
    };
    let row = RouteRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: req.name.or(parent.name),
        costmap_id: parent.costmap_id,
        parent_id: Some(id),
        created_at: now_millis(),
        request: to_json(&stored_request)?,
        changes: to_json(&changes)?,
        result: to_json(&StoredResult {
            planner: planned.planner,
            reused_search: planned.reused_search,
            route: planned.route,
        })?,
    };
    insert(&state, &row).await?;
    if let Some(search) = planned.search {
        state.routes.searches.put(&row.id, search);
    }
    created(&row)
}

/// Routes, newest first, a page at a time; only those of one costmap with
/// `?costmap_id=`.
#[utoipa::path(
    get,
    path = "/api/v1/routes",
    tag = "routes",
    params(ListQuery, RouteFilter),
    responses(
        (status = 200, description = "A page of routes", body = RouteList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_routes(
    State(state): State<AppState>,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<RouteFilter>, QueryRejection>,
) -> Result<Json<RouteList>, ApiError> {
    let (limit, offset) = page(query)?;
    let Query(filter) =
        filter.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    if let Some(issue) = filter.costmap_id.as_deref().and_then(|id| {
        crate::api::names::control_character_issue("/costmap_id", "the costmap id", id)
    }) {
        return Err(ApiError::BadRequest(format!(
            "bad query string: {}",
            issue.message
        )));
    }
    let (rows, total) = state
        .db
        .list_routes(filter.costmap_id.as_deref(), limit, offset)
        .await?;
    let items = rows.iter().map(response).collect::<Result<Vec<_>, _>>()?;
    Ok(Json(RouteList {
        items,
        total,
        limit,
        offset,
    }))
}

/// A route.
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The route", body = RouteResponse),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get_route(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<RouteResponse>, ApiError> {
    let row = state
        .db
        .get_route(&id)
        .await?
        .ok_or_else(|| not_found(&id))?;
    Ok(Json(response(&row)?))
}

/// Delete a route (its replans stay, their `parent_id` naming it) and
/// the search the server holds for it.
#[utoipa::path(
    delete,
    path = "/api/v1/routes/{id}",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_route(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let deleted = state.db.delete_route(&id).await?;
    state.routes.searches.remove(&id);
    if deleted {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(not_found(&id))
    }
}

/// A file rendered from a stored route, as an attachment.
async fn route_file(
    state: &AppState,
    id: &str,
    extension: &str,
    content_type: &'static str,
    render: impl FnOnce(&RouteRow, &StoredRequest, &StoredResult) -> Result<String, ApiError>,
) -> Result<Response, ApiError> {
    let row = state.db.get_route(id).await?.ok_or_else(|| not_found(id))?;
    let request: StoredRequest = stored(id, "request", &row.request)?;
    let result: StoredResult = stored(id, "result", &row.result)?;
    let body = render(&row, &request, &result)?;
    let mut res = body.into_response();
    let headers = res.headers_mut();
    headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    let disposition = format!(
        "attachment; filename=\"terraplan-route-{}.{extension}\"",
        short_id(id)
    );
    if let Ok(v) = HeaderValue::from_str(&disposition) {
        headers.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(res)
}

/// The route as a GeoJSON FeatureCollection of one Feature: a LineString
/// through the waypoints (`[lon, lat, height above the WGS 84 ellipsoid]`
/// when every terrain height is known), with the route's figures, the
/// terrain heights and the EGM96 undulations as properties.
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/route.geojson",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The route, as an attachment", content_type = "application/geo+json", body = Object),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn route_geojson_file(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &id,
        "geojson",
        "application/geo+json",
        |row, _, result| {
            let mut properties = Map::new();
            properties.insert("id".into(), json!(row.id));
            properties.insert("name".into(), json!(row.name));
            properties.insert("costmap_id".into(), json!(row.costmap_id));
            properties.insert("parent_id".into(), json!(row.parent_id));
            properties.insert("planner".into(), json!(result.planner));
            to_json(&route_geojson(&result.route, properties))
        },
    )
    .await
}

/// The waypoints as CSV: `index,easting,northing,zone,height` (UTM metres
/// in the route's zone; height empty where unknown).
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/route.csv",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The waypoints, as an attachment", content_type = "text/csv", body = String),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn route_csv_file(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &id,
        "csv",
        "text/csv; charset=utf-8",
        |_, _, result| Ok(route_csv(&result.route)),
    )
    .await
}

/// An ArduPilot Rover mission (QGC WPL 110): home at the start, a
/// DO_CHANGE_SPEED when the route has a speed, then one NAV_WAYPOINT per
/// waypoint, the goal last.
#[utoipa::path(
    get,
    path = "/api/v1/routes/{id}/mission.waypoints",
    tag = "routes",
    params(("id" = String, Path, description = "Route id")),
    responses(
        (status = 200, description = "The mission, as an attachment", content_type = "text/plain", body = String),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn mission_waypoints(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    route_file(
        &state,
        &id,
        "waypoints",
        "text/plain; charset=utf-8",
        |_, request, result| {
            Ok(write_waypoints(&rover_mission(
                &result.route,
                request.speed_m_s,
            )))
        },
    )
    .await
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pointers<T>(r: Result<T, ApiError>) -> Vec<String> {
        match r {
            Err(ApiError::Validation(issues)) => issues.into_iter().map(|i| i.pointer).collect(),
            Err(e) => panic!("expected issues, got {e}"),
            Ok(_) => panic!("expected issues"),
        }
    }

    #[test]
    fn create_requests() {
        let r = parse_create(&json!({"start": [-75.0, 38.8], "goal": {"utm": [500000, 4300000]}}))
            .unwrap();
        assert_eq!(r.start, Position::LonLat([-75.0, 38.8]));
        assert_eq!(
            r.goal,
            Position::Utm {
                utm: [500_000.0, 4_300_000.0]
            }
        );
        assert_eq!(r.options.arc_cost, ArcCost::Integrated);
        assert_eq!(r.options.planner(), Planner::DstarLite);
        assert!(r.options.smooth);
        let r = parse_create(&json!({
            "start": [0, 0], "goal": [1, 1], "epsilon": 2, "arc_cost": {"mode": "thesis"},
            "smooth": false, "speed_m_s": 1.5, "name": "r"
        }))
        .unwrap();
        assert_eq!(r.options.planner(), Planner::Astar);
        assert_eq!(r.options.arc_cost, ArcCost::thesis());
        assert_eq!(r.speed_m_s, Some(1.5));
        assert_eq!(r.options.route_options(10).max_expansions, Some(40));
    }

    #[test]
    fn create_faults_are_named_by_pointer() {
        let p = pointers(parse_create(&json!({
            "start": [200, 0],
            "goal": {"utm": [1]},
            "epsilon": 0.5,
            "arc_cost": {"mode": "thesis", "d_max": 0},
            "smooth": 1,
            "speed_m_s": 0,
            "colour": "red",
        })));
        assert_eq!(
            p,
            [
                "/colour",
                "/start",
                "/goal/utm",
                "/smooth",
                "/speed_m_s",
                "/epsilon",
                "/arc_cost/d_max"
            ]
        );
        assert_eq!(pointers(parse_create(&json!({}))), ["/start", "/goal"]);
        assert_eq!(
            pointers(parse_create(
                &json!({"start": [0, 0], "goal": {"utm": [1, 2], "zone": 3}})
            )),
            ["/goal/zone"]
        );
        assert_eq!(
            pointers(parse_create(
                &json!({"start": [0, 0], "goal": [0, 0], "arc_cost": {"mode": "mcp"}})
            )),
            ["/arc_cost/mode"]
        );
        assert_eq!(pointers(parse_create(&json!([1]))), [""]);
    }

    fn square(x: f64, y: f64, d: f64) -> Value {
        json!({"type": "Polygon", "coordinates": [[[x, y], [x + d, y], [x + d, y + d], [x, y + d], [x, y]]]})
    }

    fn replan_of(doc: &Value) -> Result<ReplanRequest, ApiError> {
        parse_replan(doc, &Limits::default(), Earlier::default())
    }

    #[test]
    fn replan_limits_apply_before_any_area_is_checked() {
        let limits = Limits {
            max_no_fly_zones: 3,
            max_vertices: 12,
            ..Limits::default()
        };
        let bowtie =
            json!({"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]});
        let detail = |r: Result<ReplanRequest, ApiError>| match r {
            Err(ApiError::Validation(issues)) => issues
                .iter()
                .map(|i| format!("{}: {}", i.pointer, i.message))
                .collect::<Vec<_>>(),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("accepted"),
        };
        // Four areas, one of them with the earlier replans: one fault, the
        // count, and the bow tie is not looked at.
        let four = json!({"position": [0, 0], "blocked": [bowtie, square(0.0, 0.0, 1.0)], "cost_changes": [{"area": square(2.0, 0.0, 1.0), "cost": 2}]});
        let one = Earlier {
            areas: 1,
            vertices: 0,
        };
        assert_eq!(
            detail(parse_replan(&four, &limits, one)),
            [
                "/blocked: 4 areas (blocked and cost changes, with those of the earlier replans) exceed the limit of 3"
            ]
        );
        assert!(parse_replan(&four, &limits, Earlier::default()).is_err());
        // Vertices: 5 + 5 + 5 over 12 (3 earlier ones make it 18).
        let three = json!({"position": [0, 0], "blocked": [square(0.0, 0.0, 1.0), bowtie, square(2.0, 0.0, 1.0)]});
        let earlier = Earlier {
            areas: 0,
            vertices: 3,
        };
        assert_eq!(
            detail(parse_replan(&three, &limits, earlier)),
            [
                "/blocked: 18 vertices in the areas (with those of the earlier replans) exceed the limit of 12"
            ]
        );
        // Under both: the bow tie's fault, by pointer.
        let two = json!({"position": [0, 0], "cost_changes": [{"area": bowtie, "cost": 2}]});
        let faults = detail(parse_replan(&two, &limits, earlier));
        assert_eq!(faults.len(), 1, "{faults:?}");
        assert!(faults[0].starts_with("/cost_changes/0/area"), "{faults:?}");
    }

    #[test]
    fn replan_requests_and_faults() {
        let r = replan_of(&json!({
            "position": [0, 0],
            "blocked": [square(0.0, 0.0, 1.0), {"type": "Feature", "properties": {}, "geometry": square(2.0, 0.0, 1.0)}],
            "cost_changes": [{"area": square(5.0, 5.0, 1.0), "cost": 7}],
        }))
        .unwrap();
        assert_eq!(r.blocked.len(), 2);
        assert_eq!(r.blocked[1].pointer, "/blocked/1");
        assert_eq!(r.cost_changes.len(), 1);
        assert_eq!(r.cost_changes[0].1, 7.0);
        let bowtie =
            json!({"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1], [0, 0]]]});
        let p = pointers(replan_of(&json!({
            "blocked": [square(0.0, 0.0, 1.0), bowtie],
            "cost_changes": [{"area": square(0.0, 0.0, 1.0), "cost": 0}, {"cost": 2}, {"area": {"type": "Point", "coordinates": [0, 0]}, "cost": f64::MAX, "x": 1}],
            "extra": true,
        })));
        assert_eq!(p[0], "/extra");
        assert_eq!(p[1], "/position");
        assert!(p[2].starts_with("/blocked/1"), "{p:?}");
        let rest = &p[3..];
        for expected in [
            "/cost_changes/0/cost",
            "/cost_changes/1/area",
            "/cost_changes/2/x",
            "/cost_changes/2/area/type",
            "/cost_changes/2/cost",
        ] {
            assert!(
                rest.contains(&expected.to_string()),
                "{expected} not in {p:?}"
            );
        }
    }

    #[test]
    fn stored_polygons_round_trip_counter_clockwise() {
        // Given clockwise, stored counter-clockwise and closed.
        let cw = json!({"type": "Polygon", "coordinates": [[[0, 0], [0, 1], [1, 1], [1, 0]]]});
        let mut issues = Vec::new();
        let areas = parse_area(&cw, "/blocked/0", &mut issues, &mut 0, usize::MAX);
        assert!(issues.is_empty());
        let v = polygon_geojson(&areas[0].polygon);
        assert_eq!(
            v["coordinates"][0],
            json!([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.0, 0.0]])
        );
        assert_eq!(
            stored_polygon(&v).unwrap(),
            areas[0].polygon.orient(Direction::Default)
        );
    }

    #[test]
    fn cell_changes_keep_obstacles_and_let_blocking_win() {
        let changes = CellChanges {
            costs: vec![(vec![0, 1, 2], 5.0), (vec![1], 7.0)],
            blocked: vec![2, 3],
        };
        let costs = [1.0, 1.0, 1.0, 1.0, f32::NAN];
        let on = changes.on(&costs);
        assert_eq!(on.get(&0), Some(&5.0));
        assert_eq!(on.get(&1), Some(&7.0), "the later cost change wins");
        assert!(on[&2].is_nan() && on[&3].is_nan(), "blocking wins");
        assert!(!on.contains_key(&4), "obstacles stay");
    }
}
