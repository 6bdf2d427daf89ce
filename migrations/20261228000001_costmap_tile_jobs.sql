-- Costmaps built as tiles by every process on the database (issue 22
-- item 2). Portable SQL: runs unchanged on SQLite and PostgreSQL.
--
-- A costmap of more working cells than `--costmap-tile-cells` is planned
-- as tile jobs by the process that claims its costmap job: its row gets
-- `tiled` (the tile side; 0 for a costmap built whole), no owner and no
-- lease (its tile jobs have their own), and every job of its five stages
-- is inserted at once: 1 classify (one per tile), 2 join (one, tile 0),
-- 3 fill (one per tile), 4 cost (one per tile), 5 finish (one, tile 0).
-- A job may be run by any process once every job of the earlier stages
-- of its costmap is done.
ALTER TABLE costmaps ADD COLUMN tiled BIGINT NOT NULL DEFAULT 0;

-- The queue. `status` is queued, running or done; a running job is held
-- by `owner` until `lease_until` (Unix ms) unless renewed, then taken
-- over. `attempts` counts the runs started; `error` is the last run's
-- error when it stopped on one that may pass (a storage fault).
CREATE TABLE IF NOT EXISTS costmap_tile_jobs (
    costmap_id   TEXT NOT NULL REFERENCES costmaps (id) ON DELETE CASCADE,
    stage        BIGINT NOT NULL,
    tile         BIGINT NOT NULL,
    status       TEXT NOT NULL,
    owner        TEXT,
    lease_until  BIGINT NOT NULL DEFAULT 0,
    attempts     BIGINT NOT NULL DEFAULT 0,
    error        TEXT,
    updated_at   BIGINT NOT NULL,
    PRIMARY KEY (costmap_id, stage, tile)
);
CREATE INDEX IF NOT EXISTS costmap_tile_jobs_status ON costmap_tile_jobs (status, costmap_id);

-- What the stages pass on, and the output tiles, written with their
-- job's status done in one transaction: `kind` is prefill, edges, fill,
-- final, cost, class, tally, preview or layer:<name>; `tile` the tile
-- index (0 for the join's). Class and raster tiles are zlib-compressed.
-- Deleted when the costmap is done, failed or deleted.
CREATE TABLE IF NOT EXISTS costmap_tiles (
    costmap_id  TEXT NOT NULL REFERENCES costmaps (id) ON DELETE CASCADE,
    kind        TEXT NOT NULL,
    tile        BIGINT NOT NULL,
    data        BYTEA NOT NULL,
    PRIMARY KEY (costmap_id, kind, tile)
);
