//! What the DEMs resource answers: the stored DEM's metadata, listings,
//! heights, and the OpenAPI schemas of its bodies and queries.

use planner_core::geo::Issue;
use planner_core::terrain::DemInfo;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::api::access::{answered_project, visible};
use crate::auth::{Caller, Role};
use crate::clock::rfc3339;
use crate::db::DemMetaRow;
use crate::error::ApiError;
use crate::state::AppState;

/// A stored DEM: who it is and what the raster holds.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct DemResponse {
    id: String,
    name: Option<String>,
    /// The uploaded file's name, when one was given.
    file_name: Option<String>,
    /// Upload time, RFC 3339 (UTC).
    created_at: String,
    /// Size of the uploaded file, bytes.
    size_bytes: i64,
    #[serde(flatten)]
    info: DemInfo,
    /// URL of this DEM.
    pub(super) url: String,
    /// URL of its hillshade preview (PNG).
    hillshade: String,
    /// The project it belongs to.
    project_id: String,
}

/// A page of DEMs, newest first.
#[derive(Serialize, Deserialize, ToSchema)]
pub struct DemList {
    items: Vec<DemResponse>,
    /// DEMs stored in all.
    total: i64,
    limit: i64,
    offset: i64,
}

/// A file's bytes.
#[derive(ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)] // documents binary bodies for the OpenAPI schema
pub struct BinaryFile(Vec<u8>);

pub fn dem_url(id: &str) -> String {
    format!("/api/v1/dems/{id}")
}

/// An EPSG code from `EPSG:32633` (any case) or `32633`.
pub fn parse_epsg(text: &str) -> Result<u32, String> {
    let t = text.trim();
    let digits = match t.get(..5) {
        Some(p) if p.eq_ignore_ascii_case("epsg:") => t[5..].trim(),
        _ => t,
    };
    match digits.parse::<u32>() {
        Ok(code) if code > 0 && digits.bytes().all(|b| b.is_ascii_digit()) => Ok(code),
        _ => Err(format!(
            "the CRS must be an EPSG code such as EPSG:32633 or 32633, got {text:?}"
        )),
    }
}

pub(crate) fn stored_info(row: &DemMetaRow) -> Result<DemInfo, ApiError> {
    let mut info: DemInfo = serde_json::from_str(&row.info).map_err(|e| {
        ApiError::Internal(format!("stored DEM info of {} unreadable: {e}", row.id))
    })?;
    // Stored before `crs.proj4` existed.
    info.crs.fill_proj4();
    Ok(info)
}

pub(super) fn response(row: &DemMetaRow, info: DemInfo) -> DemResponse {
    let url = dem_url(&row.id);
    DemResponse {
        id: row.id.clone(),
        name: row.name.clone(),
        file_name: row.file_name.clone(),
        created_at: rfc3339(row.created_at),
        size_bytes: row.size_bytes,
        info,
        hillshade: format!("{url}/hillshade.png"),
        url,
        project_id: answered_project(&row.project_id),
    }
}

crate::api::paging::listing!(DemList, DemResponse);

/// The stored DEM `id` when the caller has at least `need` in its
/// project; one of another project is the 404 of a missing one.
pub async fn visible_dem(
    state: &AppState,
    caller: &Caller,
    id: &str,
    need: Role,
) -> Result<DemMetaRow, ApiError> {
    let row = state.db.get_dem_meta(id).await?;
    visible(&state.db, caller, row, "DEM", id, need).await
}

/// In a request naming a DEM (a costmap's, a survey's), an unknown DEM
/// is a fault of the request, at `pointer`.
pub fn dem_fault(e: ApiError, pointer: &str, id: &str) -> ApiError {
    match e {
        ApiError::NotFound(_) => ApiError::Validation(vec![Issue::new(
            pointer,
            &format!("no DEM with id {id:?}: upload it with POST /api/v1/dems first"),
        )]),
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_forms() {
        assert_eq!(parse_epsg("EPSG:32633"), Ok(32633));
        assert_eq!(parse_epsg("epsg:4326"), Ok(4326));
        assert_eq!(parse_epsg(" 26918 "), Ok(26918));
        assert!(parse_epsg("EPSG:").is_err());
        assert!(parse_epsg("+32633").is_err());
        assert!(parse_epsg("0").is_err());
        assert!(parse_epsg("EPSG:abc").is_err());
        assert!(parse_epsg("ÉPSG:1").is_err());
    }

    /// A DEM stored before `crs.proj4` existed is returned with it.
    #[test]
    fn stored_info_gains_proj4() {
        let row = DemMetaRow {
            id: "d1".into(),
            name: None,
            created_at: 0,
            file_name: None,
            crs_override: None,
            info: r#"{"format":"geotiff","width":2,"height":2,
                "crs":{"epsg":27700,"name":"OSGB36 / British National Grid","geographic":false},
                "resolution_m":[1.0,1.0],"resolution":[1.0,1.0],
                "bounds":[0.0,0.0,2.0,2.0],"bounds_wgs84":[-7.5,49.7,-7.5,49.7],
                "min":1.0,"max":2.0,"nodata_value":null,"nodata_fraction":0.0}"#
                .into(),
            size_bytes: 1,
            read_bytes: None,
            project_id: None,
        };
        let info = stored_info(&row).unwrap();
        assert!(
            info.crs.proj4.starts_with("+proj=tmerc") && info.crs.proj4.contains("+towgs84="),
            "{}",
            info.crs.proj4
        );
    }
}
