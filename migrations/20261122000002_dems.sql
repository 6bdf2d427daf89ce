-- Uploaded digital elevation models. Portable SQL: runs unchanged on SQLite
-- and PostgreSQL (BYTEA is PostgreSQL's binary type; SQLite stores blobs
-- as given whatever the declared type). `data` is the file exactly as
-- uploaded; `info` is its metadata (planner_core::terrain::DemInfo) as
-- JSON, so listings never touch `data`. `crs_override` is the EPSG code
-- the uploader gave, needed to parse `data` again.
CREATE TABLE IF NOT EXISTS dems (
    id            TEXT PRIMARY KEY,
    name          TEXT,
    created_at    BIGINT NOT NULL,
    file_name     TEXT,
    crs_override  BIGINT,
    info          TEXT NOT NULL,
    size_bytes    BIGINT NOT NULL,
    data          BYTEA NOT NULL
);
CREATE INDEX IF NOT EXISTS dems_created_at ON dems (created_at DESC, id DESC);
