//! HTTP API, one module per resource.

pub mod cameras;
pub mod costmaps;
mod dem_header;
pub mod dems;
pub mod health;
pub mod json_body;
pub mod names;
pub mod paging;
pub mod routes;
pub mod surveys;
pub mod vehicles;

/// Unix milliseconds as RFC 3339 UTC, as every resource's timestamps.
pub fn rfc3339(millis: i64) -> String {
    let t = std::time::UNIX_EPOCH + std::time::Duration::from_millis(millis.max(0) as u64);
    humantime::format_rfc3339_millis(t).to_string()
}

/// The first 8 characters of an id, for download file names.
pub fn short_id(id: &str) -> &str {
    id.get(..8).unwrap_or(id)
}
