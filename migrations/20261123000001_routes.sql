-- UGV routes planned on a finished costmap. Portable SQL: runs unchanged
-- on SQLite and PostgreSQL.
--
-- `parent_id` is the route this one was replanned from (NULL for a route
-- planned from scratch); it is kept as history and may name a route that
-- has since been deleted. `request` is what was asked for ({"start",
-- "goal", "options", "speed_m_s"}; a replan's start is its position, its
-- goal, options and speed the parent's), `changes` every change of the
-- costmap applied so far, cumulative over replans ({"blocked": [GeoJSON
-- Polygon], "cost_changes": [{"area": GeoJSON Polygon, "cost"}]}), and
-- `result` the planned route (planner_core::route::MapRoute with the
-- planner used), all JSON. Files (GeoJSON, CSV, mission) are rendered
-- from `result` when downloaded. Deleting a costmap deletes its routes.
CREATE TABLE IF NOT EXISTS routes (
    id          TEXT PRIMARY KEY,
    name        TEXT,
    costmap_id  TEXT NOT NULL REFERENCES costmaps (id) ON DELETE CASCADE,
    parent_id   TEXT,
    created_at  BIGINT NOT NULL,
    request     TEXT NOT NULL,
    changes     TEXT NOT NULL,
    result      TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS routes_created_at ON routes (created_at DESC, id DESC);
CREATE INDEX IF NOT EXISTS routes_costmap ON routes (costmap_id);
