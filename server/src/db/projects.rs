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

/// What [`Db::change_member`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MemberChange {
    Added,
    Changed,
    Removed,
    /// Nothing: the user is not a member (to remove).
    NotMember,
    /// Nothing: the user is the project's only owner.
    LastOwner,
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

    /// Add a member, change its role (`role` given) or remove it (`None`),
    /// never leaving the project without an owner. The project's row is
    /// written first, which locks it (a row lock on PostgreSQL, the write
    /// lock on SQLite), so two owners demoting each other at once cannot
    /// both succeed.
    pub async fn change_member(
        &self,
        project_id: &str,
        user_id: &str,
        role: Option<&str>,
    ) -> Result<MemberChange, sqlx::Error> {
        const LOCK: &str = "UPDATE projects SET name = name WHERE id = $1";
        const CURRENT: &str =
            "SELECT role FROM project_members WHERE project_id = $1 AND user_id = $2";
        const OWNERS: &str =
            "SELECT COUNT(*) FROM project_members WHERE project_id = $1 AND role = 'owner'";
        const UPDATE: &str =
            "UPDATE project_members SET role = $3 WHERE project_id = $1 AND user_id = $2";
        const INSERT: &str =
            "INSERT INTO project_members (project_id, user_id, role) VALUES ($1, $2, $3)";
        const DELETE: &str = "DELETE FROM project_members WHERE project_id = $1 AND user_id = $2";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(LOCK).bind(project_id).execute(&mut *tx).await?;
            let current: Option<(String,)> = sqlx::query_as(CURRENT)
                .bind(project_id)
                .bind(user_id)
                .fetch_optional(&mut *tx)
                .await?;
            let current = current.map(|(r,)| r);
            if current.as_deref() == Some("owner") && role != Some("owner") {
                let (owners,): (i64,) =
                    sqlx::query_as(OWNERS).bind(project_id).fetch_one(&mut *tx).await?;
                if owners <= 1 {
                    return Ok(MemberChange::LastOwner);
                }
            }
            let change = match (current, role) {
                (None, None) => return Ok(MemberChange::NotMember),
                (Some(_), None) => {
                    sqlx::query(DELETE).bind(project_id).bind(user_id).execute(&mut *tx).await?;
                    MemberChange::Removed
                }
                (Some(_), Some(role)) => {
                    sqlx::query(UPDATE).bind(project_id).bind(user_id).bind(role).execute(&mut *tx).await?;
                    MemberChange::Changed
                }
                (None, Some(role)) => {
                    sqlx::query(INSERT).bind(project_id).bind(user_id).bind(role).execute(&mut *tx).await?;
                    MemberChange::Added
                }
            };
            tx.commit().await?;
            Ok(change)
        })
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

    /// A project's stored bytes (its DEMs' tiles and kept files, the tiles
    /// of its uploads running, its costmap files; see `quota`) and its
    /// costmap jobs queued or running.
    pub async fn project_usage(&self, project_id: &str) -> Result<(i64, i64), sqlx::Error> {
        // SUM of BIGINT is NUMERIC on PostgreSQL: cast back.
        const SQL: &str = "SELECT \
            CAST((SELECT COALESCE(SUM(d.size_bytes), 0) FROM dems d WHERE d.project_id = $1 \
                  AND EXISTS (SELECT 1 FROM dem_chunks c WHERE c.dem_id = d.id AND c.seq = 0)) \
                 + (SELECT COALESCE(SUM(t.size_bytes), 0) FROM dem_tile_sets t \
                  JOIN dems d ON d.id = t.dem_id WHERE d.project_id = $1) \
                 + (SELECT COALESCE(SUM(u.size_bytes), 0) FROM dem_uploads u \
                  WHERE u.project_id = $1) AS BIGINT), \
            CAST((SELECT COALESCE(SUM(f.size_bytes), 0) FROM costmap_files f \
                  JOIN costmaps c ON c.id = f.costmap_id WHERE c.project_id = $1) AS BIGINT), \
            (SELECT COUNT(*) FROM costmaps WHERE project_id = $1 \
                  AND status IN ('queued', 'running'))";
        on_pool!(self, pool => sqlx::query_as::<_, (i64, i64, i64)>(SQL)
            .bind(project_id)
            .fetch_one(pool)
            .await
            .map(|(dems, costmaps, queued)| (dems.saturating_add(costmaps), queued)))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::UserRow;

    async fn user(db: &Db, name: &str) -> String {
        let row = UserRow {
            id: format!("id-{name}"),
            name: name.to_string(),
            password_hash: None,
            admin: 0,
            disabled: 0,
            created_at: 1,
        };
        db.insert_user(&row).await.unwrap();
        row.id
    }

    /// Two owners demoting each other at the same time: one succeeds, the
    /// other finds itself the last owner, and the project keeps one.
    #[tokio::test]
    async fn a_project_always_keeps_an_owner() {
        let dir = std::env::temp_dir().join(format!("terraplan-proj-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = Db::connect(None, &dir).await.unwrap();
        let (a, b) = (user(&db, "a").await, user(&db, "b").await);
        let project = ProjectRow {
            id: "p".into(),
            name: "p".into(),
            personal_of: None,
            created_at: 1,
        };
        db.insert_project(&project, &a).await.unwrap();
        assert_eq!(
            db.change_member("p", &b, Some("owner")).await.unwrap(),
            MemberChange::Added
        );
        let (x, y) = tokio::join!(
            db.change_member("p", &a, Some("viewer")),
            db.change_member("p", &b, Some("viewer")),
        );
        let mut outcomes = [x.unwrap(), y.unwrap()];
        outcomes.sort_by_key(|c| *c == MemberChange::LastOwner);
        assert_eq!(outcomes, [MemberChange::Changed, MemberChange::LastOwner]);
        let owners = db.project_members("p").await.unwrap();
        assert_eq!(owners.iter().filter(|m| m.role == "owner").count(), 1);
        assert_eq!(
            db.change_member("p", "id-nobody", None).await.unwrap(),
            MemberChange::NotMember
        );
        let last = owners.iter().find(|m| m.role == "owner").unwrap();
        let last_id = format!("id-{}", last.user_name);
        assert_eq!(
            db.change_member("p", &last_id, None).await.unwrap(),
            MemberChange::LastOwner
        );
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
