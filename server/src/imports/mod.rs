//! GIS files as GeoJSON for a survey's ROI, no-fly zones or corridor: the
//! formats of `planner_core::import` chosen by extension.

use std::path::Path;

use planner_core::import::{Format, ImportError, Imported, import_bytes, import_path};

pub mod gpkg;
use serde_json::Value;

/// What a file is read for: which geometries it must hold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Polygons: an ROI or no-fly zones.
    Area,
    /// One line: a corridor's centre line.
    Line,
}

/// Whether the file at `path` is read by an importer (a Shapefile, KML,
/// KMZ or GPX) rather than as GeoJSON.
pub fn is_gis_file(path: &Path) -> bool {
    let name = path.to_string_lossy();
    is_gpkg(&name)
        || name.to_ascii_lowercase().ends_with(".shp")
        || !matches!(Format::from_name(&name), Some(Format::GeoJson) | None)
}

/// The geometries for `role` in the GIS file at `path` (any format of
/// [`is_gis_file`], or GeoJSON naming a CRS), in WGS84, as a
/// FeatureCollection, and messages about the features skipped.
pub fn read_geometry_file(path: &Path, role: Role) -> Result<(Value, Vec<String>), String> {
    let imported = if is_gis_file(path) {
        import_file(path)
    } else {
        let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
        import_bytes("file.geojson", &bytes)
    };
    select(imported.map_err(|e| e.to_string())?, role)
}

/// Whether `name` is a GeoPackage's (`.gpkg`).
pub fn is_gpkg(name: &str) -> bool {
    name.to_ascii_lowercase().ends_with(".gpkg")
}

/// The file at `path`: a GeoPackage, or any file `import_path` reads.
pub fn import_file(path: &Path) -> Result<Imported, ImportError> {
    if is_gpkg(&path.to_string_lossy()) {
        gpkg::read_gpkg_blocking(path)
    } else {
        import_path(path)
    }
}

/// The reply to an import: `{"features": FeatureCollection (WGS84),
/// "messages": [what was skipped]}`.
pub fn reply(imported: &Imported) -> Value {
    serde_json::json!({
        "features": imported.to_feature_collection(),
        "messages": imported.messages,
    })
}

/// The features of `imported` that `role` takes, as a FeatureCollection.
pub fn select(imported: Imported, role: Role) -> Result<(Value, Vec<String>), String> {
    let found = match role {
        Role::Area => imported.polygons(),
        Role::Line => imported.lines(),
    };
    let others = imported.features.len();
    let mut messages = imported.messages;
    match found {
        Some(fc) => {
            let kept = fc["features"].as_array().map_or(0, Vec::len);
            if kept < others {
                let what = match role {
                    Role::Area => "line features ignored (an area takes polygons)",
                    Role::Line => "polygon features ignored (a corridor takes lines)",
                };
                messages.push(format!("{} {what}", others - kept));
            }
            Ok((fc, messages))
        }
        None => {
            let want = match role {
                Role::Area => "no polygon",
                Role::Line => "no line",
            };
            let mut m = format!("holds {want}");
            if !messages.is_empty() {
                m.push_str(&format!(" ({})", messages.join("; ")));
            }
            Err(m)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn areas_take_polygons_and_lines_take_lines() {
        let kml = br#"<kml><Placemark><LineString><coordinates>5,52 5.1,52.1</coordinates></LineString></Placemark></kml>"#;
        let imported = import_bytes("a.kml", kml).unwrap();
        let e = select(imported.clone(), Role::Area).unwrap_err();
        assert_eq!(e, "holds no polygon");
        let (fc, messages) = select(imported, Role::Line).unwrap();
        assert_eq!(fc["features"][0]["geometry"]["type"], "LineString");
        assert!(messages.is_empty());
    }

    #[test]
    fn gis_files_by_extension() {
        assert!(!is_gis_file(Path::new("a/roi.geojson")));
        assert!(!is_gis_file(Path::new("roi.txt")));
        assert!(is_gis_file(Path::new("roi.SHP")) && is_gis_file(Path::new("r.kmz")));
        assert!(is_gis_file(Path::new("r.GPKG")));
    }
}
