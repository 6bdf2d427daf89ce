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
    /// The project it belongs to (`None`: made before accounts, visible
    /// to no one).
    pub project_id: Option<String>,
}

/// A survey without its documents, for listings.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct SurveySummaryRow {
    pub id: String,
    pub name: Option<String>,
    pub created_at: i64,
    pub plan: String,
    pub project_id: Option<String>,
}

impl Db {
    pub async fn insert_survey(&self, row: &SurveyRow) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO surveys (id, name, created_at, request, plan, project_id) \
             VALUES ($1, $2, $3, $4, $5, $6)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(row.created_at)
            .bind(&row.request)
            .bind(&row.plan)
            .bind(&row.project_id)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_survey(&self, id: &str) -> Result<Option<SurveyRow>, sqlx::Error> {
        const SQL: &str =
            "SELECT id, name, created_at, request, plan, project_id FROM surveys WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, SurveyRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first: those of the projects `user_id` is a member of (of
    /// `project_id` only, when given).
    pub async fn list_surveys(
        &self,
        user_id: &str,
        project_id: Option<&str>,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<SurveySummaryRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT id, name, created_at, plan, project_id FROM surveys WHERE ",
            visible_to_member!(),
            " ORDER BY created_at DESC, id DESC LIMIT $3 OFFSET $4"
        );
        const COUNT: &str = concat!("SELECT COUNT(*) FROM surveys WHERE ", visible_to_member!());
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, SurveySummaryRow>(SQL)
                .bind(user_id)
                .bind(project_id)
                .bind(limit)
                .bind(offset)
                .fetch_all(pool)
                .await?;
            let (total,): (i64,) = sqlx::query_as(COUNT)
                .bind(user_id)
                .bind(project_id)
                .fetch_one(pool)
                .await?;
            Ok((rows, total))
        })
    }

    /// True when a survey was deleted.
    pub async fn delete_survey(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM surveys WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::ProjectRow;

    fn survey(id: &str, created_at: i64, project_id: Option<&str>) -> SurveyRow {
        SurveyRow {
            id: id.into(),
            name: None,
            created_at,
            request: "{}".into(),
            plan: "{}".into(),
            project_id: project_id.map(str::to_string),
        }
    }

    /// A listing holds the rows of the caller's projects only (of one
    /// when asked), never a row of no project.
    #[tokio::test]
    async fn lists_hold_only_the_members_projects() {
        let dir = std::env::temp_dir().join(format!("terraplan-db-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = Db::connect(None, &dir).await.unwrap();
        for user in ["u1", "u2"] {
            let Db::Sqlite(pool) = &db else {
                unreachable!()
            };
            sqlx::query("INSERT INTO users (id, name, created_at) VALUES ($1, $1, 0)")
                .bind(user)
                .execute(pool)
                .await
                .unwrap();
            let project = ProjectRow {
                id: format!("p-{user}"),
                name: user.into(),
                personal_of: None,
                created_at: 0,
            };
            db.insert_project(&project, user).await.unwrap();
        }
        db.insert_survey(&survey("s1", 1, Some("p-u1")))
            .await
            .unwrap();
        db.insert_survey(&survey("s2", 2, Some("p-u2")))
            .await
            .unwrap();
        db.insert_survey(&survey("s3", 3, None)).await.unwrap();
        db.insert_survey(&survey("s4", 4, Some("p-u1")))
            .await
            .unwrap();
        let ids = |(rows, total): (Vec<SurveySummaryRow>, i64)| {
            let ids: Vec<String> = rows.into_iter().map(|r| r.id).collect();
            (ids, total)
        };
        let listed = ids(db.list_surveys("u1", None, 10, 0).await.unwrap());
        assert_eq!(listed, (vec!["s4".to_string(), "s1".to_string()], 2));
        let listed = ids(db.list_surveys("u1", Some("p-u1"), 1, 1).await.unwrap());
        assert_eq!(listed, (vec!["s1".to_string()], 2));
        let listed = ids(db.list_surveys("u1", Some("p-u2"), 10, 0).await.unwrap());
        assert_eq!(listed, (vec![], 0));
        let listed = ids(db.list_surveys("u2", None, 10, 0).await.unwrap());
        assert_eq!(listed, (vec!["s2".to_string()], 1));
        let listed = ids(db.list_surveys("nobody", None, 10, 0).await.unwrap());
        assert_eq!(listed, (vec![], 0));
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
