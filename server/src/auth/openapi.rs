//! How the OpenAPI document states the credentials: two security schemes
//! (a bearer API token, the session cookie) required by every operation
//! that [`is_open`](super::caller::is_open) does not open, each with its
//! 401 and 403 answers. Derived from the same rule as the middleware, so
//! the document cannot drift from what the service enforces.

use axum::http::Method;
use utoipa::openapi::path::Operation;
use utoipa::openapi::response::ResponseBuilder;
use utoipa::openapi::security::{
    ApiKey, ApiKeyValue, HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme,
};
use utoipa::openapi::{ContentBuilder, OpenApi, Ref};

use super::caller::{SESSION_COOKIE, is_open};

const BEARER: &str = "bearer";
const COOKIE: &str = "session_cookie";

/// Add the security schemes, and the requirement and its answers to every
/// closed operation.
pub fn describe_credentials(doc: &mut OpenApi) {
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
    for (path, item) in doc.paths.paths.iter_mut() {
        let ops = [
            (Method::GET, &mut item.get),
            (Method::POST, &mut item.post),
            (Method::PUT, &mut item.put),
            (Method::DELETE, &mut item.delete),
            (Method::PATCH, &mut item.patch),
            (Method::HEAD, &mut item.head),
        ];
        for (method, op) in ops {
            if let Some(op) = op
                && path.starts_with("/api/v1/")
                && !is_open(&method, path)
            {
                require_credentials(op);
            }
        }
    }
}

fn require_credentials(op: &mut Operation) {
    op.security = Some(vec![
        SecurityRequirement::new(BEARER, Vec::<String>::new()),
        SecurityRequirement::new(COOKIE, Vec::<String>::new()),
    ]);
    let problem = |description: &str| {
        ResponseBuilder::new()
            .description(description)
            .content(
                "application/problem+json",
                ContentBuilder::new()
                    .schema(Some(Ref::from_schema_name("Problem")))
                    .build(),
            )
            .build()
    };
    let responses = &mut op.responses.responses;
    responses
        .entry("401".to_string())
        .or_insert_with(|| problem("No valid credentials (API token or session cookie)").into());
    responses.entry("403".to_string()).or_insert_with(|| {
        problem("The caller's role is too low for this, or a cookie-authenticated write lacks X-CSRF-Token").into()
    });
}
