//! The DEMs resource: upload an elevation raster (GeoTIFF, ESRI ASCII grid
//! or SRTM `.hgt`), list, fetch its metadata, delete, render a hillshade
//! preview and read heights at WGS84 points.

mod download;
mod handlers;
mod header;
mod model;
mod upload;

pub(crate) use upload::{multipart_error, too_large};

use axum::extract::DefaultBodyLimit;
use utoipa_axum::router::{OpenApiRouter, UtoipaMethodRouterExt};
use utoipa_axum::routes;

pub(crate) use self::model::stored_info as stored_dem_info;
pub use self::model::{BinaryFile, dem_fault, parse_epsg, visible_dem};
use crate::state::AppState;

/// The DEM endpoints; uploads have their own body limit, `max_dem_bytes`.
pub fn routes(max_dem_bytes: usize) -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(
            routes!(upload::upload_dem, handlers::list_dems)
                .layer(DefaultBodyLimit::max(max_dem_bytes)),
        )
        .routes(routes!(handlers::get_dem, handlers::delete_dem))
        .routes(routes!(handlers::hillshade))
        .routes(routes!(handlers::window))
        .routes(routes!(download::download_dem))
        .routes(routes!(handlers::elevation, handlers::elevations))
}
