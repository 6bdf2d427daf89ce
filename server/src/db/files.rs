//! Stored files (a DEM's upload, a costmap's outputs), read back a chunk
//! at a time.

use futures_util::Stream;

use super::Db;

/// A stored file, read a chunk at a time.
#[derive(Debug, Clone)]
pub enum StoredFile {
    /// A DEM's file as uploaded.
    Dem(String),
    /// A costmap's file: costmap id and file name.
    Costmap(String, String),
}

impl Db {
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

    /// The length in bytes of each chunk of a stored file, in `seq`
    /// order, with its `seq`: where each chunk lies in the file, for
    /// reading byte ranges (chunks are at most 1 MiB, not all the same).
    pub async fn file_chunk_lengths(
        &self,
        file: &StoredFile,
    ) -> Result<Vec<(i64, i64)>, sqlx::Error> {
        const DEM: &str = "SELECT seq, CAST(length(data) AS BIGINT) FROM dem_chunks \
                           WHERE dem_id = $1 ORDER BY seq";
        const COSTMAP: &str = "SELECT seq, CAST(length(data) AS BIGINT) FROM costmap_file_chunks \
                               WHERE costmap_id = $1 AND name = $2 ORDER BY seq";
        on_pool!(self, pool => match file {
            StoredFile::Dem(id) => sqlx::query_as(DEM).bind(id).fetch_all(pool).await,
            StoredFile::Costmap(id, name) => {
                sqlx::query_as(COSTMAP).bind(id).bind(name).fetch_all(pool).await
            }
        })
    }

    /// Chunks `first..=last` of a stored file, (`seq`, data) in order (those
    /// that exist).
    pub async fn file_chunks_between(
        &self,
        file: &StoredFile,
        first: i64,
        last: i64,
    ) -> Result<Vec<(i64, Vec<u8>)>, sqlx::Error> {
        const DEM: &str = "SELECT seq, data FROM dem_chunks \
                           WHERE dem_id = $1 AND seq >= $2 AND seq <= $3 ORDER BY seq";
        const COSTMAP: &str = "SELECT seq, data FROM costmap_file_chunks \
                               WHERE costmap_id = $1 AND name = $2 AND seq >= $3 AND seq <= $4 \
                               ORDER BY seq";
        on_pool!(self, pool => match file {
            StoredFile::Dem(id) => {
                sqlx::query_as(DEM)
                    .bind(id)
                    .bind(first)
                    .bind(last)
                    .fetch_all(pool)
                    .await
            }
            StoredFile::Costmap(id, name) => {
                sqlx::query_as(COSTMAP)
                    .bind(id)
                    .bind(name)
                    .bind(first)
                    .bind(last)
                    .fetch_all(pool)
                    .await
            }
        })
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
}
