//! Reading a `POST /api/v1/costmaps` body: every fault that needs no DEM
//! named by JSON pointer, and the land-cover raster's CRS checked against
//! the DEM's.

use std::sync::Arc;

use planner_core::costmap::{CostmapOptions, Vehicle, VehicleSpec};
use planner_core::geo::{Issue, deserialize_at, escape_pointer_token};
use planner_core::terrain::{Dem, TerrainSampler};
use serde_json::Value;

use crate::api::access::read_project_id;
use crate::api::names::{control_character_issue, read_name};
use crate::error::ApiError;

/// Fields of `POST /api/v1/costmaps`.
const FIELDS: [&str; 5] = ["name", "project_id", "dem_id", "vehicle", "options"];

/// A checked `POST /api/v1/costmaps` body.
pub(super) struct CostmapRequest {
    pub(super) name: Option<String>,
    /// The project asked for; the caller's personal one when `None`.
    pub(super) project_id: Option<String>,
    pub(super) dem_id: String,
    /// The vehicle as given (`null` for the default).
    pub(super) vehicle_spec: Value,
    pub(super) vehicle: Vehicle,
    pub(super) options: CostmapOptions,
}

/// Read a request body, reporting every fault that needs no DEM by JSON
/// pointer.
pub(super) fn parse_request(doc: &Value) -> Result<CostmapRequest, ApiError> {
    let Some(obj) = doc.as_object() else {
        return Err(ApiError::Validation(vec![Issue::new(
            "",
            "the request body must be a JSON object with dem_id (and optionally name, vehicle, options)",
        )]));
    };
    let mut issues = Vec::new();
    for key in obj.keys().filter(|k| !FIELDS.contains(&k.as_str())) {
        issues.push(Issue::new(
            &format!("/{}", escape_pointer_token(key)),
            &format!(
                "unknown field {key:?}: expected name, project_id, dem_id, vehicle or options"
            ),
        ));
    }
    let name = read_name(obj.get("name")).unwrap_or_else(|issue| {
        issues.push(issue);
        None
    });
    let project_id = read_project_id(obj.get("project_id")).unwrap_or_else(|issue| {
        issues.push(issue);
        None
    });
    let dem_id = match obj.get("dem_id") {
        Some(Value::String(s))
            if let Some(issue) = control_character_issue("/dem_id", "the DEM id", s) =>
        {
            issues.push(issue);
            String::new()
        }
        Some(Value::String(s)) if !s.is_empty() => s.clone(),
        None | Some(Value::Null) => {
            issues.push(Issue::new(
                "/dem_id",
                "required: the id of an uploaded DEM (POST /api/v1/dems)",
            ));
            String::new()
        }
        Some(_) => {
            issues.push(Issue::new(
                "/dem_id",
                "must be the id (a non-empty string) of an uploaded DEM",
            ));
            String::new()
        }
    };
    let vehicle_spec = obj.get("vehicle").cloned().unwrap_or(Value::Null);
    let vehicle = if vehicle_spec.is_null() {
        VehicleSpec::default().resolve("/vehicle")
    } else {
        deserialize_at::<VehicleSpec>(&vehicle_spec, "/vehicle")
            .map_err(|i| vec![i])
            .and_then(|spec| spec.resolve("/vehicle"))
    };
    let vehicle = match vehicle {
        Ok(v) => Some(v),
        Err(mut v) => {
            issues.append(&mut v);
            None
        }
    };
    let options = match obj.get("options") {
        None | Some(Value::Null) => Some(CostmapOptions::default()),
        Some(v) => match deserialize_at::<CostmapOptions>(v, "/options") {
            Ok(o) => {
                issues.extend(o.validate("/options"));
                Some(o)
            }
            Err(i) => {
                issues.push(i);
                None
            }
        },
    };
    match (vehicle, options) {
        (Some(vehicle), Some(options)) if issues.is_empty() => Ok(CostmapRequest {
            name,
            project_id,
            dem_id,
            vehicle_spec,
            vehicle,
            options,
        }),
        _ => Err(ApiError::Validation(issues)),
    }
}

/// A fault at `/options/landcover/source` when PROJ cannot relate the
/// land-cover raster's CRS to the DEM's (the job samples the raster at
/// each costmap cell, given in the DEM's CRS).
pub(super) async fn landcover_crs_fault(
    dem: &Arc<Dem>,
    landcover: Arc<Dem>,
) -> Result<Option<Issue>, ApiError> {
    let dem_crs = dem.crs.clone();
    // Building a PROJ transformation reads PROJ's database: off the
    // async runtime (and the sampler, holding it, is not `Send`).
    let fault = tokio::task::spawn_blocking(move || {
        TerrainSampler::new(&landcover, dem_crs.epsg)
            .err()
            .map(|e| (landcover.crs.clone(), e))
    })
    .await
    .map_err(|e| ApiError::Internal(format!("land-cover CRS check failed: {e}")))?;
    Ok(fault.map(|(landcover_crs, e)| {
        Issue::new(
            "/options/landcover/source",
            &format!(
                "the land-cover raster's CRS EPSG:{} ({}) cannot be related to the DEM's CRS \
                 EPSG:{} ({}): {e}; upload the land-cover raster in the DEM's CRS",
                landcover_crs.epsg, landcover_crs.name, dem.crs.epsg, dem.crs.name
            ),
        )
    }))
}

#[cfg(test)]
mod tests {
    use planner_core::terrain::Crs;
    use serde_json::json;

    use super::*;

    fn pointers(r: Result<CostmapRequest, ApiError>) -> Vec<String> {
        match r {
            Err(ApiError::Validation(issues)) => issues.into_iter().map(|i| i.pointer).collect(),
            Err(e) => panic!("expected issues, got {e}"),
            Ok(_) => panic!("expected issues"),
        }
    }

    #[test]
    fn minimal_request() {
        let r = parse_request(&json!({"dem_id": "abc"})).unwrap();
        assert_eq!(r.dem_id, "abc");
        assert_eq!(r.vehicle.name, "u-go");
        assert_eq!(r.options, CostmapOptions::default());
        assert!(r.vehicle_spec.is_null());
    }

    #[test]
    fn faults_are_named_by_pointer() {
        let p = pointers(parse_request(&json!({
            "dem_id": 5,
            "name": 1,
            "colour": "red",
            "vehicle": {"max_slope_deg": 95},
            "options": {"resolution_m": -1},
        })));
        assert_eq!(
            p,
            [
                "/colour",
                "/name",
                "/dem_id",
                "/vehicle/max_slope_deg",
                "/options/resolution_m"
            ]
        );
        let p = pointers(parse_request(
            &json!({"dem_id": "a", "options": {"layers": ["slope", "nope"]}}),
        ));
        assert_eq!(p, ["/options/layers/1"]);
        let p = pointers(parse_request(
            &json!({"dem_id": "a", "vehicle": {"wheels": 4}}),
        ));
        assert_eq!(p, ["/vehicle/wheels"]);
        let p = pointers(parse_request(&json!({"vehicle": {"preset": "tank"}})));
        assert_eq!(p, ["/dem_id", "/vehicle/preset"]);
        assert_eq!(pointers(parse_request(&json!([1]))), [""]);
    }

    /// A 2 × 2 raster in `EPSG:epsg` (the CRS is not looked up).
    fn raster(epsg: u32) -> Arc<Dem> {
        Arc::new(Dem {
            width: 2,
            height: 2,
            values: vec![1.0; 4],
            nodata: None,
            transform: planner_core::terrain::GeoTransform {
                origin_x: 500_000.0,
                pixel_width: 1.0,
                row_rotation: 0.0,
                origin_y: 5_000_000.0,
                col_rotation: 0.0,
                pixel_height: -1.0,
            },
            crs: Crs {
                epsg,
                name: format!("test CRS {epsg}"),
                geographic: false,
                proj4: String::new(),
            },
            format: planner_core::terrain::DemFormat::Asc,
        })
    }

    // Every pair of CRSs a raster can be uploaded in (PROJ relates each to
    // WGS84 at upload) is related by PROJ, if only by a ballpark
    // transformation; so a land-cover raster whose CRS PROJ cannot relate
    // to the DEM's is made here, with a code PROJ does not know.
    #[tokio::test]
    async fn landcover_crs_is_checked_against_the_dem() {
        let dem = raster(32633);
        let fault = landcover_crs_fault(&dem, raster(999_999))
            .await
            .unwrap()
            .expect("a fault");
        assert_eq!(fault.pointer, "/options/landcover/source");
        let says = fault.to_string();
        assert!(
            says.contains("EPSG:999999 (test CRS 999999)")
                && says.contains("EPSG:32633 (test CRS 32633)"),
            "{says}"
        );
        for related in [32633, 4326, 26918] {
            assert!(
                landcover_crs_fault(&dem, raster(related))
                    .await
                    .unwrap()
                    .is_none(),
                "EPSG:{related}"
            );
        }
    }
}
