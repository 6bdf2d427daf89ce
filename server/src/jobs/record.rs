//! What a costmap job stores and shows: its status, stage names, the
//! stored request and result documents, its file names and the job
//! constants the handlers share.

use planner_core::costmap::{CostmapOptions, CostmapStats, Layer, ResolvedParams, Stage, Vehicle};
use planner_core::terrain::Crs;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// How long a claim on a job lasts unless renewed, by default
/// (`--job-lease-s`).
pub const DEFAULT_LEASE: std::time::Duration = std::time::Duration::from_secs(15);
/// Runs a job may start; one interrupted more often (its server killed
/// each time) is failed rather than run again.
pub const MAX_ATTEMPTS: i64 = 3;
/// Longest side of the stored preview image, pixels.
pub const PREVIEW_MAX_SIDE: usize = 1024;

pub const COSTMAP_TIF: &str = "costmap.tif";
pub const PREVIEW_PNG: &str = "preview.png";
pub const LEGEND_SVG: &str = "legend.svg";

/// The stored name of a layer's file.
pub fn layer_file(layer: Layer) -> String {
    format!("layers/{}.tif", layer.name())
}

/// Where a job stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    /// Waiting for a free slot (`--costmap-jobs`).
    Queued,
    Running,
    /// Finished: the files are ready.
    Done,
    /// Stopped by an error (see `error`).
    Failed,
}

impl JobStatus {
    pub fn as_str(self) -> &'static str {
        match self {
            JobStatus::Queued => "queued",
            JobStatus::Running => "running",
            JobStatus::Done => "done",
            JobStatus::Failed => "failed",
        }
    }

    pub fn parse(s: &str) -> Option<JobStatus> {
        [
            JobStatus::Queued,
            JobStatus::Running,
            JobStatus::Done,
            JobStatus::Failed,
        ]
        .into_iter()
        .find(|j| j.as_str() == s)
    }

    pub fn is_finished(self) -> bool {
        matches!(self, JobStatus::Done | JobStatus::Failed)
    }
}

/// A stage's name as stored (its serde name).
pub fn stage_name(stage: Stage) -> String {
    serde_json::to_value(stage)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

pub fn parse_stage(name: &str) -> Option<Stage> {
    serde_json::from_value(serde_json::Value::String(name.to_string())).ok()
}

/// What a finished job found, stored as JSON with status done.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CostmapResult {
    pub vehicle: Vehicle,
    pub params: ResolvedParams,
    pub stats: CostmapStats,
    pub warnings: Vec<String>,
    pub width: usize,
    pub height: usize,
    pub crs: Crs,
    /// The layers kept, each with a file.
    pub layers: Vec<Layer>,
    /// [min x, min y, max x, max y] of the working grid in `crs`, and in
    /// WGS84 lon/lat (absent from costmaps built before they were kept).
    #[serde(default)]
    pub bounds: Option<[f64; 4]>,
    #[serde(default)]
    pub bounds_wgs84: Option<[f64; 4]>,
}

/// What a job was asked for, stored as JSON.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct StoredRequest {
    /// The vehicle as given (preset and overrides); `null` for the default.
    pub vehicle: serde_json::Value,
    pub options: CostmapOptions,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_and_stage_names() {
        for s in [
            JobStatus::Queued,
            JobStatus::Running,
            JobStatus::Done,
            JobStatus::Failed,
        ] {
            assert_eq!(JobStatus::parse(s.as_str()), Some(s));
            assert_eq!(
                serde_json::to_value(s).unwrap(),
                serde_json::json!(s.as_str())
            );
        }
        assert_eq!(JobStatus::parse("lost"), None);
        assert_eq!(stage_name(Stage::Normals), "normals");
        assert_eq!(parse_stage("inflate"), Some(Stage::Inflate));
        assert_eq!(parse_stage("nope"), None);
    }

    #[test]
    fn layer_files() {
        assert_eq!(layer_file(Layer::NegativeStep), "layers/negative_step.tif");
    }
}
