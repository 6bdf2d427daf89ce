//! How the OpenAPI document states the credentials: two security schemes
//! (a bearer API token, the session cookie) required by every operation
//! that [`is_open`](super::caller::is_open) does not open, each with its
//! 401 and 403 answers. Derived from the same rule as the middleware, so
//! the document cannot drift from what the service enforces.

use axum::http::Method;
use utoipa::openapi::OpenApi;
use utoipa::openapi::path::Operation;
use utoipa::openapi::security::{
    ApiKey, ApiKeyValue, HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme,
};

use super::caller::{SESSION_COOKIE, is_open};
use crate::error::document_answer;

const BEARER: &str = "bearer";
const COOKIE: &str = "session_cookie";

/// Add the two security schemes to the document's components.
pub fn add_schemes(doc: &mut OpenApi) {
    let components = doc.components.get_or_insert_with(Default::default);
    components.add_security_scheme(
        BEARER,
        SecurityScheme::Http(
            HttpBuilder::new()
                .scheme(HttpAuthScheme::Bearer)
                .bearer_format("tp_…")
                .description(Some(
                    "An API token (`terraplan user create`, `terraplan user token`, or POST /api/v1/tokens)",
                ))
                .build(),
        ),
    );
    components.add_security_scheme(
        COOKIE,
        SecurityScheme::ApiKey(ApiKey::Cookie(ApiKeyValue::with_description(
            SESSION_COOKIE,
            "The web page's session (POST /api/v1/session); writes also need the X-CSRF-Token header",
        ))),
    );
}

/// Whether the operation `method path` (a path template) needs credentials.
pub fn needs_credentials(method: &Method, path: &str) -> bool {
    path.starts_with("/api/v1/") && !is_open(method, path)
}

/// State that an operation needs credentials, and its 401 and 403.
pub fn require_credentials(op: &mut Operation) {
    // Only the bearer token is stated as the requirement: it is what
    // programs use. The page's cookie is described as a scheme, but a
    // client given the choice (a contract tester) would otherwise send a
    // cookie it cannot have.
    op.security = Some(vec![SecurityRequirement::new(BEARER, Vec::<String>::new())]);
    document_answer(
        op,
        401,
        "No valid credentials (API token or session cookie)",
    );
    document_answer(
        op,
        403,
        "The caller's role is too low for this, or a cookie-authenticated write lacks X-CSRF-Token",
    );
}
