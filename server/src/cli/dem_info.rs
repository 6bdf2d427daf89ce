//! `terraplan dem-info`: a DEM read as the service reads an upload, its
//! metadata printed as JSON.

use std::path::PathBuf;

use planner_core::terrain::{DemFormat, DemInfo, DemLimits, GeoTiffWindows, RasterWindows};
use serde::Serialize;

use super::common::{Failure, describe_dem_fault, read_dem_file};
use crate::state::dem_store::tiles::{cell_stats, windows_info};

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
    let (info, file_name, size_bytes) = match geotiff_info(args, &limits)? {
        Some(found) => found,
        None => {
            let (dem, file_name, size_bytes) =
                read_dem_file(&args.file, args.crs.as_deref(), "--crs", limits)?;
            let info = dem
                .info()
                .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
            (info, file_name, size_bytes)
        }
    };
    let doc = DemFileInfo {
        file_name,
        size_bytes,
        info: &info,
    };
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Failure::other(e.to_string()))?;
    println!("{text}");
    Ok(())
}

/// A GeoTIFF's info, read a window at a time as the service reads an
/// upload (a band of 512 rows in memory, whatever its size); `None` for a
/// file that is not a TIFF.
fn geotiff_info(
    args: &DemInfoArgs,
    limits: &DemLimits,
) -> Result<Option<(DemInfo, Option<String>, u64)>, Failure> {
    use std::io::Read;
    let path = &args.file;
    let cannot =
        |e: std::io::Error| Failure::input(format!("cannot read DEM file {}: {e}", path.display()));
    let mut file = std::fs::File::open(path).map_err(cannot)?;
    let mut head = [0u8; 4];
    let got = file.read(&mut head).map_err(cannot)?;
    if !matches!(&head[..got], b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+") {
        return Ok(None);
    }
    let size_bytes = file.metadata().map_err(cannot)?.len();
    let crs = args
        .crs
        .as_deref()
        .map(crate::api::dems::parse_epsg)
        .transpose()
        .map_err(|m| Failure::input(format!("--crs: {m}")))?;
    let fault = |e| describe_dem_fault(path, "--crs", e);
    let windows = GeoTiffWindows::open(file, crs, limits).map_err(fault)?;
    let stats = cell_stats(&windows).map_err(fault)?;
    let info = windows_info(windows.grid(), DemFormat::GeoTiff, &stats).map_err(fault)?;
    let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    Ok(Some((info, file_name, size_bytes)))
}
