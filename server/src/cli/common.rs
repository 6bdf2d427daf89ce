//! What the subcommands share: a failure with its exit status, reading
//! JSON and DEM files as the service reads them, and listing faults.

use std::path::Path;

use planner_core::geo::Issue;
use planner_core::terrain::{Dem, DemLimits, TerrainError, read_dem};
use serde_json::Value;

/// A failure with its exit status.
pub(super) struct Failure {
    pub(super) status: u8,
    pub(super) message: String,
}

impl Failure {
    pub(super) fn input(message: impl Into<String>) -> Self {
        Failure {
            status: 2,
            message: message.into(),
        }
    }
    pub(super) fn other(message: impl Into<String>) -> Self {
        Failure {
            status: 1,
            message: message.into(),
        }
    }
}

pub(super) fn read_json(path: &Path, what: &str) -> Result<Value, Failure> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Failure::input(format!("cannot read {what} file {}: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| {
        Failure::input(format!(
            "{what} file {} is not valid JSON: {e}",
            path.display()
        ))
    })
}

/// Read a DEM file as the service reads an upload: (DEM, file name, size).
/// `crs_flag` names the option that gave `crs`, for messages.
pub(super) fn read_dem_file(
    file: &Path,
    crs: Option<&str>,
    crs_flag: &str,
    limits: DemLimits,
) -> Result<(Dem, Option<String>, u64), Failure> {
    let path = file.display();
    let crs = crs
        .map(crate::api::dems::parse_epsg)
        .transpose()
        .map_err(|m| Failure::input(format!("{crs_flag}: {m}")))?;
    let bytes = read_large_file(file)
        .map_err(|e| Failure::input(format!("cannot read DEM file {path}: {e}")))?;
    let file_name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    let dem = read_dem(&bytes, file_name.as_deref(), crs, &limits)
        .map_err(|e| describe_dem_fault(file, crs_flag, e))?;
    Ok((dem, file_name, bytes.len() as u64))
}

/// A DEM file's fault as the user reads it; `crs_flag` names the option
/// that gives the CRS.
pub(super) fn describe_dem_fault(file: &Path, crs_flag: &str, e: TerrainError) -> Failure {
    let path = file.display();
    Failure::input(match e {
        TerrainError::UnknownCrs(why) => format!(
            "{path}: the raster's coordinate reference system cannot be determined ({why}); \
             give it with {crs_flag}, e.g. {crs_flag} EPSG:32633"
        ),
        TerrainError::Invalid(m) => format!("{path} cannot be read as a DEM: {m}"),
        other => format!("{path}: {other}"),
    })
}

/// The whole file, in a buffer backed by huge pages where the kernel
/// grants them: a 64 MB DEM read into ordinary pages costs 16 000 page
/// faults, a noticeable part of `terraplan costmap`'s time.
fn read_large_file(file: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut f = std::fs::File::open(file)?;
    let len = usize::try_from(f.metadata()?.len()).unwrap_or(0);
    let mut bytes = planner_core::buffer::filled(len, 0u8);
    let mut got = 0;
    while got < len {
        match f.read(&mut bytes[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    // The file may have changed size since: keep what was read, and any rest.
    bytes.truncate(got);
    f.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// "invalid input: …" with each issue on its own line, its pointer turned
/// into a place the user knows by `locate`.
pub(super) fn list_issues(issues: &[Issue], locate: impl Fn(&str) -> String) -> String {
    let lines: Vec<String> = planner_core::geo::cap_issues(issues.to_vec())
        .iter()
        .map(|i| format!("{}: {}", locate(&i.pointer), i.message))
        .collect();
    if lines.len() == 1 {
        format!("invalid input: {}", lines[0])
    } else {
        format!("invalid input:\n  {}", lines.join("\n  "))
    }
}
