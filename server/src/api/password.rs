//! `POST /api/v1/session/password`: signed-in users change their own
//! password. The current one must be given (unless the user has none and
//! signs in with tokens only); every web session of the user then ends,
//! its API tokens go on working.

use axum::extract::State;
use axum::http::StatusCode;
use serde::Deserialize;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{invalid, object, required_string, string_member};
use super::json_body::JsonBody;
use crate::auth::{Caller, password};
use crate::error::{ApiError, Problem};
use crate::state::{AppState, off_runtime};

/// `{"current", "new"}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct PasswordChange {
    /// The current password; not needed by a user who has none yet.
    current: Option<String>,
    /// The new password: at least 8 characters, at most 1024 bytes.
    new: String,
}

/// Change the caller's own password.
#[utoipa::path(
    post,
    path = "/api/v1/session/password",
    tag = "accounts",
    request_body = PasswordChange,
    responses(
        (status = 204, description = "Changed: every web session of the user has ended (sign in again); API tokens go on working"),
        (status = 422, description = "The current password is wrong or missing, the new one too short or too long, or an unknown member", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn change_password(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(body): JsonBody,
) -> Result<StatusCode, ApiError> {
    let body = object(&body)?;
    if let Some(key) = body
        .keys()
        .find(|k| !matches!(k.as_str(), "current" | "new"))
    {
        return Err(invalid(
            &format!("/{key}"),
            &format!("unknown field {key:?}: expected current or new"),
        ));
    }
    let new = required_string(body, "new")?;
    if let Some(fault) = password::fault(&new) {
        return Err(invalid("/new", &fault));
    }
    let current = string_member(body, "current")?;
    // Guessing the current password through a taken session is limited
    // like signing in.
    state.rates.sign_in_name(&caller.name)?;
    let user = state
        .db
        .user_by_id(&caller.user_id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("user {:?} vanished", caller.name)))?;
    if let Some(phc) = user.password_hash {
        let current = current.ok_or_else(|| invalid("/current", "current is required"))?;
        let matched = off_runtime(move || password::verify(&current, &phc)).await?;
        if !matched {
            return Err(invalid("/current", "this is not your current password"));
        }
    }
    let hash = off_runtime(move || password::hash(&new)).await?;
    state.db.set_password_hash(&user.id, &hash).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `/api/v1/session/password`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(change_password))
}
