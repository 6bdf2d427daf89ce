//! DEMs: their metadata, their files stored as chunks, and their tiles.

use super::files::StoredFile;
use super::{CHUNK_BYTES, Db};

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
    /// The project it belongs to; `None` for DEMs stored before accounts
    /// and not yet adopted (visible to no one).
    pub project_id: Option<String>,
}

/// What is needed to parse a stored DEM again.
#[derive(Debug, Clone)]
pub struct DemDataRow {
    pub file_name: Option<String>,
    pub crs_override: Option<i64>,
    pub data: Vec<u8>,
}

/// How a DEM's tiles are stored (`state::dem_store::tiles::TileSet`).
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct DemTileSetRow {
    pub tile_size: i64,
    /// `f32` or `f64`.
    pub sample: String,
    pub levels: i64,
    /// The level-0 `GeoTransform`, as JSON.
    pub transform: String,
    /// Bytes of all its tiles, compressed.
    pub size_bytes: i64,
}

/// One compressed tile, to store.
#[derive(Debug, Clone)]
pub struct DemTileRow {
    pub level: i64,
    pub row: i64,
    pub col: i64,
    pub data: Vec<u8>,
}

impl Db {
    /// Store a DEM and its file (`meta.size_bytes` must be its length),
    /// a chunk at a time, in one transaction.
    #[cfg_attr(not(test), allow(dead_code))] // uploads store tiles too (insert_dem_tiled)
    pub async fn insert_dem(&self, meta: &DemMetaRow, data: &[u8]) -> Result<(), sqlx::Error> {
        self.insert_dem_with(meta, data, None).await
    }

    /// [`Db::insert_dem`], with the DEM's tile set (the insert and the row)
    /// in the same transaction.
    async fn insert_dem_with(
        &self,
        meta: &DemMetaRow,
        data: &[u8],
        set: Option<(&'static str, &DemTileSetRow)>,
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO dems (id, name, created_at, file_name, crs_override, info, \
                           size_bytes, read_bytes, project_id) \
                           VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)";
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
                .bind(&meta.project_id)
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
            if let Some((sql, set)) = set {
                // The upload ends here; swept meanwhile, it stores nothing.
                const UPLOAD: &str = "DELETE FROM dem_uploads WHERE dem_id = $1";
                let held = sqlx::query(UPLOAD)
                    .bind(&meta.id)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected()
                    == 1;
                if !held {
                    tx.rollback().await?;
                    return Err(sqlx::Error::RowNotFound);
                }
                sqlx::query(sql)
                    .bind(&meta.id)
                    .bind(set.tile_size)
                    .bind(&set.sample)
                    .bind(set.levels)
                    .bind(&set.transform)
                    .bind(set.size_bytes)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await
        })
    }

    pub async fn get_dem_meta(&self, id: &str) -> Result<Option<DemMetaRow>, sqlx::Error> {
        const SQL: &str = "SELECT id, name, created_at, file_name, crs_override, info, size_bytes, \
                           read_bytes, project_id FROM dems WHERE id = $1";
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

    /// Newest first, without the files: those of the projects `user_id`
    /// is a member of (of `project_id` only, when given).
    pub async fn list_dems(
        &self,
        user_id: &str,
        project_id: Option<&str>,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<DemMetaRow>, i64), sqlx::Error> {
        const SQL: &str = concat!(
            "SELECT id, name, created_at, file_name, crs_override, info, size_bytes, read_bytes, \
             project_id FROM dems WHERE ",
            visible_to_member!(),
            " ORDER BY created_at DESC, id DESC LIMIT $3 OFFSET $4"
        );
        const COUNT: &str = concat!("SELECT COUNT(*) FROM dems WHERE ", visible_to_member!());
        on_pool!(self, pool => {
            let rows = sqlx::query_as::<_, DemMetaRow>(SQL)
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

    /// True when a DEM was deleted (with its tiles).
    pub async fn delete_dem(&self, id: &str) -> Result<bool, sqlx::Error> {
        const SQL: &str = "DELETE FROM dems WHERE id = $1";
        const TILES: &str = "DELETE FROM dem_tiles WHERE dem_id = $1";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let gone = sqlx::query(SQL).bind(id).execute(&mut *tx).await?.rows_affected() > 0;
            sqlx::query(TILES).bind(id).execute(&mut *tx).await?;
            tx.commit().await?;
            Ok(gone)
        })
    }

    /// Record upload `dem_id` (of `project_id`, held by `owner` until
    /// `lease_until`, ms) before any of its tiles is stored.
    pub async fn begin_dem_upload(
        &self,
        dem_id: &str,
        project_id: Option<&str>,
        owner: &str,
        now: i64,
        lease_until: i64,
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO dem_uploads (dem_id, project_id, owner, started_at, \
                           lease_until, size_bytes) VALUES ($1, $2, $3, $4, $5, 0)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(dem_id)
            .bind(project_id)
            .bind(owner)
            .bind(now)
            .bind(lease_until)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    /// Renew `owner`'s lease on upload `dem_id`; false when the upload is
    /// no longer recorded (swept after its lease ran out).
    pub async fn renew_dem_upload(
        &self,
        dem_id: &str,
        owner: &str,
        lease_until: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE dem_uploads SET lease_until = $3 \
                           WHERE dem_id = $1 AND owner = $2";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(dem_id)
            .bind(owner)
            .bind(lease_until)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() == 1))
    }

    /// Store tiles of upload `dem_id` (held by `owner`; its DEM's row
    /// comes later, with [`Db::insert_dem_tiled`]) in one short
    /// transaction that also adds their bytes to the upload's and renews
    /// its lease to `lease_until`. False, and nothing stored, when the
    /// upload is no longer recorded (swept).
    pub async fn insert_dem_tiles(
        &self,
        dem_id: &str,
        owner: &str,
        tiles: &[DemTileRow],
        lease_until: i64,
    ) -> Result<bool, sqlx::Error> {
        // The upload's row first: on PostgreSQL its lock orders this
        // transaction with a sweep of the same upload.
        const UPLOAD: &str = "UPDATE dem_uploads SET size_bytes = size_bytes + $3, \
                              lease_until = $4 WHERE dem_id = $1 AND owner = $2";
        const SQL: &str = "INSERT INTO dem_tiles (dem_id, level, tile_row, tile_col, data) \
                           VALUES ($1, $2, $3, $4, $5)";
        let bytes: i64 = tiles.iter().map(|t| t.data.len() as i64).sum();
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let held = sqlx::query(UPLOAD)
                .bind(dem_id)
                .bind(owner)
                .bind(bytes)
                .bind(lease_until)
                .execute(&mut *tx)
                .await?
                .rows_affected()
                == 1;
            if !held {
                tx.rollback().await?;
                return Ok(false);
            }
            for t in tiles {
                sqlx::query(SQL)
                    .bind(dem_id)
                    .bind(t.level)
                    .bind(t.row)
                    .bind(t.col)
                    .bind(&t.data)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// Remove an upload that failed: its tiles and its record, in one
    /// transaction.
    pub async fn abandon_dem_upload(&self, dem_id: &str) -> Result<(), sqlx::Error> {
        const TILES: &str = "DELETE FROM dem_tiles WHERE dem_id = $1";
        const UPLOAD: &str = "DELETE FROM dem_uploads WHERE dem_id = $1";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(TILES).bind(dem_id).execute(&mut *tx).await?;
            sqlx::query(UPLOAD).bind(dem_id).execute(&mut *tx).await?;
            tx.commit().await
        })
    }

    /// Sweep the uploads whose lease ended before `now` (every upload
    /// recorded, when `every` is set: a SQLite server at start-up is the
    /// only process on its file), each with its tiles in one transaction;
    /// the ids swept. An upload renewed meanwhile is left alone.
    pub async fn sweep_dem_uploads(
        &self,
        now: i64,
        every: bool,
    ) -> Result<Vec<String>, sqlx::Error> {
        const EXPIRED: &str = "SELECT dem_id FROM dem_uploads WHERE lease_until < $1 OR $2";
        const UPLOAD: &str =
            "DELETE FROM dem_uploads WHERE dem_id = $1 AND (lease_until < $2 OR $3)";
        const TILES: &str = "DELETE FROM dem_tiles WHERE dem_id = $1";
        on_pool!(self, pool => {
            let ids: Vec<(String,)> = sqlx::query_as(EXPIRED)
                .bind(now)
                .bind(every)
                .fetch_all(pool)
                .await?;
            let mut swept = Vec::new();
            for (id,) in ids {
                let mut tx = pool.begin().await?;
                let gone = sqlx::query(UPLOAD)
                    .bind(&id)
                    .bind(now)
                    .bind(every)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected()
                    == 1;
                if gone {
                    sqlx::query(TILES).bind(&id).execute(&mut *tx).await?;
                }
                tx.commit().await?;
                if gone {
                    swept.push(id);
                }
            }
            Ok(swept)
        })
    }

    /// Delete the tiles that belong to no DEM and no upload in progress
    /// (left by a server killed mid-upload before uploads were recorded);
    /// the ids whose tiles went.
    pub async fn sweep_unowned_dem_tiles(&self) -> Result<Vec<String>, sqlx::Error> {
        const UNOWNED: &str = "SELECT DISTINCT t.dem_id FROM dem_tiles t \
            WHERE NOT EXISTS (SELECT 1 FROM dems d WHERE d.id = t.dem_id) \
            AND NOT EXISTS (SELECT 1 FROM dem_uploads u WHERE u.dem_id = t.dem_id)";
        const TILES: &str = "DELETE FROM dem_tiles WHERE dem_id = $1 \
            AND NOT EXISTS (SELECT 1 FROM dems d WHERE d.id = $1) \
            AND NOT EXISTS (SELECT 1 FROM dem_uploads u WHERE u.dem_id = $1)";
        on_pool!(self, pool => {
            let ids: Vec<(String,)> = sqlx::query_as(UNOWNED).fetch_all(pool).await?;
            for (id,) in &ids {
                sqlx::query(TILES).bind(id).execute(pool).await?;
            }
            Ok(ids.into_iter().map(|(id,)| id).collect())
        })
    }

    /// Store the DEM of upload `meta.id`, whose tiles are stored (its
    /// file, if any, is `data`): its row, its tile set and its file's
    /// chunks, with the upload's record removed, in one transaction.
    /// Fails (storing nothing) when the upload is no longer recorded.
    pub async fn insert_dem_tiled(
        &self,
        meta: &DemMetaRow,
        set: &DemTileSetRow,
        data: &[u8],
    ) -> Result<(), sqlx::Error> {
        const SET: &str = "INSERT INTO dem_tile_sets (dem_id, tile_size, sample, levels, \
                           transform, size_bytes) VALUES ($1, $2, $3, $4, $5, $6)";
        self.insert_dem_with(meta, data, Some((SET, set))).await
    }

    /// A DEM's tile set; `None` for a DEM stored before tiles (or none).
    pub async fn dem_tile_set(&self, id: &str) -> Result<Option<DemTileSetRow>, sqlx::Error> {
        const SQL: &str = "SELECT tile_size, sample, levels, transform, size_bytes FROM dem_tile_sets \
                           WHERE dem_id = $1";
        on_pool!(self, pool => sqlx::query_as::<_, DemTileSetRow>(SQL).bind(id).fetch_optional(pool).await)
    }

    /// One compressed tile of a DEM.
    pub async fn dem_tile(
        &self,
        id: &str,
        level: i64,
        row: i64,
        col: i64,
    ) -> Result<Option<Vec<u8>>, sqlx::Error> {
        const SQL: &str = "SELECT data FROM dem_tiles \
                           WHERE dem_id = $1 AND level = $2 AND tile_row = $3 AND tile_col = $4";
        let row: Option<(Vec<u8>,)> = on_pool!(self, pool => sqlx::query_as(SQL)
            .bind(id)
            .bind(level)
            .bind(row)
            .bind(col)
            .fetch_optional(pool)
            .await)?;
        Ok(row.map(|(d,)| d))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn temp_db() -> (Db, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("terraplan-uploads-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        (Db::connect(None, &dir).await.unwrap(), dir)
    }

    fn tiles(n: usize) -> Vec<DemTileRow> {
        (0..n)
            .map(|i| DemTileRow {
                level: 0,
                row: 0,
                col: i as i64,
                data: vec![i as u8; 10],
            })
            .collect()
    }

    async fn count(db: &Db, table: &str) -> i64 {
        let sql = format!("SELECT COUNT(*) FROM {table}");
        on_pool!(db, pool => sqlx::query_as::<_, (i64,)>(sqlx::AssertSqlSafe(sql.as_str()))
            .fetch_one(pool).await.unwrap().0)
    }

    fn meta(id: &str) -> DemMetaRow {
        DemMetaRow {
            id: id.into(),
            name: None,
            created_at: 1,
            file_name: None,
            crs_override: None,
            info: "{}".into(),
            size_bytes: 5,
            read_bytes: None,
            project_id: None,
        }
    }

    fn set(bytes: i64) -> DemTileSetRow {
        DemTileSetRow {
            tile_size: 512,
            sample: "f32".into(),
            levels: 1,
            transform: "{}".into(),
            size_bytes: bytes,
        }
    }

    /// Only uploads whose lease ran out are swept (with their tiles), one
    /// renewed in time is not; a swept upload's holder can store no more
    /// tiles nor its DEM; a finished upload leaves no record.
    #[tokio::test]
    async fn uploads_whose_lease_ran_out_are_swept_with_their_tiles() {
        let (db, dir) = temp_db().await;
        db.begin_dem_upload("dead", Some("p"), "a", 0, 1000)
            .await
            .unwrap();
        db.begin_dem_upload("alive", Some("p"), "b", 0, 1000)
            .await
            .unwrap();
        assert!(
            db.insert_dem_tiles("dead", "a", &tiles(3), 1500)
                .await
                .unwrap()
        );
        assert!(
            db.insert_dem_tiles("alive", "b", &tiles(2), 1500)
                .await
                .unwrap()
        );
        // Another owner's claim stores nothing.
        assert!(
            !db.insert_dem_tiles("alive", "a", &tiles(1), 1500)
                .await
                .unwrap()
        );
        assert!(db.renew_dem_upload("alive", "b", 5000).await.unwrap());
        assert_eq!(count(&db, "dem_tiles").await, 5);

        assert_eq!(
            db.sweep_dem_uploads(2000, false).await.unwrap(),
            vec!["dead"]
        );
        assert_eq!(count(&db, "dem_tiles").await, 2);
        assert_eq!(count(&db, "dem_uploads").await, 1);
        // The swept upload's holder finds it gone.
        assert!(!db.renew_dem_upload("dead", "a", 9000).await.unwrap());
        assert!(
            !db.insert_dem_tiles("dead", "a", &tiles(1), 9000)
                .await
                .unwrap()
        );
        assert!(matches!(
            db.insert_dem_tiled(&meta("dead"), &set(30), &[]).await,
            Err(sqlx::Error::RowNotFound)
        ));
        assert!(db.get_dem_meta("dead").await.unwrap().is_none());
        assert_eq!(count(&db, "dem_tiles").await, 2);

        // The running one finishes: its record goes with the DEM's commit.
        db.insert_dem_tiled(&meta("alive"), &set(20), &[])
            .await
            .unwrap();
        assert_eq!(count(&db, "dem_uploads").await, 0);
        assert_eq!(count(&db, "dem_tile_sets").await, 1);
        // At start-up on SQLite every record is swept, whatever its lease;
        // tiles of no DEM and no upload too, and a DEM's are kept.
        db.begin_dem_upload("fresh", None, "c", 0, i64::MAX)
            .await
            .unwrap();
        assert!(
            db.insert_dem_tiles("fresh", "c", &tiles(1), i64::MAX)
                .await
                .unwrap()
        );
        assert_eq!(
            db.sweep_dem_uploads(0, false).await.unwrap(),
            Vec::<String>::new()
        );
        assert_eq!(db.sweep_dem_uploads(0, true).await.unwrap(), vec!["fresh"]);
        on_pool!(&db, pool => sqlx::query(
            "INSERT INTO dem_tiles (dem_id, level, tile_row, tile_col, data) VALUES ('lost', 0, 0, 0, x'00')")
            .execute(pool).await.map(|_| ()).unwrap());
        assert_eq!(db.sweep_unowned_dem_tiles().await.unwrap(), vec!["lost"]);
        assert_eq!(count(&db, "dem_tiles").await, 2);
        // A failed upload is abandoned: tiles and record.
        db.begin_dem_upload("failed", None, "d", 0, i64::MAX)
            .await
            .unwrap();
        assert!(
            db.insert_dem_tiles("failed", "d", &tiles(4), i64::MAX)
                .await
                .unwrap()
        );
        db.abandon_dem_upload("failed").await.unwrap();
        assert_eq!(count(&db, "dem_tiles").await, 2);
        assert_eq!(count(&db, "dem_uploads").await, 0);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    /// A project's usage counts its DEMs' tiles, the files kept, and the
    /// tiles of its uploads running.
    #[tokio::test]
    async fn usage_counts_tiles_kept_files_and_uploads_running() {
        let (db, dir) = temp_db().await;
        let in_p = |id: &str, size| DemMetaRow {
            project_id: Some("p".into()),
            size_bytes: size,
            ..meta(id)
        };
        // Projects are rows of their own: the DEMs' project must exist.
        on_pool!(&db, pool => sqlx::query(
            "INSERT INTO projects (id, name, created_at, personal_of) VALUES ('p', 'p', 0, NULL)")
            .execute(pool).await.map(|_| ()).unwrap());
        // A GeoTIFF: tiles only (its file, 5 bytes, is not kept).
        db.begin_dem_upload("g", Some("p"), "o", 0, i64::MAX)
            .await
            .unwrap();
        assert!(
            db.insert_dem_tiles("g", "o", &tiles(3), i64::MAX)
                .await
                .unwrap()
        );
        db.insert_dem_tiled(&in_p("g", 5), &set(30), &[])
            .await
            .unwrap();
        assert_eq!(db.project_usage("p").await.unwrap().0, 30);
        // An ESRI grid: tiles and its file.
        db.begin_dem_upload("e", Some("p"), "o", 0, i64::MAX)
            .await
            .unwrap();
        db.insert_dem_tiled(&in_p("e", 7), &set(11), b"1234567")
            .await
            .unwrap();
        assert_eq!(db.project_usage("p").await.unwrap().0, 30 + 11 + 7);
        // An upload running: its tiles so far.
        db.begin_dem_upload("u", Some("p"), "o", 0, i64::MAX)
            .await
            .unwrap();
        assert!(
            db.insert_dem_tiles("u", "o", &tiles(2), i64::MAX)
                .await
                .unwrap()
        );
        assert_eq!(db.project_usage("p").await.unwrap().0, 30 + 11 + 7 + 20);
        // A DEM stored before tiles: its file.
        db.insert_dem(&in_p("old", 4), b"abcd").await.unwrap();
        assert_eq!(db.project_usage("p").await.unwrap().0, 30 + 11 + 7 + 20 + 4);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }
}
