//! The caller of a request: credentials (a bearer API token, or the web
//! page's session cookie) checked once per request by [`authenticate`],
//! and the [`Caller`] handlers take as an extractor.

use axum::extract::{FromRequestParts, Request, State};
use axum::http::request::Parts;
use axum::http::{HeaderMap, Method, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq;

use super::secret::{self, SESSION_PREFIX, TOKEN_PREFIX};
use crate::clock::now_millis;
use crate::db::{Db, UserRow};
use crate::error::ApiError;
use crate::state::AppState;

/// The name of the web page's session cookie.
pub const SESSION_COOKIE: &str = "terraplan_session";
/// The header a cookie-authenticated write must carry.
pub const CSRF_HEADER: &str = "x-csrf-token";
/// A session ends this long after its last use …
pub const SESSION_IDLE_MS: i64 = 12 * 3600 * 1000;
/// … and this long after sign-in at the latest.
pub const SESSION_MAX_MS: i64 = 7 * 24 * 3600 * 1000;
/// Last-use times are written at most this often per token or session, so
/// reads do not each become a write.
const TOUCH_EVERY_MS: i64 = 60 * 1000;

/// Compared against when there is no stored secret, so a missing row
/// costs the same comparison as a wrong secret.
const NO_HASH: &str = "0000000000000000000000000000000000000000000000000000000000000000";

/// Who is calling: a signed-in, enabled user.
#[derive(Clone, Debug)]
pub struct Caller {
    pub user_id: String,
    pub name: String,
    pub admin: bool,
    /// How the caller signed in.
    pub via: Via,
}

/// The credentials of a request.
#[derive(Clone, Debug)]
pub enum Via {
    /// `Authorization: Bearer tp_…`.
    Token,
    /// The session cookie: the session's id and its CSRF token.
    Session { id: String, csrf_token: String },
}

impl Caller {
    fn from_user(user: UserRow, via: Via) -> Caller {
        Caller {
            user_id: user.id,
            name: user.name,
            admin: user.admin != 0,
            via,
        }
    }

    /// 403 unless the caller is an admin.
    pub fn require_admin(&self) -> Result<(), ApiError> {
        if self.admin {
            Ok(())
        } else {
            Err(ApiError::Forbidden(
                "only an admin may manage users".to_string(),
            ))
        }
    }
}

/// The `/api/v1` routes open without credentials: the OpenAPI document,
/// signing in, and the static catalogues of vehicles and cameras.
pub(crate) fn is_open(method: &Method, path: &str) -> bool {
    matches!(
        (method.as_str(), path),
        (
            "GET" | "HEAD",
            "/api/v1/openapi.json" | "/api/v1/openapi-ui.json"
        ) | ("GET" | "HEAD", "/api/v1/vehicles" | "/api/v1/cameras")
            | ("POST", "/api/v1/session")
    ) || method == Method::OPTIONS
}

/// Middleware: under `/api/v1`, find the caller from the request's
/// credentials and keep it in the request's extensions; answer 401 when a
/// closed route has no valid credentials, 403 when a cookie-authenticated
/// write lacks its CSRF token.
pub async fn authenticate(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    let path = req.uri().path();
    if !path.starts_with("/api/v1/") && path != "/api/v1" {
        return next.run(req).await;
    }
    let open = is_open(req.method(), path);
    match caller_of(&state.db, req.method(), req.headers()).await {
        Ok(Some(caller)) => {
            req.extensions_mut().insert(caller);
            next.run(req).await
        }
        // An open route needs no credentials, so stale ones (an ended
        // session's cookie, say) must not keep anyone from signing in.
        Ok(None) | Err(_) if open => next.run(req).await,
        Ok(None) => unauthorized().into_response(),
        Err(e) => e.into_response(),
    }
}

fn unauthorized() -> ApiError {
    ApiError::Unauthorized(
        "sign in first: send \"Authorization: Bearer <API token>\" or the session cookie of \
         POST /api/v1/session"
            .to_string(),
    )
}

/// The caller named by a request's credentials; `None` when it carries
/// none. Credentials that are present but wrong, expired or of a disabled
/// user are a 401 at once, never a fall-back to none.
async fn caller_of(
    db: &Db,
    method: &Method,
    headers: &HeaderMap,
) -> Result<Option<Caller>, ApiError> {
    if let Some(value) = headers.get(header::AUTHORIZATION) {
        let token = value
            .to_str()
            .ok()
            .and_then(|v| v.strip_prefix("Bearer "))
            .map(str::trim)
            .ok_or_else(|| {
                ApiError::Unauthorized(
                    "the Authorization header must be \"Bearer <API token>\"".to_string(),
                )
            })?;
        return token_caller(db, token).await.map(Some);
    }
    let Some(cookie) = session_cookie(headers) else {
        return Ok(None);
    };
    let caller = session_caller(db, cookie).await?;
    if is_write(method)
        && let Via::Session { csrf_token, .. } = &caller.via
    {
        let sent = headers
            .get(CSRF_HEADER)
            .map(|v| v.as_bytes())
            .unwrap_or_default();
        if !bool::from(sent.ct_eq(csrf_token.as_bytes())) {
            return Err(ApiError::Forbidden(
                "a write signed in by the session cookie must send the session's csrf_token in \
                 the X-CSRF-Token header"
                    .to_string(),
            ));
        }
    }
    Ok(Some(caller))
}

fn is_write(method: &Method) -> bool {
    !matches!(*method, Method::GET | Method::HEAD | Method::OPTIONS)
}

/// The value of the session cookie, if the request has one.
pub fn session_cookie(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|pair| pair.trim().split_once('='))
        .find(|(name, _)| *name == SESSION_COOKIE)
        .map(|(_, value)| value.trim())
}

/// The caller of a bearer API token.
pub async fn token_caller(db: &Db, token: &str) -> Result<Caller, ApiError> {
    let refused = || {
        ApiError::Unauthorized(
            "the API token is not valid (unknown, revoked, expired or of a disabled user)"
                .to_string(),
        )
    };
    let (id, secret) = secret::parse(TOKEN_PREFIX, token).ok_or_else(refused)?;
    let row = db.token_by_id(id).await?;
    // Compare against a hash even when there is no such token, so the
    // answer takes as long either way.
    let stored = row.as_ref().map_or(NO_HASH, |r| r.secret_hash.as_str());
    let matched = secret::matches(secret, stored);
    let row = row.filter(|_| matched).ok_or_else(refused)?;
    let now = now_millis();
    if row.expires_at.is_some_and(|t| t <= now) {
        return Err(refused());
    }
    let user = enabled_user(db, &row.user_id).await?.ok_or_else(refused)?;
    if row.last_used_at.is_none_or(|t| now - t >= TOUCH_EVERY_MS) {
        db.touch_token(&row.id, now).await?;
    }
    Ok(Caller::from_user(user, Via::Token))
}

async fn session_caller(db: &Db, cookie: &str) -> Result<Caller, ApiError> {
    let refused = || ApiError::Unauthorized("the session has ended: sign in again".to_string());
    let (id, secret) = secret::parse(SESSION_PREFIX, cookie).ok_or_else(refused)?;
    let row = db.session_by_id(id).await?;
    let stored = row.as_ref().map_or(NO_HASH, |r| r.secret_hash.as_str());
    let matched = secret::matches(secret, stored);
    let row = row.filter(|_| matched).ok_or_else(refused)?;
    let now = now_millis();
    if row.expires_at <= now || now - row.last_used_at >= SESSION_IDLE_MS {
        db.delete_session(&row.id).await?;
        return Err(refused());
    }
    let user = enabled_user(db, &row.user_id).await?.ok_or_else(refused)?;
    if now - row.last_used_at >= TOUCH_EVERY_MS {
        db.touch_session(&row.id, now).await?;
    }
    Ok(Caller::from_user(
        user,
        Via::Session {
            id: row.id,
            csrf_token: row.csrf_token,
        },
    ))
}

async fn enabled_user(db: &Db, id: &str) -> Result<Option<UserRow>, ApiError> {
    Ok(db.user_by_id(id).await?.filter(|u| u.disabled == 0))
}

/// Handlers take the caller as an argument; on a route that `authenticate`
/// closes it is always there, on an open one it is a 401 when absent.
impl<S: Send + Sync> FromRequestParts<S> for Caller {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _state: &S) -> Result<Self, Self::Rejection> {
        parts
            .extensions
            .get::<Caller>()
            .cloned()
            .ok_or_else(unauthorized)
    }
}
