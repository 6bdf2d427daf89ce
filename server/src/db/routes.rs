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
    /// Its costmap's project (`None`: made before accounts, visible to no
    /// one).
    pub project_id: Option<String>,
}

/// The columns of [`RouteRow`], for `concat!` (SQL must be static).
macro_rules! route_columns {
    () => {
        "id, name, costmap_id, parent_id, created_at, request, changes, result, project_id"
    };
}

impl Db {
    pub async fn insert_route(&self, row: &RouteRow) -> Result<(), sqlx::Error> {
        const SQL: &str = concat!(
            "INSERT INTO routes (",
            route_columns!(),
            ") VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)"
        );
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(&row.costmap_id)
            .bind(&row.parent_id)
            .bind(row.created_at)
            .bind(&row.request)
            .bind(&row.changes)
            .bind(&row.result)
            .bind(&row.project_id)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_route(&self, id: &str) -> Result<Option<RouteRow>, sqlx::Error> {
        const SQL: &str = concat!("SELECT ", route_columns!(), " FROM routes WHERE id = $1");
        on_pool!(self, pool => sqlx::query_as::<_, RouteRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first: those of the projects `user_id` is a member of (of
    /// `project_id` only, when given), and only those on `costmap_id` when
    /// given.
    pub async fn list_routes(
        &self,
        user_id: &str,
        project_id: Option<&str>,
        costmap_id: Option<&str>,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<RouteRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            route_columns!(),
            " FROM routes WHERE ",
            visible_to_member!(),
            " AND ($3 IS NULL OR costmap_id = $3) \
             ORDER BY created_at DESC, id DESC LIMIT $4 OFFSET $5"
        );
        const COUNT: &str = concat!(
            "SELECT COUNT(*) FROM routes WHERE ",
            visible_to_member!(),
            " AND ($3 IS NULL OR costmap_id = $3)"
        );
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, RouteRow>(SQL)
                .bind(user_id)
                .bind(project_id)
                .bind(costmap_id)
                .bind(limit)
                .bind(offset)
                .fetch_all(pool)
                .await?;
            let (total,): (i64,) = sqlx::query_as(COUNT)
                .bind(user_id)
                .bind(project_id)
                .bind(costmap_id)
                .fetch_one(pool)
                .await?;
            Ok((rows, total))
        })
    }

    /// True when a route was deleted.
    pub async fn delete_route(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM routes WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }
}
