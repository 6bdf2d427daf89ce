//! terraplan's planning algorithms, one module per pipeline stage.
//!
//! The stages know nothing of HTTP or storage: `server` translates requests
//! and files into calls of this API.
//!
//! All planning geometry is in metres in a UTM zone (see [`geo::UtmProjection`]);
//! WGS84 lon/lat only appears at the edges (input parsing and export).

pub mod buffer;
pub mod cancel;
pub mod costmap;
pub mod coverage;
pub mod decompose;
pub mod export;
pub mod flock;
pub mod geo;
pub mod import;
pub mod num;
pub mod overlay;
pub mod route;
pub mod survey;
pub mod terrain;
#[cfg(test)]
pub(crate) mod test_rng;
mod xml;
