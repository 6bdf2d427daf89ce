//! Background jobs: the costmap job runner ([`runner`]), one run of a job
//! ([`build`]), its live state ([`live`]), what it stores ([`record`])
//! and the notes about jobs between the processes on one database
//! ([`feed`]); costmaps built as tiles by every process ([`tiles`]).

mod build;
mod feed;
mod live;
pub mod record;
mod runner;
mod tiles;

pub use feed::JobNote;
pub use live::Live;
pub use record::{
    COSTMAP_TIF, CostmapResult, DEFAULT_LEASE, JobStatus, LEGEND_SVG, PREVIEW_MAX_SIDE,
    PREVIEW_PNG, StoredRequest, layer_file, parse_stage, stage_name,
};
pub use runner::{CostmapJobs, MIN_LEASE};
pub use tiles::TileSettings;
pub use tiles::context::dem_source;
