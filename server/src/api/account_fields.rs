//! What the account endpoints (session, tokens, users, projects, members)
//! share: reading their JSON members with faults at JSON pointers, and
//! the user shape they answer with.

use planner_core::geo::Issue;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::ToSchema;

use super::names::{NAME_MAX_CHARS, control_character_issue};
use crate::auth::accounts::AccountError;
use crate::clock::rfc3339;
use crate::db::UserRow;
use crate::error::ApiError;

/// A user as admins see it.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct UserView {
    pub id: String,
    pub name: String,
    pub admin: bool,
    pub disabled: bool,
    /// RFC 3339 UTC.
    pub created_at: String,
}

impl From<&UserRow> for UserView {
    fn from(u: &UserRow) -> Self {
        UserView {
            id: u.id.clone(),
            name: u.name.clone(),
            admin: u.admin != 0,
            disabled: u.disabled != 0,
            created_at: rfc3339(u.created_at),
        }
    }
}

/// The body as a JSON object, or the fault at the root.
pub fn object(body: &Value) -> Result<&serde_json::Map<String, Value>, ApiError> {
    body.as_object()
        .ok_or_else(|| invalid("", "the request body must be a JSON object"))
}

/// A 422 with one fault at `pointer`.
pub fn invalid(pointer: &str, message: &str) -> ApiError {
    ApiError::Validation(vec![Issue::new(pointer, message)])
}

/// The string member `key` (absent or null: `None`), at `/key`.
pub fn string_member(
    body: &serde_json::Map<String, Value>,
    key: &str,
) -> Result<Option<String>, ApiError> {
    match body.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(Value::String(s)) => Ok(Some(s.clone())),
        Some(_) => Err(invalid(
            &format!("/{key}"),
            &format!("{key} must be a string"),
        )),
    }
}

/// The string member `key`, which must be there.
pub fn required_string(
    body: &serde_json::Map<String, Value>,
    key: &str,
) -> Result<String, ApiError> {
    string_member(body, key)?
        .ok_or_else(|| invalid(&format!("/{key}"), &format!("{key} is required")))
}

/// The required `name` of a token or project: 1 to [`NAME_MAX_CHARS`]
/// characters without control characters.
pub fn required_label(body: &serde_json::Map<String, Value>) -> Result<String, ApiError> {
    let name = required_string(body, "name")?;
    if let Some(issue) = control_character_issue("/name", "the name", &name) {
        return Err(ApiError::Validation(vec![issue]));
    }
    let chars = name.chars().count();
    if chars == 0 || chars > NAME_MAX_CHARS {
        return Err(invalid(
            "/name",
            &format!("the name must have 1 to {NAME_MAX_CHARS} characters"),
        ));
    }
    Ok(name)
}

/// An account error as an answer; faults of the request's `name` and
/// `password` members at their pointers.
pub fn account_error(e: AccountError) -> ApiError {
    match e {
        AccountError::Invalid(m) if m.contains("password") => invalid("/password", &m),
        AccountError::Invalid(m) => invalid("/name", &m),
        AccountError::Exists(_) => ApiError::Conflict(e.to_string()),
        AccountError::UnknownUser(_) => ApiError::NotFound(e.to_string()),
        AccountError::Db(e) => e.into(),
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn pointer_of(e: ApiError) -> String {
        match e {
            ApiError::Validation(issues) => issues[0].pointer.clone(),
            other => panic!("not a 422: {other:?}"),
        }
    }

    #[test]
    fn members_are_read_with_their_pointers() {
        let body = json!({"name": "ok", "n": 3, "bad": "a\u{7}b", "empty": ""});
        let map = object(&body).unwrap();
        assert_eq!(required_string(map, "name").unwrap(), "ok");
        assert_eq!(string_member(map, "missing").unwrap(), None);
        assert_eq!(
            pointer_of(required_string(map, "missing").unwrap_err()),
            "/missing"
        );
        assert_eq!(pointer_of(string_member(map, "n").unwrap_err()), "/n");
        assert_eq!(pointer_of(object(&json!([1])).unwrap_err()), "");
        assert_eq!(required_label(map).unwrap(), "ok");
        let control = json!({"name": "a\u{7}b"});
        assert_eq!(
            pointer_of(required_label(object(&control).unwrap()).unwrap_err()),
            "/name"
        );
        let empty = json!({"name": ""});
        assert_eq!(
            pointer_of(required_label(object(&empty).unwrap()).unwrap_err()),
            "/name"
        );
    }

    #[test]
    fn account_errors_map_to_statuses() {
        let pw = account_error(AccountError::Invalid("a password needs …".into()));
        assert_eq!(pointer_of(pw), "/password");
        let exists = account_error(AccountError::Exists("x".into()));
        assert_eq!(exists.status(), axum::http::StatusCode::CONFLICT);
    }
}
