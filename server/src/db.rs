//! Storage: SQLite in the data directory by default, PostgreSQL when
//! `DATABASE_URL=postgres://…`. All SQL lives here and is written once in
//! the dialect both accept (`$n` placeholders in order, TEXT and BIGINT).

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use futures_util::Stream;

use sqlx::postgres::{PgPool, PgPoolOptions};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};

static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("../migrations");

/// Files are stored as rows of at most this many bytes (see the
/// migration `file_chunks`), written and read one at a time.
pub const CHUNK_BYTES: usize = 1024 * 1024;

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
    /// Memory reading the file again takes, estimated from its header at
    /// upload; `None` for DEMs stored before it was kept.
    pub read_bytes: Option<i64>,
}

/// What is needed to parse a stored DEM again.
#[derive(Debug, Clone)]
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

/// A stored file, read a chunk at a time.
#[derive(Debug, Clone)]
pub enum StoredFile {
    /// A DEM's file as uploaded.
    Dem(String),
    /// A costmap's file: costmap id and file name.
    Costmap(String, String),
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

    /// Store a DEM and its file (`meta.size_bytes` must be its length),
    /// a chunk at a time, in one transaction.
    pub async fn insert_dem(&self, meta: &DemMetaRow, data: &[u8]) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO dems (id, name, created_at, file_name, crs_override, info, \
                           size_bytes, read_bytes) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)";
        const CHUNK: &str = "INSERT INTO dem_chunks (dem_id, seq, data) VALUES ($1, $2, $3)";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(SQL)
                .bind(&meta.id)
                .bind(&meta.name)
                .bind(meta.created_at)
                .bind(&meta.file_name)
                .bind(meta.crs_override)
                .bind(&meta.info)
                .bind(meta.size_bytes)
                .bind(meta.read_bytes)
                .execute(&mut *tx)
                .await?;
            for (seq, chunk) in data.chunks(CHUNK_BYTES).enumerate() {
                sqlx::query(CHUNK)
                    .bind(&meta.id)
                    .bind(seq as i64)
                    .bind(chunk)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await
        })
    }

    pub async fn get_dem_meta(&self, id: &str) -> Result<Option<DemMetaRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, file_name, crs_override, info, size_bytes, \
                           read_bytes FROM dems WHERE id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, DemMetaRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// A stored DEM's file, read whole (a chunk at a time into one buffer).
    pub async fn get_dem_data(&self, id: &str) -> Result<Option<DemDataRow>, sqlx::Error> {
        const SQL: &str = "SELECT file_name, crs_override, size_bytes FROM dems WHERE id = $1";
        let row: Option<(Option<String>, Option<i64>, i64)> = on_pool!(self, pool =>
            sqlx::query_as(SQL).bind(id).fetch_optional(pool).await)?;
        let Some((file_name, crs_override, size)) = row else {
            return Ok(None);
        };
        let data = self
            .read_file(&StoredFile::Dem(id.to_string()), size)
            .await?;
        Ok(Some(DemDataRow {
            file_name,
            crs_override,
            data,
        }))
    }

    /// Chunk `seq` of a stored file; `None` past its end.
    pub async fn file_chunk(
        &self,
        file: &StoredFile,
        seq: i64,
    ) -> Result<Option<Vec<u8>>, sqlx::Error> {
        const DEM: &str = "SELECT data FROM dem_chunks WHERE dem_id = $1 AND seq = $2";
        const COSTMAP: &str = "SELECT data FROM costmap_file_chunks \
                               WHERE costmap_id = $1 AND name = $2 AND seq = $3";
        let row: Option<(Vec<u8>,)> = match file {
            StoredFile::Dem(id) => on_pool!(self, pool => sqlx::query_as(DEM)
                .bind(id)
                .bind(seq)
                .fetch_optional(pool)
                .await)?,
            StoredFile::Costmap(id, name) => on_pool!(self, pool => sqlx::query_as(COSTMAP)
                .bind(id)
                .bind(name)
                .bind(seq)
                .fetch_optional(pool)
                .await)?,
        };
        Ok(row.map(|(data,)| data))
    }

    /// The `size` bytes of a stored file, a chunk at a time: one query per
    /// chunk, so no connection is held between chunks (a slow reader holds
    /// none). Ends with an error if the file turns out shorter (deleted
    /// meanwhile).
    pub fn file_chunks(
        &self,
        file: StoredFile,
        size: i64,
    ) -> impl Stream<Item = Result<Vec<u8>, sqlx::Error>> + Send + 'static {
        let size = u64::try_from(size).unwrap_or(0);
        futures_util::stream::try_unfold(
            (self.clone(), file, 0i64, 0u64),
            move |(db, file, seq, done)| async move {
                if done >= size {
                    return Ok(None);
                }
                match db.file_chunk(&file, seq).await? {
                    Some(chunk) if !chunk.is_empty() => {
                        let done = done + chunk.len() as u64;
                        Ok(Some((chunk, (db, file, seq + 1, done))))
                    }
                    _ => Err(sqlx::Error::RowNotFound),
                }
            },
        )
    }

    /// A stored file of `size` bytes, read whole into one buffer.
    pub async fn read_file(&self, file: &StoredFile, size: i64) -> Result<Vec<u8>, sqlx::Error> {
        use futures_util::TryStreamExt;
        let mut data = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
        let mut chunks = std::pin::pin!(self.file_chunks(file.clone(), size));
        while let Some(chunk) = chunks.try_next().await? {
            data.extend_from_slice(&chunk);
        }
        Ok(data)
    }

    /// Newest first, without the files.
    pub async fn list_dems(
        &self,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<DemMetaRow>, i64), sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, file_name, crs_override, info, size_bytes, \
                           read_bytes FROM dems ORDER BY created_at DESC, id DESC LIMIT $1 OFFSET $2";
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

#[cfg(test)]
mod tests {
    use futures_util::TryStreamExt;

    use super::*;

    /// `n` bytes that differ from chunk to chunk.
    fn pattern(n: usize) -> Vec<u8> {
        (0..n)
            .map(|i| (i % 251) as u8 ^ (i / CHUNK_BYTES) as u8)
            .collect()
    }

    async fn temp_db() -> (Db, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("terraplan-db-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        (Db::connect(None, &dir).await.unwrap(), dir)
    }

    fn dem_row(id: &str, size: usize) -> DemMetaRow {
        DemMetaRow {
            id: id.into(),
            name: None,
            created_at: 1,
            file_name: Some("x.tif".into()),
            crs_override: None,
            info: "{}".into(),
            size_bytes: size as i64,
            read_bytes: Some(7),
        }
    }

    /// Files go in as chunks of 1 MiB and come out whole, streamed or
    /// read at once; deleting their owner deletes the chunks.
    #[tokio::test]
    async fn files_are_stored_and_read_in_chunks() {
        let (db, dir) = temp_db().await;
        let data = pattern(2 * CHUNK_BYTES + 5);
        db.insert_dem(&dem_row("d", data.len()), &data)
            .await
            .unwrap();
        assert_eq!(db.get_dem_data("d").await.unwrap().unwrap().data, data);
        assert_eq!(
            db.get_dem_meta("d").await.unwrap().unwrap().read_bytes,
            Some(7)
        );
        let file = StoredFile::Dem("d".into());
        let chunks: Vec<Vec<u8>> = db
            .file_chunks(file.clone(), data.len() as i64)
            .try_collect()
            .await
            .unwrap();
        let sizes: Vec<usize> = chunks.iter().map(Vec::len).collect();
        assert_eq!(sizes, [CHUNK_BYTES, CHUNK_BYTES, 5]);
        // A file shorter than its owner says ends in an error, not short.
        let long: Result<Vec<Vec<u8>>, _> = db
            .file_chunks(file, data.len() as i64 + 1)
            .try_collect()
            .await;
        assert!(long.is_err());
        assert!(db.delete_dem("d").await.unwrap());
        let Db::Sqlite(pool) = &db else {
            unreachable!()
        };
        let (left,): (i64,) = sqlx::query_as("SELECT COUNT(*) FROM dem_chunks")
            .fetch_one(pool)
            .await
            .unwrap();
        assert_eq!(left, 0);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    /// A database of the migrations before chunks, with files stored
    /// whole, is migrated: every file reads back the same, in chunks.
    #[tokio::test]
    async fn stored_files_migrate_to_chunks() {
        let dir = std::env::temp_dir().join(format!("terraplan-db-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let opts = SqliteConnectOptions::new().filename(dir.join("terraplan.sqlite3"));
        let pool = sqlite_pool(opts).await.unwrap();
        // The migrations before `file_chunks`, as sqlx applies them.
        let old_dir = dir.join("migrations");
        std::fs::create_dir_all(&old_dir).unwrap();
        let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../migrations");
        let mut copied = 0;
        for entry in std::fs::read_dir(source).unwrap() {
            let path = entry.unwrap().path();
            let name = path.file_name().unwrap().to_str().unwrap().to_string();
            if name.as_str() < "20261201000001" {
                std::fs::copy(&path, old_dir.join(name)).unwrap();
                copied += 1;
            }
        }
        assert_eq!(copied, 4);
        let before = sqlx::migrate::Migrator::new(old_dir.as_path())
            .await
            .unwrap();
        before.run(&pool).await.unwrap();
        let dem = pattern(3 * CHUNK_BYTES);
        let tif = pattern(CHUNK_BYTES + 1);
        sqlx::query(
            "INSERT INTO dems (id, name, created_at, file_name, crs_override, info, size_bytes, \
             data) VALUES ('d', NULL, 1, 'x.tif', NULL, '{}', $1, $2)",
        )
        .bind(dem.len() as i64)
        .bind(&dem)
        .execute(&pool)
        .await
        .unwrap();
        sqlx::query(
            "INSERT INTO costmaps (id, dem_id, created_at, updated_at, request, vehicle, status) \
             VALUES ('c', 'd', 1, 1, '{}', '{}', 'done')",
        )
        .execute(&pool)
        .await
        .unwrap();
        for (name, data) in [("costmap.tif", &tif), ("legend.svg", &b"<svg/>".to_vec())] {
            sqlx::query(
                "INSERT INTO costmap_files (costmap_id, name, content_type, data) \
                 VALUES ('c', $1, 'x', $2)",
            )
            .bind(name)
            .bind(data)
            .execute(&pool)
            .await
            .unwrap();
        }
        MIGRATOR.run(&pool).await.unwrap();
        let db = Db::Sqlite(pool.clone());
        let meta = db.get_dem_meta("d").await.unwrap().unwrap();
        assert_eq!((meta.size_bytes, meta.read_bytes), (dem.len() as i64, None));
        assert_eq!(db.get_dem_data("d").await.unwrap().unwrap().data, dem);
        let file = db
            .get_costmap_file("c", "costmap.tif")
            .await
            .unwrap()
            .unwrap();
        assert_eq!(file.data, tif);
        let meta = db
            .costmap_file_meta("c", "legend.svg")
            .await
            .unwrap()
            .unwrap();
        assert_eq!(meta.size_bytes, 6);
        let (chunks,): (i64,) =
            sqlx::query_as("SELECT COUNT(*) FROM dem_chunks WHERE dem_id = 'd'")
                .fetch_one(&pool)
                .await
                .unwrap();
        assert_eq!(chunks, 3);
        assert!(db.delete_costmap("c").await.unwrap());
        let (left,): (i64,) = sqlx::query_as("SELECT COUNT(*) FROM costmap_file_chunks")
            .fetch_one(&pool)
            .await
            .unwrap();
        assert_eq!(left, 0);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
