//! Storage: SQLite in the data directory by default, PostgreSQL when
//! `DATABASE_URL=postgres://…`. All SQL lives here and is written once in
//! the dialect both accept (`$n` placeholders in order, TEXT and BIGINT).

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use sqlx::postgres::{PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};

static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations");

#[derive(Clone, Debug)]
pub enum Db {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// Run the same query on whichever pool this is.
macro_rules! on_pool {
    ($db:expr, $pool:ident => $body:expr) => {
        match $db {
            Db::Sqlite($pool) => $body,
            Db::Postgres($pool) => $body,
        }
    };
}

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

/// A stored DEM's metadata (everything but the file).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct DemMetaRow {
    pub id: String,
    pub name: Option<String>,
    pub created_at: i64,
    pub file_name: Option<String>,
    pub crs_override: Option<i64>,
    /// `DemInfo` as JSON.
    pub info: String,
    pub size_bytes: i64,
}

/// What is needed to parse a stored DEM again.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct DemDataRow {
    pub file_name: Option<String>,
    pub crs_override: Option<i64>,
    pub data: Vec<u8>,
}

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
}

/// One file of a finished costmap.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct CostmapFileRow {
    pub name: String,
    pub content_type: String,
    pub data: Vec<u8>,
}

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

/// The columns of [`CostmapRow`], for `concat!` (SQL must be static).
macro_rules! costmap_columns {
    () => {
        "id, name, dem_id, created_at, updated_at, request, vehicle, status, progress, stage, \
         result, error, attempts"
    };
}

impl Db {
    /// Connect (PostgreSQL when `database_url` is given, else SQLite in
    /// `data_dir`) and run the migrations.
    pub async fn connect(database_url: Option<&str>, data_dir: &Path) -> Result<Db, sqlx::Error> {
        let db = match database_url {
            Some(url) if url.starts_with("postgres://") || url.starts_with("postgresql://") => {
                Db::Postgres(
                    PgPoolOptions::new()
                        .max_connections(16)
                        .acquire_timeout(Duration::from_secs(10))
                        .connect(url)
                        .await?,
                )
            }
            Some(url) if url.starts_with("sqlite:") => {
                Db::Sqlite(sqlite_pool(SqliteConnectOptions::from_str(url)?).await?)
            }
            Some(url) => {
                return Err(sqlx::Error::Configuration(
                    format!("DATABASE_URL must start with postgres:// or sqlite:, got {url:?}")
                        .into(),
                ));
            }
            None => {
                let opts = SqliteConnectOptions::new().filename(data_dir.join("terraplan.sqlite3"));
                Db::Sqlite(sqlite_pool(opts).await?)
            }
        };
        on_pool!(&db, pool => MIGRATOR.run(pool).await)?;
        Ok(db)
    }

    pub fn backend(&self) -> &'static str {
        match self {
            Db::Sqlite(_) => "sqlite",
            Db::Postgres(_) => "postgres",
        }
    }

    pub async fn ping(&self) -> Result<(), sqlx::Error> {
        on_pool!(self, pool => sqlx::query("SELECT 1").execute(pool).await.map(|_| ()))
    }

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

    pub async fn insert_dem(&self, meta: &DemMetaRow, data: &[u8]) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO dems (id, name, created_at, file_name, crs_override, info, size_bytes, data) \
                           VALUES ($1, $2, $3, $4, $5, $6, $7, $8)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&meta.id)
            .bind(&meta.name)
            .bind(meta.created_at)
            .bind(&meta.file_name)
            .bind(meta.crs_override)
            .bind(&meta.info)
            .bind(meta.size_bytes)
            .bind(data)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    pub async fn get_dem_meta(&self, id: &str) -> Result<Option<DemMetaRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, file_name, crs_override, info, size_bytes \
                           FROM dems WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, DemMetaRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    pub async fn get_dem_data(&self, id: &str) -> Result<Option<DemDataRow>, sqlx::Error> {
        const SQL: &str = "SELECT file_name, crs_override, data FROM dems WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, DemDataRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// Newest first, without the files.
    pub async fn list_dems(
        &self,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<DemMetaRow>, i64), sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, file_name, crs_override, info, size_bytes \
                           FROM dems ORDER BY created_at DESC, id DESC LIMIT $1 OFFSET $2";
        const COUNT: &str = "SELECT COUNT(*) FROM dems";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, DemMetaRow>(SQL).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).fetch_one(pool).await?;
            Ok((rows, total))
        })
    }

    /// True when a DEM was deleted.
    pub async fn delete_dem(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM dems WHERE id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(id).execute(pool).await.map(|r| r.rows_affected() > 0))
    }

    /// Store a new job, queued and held by `owner` until `lease_until`.
    pub async fn insert_costmap(
        &self,
        row: &CostmapRow,
        owner: &str,
        lease_until: i64,
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO costmaps (id, name, dem_id, created_at, updated_at, request, \
                           vehicle, status, progress, stage, result, error, attempts, owner, lease_until) \
                           VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15)";
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

    /// Newest first, without the files.
    pub async fn list_costmaps(
        &self,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<CostmapRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT ",
            costmap_columns!(),
            " FROM costmaps ORDER BY created_at DESC, id DESC LIMIT $1 OFFSET $2"
        );
        const COUNT: &str = "SELECT COUNT(*) FROM costmaps";
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, CostmapRow>(SQL).bind(limit).bind(offset).fetch_all(pool).await?;
            let (total,): (i64,) = sqlx::query_as(COUNT).fetch_one(pool).await?;
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
    /// files, in one transaction. False (and nothing written) when the job
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
        const FILE: &str = "INSERT INTO costmap_files (costmap_id, name, content_type, data) VALUES ($1, $2, $3, $4)";
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
                    .bind(&f.data)
                    .execute(&mut *tx)
                    .await?;
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
    /// `expired_before`; oldest first.
    pub async fn orphaned_costmaps(&self, expired_before: i64) -> Result<Vec<String>, sqlx::Error> {
        const SQL: &str = "SELECT id FROM costmaps WHERE status IN ('queued', 'running') \
                           AND (owner IS NULL OR lease_until < $1) ORDER BY created_at, id";
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
                           WHERE id = $1 AND status IN ('queued', 'running') \
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

    pub async fn get_costmap_file(
        &self,
        id: &str,
        name: &str,
    ) -> Result<Option<CostmapFileRow>, sqlx::Error> {
        const SQL: &str = "SELECT name, content_type, data FROM costmap_files \
                           WHERE costmap_id = $1 AND name = $2";
        on_pool!(self, pool => sqlx::query_as::<_, CostmapFileRow>(SQL)
            .bind(id)
            .bind(name)
            .fetch_optional(pool)
            .await)
    }

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

    pub async fn close(&self) {
        on_pool!(self, pool => pool.close().await)
    }
}

async fn sqlite_pool(opts: SqliteConnectOptions) -> Result<SqlitePool, sqlx::Error> {
    let opts = opts
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Normal)
        .busy_timeout(Duration::from_secs(10))
        .foreign_keys(true);
    SqlitePoolOptions::new()
        .max_connections(8)
        .connect_with(opts)
        .await
}
