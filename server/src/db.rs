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
