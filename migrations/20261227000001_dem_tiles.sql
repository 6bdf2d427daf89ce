-- DEMs stored as tiles (issue 22 item 1). Portable SQL: runs unchanged on
-- SQLite and PostgreSQL.
--
-- A DEM is read a window at a time from `dem_tiles`, so a raster larger
-- than memory (30 000 × 30 000 cells) is stored and served without being
-- held whole. Level 0 holds the DEM's cells in tiles of `tile_size`²
-- (those at the right and bottom edges cut to the raster), row-major,
-- each tile its samples (`sample`: 'f32' when every value converts
-- exactly, else 'f64'; little-endian, NaN for nodata) compressed with
-- zlib. Level k+1 is the 2×2 mean of level k's non-NaN cells (its width
-- and height the halves of level k's, rounded up), down to the first
-- level that fits one tile: the previews of big DEMs read those.
--
-- Tiles are written as they are made, in short transactions (an upload
-- of a big DEM must not hold SQLite's write lock for minutes), before the
-- DEM's row: `dem_tiles` has no foreign key, and tiles of an upload that
-- fails are deleted by its id; the DEM exists once its row and tile set
-- are committed together. Deleting a DEM deletes its tiles.
--
-- A DEM stored before this migration has no tile set and is read from
-- its file (dem_chunks) as before; the file is still kept for downloads.
CREATE TABLE IF NOT EXISTS dem_tile_sets (
    dem_id     TEXT PRIMARY KEY REFERENCES dems (id) ON DELETE CASCADE,
    tile_size  BIGINT NOT NULL,
    sample     TEXT NOT NULL,
    levels     BIGINT NOT NULL,
    -- The level-0 georeferencing (planner_core::terrain::GeoTransform as
    -- JSON; the CRS, size and nodata value are in dems.info).
    transform  TEXT NOT NULL,
    -- Bytes of all its tiles, compressed.
    size_bytes BIGINT NOT NULL
);

CREATE TABLE IF NOT EXISTS dem_tiles (
    dem_id    TEXT NOT NULL,
    level     BIGINT NOT NULL,
    tile_row  BIGINT NOT NULL,
    tile_col  BIGINT NOT NULL,
    data      BYTEA NOT NULL,
    PRIMARY KEY (dem_id, level, tile_row, tile_col)
);
