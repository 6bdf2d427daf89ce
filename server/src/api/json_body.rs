//! Request body extraction with problem+json errors: the content type must
//! be JSON (415 otherwise), the body within the size limit (413), and the
//! JSON well-formed (400 naming line and column).

use axum::body::Bytes;
use axum::extract::{FromRequest, Request};
use axum::http::header;
use serde_json::Value;

use crate::error::ApiError;

/// A JSON request body as a `serde_json::Value`, validated further by the
/// handler (so faults are reported with JSON pointers).
pub struct JsonBody(pub Value);

impl<S: Send + Sync> FromRequest<S> for JsonBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, Self::Rejection> {
        let (content_type, essence) = media_type(req.headers());
        if !(essence == "application/json"
            || (essence.starts_with("application/") && essence.ends_with("+json")))
        {
            return Err(ApiError::UnsupportedMediaType(if content_type.is_empty() {
                "the request has no Content-Type: send the body as application/json".to_string()
            } else {
                format!(
                    "Content-Type {content_type:?} is not supported: send the body as application/json"
                )
            }));
        }
        let bytes = Bytes::from_request(req, state).await.map_err(|e| {
            if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::PayloadTooLarge(format!(
                    "the request body is too large: {}",
                    e.body_text()
                ))
            } else {
                ApiError::BadRequest(format!("cannot read the request body: {}", e.body_text()))
            }
        })?;
        if bytes.is_empty() {
            return Err(ApiError::BadRequest(
                "the request body is empty: a JSON object is expected".into(),
            ));
        }
        serde_json::from_slice(&bytes)
            .map(JsonBody)
            .map_err(|e| ApiError::BadRequest(format!("the request body is not valid JSON: {e}")))
    }
}

/// A request's Content-Type as sent, and its essence (type/subtype,
/// lower-case, without parameters); both empty when there is none.
pub fn media_type(headers: &axum::http::HeaderMap) -> (String, String) {
    let content_type = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_string();
    let essence = content_type
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    (content_type, essence)
}

/// A request's declared body length (`Content-Length`), if it has one.
pub fn declared_length(headers: &axum::http::HeaderMap) -> Option<u64> {
    headers
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}
