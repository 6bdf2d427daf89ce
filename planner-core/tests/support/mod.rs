//! Shared by the DEM tests and the DEM bench: where the real DEMs are.

use std::path::{Path, PathBuf};

/// `../shared/data/dems` beside the repository; `TERRAPLAN_SHARED_DATA`
/// (the data directory or its `dems/`) overrides it.
pub fn data_dir() -> PathBuf {
    if let Ok(dir) = std::env::var("TERRAPLAN_SHARED_DATA") {
        let dir = PathBuf::from(dir);
        let dems = dir.join("dems");
        return if dems.is_dir() { dems } else { dir };
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/dems")
}
