//! A DEM's horizontal CRS: an EPSG code, its name, whether its units are
//! degrees (geographic) or metres (projected), and its PROJ.4 definition.

use std::collections::HashMap;
use std::ffi::{CStr, CString};
use std::ptr;
use std::sync::{Mutex, OnceLock};

use proj::Proj;
use serde::{Deserialize, Serialize};

use super::TerrainError;

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Crs {
    /// EPSG code of the horizontal CRS.
    pub epsg: u32,
    /// Its name in the EPSG registry, e.g. "WGS 84 / UTM zone 16N".
    pub name: String,
    /// Coordinates are longitude/latitude degrees (not metres).
    pub geographic: bool,
    /// PROJ.4 definition bound to WGS84 (with +towgs84 where PROJ has a
    /// transformation), for clients like proj4js; empty when PROJ cannot
    /// write the CRS as one.
    #[serde(default)]
    pub proj4: String,
}

impl Crs {
    /// Look `EPSG:code` up in PROJ's database. Only geographic 2D/3D and
    /// projected CRSs can hold a DEM's horizontal coordinates.
    pub fn from_epsg(code: u32) -> Result<Crs, TerrainError> {
        let def = format!("EPSG:{code}");
        let p = Proj::new(&def)
            .map_err(|_| TerrainError::Crs(format!("EPSG:{code} is not a CRS known to PROJ")))?;
        let json = p
            .to_projjson(Some(false), None, None)
            .map_err(|e| TerrainError::Crs(format!("EPSG:{code}: {e}")))?;
        let v: serde_json::Value = serde_json::from_str(&json)
            .map_err(|e| TerrainError::Crs(format!("EPSG:{code}: {e}")))?;
        let kind = v.get("type").and_then(|t| t.as_str()).unwrap_or("");
        let geographic = match kind {
            "GeographicCRS" => true,
            "ProjectedCRS" => false,
            other => {
                return Err(TerrainError::Crs(format!(
                    "EPSG:{code} is a {} CRS, not a geographic or projected one that \
                     can hold a DEM's horizontal coordinates",
                    if other.is_empty() { "non-" } else { other }
                )));
            }
        };
        if geographic {
            // Degrees must be the unit: a geographic CRS in grads or radians
            // would be read as degrees everywhere else.
            let unit = v
                .pointer("/coordinate_system/axis/0/unit")
                .and_then(|u| {
                    u.as_str()
                        .map(str::to_string)
                        .or_else(|| u.get("name")?.as_str().map(str::to_string))
                })
                .unwrap_or_default();
            if unit != "degree" {
                return Err(TerrainError::Crs(format!(
                    "EPSG:{code} is geographic with unit {unit:?}; only degrees are supported"
                )));
            }
        }
        let name = v
            .get("name")
            .and_then(|n| n.as_str())
            .unwrap_or("")
            .to_string();
        // A CRS PROJ cannot write as a PROJ.4 string still holds a DEM; clients then place it by its WGS84 bounds.
        let proj4 = proj4_bound_to_wgs84(&def).unwrap_or_default();
        Ok(Crs {
            epsg: code,
            name,
            geographic,
            proj4,
        })
    }

    /// Fill in `proj4` when it is empty, as in a CRS stored before the
    /// field existed, from PROJ by `epsg` (cached). It stays empty if PROJ
    /// does not know the code.
    pub fn fill_proj4(&mut self) {
        if self.proj4.is_empty()
            && let Ok(crs) = crs_from_epsg(self.epsg)
        {
            self.proj4 = crs.proj4;
        }
    }

    /// `"EPSG:<code>"`, as PROJ takes it.
    pub fn proj_id(&self) -> String {
        format!("EPSG:{}", self.epsg)
    }
}

/// [`Crs::from_epsg`], remembered: asking PROJ costs milliseconds, about
/// as much as reading a DEM of a few megabytes.
pub(super) fn crs_from_epsg(code: u32) -> Result<Crs, TerrainError> {
    static CACHE: OnceLock<Mutex<HashMap<u32, Crs>>> = OnceLock::new();
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(crs) = cache.lock().ok().and_then(|c| c.get(&code).cloned()) {
        return Ok(crs);
    }
    let crs = Crs::from_epsg(code)?;
    if let Ok(mut c) = cache.lock()
        && c.len() < 4096
    {
        c.insert(code, crs.clone());
    }
    Ok(crs)
}

/// The PROJ.4 string of the CRS `def` bound to WGS84, without `+type=crs`
/// (proj4js ignores it; GDAL does not write it); `None` when PROJ knows no
/// such CRS or cannot write it as a PROJ.4 string.
///
/// The binding (`+towgs84=`) is PROJ's own when its database has exactly
/// one Helmert transformation from the CRS's datum to WGS84 (as GDAL
/// exports it), else the first Helmert transformation of those PROJ ranks
/// for the CRS's area of use (largest overlap, then best accuracy): the
/// one PROJ itself applies there without its optional grids (e.g. "OSGB36
/// to WGS 84 (6)" for EPSG:27700, where PROJ binds nothing as there are
/// several). A CRS on WGS84 (EPSG:4326, UTM 326xx, 3857) or one without
/// any such transformation gets its plain PROJ.4 string.
fn proj4_bound_to_wgs84(def: &str) -> Option<String> {
    use proj_sys as p;
    let def = CString::new(def).ok()?;
    // SAFETY: the context and every object made from it (CRSs, operation
    // factory context, operation list, operations) are created here,
    // checked for null before they are used (PROJ's destroy functions
    // accept null), used on this thread only and destroyed before
    // returning, the objects before their context. `proj_as_proj_string`
    // returns a NUL-terminated string owned by its PJ, valid until that is
    // destroyed: it is copied into a `String` first. `towgs84` has room
    // for the 7 values asked for.
    let text = unsafe {
        let ctx = p::proj_context_create();
        if ctx.is_null() {
            return None;
        }
        p::proj_log_level(ctx, p::PJ_LOG_LEVEL_PJ_LOG_NONE);
        let as_proj4 = |obj: *const p::PJ| -> Option<String> {
            if obj.is_null() {
                return None;
            }
            let s = p::proj_as_proj_string(ctx, obj, p::PJ_PROJ_STRING_TYPE_PJ_PROJ_4, ptr::null());
            (!s.is_null()).then(|| CStr::from_ptr(s).to_string_lossy().into_owned())
        };
        let crs = p::proj_create(ctx, def.as_ptr());
        let plain = as_proj4(crs);
        let bound = p::proj_crs_create_bound_crs_to_WGS84(ctx, crs, ptr::null());
        let mut text = as_proj4(bound).filter(|s| s.contains("+towgs84="));
        p::proj_destroy(bound);
        if text.is_none() && plain.is_some() {
            let geod = p::proj_crs_get_geodetic_crs(ctx, crs);
            let wgs84 = p::proj_create(ctx, c"EPSG:4326".as_ptr());
            let factory = p::proj_create_operation_factory_context(ctx, ptr::null());
            let ops = if geod.is_null() || wgs84.is_null() || factory.is_null() {
                ptr::null_mut()
            } else {
                p::proj_operation_factory_context_set_spatial_criterion(
                    ctx,
                    factory,
                    p::PROJ_SPATIAL_CRITERION_PROJ_SPATIAL_CRITERION_PARTIAL_INTERSECTION,
                );
                p::proj_create_operations(ctx, geod, wgs84, factory)
            };
            let n = if ops.is_null() {
                0
            } else {
                p::proj_list_get_count(ops)
            };
            let mut towgs84 = [0.0f64; 7];
            for i in 0..n {
                let op = p::proj_list_get(ctx, ops, i);
                if !op.is_null()
                    && p::proj_coordoperation_get_towgs84_values(
                        ctx,
                        op,
                        towgs84.as_mut_ptr(),
                        7,
                        0,
                    ) != 0
                {
                    let bound = p::proj_crs_create_bound_crs(ctx, crs, wgs84, op);
                    text = as_proj4(bound).filter(|s| s.contains("+towgs84="));
                    p::proj_destroy(bound);
                }
                p::proj_destroy(op);
                if text.is_some() {
                    break;
                }
            }
            p::proj_list_destroy(ops);
            p::proj_operation_factory_context_destroy(factory);
            p::proj_destroy(wgs84);
            p::proj_destroy(geod);
        }
        p::proj_destroy(crs);
        p::proj_context_destroy(ctx);
        text.or(plain)
    }?;
    let params: Vec<&str> = text
        .split_whitespace()
        .filter(|p| *p != "+type=crs")
        .collect();
    (!params.is_empty()).then(|| params.join(" "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_codes() {
        let utm = Crs::from_epsg(32616).unwrap();
        assert_eq!(utm.name, "WGS 84 / UTM zone 16N");
        assert!(!utm.geographic);
        let wgs = Crs::from_epsg(4326).unwrap();
        assert_eq!(wgs.name, "WGS 84");
        assert!(wgs.geographic);
        let nad83 = Crs::from_epsg(26918).unwrap();
        assert!(!nad83.geographic);
    }

    /// Metres between two points of `crs` (degrees on a geographic one,
    /// at latitude `lat`).
    fn gap(crs: &Crs, a: (f64, f64), b: (f64, f64), lat: f64) -> f64 {
        let (dx, dy) = (a.0 - b.0, a.1 - b.1);
        if crs.geographic {
            (dx * 111_320.0 * lat.to_radians().cos()).hypot(dy * 110_574.0)
        } else {
            dx.hypot(dy)
        }
    }

    #[test]
    fn proj4_strings_transform_like_the_epsg_codes() {
        // A point inside each CRS's area of use, lon/lat.
        let cases = [
            (32618, -77.05, 38.81),
            (4326, -77.05, 38.81),
            (3857, -77.05, 38.81),
            (5070, -77.05, 38.81),
            (27700, -1.5, 52.5),
            (2154, 2.3, 46.5),
            (28992, 5.3, 52.1),
            (2056, 7.5, 46.8),
            (3035, 10.0, 52.0),
        ];
        for (code, lon, lat) in cases {
            let crs = Crs::from_epsg(code).unwrap();
            let s = &crs.proj4;
            assert!(s.starts_with("+proj="), "EPSG:{code}: {s}");
            assert!(!s.contains("+type=crs"), "EPSG:{code}: {s}");
            // `new_known_crs` takes and gives EPSG:4326 as lon, lat (it
            // normalises the axis order for visualisation).
            let by_code = Proj::new_known_crs("EPSG:4326", &crs.proj_id(), None).unwrap();
            let by_string = Proj::new_known_crs("EPSG:4326", s, None).unwrap();
            let want = by_code.convert((lon, lat)).unwrap();
            let got = by_string.convert((lon, lat)).unwrap();
            let d = gap(&crs, got, want, lat);
            eprintln!("EPSG:{code}: {d:.1e} m apart; {s}");
            assert!(
                d < 2.0,
                "EPSG:{code}: {got:?} vs {want:?}, {d} m apart; {s}"
            );
        }
        // Without their datum shift the British and Dutch grids are 100 m
        // and more off: the +towgs84 is what places them.
        for (code, lon, lat) in [(27700, -1.5, 52.5), (28992, 5.3, 52.1)] {
            let crs = Crs::from_epsg(code).unwrap();
            assert!(
                crs.proj4.contains("+towgs84="),
                "EPSG:{code}: {}",
                crs.proj4
            );
            let shiftless: Vec<&str> = crs
                .proj4
                .split_whitespace()
                .filter(|p| !p.starts_with("+towgs84="))
                .collect();
            let shiftless = Proj::new_known_crs("EPSG:4326", &shiftless.join(" "), None).unwrap();
            let by_code = Proj::new_known_crs("EPSG:4326", &crs.proj_id(), None).unwrap();
            let d = gap(
                &crs,
                shiftless.convert((lon, lat)).unwrap(),
                by_code.convert((lon, lat)).unwrap(),
                lat,
            );
            eprintln!("EPSG:{code} without +towgs84: {d:.1} m");
            assert!(d > 50.0, "EPSG:{code}: {d} m");
        }
    }

    #[test]
    fn proj4_of_the_earlier_tests_codes() {
        assert_eq!(
            Crs::from_epsg(32616).unwrap().proj4,
            "+proj=utm +zone=16 +datum=WGS84 +units=m +no_defs"
        );
        assert_eq!(
            Crs::from_epsg(4326).unwrap().proj4,
            "+proj=longlat +datum=WGS84 +no_defs"
        );
        assert!(
            Crs::from_epsg(27700)
                .unwrap()
                .proj4
                .contains("+towgs84=446.448,-125.157,542.06,0.15,0.247,0.842,-20.489")
        );
    }

    #[test]
    fn proj4_defaults_to_empty_when_stored_without_it() {
        let old = r#"{"epsg":32616,"name":"WGS 84 / UTM zone 16N","geographic":false}"#;
        let mut crs: Crs = serde_json::from_str(old).unwrap();
        assert_eq!(crs.epsg, 32616);
        assert!(crs.proj4.is_empty());
        crs.fill_proj4();
        assert_eq!(crs, Crs::from_epsg(32616).unwrap());
    }

    #[test]
    fn rejects_non_horizontal() {
        // EPSG:5773 is EGM96 height (vertical), 999999 does not exist.
        assert!(matches!(Crs::from_epsg(5773), Err(TerrainError::Crs(_))));
        assert!(matches!(Crs::from_epsg(999_999), Err(TerrainError::Crs(_))));
    }
}
