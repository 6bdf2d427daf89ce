//! `GET /healthz`: liveness and database reachability.

use axum::Json;
use axum::extract::State;
use serde::Serialize;
use utoipa::ToSchema;

use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::error::{ApiError, Problem};
use crate::state::AppState;

#[derive(Serialize, ToSchema)]
pub struct Health {
    /// "ok" when the service and its database answer.
    status: &'static str,
    /// "sqlite" or "postgres".
    database: &'static str,
    version: &'static str,
}

/// Is the service up and its database reachable?
#[utoipa::path(
    get,
    path = "/healthz",
    tag = "service",
    responses(
        (status = 200, description = "The service and its database answer", body = Health),
        (status = 500, description = "The database does not answer", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn healthz(State(state): State<AppState>) -> Result<Json<Health>, ApiError> {
    state.db.ping().await?;
    Ok(Json(Health {
        status: "ok",
        database: state.db.backend(),
        version: env!("CARGO_PKG_VERSION"),
    }))
}

/// `GET /healthz`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(healthz))
}
