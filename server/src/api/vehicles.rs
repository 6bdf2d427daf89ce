//! `GET /api/v1/vehicles`: the named ground-vehicle profiles a costmap can
//! be built for (`vehicle.preset` in `POST /api/v1/costmaps`), with their
//! numbers, so clients can show and start from them.

use axum::Json;
use planner_core::costmap::{Vehicle, VehiclePreset};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::state::AppState;

/// Every preset, the default (`u-go`) first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct VehicleList {
    items: Vec<Vehicle>,
}

/// The vehicle presets and their numbers.
#[utoipa::path(
    get,
    path = "/api/v1/vehicles",
    tag = "costmaps",
    responses(
        (status = 200, description = "The presets, the default first", body = VehicleList),
    )
)]
pub async fn list_vehicles() -> Json<VehicleList> {
    Json(VehicleList {
        items: VehiclePreset::ALL.iter().map(|p| p.vehicle()).collect(),
    })
}

/// `GET /api/v1/vehicles`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_vehicles))
}
