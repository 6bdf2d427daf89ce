//! Export stage: missions and their file formats (SPEC §3.6). Rasters
//! (costmap GeoTIFFs) are written by [`crate::terrain::geotiff`].

pub mod geoid;
pub mod geojson;
pub mod ground_route;
pub mod kml;
pub mod litchi;
pub mod mission;
pub mod qgc_plan;
pub mod waypoints;
pub mod wpml;
pub mod wpml_route;

pub use kml::write_kml;
pub use mission::{AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem};
pub use qgc_plan::write_plan;
pub use waypoints::{write_fence, write_waypoints};
