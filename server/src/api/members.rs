//! `/api/v1/projects/{id}/members`: who may see and change a project's
//! resources. Members (viewers and up) list them; owners add, change and
//! remove them, and a project always keeps at least one owner.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{invalid, object, required_string};
use super::json_body::JsonBody;
use super::paging::{self, ListQuery, Page, listing};
use super::projects::project_for;
use crate::auth::{Caller, Role};
use crate::db::{MemberChange, MemberRow};
use crate::error::{ApiError, Problem};
use crate::state::AppState;

/// A member of a project.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct MemberView {
    /// The user's name.
    pub user: String,
    pub role: Role,
}

impl MemberView {
    fn of(row: &MemberRow) -> Result<MemberView, ApiError> {
        Ok(MemberView {
            user: row.user_name.clone(),
            role: Role::parse(&row.role)
                .ok_or_else(|| ApiError::Internal(format!("stored role {:?}", row.role)))?,
        })
    }
}

/// A page of a project's members, owners first, then by name.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct MemberList {
    items: Vec<MemberView>,
    total: i64,
    limit: i64,
    offset: i64,
}
listing!(MemberList, MemberView);

/// `{"user": name, "role"}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct NewMember {
    /// The user's name.
    user: String,
    role: Role,
}

/// The members of a project (any member may look).
#[utoipa::path(
    get,
    path = "/api/v1/projects/{id}/members",
    tag = "projects",
    params(("id" = String, Path, description = "Project id"), ListQuery),
    responses(
        (status = 200, description = "A page of the members", body = MemberList),
        (status = 400, description = "Bad paging", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such project among the caller's", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_members(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<MemberList>, ApiError> {
    let (limit, offset) = paging::page(query)?;
    project_for(&state, &caller, &id, Role::Viewer).await?;
    let rows = state.db.project_members(&id).await?;
    let items = rows
        .iter()
        .skip(usize::try_from(offset).unwrap_or(usize::MAX))
        .take(usize::try_from(limit).unwrap_or(0))
        .map(MemberView::of)
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Json(
        Page {
            items,
            total: rows.len() as i64,
            limit,
            offset,
        }
        .into(),
    ))
}

/// Add a member or change its role (owners).
#[utoipa::path(
    post,
    path = "/api/v1/projects/{id}/members",
    tag = "projects",
    params(("id" = String, Path, description = "Project id")),
    request_body = NewMember,
    responses(
        (status = 201, description = "A new member", body = MemberView),
        (status = 200, description = "The member's role changed", body = MemberView),
        (status = 403, description = "The caller is not an owner", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such project among the caller's", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "This would leave the project without an owner", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "An unknown user or role", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn set_member(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
    JsonBody(body): JsonBody,
) -> Result<(StatusCode, Json<MemberView>), ApiError> {
    project_for(&state, &caller, &id, Role::Owner).await?;
    let body = object(&body)?;
    let name = required_string(body, "user")?;
    let role_text = required_string(body, "role")?;
    let role = Role::parse(&role_text)
        .ok_or_else(|| invalid("/role", "role must be \"viewer\", \"editor\" or \"owner\""))?;
    let unknown = || invalid("/user", &format!("there is no user named {name:?}"));
    // A name no user can have is not looked up (PostgreSQL refuses NUL).
    if crate::auth::accounts::name_fault(&name).is_some() {
        return Err(unknown());
    }
    let user = state.db.user_by_name(&name).await?.ok_or_else(unknown)?;
    let status = match state
        .db
        .change_member(&id, &user.id, Some(role.as_str()))
        .await?
    {
        MemberChange::Added => StatusCode::CREATED,
        MemberChange::LastOwner => return Err(last_owner(&id, "demote")),
        _ => StatusCode::OK,
    };
    Ok((
        status,
        Json(MemberView {
            user: user.name,
            role,
        }),
    ))
}

/// The 409 of a change that would leave project `id` without an owner.
fn last_owner(id: &str, verb: &str) -> ApiError {
    ApiError::Conflict(format!(
        "cannot {verb} the last owner of project {id:?}: make another member an owner first"
    ))
}

/// Remove a member (owners).
#[utoipa::path(
    delete,
    path = "/api/v1/projects/{id}/members/{user}",
    tag = "projects",
    params(
        ("id" = String, Path, description = "Project id"),
        ("user" = String, Path, description = "The member's user name"),
    ),
    responses(
        (status = 204, description = "Removed"),
        (status = 403, description = "The caller is not an owner", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such project among the caller's, or no such member", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The last owner", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn remove_member(
    State(state): State<AppState>,
    caller: Caller,
    Path((id, name)): Path<(String, String)>,
) -> Result<StatusCode, ApiError> {
    project_for(&state, &caller, &id, Role::Owner).await?;
    let not_member =
        || ApiError::NotFound(format!("user {name:?} is not a member of project {id:?}"));
    let user = state.db.user_by_name(&name).await?.ok_or_else(not_member)?;
    match state.db.change_member(&id, &user.id, None).await? {
        MemberChange::NotMember => Err(not_member()),
        MemberChange::LastOwner => Err(last_owner(&id, "remove")),
        _ => Ok(StatusCode::NO_CONTENT),
    }
}

/// `/api/v1/projects/{id}/members`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_members, set_member))
        .routes(routes!(remove_member))
}
