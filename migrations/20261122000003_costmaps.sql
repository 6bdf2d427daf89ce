-- Traversability costmaps, built as background jobs. Portable SQL: runs
-- unchanged on SQLite and PostgreSQL.
--
-- `request` is what was asked for ({"vehicle": VehicleSpec, "options":
-- CostmapOptions}) and `vehicle` the profile it resolved to, both JSON.
-- `status` is queued, running, done or failed; `progress` (0..1) and
-- `stage` are written when the stage changes (live progress is kept in
-- the server's memory). `result` (JSON: vehicle, params, stats, warnings,
-- width, height, layers) is set with status done, in the same transaction
-- as the files; `error` with status failed.
--
-- `owner` is the server process holding a queued or running job and
-- `lease_until` (Unix ms) how long its claim lasts unless renewed; a job
-- whose lease has run out (its server died) is taken over by another
-- server, or by the next one to start. `attempts` counts the runs
-- started, so a job that keeps killing its server is failed in the end.
CREATE TABLE IF NOT EXISTS costmaps (
    id           TEXT PRIMARY KEY,
    name         TEXT,
    dem_id       TEXT NOT NULL,
    created_at   BIGINT NOT NULL,
    updated_at   BIGINT NOT NULL,
    request      TEXT NOT NULL,
    vehicle      TEXT NOT NULL,
    status       TEXT NOT NULL,
    progress     DOUBLE PRECISION NOT NULL DEFAULT 0,
    stage        TEXT,
    result       TEXT,
    error        TEXT,
    owner        TEXT,
    lease_until  BIGINT NOT NULL DEFAULT 0,
    attempts     BIGINT NOT NULL DEFAULT 0
);
CREATE INDEX IF NOT EXISTS costmaps_created_at ON costmaps (created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS costmaps_status ON costmaps (status);

-- The files of a finished costmap (costmap.tif, preview.png, legend.svg,
-- layers/<name>.tif), written in the transaction that sets status done.
CREATE TABLE IF NOT EXISTS costmap_files (
    costmap_id    TEXT NOT NULL REFERENCES costmaps (id) ON DELETE CASCADE,
    name          TEXT NOT NULL,
    content_type  TEXT NOT NULL,
    data          BYTEA NOT NULL,
    PRIMARY KEY (costmap_id, name)
);
