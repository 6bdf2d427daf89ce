//! `/api/v1/users` (admins only): list the users, make one (with its
//! personal project and a first API token), disable one. Being an admin
//! opens no one else's projects.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{
    UserView, account_error, invalid, object, required_string, string_member,
};
use super::json_body::JsonBody;
use super::paging::{self, ListQuery, listing};
use crate::auth::Caller;
use crate::auth::accounts::{self, create_user};
use crate::error::{ApiError, Problem};
use crate::state::AppState;

/// A page of users, oldest first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct UserList {
    items: Vec<UserView>,
    total: i64,
    limit: i64,
    offset: i64,
}
listing!(UserList, UserView);

/// A user just made and its first API token (shown only now).
#[derive(Serialize, Deserialize, ToSchema)]
pub struct UserCreated {
    pub user: UserView,
    pub token: String,
}

/// `{"name", "password"?, "admin"?}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct NewUser {
    /// 1 to 64 letters, digits, '.', '_' or '-'.
    name: String,
    /// At least 8 characters; absent: the user signs in with tokens only.
    password: Option<String>,
    /// Default false.
    admin: Option<bool>,
}

/// List the users (admins only).
#[utoipa::path(
    get,
    path = "/api/v1/users",
    tag = "accounts",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of users", body = UserList),
        (status = 400, description = "Bad paging", body = Problem, content_type = "application/problem+json"),
        (status = 403, description = "The caller is not an admin", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_users(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<UserList>, ApiError> {
    caller.require_admin()?;
    let page = paging::list(
        query,
        |limit, offset| state.db.list_users(limit, offset),
        |row| Ok(UserView::from(row)),
    )
    .await?;
    Ok(Json(page.into()))
}

/// Make a user (admins only), with its personal project and a first token.
#[utoipa::path(
    post,
    path = "/api/v1/users",
    tag = "accounts",
    request_body = NewUser,
    responses(
        (status = 201, description = "The user and its first API token", body = UserCreated),
        (status = 403, description = "The caller is not an admin", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The name is taken", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A bad name, password or admin flag", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn add_user(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(body): JsonBody,
) -> Result<(StatusCode, Json<UserCreated>), ApiError> {
    caller.require_admin()?;
    let body = object(&body)?;
    let name = required_string(body, "name")?;
    let password = string_member(body, "password")?;
    let admin = match body.get("admin") {
        None | Some(Value::Null) => false,
        Some(Value::Bool(b)) => *b,
        Some(_) => return Err(invalid("/admin", "admin must be true or false")),
    };
    let made = create_user(&state.db, &name, password.as_deref(), admin)
        .await
        .map_err(account_error)?;
    Ok((
        StatusCode::CREATED,
        Json(UserCreated {
            user: UserView::from(&made.user),
            token: made.token,
        }),
    ))
}

/// Disable a user (admins only): its tokens and sessions stop working.
#[utoipa::path(
    post,
    path = "/api/v1/users/{name}/disable",
    tag = "accounts",
    params(("name" = String, Path, description = "User name")),
    responses(
        (status = 200, description = "The user, disabled", body = UserView),
        (status = 403, description = "The caller is not an admin", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such user", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "Admins cannot disable themselves", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn disable_user(
    State(state): State<AppState>,
    caller: Caller,
    Path(name): Path<String>,
) -> Result<Json<UserView>, ApiError> {
    caller.require_admin()?;
    let user = state
        .db
        .user_by_name(&name)
        .await?
        .ok_or_else(|| account_error(accounts::AccountError::UnknownUser(name.clone())))?;
    if user.id == caller.user_id {
        // Else the last admin could lock everyone out of user management.
        return Err(ApiError::Conflict(
            "you cannot disable yourself: ask another admin".to_string(),
        ));
    }
    state.db.disable_user(&user.id).await?;
    let user = state
        .db
        .user_by_id(&user.id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("user {name:?} vanished")))?;
    Ok(Json(UserView::from(&user)))
}

/// `/api/v1/users`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_users, add_user))
        .routes(routes!(disable_user))
}
