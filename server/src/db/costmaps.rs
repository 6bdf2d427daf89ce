//! Costmap jobs: their rows, the leases that say which server runs them,
//! and their output files.

use super::files::StoredFile;
use super::{CHUNK_BYTES, Db};

/// A stored costmap job (everything but its files).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CostmapRow {
    pub id: String,
    pub name: Option<String>,
    pub dem_id: String,
    pub created_at: i64,
    pub updated_at: i64,
    /// `{"vehicle": VehicleSpec, "options": CostmapOptions}` as asked, JSON.
    pub request: String,
    /// The resolved `Vehicle`, JSON.
    pub vehicle: String,
    /// queued, running, done or failed.
    pub status: String,
    pub progress: f64,
    pub stage: Option<String>,
    /// What a finished job found (JSON), with status done.
    pub result: Option<String>,
    /// Why the job failed, with status failed.
    pub error: Option<String>,
    /// Runs started.
    pub attempts: i64,
    /// The project it belongs to (`None`: made before accounts, visible
    /// to no one).
    pub project_id: Option<String>,
}

/// One file of a finished costmap.
#[derive(Debug, Clone)]
pub struct CostmapFileRow {
    pub name: String,
    pub content_type: String,
    pub data: Vec<u8>,
}

/// A stored file of a costmap, without its bytes (see [`Db::file_chunks`]).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CostmapFileMeta {
    pub content_type: String,
    pub size_bytes: i64,
}

/// The columns of [`CostmapRow`], for `concat!` (SQL must be static).
macro_rules! costmap_columns {
    () => {
        "id, name, dem_id, created_at, updated_at, request, vehicle, status, progress, stage, \
         result, error, attempts, project_id"
    };
}

impl Db {
    /// Store a new job, queued and held by `owner` until `lease_until`.
    pub async fn insert_costmap(
        &self,
        row: &CostmapRow,
        owner: &str,
        lease_until: i64,
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = concat!(
            "INSERT INTO costmaps (",
            costmap_columns!(),
            ", owner, lease_until) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16)"
        );
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&row.id)
            .bind(&row.name)
            .bind(&row.dem_id)
            .bind(row.created_at)
            .bind(row.updated_at)
            .bind(&row.request)
            .bind(&row.vehicle)
            .bind(&row.status)
            .bind(row.progress)
            .bind(&row.stage)
            .bind(&row.result)
            .bind(&row.error)
            .bind(row.attempts)
            .bind(&row.project_id)
            .bind(owner)
            .bind(lease_until)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_costmap(&self, id: &str) -> Result<Option<CostmapRow>, sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            costmap_columns!(),
            " FROM costmaps WHERE id = $1"
        );
        on_pool!(self, pool => sqlx::query_as::<_, CostmapRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first, without the files: those of the projects `user_id`
    /// is a member of (of `project_id` only, when given).
    pub async fn list_costmaps(
        &self,
        user_id: &str,
        project_id: Option<&str>,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<CostmapRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            costmap_columns!(),
            " FROM costmaps WHERE ",
            visible_to_member!(),
            " ORDER BY created_at DESC, id DESC LIMIT $3 OFFSET $4"
        );
        const COUNT: &str = concat!("SELECT COUNT(*) FROM costmaps WHERE ", visible_to_member!());
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, CostmapRow>(SQL)
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

    /// Delete a costmap, its files and its routes; true when there was one.
    pub async fn delete_costmap(&self, id: &str) -> Result<bool, sqlx::Error> {
        const FILES: &str = "DELETE FROM costmap_files WHERE costmap_id = $1";
        const ROUTES: &str = "DELETE FROM routes WHERE costmap_id = $1";
        const SQL: &str = "DELETE FROM costmaps WHERE id = $1";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(FILES).bind(id).execute(&mut *tx).await?;
            sqlx::query(ROUTES).bind(id).execute(&mut *tx).await?;
            let deleted = sqlx::query(SQL).bind(id).execute(&mut *tx).await?.rows_affected() > 0;
            tx.commit().await?;
            Ok(deleted)
        })
    }

    /// Start a run of a job `owner` holds: status running, progress 0,
    /// one more attempt. The row as it is then (updated and read in one
    /// statement, so a failure leaves either no change or a claimed row),
    /// or `None` when the job is no longer this owner's to run (deleted,
    /// finished, taken over).
    pub async fn claim_costmap(
        &self,
        id: &str,
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<Option<CostmapRow>, sqlx::Error> {
        const SQL: &str = concat!(
            "UPDATE costmaps SET status = 'running', progress = 0, stage = NULL, \
             attempts = attempts + 1, updated_at = $3, lease_until = $4 \
             WHERE id = $1 AND owner = $2 AND status IN ('queued', 'running') RETURNING ",
            costmap_columns!()
        );
        on_pool!(self, pool => sqlx::query_as::<_, CostmapRow>(SQL)
            .bind(id)
            .bind(owner)
            .bind(now)
            .bind(lease_until)
            .fetch_optional(pool)
            .await)
    }

    /// Record a running job's stage; false when the job is no longer
    /// `owner`'s (deleted or taken over).
    pub async fn set_costmap_progress(
        &self,
        id: &str,
        owner: &str,
        progress: f64,
        stage: Option<&str>,
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmaps SET progress = $3, stage = $4, updated_at = $5 \
                           WHERE id = $1 AND owner = $2 AND status = 'running'";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(id)
            .bind(owner)
            .bind(progress)
            .bind(stage)
            .bind(now)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// Finish a job `owner` runs: status done with `result`, and its
    /// files (a chunk at a time), in one transaction. False (and nothing written) when the job
    /// is no longer `owner`'s to finish.
    pub async fn finish_costmap(
        &self,
        id: &str,
        owner: &str,
        result: &str,
        files: &[CostmapFileRow],
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmaps SET status = 'done', progress = 1, stage = NULL, \
                           result = $3, error = NULL, updated_at = $4, owner = NULL, lease_until = 0 \
                           WHERE id = $1 AND owner = $2 AND status = 'running'";
        const CLEAR: &str = "DELETE FROM costmap_files WHERE costmap_id = $1";
        const FILE: &str = "INSERT INTO costmap_files (costmap_id, name, content_type, size_bytes) \
                            VALUES ($1, $2, $3, $4)";
        const CHUNK: &str = "INSERT INTO costmap_file_chunks (costmap_id, name, seq, data) \
                             VALUES ($1, $2, $3, $4)";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let updated = sqlx::query(SQL)
                .bind(id)
                .bind(owner)
                .bind(result)
                .bind(now)
                .execute(&mut *tx)
                .await?
                .rows_affected();
            if updated == 0 {
                tx.rollback().await?;
                return Ok(false);
            }
            sqlx::query(CLEAR).bind(id).execute(&mut *tx).await?;
            for f in files {
                sqlx::query(FILE)
                    .bind(id)
                    .bind(&f.name)
                    .bind(&f.content_type)
                    .bind(f.data.len() as i64)
                    .execute(&mut *tx)
                    .await?;
                for (seq, chunk) in f.data.chunks(CHUNK_BYTES).enumerate() {
                    sqlx::query(CHUNK)
                        .bind(id)
                        .bind(&f.name)
                        .bind(seq as i64)
                        .bind(chunk)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// Fail a job `owner` holds, with the reason; false when it is no
    /// longer `owner`'s.
    pub async fn fail_costmap(
        &self,
        id: &str,
        owner: &str,
        error: &str,
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmaps SET status = 'failed', stage = NULL, error = $3, \
                           updated_at = $4, owner = NULL, lease_until = 0 \
                           WHERE id = $1 AND owner = $2 AND status IN ('queued', 'running')";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(id)
            .bind(owner)
            .bind(error)
            .bind(now)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// Extend the lease of the unfinished jobs among `ids` that `owner`
    /// holds. Only the jobs the holder actually has in hand are passed: a
    /// job it still owns in the database but no longer runs or queues (its
    /// run ended on a storage error) lets its lease run out, so that it is
    /// taken over and run again.
    pub async fn renew_costmap_leases(
        &self,
        owner: &str,
        ids: &[String],
        lease_until: i64,
    ) -> Result<u64, sqlx::Error> {
        /// Ids per statement, well below either backend's limit on
        /// parameters.
        const CHUNK: usize = 500;
        let mut renewed = 0;
        for chunk in ids.chunks(CHUNK) {
            // Only placeholders are spliced in, never a value.
            let placeholders = (0..chunk.len())
                .map(|i| format!("${}", i + 3))
                .collect::<Vec<_>>()
                .join(", ");
            let sql = format!(
                "UPDATE costmaps SET lease_until = $2 \
                 WHERE owner = $1 AND status IN ('queued', 'running') AND id IN ({placeholders})"
            );
            renewed += on_pool!(self, pool => {
                let mut q = sqlx::query(sqlx::AssertSqlSafe(sql.as_str()))
                    .bind(owner)
                    .bind(lease_until);
                for id in chunk {
                    q = q.bind(id);
                }
                q.execute(pool).await.map(|r| r.rows_affected())
            })?;
        }
        Ok(renewed)
    }

    /// Unfinished jobs nobody holds: no owner, or a lease ended before
    /// `expired_before`; oldest first. Costmaps built as tiles are not
    /// among them: their tile jobs have leases of their own.
    pub async fn orphaned_costmaps(&self, expired_before: i64) -> Result<Vec<String>, sqlx::Error> {
        const SQL: &str = "SELECT id FROM costmaps WHERE status IN ('queued', 'running') \
                           AND tiled = 0 AND (owner IS NULL OR lease_until < $1) \
                           ORDER BY created_at, id";
        on_pool!(self, pool => sqlx::query_as::<_, (String,)>(SQL)
            .bind(expired_before)
            .fetch_all(pool)
            .await
            .map(|rows| rows.into_iter().map(|(id,)| id).collect()))
    }

    /// Take over an orphaned job (see [`Db::orphaned_costmaps`]) for
    /// `owner`, queued again; false when someone else got it first.
    pub async fn adopt_costmap(
        &self,
        id: &str,
        owner: &str,
        expired_before: i64,
        now: i64,
        lease_until: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmaps SET owner = $2, lease_until = $5, status = 'queued', \
                           progress = 0, stage = NULL, updated_at = $4 \
                           WHERE id = $1 AND status IN ('queued', 'running') AND tiled = 0 \
                           AND (owner IS NULL OR lease_until < $3)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(id)
            .bind(owner)
            .bind(expired_before)
            .bind(now)
            .bind(lease_until)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// Let go of a job `owner` holds after a storage error left its run
    /// without an outcome (it could not be started, or its result or
    /// failure could not be recorded): queued again with no owner, so that
    /// it is taken over (by this server or another) and run again. The run
    /// still counts as an attempt; once `max_attempts` runs have started
    /// the job is failed with `give_up` instead. The status it is left in,
    /// or `None` when it is no longer `owner`'s.
    pub async fn release_costmap_after_error(
        &self,
        id: &str,
        owner: &str,
        now: i64,
        max_attempts: i64,
        give_up: &str,
    ) -> Result<Option<String>, sqlx::Error> {
        const SQL: &str = "UPDATE costmaps SET owner = NULL, lease_until = 0, progress = 0, \
                           stage = NULL, updated_at = $3, \
                           status = CASE WHEN attempts >= $4 THEN 'failed' ELSE 'queued' END, \
                           error = CASE WHEN attempts >= $4 THEN $5 ELSE error END \
                           WHERE id = $1 AND owner = $2 AND status IN ('queued', 'running') \
                           RETURNING status";
        on_pool!(self, pool => sqlx::query_as::<_, (String,)>(SQL)
            .bind(id)
            .bind(owner)
            .bind(now)
            .bind(max_attempts)
            .bind(give_up)
            .fetch_optional(pool)
            .await
            .map(|r| r.map(|(status,)| status)))
    }

    /// Give back the unfinished jobs `owner` holds (all, or just `id`),
    /// queued for whichever server runs next (at shutdown).
    pub async fn release_costmaps(
        &self,
        owner: &str,
        id: Option<&str>,
        now: i64,
    ) -> Result<u64, sqlx::Error> {
        // A run stopped this way does not count as an attempt.
        const ALL: &str = "UPDATE costmaps SET owner = NULL, lease_until = 0, status = 'queued', \
                           progress = 0, stage = NULL, updated_at = $2, attempts = CASE \
                           WHEN status = 'running' AND attempts > 0 THEN attempts - 1 ELSE attempts END \
                           WHERE owner = $1 AND status IN ('queued', 'running')";
        const ONE: &str = "UPDATE costmaps SET owner = NULL, lease_until = 0, status = 'queued', \
                           progress = 0, stage = NULL, updated_at = $2, attempts = CASE \
                           WHEN status = 'running' AND attempts > 0 THEN attempts - 1 ELSE attempts END \
                           WHERE owner = $1 AND status IN ('queued', 'running') AND id = $3";
        on_pool!(self, pool => {
            let q = match id {
                None => sqlx::query(ALL).bind(owner).bind(now),
                Some(id) => sqlx::query(ONE).bind(owner).bind(now).bind(id),
            };
            q.execute(pool).await.map(|r| r.rows_affected())
        })
    }

    /// A stored file of a costmap without its bytes (stream them with
    /// [`Db::file_chunks`]).
    pub async fn costmap_file_meta(
        &self,
        id: &str,
        name: &str,
    ) -> Result<Option<CostmapFileMeta>, sqlx::Error> {
        const SQL: &str = "SELECT content_type, size_bytes FROM costmap_files \
                           WHERE costmap_id = $1 AND name = $2";
        on_pool!(self, pool => sqlx::query_as::<_, CostmapFileMeta>(SQL)
            .bind(id)
            .bind(name)
            .fetch_optional(pool)
            .await)
    }

    /// A stored file of a costmap, read whole.
    pub async fn get_costmap_file(
        &self,
        id: &str,
        name: &str,
    ) -> Result<Option<CostmapFileRow>, sqlx::Error> {
        let Some(meta) = self.costmap_file_meta(id, name).await? else {
            return Ok(None);
        };
        let file = StoredFile::Costmap(id.to_string(), name.to_string());
        let data = self.read_file(&file, meta.size_bytes).await?;
        Ok(Some(CostmapFileRow {
            name: name.to_string(),
            content_type: meta.content_type,
            data,
        }))
    }
}
