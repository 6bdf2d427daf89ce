//! `terraplan dem-info`: a DEM read as the service reads an upload, its
//! metadata printed as JSON.

use std::path::PathBuf;

use planner_core::terrain::{DemInfo, DemLimits};
use serde::Serialize;

use super::common::{Failure, read_dem_file};

#[derive(clap::Args)]
pub(super) struct DemInfoArgs {
    /// The DEM file.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Horizontal CRS of the raster (`EPSG:32633` or `32633`): needed when
    /// the file does not say; overrides the file's.
    #[arg(long, value_name = "EPSG:CODE")]
    crs: Option<String>,
    /// Most pixels (width × height) accepted.
    #[arg(long, default_value_t = DemLimits::default().max_pixels)]
    max_pixels: u64,
}

/// What `dem-info` prints: the file, then the raster's metadata (the
/// fields `POST /api/v1/dems` answers with).
#[derive(Serialize)]
struct DemFileInfo<'a> {
    file_name: Option<String>,
    size_bytes: u64,
    #[serde(flatten)]
    info: &'a DemInfo,
}

pub(super) fn dem_info(args: &DemInfoArgs) -> Result<(), Failure> {
    let limits = DemLimits {
        max_pixels: args.max_pixels,
        ..DemLimits::default()
    };
    let (dem, file_name, size_bytes) =
        read_dem_file(&args.file, args.crs.as_deref(), "--crs", limits)?;
    let info = dem
        .info()
        .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
    let doc = DemFileInfo {
        file_name,
        size_bytes,
        info: &info,
    };
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Failure::other(e.to_string()))?;
    println!("{text}");
    Ok(())
}
