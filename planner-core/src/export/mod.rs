//! Export stage: missions and their file formats (SPEC §3.6).

pub mod geojson;
pub mod geotiff;
pub mod kml;
pub mod mission;
pub mod qgc_plan;
pub mod waypoints;

pub use geotiff::{Band, BandData, write_geotiff_f32};
pub use kml::write_kml;
pub use mission::{AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem};
pub use qgc_plan::write_plan;
pub use waypoints::{write_fence, write_waypoints};
