//! Who may see a stored resource (DEM, survey, costmap, route): each is
//! looked up first, then the caller's role in its project checked, so one
//! of another project answers exactly like a missing one; and the
//! `?project_id=` filter every listing takes.

use axum::extract::{Query, rejection::QueryRejection};
use planner_core::geo::Issue;
use serde::Deserialize;
use serde_json::Value;
use utoipa::IntoParams;

use crate::api::names::control_character_issue;
use crate::api::paging::{ListQuery, Page, list, page};
use crate::auth::{Caller, Role, require_role};
use crate::db::{CostmapRow, Db, DemMetaRow, RouteRow, SurveyRow};
use crate::error::{ApiError, not_found};

/// Where a request body names the project of a new resource.
pub const PROJECT_POINTER: &str = "/project_id";

/// A stored resource that belongs to a project.
pub trait InProject {
    /// Its project; `None` for rows made before accounts and not adopted.
    fn project_id(&self) -> Option<&str>;
}

macro_rules! in_project {
    ($($row:ty),*) => {
        $(impl InProject for $row {
            fn project_id(&self) -> Option<&str> {
                self.project_id.as_deref()
            }
        })*
    };
}
in_project!(DemMetaRow, SurveyRow, CostmapRow, RouteRow);

/// The resource `row` (looked up by `id`) when the caller has at least
/// `need` in its project. Missing, or in a project the caller is not a
/// member of: the same 404 of [`not_found`] (`kind`, `id`), after the same
/// membership query. A member with a lower role: 403.
pub async fn visible<T: InProject>(
    db: &Db,
    caller: &Caller,
    row: Option<T>,
    kind: &str,
    id: &str,
    need: Role,
) -> Result<T, ApiError> {
    let hidden = || not_found(kind, id);
    // A missing row is checked against no project (""), so that it costs
    // the same query as a hidden one before it is answered the same way.
    let project = row.as_ref().map_or(Some(""), |r| r.project_id());
    require_role(db, caller, project, need, hidden).await?;
    row.ok_or_else(hidden)
}

/// The project filter of a listing.
#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ProjectFilter {
    /// Only the resources of this project (one the caller is a member
    /// of); without it, those of all the caller's projects.
    project_id: Option<String>,
}

/// The project a listing is limited to: `None` for all the caller's.
/// 400 when the query string is malformed; 404 for a project the caller
/// is not a member of, like one that does not exist.
pub async fn project_filter(
    db: &Db,
    caller: &Caller,
    filter: Result<Query<ProjectFilter>, QueryRejection>,
) -> Result<Option<String>, ApiError> {
    let Query(filter) =
        filter.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let Some(id) = filter.project_id else {
        return Ok(None);
    };
    require_role(db, caller, Some(&id), Role::Viewer, || {
        not_found("project", &id)
    })
    .await?;
    Ok(Some(id))
}

/// The page of a listing of resources the caller may see: `fetch` reads
/// the rows of the page for (project filter, limit, offset), the filter
/// checked by [`project_filter`] (a bad page is named before a bad
/// filter); `item` answers each row.
pub async fn list_visible<R, T, Fut>(
    db: &Db,
    caller: &Caller,
    query: Result<Query<ListQuery>, QueryRejection>,
    filter: Result<Query<ProjectFilter>, QueryRejection>,
    fetch: impl FnOnce(Option<String>, i64, i64) -> Fut,
    item: impl FnMut(&R) -> Result<T, ApiError>,
) -> Result<Page<T>, ApiError>
where
    Fut: Future<Output = Result<(Vec<R>, i64), sqlx::Error>>,
{
    let project = match project_filter(db, caller, filter).await {
        Ok(project) => project,
        Err(e) => {
            page(query)?;
            return Err(e);
        }
    };
    list(query, |limit, offset| fetch(project, limit, offset), item).await
}

/// The `project_id` member of a request body: absent or null for the
/// caller's personal project, else a non-empty string; a fault at
/// `/project_id` otherwise.
pub fn read_project_id(value: Option<&Value>) -> Result<Option<String>, Issue> {
    match value {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s))
            if let Some(issue) = control_character_issue(PROJECT_POINTER, "the project id", s) =>
        {
            Err(issue)
        }
        Some(Value::String(s)) if !s.is_empty() => Ok(Some(s.clone())),
        Some(_) => Err(Issue::new(
            PROJECT_POINTER,
            "must be the id (a non-empty string) of a project of yours (GET /api/v1/projects), \
             or null for your personal project",
        )),
    }
}

/// The project of a resource as answered: every row served has one (rows
/// of no project are visible to no one).
pub fn answered_project(project_id: &Option<String>) -> String {
    project_id.clone().unwrap_or_default()
}
