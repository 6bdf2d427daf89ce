//! A route on a [`RouteMap`] as a rover needs it: the A* search between
//! two positions and its description (SPEC §4.3, thesis §3.6.4) —
//! waypoints in WGS84 and UTM, 2D and 3D length, and the height and slope
//! profile sampled along the waypoint polyline.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::on_map::{Endpoint, MapRouteError, Position, RouteMap};
use super::{Cell, Route, RouteError, RouteOptions, astar};

impl RouteMap {
    /// The cheapest route from `start` to `goal` by A* (see
    /// [`astar()`]), described by [`describe`](Self::describe).
    pub fn plan(
        &self,
        start: &Position,
        goal: &Position,
        options: &RouteOptions,
        cancel: &dyn Fn() -> bool,
    ) -> Result<MapRoute, MapRouteError> {
        options.validate().map_err(MapRouteError::Search)?;
        let s = self.locate(start, Endpoint::Start)?;
        let g = self.locate(goal, Endpoint::Goal)?;
        let began = Instant::now();
        let route = astar(&self.grid, s, g, options, cancel).map_err(search_error)?;
        let ms = began.elapsed().as_secs_f64() * 1e3;
        self.describe(&route, ms)
    }

    /// Height at a cell, `None` without heights or on unknown cells.
    pub(super) fn height_at(&self, (r, c): Cell) -> Option<f64> {
        let h = self.heights.as_ref()?[r * self.grid.width() + c];
        h.is_finite().then_some(h)
    }

    /// Terrain slope in degrees at a cell (Horn's 3 × 3 gradient, as
    /// `gdaldem slope`), `None` without heights or where the window has an
    /// unknown height or leaves the map.
    pub fn slope_deg_at(&self, cell: Cell) -> Option<f64> {
        slope_deg_at(&self.terrain(), &|c| self.height_at(c), cell)
    }

    fn terrain(&self) -> Terrain<'_> {
        Terrain {
            width: self.grid.width(),
            height: self.grid.height(),
            dx: self.grid.dx_per_row(),
            dy: self.grid.dy(),
        }
    }

    /// The route as a rover takes it: waypoints in WGS84 and UTM with
    /// heights, its 2D and 3D length, and the terrain slope under it.
    /// Lengths, heights and slopes are measured along the waypoint
    /// polyline (the path driven), sampled at least every half cell.
    pub fn describe(&self, route: &Route, search_ms: f64) -> Result<MapRoute, MapRouteError> {
        let mut waypoints = Vec::with_capacity(route.waypoints.len());
        for &(row, col) in &route.waypoints {
            let xy = self.centre((row, col));
            let [lon, lat] = self.to_lonlat(xy)?;
            let [easting, northing] = self.to_utm(xy)?;
            waypoints.push(RoutePoint {
                lon,
                lat,
                easting,
                northing,
                height_m: self.height_at((row, col)),
                row,
                col,
            });
        }
        let profile = self.profile(&route.waypoints);
        Ok(MapRoute {
            utm_zone: self.utm_zone_name(),
            utm_epsg: self.utm.epsg(),
            waypoints,
            length_2d_m: route.waypoints_length_m,
            length_3d_m: profile.length_3d_m,
            cost: route.waypoints_cost,
            path_cost: route.cost,
            path_length_m: route.length_m,
            path_cells: route.cells.len(),
            max_slope_deg: profile.max_slope_deg,
            mean_slope_deg: profile.mean_slope_deg,
            max_grade_deg: profile.max_grade_deg,
            climb_m: profile.climb_m,
            descent_m: profile.descent_m,
            expanded: route.expanded,
            search_ms,
        })
    }

    /// Heights and slopes sampled along the polyline through the cell
    /// centres of `points`.
    fn profile(&self, points: &[Cell]) -> Profile {
        if self.heights.is_none() {
            return Profile::default();
        }
        profile(&self.terrain(), &|c| self.height_at(c), points)
    }
}

/// A grid's size and cell sizes, for sampling heights on it.
pub(super) struct Terrain<'a> {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Cell width per row, metres.
    pub(super) dx: &'a [f64],
    pub(super) dy: f64,
}

/// Bilinear height at fractional cell position (col, row) measured in
/// cells from the top-left corner; falls back to the nearest cell when a
/// neighbour is unknown. `z` gives the height of a cell.
fn height_at_point(
    t: &Terrain,
    z: &dyn Fn(Cell) -> Option<f64>,
    col: f64,
    row: f64,
) -> Option<f64> {
    let (w, h) = (t.width, t.height);
    let x = (col - 0.5).clamp(0.0, (w - 1) as f64);
    let y = (row - 0.5).clamp(0.0, (h - 1) as f64);
    let (c0, r0) = (x.floor() as usize, y.floor() as usize);
    let (c1, r1) = ((c0 + 1).min(w - 1), (r0 + 1).min(h - 1));
    let (fx, fy) = (x - c0 as f64, y - r0 as f64);
    let corners = [z((r0, c0)), z((r0, c1)), z((r1, c0)), z((r1, c1))];
    if let [Some(a), Some(b), Some(c), Some(d)] = corners {
        let top = a + (b - a) * fx;
        let bottom = c + (d - c) * fx;
        return Some(top + (bottom - top) * fy);
    }
    let nearest = (
        (row.floor().max(0.0) as usize).min(h - 1),
        (col.floor().max(0.0) as usize).min(w - 1),
    );
    z(nearest)
}

/// Terrain slope in degrees at a cell (Horn's 3 × 3 gradient, as
/// `gdaldem slope`), `None` where the window has an unknown height or
/// leaves the grid.
pub(super) fn slope_deg_at(
    t: &Terrain,
    z: &dyn Fn(Cell) -> Option<f64>,
    (r, c): Cell,
) -> Option<f64> {
    if r == 0 || c == 0 || r + 1 >= t.height || c + 1 >= t.width {
        return None;
    }
    let mut v = [[0.0; 3]; 3];
    for (dr, row) in v.iter_mut().enumerate() {
        for (dc, cell) in row.iter_mut().enumerate() {
            *cell = z((r + dr - 1, c + dc - 1))?;
        }
    }
    let (sx, sy) = (t.dx[r], t.dy);
    let gx =
        ((v[0][2] + 2.0 * v[1][2] + v[2][2]) - (v[0][0] + 2.0 * v[1][0] + v[2][0])) / (8.0 * sx);
    let gy =
        ((v[2][0] + 2.0 * v[2][1] + v[2][2]) - (v[0][0] + 2.0 * v[0][1] + v[0][2])) / (8.0 * sy);
    Some(gx.hypot(gy).atan().to_degrees())
}

/// Heights and slopes sampled along the polyline through the cell centres
/// of `points`, every half cell at least; `z` gives the height of a cell.
pub(super) fn profile(
    terrain: &Terrain,
    height: &dyn Fn(Cell) -> Option<f64>,
    points: &[Cell],
) -> Profile {
    let mut p = Profile::default();
    let mut length_3d = 0.0;
    let (mut slope_sum, mut slope_len, mut slope_max) = (0.0, 0.0, f64::NEG_INFINITY);
    let mut grade_max = f64::NEG_INFINITY;
    let (mut climb, mut descent) = (0.0, 0.0);
    let mut heights_known = true;
    for pair in points.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        let (ca, ra) = (a.1 as f64 + 0.5, a.0 as f64 + 0.5);
        let (cb, rb) = (b.1 as f64 + 0.5, b.0 as f64 + 0.5);
        let span = (cb - ca).abs().max((rb - ra).abs());
        let steps = ((span * 2.0).ceil() as usize).max(1);
        let mut prev: Option<(f64, f64, f64)> = None; // (x m, y m, z)
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let (col, row) = (ca + (cb - ca) * t, ra + (rb - ra) * t);
            let r = (row.floor() as usize).min(terrain.height - 1);
            // Metres along the segment from its start.
            let xm = (col - ca) * terrain.dx[r];
            let ym = (row - ra) * terrain.dy;
            let z = height_at_point(terrain, height, col, row);
            let Some(z) = z else {
                heights_known = false;
                prev = None;
                continue;
            };
            if let Some((px, py, pz)) = prev {
                let d = (xm - px).hypot(ym - py);
                length_3d += d.hypot(z - pz);
                if d > 0.0 {
                    grade_max = grade_max.max(((z - pz).abs() / d).atan().to_degrees());
                    let cell = (r, (col.floor() as usize).min(terrain.width - 1));
                    if let Some(s) = slope_deg_at(terrain, height, cell) {
                        slope_sum += s * d;
                        slope_len += d;
                        slope_max = slope_max.max(s);
                    }
                }
                if z > pz {
                    climb += z - pz;
                } else {
                    descent += pz - z;
                }
            }
            prev = Some((xm, ym, z));
        }
    }
    if heights_known {
        p.length_3d_m = Some(length_3d);
        p.climb_m = Some(climb);
        p.descent_m = Some(descent);
        if grade_max.is_finite() {
            p.max_grade_deg = Some(grade_max);
        }
    }
    if slope_len > 0.0 {
        p.max_slope_deg = Some(slope_max);
        p.mean_slope_deg = Some(slope_sum / slope_len);
    }
    p
}

fn search_error(e: RouteError) -> MapRouteError {
    match e {
        RouteError::Unreachable => MapRouteError::Unreachable,
        other => MapRouteError::Search(other),
    }
}

#[derive(Default)]
pub(super) struct Profile {
    pub(super) length_3d_m: Option<f64>,
    pub(super) max_slope_deg: Option<f64>,
    pub(super) mean_slope_deg: Option<f64>,
    pub(super) max_grade_deg: Option<f64>,
    pub(super) climb_m: Option<f64>,
    pub(super) descent_m: Option<f64>,
}

/// One waypoint of a route.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoutePoint {
    pub lon: f64,
    pub lat: f64,
    /// UTM easting, metres, in the route's zone.
    pub easting: f64,
    pub northing: f64,
    /// Terrain height of the cell (the DEM's vertical datum); absent where
    /// unknown or when the map has no heights.
    pub height_m: Option<f64>,
    /// The costmap cell, row 0 at the top.
    pub row: usize,
    pub col: usize,
}

/// A route on a map, as the API and CLI report it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapRoute {
    /// UTM zone of the eastings and northings, e.g. "18N".
    pub utm_zone: String,
    /// Its EPSG code (WGS 84 / UTM, 326zz or 327zz).
    pub utm_epsg: u32,
    /// Start, turning points, goal.
    pub waypoints: Vec<RoutePoint>,
    /// Length of the waypoint polyline in metres, horizontally.
    pub length_2d_m: f64,
    /// Length along the terrain (heights sampled every half cell); absent
    /// without heights or where the route crosses unknown heights.
    pub length_3d_m: Option<f64>,
    /// Integrated cost of the waypoint polyline: the line integral of the
    /// cell cost along it (cost × metres).
    pub cost: f64,
    /// What the search minimised: the cost of the 8-connected cell path
    /// under the chosen arc rule (before smoothing).
    pub path_cost: f64,
    /// Length of the cell path in metres.
    pub path_length_m: f64,
    /// Cells on the cell path.
    pub path_cells: usize,
    /// Steepest terrain slope (Horn, degrees) under the route.
    pub max_slope_deg: Option<f64>,
    /// Length-weighted mean terrain slope under the route, degrees.
    pub mean_slope_deg: Option<f64>,
    /// Steepest climb or descent along the direction of travel, degrees.
    pub max_grade_deg: Option<f64>,
    /// Total ascent and descent along the route, metres.
    pub climb_m: Option<f64>,
    pub descent_m: Option<f64>,
    /// Cells the search expanded.
    pub expanded: u64,
    /// Time the search took, milliseconds.
    pub search_ms: f64,
}
