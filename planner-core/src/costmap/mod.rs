//! Traversability costmaps for a ground vehicle (SPEC §4.2, thesis
//! chapter 3). Being built stage by stage; so far the exact Euclidean
//! distance transform the `distance` inflation mode rests on.

pub mod distance;

pub use distance::distance_transform;
