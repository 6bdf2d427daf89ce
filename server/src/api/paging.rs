//! The `?limit=&offset=` paging of every listing.

use axum::extract::{Query, rejection::QueryRejection};
use serde::Deserialize;
use utoipa::IntoParams;

use crate::error::ApiError;

#[derive(Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ListQuery {
    /// Page size.
    #[param(minimum = 1, maximum = 100, default = 20)]
    limit: Option<i64>,
    /// Items to skip.
    #[param(minimum = 0, default = 0)]
    offset: Option<i64>,
}

/// The page asked for, as (limit, offset): 400 on a malformed query string
/// or a value out of range.
pub fn page(query: Result<Query<ListQuery>, QueryRejection>) -> Result<(i64, i64), ApiError> {
    let Query(q) =
        query.map_err(|e| ApiError::BadRequest(format!("bad query string: {}", e.body_text())))?;
    let limit = q.limit.unwrap_or(20);
    let offset = q.offset.unwrap_or(0);
    if !(1..=100).contains(&limit) {
        return Err(ApiError::BadRequest(format!(
            "limit {limit} is outside [1, 100]"
        )));
    }
    if offset < 0 {
        return Err(ApiError::BadRequest(format!("offset {offset} is negative")));
    }
    Ok((limit, offset))
}
