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

    /// Store tiles of DEM `dem_id` (whose row comes later, with
    /// [`Db::insert_dem_tiled`]), in one short transaction.
    pub async fn insert_dem_tiles(
        &self,
        dem_id: &str,
        tiles: &[DemTileRow],
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO dem_tiles (dem_id, level, tile_row, tile_col, data) \
                           VALUES ($1, $2, $3, $4, $5)";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
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
            tx.commit().await
        })
    }

    /// Remove the tiles of an upload that failed.
    pub async fn delete_dem_tiles(&self, dem_id: &str) -> Result<(), sqlx::Error> {
        const SQL: &str = "DELETE FROM dem_tiles WHERE dem_id = $1";
        on_pool!(self, pool => sqlx::query(SQL).bind(dem_id).execute(pool).await.map(|_| ()))
    }

    /// Store a DEM whose tiles are stored (its file, if any, is `data`):
    /// its row, its tile set and its file's chunks in one transaction.
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
