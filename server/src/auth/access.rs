//! Roles in a project and the two checks every resource handler makes:
//! may the caller act on this resource ([`require_role`]), and which
//! project does a new resource go into ([`new_resource_project`]).

use planner_core::geo::Issue;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::Caller;
use crate::db::Db;
use crate::error::ApiError;

/// A member's role in a project; each includes the rights of those before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Reads, lists and downloads.
    Viewer,
    /// Also creates, replans and deletes.
    Editor,
    /// Also manages the members and deletes the project.
    Owner,
}

impl Role {
    pub fn as_str(self) -> &'static str {
        match self {
            Role::Viewer => "viewer",
            Role::Editor => "editor",
            Role::Owner => "owner",
        }
    }

    pub fn parse(text: &str) -> Option<Role> {
        match text {
            "viewer" => Some(Role::Viewer),
            "editor" => Some(Role::Editor),
            "owner" => Some(Role::Owner),
            _ => None,
        }
    }
}

/// The caller's role in a project; `None` when not a member, when there
/// is no such project, or for a resource of no project.
pub async fn role_in(
    db: &Db,
    caller: &Caller,
    project_id: Option<&str>,
) -> Result<Option<Role>, ApiError> {
    let Some(project_id) = project_id else {
        return Ok(None);
    };
    Ok(db
        .member_role(project_id, &caller.user_id)
        .await?
        .as_deref()
        .and_then(Role::parse))
}

/// Check that the caller may act with `need` on a resource of
/// `project_id`. Not a member: `hidden()`, the very answer of a missing
/// resource, so a resource of another project cannot be told from none.
/// A member with a lower role: 403 naming the role needed.
pub async fn require_role(
    db: &Db,
    caller: &Caller,
    project_id: Option<&str>,
    need: Role,
    hidden: impl FnOnce() -> ApiError,
) -> Result<Role, ApiError> {
    match role_in(db, caller, project_id).await? {
        None => Err(hidden()),
        Some(role) if role < need => Err(ApiError::Forbidden(format!(
            "this needs the {} role in project {:?}; you are a {}",
            need.as_str(),
            project_id.unwrap_or_default(),
            role.as_str()
        ))),
        Some(role) => Ok(role),
    }
}

/// The project a new resource goes into: `requested` (the request's
/// `project_id`, found at `pointer`), or the caller's personal project.
/// The caller must be an editor there; a project the caller is not a
/// member of is refused like one that does not exist (422 at `pointer`).
pub async fn new_resource_project(
    db: &Db,
    caller: &Caller,
    requested: Option<&str>,
    pointer: &str,
) -> Result<String, ApiError> {
    let project_id = match requested {
        Some(id) => id.to_string(),
        None => db
            .personal_project(&caller.user_id)
            .await?
            .map(|p| p.id)
            .ok_or_else(|| {
                ApiError::Internal(format!("user {:?} has no personal project", caller.name))
            })?,
    };
    require_role(db, caller, Some(&project_id), Role::Editor, || {
        ApiError::Validation(vec![Issue::new(
            pointer,
            &format!("there is no project with id {project_id:?}"),
        )])
    })
    .await?;
    Ok(project_id)
}
