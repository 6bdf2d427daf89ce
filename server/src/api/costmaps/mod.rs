//! The costmaps resource: ask for a traversability costmap of an uploaded
//! DEM for a ground vehicle (built in the background, see [`crate::jobs`]),
//! follow its progress (polling or Server-Sent Events), list, fetch,
//! delete, and download its files: the GeoTIFF (Float32 cost page, Byte
//! class page), a PNG preview with its SVG legend, and the per-layer
//! GeoTIFFs asked for.

mod events;
mod files;
mod handlers;
mod model;
mod request;

use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub use self::handlers::visible_costmap;
pub use self::model::costmap_url;
use crate::state::AppState;

/// The costmap endpoints.
pub fn routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(handlers::create_costmap, handlers::list_costmaps))
        .routes(routes!(handlers::get_costmap, handlers::delete_costmap))
        .routes(routes!(events::costmap_events))
        .routes(routes!(files::costmap_tif))
        .routes(routes!(files::preview))
        .routes(routes!(files::legend))
        .routes(routes!(files::layer))
}
