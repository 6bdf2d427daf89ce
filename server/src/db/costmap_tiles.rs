//! Costmaps built as tiles by every process on the database: the queue
//! of tile jobs (`costmap_tile_jobs`), what the stages pass on and the
//! output tiles (`costmap_tiles`), and the files the finish stage writes
//! a chunk at a time (see the migration `costmap_tile_jobs`).
//!
//! A job is claimable when it is queued, or running with a lease that ran
//! out, and every job of the earlier stages of its costmap is done. On
//! PostgreSQL the claim locks the row it picks with `FOR UPDATE SKIP
//! LOCKED`, so processes claiming at once each get another job; SQLite is
//! one process' alone and serialises writes. A job's outputs and its
//! status done are written in one transaction guarded by its owner, so a
//! job taken over after its lease ran out is never counted twice.

use super::{CostmapFileRow, Db};

/// The stages of a tiled costmap, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum TileStage {
    /// Per tile: classes before the pocket fill and the edges for the join.
    Classify = 1,
    /// Once: the edges joined into the fill decision.
    Join = 2,
    /// Per tile: the pockets filled, final classes.
    Fill = 3,
    /// Per tile: inflation, costs, layers, statistics and preview parts.
    Cost = 4,
    /// Once: statistics, preview, legend, result and the files.
    Finish = 5,
}

impl TileStage {
    pub const ALL: [TileStage; 5] = [
        TileStage::Classify,
        TileStage::Join,
        TileStage::Fill,
        TileStage::Cost,
        TileStage::Finish,
    ];

    pub fn number(self) -> i64 {
        self as i64
    }

    pub fn from_number(n: i64) -> Option<TileStage> {
        TileStage::ALL.into_iter().find(|s| s.number() == n)
    }

    pub fn name(self) -> &'static str {
        match self {
            TileStage::Classify => "classify",
            TileStage::Join => "join",
            TileStage::Fill => "fill",
            TileStage::Cost => "cost",
            TileStage::Finish => "finish",
        }
    }

    /// One job per tile (else one for the whole costmap).
    pub fn per_tile(self) -> bool {
        matches!(
            self,
            TileStage::Classify | TileStage::Fill | TileStage::Cost
        )
    }

    /// The share of the whole build this stage is (rough timings: the
    /// per-tile stages that compute the surface weigh most).
    fn weight(self) -> f64 {
        match self {
            TileStage::Classify => 0.40,
            TileStage::Join => 0.02,
            TileStage::Fill => 0.08,
            TileStage::Cost => 0.45,
            TileStage::Finish => 0.05,
        }
    }

    /// The pipeline stage (`planner_core::costmap::Stage`'s stored name)
    /// the costmap's row shows while this stage runs.
    pub fn shown_as(self) -> &'static str {
        match self {
            TileStage::Classify => "normals",
            TileStage::Join | TileStage::Fill => "regions",
            TileStage::Cost | TileStage::Finish => "cost",
        }
    }

    /// What a job of this stage is, for messages.
    pub fn job_name(self, tile: i64) -> String {
        if self.per_tile() {
            format!("tile {tile} of stage {}", self.name())
        } else {
            format!("the {} stage", self.name())
        }
    }
}

/// One tile job.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TileJobKey {
    pub costmap_id: String,
    pub stage: TileStage,
    pub tile: i64,
}

/// A claimed tile job.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileJob {
    pub key: TileJobKey,
    /// Runs started, this one included.
    pub attempts: i64,
}

/// What a claim found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TileClaim {
    /// A job to run.
    Job(TileJob),
    /// A job that had started too often: its costmap is failed with
    /// `error` (and its tile jobs deleted).
    GaveUp { costmap_id: String, error: String },
}

/// Where a tiled costmap stands after one of its jobs was done.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileProgress {
    /// [0, 1], the stages weighted.
    pub progress: f64,
    /// The first stage not complete (`None`: all are).
    pub stage: Option<TileStage>,
}

/// One output of a tile job.
#[derive(Clone, Debug)]
pub struct TileOutput {
    pub kind: String,
    pub tile: i64,
    pub data: Vec<u8>,
}

/// A file the finish stage wrote in chunks under `partial` (see
/// [`Db::start_costmap_file`]), stored as `name` when the costmap is done.
#[derive(Clone, Debug)]
pub struct WrittenFile {
    pub partial: String,
    pub name: String,
    pub size_bytes: i64,
}

/// The stored name of a file being written by run `attempt` of `owner`,
/// apart from any other run's.
pub fn partial_file_name(owner: &str, attempt: i64, name: &str) -> String {
    format!("{PARTIAL_PREFIX}{owner}/{attempt}/{name}")
}

const PARTIAL_PREFIX: &str = "partial/";

const DELETE_JOBS: &str = "DELETE FROM costmap_tile_jobs WHERE costmap_id = $1";
const DELETE_TILES: &str = "DELETE FROM costmap_tiles WHERE costmap_id = $1";

/// Columns of a claimed job, for `RETURNING`.
type JobColumns = (String, i64, i64, i64, Option<String>);

/// The claim: the first claimable job in (costmap, stage, tile) order.
/// `$1` owner, `$2` now, `$3` lease end.
macro_rules! claim_sql {
    ($lock:literal) => {
        concat!(
            "UPDATE costmap_tile_jobs SET status = 'running', owner = $1, lease_until = $3, \
             attempts = attempts + 1, updated_at = $2 \
             WHERE (costmap_id, stage, tile) = (\
             SELECT j.costmap_id, j.stage, j.tile FROM costmap_tile_jobs j \
             WHERE (j.status = 'queued' OR (j.status = 'running' AND j.lease_until < $2)) \
             AND NOT EXISTS (SELECT 1 FROM costmap_tile_jobs e WHERE e.costmap_id = j.costmap_id \
             AND e.stage < j.stage AND e.status <> 'done') \
             ORDER BY j.costmap_id, j.stage, j.tile LIMIT 1",
            $lock,
            ") RETURNING costmap_id, stage, tile, attempts, error"
        )
    };
}

impl Db {
    /// Plan costmap `id` (running, held by `owner`) as tiles of `tile_side`
    /// cells, `tiles` of them: every job of every stage inserted queued,
    /// and the costmap's row let go of (its tile jobs have their own
    /// leases), in one transaction. False (nothing written) when the
    /// costmap is no longer `owner`'s.
    pub async fn plan_costmap_tiles(
        &self,
        id: &str,
        owner: &str,
        tile_side: i64,
        tiles: i64,
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const ROW: &str = "UPDATE costmaps SET tiled = $3, owner = NULL, lease_until = 0, \
                           status = 'running', progress = 0, stage = $5, updated_at = $4 \
                           WHERE id = $1 AND owner = $2 AND status = 'running'";
        const JOBS: &str = "WITH RECURSIVE k (tile) AS (SELECT 0 UNION ALL \
                            SELECT tile + 1 FROM k WHERE tile + 1 < $2) \
                            INSERT INTO costmap_tile_jobs (costmap_id, stage, tile, status, updated_at) \
                            SELECT $1, $3, tile, 'queued', $4 FROM k";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let updated = sqlx::query(ROW)
                .bind(id)
                .bind(owner)
                .bind(tile_side)
                .bind(now)
                .bind(TileStage::Classify.shown_as())
                .execute(&mut *tx)
                .await?
                .rows_affected();
            if updated == 0 {
                tx.rollback().await?;
                return Ok(false);
            }
            sqlx::query(DELETE_JOBS).bind(id).execute(&mut *tx).await?;
            sqlx::query(DELETE_TILES).bind(id).execute(&mut *tx).await?;
            for stage in TileStage::ALL {
                let n = if stage.per_tile() { tiles } else { 1 };
                sqlx::query(JOBS)
                    .bind(id)
                    .bind(n)
                    .bind(stage.number())
                    .bind(now)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            Ok(true)
        })
    }

    /// The tile side of costmap `id` while it is being built as tiles;
    /// `None` once it is not (done, failed, deleted, or built whole).
    pub async fn costmap_tile_side(&self, id: &str) -> Result<Option<i64>, sqlx::Error> {
        const SQL: &str =
            "SELECT tiled FROM costmaps WHERE id = $1 AND status = 'running' AND tiled > 0";
        let row: Option<(i64,)> = on_pool!(self, pool => sqlx::query_as(SQL)
            .bind(id)
            .fetch_optional(pool)
            .await)?;
        Ok(row.map(|(t,)| t))
    }

    /// Claim the next claimable tile job for `owner` until `lease_until`
    /// (see the module's doc). A job that would start its run number
    /// `max_attempts + 1` is not run: its costmap is failed instead, saying
    /// which job and why ([`TileClaim::GaveUp`]). `None`: nothing to do.
    pub async fn claim_tile_job(
        &self,
        owner: &str,
        now: i64,
        lease_until: i64,
        max_attempts: i64,
    ) -> Result<Option<TileClaim>, sqlx::Error> {
        const SQLITE: &str = claim_sql!("");
        const POSTGRES: &str = claim_sql!(" FOR UPDATE SKIP LOCKED");
        let row: Option<JobColumns> = match self {
            Db::Sqlite(pool) => {
                sqlx::query_as(SQLITE)
                    .bind(owner)
                    .bind(now)
                    .bind(lease_until)
                    .fetch_optional(pool)
                    .await?
            }
            Db::Postgres(pool) => {
                sqlx::query_as(POSTGRES)
                    .bind(owner)
                    .bind(now)
                    .bind(lease_until)
                    .fetch_optional(pool)
                    .await?
            }
        };
        let Some((costmap_id, stage, tile, attempts, error)) = row else {
            return Ok(None);
        };
        let Some(stage) = TileStage::from_number(stage) else {
            let error = format!("its tile jobs are unreadable (a stage numbered {stage})");
            self.fail_tiled_costmap(&costmap_id, &error, now).await?;
            return Ok(Some(TileClaim::GaveUp { costmap_id, error }));
        };
        if attempts > max_attempts {
            let job = stage.job_name(tile);
            let runs = attempts - 1;
            let error = match error {
                Some(e) => format!("{job} failed {runs} times, the last time: {e}"),
                None => format!(
                    "{job} was interrupted {runs} times (the process running it stopped) and is \
                     not tried again"
                ),
            };
            self.fail_tiled_costmap(&costmap_id, &error, now).await?;
            return Ok(Some(TileClaim::GaveUp { costmap_id, error }));
        }
        Ok(Some(TileClaim::Job(TileJob {
            key: TileJobKey {
                costmap_id,
                stage,
                tile,
            },
            attempts,
        })))
    }

    /// Extend the lease of a job `owner` runs; false when it is no longer
    /// its to run (its costmap was deleted or failed, or the job was taken
    /// over after its lease ran out): the run should stop.
    pub async fn renew_tile_lease(
        &self,
        key: &TileJobKey,
        owner: &str,
        lease_until: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmap_tile_jobs SET lease_until = $5 \
                           WHERE costmap_id = $1 AND stage = $2 AND tile = $3 AND owner = $4 \
                           AND status = 'running'";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&key.costmap_id)
            .bind(key.stage.number())
            .bind(key.tile)
            .bind(owner)
            .bind(lease_until)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// Job `key`, run by `owner`, is done: its outputs stored, its status
    /// done and the costmap's progress updated, in one transaction. `None`
    /// (nothing written) when the job is no longer `owner`'s.
    pub async fn complete_tile_job(
        &self,
        key: &TileJobKey,
        owner: &str,
        outputs: &[TileOutput],
        now: i64,
    ) -> Result<Option<TileProgress>, sqlx::Error> {
        const DONE: &str = "UPDATE costmap_tile_jobs SET status = 'done', owner = NULL, \
                            lease_until = 0, error = NULL, updated_at = $5 \
                            WHERE costmap_id = $1 AND stage = $2 AND tile = $3 AND owner = $4 \
                            AND status = 'running'";
        const OUTPUT: &str = "INSERT INTO costmap_tiles (costmap_id, kind, tile, data) \
                              VALUES ($1, $2, $3, $4) ON CONFLICT (costmap_id, kind, tile) \
                              DO UPDATE SET data = excluded.data";
        const PROGRESS: &str = "UPDATE costmaps SET progress = $2, stage = $3, updated_at = $4 \
                                WHERE id = $1 AND status = 'running'";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let updated = sqlx::query(DONE)
                .bind(&key.costmap_id)
                .bind(key.stage.number())
                .bind(key.tile)
                .bind(owner)
                .bind(now)
                .execute(&mut *tx)
                .await?
                .rows_affected();
            if updated == 0 {
                tx.rollback().await?;
                return Ok(None);
            }
            for o in outputs {
                sqlx::query(OUTPUT)
                    .bind(&key.costmap_id)
                    .bind(&o.kind)
                    .bind(o.tile)
                    .bind(&o.data)
                    .execute(&mut *tx)
                    .await?;
            }
            let counts: Vec<(i64, i64, i64)> = sqlx::query_as(STAGE_COUNTS)
                .bind(&key.costmap_id)
                .fetch_all(&mut *tx)
                .await?;
            let progress = progress_of(&counts);
            sqlx::query(PROGRESS)
                .bind(&key.costmap_id)
                .bind(progress.progress)
                .bind(progress.stage.map(TileStage::shown_as))
                .bind(now)
                .execute(&mut *tx)
                .await?;
            tx.commit().await?;
            Ok(Some(progress))
        })
    }

    /// Where tiled costmap `id` stands.
    pub async fn tile_progress(&self, id: &str) -> Result<TileProgress, sqlx::Error> {
        let counts: Vec<(i64, i64, i64)> = on_pool!(self, pool => sqlx::query_as(STAGE_COUNTS)
            .bind(id)
            .fetch_all(pool)
            .await)?;
        Ok(progress_of(&counts))
    }

    /// Let go of job `key` that `owner` runs after its run stopped on a
    /// fault that may pass (a storage error): queued again, the run counted
    /// and `error` kept for the message should it keep failing. False
    /// when it is no longer `owner`'s.
    pub async fn release_tile_job(
        &self,
        key: &TileJobKey,
        owner: &str,
        error: &str,
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const SQL: &str = "UPDATE costmap_tile_jobs SET status = 'queued', owner = NULL, \
                           lease_until = 0, error = $5, updated_at = $6 \
                           WHERE costmap_id = $1 AND stage = $2 AND tile = $3 AND owner = $4 \
                           AND status = 'running'";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(&key.costmap_id)
            .bind(key.stage.number())
            .bind(key.tile)
            .bind(owner)
            .bind(error)
            .bind(now)
            .execute(pool)
            .await
            .map(|r| r.rows_affected() > 0))
    }

    /// Give back the tile jobs `owner` runs (at shutdown): queued with no
    /// holder, the runs not counted. The costmaps they belong to.
    pub async fn give_back_tile_jobs(
        &self,
        owner: &str,
        now: i64,
    ) -> Result<Vec<String>, sqlx::Error> {
        const SQL: &str = "UPDATE costmap_tile_jobs SET status = 'queued', owner = NULL, \
                           lease_until = 0, updated_at = $2, \
                           attempts = CASE WHEN attempts > 0 THEN attempts - 1 ELSE 0 END \
                           WHERE owner = $1 AND status = 'running' RETURNING costmap_id";
        let mut ids: Vec<String> = on_pool!(self, pool => sqlx::query_as::<_, (String,)>(SQL)
            .bind(owner)
            .bind(now)
            .fetch_all(pool)
            .await)?
        .into_iter()
        .map(|(id,)| id)
        .collect();
        ids.sort();
        ids.dedup();
        Ok(ids)
    }

    /// At the start of the only process on a SQLite database: the tile
    /// jobs a previous process left running are claimable now (the runs
    /// stay counted: they were interrupted).
    pub async fn requeue_running_tile_jobs(&self, now: i64) -> Result<u64, sqlx::Error> {
        const SQL: &str = "UPDATE costmap_tile_jobs SET status = 'queued', owner = NULL, \
                           lease_until = 0, updated_at = $1 WHERE status = 'running'";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(now)
            .execute(pool)
            .await
            .map(|r| r.rows_affected()))
    }

    /// Fail tiled costmap `id` with `error`: its tile jobs, tiles and
    /// partly written files deleted, in one transaction. False when it was
    /// no longer unfinished (done, failed or deleted).
    pub async fn fail_tiled_costmap(
        &self,
        id: &str,
        error: &str,
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const ROW: &str = "UPDATE costmaps SET status = 'failed', stage = NULL, error = $2, \
                           updated_at = $3, owner = NULL, lease_until = 0 \
                           WHERE id = $1 AND tiled > 0 AND status IN ('queued', 'running')";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let failed = sqlx::query(ROW)
                .bind(id)
                .bind(error)
                .bind(now)
                .execute(&mut *tx)
                .await?
                .rows_affected()
                > 0;
            if failed {
                sqlx::query(DELETE_JOBS).bind(id).execute(&mut *tx).await?;
                sqlx::query(DELETE_TILES).bind(id).execute(&mut *tx).await?;
                sqlx::query("DELETE FROM costmap_files WHERE costmap_id = $1")
                    .bind(id)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await?;
            Ok(failed)
        })
    }

    /// A stored tile of costmap `id`.
    pub async fn costmap_tile(
        &self,
        id: &str,
        kind: &str,
        tile: i64,
    ) -> Result<Option<Vec<u8>>, sqlx::Error> {
        const SQL: &str =
            "SELECT data FROM costmap_tiles WHERE costmap_id = $1 AND kind = $2 AND tile = $3";
        let row: Option<(Vec<u8>,)> = on_pool!(self, pool => sqlx::query_as(SQL)
            .bind(id)
            .bind(kind)
            .bind(tile)
            .fetch_optional(pool)
            .await)?;
        Ok(row.map(|(d,)| d))
    }

    /// The stored tiles of one kind of costmap `id` from tile `from` on,
    /// at most `limit`, in tile order (the small pieces: edges, tallies,
    /// preview parts).
    pub async fn costmap_tiles_of_kind(
        &self,
        id: &str,
        kind: &str,
        from: i64,
        limit: i64,
    ) -> Result<Vec<(i64, Vec<u8>)>, sqlx::Error> {
        const SQL: &str = "SELECT tile, data FROM costmap_tiles \
                           WHERE costmap_id = $1 AND kind = $2 AND tile >= $3 \
                           ORDER BY tile LIMIT $4";
        on_pool!(self, pool => sqlx::query_as(SQL)
            .bind(id)
            .bind(kind)
            .bind(from)
            .bind(limit)
            .fetch_all(pool)
            .await)
    }

    /// Begin a file of costmap `id` to be written a chunk at a time
    /// ([`Db::add_costmap_file_chunk`]) under `partial` (see
    /// [`partial_file_name`]): no one reads it until
    /// [`Db::finish_tiled_costmap`] stores it under its name.
    pub async fn start_costmap_file(
        &self,
        id: &str,
        partial: &str,
        content_type: &str,
    ) -> Result<(), sqlx::Error> {
        const CLEAR: &str = "DELETE FROM costmap_files WHERE costmap_id = $1 AND name = $2";
        const SQL: &str = "INSERT INTO costmap_files (costmap_id, name, content_type, size_bytes) \
                           VALUES ($1, $2, $3, 0)";
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            sqlx::query(CLEAR).bind(id).bind(partial).execute(&mut *tx).await?;
            sqlx::query(SQL)
                .bind(id)
                .bind(partial)
                .bind(content_type)
                .execute(&mut *tx)
                .await?;
            tx.commit().await
        })
    }

    /// Chunk `seq` of a file begun with [`Db::start_costmap_file`].
    pub async fn add_costmap_file_chunk(
        &self,
        id: &str,
        partial: &str,
        seq: i64,
        data: &[u8],
    ) -> Result<(), sqlx::Error> {
        const SQL: &str = "INSERT INTO costmap_file_chunks (costmap_id, name, seq, data) \
                           VALUES ($1, $2, $3, $4)";
        on_pool!(self, pool => sqlx::query(SQL)
            .bind(id)
            .bind(partial)
            .bind(seq)
            .bind(data)
            .execute(pool)
            .await
            .map(|_| ()))
    }

    /// The finish job `key` run by `owner` is done: the costmap's status
    /// done with `result`, the files written in chunks stored under their
    /// names, `small` stored whole, and the tile jobs, tiles and any other
    /// run's partial files deleted, in one transaction. False (nothing
    /// written) when the job is no longer `owner`'s or the costmap no
    /// longer unfinished.
    pub async fn finish_tiled_costmap(
        &self,
        key: &TileJobKey,
        owner: &str,
        result: &str,
        written: &[WrittenFile],
        small: &[CostmapFileRow],
        now: i64,
    ) -> Result<bool, sqlx::Error> {
        const JOB: &str = "UPDATE costmap_tile_jobs SET status = 'done', owner = NULL, \
                           updated_at = $5 \
                           WHERE costmap_id = $1 AND stage = $2 AND tile = $3 AND owner = $4 \
                           AND status = 'running'";
        const ROW: &str = "UPDATE costmaps SET status = 'done', progress = 1, stage = NULL, \
                           result = $2, error = NULL, updated_at = $3, owner = NULL, lease_until = 0 \
                           WHERE id = $1 AND tiled > 0 AND status = 'running'";
        const CLEAR: &str =
            "DELETE FROM costmap_files WHERE costmap_id = $1 AND name NOT LIKE 'partial/%'";
        const NAMED: &str = "INSERT INTO costmap_files (costmap_id, name, content_type, size_bytes) \
                             SELECT costmap_id, $3, content_type, $4 FROM costmap_files \
                             WHERE costmap_id = $1 AND name = $2";
        const MOVE: &str = "UPDATE costmap_file_chunks SET name = $3 \
                            WHERE costmap_id = $1 AND name = $2";
        const DROP_PARTIALS: &str =
            "DELETE FROM costmap_files WHERE costmap_id = $1 AND name LIKE 'partial/%'";
        const FILE: &str = "INSERT INTO costmap_files (costmap_id, name, content_type, size_bytes) \
                            VALUES ($1, $2, $3, $4)";
        const CHUNK: &str = "INSERT INTO costmap_file_chunks (costmap_id, name, seq, data) \
                             VALUES ($1, $2, $3, $4)";
        let id = &key.costmap_id;
        on_pool!(self, pool => {
            let mut tx = pool.begin().await?;
            let job = sqlx::query(JOB)
                .bind(id)
                .bind(key.stage.number())
                .bind(key.tile)
                .bind(owner)
                .bind(now)
                .execute(&mut *tx)
                .await?
                .rows_affected();
            let row = if job == 0 {
                0
            } else {
                sqlx::query(ROW)
                    .bind(id)
                    .bind(result)
                    .bind(now)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected()
            };
            if row == 0 {
                tx.rollback().await?;
                return Ok(false);
            }
            sqlx::query(CLEAR).bind(id).execute(&mut *tx).await?;
            for f in written {
                let named = sqlx::query(NAMED)
                    .bind(id)
                    .bind(&f.partial)
                    .bind(&f.name)
                    .bind(f.size_bytes)
                    .execute(&mut *tx)
                    .await?
                    .rows_affected();
                if named != 1 {
                    // Deleted meanwhile (another run's finish or failure).
                    tx.rollback().await?;
                    return Err(sqlx::Error::RowNotFound);
                }
                sqlx::query(MOVE)
                    .bind(id)
                    .bind(&f.partial)
                    .bind(&f.name)
                    .execute(&mut *tx)
                    .await?;
            }
            sqlx::query(DROP_PARTIALS).bind(id).execute(&mut *tx).await?;
            for f in small {
                sqlx::query(FILE)
                    .bind(id)
                    .bind(&f.name)
                    .bind(&f.content_type)
                    .bind(f.data.len() as i64)
                    .execute(&mut *tx)
                    .await?;
                for (seq, chunk) in f.data.chunks(super::CHUNK_BYTES).enumerate() {
                    sqlx::query(CHUNK)
                        .bind(id)
                        .bind(&f.name)
                        .bind(seq as i64)
                        .bind(chunk)
                        .execute(&mut *tx)
                        .await?;
                }
            }
            sqlx::query(DELETE_JOBS).bind(id).execute(&mut *tx).await?;
            sqlx::query(DELETE_TILES).bind(id).execute(&mut *tx).await?;
            tx.commit().await?;
            Ok(true)
        })
    }
}

/// Jobs and done jobs of each stage of a costmap: (stage, jobs, done).
const STAGE_COUNTS: &str = "SELECT stage, COUNT(*), \
                            CAST(SUM(CASE WHEN status = 'done' THEN 1 ELSE 0 END) AS BIGINT) \
                            FROM costmap_tile_jobs WHERE costmap_id = $1 GROUP BY stage";

/// The progress the stage counts (stage, jobs, done) say.
fn progress_of(counts: &[(i64, i64, i64)]) -> TileProgress {
    let mut progress = 0.0;
    let mut stage = None;
    for s in TileStage::ALL {
        let (jobs, done) = counts
            .iter()
            .find(|c| c.0 == s.number())
            .map_or((0, 0), |c| (c.1, c.2));
        if jobs == 0 || done >= jobs {
            progress += s.weight();
        } else {
            progress += s.weight() * done as f64 / jobs as f64;
            stage = stage.or(Some(s));
        }
    }
    TileProgress {
        progress: progress.clamp(0.0, 1.0),
        stage,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::CostmapRow;

    const A: &str = "process-a";
    const B: &str = "process-b";
    const LEASE: i64 = 1000;

    async fn temp_db() -> (Db, std::path::PathBuf) {
        let dir = std::env::temp_dir().join(format!("terraplan-tiles-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        (Db::connect(None, &dir).await.unwrap(), dir)
    }

    /// A costmap job claimed by `A` and planned as `tiles` tiles.
    async fn planned(db: &Db, id: &str, tiles: i64) {
        let row = CostmapRow {
            id: id.into(),
            name: None,
            dem_id: "d".into(),
            created_at: 1,
            updated_at: 1,
            request: "{}".into(),
            vehicle: "{}".into(),
            status: "queued".into(),
            progress: 0.0,
            stage: None,
            result: None,
            error: None,
            attempts: 0,
            project_id: None,
        };
        db.insert_costmap(&row, A, LEASE).await.unwrap();
        assert!(db.claim_costmap(id, A, 1, LEASE).await.unwrap().is_some());
        // Only its holder plans it.
        assert!(!db.plan_costmap_tiles(id, B, 16, tiles, 2).await.unwrap());
        assert!(db.plan_costmap_tiles(id, A, 16, tiles, 2).await.unwrap());
    }

    async fn claim(db: &Db, owner: &str, now: i64) -> Option<TileClaim> {
        db.claim_tile_job(owner, now, now + LEASE, 3).await.unwrap()
    }

    /// The job claimed, which must be one.
    async fn job(db: &Db, owner: &str, now: i64) -> TileJob {
        match claim(db, owner, now).await {
            Some(TileClaim::Job(j)) => j,
            other => panic!("expected a job, got {other:?}"),
        }
    }

    fn key(id: &str, stage: TileStage, tile: i64) -> TileJobKey {
        TileJobKey {
            costmap_id: id.into(),
            stage,
            tile,
        }
    }

    fn output(kind: &str, tile: i64, data: &[u8]) -> TileOutput {
        TileOutput {
            kind: kind.into(),
            tile,
            data: data.to_vec(),
        }
    }

    async fn done(db: &Db, owner: &str, k: &TileJobKey) -> TileProgress {
        db.complete_tile_job(k, owner, &[output(k.stage.name(), k.tile, b"x")], 5)
            .await
            .unwrap()
            .expect("the job is the owner's")
    }

    #[tokio::test]
    async fn jobs_are_claimed_in_stage_order_each_stage_after_the_previous() {
        let (db, dir) = temp_db().await;
        planned(&db, "c1", 3).await;
        planned(&db, "c2", 1).await;
        // The tiled costmaps are not orphans of the whole-job runner.
        assert!(db.orphaned_costmaps(i64::MAX).await.unwrap().is_empty());
        let row = db.get_costmap("c1").await.unwrap().unwrap();
        assert_eq!(
            (row.status.as_str(), row.stage.as_deref()),
            ("running", Some("normals"))
        );

        let mut got = Vec::new();
        for _ in 0..4 {
            got.push(job(&db, A, 10).await.key);
        }
        assert_eq!(
            got,
            [
                key("c1", TileStage::Classify, 0),
                key("c1", TileStage::Classify, 1),
                key("c1", TileStage::Classify, 2),
                // c1's join waits for its classify jobs; c2's next.
                key("c2", TileStage::Classify, 0),
            ]
        );
        assert_eq!(claim(&db, B, 10).await, None);
        done(&db, A, &got[0]).await;
        let p = done(&db, A, &got[2]).await;
        assert_eq!(p.stage, Some(TileStage::Classify));
        assert!((p.progress - 0.4 * 2.0 / 3.0).abs() < 1e-12, "{p:?}");
        assert_eq!(
            claim(&db, B, 10).await,
            None,
            "one classify job is not done"
        );
        let p = done(&db, A, &got[1]).await;
        assert_eq!(p.stage, Some(TileStage::Join));
        let join = job(&db, B, 10).await;
        assert_eq!(join.key, key("c1", TileStage::Join, 0));
        assert_eq!(claim(&db, B, 10).await, None);
        done(&db, B, &join.key).await;
        let row = db.get_costmap("c1").await.unwrap().unwrap();
        assert_eq!(row.stage.as_deref(), Some("regions"));
        assert!((row.progress - 0.42).abs() < 1e-12);
        for t in 0..3 {
            assert_eq!(job(&db, B, 10).await.key, key("c1", TileStage::Fill, t));
        }
        // The outputs are stored, readable by kind in tile order.
        let edges = db
            .costmap_tiles_of_kind("c1", "classify", 0, 10)
            .await
            .unwrap();
        assert_eq!(edges.iter().map(|(t, _)| *t).collect::<Vec<_>>(), [0, 1, 2]);
        assert_eq!(
            db.costmap_tile("c1", "join", 0).await.unwrap().as_deref(),
            Some(&b"x"[..])
        );
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn an_expired_lease_is_taken_over_and_only_the_owner_completes() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 1).await;
        let first = job(&db, A, 10).await;
        assert_eq!(first.attempts, 1);
        // Still leased: nothing for B; renewed by A only.
        assert_eq!(claim(&db, B, 10 + LEASE - 1).await, None);
        assert!(
            db.renew_tile_lease(&first.key, A, 10 + 2 * LEASE)
                .await
                .unwrap()
        );
        assert!(
            !db.renew_tile_lease(&first.key, B, 10 + 2 * LEASE)
                .await
                .unwrap()
        );
        assert_eq!(claim(&db, B, 10 + 2 * LEASE - 1).await, None);
        // Once the lease ran out B takes it over; A can no longer finish
        // or renew it.
        let taken = job(&db, B, 10 + 2 * LEASE + 1).await;
        assert_eq!((taken.key.clone(), taken.attempts), (first.key.clone(), 2));
        assert!(!db.renew_tile_lease(&first.key, A, i64::MAX).await.unwrap());
        let late = db
            .complete_tile_job(&first.key, A, &[output("prefill", 0, b"late")], 20)
            .await
            .unwrap();
        assert_eq!(late, None);
        assert_eq!(db.costmap_tile("c", "prefill", 0).await.unwrap(), None);
        db.complete_tile_job(&first.key, B, &[output("prefill", 0, b"b")], 20)
            .await
            .unwrap()
            .unwrap();
        // Done once: a second completion by anyone finds nothing to do.
        assert_eq!(
            db.complete_tile_job(&first.key, B, &[output("prefill", 0, b"again")], 21)
                .await
                .unwrap(),
            None
        );
        assert_eq!(
            db.costmap_tile("c", "prefill", 0).await.unwrap().as_deref(),
            Some(&b"b"[..])
        );
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn a_job_interrupted_too_often_fails_its_costmap_saying_why() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 2).await;
        let mut now = 10;
        for attempt in 1..=3 {
            let j = job(&db, A, now).await;
            assert_eq!((j.key.tile, j.attempts), (0, attempt));
            // Tile 1 is claimed (and done) alongside.
            if attempt == 1 {
                let other = job(&db, A, now).await;
                done(&db, A, &other.key).await;
            }
            now += 2 * LEASE;
        }
        match claim(&db, B, now).await {
            Some(TileClaim::GaveUp { costmap_id, error }) => {
                assert_eq!(costmap_id, "c");
                assert!(
                    error.contains("tile 0 of stage classify was interrupted 3 times"),
                    "{error}"
                );
            }
            other => panic!("{other:?}"),
        }
        let row = db.get_costmap("c").await.unwrap().unwrap();
        assert_eq!(row.status, "failed");
        assert!(row.error.unwrap().contains("interrupted 3 times"));
        // Its jobs and tiles are gone: nothing left to claim or read.
        assert_eq!(claim(&db, B, now).await, None);
        assert!(
            db.costmap_tiles_of_kind("c", "classify", 0, 10)
                .await
                .unwrap()
                .is_empty()
        );
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn a_job_failing_on_a_fault_is_retried_then_fails_with_the_fault() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 1).await;
        for _ in 0..3 {
            let j = job(&db, A, 10).await;
            assert!(
                db.release_tile_job(&j.key, A, "disk I/O error", 11)
                    .await
                    .unwrap()
            );
        }
        match claim(&db, A, 12).await {
            Some(TileClaim::GaveUp { error, .. }) => assert_eq!(
                error,
                "tile 0 of stage classify failed 3 times, the last time: disk I/O error"
            ),
            other => panic!("{other:?}"),
        }
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn jobs_given_back_are_not_counted_and_are_claimed_again() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 2).await;
        let a = job(&db, A, 10).await;
        let b = job(&db, B, 10).await;
        assert_eq!(db.give_back_tile_jobs(A, 11).await.unwrap(), ["c"]);
        // A's job again, at once (no lease to wait for), its first run.
        let again = job(&db, B, 12).await;
        assert_eq!((again.key, again.attempts), (a.key, 1));
        assert!(db.renew_tile_lease(&b.key, B, 99).await.unwrap());
        // On SQLite's restart, every running job is claimable at once.
        assert_eq!(db.requeue_running_tile_jobs(13).await.unwrap(), 2);
        assert_eq!(job(&db, A, 14).await.attempts, 2);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn the_finish_stores_the_files_and_deletes_the_intermediates() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 1).await;
        for stage in [
            TileStage::Classify,
            TileStage::Join,
            TileStage::Fill,
            TileStage::Cost,
        ] {
            let j = job(&db, A, 10).await;
            assert_eq!(j.key.stage, stage);
            done(&db, A, &j.key).await;
        }
        let finish = job(&db, B, 10).await;
        assert_eq!(finish.key.stage, TileStage::Finish);
        // A file written in chunks, and one left by an earlier run.
        let tif = vec![7u8; super::super::CHUNK_BYTES + 3];
        let partial = partial_file_name(B, finish.attempts, "costmap.tif");
        let stale = partial_file_name(A, 1, "costmap.tif");
        for p in [&partial, &stale] {
            db.start_costmap_file("c", p, "image/tiff").await.unwrap();
        }
        for (seq, chunk) in tif.chunks(super::super::CHUNK_BYTES).enumerate() {
            db.add_costmap_file_chunk("c", &partial, seq as i64, chunk)
                .await
                .unwrap();
        }
        db.add_costmap_file_chunk("c", &stale, 0, b"old")
            .await
            .unwrap();
        let written = [WrittenFile {
            partial: partial.clone(),
            name: "costmap.tif".into(),
            size_bytes: tif.len() as i64,
        }];
        let small = [CostmapFileRow {
            name: "legend.svg".into(),
            content_type: "image/svg+xml".into(),
            data: b"<svg/>".to_vec(),
        }];
        // Not A's to finish.
        assert!(
            !db.finish_tiled_costmap(&finish.key, A, "{}", &written, &small, 20)
                .await
                .unwrap()
        );
        assert!(
            db.finish_tiled_costmap(&finish.key, B, "{\"r\":1}", &written, &small, 20)
                .await
                .unwrap()
        );
        let row = db.get_costmap("c").await.unwrap().unwrap();
        assert_eq!(
            (row.status.as_str(), row.progress, row.result.as_deref()),
            ("done", 1.0, Some("{\"r\":1}"))
        );
        let file = db
            .get_costmap_file("c", "costmap.tif")
            .await
            .unwrap()
            .unwrap();
        assert_eq!(file.data, tif);
        assert_eq!(
            db.get_costmap_file("c", "legend.svg")
                .await
                .unwrap()
                .unwrap()
                .data,
            b"<svg/>"
        );
        let Db::Sqlite(pool) = &db else {
            unreachable!()
        };
        for (table, want) in [
            ("costmap_tile_jobs", 0),
            ("costmap_tiles", 0),
            ("costmap_files", 2),
            ("costmap_file_chunks", 3),
        ] {
            let sql = format!("SELECT COUNT(*) FROM {table}");
            let (n,): (i64,) = sqlx::query_as(sqlx::AssertSqlSafe(sql))
                .fetch_one(pool)
                .await
                .unwrap();
            assert_eq!(n, want, "{table}");
        }
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[tokio::test]
    async fn a_deleted_costmap_takes_its_tile_jobs_with_it() {
        let (db, dir) = temp_db().await;
        planned(&db, "c", 2).await;
        let j = job(&db, A, 10).await;
        assert!(db.delete_costmap("c").await.unwrap());
        assert!(!db.renew_tile_lease(&j.key, A, 99).await.unwrap());
        assert_eq!(
            db.complete_tile_job(&j.key, A, &[output("prefill", 0, b"x")], 11)
                .await
                .unwrap(),
            None
        );
        assert_eq!(claim(&db, A, 12).await, None);
        db.close().await;
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn progress_weighs_the_stages() {
        let all_done = progress_of(&[(1, 4, 4), (2, 1, 1), (3, 4, 4), (4, 4, 4), (5, 1, 1)]);
        assert_eq!(all_done.stage, None);
        assert!((all_done.progress - 1.0).abs() < 1e-12);
        let half = progress_of(&[(1, 4, 4), (2, 1, 1), (3, 4, 4), (4, 4, 2), (5, 1, 0)]);
        assert_eq!(half.stage, Some(TileStage::Cost));
        assert!((half.progress - (0.5 + 0.45 / 2.0)).abs() < 1e-12);
        for s in TileStage::ALL {
            assert_eq!(TileStage::from_number(s.number()), Some(s));
        }
        let weights: f64 = TileStage::ALL.iter().map(|s| s.weight()).sum();
        assert!((weights - 1.0).abs() < 1e-12);
    }
}
