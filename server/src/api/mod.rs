//! HTTP API, one module per resource.

pub mod health;
pub mod json_body;
pub mod surveys;
