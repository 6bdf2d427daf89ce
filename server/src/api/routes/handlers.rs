//! The route handlers: plan, replan, list, get and delete.

use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

use super::model::{
    Changes, CostChange, CreateRoute, Planner, ReplanRoute, RouteFilter, RouteList, RouteResponse,
    StoredRequest, StoredResult, response, stored, to_json,
};
use super::request::{Earlier, parse_create, parse_replan, polygon_geojson};
use super::search::{
    Planned, ReplanInput, map_source, not_in_memory, plan_route, replan, warm_search,
};
use crate::api::access::{ProjectFilter, list_visible, visible};
use crate::api::costmaps::visible_costmap;
use crate::api::json_body::JsonBody;
use crate::api::paging::{ListQuery, page};
use crate::auth::{Caller, Role};
use crate::clock::now_millis;
use crate::db::{CostmapRow, RouteRow};
use crate::error::{ApiError, Problem, deleted, found};
use crate::jobs::JobStatus;
use crate::state::{AppState, Work, off_runtime};

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

/// What a new route is stored from.
struct NewRoute {
    name: Option<String>,
    costmap_id: String,
    /// The costmap's project.
    project_id: Option<String>,
    parent_id: Option<String>,
    request: StoredRequest,
    changes: Changes,
}

/// Store a planned route, keep its D* Lite search (a replan's) and answer
/// 201 with it.
async fn store(state: &AppState, new: NewRoute, planned: Planned) -> Result<RouteRow, ApiError> {
    let row = RouteRow {
        id: uuid::Uuid::now_v7().to_string(),
        name: new.name,
        costmap_id: new.costmap_id,
        parent_id: new.parent_id,
        created_at: now_millis(),
        request: to_json(&new.request)?,
        changes: to_json(&new.changes)?,
        result: to_json(&StoredResult {
            planner: planned.planner,
            reused_search: planned.reused_search,
            route: planned.route,
            search: planned.report,
        })?,
        project_id: new.project_id,
    };
    insert(state, &row).await?;
    if let Some(search) = planned.search {
        state.routes.searches.put(&row.id, search);
    }
    Ok(row)
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
        (status = 403, description = "The caller is a viewer of the costmap's project", body = Problem, content_type = "application/problem+json"),
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
    caller: Caller,
    Path(costmap_id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    // A route goes into its costmap's project: editors there plan them.
    let costmap = visible_costmap(&state, &caller, &costmap_id, Role::Editor).await?;
    ready(&state, &costmap)?;
    let req = parse_create(&doc)?;
    let src = Arc::new(map_source(&state, &costmap).await?);
    let (start, goal, options) = (req.start, req.goal, req.options.clone());
    let source = src.clone();
    // Stopped when the client goes away or after --route-timeout-s.
    let mut planned = state
        .run_planner(Work::Route, move |stop| {
            plan_route(&source, &start, &goal, &options, stop)
        })
        .await??;
    let warm = planned.warm.take();
    let new = NewRoute {
        name: req.name,
        costmap_id,
        project_id: costmap.project_id.clone(),
        parent_id: None,
        request: StoredRequest {
            start: req.start,
            goal: req.goal,
            options: req.options.clone(),
            speed_m_s: req.speed_m_s,
        },
        changes: Changes::default(),
    };
    let row = store(&state, new, planned).await?;
    if let Some(search) = warm {
        let warming = state.routes.begin_warming(&row.id);
        let (held, id) = (state.clone(), row.id.clone());
        tokio::spawn(async move {
            let _warming = warming;
            // Not the client's: stopped only by --route-timeout-s.
            let built = held
                .run_planner(Work::Route, move |stop| {
                    // The source holds the search's room in the memory budget.
                    let _room = &src;
                    warm_search(search, stop)
                })
                .await
                .map_err(|e| e.to_string())
                .and_then(|built| built);
            match built {
                Ok(search) => held.routes.searches.put(&id, search),
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
        (status = 403, description = "The caller is a viewer of the route's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body too large", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Body is not JSON", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid request: `errors` names each fault by JSON pointer (`/position` outside the costmap or blocked, `/blocked/N` or `/cost_changes/N/area` not a valid polygon or covering the goal, `/cost_changes/N/cost` out of range, the goal cut off; or, with the pointer \"\", a search needing more than the server's memory budget)", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "No planner thread became free in time, or the search took longer than the server's limit; retry (see Retry-After)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn replan_route(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    JsonBody(doc): JsonBody,
) -> Result<Response, ApiError> {
    // Before the searches kept for replanning (keyed by route id) are
    // asked.
    let parent = visible_route(&state, &caller, &id, Role::Editor).await?;
    let request: StoredRequest = stored(&id, "request", &parent.request)?;
    let previous: Changes = stored(&id, "changes", &parent.changes)?;
    let earlier = Earlier::of(&previous)?;
    // Checking the areas' polygons is work: off the runtime threads.
    let limits = state.limits.clone();
    let req = off_runtime(move || parse_replan(&doc, &limits, earlier)).await??;

    let costmap = found(
        state.db.get_costmap(&parent.costmap_id).await?,
        "route",
        &id,
    )?;
    let src = map_source(&state, &costmap).await?;
    if src.is_windowed() {
        return Err(not_in_memory(&src));
    }
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
    let planned = replan_off_runtime(&state, &id, input).await?;
    let new = NewRoute {
        name: req.name.or(parent.name),
        costmap_id: parent.costmap_id,
        project_id: costmap.project_id,
        parent_id: Some(id),
        request: StoredRequest {
            start: req.position,
            goal: request.goal,
            options: request.options,
            speed_m_s: request.speed_m_s,
        },
        changes,
    };
    let row = store(&state, new, planned).await?;
    created(&row)
}

/// A replan on a planner thread, from the parent's D* Lite search when the
/// server holds it; that search is put back when the replan fails.
async fn replan_off_runtime(
    state: &AppState,
    parent_id: &str,
    input: ReplanInput,
) -> Result<Planned, ApiError> {
    let held = state.clone();
    let parent_id = parent_id.to_string();
    state
        .run_planner(Work::Route, move |stop| {
            let searches = &held.routes.searches;
            let cached = match input.options.planner() {
                Planner::DstarLite => searches.take(&parent_id),
                Planner::Astar | Planner::CoarseToFine => None,
            };
            tracing::debug!(route = %parent_id, held = cached.is_some(), "replanning");
            replan(&input, cached, stop).map_err(|failure| {
                if let Some(search) = failure.kept {
                    searches.put(&parent_id, *search);
                }
                failure.error
            })
        })
        .await?
}

/// The stored route `id` when the caller has at least `need` in its
/// (its costmap's) project; one of another project is the 404 of a
/// missing one.
pub(super) async fn visible_route(
    state: &AppState,
    caller: &Caller,
    id: &str,
    need: Role,
) -> Result<RouteRow, ApiError> {
    let row = state.db.get_route(id).await?;
    visible(&state.db, caller, row, "route", id, need).await
}

/// Routes, newest first, a page at a time; only those of one costmap with
/// `?costmap_id=`.
#[utoipa::path(
    get,
    path = "/api/v1/routes",
    tag = "routes",
    params(ListQuery, RouteFilter, ProjectFilter),
    responses(
        (status = 200, description = "A page of the routes of the caller's projects", body = RouteList),
        (status = 400, description = "Bad paging parameters", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No project `project_id` (of the caller's)", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_routes(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<RouteFilter>, QueryRejection>,
    projects: Result<Query<ProjectFilter>, QueryRejection>,
) -> Result<Json<RouteList>, ApiError> {
    let costmap_id = match costmap_filter(filter) {
        Ok(id) => id,
        Err(e) => {
            // A bad page is named before a bad filter.
            page(query)?;
            return Err(e);
        }
    };
    let (db, user, costmap_id) = (&state.db, caller.user_id.as_str(), costmap_id.as_deref());
    let page = list_visible(
        db,
        &caller,
        query,
        projects,
        |project, limit, offset| async move {
            db.list_routes(user, project.as_deref(), costmap_id, limit, offset)
                .await
        },
        response,
    )
    .await?;
    Ok(Json(page.into()))
}

/// The costmap id of the listing's filter: 400 when malformed.
fn costmap_filter(
    filter: Result<Query<RouteFilter>, QueryRejection>,
) -> Result<Option<String>, ApiError> {
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
    Ok(filter.costmap_id)
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
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<RouteResponse>, ApiError> {
    let row = visible_route(&state, &caller, &id, Role::Viewer).await?;
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
        (status = 403, description = "The caller is a viewer of the route's project", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such route", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_route(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    visible_route(&state, &caller, &id, Role::Editor).await?;
    let was_deleted = state.db.delete_route(&id).await?;
    state.routes.searches.remove(&id);
    deleted(was_deleted, "route", &id)
}
