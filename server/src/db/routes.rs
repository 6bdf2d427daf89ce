//! Routes planned on costmaps, with the changes each replan applied.

use super::Db;

/// A stored route.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct RouteRow {
    pub id: String,
    pub name: Option<String>,
    pub costmap_id: String,
    /// The route this one was replanned from.
    pub parent_id: Option<String>,
    pub created_at: i64,
    /// `{"start", "goal", "options", "speed_m_s"}`, JSON.
    pub request: String,
    /// Every change of the costmap applied so far (`{"blocked",
    /// "cost_changes"}`), JSON.
    pub changes: String,
    /// The planned route, JSON.
    pub result: String,
}

impl Db {
    pub async fn insert_route(&self, row: &RouteRow) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO routes (id, name, costmap_id, parent_id, created_at, request, \
                           changes, result) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(&row.costmap_id)
            .bind(&row.parent_id)
            .bind(row.created_at)
            .bind(&row.request)
            .bind(&row.changes)
            .bind(&row.result)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_route(&self, id: &str) -> Result<Option<RouteRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, costmap_id, parent_id, created_at, request, changes, \
                           result FROM routes WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, RouteRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first; only the routes on `costmap_id` when given.
    pub async fn list_routes(
        &self,
        costmap_id: Option<&str>,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<RouteRow>, i64), sqlx::Error> {
        const ALL: &str = "SELECT id, name, costmap_id, parent_id, created_at, request, changes, \
                           result FROM routes ORDER BY created_at DESC, id DESC LIMIT $1 OFFSET $2";
        const COUNT_ALL: &str = "SELECT COUNT(*) FROM routes";
        const OF: &str = "SELECT id, name, costmap_id, parent_id, created_at, request, changes, \
                          result FROM routes WHERE costmap_id = $1 \
                          ORDER BY created_at DESC, id DESC LIMIT $2 OFFSET $3";
        const COUNT_OF: &str = "SELECT COUNT(*) FROM routes WHERE costmap_id = $1";
        on_pool!(self, pool => {
            let (rows, (total,)): (Vec<RouteRow>, (i64,)) = match costmap_id {
                None => (
                    sqlx::query_as(ALL).bind(limit).bind(offset).fetch_all(pool).await?,
                    sqlx::query_as(COUNT_ALL).fetch_one(pool).await?,
                ),
                Some(c) => (
                    sqlx::query_as(OF).bind(c).bind(limit).bind(offset).fetch_all(pool).await?,
                    sqlx::query_as(COUNT_OF).bind(c).fetch_one(pool).await?,
                ),
            };
            Ok((rows, total))
        })
    }

    /// True when a route was deleted.
    pub async fn delete_route(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM routes WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }
}
