//! Vehicle links (issue 23 item 4, the service half): a stored survey's
//! mission sent to a vehicle over MAVLink, with progress as Server-Sent
//! Events (`upload`), and which vehicles the service may reach
//! (`GET /api/v1/vehicle-links`). Switched off unless `serve
//! --vehicle-links` names the addresses.

use axum::Json;
use axum::extract::State;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::auth::Caller;
use crate::state::AppState;

mod request;
mod upload;

/// One entry of `--vehicle-links`.
#[derive(Serialize, ToSchema)]
pub struct VehicleLinkEntry {
    /// The address, or address pattern: `udpout:HOST:PORT`,
    /// `udpin:HOST:PORT`, `tcpout:HOST:PORT`, `serial:DEVICE:BAUD`, where
    /// the port (baud rate) may be a range `LO-HI` or `*` (any).
    address: String,
    /// The entry names one address, to be sent as it is; otherwise a port
    /// (baud rate) in its range must be chosen.
    exact: bool,
}

/// Whether the service may send missions to vehicles, and to which.
#[derive(Serialize, ToSchema)]
pub struct VehicleLinksAnswer {
    /// Uploads are switched on (`serve --vehicle-links`); when false,
    /// `POST /api/v1/surveys/{id}/uavs/{uav}/upload` answers 404.
    enabled: bool,
    /// The addresses the service may reach, as configured.
    addresses: Vec<VehicleLinkEntry>,
}

/// The vehicle links this service may reach (`serve --vehicle-links`):
/// what the page offers for "Send to vehicle".
#[utoipa::path(
    get,
    path = "/api/v1/vehicle-links",
    tag = "vehicle-links",
    responses(
        (status = 200, description = "Whether uploads are on, and the allowed addresses", body = VehicleLinksAnswer),
    )
)]
pub async fn list_vehicle_links(
    State(state): State<AppState>,
    _caller: Caller,
) -> Json<VehicleLinksAnswer> {
    let links = &state.vehicle_links;
    Json(VehicleLinksAnswer {
        enabled: links.enabled(),
        addresses: links
            .allowed()
            .iter()
            .map(|p| VehicleLinkEntry {
                address: p.to_string(),
                exact: p.is_exact(),
            })
            .collect(),
    })
}

/// The vehicle-link endpoints.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_vehicle_links))
        .routes(routes!(upload::upload_to_vehicle))
}
