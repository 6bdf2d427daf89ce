//! One error type for the HTTP API, rendered as RFC 9457
//! `application/problem+json`.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use planner_core::cancel::Cancelled;
use planner_core::geo::Issue;
use planner_core::route::RouteError;
use planner_core::survey::PlanError;
use planner_core::terrain::TerrainError;
use serde::Serialize;
use utoipa::ToSchema;

pub const PROBLEM_JSON: &str = "application/problem+json";

#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    /// The request is well-formed but invalid: 422 with one entry per fault.
    #[error("invalid request")]
    Validation(Vec<Issue>),
    /// Malformed request (e.g. JSON syntax): 400.
    #[error("{0}")]
    BadRequest(String),
    /// No valid credentials: 401 with `WWW-Authenticate: Bearer`.
    #[error("{0}")]
    Unauthorized(String),
    /// Valid credentials, too little right (a role, not admin, no CSRF token): 403.
    #[error("{0}")]
    Forbidden(String),
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    MethodNotAllowed(String),
    /// The resource is not in a state to answer (e.g. a job still running): 409.
    #[error("{0}")]
    Conflict(String),
    /// The request body arrived too slowly: 408.
    #[error("{0}")]
    RequestTimeout(String),
    #[error("{0}")]
    PayloadTooLarge(String),
    #[error("{0}")]
    UnsupportedMediaType(String),
    /// The planner is saturated: 503, try again.
    #[error("{0}")]
    Unavailable(String),
    /// A rate limit: 429 with `Retry-After` (whole seconds).
    #[error("{message}")]
    TooManyRequests { message: String, retry_after_s: u64 },
    /// A bug: 500. The detail is logged; the client gets a generic message.
    #[error("{0}")]
    Internal(String),
}

/// The problem document (RFC 9457) every error response carries.
#[derive(Debug, Serialize, serde::Deserialize, ToSchema)]
pub struct Problem {
    /// A URI reference naming the problem type ("about:blank": see `title`).
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary of the problem type (the HTTP reason phrase).
    pub title: String,
    /// HTTP status code.
    pub status: u16,
    /// What went wrong with this request, in plain words.
    pub detail: String,
    /// For validation errors: every fault, with the JSON pointer of the
    /// request member at fault.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schema(value_type = Vec<IssueSchema>)]
    pub errors: Vec<Issue>,
}

/// One validation fault.
#[derive(ToSchema)]
#[allow(dead_code)] // documents the shape of `Issue` for the OpenAPI schema
pub struct IssueSchema {
    /// JSON pointer (RFC 6901) of the member at fault; "" for the whole body.
    pointer: String,
    message: String,
}

/// The 404 of a resource that does not exist: `kind` names it ("DEM",
/// "costmap", "survey", "route").
pub fn not_found(kind: &str, id: &str) -> ApiError {
    ApiError::NotFound(format!("there is no {kind} with id {id:?}"))
}

/// The resource a lookup found, or the 404 of [`not_found`].
pub fn found<T>(row: Option<T>, kind: &str, id: &str) -> Result<T, ApiError> {
    row.ok_or_else(|| not_found(kind, id))
}

/// `Ok` when a resource was deleted, the 404 of [`not_found`] when there
/// was none.
pub fn deleted(deleted: bool, kind: &str, id: &str) -> Result<StatusCode, ApiError> {
    if deleted {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(not_found(kind, id))
    }
}

impl ApiError {
    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::Validation(_) => StatusCode::UNPROCESSABLE_ENTITY,
            ApiError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::Forbidden(_) => StatusCode::FORBIDDEN,
            ApiError::NotFound(_) => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed(_) => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::Conflict(_) => StatusCode::CONFLICT,
            ApiError::RequestTimeout(_) => StatusCode::REQUEST_TIMEOUT,
            ApiError::PayloadTooLarge(_) => StatusCode::PAYLOAD_TOO_LARGE,
            ApiError::UnsupportedMediaType(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::TooManyRequests { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    pub fn problem(&self) -> Problem {
        let status = self.status();
        let (detail, errors) = match self {
            ApiError::Validation(issues) => {
                let detail = match issues.as_slice() {
                    [one] => one.to_string(),
                    many => format!("{} problems in the request; see errors", many.len()),
                };
                let issues = planner_core::geo::cap_issues(issues.clone());
                (detail, issues)
            }
            ApiError::Internal(_) => (
                "the server failed to handle this request; it has been logged".to_string(),
                vec![],
            ),
            other => (other.to_string(), vec![]),
        };
        Problem {
            kind: "about:blank".to_string(),
            title: status.canonical_reason().unwrap_or("Error").to_string(),
            status: status.as_u16(),
            detail,
            errors,
        }
    }
}

/// A problem+json answer as the OpenAPI document lists it, for the rules
/// that add answers to many operations at once (credentials, rate limits,
/// JSON bodies).
pub fn documented_problem(description: &str) -> utoipa::openapi::RefOr<utoipa::openapi::Response> {
    utoipa::openapi::response::ResponseBuilder::new()
        .description(description)
        .content(
            PROBLEM_JSON,
            utoipa::openapi::ContentBuilder::new()
                .schema(Some(utoipa::openapi::Ref::from_schema_name("Problem")))
                .build(),
        )
        .build()
        .into()
}

/// Add `status` with `description` to an operation's answers, unless the
/// operation documents that status itself.
pub fn document_answer(op: &mut utoipa::openapi::path::Operation, status: u16, description: &str) {
    op.responses
        .responses
        .entry(status.to_string())
        .or_insert_with(|| documented_problem(description));
}

/// The problem document of an answer `status` with `detail`, serialised
/// (for answers made outside the router, as hyper's parse errors).
pub fn problem_body(status: StatusCode, detail: String) -> Vec<u8> {
    let problem = Problem {
        kind: "about:blank".to_string(),
        title: status.canonical_reason().unwrap_or("Error").to_string(),
        status: status.as_u16(),
        detail,
        errors: vec![],
    };
    serde_json::to_vec(&problem).unwrap_or_default()
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if let ApiError::Internal(m) = &self {
            tracing::error!(error = %m, "internal error");
        }
        let status = self.status();
        let body = serde_json::to_vec(&self.problem()).unwrap_or_default();
        let mut res = (status, body).into_response();
        res.headers_mut()
            .insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        match &self {
            ApiError::Unavailable(_) => {
                res.headers_mut()
                    .insert(header::RETRY_AFTER, HeaderValue::from_static("5"));
            }
            ApiError::TooManyRequests { retry_after_s, .. } => {
                res.headers_mut()
                    .insert(header::RETRY_AFTER, HeaderValue::from(*retry_after_s));
            }
            ApiError::Unauthorized(_) => {
                res.headers_mut().insert(
                    header::WWW_AUTHENTICATE,
                    HeaderValue::from_static("Bearer realm=\"terraplan\""),
                );
            }
            _ => {}
        }
        res
    }
}

/// Work stopped by its token: a 503. The client that went away never
/// reads it; a time limit is named by the caller where it knows the flag.
impl From<Cancelled> for ApiError {
    fn from(c: Cancelled) -> Self {
        ApiError::Unavailable(match c {
            Cancelled::Stopped => "the request was cancelled".to_string(),
            Cancelled::TimedOut { .. } => format!("{c}: retry when the service is less busy"),
        })
    }
}

impl From<PlanError> for ApiError {
    fn from(e: PlanError) -> Self {
        match e {
            PlanError::Invalid(issues) => ApiError::Validation(issues),
            PlanError::Internal(m) => ApiError::Internal(m),
            PlanError::Cancelled(c) => c.into(),
        }
    }
}

/// A raster of the request that cannot be read: the client's fault (422,
/// or 413 over the pixel limits).
impl From<TerrainError> for ApiError {
    fn from(e: TerrainError) -> Self {
        let invalid = |m: String| ApiError::Validation(vec![Issue::new("", &m)]);
        match e {
            TerrainError::TooLarge { .. } => {
                ApiError::PayloadTooLarge(format!("the DEM is too large: {e}"))
            }
            TerrainError::UnknownCrs(why) => invalid(format!(
                "the raster's coordinate reference system cannot be determined ({why}): give it \
                 in the query string, e.g. ?crs=EPSG:32633"
            )),
            TerrainError::Invalid(m) => invalid(format!("the file cannot be read as a DEM: {m}")),
            TerrainError::Unsupported(m) => invalid(format!(
                "the DEM uses a feature terraplan does not read: {m}"
            )),
            TerrainError::Crs(m) => invalid(format!("coordinate reference system: {m}")),
            TerrainError::Cancelled(c) => c.into(),
        }
    }
}

/// A failed route search, for the faults that need no context: invalid
/// options are the request's (422), the rest a bug (500). The handler
/// names the faults of the start, the goal and a cancellation itself,
/// since their pointers and messages depend on the request.
impl From<RouteError> for ApiError {
    fn from(e: RouteError) -> Self {
        match e {
            RouteError::InvalidOptions(issues) => ApiError::Validation(issues),
            other => ApiError::Internal(format!("route search: {other}")),
        }
    }
}

impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> Self {
        ApiError::Internal(format!("database: {e}"))
    }
}
