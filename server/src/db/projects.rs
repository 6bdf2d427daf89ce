//! Projects and their members: who may see and change which resources.

use super::Db;

/// A project.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct ProjectRow {
    pub id: String,
    pub name: String,
    /// The user whose personal project this is.
    pub personal_of: Option<String>,
    pub created_at: i64,
}

/// A project as one member sees it: the project and the member's role.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct MembershipRow {
    pub id: String,
    pub name: String,
    pub personal_of: Option<String>,
    pub created_at: i64,
    pub role: String,
}

/// A member of a project, by name.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct MemberRow {
    pub user_name: String,
    pub role: String,
}

/// The tables whose rows belong to a project (constants, so the SQL
/// built from them is safe).
const RESOURCE_TABLES: [&str; 4] = ["dems", "surveys", "costmaps", "routes"];

impl Db {
    /// Make a project with `owner` as its owner.
    pub async fn insert_project(&self, row: &ProjectRow, owner: &str) -> Result<(), sqlx::Error> {
        const SQL: &str =
            "INSERT INTO projects (id, name, personal_of, created_at) VALUES ($1, $2, $3, $4)";
        const MEMBER: &str =
            "INSERT INTO project_members (project_id, user_id, role) VALUES ($1, $2, 'owner')";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(SQL)
                .bind(&row.id)
                .bind(&row.name)
                .bind(&row.personal_of)
                .bind(row.created_at)
                .execute(&mut *tx)
                .await?;
            sqlx::query(MEMBER).bind(&row.id).bind(owner).execute(&mut *tx).await?;
            tx.commit().await
        })
    }

    pub async fn project_by_id(&self, id: &str) -> Result<Option<ProjectRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, personal_of, created_at FROM projects WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, ProjectRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// The personal project of a user.
    pub async fn personal_project(&self, user_id: &str) -> Result<Option<ProjectRow>, sqlx::Error> {
        const SQL: &str =
            "SELECT id, name, personal_of, created_at FROM projects WHERE personal_of = $1";
        on_pool!(self, pool => sqlx::query_as::<_, ProjectRow>(SQL).bind(user_id).fetch_optional(pool).await)
    }

    /// The role of a user in a project; `None` when not a member (or no
    /// such project).
    pub async fn member_role(
        &self,
        project_id: &str,
        user_id: &str,
    ) -> Result<Option<String>, sqlx::Error> {
        const SQL: &str = "SELECT role FROM project_members WHERE project_id = $1 AND user_id = $2";
        on_pool!(self, pool => sqlx::query_as::<_, (String,)>(SQL)
            .bind(project_id)
            .bind(user_id)
            .fetch_optional(pool)
            .await
            .map(|r| r.map(|(role,)| role)))
    }

    /// The projects a user is a member of, personal first, then oldest first.
    pub async fn projects_of(
        &self,
        user_id: &str,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<MembershipRow>, i64), sqlx::Error> {
        const SQL: &str = "SELECT p.id, p.name, p.personal_of, p.created_at, m.role \
            FROM projects p JOIN project_members m ON m.project_id = p.id \
            WHERE m.user_id = $1 \
            ORDER BY CASE WHEN p.personal_of = $1 THEN 0 ELSE 1 END, p.created_at, p.id \
            LIMIT $2 OFFSET $3";
        const COUNT: &str = "SELECT COUNT(*) FROM project_members WHERE user_id = $1";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, MembershipRow>(SQL).bind(user_id).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).bind(user_id).fetch_one(pool).await?;
            Ok((rows, total))
        })
    }

    /// The members of a project, owners first, then by name.
    pub async fn project_members(&self, project_id: &str) -> Result<Vec<MemberRow>, sqlx::Error> {
        const SQL: &str = "SELECT u.name AS user_name, m.role \
            FROM project_members m JOIN users u ON u.id = m.user_id \
            WHERE m.project_id = $1 \
            ORDER BY CASE m.role WHEN 'owner' THEN 0 WHEN 'editor' THEN 1 ELSE 2 END, u.name";
        on_pool!(self, pool => sqlx::query_as::<_, MemberRow>(SQL).bind(project_id).fetch_all(pool).await)
    }

    /// Add a member or change its role; true when the member is new.
    pub async fn set_member(
        &self,
        project_id: &str,
        user_id: &str,
        role: &str,
    ) -> Result<bool, sqlx::Error> {
        const UPDATE: &str =
            "UPDATE project_members SET role = $3 WHERE project_id = $1 AND user_id = $2";
        const INSERT: &str =
            "INSERT INTO project_members (project_id, user_id, role) VALUES ($1, $2, $3)";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let changed = sqlx::query(UPDATE)
                .bind(project_id)
                .bind(user_id)
                .bind(role)
                .execute(&mut *tx)
                .await?
                .rows_affected();
            if changed == 0 {
                sqlx::query(INSERT).bind(project_id).bind(user_id).bind(role).execute(&mut *tx).await?;
            }
            tx.commit().await?;
            Ok(changed == 0)
        })
    }

    /// Remove a member; true when it was one.
    pub async fn remove_member(
        &self,
        project_id: &str,
        user_id: &str,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM project_members WHERE project_id = $1 AND user_id = $2";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(project_id)
            .bind(user_id)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// How many owners a project has.
    pub async fn count_owners(&self, project_id: &str) -> Result<i64, sqlx::Error> {
        const SQL: &str =
            "SELECT COUNT(*) FROM project_members WHERE project_id = $1 AND role = 'owner'";
        on_pool!(self, pool => sqlx::query_as::<_, (i64,)>(SQL).bind(project_id).fetch_one(pool).await.map(|r| r.0))
    }

    /// How many resources (DEMs, surveys, costmaps, routes) a project holds.
    pub async fn count_project_resources(&self, project_id: &str) -> Result<i64, sqlx::Error> {
        let mut total = 0;
        for table in RESOURCE_TABLES {
            let sql = format!("SELECT COUNT(*) FROM {table} WHERE project_id = $1");
            total += on_pool!(self, pool => sqlx::query_as::<_, (i64,)>(sqlx::AssertSqlSafe(sql.as_str())).bind(project_id).fetch_one(pool).await.map(|r| r.0))?;
        }
        Ok(total)
    }

    /// Delete a project (its members go with it); true when it existed.
    pub async fn delete_project(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM projects WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }

    /// Move every resource made before accounts (no project) into
    /// `project_id`; how many moved.
    pub async fn adopt_unowned_resources(&self, project_id: &str) -> Result<u64, sqlx::Error> {
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let mut moved = 0;
            for table in RESOURCE_TABLES {
                let sql = format!("UPDATE {table} SET project_id = $1 WHERE project_id IS NULL");
                moved += sqlx::query(sqlx::AssertSqlSafe(sql.as_str())).bind(project_id).execute(&mut *tx).await?.rows_affected();
            }
            tx.commit().await?;
            Ok(moved)
        })
    }
}
