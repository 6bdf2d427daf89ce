//! Export stage: missions and their file formats (SPEC §3.6), and
//! georeferenced Float32 and Byte rasters (costmaps, SPEC §4.2).

pub mod geoid;
pub mod geojson;
pub mod geotiff;
pub mod ground_route;
pub mod kml;
pub mod mission;
pub mod qgc_plan;
pub mod waypoints;

pub use geotiff::{Band, BandData, Page, SampleType, write_geotiff};
pub use kml::write_kml;
pub use mission::{AltitudeFrame, FencePolygon, GeoPoint, Mission, MissionItem};
pub use qgc_plan::write_plan;
pub use waypoints::{write_fence, write_waypoints};

/// `text` escaped for XML character data, without the control characters
/// XML 1.0 forbids (and NUL, which would end the TIFF ASCII value).
pub(crate) fn xml_escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&apos;"),
            '\t' | '\n' | '\r' => s.push(c),
            c if c.is_control() => {}
            c => s.push(c),
        }
    }
    s
}
