//! WGS84 ⇄ UTM through PROJ (SPEC §2: plan in metres in the UTM zone of the
//! ROI centroid).

use geo_types::{Coord, MultiPolygon, Polygon};
use proj::Proj;

use super::GeoError;

/// Half-width (degrees of longitude) of the band around a zone's central
/// meridian in which we accept geometry. A zone is 6° wide; transverse
/// Mercator stays accurate (scale error < 0.1 %) a little beyond its edge,
/// and 4° keeps an ROI that straddles a zone border usable.
pub const MAX_OFFSET_FROM_CENTRAL_MERIDIAN_DEG: f64 = 4.0;

/// A UTM zone and the PROJ transformations into and out of it.
pub struct UtmProjection {
    zone: u8,
    north: bool,
    forward: Proj,
    inverse: Proj,
}

impl std::fmt::Debug for UtmProjection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "UtmProjection(EPSG:{})", self.epsg())
    }
}

impl UtmProjection {
    /// The zone containing `lonlat` (WGS84 degrees). UTM covers 80°S–84°N.
    pub fn for_lonlat(lonlat: Coord<f64>) -> Result<Self, GeoError> {
        if !(-80.0..=84.0).contains(&lonlat.y) {
            return Err(GeoError::OutsideUtm { lat: lonlat.y });
        }
        let zone = (((lonlat.x + 180.0) / 6.0).floor() as i32).clamp(0, 59) as u8 + 1;
        Self::new(zone, lonlat.y >= 0.0)
    }

    /// UTM zone `zone` (1–60), northern or southern hemisphere.
    pub fn new(zone: u8, north: bool) -> Result<Self, GeoError> {
        let epsg = utm_epsg(zone, north);
        let target = format!("EPSG:{epsg}");
        let forward = Proj::new_known_crs("EPSG:4326", &target, None)
            .map_err(|e| GeoError::Projection(e.to_string()))?;
        let inverse = Proj::new_known_crs(&target, "EPSG:4326", None)
            .map_err(|e| GeoError::Projection(e.to_string()))?;
        Ok(UtmProjection {
            zone,
            north,
            forward,
            inverse,
        })
    }

    pub fn zone(&self) -> u8 {
        self.zone
    }

    pub fn is_north(&self) -> bool {
        self.north
    }

    /// EPSG code: 326zz (north) or 327zz (south).
    pub fn epsg(&self) -> u32 {
        utm_epsg(self.zone, self.north)
    }

    /// Longitude of the zone's central meridian.
    pub fn central_meridian(&self) -> f64 {
        f64::from(self.zone) * 6.0 - 183.0
    }

    /// lon/lat (degrees) → easting/northing (metres).
    pub fn to_utm(&self, lonlat: Coord<f64>) -> Result<Coord<f64>, GeoError> {
        let (x, y) = self
            .forward
            .convert((lonlat.x, lonlat.y))
            .map_err(|e| GeoError::Projection(e.to_string()))?;
        Ok(Coord { x, y })
    }

    /// easting/northing (metres) → lon/lat (degrees).
    pub fn to_wgs84(&self, en: Coord<f64>) -> Result<Coord<f64>, GeoError> {
        let (x, y) = self
            .inverse
            .convert((en.x, en.y))
            .map_err(|e| GeoError::Projection(e.to_string()))?;
        Ok(Coord { x, y })
    }

    pub fn polygon_to_utm(&self, p: &Polygon<f64>) -> Result<Polygon<f64>, GeoError> {
        map_polygon(p, |c| self.to_utm(c))
    }

    pub fn polygon_to_wgs84(&self, p: &Polygon<f64>) -> Result<Polygon<f64>, GeoError> {
        map_polygon(p, |c| self.to_wgs84(c))
    }

    pub fn multi_polygon_to_wgs84(
        &self,
        mp: &MultiPolygon<f64>,
    ) -> Result<MultiPolygon<f64>, GeoError> {
        mp.0.iter()
            .map(|p| self.polygon_to_wgs84(p))
            .collect::<Result<Vec<_>, _>>()
            .map(MultiPolygon)
    }
}

fn utm_epsg(zone: u8, north: bool) -> u32 {
    let base: u32 = if north { 32600 } else { 32700 };
    base + u32::from(zone)
}

fn map_polygon(
    p: &Polygon<f64>,
    mut f: impl FnMut(Coord<f64>) -> Result<Coord<f64>, GeoError>,
) -> Result<Polygon<f64>, GeoError> {
    let mut ring =
        |ls: &geo_types::LineString<f64>| -> Result<geo_types::LineString<f64>, GeoError> {
            ls.0.iter()
                .map(|&c| f(c))
                .collect::<Result<Vec<_>, _>>()
                .map(geo_types::LineString::new)
        };
    let ext = ring(p.exterior())?;
    let holes = p
        .interiors()
        .iter()
        .map(&mut ring)
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Polygon::new(ext, holes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zone_and_round_trip() {
        // Wageningen (NL) is in zone 31N, 5.66°E.
        let p = UtmProjection::for_lonlat(Coord { x: 5.66, y: 51.97 }).unwrap();
        assert_eq!(p.epsg(), 32631);
        assert_eq!(p.central_meridian(), 3.0);
        let en = p.to_utm(Coord { x: 3.0, y: 0.0 }).unwrap();
        // The central meridian at the equator maps to the false easting.
        assert!(
            (en.x - 500_000.0).abs() < 1e-6 && en.y.abs() < 1e-6,
            "{en:?}"
        );
        let c = Coord { x: 5.66, y: 51.97 };
        let back = p.to_wgs84(p.to_utm(c).unwrap()).unwrap();
        assert!((back.x - c.x).abs() < 1e-9 && (back.y - c.y).abs() < 1e-9);
    }

    #[test]
    fn southern_hemisphere_and_limits() {
        let p = UtmProjection::for_lonlat(Coord { x: -70.6, y: -33.4 }).unwrap();
        assert_eq!(p.epsg(), 32719);
        let en = p.to_utm(Coord { x: -70.6, y: -33.4 }).unwrap();
        assert!(en.y > 6_000_000.0 && en.y < 10_000_000.0);
        assert!(matches!(
            UtmProjection::for_lonlat(Coord { x: 0.0, y: 85.0 }),
            Err(GeoError::OutsideUtm { .. })
        ));
        assert_eq!(
            UtmProjection::for_lonlat(Coord { x: 180.0, y: 0.0 })
                .unwrap()
                .zone(),
            60
        );
        assert_eq!(
            UtmProjection::for_lonlat(Coord { x: -180.0, y: 0.0 })
                .unwrap()
                .zone(),
            1
        );
    }
}
