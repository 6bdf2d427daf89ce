//! HTTP API, one module per resource.

pub mod dems;
pub mod health;
pub mod json_body;
pub mod paging;
pub mod surveys;
