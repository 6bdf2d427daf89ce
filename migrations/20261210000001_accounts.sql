-- Accounts, API tokens, sign-in sessions, projects and their members
-- (issue 19). Portable SQL: runs unchanged on SQLite and PostgreSQL
-- (flags are BIGINT 0/1, times Unix milliseconds). Secrets are stored only
-- as hashes: passwords as argon2id PHC strings, token and session secrets
-- as hex SHA-256 (they are 32 random bytes, so a fast hash is enough).
CREATE TABLE IF NOT EXISTS users (
    id            TEXT PRIMARY KEY,
    name          TEXT NOT NULL UNIQUE,
    password_hash TEXT,
    admin         BIGINT NOT NULL DEFAULT 0,
    disabled      BIGINT NOT NULL DEFAULT 0,
    created_at    BIGINT NOT NULL
);

CREATE TABLE IF NOT EXISTS api_tokens (
    id            TEXT PRIMARY KEY,
    user_id       TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    name          TEXT NOT NULL,
    secret_hash   TEXT NOT NULL,
    created_at    BIGINT NOT NULL,
    last_used_at  BIGINT,
    expires_at    BIGINT
);
CREATE INDEX IF NOT EXISTS api_tokens_user ON api_tokens (user_id, created_at);

CREATE TABLE IF NOT EXISTS sessions (
    id            TEXT PRIMARY KEY,
    user_id       TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    secret_hash   TEXT NOT NULL,
    csrf_token    TEXT NOT NULL,
    created_at    BIGINT NOT NULL,
    last_used_at  BIGINT NOT NULL,
    expires_at    BIGINT NOT NULL
);
CREATE INDEX IF NOT EXISTS sessions_user ON sessions (user_id);

-- `personal_of` is the user whose personal project this is (one each).
CREATE TABLE IF NOT EXISTS projects (
    id            TEXT PRIMARY KEY,
    name          TEXT NOT NULL,
    personal_of   TEXT UNIQUE REFERENCES users (id) ON DELETE CASCADE,
    created_at    BIGINT NOT NULL
);

-- role: 'viewer', 'editor' or 'owner'.
CREATE TABLE IF NOT EXISTS project_members (
    project_id    TEXT NOT NULL REFERENCES projects (id) ON DELETE CASCADE,
    user_id       TEXT NOT NULL REFERENCES users (id) ON DELETE CASCADE,
    role          TEXT NOT NULL,
    PRIMARY KEY (project_id, user_id)
);
CREATE INDEX IF NOT EXISTS project_members_user ON project_members (user_id);

-- Every resource belongs to a project. Rows made before accounts have none
-- until the first admin is made, who then adopts them (server: db/projects.rs).
ALTER TABLE dems ADD COLUMN project_id TEXT;
ALTER TABLE surveys ADD COLUMN project_id TEXT;
ALTER TABLE costmaps ADD COLUMN project_id TEXT;
ALTER TABLE routes ADD COLUMN project_id TEXT;
CREATE INDEX IF NOT EXISTS dems_project ON dems (project_id, created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS surveys_project ON surveys (project_id, created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS costmaps_project ON costmaps (project_id, created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS routes_project ON routes (project_id, created_at DESC, id DESC);
