//! `terraplan import`: a GIS file (Shapefile, KML/KMZ, GPX, GeoJSON in any
//! named CRS) read as `POST /api/v1/imports` reads an upload, printed as
//! WGS84 GeoJSON with a message per feature skipped.

use std::path::PathBuf;

use super::common::Failure;

#[derive(clap::Args)]
pub(super) struct ImportArgs {
    /// The file: a zipped Shapefile (.zip), .shp (with its .dbf and .prj
    /// beside it), .gpkg, .kml, .kmz, .gpx or .geojson.
    #[arg(value_name = "FILE")]
    file: PathBuf,
}

pub(super) fn import(args: &ImportArgs) -> Result<(), Failure> {
    let imported = crate::imports::import_file(&args.file)
        .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
    let doc = crate::imports::reply(&imported);
    let text = serde_json::to_string(&doc).map_err(|e| Failure::other(e.to_string()))?;
    println!("{text}");
    Ok(())
}
