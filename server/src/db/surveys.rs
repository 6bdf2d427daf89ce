//! Surveys: the request and plan documents of each stored survey.

use super::Db;

/// A stored survey.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SurveyRow {
    pub id: String,
    pub name: Option<String>,
    pub created_at: i64,
    pub request: String,
    pub plan: String,
}

/// A survey without its documents, for listings.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SurveySummaryRow {
    pub id: String,
    pub name: Option<String>,
    pub created_at: i64,
    pub plan: String,
}

impl Db {
    pub async fn insert_survey(&self, row: &SurveyRow) -> Result<(), sqlx::Error> {
        const SQL: &str =
            "INSERT INTO surveys (id, name, created_at, request, plan) VALUES ($1, $2, $3, $4, $5)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(row.created_at)
            .bind(&row.request)
            .bind(&row.plan)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_survey(&self, id: &str) -> Result<Option<SurveyRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, request, plan FROM surveys WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, SurveyRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first.
    pub async fn list_surveys(
        &self,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<SurveySummaryRow>, i64), sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, plan FROM surveys ORDER BY created_at DESC, id DESC LIMIT $1 OFFSET $2";
        const COUNT: &str = "SELECT COUNT(*) FROM surveys";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, SurveySummaryRow>(SQL).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).fetch_one(pool).await?;
            Ok((rows, total))
        })
    }

    /// True when a survey was deleted.
    pub async fn delete_survey(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM surveys WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }
}
