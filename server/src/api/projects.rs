//! `/api/v1/projects`: the projects the caller is a member of — make one
//! (the caller its owner), list, read, delete (owners; never a personal
//! project nor one still holding resources). Members: `api/members.rs`.

use axum::Json;
use axum::extract::{Path, Query, State, rejection::QueryRejection};
use axum::http::StatusCode;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{object, required_label};
use super::json_body::JsonBody;
use super::paging::{self, ListQuery, listing};
use crate::auth::{Caller, Role, require_role};
use crate::clock::{now_millis, rfc3339};
use crate::db::{MembershipRow, ProjectRow};
use crate::error::{ApiError, Problem, not_found};
use crate::quota::Usage;
use crate::state::AppState;

/// A project as the caller sees it.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct ProjectView {
    pub id: String,
    pub name: String,
    /// The caller's personal project (or another member's, shared).
    pub personal: bool,
    /// The caller's role in it.
    pub role: Role,
    /// RFC 3339 UTC.
    pub created_at: String,
    /// Its use of the storage and job quotas (in `GET /api/v1/projects/{id}`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub usage: Option<Usage>,
}

impl ProjectView {
    fn of(row: &MembershipRow) -> Result<ProjectView, ApiError> {
        Ok(ProjectView {
            id: row.id.clone(),
            name: row.name.clone(),
            personal: row.personal_of.is_some(),
            role: Role::parse(&row.role)
                .ok_or_else(|| ApiError::Internal(format!("stored role {:?}", row.role)))?,
            created_at: rfc3339(row.created_at),
            usage: None,
        })
    }
}

/// A page of the caller's projects, the personal one first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct ProjectList {
    items: Vec<ProjectView>,
    total: i64,
    limit: i64,
    offset: i64,
}
listing!(ProjectList, ProjectView);

/// `{"name"}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct NewProject {
    /// 1 to 200 characters.
    name: String,
}

/// The 404 of a project that does not exist or that the caller is not a
/// member of: the same answer for both.
pub fn no_project(id: &str) -> ApiError {
    not_found("project", id)
}

/// Project `id` with the caller's role in it, at least `need`.
pub async fn project_for(
    state: &AppState,
    caller: &Caller,
    id: &str,
    need: Role,
) -> Result<(ProjectRow, Role), ApiError> {
    let role = require_role(&state.db, caller, Some(id), need, || no_project(id)).await?;
    let project = state
        .db
        .project_by_id(id)
        .await?
        .ok_or_else(|| no_project(id))?;
    Ok((project, role))
}

/// Make a project; the caller is its owner.
#[utoipa::path(
    post,
    path = "/api/v1/projects",
    tag = "projects",
    request_body = NewProject,
    responses(
        (status = 201, description = "The project", body = ProjectView),
        (status = 422, description = "A bad name", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn create_project(
    State(state): State<AppState>,
    caller: Caller,
    JsonBody(body): JsonBody,
) -> Result<(StatusCode, Json<ProjectView>), ApiError> {
    let name = required_label(object(&body)?)?;
    let row = ProjectRow {
        id: uuid::Uuid::now_v7().to_string(),
        name,
        personal_of: None,
        created_at: now_millis(),
    };
    state.db.insert_project(&row, &caller.user_id).await?;
    Ok((
        StatusCode::CREATED,
        Json(ProjectView {
            id: row.id,
            name: row.name,
            personal: false,
            role: Role::Owner,
            created_at: rfc3339(row.created_at),
            usage: None,
        }),
    ))
}

/// The caller's projects, the personal one first, then oldest first.
#[utoipa::path(
    get,
    path = "/api/v1/projects",
    tag = "projects",
    params(ListQuery),
    responses(
        (status = 200, description = "A page of the caller's projects", body = ProjectList),
        (status = 400, description = "Bad paging", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn list_projects(
    State(state): State<AppState>,
    caller: Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
) -> Result<Json<ProjectList>, ApiError> {
    let page = paging::list(
        query,
        |limit, offset| state.db.projects_of(&caller.user_id, limit, offset),
        ProjectView::of,
    )
    .await?;
    Ok(Json(page.into()))
}

/// One of the caller's projects.
#[utoipa::path(
    get,
    path = "/api/v1/projects/{id}",
    tag = "projects",
    params(("id" = String, Path, description = "Project id")),
    responses(
        (status = 200, description = "The project", body = ProjectView),
        (status = 404, description = "No such project among the caller's", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn get_project(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Json<ProjectView>, ApiError> {
    let (project, role) = project_for(&state, &caller, &id, Role::Viewer).await?;
    let usage = state.quotas.usage(&state.db, &project.id).await?;
    Ok(Json(ProjectView {
        id: project.id,
        name: project.name,
        personal: project.personal_of.is_some(),
        role,
        created_at: rfc3339(project.created_at),
        usage: Some(usage),
    }))
}

/// Delete a project (owners): not a personal one, and only once empty.
#[utoipa::path(
    delete,
    path = "/api/v1/projects/{id}",
    tag = "projects",
    params(("id" = String, Path, description = "Project id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 403, description = "The caller is not an owner", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such project among the caller's", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "A personal project, or one that still holds resources", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn delete_project(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let (project, _) = project_for(&state, &caller, &id, Role::Owner).await?;
    if project.personal_of.is_some() {
        return Err(ApiError::Conflict(format!(
            "project {id:?} is a personal project: it goes only with its user"
        )));
    }
    let held = state.db.count_project_resources(&id).await?;
    if held > 0 {
        return Err(ApiError::Conflict(format!(
            "project {id:?} still holds {held} resources (DEMs, surveys, costmaps, routes): \
             delete them first"
        )));
    }
    state.db.delete_project(&id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `/api/v1/projects`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_project, list_projects))
        .routes(routes!(get_project, delete_project))
}
