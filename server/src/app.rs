//! The application: shared state, the router with its middleware, and the
//! OpenAPI document generated from the handlers.

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::extract::Request;
use axum::http::{HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use planner_core::geo::Limits;
use tokio::sync::Semaphore;
use tower_http::LatencyUnit;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;
use utoipa_swagger_ui::SwaggerUi;

use crate::api::{health, surveys};
use crate::db::Db;
use crate::error::ApiError;

/// How long a request waits for a free planner before a 503.
const PLANNER_QUEUE_TIMEOUT: Duration = Duration::from_secs(120);

#[derive(Clone)]
pub struct AppState {
    pub db: Db,
    pub limits: Limits,
    /// Bounds the plans computed at once, so a burst of heavy requests
    /// queues instead of exhausting the blocking pool and memory.
    pub planner: Arc<Semaphore>,
}

impl AppState {
    /// Run CPU-heavy planning off the async runtime, at most
    /// `planner_threads` at a time.
    pub async fn run_planner<T: Send + 'static>(
        &self,
        job: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ApiError> {
        let permit =
            tokio::time::timeout(PLANNER_QUEUE_TIMEOUT, self.planner.clone().acquire_owned())
                .await
                .map_err(|_| {
                    ApiError::Unavailable("the planner is busy: retry in a moment".into())
                })?
                .map_err(|_| ApiError::Unavailable("the service is shutting down".into()))?;
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            job()
        })
        .await
        .map_err(|e| ApiError::Internal(format!("planner task failed: {e}")))
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "terraplan",
        description = "Mission planning for UAV survey flocks and ground robots. Geometry is GeoJSON \
                       (RFC 7946, WGS84 lon/lat); units are metres, seconds, degrees and m/s. Errors \
                       are RFC 9457 application/problem+json."
    ),
    tags(
        (name = "surveys", description = "Photo-survey planning: decomposition, lawnmower paths, missions"),
        (name = "service", description = "Health"),
    ),
    components(schemas(crate::error::Problem, crate::error::IssueSchema))
)]
struct ApiDoc;

/// The OpenAPI document and the router it describes.
pub fn router(state: AppState, cors_origins: &[String], max_body_bytes: usize) -> Router {
    let (api, openapi) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(health::healthz))
        .routes(routes!(surveys::create_survey, surveys::list_surveys))
        .routes(routes!(surveys::get_survey, surveys::delete_survey))
        .routes(routes!(surveys::uav_file))
        .routes(routes!(surveys::cells_file))
        .split_for_parts();
    let openapi = Arc::new(openapi);
    let doc = openapi.clone();
    let request_id = HeaderName::from_static("x-request-id");

    let mut app = api
        .route(
            "/api/v1/openapi.json",
            axum::routing::get(move || {
                let doc = doc.clone();
                async move { axum::Json(doc.as_ref().clone()) }
            }),
        )
        .merge(SwaggerUi::new("/api/docs").url("/api/v1/openapi-ui.json", openapi.as_ref().clone()))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .with_state(state)
        .layer(DefaultBodyLimit::max(max_body_bytes))
        .layer(middleware::from_fn(move |req: Request, next: Next| {
            reject_declared_oversize(req, next, max_body_bytes)
        }))
        .layer(CompressionLayer::new())
        .layer(CatchPanicLayer::custom(panic_response))
        .layer(
            TraceLayer::new_for_http().make_span_with(|req: &Request| {
                let id = req
                    .headers()
                    .get("x-request-id")
                    .and_then(|v| v.to_str().ok())
                    .unwrap_or("-");
                tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %id)
            })
            .on_response(DefaultOnResponse::new().level(tracing::Level::INFO).latency_unit(LatencyUnit::Millis)),
        )
        .layer(PropagateRequestIdLayer::new(request_id.clone()))
        .layer(SetRequestIdLayer::new(request_id, MakeRequestUuid));
    if let Some(cors) = cors_layer(cors_origins) {
        app = app.layer(cors);
    }
    app
}

fn cors_layer(origins: &[String]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    let layer = CorsLayer::new()
        .allow_methods([Method::GET, Method::POST, Method::DELETE])
        .allow_headers(Any)
        .expose_headers([
            axum::http::header::LOCATION,
            axum::http::header::CONTENT_DISPOSITION,
        ]);
    Some(if origins.iter().any(|o| o == "*") {
        layer.allow_origin(Any)
    } else {
        let list: Vec<HeaderValue> = origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        layer.allow_origin(AllowOrigin::list(list))
    })
}

/// Refuse a body whose declared Content-Length is over the limit before
/// reading any of it (DefaultBodyLimit alone only notices once that much
/// has arrived).
async fn reject_declared_oversize(req: Request, next: Next, limit: usize) -> Response {
    let declared = req
        .headers()
        .get(axum::http::header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    match declared {
        Some(n) if n > limit as u64 => ApiError::PayloadTooLarge(format!(
            "the request body is too large: {n} bytes declared, the limit is {limit} bytes"
        ))
        .into_response(),
        _ => next.run(req).await,
    }
}

async fn not_found(req: Request) -> ApiError {
    ApiError::NotFound(format!(
        "there is no resource at {} {}",
        req.method(),
        req.uri().path()
    ))
}

async fn method_not_allowed(req: Request) -> ApiError {
    ApiError::MethodNotAllowed(format!(
        "{} is not allowed on {}",
        req.method(),
        req.uri().path()
    ))
}

fn panic_response(_: Box<dyn std::any::Any + Send + 'static>) -> Response {
    let e = ApiError::Internal("a handler panicked".into());
    let mut res = e.into_response();
    *res.status_mut() = StatusCode::INTERNAL_SERVER_ERROR;
    res
}
