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
