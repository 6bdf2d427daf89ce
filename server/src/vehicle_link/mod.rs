//! Sending missions, fences and rally points to a vehicle over MAVLink
//! (`terraplan upload`, and the service's
//! `POST /api/v1/surveys/{id}/uavs/{uav}/upload`).
//!
//! - `address`: the `udpout:HOST:PORT` / `udpin:` / `tcpout:` /
//!   `serial:DEV:BAUD` syntax, checked before any socket opens;
//! - `mission_file`: the lists read from `.waypoints` and `.plan` files;
//! - `items`: mission items in their MISSION_ITEM_INT form;
//! - `connection`: the [`Link`] the engine talks through and its
//!   `mavlink`-crate implementation;
//! - `exchange`: options, errors and messages the protocol steps share;
//! - `upload` / `download`: the mission protocol's two transfers, as
//!   state machines over any `Link` (unit-tested against an in-memory
//!   vehicle, `test_vehicle`);
//! - `compare`: the read-back against what was sent;
//! - `transfer`: upload + read-back + compare for each list;
//! - `allow` / `busy`: the addresses the service may reach
//!   (`serve --vehicle-links`) and the one upload per address it runs.

pub mod address;
pub mod allow;
pub mod busy;
pub mod compare;
pub mod connection;
pub mod download;
pub mod exchange;
pub mod items;
pub mod mission_file;
#[cfg(test)]
mod test_vehicle;
pub mod transfer;
pub mod upload;

pub use address::VehicleAddress;
pub use allow::LinkPattern;
pub use busy::VehicleLinks;
pub use connection::MavlinkLink;
pub use exchange::{Options, Progress, Stage};
pub use items::MissionKind;
pub use mission_file::ItemList;
pub use transfer::send_and_verify;
