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
//! kept in memory (`SearchCache`), so that a replan from it
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
//!
//! One job per module: `model` (stored and answered shapes), `request`
//! (reading bodies), `search` (searches on planner threads), `handlers`
//! (the resource) and `files` (downloads).

mod files;
mod handlers;
mod model;
mod request;
mod search;
mod stored_file;

use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::state::AppState;

/// The route endpoints, with their OpenAPI paths.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(handlers::create_route))
        .routes(routes!(handlers::list_routes))
        .routes(routes!(handlers::get_route, handlers::delete_route))
        .routes(routes!(handlers::replan_route))
        .routes(routes!(files::route_geojson_file))
        .routes(routes!(files::route_csv_file))
        .routes(routes!(files::mission_waypoints))
}
