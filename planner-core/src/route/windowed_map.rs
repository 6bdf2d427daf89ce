//! A costmap too big to hold, planned on where it lies: its georeferencing
//! and projections as [`RouteMap`] has them, its costs read a window at a
//! time ([`WindowCosts`]), start and goal located by reading their cells,
//! and the coarse-to-fine route described as a [`MapRoute`] (waypoints in
//! WGS84 and UTM), with heights and slopes along it when given the heights
//! on the costmap's grid (also read by windows, e.g. [`AveragedHeights`]).
//! What needs the whole map in memory is not offered: smoothing (the
//! waypoints are the turning points of the cell path) and replanning.
//!
//! [`AveragedHeights`]: super::AveragedHeights
//!
//! [`RouteMap`]: super::RouteMap

use std::cell::RefCell;
use std::collections::HashMap;

use proj::Proj;

use super::coarse_to_fine::{BigRouteError, CoarseToFine, CoarseToFineOptions, coarse_to_fine};
use super::cost_source::{CostSource, CostSourceError, WindowCosts};
use super::map_route::{MapRoute, Profile, RoutePoint, Terrain, profile};
use super::on_map::{
    Endpoint, MapProjections, MapRouteError, Position, blocked_on, coordinates_fault,
    corners_extent_lonlat, crs_error,
};
use super::{Cell, RouteOptions, turning_points};
use crate::costmap::Class;
use crate::geo::UtmProjection;
use crate::terrain::{GeoTransform, RasterWindows};

/// Why a route on a windowed map could not be planned.
#[derive(Debug, thiserror::Error)]
pub enum WindowedRouteError {
    #[error(transparent)]
    Map(#[from] MapRouteError),
    #[error(transparent)]
    Search(#[from] BigRouteError),
}

/// A costmap read by windows, with its georeferencing.
pub struct WindowedMap<'a> {
    costs: WindowCosts<'a>,
    classes: Option<&'a dyn RasterWindows>,
    heights: Option<&'a dyn RasterWindows>,
    transform: GeoTransform,
    utm: UtmProjection,
    map_to_wgs84: Option<Proj>,
    wgs84_to_map: Option<Proj>,
    map_to_utm: Proj,
    utm_to_map: Proj,
}

fn source_error(e: CostSourceError) -> MapRouteError {
    match e {
        CostSourceError::RotatedGrid => MapRouteError::RotatedGrid,
        other => MapRouteError::CostmapFile(other.to_string()),
    }
}

impl<'a> WindowedMap<'a> {
    /// The costmap whose costs `costs` reads (band 1 of page 1 of a
    /// costmap GeoTIFF), and optionally its class codes (page 2) to say
    /// what a blocked endpoint is on.
    pub fn new(
        costs: &'a dyn RasterWindows,
        classes: Option<&'a dyn RasterWindows>,
    ) -> Result<WindowedMap<'a>, MapRouteError> {
        let grid = costs.grid();
        if let Some(c) = classes
            && (c.grid().width, c.grid().height, c.grid().transform)
                != (grid.width, grid.height, grid.transform)
        {
            return Err(MapRouteError::CostmapFile(
                "the class page is not on the cost page's grid".into(),
            ));
        }
        let transform = grid.transform;
        let MapProjections {
            utm,
            map_to_utm,
            utm_to_map,
            map_to_wgs84,
            wgs84_to_map,
        } = MapProjections::new(&grid.crs, &transform, (grid.width, grid.height))?;
        Ok(WindowedMap {
            costs: WindowCosts::new(costs).map_err(source_error)?,
            classes,
            heights: None,
            transform,
            map_to_utm,
            utm_to_map,
            utm,
            map_to_wgs84,
            wgs84_to_map,
        })
    }

    /// The map with the terrain's heights on its grid (metres, NaN
    /// unknown), for the heights, 3D length and slopes along its routes.
    pub fn with_heights(
        mut self,
        heights: &'a dyn RasterWindows,
    ) -> Result<WindowedMap<'a>, MapRouteError> {
        let g = heights.grid();
        let (w, h) = (self.costs.width(), self.costs.height());
        if (g.width, g.height) != (w, h) {
            return Err(MapRouteError::LayerSize {
                what: "the height grid",
                expected: w * h,
                got: g.width * g.height,
            });
        }
        self.heights = Some(heights);
        Ok(self)
    }

    /// The costs, as a search reads them.
    pub fn costs(&self) -> &WindowCosts<'a> {
        &self.costs
    }

    /// "18N", "33S".
    pub fn utm_zone_name(&self) -> String {
        format!(
            "{}{}",
            self.utm.zone(),
            if self.utm.is_north() { 'N' } else { 'S' }
        )
    }

    fn to_lonlat(&self, (x, y): (f64, f64)) -> Result<[f64; 2], MapRouteError> {
        match &self.map_to_wgs84 {
            None => Ok([x, y]),
            Some(p) => p.convert((x, y)).map(|(a, b)| [a, b]).map_err(crs_error),
        }
    }

    fn centre(&self, (r, c): Cell) -> (f64, f64) {
        self.transform.apply(c as f64 + 0.5, r as f64 + 0.5)
    }

    /// The cell under `p`, checked: valid coordinates, inside the map and
    /// traversable (as [`RouteMap::locate`](super::RouteMap::locate)).
    pub fn locate(&self, p: &Position, end: Endpoint) -> Result<Cell, MapRouteError> {
        let invalid = |reason: &str| MapRouteError::InvalidPosition {
            end,
            position: *p,
            reason: reason.to_string(),
        };
        if let Some(reason) = coordinates_fault(p) {
            return Err(invalid(reason));
        }
        let (x, y) = match *p {
            Position::LonLat([lon, lat]) => match &self.wgs84_to_map {
                None => (lon, lat),
                Some(t) => t
                    .convert((lon, lat))
                    .map_err(|_| invalid("it cannot be transformed into the costmap's CRS"))?,
            },
            Position::Utm { utm: [e, n] } => self
                .utm_to_map
                .convert((e, n))
                .map_err(|_| invalid("it cannot be transformed into the costmap's CRS"))?,
        };
        if !(x.is_finite() && y.is_finite()) {
            return Err(invalid("it cannot be transformed into the costmap's CRS"));
        }
        let lonlat = match *p {
            Position::LonLat(ll) => ll,
            Position::Utm { .. } => self
                .to_lonlat((x, y))
                .map_err(|_| invalid("it cannot be transformed into longitude and latitude"))?,
        };
        let (w, h) = (self.costs.width(), self.costs.height());
        let cell = self.transform.invert(x, y).and_then(|(c, r)| {
            let inside = c >= 0.0 && r >= 0.0 && c < w as f64 && r < h as f64;
            inside.then_some((r as usize, c as usize))
        });
        let Some(cell) = cell else {
            return Err(MapRouteError::Outside {
                end,
                lonlat,
                extent: corners_extent_lonlat(&self.transform, (w, h), |xy| self.to_lonlat(xy)),
            });
        };
        let mut cost = [0.0f32];
        self.costs
            .read_costs(cell.0, cell.1, 1, 1, &mut cost)
            .map_err(source_error)?;
        if !cost[0].is_finite() {
            let mut class = [f64::NAN];
            let code = self
                .classes
                .and_then(|c| c.read_window(cell.1, cell.0, 1, 1, &mut class).ok())
                .and_then(|()| {
                    let v = class[0];
                    ((0.0..=255.0).contains(&v) && v.fract() == 0.0).then_some(v as u8)
                });
            let what = blocked_on(code.and_then(Class::from_code));
            return Err(MapRouteError::Blocked {
                end,
                lonlat,
                what: what.to_string(),
            });
        }
        Ok(cell)
    }

    /// The coarse-to-fine route between two positions, described.
    pub fn plan(
        &self,
        start: &Position,
        goal: &Position,
        options: &RouteOptions,
        c2f: &CoarseToFineOptions,
        cancel: &dyn Fn() -> bool,
    ) -> Result<(MapRoute, CoarseToFine), WindowedRouteError> {
        options.validate().map_err(MapRouteError::Search)?;
        let s = self.locate(start, Endpoint::Start)?;
        let g = self.locate(goal, Endpoint::Goal)?;
        let began = std::time::Instant::now();
        let found = coarse_to_fine(&self.costs, s, g, options, c2f, cancel)?;
        let ms = began.elapsed().as_secs_f64() * 1e3;
        Ok((self.describe(&found, ms)?, found))
    }

    /// The route as [`RouteMap::describe`](super::RouteMap::describe)
    /// gives it: the waypoints are the turning points of the cell path, so
    /// the polyline is the path and its integrated cost is summed along
    /// the cells; heights (each cell's read once) and slopes sampled
    /// along it as there, when the map has heights.
    pub fn describe(
        &self,
        found: &CoarseToFine,
        search_ms: f64,
    ) -> Result<MapRoute, MapRouteError> {
        let points = turning_points(&found.cells);
        let read: RefCell<HashMap<Cell, Option<f64>>> = RefCell::default();
        let failed: RefCell<Option<String>> = RefCell::default();
        let height_at = |cell: Cell| -> Option<f64> {
            let heights = self.heights?;
            if let Some(&z) = read.borrow().get(&cell) {
                return z;
            }
            let mut z = [f64::NAN];
            if let Err(e) = heights.read_window(cell.1, cell.0, 1, 1, &mut z) {
                failed.borrow_mut().get_or_insert(e.to_string());
            }
            let z = z[0].is_finite().then_some(z[0]);
            read.borrow_mut().insert(cell, z);
            z
        };
        let terrain = Terrain {
            width: self.costs.width(),
            height: self.costs.height(),
            dx: self.costs.dx_per_row(),
            dy: self.costs.dy(),
        };
        let profile = match self.heights {
            Some(_) => profile(&terrain, &height_at, &points),
            None => Profile::default(),
        };
        let mut waypoints = Vec::with_capacity(points.len());
        for &(row, col) in &points {
            let xy = self.centre((row, col));
            let [lon, lat] = self.to_lonlat(xy)?;
            let (easting, northing) = self.map_to_utm.convert(xy).map_err(crs_error)?;
            waypoints.push(RoutePoint {
                lon,
                lat,
                easting,
                northing,
                height_m: height_at((row, col)),
                row,
                col,
            });
        }
        // The integrated line cost of the path (the polyline through its
        // turning points), read cell by cell along it.
        let mut line_cost = 0.0;
        let dx = self.costs.dx_per_row();
        let dy = self.costs.dy();
        let mut prev: Option<(Cell, f32)> = None;
        for &cell in &found.cells {
            let mut c = [0.0f32];
            self.costs
                .read_costs(cell.0, cell.1, 1, 1, &mut c)
                .map_err(source_error)?;
            if let Some(((ar, ac), ca)) = prev {
                let len = match (ar != cell.0, ac != cell.1) {
                    (false, _) => dx[ar],
                    (true, false) => dy,
                    (true, true) => (0.5 * (dx[ar] + dx[cell.0])).hypot(dy),
                };
                line_cost += len * 0.5 * (f64::from(ca) + f64::from(c[0]));
            }
            prev = Some((cell, c[0]));
        }
        if let Some(why) = failed.into_inner() {
            return Err(MapRouteError::Heights(why));
        }
        Ok(MapRoute {
            utm_zone: self.utm_zone_name(),
            utm_epsg: self.utm.epsg(),
            waypoints,
            length_2d_m: found.length_m,
            length_3d_m: profile.length_3d_m,
            cost: line_cost,
            path_cost: found.cost,
            path_length_m: found.length_m,
            path_cells: found.cells.len(),
            max_slope_deg: profile.max_slope_deg,
            mean_slope_deg: profile.mean_slope_deg,
            max_grade_deg: profile.max_grade_deg,
            climb_m: profile.climb_m,
            descent_m: profile.descent_m,
            expanded: found.stats.expanded,
            search_ms,
        })
    }
}

impl super::RouteMap {
    /// The route between two positions by [`coarse_to_fine`] on the map's
    /// grid in memory (no 16 bytes per cell of search arrays; heights,
    /// slopes and smoothing as [`plan`](Self::plan) gives them), with the
    /// search's proof and figures.
    pub fn plan_coarse_to_fine(
        &self,
        start: &Position,
        goal: &Position,
        options: &RouteOptions,
        c2f: &CoarseToFineOptions,
        cancel: &dyn Fn() -> bool,
    ) -> Result<(MapRoute, CoarseToFine), WindowedRouteError> {
        options.validate().map_err(MapRouteError::Search)?;
        let s = self.locate(start, Endpoint::Start)?;
        let g = self.locate(goal, Endpoint::Goal)?;
        let began = std::time::Instant::now();
        let (route, found) = super::coarse_to_fine_route(self.grid(), s, g, options, c2f, cancel)?;
        let ms = began.elapsed().as_secs_f64() * 1e3;
        Ok((self.describe(&route, ms)?, found))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::RouteMap;
    use crate::terrain::test_support::{dem, north_up};
    use crate::terrain::{Crs, DemWindows};

    #[test]
    fn the_windowed_route_is_the_in_memory_one() {
        // A 2 m UTM costmap with a wall and a gap: the same cost, cells and
        // waypoint positions as RouteMap's A* route (unsmoothed).
        let (w, h) = (90, 70);
        let values: Vec<f64> = (0..w * h)
            .map(|i| {
                let (r, c) = (i / w, i % w);
                if c == 45 && r < 60 {
                    f64::NAN
                } else {
                    1.0 + ((r * 7 + c * 3) % 5) as f64
                }
            })
            .collect();
        let mut d = dem(
            w,
            h,
            values.clone(),
            north_up(472_000.0, 4_295_000.0, 2.0, 2.0),
            false,
        );
        d.crs = Crs::from_epsg(32618).unwrap();
        // Heights: a tilted, rippled surface with an unknown patch.
        let mut hd = d.clone();
        hd.values = (0..w * h)
            .map(|i| {
                let (r, c) = (i / w, i % w);
                if (30..33).contains(&r) && (70..74).contains(&c) {
                    f64::NAN
                } else {
                    200.0 + 0.3 * c as f64 - 0.2 * r as f64 + ((r * 5 + c * 11) % 7) as f64 * 0.1
                }
            })
            .collect();
        let windows = DemWindows::new(&d);
        let height_windows = DemWindows::new(&hd);
        let map = WindowedMap::new(&windows, None)
            .unwrap()
            .with_heights(&height_windows)
            .unwrap();
        let costs = values.iter().map(|&v| v as f32).collect();
        let memory = RouteMap::new(
            w,
            h,
            d.transform,
            d.crs.clone(),
            costs,
            Some(hd.values.clone()),
            None,
        )
        .unwrap();
        let at = |cell: Cell| {
            let (x, y) = d.transform.apply(cell.1 as f64 + 0.5, cell.0 as f64 + 0.5);
            let (e, n) = map.map_to_utm.convert((x, y)).unwrap();
            Position::Utm { utm: [e, n] }
        };
        let options = RouteOptions {
            smooth: false,
            ..RouteOptions::default()
        };
        let (start, goal) = (at((10, 5)), at((10, 85)));
        let c2f = CoarseToFineOptions {
            block: 8,
            tile: 32,
            ..CoarseToFineOptions::default()
        };
        let (route, found) = map.plan(&start, &goal, &options, &c2f, &|| false).unwrap();
        let plain = memory.plan(&start, &goal, &options, &|| false).unwrap();
        let (in_memory, _) = memory
            .plan_coarse_to_fine(&start, &goal, &options, &c2f, &|| false)
            .unwrap();
        assert!((in_memory.path_cost - plain.path_cost).abs() <= 1e-9 * plain.path_cost);
        assert!(found.proven_optimal);
        assert!((route.path_cost - plain.path_cost).abs() <= 1e-9 * plain.path_cost);
        assert!((route.cost - plain.cost).abs() <= 1e-9 * plain.cost);
        assert!((route.length_2d_m - plain.length_2d_m).abs() <= 1e-9 * plain.length_2d_m);
        assert_eq!(route.utm_zone, "18N");
        // Heights and the profile as the map in memory gives them for the
        // same path (plain A* may take another of the same cost).
        assert_eq!(route.waypoints.len(), in_memory.waypoints.len());
        let plain = in_memory;
        let close = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => (a - b).abs() <= 1e-9 * a.abs().max(1.0),
            (None, None) => true,
            _ => false,
        };
        assert!(plain.length_3d_m.is_some() && plain.max_slope_deg.is_some());
        for (a, b) in [
            (route.length_3d_m, plain.length_3d_m),
            (route.climb_m, plain.climb_m),
            (route.descent_m, plain.descent_m),
            (route.max_slope_deg, plain.max_slope_deg),
            (route.mean_slope_deg, plain.mean_slope_deg),
            (route.max_grade_deg, plain.max_grade_deg),
        ] {
            assert!(close(a, b), "{a:?} vs {b:?}");
        }
        let heights = |r: &MapRoute| r.waypoints.iter().map(|p| p.height_m).collect::<Vec<_>>();
        assert_eq!(heights(&route), heights(&plain));
        // A height grid of another size is refused.
        let small = DemWindows::new(&d);
        let mut cut = d.clone();
        cut.width = w - 1;
        cut.values.truncate((w - 1) * h);
        let cut_windows = DemWindows::new(&cut);
        assert!(matches!(
            WindowedMap::new(&small, None)
                .unwrap()
                .with_heights(&cut_windows),
            Err(MapRouteError::LayerSize { .. })
        ));
        assert!(
            route.waypoints.iter().any(|p| p.row >= 60),
            "round the wall"
        );
        // Endpoint faults as RouteMap names them.
        let e = map.locate(&at((30, 45)), Endpoint::Goal).unwrap_err();
        assert!(e.to_string().starts_with("the goal"), "{e}");
        assert!(matches!(
            map.locate(&Position::LonLat([200.0, 0.0]), Endpoint::Start),
            Err(MapRouteError::InvalidPosition { .. })
        ));
        let off = Position::Utm {
            utm: [472_000.0 - 50.0, 4_295_000.0 + 50.0],
        };
        assert!(matches!(
            map.locate(&off, Endpoint::Start),
            Err(MapRouteError::Outside { .. })
        ));
    }
}
