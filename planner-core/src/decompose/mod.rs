//! Free space and its boustrophedon (Morse) decomposition (SPEC §3.2, thesis §5.3).
//!
//! [`free_space`] subtracts the no-fly zones from the region of interest;
//! [`decompose`] cuts the free space into cells with straight slice lines of a
//! given bearing, drawn only where the slice's connectivity changes. Every cell
//! is a simple polygon that each slice line meets in at most one segment, so a
//! back-and-forth path along the slice covers it without leaving it.
//!
//! All geometry is planar, in metres (UTM easting/northing).

mod boustrophedon;
mod frame;
mod free_space;
mod merge;
mod ring;
mod sweep;
#[cfg(test)]
mod test_support;
mod touch;

pub use boustrophedon::{MergedCell, PreparedFree, decompose, decompose_merged};
pub use free_space::free_space;

/// Why [`decompose`] could not produce cells.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecomposeError {
    /// Nothing is left to cover: no polygon, or only zero-area ones.
    #[error("the free space is empty: nothing is left to cover once the no-fly zones are removed")]
    EmptyFreeSpace,
    /// The line spacing given for joining cells is not a positive number.
    #[error("the line spacing must be a positive number of metres")]
    NonPositiveSpacing,
    /// The slice angle is NaN or infinite.
    #[error("the slice angle must be a finite number of degrees")]
    NonFiniteAngle,
    /// A coordinate of the free space is NaN or infinite.
    #[error("the free space has a coordinate that is not a finite number")]
    NonFiniteCoordinate,
    /// The free space is broken beyond what the built-in repair (a non-zero
    /// union) can fix, e.g. rings that cross each other in a way the union
    /// cannot resolve.
    #[error("the free space is not a valid polygon set: {0}")]
    InvalidGeometry(String),
    /// Stopped by its cancellation token (see [`crate::cancel`]).
    #[error(transparent)]
    Cancelled(#[from] crate::cancel::Cancelled),
}
