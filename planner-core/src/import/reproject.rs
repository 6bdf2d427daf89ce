//! Reprojection of imported coordinates from the file's CRS (WKT, an EPSG
//! code or an OGC URN) to WGS84 lon/lat through PROJ.

use geo::MapCoords;
use geo_types::{Coord, Geometry};
use proj::Proj;

use super::ImportError;

/// A transformation from one CRS to WGS84 lon/lat, or none when the source
/// already is WGS84 lon/lat.
pub struct ToWgs84 {
    proj: Option<Proj>,
}

impl std::fmt::Debug for ToWgs84 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(if self.proj.is_some() {
            "ToWgs84(PROJ)"
        } else {
            "ToWgs84(identity)"
        })
    }
}

impl ToWgs84 {
    /// No transformation: the coordinates are WGS84 lon/lat.
    pub fn identity() -> Self {
        ToWgs84 { proj: None }
    }

    /// From the CRS `definition` (WKT as in a `.prj`, `EPSG:28992`,
    /// `urn:ogc:def:crs:EPSG::28992`, …) to WGS84. PROJ's axis order is
    /// normalised, so inputs are easting/northing or lon/lat.
    pub fn from_definition(definition: &str) -> Result<Self, ImportError> {
        let definition = definition.trim();
        if is_wgs84_lonlat(definition) {
            return Ok(Self::identity());
        }
        let short: String = definition.chars().take(80).collect();
        Proj::new_known_crs(definition, "EPSG:4326", None)
            .map(|p| ToWgs84 { proj: Some(p) })
            .map_err(|e| ImportError::Crs(format!("unknown CRS {short:?}: {e}")))
    }

    /// `geometry` in WGS84; a point PROJ cannot transform becomes
    /// infinite, which the feature check reports.
    pub fn geometry(&self, geometry: Geometry<f64>) -> Geometry<f64> {
        let Some(proj) = &self.proj else {
            return geometry;
        };
        geometry.map_coords(|c| match proj.convert((c.x, c.y)) {
            Ok((x, y)) => Coord { x, y },
            Err(_) => Coord {
                x: f64::INFINITY,
                y: f64::INFINITY,
            },
        })
    }
}

/// Names PROJ would map to WGS84 lon/lat (GeoJSON's own CRS): no need to
/// transform, and no rounding from a round trip.
fn is_wgs84_lonlat(definition: &str) -> bool {
    let d = definition.to_ascii_uppercase();
    matches!(
        d.as_str(),
        "URN:OGC:DEF:CRS:OGC:1.3:CRS84" | "URN:OGC:DEF:CRS:OGC::CRS84" | "OGC:CRS84" | "CRS84"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::Point;

    #[test]
    fn rd_new_to_wgs84() {
        // Amersfoort's Onze Lieve Vrouwetoren, the origin of EPSG:28992
        // (x 155000, y 463000): 5.38720621°E, 52.15517440°N by RDNAPTRANS.
        // Without its grid PROJ uses the 7-parameter Helmert shift, within
        // about 0.25 m of it (5e-6° is some 0.35 m east, 0.55 m north).
        let t = ToWgs84::from_definition("urn:ogc:def:crs:EPSG::28992").unwrap();
        let Geometry::Point(p) = t.geometry(Point::new(155_000.0, 463_000.0).into()) else {
            panic!("a point stays a point");
        };
        assert!((p.x() - 5.387_206_21).abs() < 5e-6, "{p:?}");
        assert!((p.y() - 52.155_174_40).abs() < 5e-6, "{p:?}");
    }

    #[test]
    fn crs84_is_identity_and_unknown_crs_is_named() {
        let t = ToWgs84::from_definition("urn:ogc:def:crs:OGC:1.3:CRS84").unwrap();
        assert!(t.proj.is_none());
        let e = ToWgs84::from_definition("EPSG:999999").unwrap_err();
        assert!(e.to_string().contains("unknown CRS \"EPSG:999999\""), "{e}");
    }
}
