//! Background jobs: the costmap job runner ([`runner`]), one run of a job
//! ([`build`]), its live state ([`live`]) and what it stores ([`record`]).

mod build;
mod live;
pub mod record;
mod runner;

pub use live::Live;
pub use record::{
    COSTMAP_TIF, CostmapResult, JobStatus, LEASE_MS, LEGEND_SVG, PREVIEW_MAX_SIDE, PREVIEW_PNG,
    StoredRequest, layer_file, parse_stage, stage_name,
};
pub use runner::CostmapJobs;
