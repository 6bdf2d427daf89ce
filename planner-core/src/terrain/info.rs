//! DEM metadata: bounds (native and WGS84), resolution, statistics.

use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use proj::Proj;

use super::{Crs, Dem, DemInfo, GeoTransform, TerrainError};

/// Points per raster edge transformed to find the WGS84 bounds (the edges
/// of a projected raster are curves in lon/lat).
const EDGE_POINTS: usize = 21;

/// WGS84 semi-major axis and first eccentricity squared.
const WGS84_A: f64 = 6_378_137.0;
const WGS84_E2: f64 = 0.006_694_379_990_141_317;

/// The bounds [min x, min y, max x, max y] of a `width` × `height`
/// raster georeferenced by `t` in `crs`, and in WGS84 lon/lat (its edges
/// sampled, since a projected raster's edges are curves in lon/lat).
pub fn raster_bounds(
    t: &GeoTransform,
    width: usize,
    height: usize,
    crs: &Crs,
) -> Result<([f64; 4], [f64; 4]), TerrainError> {
    let (w, h) = (width as f64, height as f64);
    let corners = [
        t.apply(0.0, 0.0),
        t.apply(w, 0.0),
        t.apply(0.0, h),
        t.apply(w, h),
    ];
    let bounds = bbox(corners.iter().copied()).ok_or_else(|| {
        TerrainError::Invalid("the raster's georeferencing gives non-finite bounds".into())
    })?;
    // The outline: EDGE_POINTS per edge, corners included.
    let mut outline = Vec::with_capacity(4 * EDGE_POINTS);
    for i in 0..EDGE_POINTS {
        let f = i as f64 / (EDGE_POINTS - 1) as f64;
        outline.push(t.apply(f * w, 0.0));
        outline.push(t.apply(f * w, h));
        outline.push(t.apply(0.0, f * h));
        outline.push(t.apply(w, f * h));
    }
    let bounds_wgs84 = if crs.epsg == 4326 {
        bounds
    } else {
        let to_wgs84 = Proj::new_known_crs(&crs.proj_id(), "EPSG:4326", None).map_err(|e| {
            TerrainError::Crs(format!("cannot transform {} to WGS84: {e}", crs.proj_id()))
        })?;
        let lonlat = outline.iter().filter_map(|&p| to_wgs84.convert(p).ok());
        bbox(lonlat).ok_or_else(|| {
            TerrainError::Crs(format!(
                "the raster's outline cannot be transformed from {} to WGS84",
                crs.proj_id()
            ))
        })?
    };
    Ok((bounds, bounds_wgs84))
}

pub(super) fn dem_info(dem: &Dem) -> Result<DemInfo, TerrainError> {
    let (bounds, bounds_wgs84) = raster_bounds(&dem.transform, dem.width, dem.height, &dem.crs)?;
    let (mut min, mut max, mut nodata) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
    for &v in &dem.values {
        if v.is_nan() {
            nodata += 1;
        } else {
            min = min.min(v);
            max = max.max(v);
        }
    }
    let total = dem.values.len();
    let has_values = nodata < total;
    Ok(DemInfo {
        format: dem.format,
        width: dem.width,
        height: dem.height,
        crs: dem.crs.clone(),
        resolution_m: resolution_m(dem),
        resolution: resolution(dem),
        bounds,
        bounds_wgs84,
        min: has_values.then_some(min),
        max: has_values.then_some(max),
        nodata_value: dem.nodata,
        nodata_fraction: if total == 0 {
            1.0
        } else {
            nodata as f64 / total as f64
        },
    })
}

/// [min_x, min_y, max_x, max_y] of finite points; `None` if there are none.
fn bbox(points: impl Iterator<Item = (f64, f64)>) -> Option<[f64; 4]> {
    let mut b = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    let mut any = false;
    for (x, y) in points.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        any = true;
        b = [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)];
    }
    any.then_some(b)
}

/// Cell size in CRS units: the lengths of the column and row steps.
fn resolution(dem: &Dem) -> [f64; 2] {
    let t = &dem.transform;
    [
        t.pixel_width.hypot(t.col_rotation),
        t.row_rotation.hypot(t.pixel_height),
    ]
}

pub(super) fn resolution_m(dem: &Dem) -> [f64; 2] {
    let t = &dem.transform;
    if dem.crs.geographic {
        let (_, lat) = t.apply(dem.width as f64 / 2.0, dem.height as f64 / 2.0);
        let (mx, my) = metres_per_degree(lat);
        [
            (t.pixel_width * mx).hypot(t.col_rotation * my),
            (t.row_rotation * mx).hypot(t.pixel_height * my),
        ]
    } else {
        let f = unit_factor(dem.crs.epsg);
        let [x, y] = resolution(dem);
        [x * f, y * f]
    }
}

/// Metres per degree of longitude and of latitude at latitude `lat` on the
/// WGS84 ellipsoid (radius of the parallel; meridional radius of curvature).
fn metres_per_degree(lat: f64) -> (f64, f64) {
    let lat = if lat.is_finite() {
        lat.clamp(-90.0, 90.0)
    } else {
        0.0
    };
    let phi = lat.to_radians();
    let s2 = phi.sin() * phi.sin();
    let w = (1.0 - WGS84_E2 * s2).sqrt();
    let per_rad_lon = WGS84_A * phi.cos() / w;
    let per_rad_lat = WGS84_A * (1.0 - WGS84_E2) / (w * w * w);
    (per_rad_lon.to_radians(), per_rad_lat.to_radians())
}

/// Metres per unit of a projected CRS's first axis (1 when PROJ cannot
/// tell). Cached: PROJ is asked once per code.
fn unit_factor(epsg: u32) -> f64 {
    static CACHE: OnceLock<Mutex<HashMap<u32, f64>>> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(f) = cache.lock().ok().and_then(|c| c.get(&epsg).copied()) {
        return f;
    }
    let f = lookup_unit_factor(epsg).unwrap_or(1.0);
    if let Ok(mut c) = cache.lock() {
        c.insert(epsg, f);
    }
    f
}

fn lookup_unit_factor(epsg: u32) -> Option<f64> {
    let p = Proj::new(&format!("EPSG:{epsg}")).ok()?;
    let json = p.to_projjson(Some(false), None, None).ok()?;
    let v: serde_json::Value = serde_json::from_str(&json).ok()?;
    let unit = v.pointer("/coordinate_system/axis/0/unit")?;
    let f = match unit {
        serde_json::Value::String(s) if s == "metre" => 1.0,
        serde_json::Value::Object(_) => unit.get("conversion_factor")?.as_f64()?,
        _ => return None,
    };
    (f.is_finite() && f > 0.0).then_some(f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::{Crs, DemFormat, GeoTransform};

    fn dem(crs: u32, t: GeoTransform, values: Vec<f64>, width: usize) -> Dem {
        let height = values.len() / width;
        Dem {
            width,
            height,
            values,
            nodata: Some(-9999.0),
            transform: t,
            crs: Crs::from_epsg(crs).unwrap(),
            format: DemFormat::GeoTiff,
        }
    }

    fn north_up(x: f64, y: f64, dx: f64, dy: f64) -> GeoTransform {
        GeoTransform {
            origin_x: x,
            pixel_width: dx,
            row_rotation: 0.0,
            origin_y: y,
            col_rotation: 0.0,
            pixel_height: -dy,
        }
    }

    #[test]
    fn utm_info() {
        let d = dem(
            32616,
            north_up(627316.5, 4323511.0, 1.0, 2.0),
            vec![1.0, f64::NAN, 3.0, -4.5, 5.0, f64::NAN],
            3,
        );
        let i = d.info().unwrap();
        assert_eq!((i.width, i.height), (3, 2));
        assert_eq!(i.bounds, [627316.5, 4323507.0, 627319.5, 4323511.0]);
        assert_eq!(i.resolution, [1.0, 2.0]);
        assert_eq!(i.resolution_m, [1.0, 2.0]);
        assert_eq!((i.min, i.max), (Some(-4.5), Some(5.0)));
        assert!((i.nodata_fraction - 2.0 / 6.0).abs() < 1e-15);
        assert_eq!(i.nodata_value, Some(-9999.0));
        // Near 85.5°W 39.05°N (gdalinfo: 85d31'43"W, 39d3'5"N).
        let [w, s, e, n] = i.bounds_wgs84;
        assert!(
            (w - -85.52866).abs() < 1e-4 && (n - 39.05140).abs() < 1e-4,
            "{:?}",
            i.bounds_wgs84
        );
        assert!(w < e && s < n);
    }

    #[test]
    fn geographic_resolution_in_metres() {
        let d = dem(
            4326,
            north_up(40.0, 40.0, 1.0 / 1200.0, 1.0 / 1200.0),
            vec![f64::NAN; 4],
            2,
        );
        let i = d.info().unwrap();
        assert_eq!((i.min, i.max, i.nodata_fraction), (None, None, 1.0));
        assert_eq!(i.bounds_wgs84, i.bounds);
        let [rx, ry] = i.resolution_m;
        // 3" at 40°N: ~71.1 m east-west, ~92.5 m north-south.
        assert!((rx - 71.1).abs() < 0.2, "{rx}");
        assert!((ry - 92.5).abs() < 0.2, "{ry}");
        let (mx, my) = metres_per_degree(0.0);
        assert!(
            (mx - 111_319.49).abs() < 0.01 && (my - 110_574.28).abs() < 0.01,
            "{mx} {my}"
        );
        let (_, my) = metres_per_degree(90.0);
        assert!((my - 111_693.98).abs() < 0.01, "{my}");
    }

    #[test]
    fn rotated_resolution_is_vector_length() {
        let t = GeoTransform {
            origin_x: 500000.0,
            pixel_width: 3.0,
            row_rotation: 4.0,
            origin_y: 4000000.0,
            col_rotation: 4.0,
            pixel_height: -3.0,
        };
        let d = dem(32633, t, vec![0.0; 4], 2);
        let i = d.info().unwrap();
        assert_eq!(i.resolution, [5.0, 5.0]);
        assert_eq!(i.bounds, [500000.0, 3999994.0, 500014.0, 4000008.0]);
    }

    #[test]
    fn us_survey_feet_are_converted() {
        // EPSG:2264 NAD83 / North Carolina (ftUS).
        let d = dem(
            2264,
            north_up(2000000.0, 700000.0, 10.0, 10.0),
            vec![0.0; 4],
            2,
        );
        let [rx, ry] = d.resolution_m();
        assert!(
            (rx - 3.048006).abs() < 1e-5 && (ry - 3.048006).abs() < 1e-5,
            "{rx}"
        );
    }
}
