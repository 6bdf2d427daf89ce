//! Flock stage (SPEC §3.4, §3.5): NFZ-avoiding transits, the sharing of the
//! cells among the UAVs (assignment policies), and each UAV's tour.
//!
//! Pipeline: the cells' plans become [`split::Part`]s (halved while there
//! are more UAVs than parts), each part a [`FlockJob`]; a [`Policy`] shares
//! the jobs into [`Routes`]; each route is flown as a [`Tour`].

pub mod balanced;
pub mod bound;
pub mod competition;
pub mod exact;
pub mod hungarian;
pub mod instance;
pub mod min_reach;
pub mod problem;
pub mod split;
#[cfg(test)]
mod test_support;
pub mod tour;
pub mod transit;

use serde::{Deserialize, Serialize};

pub use bound::makespan_lower_bound;
pub use problem::{Flock, FlockJob, FlockUav, Routes, Stop, Visit, count_turns};
pub use split::{Part, Piece, halve_until};
pub use tour::{Tour, plan_tour, plan_tour_in};
pub use transit::{Endpoint, ObstacleMap, TransitError, polyline_length};

/// How the jobs are shared among the UAVs.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Policy {
    /// Thesis policy 1: least summed reach distance (Hungarian method).
    MinReach,
    /// Thesis policy 2: the competition of Algorithm 3.
    Competition,
    /// The competition improved for the shortest makespan.
    #[default]
    Balanced,
}

impl Policy {
    pub fn name(self) -> &'static str {
        match self {
            Policy::MinReach => "min_reach",
            Policy::Competition => "competition",
            Policy::Balanced => "balanced",
        }
    }
}

#[derive(Debug, Clone, thiserror::Error)]
pub enum FlockError {
    #[error(transparent)]
    Transit(#[from] TransitError),
    #[error("assignment failed: {0}")]
    Assignment(#[from] hungarian::AssignmentError),
}

/// Shares the flock's jobs among its UAVs by `policy`.
pub fn assign(flock: &mut Flock, policy: Policy) -> Result<Routes, FlockError> {
    Ok(match policy {
        Policy::MinReach => min_reach::min_reach(flock)?,
        Policy::Competition => competition::competition(flock)?.0,
        Policy::Balanced => {
            let (start, _) = competition::competition(flock)?;
            balanced::balanced(flock, start)?
        }
    })
}
