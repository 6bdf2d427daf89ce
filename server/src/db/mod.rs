//! Storage: SQLite in the data directory by default, PostgreSQL when
//! `DATABASE_URL=postgres://…`. All SQL lives in this module, one file per
//! resource (surveys, DEMs, costmaps, routes, stored files), and is written
//! once in the dialect both accept (`$n` placeholders in order, TEXT and
//! BIGINT). Here: the connection, the migrations and the shared helpers.

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

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

/// The condition of a listing that keeps the rows of the projects user
/// `$1` is a member of, and only those of project `$2` unless it is NULL.
/// Rows of no project are visible to no one.
macro_rules! visible_to_member {
    () => {
        "project_id IN (SELECT project_id FROM project_members WHERE user_id = $1) \
         AND ($2 IS NULL OR project_id = $2)"
    };
}

// After `on_pool!` and `visible_to_member!`: a macro is only visible to
// modules declared below it.
mod accounts;
mod costmap_tiles;
mod costmaps;
mod dems;
mod files;
mod projects;
mod routes;
mod surveys;

pub use accounts::{SessionRow, TokenRow, UserRow};
pub use costmap_tiles::{
    TileClaim, TileJob, TileJobKey, TileOutput, TileProgress, TileStage, WrittenFile,
    partial_file_name,
};
pub use costmaps::{CostmapFileRow, CostmapRow};
pub use dems::{DemMetaRow, DemTileRow, DemTileSetRow};
pub use files::StoredFile;
pub use projects::{MemberChange, MemberRow, MembershipRow, ProjectRow};
pub use routes::RouteRow;
pub use surveys::{SurveyRow, SurveySummaryRow};

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
            project_id: None,
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
