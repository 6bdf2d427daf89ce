//! Answers that never change (a DEM's hillshade, a finished costmap's
//! files): an ETag, a year-long immutable Cache-Control, and 304 Not
//! Modified when the client already has them.

use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};

/// An immutable answer, known by its ETag.
pub struct Immutable {
    etag: String,
}

impl Immutable {
    /// `etag` is the quoted entity tag.
    pub fn new(etag: String) -> Immutable {
        Immutable { etag }
    }

    /// True when the request's If-None-Match names this answer (or `*`).
    pub fn matches(&self, request: &HeaderMap) -> bool {
        request
            .get_all(header::IF_NONE_MATCH)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .flat_map(|v| v.split(','))
            .any(|t| t.trim() == self.etag || t.trim() == "*")
    }

    /// 304 Not Modified, with the cache headers.
    pub fn not_modified(&self) -> Response {
        let mut res = StatusCode::NOT_MODIFIED.into_response();
        self.apply(&mut res);
        res
    }

    /// Add the ETag and Cache-Control headers to `res`.
    pub fn apply(&self, res: &mut Response) {
        let h = res.headers_mut();
        if let Ok(v) = HeaderValue::from_str(&self.etag) {
            h.insert(header::ETAG, v);
        }
        h.insert(
            header::CACHE_CONTROL,
            HeaderValue::from_static("public, max-age=31536000, immutable"),
        );
    }
}
