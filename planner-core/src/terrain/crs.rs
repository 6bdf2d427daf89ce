//! A DEM's horizontal CRS: an EPSG code, its name, and whether its units
//! are degrees (geographic) or metres (projected).

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
        Ok(Crs {
            epsg: code,
            name,
            geographic,
        })
    }

    /// `"EPSG:<code>"`, as PROJ takes it.
    pub fn proj_id(&self) -> String {
        format!("EPSG:{}", self.epsg)
    }
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

    #[test]
    fn rejects_non_horizontal() {
        // EPSG:5773 is EGM96 height (vertical), 999999 does not exist.
        assert!(matches!(Crs::from_epsg(5773), Err(TerrainError::Crs(_))));
        assert!(matches!(Crs::from_epsg(999_999), Err(TerrainError::Crs(_))));
    }
}
