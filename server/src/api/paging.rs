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

/// One page of a listing: its items, how many there are in all, and the
/// page asked for.
pub struct Page<T> {
    pub items: Vec<T>,
    pub total: i64,
    pub limit: i64,
    pub offset: i64,
}

/// The page of a listing that `query` asks for: `fetch` reads the stored
/// rows of the page and the total for (limit, offset), `item` answers
/// each row.
pub async fn list<R, T, Fut>(
    query: Result<Query<ListQuery>, QueryRejection>,
    fetch: impl FnOnce(i64, i64) -> Fut,
    item: impl FnMut(&R) -> Result<T, ApiError>,
) -> Result<Page<T>, ApiError>
where
    Fut: Future<Output = Result<(Vec<R>, i64), sqlx::Error>>,
{
    let (limit, offset) = page(query)?;
    let (rows, total) = fetch(limit, offset).await?;
    let items = rows.iter().map(item).collect::<Result<Vec<_>, _>>()?;
    Ok(Page {
        items,
        total,
        limit,
        offset,
    })
}

/// `From<Page<$item>>` for a listing type `$list`, which has the fields
/// of a page (each listing has a type of its own for its OpenAPI schema).
macro_rules! listing {
    ($list:ty, $item:ty) => {
        impl From<$crate::api::paging::Page<$item>> for $list {
            fn from(page: $crate::api::paging::Page<$item>) -> Self {
                Self {
                    items: page.items,
                    total: page.total,
                    limit: page.limit,
                    offset: page.offset,
                }
            }
        }
    };
}
pub(crate) use listing;
