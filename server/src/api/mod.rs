//! HTTP API, one module per resource.

pub mod cameras;
pub mod costmaps;
pub mod dems;
pub mod health;
pub mod json_body;
pub mod paging;
pub mod routes;
pub mod surveys;
pub mod vehicles;
