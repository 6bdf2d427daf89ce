//! `/api/v1/session`: the web page signs in (user name and password, or an
//! API token) and gets a session cookie plus the CSRF token its writes
//! must send; who am I; sign out.

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::account_fields::{object, required_string, string_member};
use super::json_body::JsonBody;
use crate::auth::Caller;
use crate::auth::caller::{SESSION_COOKIE, SESSION_IDLE_MS, SESSION_MAX_MS, Via, token_caller};
use crate::auth::password;
use crate::auth::secret::{self, SESSION_PREFIX};
use crate::clock::now_millis;
use crate::db::{Db, SessionRow, UserRow};
use crate::error::{ApiError, Problem};
use crate::state::{AppState, off_runtime};

/// The one answer to every failed sign-in, so that it tells nothing about
/// which part was wrong.
const WRONG: &str = "wrong user name, password or token";

/// The signed-in user.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct SessionUser {
    pub id: String,
    pub name: String,
    pub admin: bool,
}

/// Who is signed in.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct SessionView {
    pub user: SessionUser,
    /// Send it as `X-CSRF-Token` with every write signed in by the
    /// cookie; null for callers with a bearer token.
    pub csrf_token: Option<String>,
    /// The project resources go into when a request names none.
    pub personal_project_id: String,
}

/// `{"user", "password"}` or `{"token"}`.
#[derive(Deserialize, ToSchema)]
#[allow(dead_code)] // The schema of the document; the body is read as JSON.
pub struct SignIn {
    user: Option<String>,
    password: Option<String>,
    token: Option<String>,
}

async fn view(
    db: &Db,
    user: SessionUser,
    csrf_token: Option<String>,
) -> Result<SessionView, ApiError> {
    let personal_project_id = db
        .personal_project(&user.id)
        .await?
        .map(|p| p.id)
        .ok_or_else(|| {
            ApiError::Internal(format!("user {:?} has no personal project", user.name))
        })?;
    Ok(SessionView {
        user,
        csrf_token,
        personal_project_id,
    })
}

/// Sign in: a session cookie and its CSRF token.
#[utoipa::path(
    post,
    path = "/api/v1/session",
    tag = "accounts",
    request_body = SignIn,
    responses(
        (status = 201, description = "Signed in; the session cookie is set", body = SessionView,
            headers(("Set-Cookie" = String, description = "terraplan_session=…; HttpOnly; SameSite=Strict; Path=/"))),
        (status = 401, description = "Wrong user name, password or token", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A member of the body is missing or not a string", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn sign_in(
    State(state): State<AppState>,
    headers: HeaderMap,
    JsonBody(body): JsonBody,
) -> Result<Response, ApiError> {
    let body = object(&body)?;
    let user = match string_member(body, "token")? {
        Some(token) => {
            let caller = token_caller(&state.db, &token)
                .await
                .map_err(|_| ApiError::Unauthorized(WRONG.to_string()))?;
            state
                .db
                .user_by_id(&caller.user_id)
                .await?
                .ok_or_else(|| ApiError::Unauthorized(WRONG.to_string()))?
        }
        None => {
            let name = required_string(body, "user")?;
            let password = required_string(body, "password")?;
            state.rates.sign_in_name(&name)?;
            check_password(&state.db, &name, password).await?
        }
    };
    let s = secret::new_secret(SESSION_PREFIX);
    let now = now_millis();
    let row = SessionRow {
        id: s.id,
        user_id: user.id.clone(),
        secret_hash: s.hash,
        csrf_token: secret::random_text(),
        created_at: now,
        last_used_at: now,
        expires_at: now + SESSION_MAX_MS,
    };
    state.db.insert_session(&row).await?;
    // Ended sessions are otherwise only forgotten when their cookie comes
    // back; each sign-in clears them out.
    state.db.purge_sessions(now, now - SESSION_IDLE_MS).await?;
    let secure = state.cookie_secure || forwarded_https(&headers);
    let cookie = session_cookie(&s.full, SESSION_MAX_MS / 1000, secure);
    let body = view(&state.db, session_user(&user), Some(row.csrf_token)).await?;
    let mut res = (StatusCode::CREATED, Json(body)).into_response();
    res.headers_mut().insert(header::SET_COOKIE, cookie);
    Ok(res)
}

/// The user named `name` if `password` is theirs and they are enabled.
/// A missing user or password costs the same argon2 verification as a
/// wrong one, so the answer's timing does not tell names apart.
async fn check_password(db: &Db, name: &str, password: String) -> Result<UserRow, ApiError> {
    // A name no user can have is not looked up (PostgreSQL refuses some,
    // NUL among them), but costs the same verification.
    let user = match crate::auth::accounts::name_fault(name) {
        Some(_) => None,
        None => db.user_by_name(name).await?,
    };
    let phc = user
        .as_ref()
        .and_then(|u| u.password_hash.clone())
        .unwrap_or_else(|| password::decoy_hash().to_string());
    let matched = off_runtime(move || password::verify(&password, &phc)).await?;
    user.filter(|u| matched && u.password_hash.is_some() && u.disabled == 0)
        .ok_or_else(|| ApiError::Unauthorized(WRONG.to_string()))
}

fn session_user(u: &UserRow) -> SessionUser {
    SessionUser {
        id: u.id.clone(),
        name: u.name.clone(),
        admin: u.admin != 0,
    }
}

/// Whether a proxy says the request came over TLS.
fn forwarded_https(headers: &HeaderMap) -> bool {
    headers
        .get("x-forwarded-proto")
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| {
            v.split(',')
                .next()
                .unwrap_or("")
                .trim()
                .eq_ignore_ascii_case("https")
        })
}

/// The `Set-Cookie` value of the session cookie (`max_age_s` 0 clears it).
fn session_cookie(value: &str, max_age_s: i64, secure: bool) -> HeaderValue {
    let secure = if secure { "; Secure" } else { "" };
    HeaderValue::from_str(&format!(
        "{SESSION_COOKIE}={value}; HttpOnly; SameSite=Strict; Path=/; Max-Age={max_age_s}{secure}"
    ))
    .expect("a session cookie is ASCII")
}

/// Who is signed in.
#[utoipa::path(
    get,
    path = "/api/v1/session",
    tag = "accounts",
    responses(
        (status = 200, description = "The caller", body = SessionView),
    )
)]
pub async fn whoami(
    State(state): State<AppState>,
    caller: Caller,
) -> Result<Json<SessionView>, ApiError> {
    let csrf_token = match &caller.via {
        Via::Session { csrf_token, .. } => Some(csrf_token.clone()),
        Via::Token => None,
    };
    let user = SessionUser {
        id: caller.user_id,
        name: caller.name,
        admin: caller.admin,
    };
    Ok(Json(view(&state.db, user, csrf_token).await?))
}

/// Sign out: the session ends and its cookie is cleared.
#[utoipa::path(
    delete,
    path = "/api/v1/session",
    tag = "accounts",
    responses(
        (status = 204, description = "Signed out; the cookie is cleared (Max-Age=0)"),
    )
)]
pub async fn sign_out(
    State(state): State<AppState>,
    headers: HeaderMap,
    caller: Caller,
) -> Result<Response, ApiError> {
    if let Via::Session { id, .. } = &caller.via {
        state.db.delete_session(id).await?;
    }
    let secure = state.cookie_secure || forwarded_https(&headers);
    let mut res = StatusCode::NO_CONTENT.into_response();
    res.headers_mut()
        .insert(header::SET_COOKIE, session_cookie("", 0, secure));
    Ok(res)
}

/// `/api/v1/session`.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(sign_in, whoami, sign_out))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cookie_attributes() {
        let c = session_cookie("ts_x", 604800, false);
        let c = c.to_str().unwrap();
        assert_eq!(
            c,
            "terraplan_session=ts_x; HttpOnly; SameSite=Strict; Path=/; Max-Age=604800"
        );
        let cleared = session_cookie("", 0, true);
        assert!(cleared.to_str().unwrap().ends_with("Max-Age=0; Secure"));
    }

    #[test]
    fn tls_is_told_by_the_proxy_header() {
        let mut h = HeaderMap::new();
        assert!(!forwarded_https(&h));
        h.insert("x-forwarded-proto", HeaderValue::from_static("HTTPS, http"));
        assert!(forwarded_https(&h));
        h.insert("x-forwarded-proto", HeaderValue::from_static("http"));
        assert!(!forwarded_https(&h));
    }
}
