-- Stored files as sequences of chunks (issue 17). Portable SQL: runs
-- unchanged on SQLite and PostgreSQL.
--
-- A DEM's file and a costmap's files were one value each, which every
-- read loaded whole (eight downloads of a 488 MiB costmap held 7.5 GB)
-- and which neither database takes beyond 1 GB. They are now rows of
-- at most 1 MiB, `seq` counting from 0, written chunk by chunk and read
-- (downloads streamed) one chunk at a time. A file is its chunks in
-- `seq` order; its length is `size_bytes` of its owner's row.
--
-- `dems.read_bytes` is the memory reading the file again takes (its
-- heights as f64, its largest decoded strip or tile, the file itself),
-- estimated from its header at upload; NULL for DEMs stored before it
-- was kept (then estimated from its size and pixels).
CREATE TABLE IF NOT EXISTS dem_chunks (
    dem_id  TEXT NOT NULL REFERENCES dems (id) ON DELETE CASCADE,
    seq     BIGINT NOT NULL,
    data    BYTEA NOT NULL,
    PRIMARY KEY (dem_id, seq)
);

ALTER TABLE dems ADD COLUMN read_bytes BIGINT;

CREATE TABLE IF NOT EXISTS costmap_file_chunks (
    costmap_id  TEXT NOT NULL,
    name        TEXT NOT NULL,
    seq         BIGINT NOT NULL,
    data        BYTEA NOT NULL,
    PRIMARY KEY (costmap_id, name, seq),
    FOREIGN KEY (costmap_id, name) REFERENCES costmap_files (costmap_id, name) ON DELETE CASCADE
);

ALTER TABLE costmap_files ADD COLUMN size_bytes BIGINT NOT NULL DEFAULT 0;
UPDATE costmap_files SET size_bytes = length(data);

-- The files stored so far, cut into chunks of 1 MiB (substr counts bytes
-- of a blob or bytea from 1 in both databases).
WITH RECURSIVE parts (dem_id, seq) AS (
    SELECT id, 0 FROM dems WHERE length(data) > 0
    UNION ALL
    SELECT p.dem_id, p.seq + 1 FROM parts p JOIN dems d ON d.id = p.dem_id
    WHERE (p.seq + 1) * 1048576 < length(d.data)
)
INSERT INTO dem_chunks (dem_id, seq, data)
SELECT p.dem_id, p.seq, substr(d.data, p.seq * 1048576 + 1, 1048576)
FROM parts p JOIN dems d ON d.id = p.dem_id;

WITH RECURSIVE parts (costmap_id, name, seq) AS (
    SELECT costmap_id, name, 0 FROM costmap_files WHERE length(data) > 0
    UNION ALL
    SELECT p.costmap_id, p.name, p.seq + 1 FROM parts p
    JOIN costmap_files f ON f.costmap_id = p.costmap_id AND f.name = p.name
    WHERE (p.seq + 1) * 1048576 < length(f.data)
)
INSERT INTO costmap_file_chunks (costmap_id, name, seq, data)
SELECT p.costmap_id, p.name, p.seq, substr(f.data, p.seq * 1048576 + 1, 1048576)
FROM parts p JOIN costmap_files f ON f.costmap_id = p.costmap_id AND f.name = p.name;

ALTER TABLE dems DROP COLUMN data;
ALTER TABLE costmap_files DROP COLUMN data;
