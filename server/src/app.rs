//! The router: each `api` module's routes, the OpenAPI document they
//! describe, the middleware (body limits, compression, tracing, request
//! ids, CORS) and the fallbacks (problem+json 404/405 under `/api`, the
//! web page elsewhere).

use std::sync::Arc;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::extract::Request;
use axum::http::{HeaderName, HeaderValue, Method, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use tower_http::LatencyUnit;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, Any, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};
use utoipa::OpenApi;
use utoipa_axum::router::OpenApiRouter;
use utoipa_swagger_ui::SwaggerUi;

use crate::api::{
    cameras, costmaps, dems, health, imports, members, password, projects, routes, session,
    surveys, tokens, users, vehicle_links, vehicles,
};
use crate::error::ApiError;
use crate::guard::{self, AllowedHosts};
use crate::state::AppState;

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
        (name = "dems", description = "Digital elevation models: upload (GeoTIFF, ESRI ASCII grid, SRTM .hgt), metadata, hillshade preview, heights at points"),
        (name = "imports", description = "GIS file imports (zipped Shapefile, KML, KMZ, GPX, GeoJSON in any named CRS) as WGS84 GeoJSON for ROIs, no-fly zones and corridors"),
        (name = "costmaps", description = "Traversability costmaps of a DEM for a ground vehicle: background jobs with progress events, GeoTIFF, preview and per-layer files"),
        (name = "routes", description = "UGV routes across a finished costmap: the cheapest safe path (A* or D* Lite), incremental replanning around blocked areas, GeoJSON, CSV (UTM) and ArduPilot Rover missions"),
        (name = "accounts", description = "Signing in (session cookie and CSRF token, or an API token), a user's own API tokens, and users (admins)"),
        (name = "projects", description = "Projects and their members: every DEM, survey, costmap and route belongs to one; viewers read, editors also create and delete, owners also manage members"),
        (name = "vehicle-links", description = "Sending a stored survey's mission (and fence and rally points) to a vehicle over MAVLink, with progress as Server-Sent Events; switched off unless the service is started with --vehicle-links"),
        (name = "service", description = "Health"),
    ),
    components(schemas(crate::error::Problem, crate::error::IssueSchema))
)]
struct ApiDoc;

/// The OpenAPI document and the router it describes.
pub fn router(
    state: AppState,
    cors_origins: &[String],
    allowed_hosts: AllowedHosts,
    max_body_bytes: usize,
) -> Router {
    let max_dem_bytes = state.dems.max_upload_bytes;
    let (api, openapi) = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .merge(health::routes())
        .merge(surveys::routes())
        .merge(dems::routes(max_dem_bytes))
        .merge(imports::routes(max_dem_bytes))
        .merge(costmaps::routes())
        .merge(vehicles::routes())
        .merge(vehicle_links::routes())
        .merge(cameras::routes())
        .merge(routes::routes())
        .merge(session::routes())
        .merge(password::routes())
        .merge(tokens::routes())
        .merge(users::routes())
        .merge(projects::routes())
        .merge(members::routes())
        .split_for_parts();
    let mut openapi = openapi;
    crate::api::document::complete(&mut openapi);
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
        .with_state(state.clone())
        .layer(DefaultBodyLimit::max(max_body_bytes))
        .layer(middleware::from_fn(
            crate::api::names::refuse_control_characters,
        ))
        .layer(middleware::from_fn_with_state(
            state.clone(),
            crate::rate_limit::limit_rates,
        ))
        .layer(middleware::from_fn_with_state(state, crate::auth::authenticate))
        .layer(middleware::from_fn(move |req: Request, next: Next| {
            let limit = if is_dem_upload(&req) {
                max_dem_bytes
            } else {
                max_body_bytes
            };
            early_answers(req, next, limit)
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
        .layer(middleware::from_fn(guard::security_headers))
        .layer(middleware::from_fn(move |req: Request, next: Next| {
            guard::check_host(allowed_hosts.clone(), req, next)
        }))
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
        .expose_headers([
            axum::http::header::LOCATION,
            axum::http::header::CONTENT_DISPOSITION,
        ]);
    Some(if origins.iter().any(|o| o == "*") {
        // Any origin, but never with credentials (cookies): a page
        // elsewhere may call the API only with a token it holds.
        layer.allow_origin(Any).allow_headers(Any)
    } else {
        let list: Vec<HeaderValue> = origins
            .iter()
            .filter_map(|o| HeaderValue::from_str(o).ok())
            .collect();
        layer
            .allow_origin(AllowOrigin::list(list))
            .allow_headers([
                axum::http::header::CONTENT_TYPE,
                axum::http::header::AUTHORIZATION,
                HeaderName::from_static(crate::auth::caller::CSRF_HEADER),
            ])
            .allow_credentials(true)
    })
}

fn is_dem_upload(req: &Request) -> bool {
    req.method() == Method::POST && req.uri().path() == "/api/v1/dems"
}

/// Bodies declared this small (Content-Length) are read whole before the
/// handler runs.
const SMALL_BODY_BYTES: u64 = 64 * 1024;

/// Request bodies and answers given before them.
///
/// - A body whose declared Content-Length is over `limit` is refused at
///   once (DefaultBodyLimit alone only notices once that much has
///   arrived), with `Connection: close`: none of it is read.
/// - A small body is read first, so that a handler answering without it
///   (a 415 from the Content-Type, a 400 from the query) leaves nothing
///   unread and the connection stays open for the client's next request.
/// - A larger or chunked body streams to the handler; when the answer
///   comes before its end, hyper closes the connection after the answer,
///   and the answer says so (`Connection: close`). The rest of the body
///   is then read and discarded by the lingering close (`crate::linger`),
///   so the client gets the answer rather than a reset.
async fn early_answers(req: Request, next: Next, limit: usize) -> Response {
    use axum::body::{Body, HttpBody};
    let declared = crate::api::json_body::declared_length(req.headers());
    if let Some(n) = declared.filter(|&n| n > limit as u64) {
        return closing(
            ApiError::PayloadTooLarge(format!(
                "the request body is too large: {n} bytes declared, the limit is {limit} bytes"
            ))
            .into_response(),
        );
    }
    if req.body().is_end_stream() {
        return next.run(req).await;
    }
    let (parts, body) = req.into_parts();
    if let Some(n) = declared.filter(|&n| n <= SMALL_BODY_BYTES) {
        return match axum::body::to_bytes(body, n as usize).await {
            Ok(bytes) => {
                next.run(Request::from_parts(parts, Body::from(bytes)))
                    .await
            }
            Err(e) => closing(
                ApiError::BadRequest(format!("cannot read the request body: {e}")).into_response(),
            ),
        };
    }
    let ended = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let seen = ended.clone();
    let mut data = body.into_data_stream();
    let tracked = futures_util::stream::poll_fn(move |cx| {
        let next = futures_util::StreamExt::poll_next_unpin(&mut data, cx);
        if let std::task::Poll::Ready(None) = next {
            seen.store(true, std::sync::atomic::Ordering::Release);
        }
        next
    });
    let res = next
        .run(Request::from_parts(parts, Body::from_stream(tracked)))
        .await;
    if ended.load(std::sync::atomic::Ordering::Acquire) {
        res
    } else {
        closing(res)
    }
}

/// `res` with `Connection: close`: hyper closes the connection after it.
fn closing(mut res: Response) -> Response {
    res.headers_mut().insert(
        axum::http::header::CONNECTION,
        HeaderValue::from_static("close"),
    );
    res
}

/// Unknown `/api` paths are problem+json 404s; every other path is the
/// web page's.
async fn not_found(
    axum::extract::State(state): axum::extract::State<AppState>,
    req: Request,
) -> Response {
    let path = req.uri().path();
    if path == "/api" || path.starts_with("/api/") {
        return ApiError::NotFound(format!("there is no resource at {} {}", req.method(), path))
            .into_response();
    }
    state.web.serve(req).await
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
