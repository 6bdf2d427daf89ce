//! `GET /api/v1/cameras`: the named camera presets a survey can use
//! (`camera` in `POST /api/v1/surveys`), with their numbers, so clients
//! can show them and start a custom camera from one.

use axum::Json;
use planner_core::coverage::{Camera, PRESETS};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use crate::state::AppState;

/// A preset: its name and its camera.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct CameraPreset {
    name: String,
    camera: Camera,
}

/// Every preset, the default first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct CameraList {
    items: Vec<CameraPreset>,
}

/// The camera presets and their numbers.
#[utoipa::path(
    get,
    path = "/api/v1/cameras",
    tag = "surveys",
    responses(
        (status = 200, description = "The presets, the default first", body = CameraList),
    )
)]
pub async fn list_cameras() -> Json<CameraList> {
    Json(CameraList {
        items: PRESETS
            .iter()
            .filter_map(|&name| {
                Camera::preset(name).map(|camera| CameraPreset {
                    name: name.to_string(),
                    camera,
                })
            })
            .collect(),
    })
}

/// `GET /api/v1/cameras`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(list_cameras))
}
