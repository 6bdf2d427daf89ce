-- DEM uploads in progress (issue 22 item 1). Portable SQL: runs unchanged
-- on SQLite and PostgreSQL.
--
-- An upload's tiles are written (in short transactions) before its DEM's
-- row, so a server killed mid-upload would leave tiles no DEM refers to.
-- Each upload is recorded here before its first tile: the process that
-- holds it (`owner`) renews `lease_until` (ms since the epoch) a few times
-- per lease while it runs, and adds the bytes of each batch of tiles to
-- `size_bytes` in the transaction that stores them (a batch whose upload
-- row is gone is not stored). The DEM's row, its tile set and the removal
-- of this row commit together. An upload whose lease ran out (its holder
-- died) is swept, row and tiles in one transaction, by any process; a
-- SQLite server (the only one on its file) sweeps every upload at
-- start-up. `size_bytes` counts in the project's storage quota while the
-- upload runs.
CREATE TABLE IF NOT EXISTS dem_uploads (
    dem_id      TEXT PRIMARY KEY,
    project_id  TEXT,
    owner       TEXT NOT NULL,
    started_at  BIGINT NOT NULL,
    lease_until BIGINT NOT NULL,
    size_bytes  BIGINT NOT NULL
);

CREATE INDEX IF NOT EXISTS dem_uploads_by_lease ON dem_uploads (lease_until);
CREATE INDEX IF NOT EXISTS dem_uploads_by_project ON dem_uploads (project_id);
