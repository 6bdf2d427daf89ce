//! `/api/v1/tokens`: a user's own API tokens — make one (shown once), list
//! them (without their secrets), revoke one.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{invalid, object, required_label};
use super::json_body::JsonBody;
use super::paging::{self, ListQuery, listing};
use crate::auth::Caller;
use crate::auth::accounts::issue_token;
use crate::clock::{now_millis, rfc3339};
use crate::db::TokenRow;
use crate::error::{ApiError, Problem, deleted};
use crate::state::AppState;

/// Longest lifetime a token may be given, days (ten years).
const MAX_DAYS: i64 = 3650;
const DAY_MS: i64 = 24 * 3600 * 1000;

/// An API token; `token` itself only in the answer that made it.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct TokenView {
    /// Public: names the token, e.g. to revoke it.
    pub id: String,
    pub name: String,
    /// RFC 3339 UTC.
    pub created_at: String,
    /// RFC 3339 UTC; null: never expires.
    pub expires_at: Option<String>,
    /// RFC 3339 UTC (to the minute); null: never used.
    pub last_used_at: Option<String>,
    /// The token to send as `Authorization: Bearer …`; shown only once.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub token: Option<String>,
}

impl TokenView {
    fn of(row: &TokenRow, token: Option<String>) -> TokenView {
        TokenView {
            id: row.id.clone(),
            name: row.name.clone(),
            created_at: rfc3339(row.created_at),
            expires_at: row.expires_at.map(rfc3339),
            last_used_at: row.last_used_at.map(rfc3339),
            token,
        }
    }
}

/// A page of the caller's tokens.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct TokenList {
    items: Vec<TokenView>,
    total: i64,
    limit: i64,
    offset: i64,
}
listing!(TokenList, TokenView);

/// `{"name", "expires_in_days"?}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct NewToken {
    name: String,
    /// 1 to 3650; absent or null: the token never expires.
    expires_in_days: Option<i64>,
}

/// `expires_in_days` as an expiry time from `now`.
fn expiry(value: Option<&Value>, now: i64) -> Result<Option<i64>, ApiError> {
    match value {
        None | Some(Value::Null) => Ok(None),
        Some(v) => match v.as_i64() {
            Some(days) if (1..=MAX_DAYS).contains(&days) => Ok(Some(now + days * DAY_MS)),
            _ => Err(invalid(
                "/expires_in_days",
                &format!("expires_in_days must be a whole number of days from 1 to {MAX_DAYS}"),
            )),
        },
    }
}

/// Make an API token for the caller.
#[utoipa::path(
    post,
    path = "/api/v1/tokens",
    tag = "accounts",
    request_body = NewToken,
    responses(
        (status = 201, description = "The token, shown only now", body = TokenView),
        (status = 422, description = "A bad name or lifetime", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_token(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(body): JsonBody,
) -> Result<(StatusCode, Json<TokenView>), ApiError> {
    let body = object(&body)?;
    let name = required_label(body)?;
    let expires_at = expiry(body.get("expires_in_days"), now_millis())?;
    let (row, token) = issue_token(&state.db, &caller.user_id, &name, expires_at).await?;
    Ok((StatusCode::CREATED, Json(TokenView::of(&row, Some(token)))))
}

/// The caller's tokens, oldest first (without the tokens themselves).
#[utoipa::path(
    get,
    path = "/api/v1/tokens",
    tag = "accounts",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of the caller's tokens", body = TokenList),
        (status = 400, description = "Bad paging", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_tokens(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<TokenList>, ApiError> {
    let page = paging::list(
        query,
        |limit, offset| state.db.list_tokens(&caller.user_id, limit, offset),
        |row| Ok(TokenView::of(row, None)),
    )
    .await?;
    Ok(Json(page.into()))
}

/// Revoke one of the caller's tokens (another user's is not found).
#[utoipa::path(
    delete,
    path = "/api/v1/tokens/{id}",
    tag = "accounts",
    params(("id" = String, Path, description = "Token id")),
    responses(
        (status = 204, description = "Revoked"),
        (status = 404, description = "The caller has no such token", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_token(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    deleted(
        state.db.delete_token(&caller.user_id, &id).await?,
        "token",
        &id,
    )
}

/// `/api/v1/tokens`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_token, list_tokens))
        .routes(routes!(delete_token))
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    #[test]
    fn lifetimes_are_whole_days_within_ten_years() {
        assert_eq!(expiry(None, 5).unwrap(), None);
        assert_eq!(expiry(Some(&Value::Null), 5).unwrap(), None);
        assert_eq!(expiry(Some(&json!(1)), 5).unwrap(), Some(5 + DAY_MS));
        assert_eq!(expiry(Some(&json!(3650)), 0).unwrap(), Some(3650 * DAY_MS));
        for bad in [json!(0), json!(3651), json!(1.5), json!("7"), json!(-1)] {
            assert!(expiry(Some(&bad), 0).is_err(), "{bad}");
        }
    }
}
