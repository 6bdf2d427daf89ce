//! HTTP API, one module per resource.

pub mod access;
mod account_fields;
pub mod cameras;
pub mod costmaps;
pub mod dems;
pub mod document;
pub mod health;
mod immutable;
pub mod imports;
pub mod json_body;
pub mod members;
pub mod names;
pub mod paging;
pub mod password;
pub mod projects;
pub mod routes;
pub mod session;
pub mod surveys;
pub mod tokens;
pub mod users;
pub mod vehicle_links;
pub mod vehicles;

/// The first 8 characters of an id, for download file names.
pub fn short_id(id: &str) -> &str {
    id.get(..8).unwrap_or(id)
}
