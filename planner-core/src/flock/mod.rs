//! Flock stage: NFZ-avoiding transits and per-UAV tours over the cells
//! (SPEC §3.4, §3.5).

#[cfg(test)]
mod test_support;
pub mod tour;
pub mod transit;

pub use tour::{Tour, plan_tour};
pub use transit::{Endpoint, ObstacleMap, TransitError, polyline_length};
