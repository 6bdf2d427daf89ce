//! Rules that complete the OpenAPI document for many operations at once,
//! each derived from the code that enforces it, so the document cannot
//! drift from the service: credentials (401, 403 and the security
//! schemes), rate limits (429), and the JSON body reader's own faults (400,
//! 415).

use axum::http::Method;
use utoipa::openapi::OpenApi;
use utoipa::openapi::path::{Operation, PathItem};

use crate::auth::openapi::{add_schemes, needs_credentials, require_credentials};
use crate::error::document_answer;
use crate::rate_limit::is_rate_limited;

/// Apply every rule to `doc`.
pub fn complete(doc: &mut OpenApi) {
    add_schemes(doc);
    for (path, item) in doc.paths.paths.iter_mut() {
        for (method, op) in operations(item) {
            if needs_credentials(&method, path) {
                require_credentials(op);
            }
            if is_rate_limited(&method, path) {
                document_answer(
                    op,
                    429,
                    "Too many requests of this kind from this user or address: see Retry-After",
                );
            }
            if takes_json(op) {
                document_answer(op, 400, "The body is not well-formed JSON");
                document_answer(op, 415, "The body is not sent as application/json");
            }
        }
    }
}

/// The operations of a path, with their methods.
fn operations(item: &mut PathItem) -> impl Iterator<Item = (Method, &mut Operation)> {
    [
        (Method::GET, item.get.as_mut()),
        (Method::POST, item.post.as_mut()),
        (Method::PUT, item.put.as_mut()),
        (Method::DELETE, item.delete.as_mut()),
        (Method::PATCH, item.patch.as_mut()),
        (Method::HEAD, item.head.as_mut()),
    ]
    .into_iter()
    .filter_map(|(method, op)| op.map(|op| (method, op)))
}

/// Whether an operation's body is read as JSON (by `JsonBody`).
fn takes_json(op: &Operation) -> bool {
    op.request_body.as_ref().is_some_and(|body| match body {
        utoipa::openapi::RefOr::T(body) => body.content.contains_key("application/json"),
        utoipa::openapi::RefOr::Ref(_) => false,
    })
}
