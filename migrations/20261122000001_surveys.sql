-- Planned surveys. Portable SQL: runs unchanged on SQLite and PostgreSQL.
-- `request` is the request document and `plan` the planner's result, both
-- JSON text; files are rendered from `plan` when downloaded.
CREATE TABLE IF NOT EXISTS surveys (
    id          TEXT PRIMARY KEY,
    name        TEXT,
    created_at  BIGINT NOT NULL,
    request     TEXT NOT NULL,
    plan        TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS surveys_created_at ON surveys (created_at DESC, id DESC);
