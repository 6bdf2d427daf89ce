//! A georeferenced costmap for routes (SPEC §4.3): the cost grid with its
//! CRS, heights and classes, loaded from a costmap GeoTIFF and its DEM;
//! where start and goal given in WGS84 or UTM fall on the grid; and areas
//! (GeoJSON polygons) turned into the cell changes a replan applies. The
//! search and the route's description are in `map_route`.

use std::borrow::Cow;

use geo_types::{Coord, LineString, Polygon};
use proj::Proj;
use serde::{Deserialize, Serialize};

use super::{Cell, CostGrid, GridError, RouteError};
use crate::costmap::Class;
use crate::costmap::grid::{work_geometry, work_grid};
use crate::geo::UtmProjection;
use crate::terrain::cell_size_m;
use crate::terrain::{
    Crs, Dem, DemLimits, GeoTransform, TerrainError, geotiff_pages, read_geotiff_page_band,
};

/// A point given by the caller: `[lon, lat]` (WGS84 degrees) or
/// `{"utm": [easting, northing]}` in the route's UTM zone (the zone of
/// the costmap's centre, reported with every route).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged, deny_unknown_fields)]
pub enum Position {
    LonLat([f64; 2]),
    Utm { utm: [f64; 2] },
}

/// Which end of a route a point is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Endpoint {
    Start,
    Goal,
}

impl Endpoint {
    pub fn name(self) -> &'static str {
        match self {
            Endpoint::Start => "start",
            Endpoint::Goal => "goal",
        }
    }
}

impl std::fmt::Display for Endpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a route on a map could not be planned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MapRouteError {
    #[error("the costmap cannot be planned on: {0}")]
    Grid(#[from] GridError),
    #[error("the costmap's grid is rotated or sheared; only north-up grids can be planned on")]
    RotatedGrid,
    #[error("{0}")]
    Crs(String),
    #[error("the costmap file cannot be read: {0}")]
    CostmapFile(String),
    #[error("the DEM is not the one the costmap was built from: {0}")]
    DemMismatch(String),
    #[error("the DEM's heights cannot be read: {0}")]
    Heights(String),
    #[error("{what} has {got} values; the costmap has {expected} cells")]
    LayerSize {
        what: &'static str,
        expected: usize,
        got: usize,
    },
    #[error("the {end} {} is not a valid position: {reason}", show(.position))]
    InvalidPosition {
        end: Endpoint,
        position: Position,
        reason: String,
    },
    #[error(
        "the {end} (lon {:.6}, lat {:.6}) is outside the costmap, which covers lon {:.6} to \
         {:.6}, lat {:.6} to {:.6}",
        crate::num::readable(.lonlat[0]), crate::num::readable(.lonlat[1]), .extent[0], .extent[2], .extent[1], .extent[3]
    )]
    Outside {
        end: Endpoint,
        lonlat: [f64; 2],
        /// [min lon, min lat, max lon, max lat] of the costmap's corners.
        extent: [f64; 4],
    },
    #[error(
        "the {end} (lon {:.6}, lat {:.6}) is on {what}, not on traversable ground",
        .lonlat[0], .lonlat[1]
    )]
    Blocked {
        end: Endpoint,
        lonlat: [f64; 2],
        what: String,
    },
    #[error(
        "the goal cannot be reached from the start: obstacles separate them \
         (they are in different traversable regions of the costmap)"
    )]
    Unreachable,
    #[error("{0}")]
    Search(RouteError),
    #[error("area {index}: {reason}")]
    InvalidArea { index: usize, reason: String },
}

fn show(p: &Position) -> String {
    use crate::num::readable;
    match p {
        Position::LonLat([lon, lat]) => format!("[{}, {}]", readable(*lon), readable(*lat)),
        Position::Utm { utm: [e, n] } => format!("{{utm: [{}, {}]}}", readable(*e), readable(*n)),
    }
}

/// A costmap ready for route searches: the cost grid with its
/// georeferencing, the heights on the same cells (for 3D length and
/// slopes) and the class codes (to say what a blocked endpoint is on).
pub struct RouteMap {
    pub(super) grid: CostGrid,
    transform: GeoTransform,
    crs: Crs,
    pub(super) heights: Option<Vec<f64>>,
    classes: Option<Vec<u8>>,
    pub(super) utm: UtmProjection,
    map_to_wgs84: Option<Proj>,
    wgs84_to_map: Option<Proj>,
    map_to_utm: Proj,
    utm_to_map: Proj,
}

impl std::fmt::Debug for RouteMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "RouteMap({}×{}, EPSG:{}, {:?})",
            self.grid.width(),
            self.grid.height(),
            self.crs.epsg,
            self.utm
        )
    }
}

pub(super) fn crs_error(e: impl std::fmt::Display) -> MapRouteError {
    MapRouteError::Crs(format!("coordinate transformation failed: {e}"))
}

pub(super) fn proj(from: &str, to: &str) -> Result<Proj, MapRouteError> {
    Proj::new_known_crs(from, to, None).map_err(crs_error)
}

/// The transformations between a map's CRS, WGS84 lon/lat and the UTM
/// zone of the map's centre (none to and from lon/lat when the map is in
/// EPSG:4326 already).
pub(super) struct MapProjections {
    pub(super) utm: UtmProjection,
    pub(super) map_to_utm: Proj,
    pub(super) utm_to_map: Proj,
    pub(super) map_to_wgs84: Option<Proj>,
    pub(super) wgs84_to_map: Option<Proj>,
}

impl MapProjections {
    /// For a `width` × `height` grid placed by `transform` in `crs`.
    pub(super) fn new(
        crs: &Crs,
        transform: &GeoTransform,
        (width, height): (usize, usize),
    ) -> Result<MapProjections, MapRouteError> {
        let map_id = crs.proj_id();
        let (map_to_wgs84, wgs84_to_map) = if crs.epsg == 4326 {
            (None, None)
        } else {
            (
                Some(proj(&map_id, "EPSG:4326")?),
                Some(proj("EPSG:4326", &map_id)?),
            )
        };
        let (cx, cy) = transform.apply(width as f64 / 2.0, height as f64 / 2.0);
        let centre = match &map_to_wgs84 {
            None => (cx, cy),
            Some(p) => p.convert((cx, cy)).map_err(crs_error)?,
        };
        let utm = UtmProjection::for_lonlat(Coord {
            x: centre.0,
            y: centre.1,
        })
        .map_err(|e| MapRouteError::Crs(e.to_string()))?;
        let utm_id = format!("EPSG:{}", utm.epsg());
        Ok(MapProjections {
            map_to_utm: proj(&map_id, &utm_id)?,
            utm_to_map: proj(&utm_id, &map_id)?,
            utm,
            map_to_wgs84,
            wgs84_to_map,
        })
    }
}

/// Why `p`'s coordinates are no position at all (not finite, or degrees
/// beyond the globe), before any transformation.
pub(super) fn coordinates_fault(p: &Position) -> Option<&'static str> {
    match *p {
        Position::LonLat([lon, lat]) => {
            if !(lon.is_finite() && lat.is_finite()) {
                Some("coordinates must be finite numbers")
            } else if !(-180.0..=180.0).contains(&lon) || !(-90.0..=90.0).contains(&lat) {
                Some("[lon, lat] must be within [-180, 180] × [-90, 90] degrees")
            } else {
                None
            }
        }
        Position::Utm { utm: [e, n] } => {
            (!(e.is_finite() && n.is_finite())).then_some("coordinates must be finite numbers")
        }
    }
}

/// [min lon, min lat, max lon, max lat] of the four corners of a
/// `width` × `height` grid placed by `transform` (corners that do not
/// transform are left out).
pub(super) fn corners_extent_lonlat(
    transform: &GeoTransform,
    (width, height): (usize, usize),
    to_lonlat: impl Fn((f64, f64)) -> Result<[f64; 2], MapRouteError>,
) -> [f64; 4] {
    let (w, h) = (width as f64, height as f64);
    let mut e = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for (c, r) in [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)] {
        if let Ok([lon, lat]) = to_lonlat(transform.apply(c, r)) {
            e = [e[0].min(lon), e[1].min(lat), e[2].max(lon), e[3].max(lat)];
        }
    }
    e
}

/// What a blocked endpoint is on, from its cell's [`Class`] (`None`
/// when the class is not known).
pub(super) fn blocked_on(class: Option<Class>) -> &'static str {
    match class {
        Some(Class::Slope) => "an obstacle (a slope steeper than the vehicle can climb)",
        Some(Class::Step) => "an obstacle (a step higher than the vehicle can climb)",
        Some(Class::Enclosed) => "an obstacle (an area enclosed by obstacles)",
        Some(Class::Other) => "an obstacle (lethal land cover or a hazard layer)",
        Some(Class::Unknown) => "unknown terrain (no height data)",
        _ => "an obstacle or unknown terrain",
    }
}

impl RouteMap {
    /// A map of `width` × `height` cells georeferenced by `transform` in
    /// `crs`: row-major `costs` (non-finite = obstacle or unknown), and
    /// optionally the heights (metres, NaN unknown) and [`Class`] codes of
    /// the same cells. Cell sizes come from the transform, in local metres
    /// for a geographic CRS.
    pub fn new(
        width: usize,
        height: usize,
        transform: GeoTransform,
        crs: Crs,
        costs: Vec<f32>,
        heights: Option<Vec<f64>>,
        classes: Option<Vec<u8>>,
    ) -> Result<RouteMap, MapRouteError> {
        if transform.col_rotation != 0.0 || transform.row_rotation != 0.0 {
            return Err(MapRouteError::RotatedGrid);
        }
        let cells = width.saturating_mul(height);
        if let Some(h) = &heights
            && h.len() != cells
        {
            return Err(MapRouteError::LayerSize {
                what: "the height grid",
                expected: cells,
                got: h.len(),
            });
        }
        if let Some(c) = &classes
            && c.len() != cells
        {
            return Err(MapRouteError::LayerSize {
                what: "the class grid",
                expected: cells,
                got: c.len(),
            });
        }
        let sizes: Vec<[f64; 2]> = (0..height)
            .map(|r| {
                cell_size_m(
                    &transform,
                    crs.geographic,
                    width as f64 / 2.0,
                    r as f64 + 0.5,
                )
            })
            .collect();
        let dy = sizes.get(height / 2).map_or(1.0, |s| s[1]);
        let dx = sizes.iter().map(|s| s[0]).collect();
        let grid = CostGrid::new(width, height, costs, dx, dy)?;

        let MapProjections {
            utm,
            map_to_utm,
            utm_to_map,
            map_to_wgs84,
            wgs84_to_map,
        } = MapProjections::new(&crs, &transform, (width, height))?;
        Ok(RouteMap {
            grid,
            transform,
            heights,
            classes,
            map_to_utm,
            utm_to_map,
            crs,
            utm,
            map_to_wgs84,
            wgs84_to_map,
        })
    }

    /// A map from the bytes of a costmap GeoTIFF as terraplan writes it
    /// (page 1 the Float32 cost, page 2 the Byte class codes, nodata 0 =
    /// unknown; or, as written before, one page of two Float32 bands, cost
    /// and class) and, for heights, the DEM it was built from: the DEM is
    /// brought to the costmap's grid by the costmap's own block averaging
    /// (`resample_factor` read off the two cell sizes) and must then cover
    /// exactly the same cells.
    pub fn from_costmap_geotiff(
        costmap_tif: &[u8],
        dem: Option<&Dem>,
        limits: &DemLimits,
    ) -> Result<RouteMap, MapRouteError> {
        let file = |e: TerrainError| MapRouteError::CostmapFile(e.to_string());
        let read = |page, band| read_geotiff_page_band(costmap_tif, page, band, None, limits);
        // Page 2 holds the classes unless it is an overview or mask of
        // page 1 (a costmap of the old layout given overviews by gdaladdo).
        let pages = geotiff_pages(costmap_tif, 2).map_err(file)?;
        let class_page = pages.get(1).is_some_and(|p| p.full_resolution);
        // One band in f64 at a time, each narrowed at once: the largest
        // maps hold 8 bytes a cell less at the peak.
        let mut cost = read(1, 1).map_err(file)?;
        let costs = cost.values.iter().map(|&v| v as f32).collect();
        cost.values = Vec::new();
        let class = if class_page { read(2, 1) } else { read(1, 2) }.map_err(file)?;
        if (class.width, class.height, class.transform) != (cost.width, cost.height, cost.transform)
        {
            return Err(MapRouteError::CostmapFile(format!(
                "the class page ({}×{} cells, geotransform {:?}) is not on the cost page's grid \
                 ({}×{} cells, geotransform {:?})",
                class.width,
                class.height,
                class.transform.coefficients(),
                cost.width,
                cost.height,
                cost.transform.coefficients()
            )));
        }
        let classes = class
            .values
            .iter()
            .map(|&v| {
                // Nodata (NaN: the Byte page's 0) and anything not a class
                // code is unknown.
                if (0.0..=255.0).contains(&v) && v.fract() == 0.0 {
                    v as u8
                } else {
                    Class::Unknown as u8
                }
            })
            .collect();
        let heights = dem.map(|d| heights_on_grid(d, &cost)).transpose()?;
        RouteMap::new(
            cost.width,
            cost.height,
            cost.transform,
            cost.crs,
            costs,
            heights,
            Some(classes),
        )
    }

    pub fn grid(&self) -> &CostGrid {
        &self.grid
    }

    /// Replace the cost grid (e.g. with the one a replanner has changed).
    pub fn set_grid(&mut self, grid: CostGrid) -> Result<(), MapRouteError> {
        if (grid.width(), grid.height()) != (self.grid.width(), self.grid.height()) {
            return Err(MapRouteError::LayerSize {
                what: "the new cost grid",
                expected: self.grid.cell_count(),
                got: grid.cell_count(),
            });
        }
        self.grid = grid;
        Ok(())
    }

    pub fn transform(&self) -> &GeoTransform {
        &self.transform
    }

    pub fn crs(&self) -> &Crs {
        &self.crs
    }

    /// The UTM zone routes are reported in: the zone of the map's centre.
    pub fn utm(&self) -> &UtmProjection {
        &self.utm
    }

    /// "18N", "33S".
    pub fn utm_zone_name(&self) -> String {
        format!(
            "{}{}",
            self.utm.zone(),
            if self.utm.is_north() { 'N' } else { 'S' }
        )
    }

    pub(super) fn to_lonlat(&self, (x, y): (f64, f64)) -> Result<[f64; 2], MapRouteError> {
        let (lon, lat) = match &self.map_to_wgs84 {
            None => (x, y),
            Some(p) => p.convert((x, y)).map_err(crs_error)?,
        };
        Ok([lon, lat])
    }

    pub(super) fn to_utm(&self, (x, y): (f64, f64)) -> Result<[f64; 2], MapRouteError> {
        let (e, n) = self.map_to_utm.convert((x, y)).map_err(crs_error)?;
        Ok([e, n])
    }

    /// A position in the map's CRS; `None` when it cannot be transformed.
    fn position_in_map(&self, p: &Position) -> Option<(f64, f64)> {
        let (x, y) = match *p {
            Position::LonLat([lon, lat]) => match &self.wgs84_to_map {
                None => (lon, lat),
                Some(t) => t.convert((lon, lat)).ok()?,
            },
            Position::Utm { utm: [e, n] } => self.utm_to_map.convert((e, n)).ok()?,
        };
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }

    /// [min lon, min lat, max lon, max lat] of the map's four corners.
    fn extent_lonlat(&self) -> [f64; 4] {
        corners_extent_lonlat(
            &self.transform,
            (self.grid.width(), self.grid.height()),
            |xy| self.to_lonlat(xy),
        )
    }

    /// The cell under `p`, checked: valid coordinates, inside the map, and
    /// traversable (else an error naming `end` and what it is on).
    pub fn locate(&self, p: &Position, end: Endpoint) -> Result<Cell, MapRouteError> {
        let invalid = |reason: &str| MapRouteError::InvalidPosition {
            end,
            position: *p,
            reason: reason.to_string(),
        };
        if let Some(reason) = coordinates_fault(p) {
            return Err(invalid(reason));
        }
        let map_xy = self
            .position_in_map(p)
            .ok_or_else(|| invalid("it cannot be transformed into the costmap's CRS"))?;
        let lonlat = match *p {
            Position::LonLat(ll) => ll,
            // Absurd eastings and northings are beyond the projection.
            Position::Utm { .. } => self
                .to_lonlat(map_xy)
                .map_err(|_| invalid("it cannot be transformed into longitude and latitude"))?,
        };
        let cell = self
            .transform
            .invert(map_xy.0, map_xy.1)
            .and_then(|(c, r)| {
                let inside = c >= 0.0
                    && r >= 0.0
                    && c < self.grid.width() as f64
                    && r < self.grid.height() as f64;
                inside.then_some((r as usize, c as usize))
            });
        let Some(cell) = cell else {
            return Err(MapRouteError::Outside {
                end,
                lonlat,
                extent: self.extent_lonlat(),
            });
        };
        if !self.grid.is_traversable(cell) {
            let i = cell.0 * self.grid.width() + cell.1;
            let what = blocked_on(self.classes.as_ref().and_then(|c| Class::from_code(c[i])));
            return Err(MapRouteError::Blocked {
                end,
                lonlat,
                what: what.to_string(),
            });
        }
        Ok(cell)
    }

    /// A cell centre in the map's CRS.
    pub(super) fn centre(&self, (r, c): Cell) -> (f64, f64) {
        self.transform.apply(c as f64 + 0.5, r as f64 + 0.5)
    }

    /// The cells of the areas (GeoJSON-style polygons in WGS84 lon/lat):
    /// every cell whose centre is inside an area or that an area's
    /// boundary passes through (so a strip narrower than a cell still
    /// blocks a line of cells). Row-major indices, sorted, no repeats;
    /// areas wholly off the map contribute nothing.
    pub fn cells_in_areas(&self, areas: &[Polygon<f64>]) -> Result<Vec<usize>, MapRouteError> {
        let (w, h) = (self.grid.width(), self.grid.height());
        let mut marked = vec![false; w * h];
        for (index, area) in areas.iter().enumerate() {
            let bad = |reason: &str| MapRouteError::InvalidArea {
                index,
                reason: reason.to_string(),
            };
            let mut rings = Vec::new();
            for ring in std::iter::once(area.exterior()).chain(area.interiors()) {
                let mut px = Vec::with_capacity(ring.0.len());
                for p in &ring.0 {
                    if !(p.x.is_finite() && p.y.is_finite()) {
                        return Err(bad("a vertex is not a finite number"));
                    }
                    let (x, y) = self
                        .position_in_map(&Position::LonLat([p.x, p.y]))
                        .ok_or_else(|| {
                            bad("a vertex cannot be transformed to the costmap's CRS")
                        })?;
                    let (c, r) = self
                        .transform
                        .invert(x, y)
                        .ok_or_else(|| bad("the costmap's grid cannot be inverted"))?;
                    px.push(Coord { x: c, y: r });
                }
                rings.push(LineString(px));
            }
            if rings[0].0.len() < 3 {
                return Err(bad("a polygon needs at least 3 vertices"));
            }
            mark_polygon(&rings, w, h, &mut marked);
        }
        Ok(marked
            .iter()
            .enumerate()
            .filter_map(|(i, &m)| m.then_some(i))
            .collect())
    }
}

/// The DEM's heights on the costmap's grid `map` (as read from its
/// GeoTIFF), averaged in blocks as the costmap pipeline does.
fn heights_on_grid(dem: &Dem, map: &Dem) -> Result<Vec<f64>, MapRouteError> {
    let factor = averaging_factor(dem, map)?;
    Ok(work_grid(Cow::Borrowed(dem), factor).z)
}

/// The block size (columns, rows) that brings `dem` onto the costmap's
/// grid `map` by the costmap's own block averaging, checked: the same
/// CRS, and the averaged grid exactly the costmap's. Neither raster's
/// values are read.
pub(super) fn averaging_factor(dem: &Dem, map: &Dem) -> Result<[usize; 2], MapRouteError> {
    let mismatch = |why: String| MapRouteError::DemMismatch(why);
    if dem.crs.epsg != map.crs.epsg {
        return Err(mismatch(format!(
            "the DEM is in EPSG:{}, the costmap in EPSG:{}",
            dem.crs.epsg, map.crs.epsg
        )));
    }
    let (d, m) = (&dem.transform, &map.transform);
    let fx = (m.pixel_width / d.pixel_width).round();
    let fy = (m.pixel_height / d.pixel_height).round();
    if !(fx >= 1.0 && fy >= 1.0) {
        return Err(mismatch("its cells are larger than the costmap's".into()));
    }
    let factor = [fx as usize, fy as usize];
    let grid = work_geometry(dem, factor);
    let g = &grid.transform;
    let close = |a: f64, b: f64, cell: f64| (a - b).abs() <= 1e-6 * cell.abs();
    let same = grid.width == map.width
        && grid.height == map.height
        && close(g.origin_x, m.origin_x, m.pixel_width)
        && close(g.origin_y, m.origin_y, m.pixel_height)
        && close(g.pixel_width, m.pixel_width, m.pixel_width)
        && close(g.pixel_height, m.pixel_height, m.pixel_height);
    if !same {
        return Err(mismatch(format!(
            "averaged {fx}×{fy} it gives a {}×{} grid at ({}, {}), the costmap is {}×{} at ({}, {})",
            grid.width,
            grid.height,
            g.origin_x,
            g.origin_y,
            map.width,
            map.height,
            m.origin_x,
            m.origin_y
        )));
    }
    Ok(factor)
}

/// Sets the cells (in a `w` × `h` grid, pixel coordinates: cell (r, c)
/// spans [c, c+1) × [r, r+1)) whose centre is inside the polygon (even-odd
/// rule over all rings) or that a ring's edge passes through.
fn mark_polygon(rings: &[LineString<f64>], w: usize, h: usize, marked: &mut [bool]) {
    let edges: Vec<(Coord<f64>, Coord<f64>)> = rings
        .iter()
        .flat_map(|ring| {
            let n = ring.0.len();
            (0..n).map(move |i| (ring.0[i], ring.0[(i + 1) % n]))
        })
        .filter(|(a, b)| a != b)
        .collect();
    let (min_y, max_y) = edges
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |m, (a, b)| {
            (m.0.min(a.y).min(b.y), m.1.max(a.y).max(b.y))
        });
    // Centres inside: scanlines through the row centres.
    let r0 = (min_y - 0.5).ceil().max(0.0);
    let r1 = (max_y - 0.5).floor().min(h as f64 - 1.0);
    let mut xs = Vec::new();
    if r0 <= r1 {
        for r in r0 as usize..=r1 as usize {
            let y = r as f64 + 0.5;
            xs.clear();
            for (a, b) in &edges {
                // Half-open in y, so a vertex on the line counts once.
                if (a.y <= y) != (b.y <= y) {
                    xs.push(a.x + (y - a.y) / (b.y - a.y) * (b.x - a.x));
                }
            }
            xs.sort_by(f64::total_cmp);
            for span in xs.chunks_exact(2) {
                let c0 = (span[0] - 0.5).ceil().max(0.0);
                let c1 = (span[1] - 0.5).floor().min(w as f64 - 1.0);
                if c0 <= c1 {
                    for c in c0 as usize..=c1 as usize {
                        marked[r * w + c] = true;
                    }
                }
            }
        }
    }
    // Cells the edges pass through: sampled finely enough that no crossed
    // cell is missed by more than a sliver of 1/8 cell.
    for (a, b) in &edges {
        let span = (b.x - a.x).abs().max((b.y - a.y).abs());
        // Edges far off the map cost nothing: clip the walk to the grid.
        let steps = ((span * 8.0).ceil() as usize).clamp(1, 8 * 4 * (w + h));
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let (x, y) = (a.x + (b.x - a.x) * t, a.y + (b.y - a.y) * t);
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                marked[y as usize * w + x as usize] = true;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::route::RouteOptions;

    /// A 100 × 80 grid of 2 m cells in UTM 18N (EPSG:32618) near
    /// 75.3°W 38.8°N, cost 1 except where `blocked` says.
    fn utm_map(blocked: impl Fn(usize, usize) -> bool, heights: Option<Vec<f64>>) -> RouteMap {
        let (w, h) = (100, 80);
        let costs = (0..w * h)
            .map(|i| if blocked(i / w, i % w) { f32::NAN } else { 1.0 })
            .collect();
        let t = GeoTransform {
            origin_x: 472_000.0,
            pixel_width: 2.0,
            col_rotation: 0.0,
            origin_y: 4_295_000.0,
            row_rotation: 0.0,
            pixel_height: -2.0,
        };
        let classes = (0..w * h)
            .map(|i| if blocked(i / w, i % w) { 3 } else { 1 })
            .collect();
        RouteMap::new(
            w,
            h,
            t,
            Crs::from_epsg(32618).unwrap(),
            costs,
            heights,
            Some(classes),
        )
        .unwrap()
    }

    fn utm_of(map: &RouteMap, cell: Cell) -> Position {
        let [e, n] = map.to_utm(map.centre(cell)).unwrap();
        Position::Utm { utm: [e, n] }
    }

    fn lonlat_of(map: &RouteMap, cell: Cell) -> Position {
        Position::LonLat(map.to_lonlat(map.centre(cell)).unwrap())
    }

    #[test]
    fn positions_land_on_their_cells() {
        let map = utm_map(|_, _| false, None);
        assert_eq!(map.utm_zone_name(), "18N");
        for cell in [(0, 0), (79, 99), (40, 17), (3, 96)] {
            assert_eq!(map.locate(&utm_of(&map, cell), Endpoint::Start), Ok(cell));
            assert_eq!(map.locate(&lonlat_of(&map, cell), Endpoint::Goal), Ok(cell));
        }
    }

    #[test]
    fn positions_parse_from_json() {
        let p: Position = serde_json::from_str("[-75.5, 38.8]").unwrap();
        assert_eq!(p, Position::LonLat([-75.5, 38.8]));
        let p: Position = serde_json::from_str(r#"{"utm": [472000, 4295000]}"#).unwrap();
        assert_eq!(
            p,
            Position::Utm {
                utm: [472_000.0, 4_295_000.0]
            }
        );
        for bad in [
            r#"{"utm": [1, 2], "zone": 18}"#,
            "[1]",
            "[1, 2, 3]",
            r#"{"lon": 1}"#,
        ] {
            assert!(serde_json::from_str::<Position>(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn endpoint_faults_name_the_end() {
        let map = utm_map(|r, c| r == 10 && c == 10, None);
        let off = Position::Utm {
            utm: [472_000.0 - 5.0, 4_295_000.0 - 10.0],
        };
        let e = map.locate(&off, Endpoint::Goal).unwrap_err();
        assert!(
            matches!(
                e,
                MapRouteError::Outside {
                    end: Endpoint::Goal,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().starts_with("the goal"), "{e}");
        let e = map
            .locate(&utm_of(&map, (10, 10)), Endpoint::Start)
            .unwrap_err();
        assert!(e.to_string().contains("step higher"), "{e}");
        assert!(matches!(
            map.locate(&Position::LonLat([200.0, 0.0]), Endpoint::Start),
            Err(MapRouteError::InvalidPosition { .. })
        ));
        assert!(matches!(
            map.locate(&Position::LonLat([f64::NAN, 0.0]), Endpoint::Start),
            Err(MapRouteError::InvalidPosition { .. })
        ));
    }

    #[test]
    fn a_wall_with_no_gap_is_unreachable() {
        let map = utm_map(|_, c| c == 50, None);
        let e = map
            .plan(
                &utm_of(&map, (40, 10)),
                &utm_of(&map, (40, 90)),
                &RouteOptions::default(),
                &|| false,
            )
            .unwrap_err();
        assert_eq!(e, MapRouteError::Unreachable);
    }

    #[test]
    fn straight_route_on_a_tilted_plane() {
        // Heights rise 1 m per 2 m cell eastwards: a 26.57° slope.
        let (w, h) = (100, 80);
        let heights = (0..w * h).map(|i| (i % w) as f64).collect();
        let map = utm_map(|_, _| false, Some(heights));
        let r = map
            .plan(
                &utm_of(&map, (40, 10)),
                &utm_of(&map, (40, 90)),
                &RouteOptions::default(),
                &|| false,
            )
            .unwrap();
        assert_eq!(r.waypoints.len(), 2);
        assert!((r.length_2d_m - 160.0).abs() < 1e-9, "{}", r.length_2d_m);
        let expect_3d = 160.0f64.hypot(80.0);
        assert!((r.length_3d_m.unwrap() - expect_3d).abs() < 1e-6);
        let slope = 0.5f64.atan().to_degrees();
        assert!((r.max_slope_deg.unwrap() - slope).abs() < 1e-9);
        assert!((r.mean_slope_deg.unwrap() - slope).abs() < 1e-9);
        assert!((r.max_grade_deg.unwrap() - slope).abs() < 1e-9);
        assert!((r.climb_m.unwrap() - 80.0).abs() < 1e-9);
        assert_eq!(r.descent_m, Some(0.0));
        assert_eq!(r.waypoints[0].height_m, Some(10.0));
        assert_eq!(r.waypoints[1].height_m, Some(90.0));
        // 80 cells at cost 1: the path cost is its length.
        assert!((r.path_cost - 160.0).abs() < 1e-9);
        assert!((r.cost - 160.0).abs() < 1e-9);
        let e = r.waypoints[1].easting - r.waypoints[0].easting;
        assert!((e - 160.0).abs() < 1e-6, "{e}");
    }

    #[test]
    fn area_cells_include_centres_and_boundary() {
        let map = utm_map(|_, _| false, None);
        let t = *map.transform();
        let ll = |c: f64, r: f64| {
            let [lon, lat] = map.to_lonlat(t.apply(c, r)).unwrap();
            Coord { x: lon, y: lat }
        };
        // A square over cells 10..20 × 5..15 (pixel corners), and a sliver
        // 0.1 cell wide along column 50.
        let square = Polygon::new(
            LineString(vec![
                ll(10.0, 5.0),
                ll(20.0, 5.0),
                ll(20.0, 15.0),
                ll(10.0, 15.0),
            ]),
            vec![],
        );
        let sliver = Polygon::new(
            LineString(vec![
                ll(50.4, 30.2),
                ll(50.5, 30.2),
                ll(50.5, 39.8),
                ll(50.4, 39.8),
            ]),
            vec![],
        );
        let cells = map.cells_in_areas(&[square, sliver]).unwrap();
        let w = 100;
        for r in 5..15 {
            for c in 10..20 {
                assert!(cells.binary_search(&(r * w + c)).is_ok(), "({r}, {c})");
            }
        }
        for r in 30..40 {
            assert!(cells.binary_search(&(r * w + 50)).is_ok(), "sliver row {r}");
        }
        // Boundary cells may include the ring of cells the edges touch,
        // never more than one cell beyond.
        for &i in &cells {
            let (r, c) = (i / w, i % w);
            let in_square = (4..=15).contains(&r) && (9..=20).contains(&c);
            let in_sliver = (30..40).contains(&r) && c == 50;
            assert!(in_square || in_sliver, "({r}, {c})");
        }
        // Off the map: nothing.
        let far = Polygon::new(
            LineString(vec![ll(-50.0, -50.0), ll(-40.0, -50.0), ll(-40.0, -40.0)]),
            vec![],
        );
        assert!(map.cells_in_areas(&[far]).unwrap().is_empty());
    }

    #[test]
    fn geographic_maps_use_local_metres() {
        // 0.0001° cells at 60°N: about 5.57 m east-west, 11.1 m north-south.
        let (w, h) = (50, 50);
        let t = GeoTransform {
            origin_x: 10.0,
            pixel_width: 1e-4,
            col_rotation: 0.0,
            origin_y: 60.0025,
            row_rotation: 0.0,
            pixel_height: -1e-4,
        };
        let map = RouteMap::new(
            w,
            h,
            t,
            Crs::from_epsg(4326).unwrap(),
            vec![1.0; w * h],
            None,
            None,
        )
        .unwrap();
        let r = map
            .plan(
                &lonlat_of(&map, (25, 5)),
                &lonlat_of(&map, (25, 45)),
                &RouteOptions::default(),
                &|| false,
            )
            .unwrap();
        let de = r.waypoints[1].easting - r.waypoints[0].easting;
        // The grid's metres agree with UTM's within 0.5 %.
        assert!(
            (r.length_2d_m / de - 1.0).abs() < 5e-3,
            "{} vs {de}",
            r.length_2d_m
        );
        assert_eq!(r.length_3d_m, None);
    }

    /// A costmap built by the pipeline at half the DEM's resolution,
    /// written as its GeoTIFF and read back with the DEM: the heights are
    /// the costmap's own block means, a wall of the DEM blocks the cells,
    /// and the route goes round it.
    #[test]
    fn costmap_geotiff_round_trip_with_the_dem() {
        use crate::costmap::{CostmapOptions, Stage, VehiclePreset, build_costmap};
        use crate::terrain::geotiff::{Band, BandData, Page, write_geotiff};
        use crate::terrain::test_support::{dem, north_up};
        let (w, h) = (120, 100);
        // A gentle plane (2 %) with a 3 m wall across columns 60..64,
        // open in rows 80.. .
        let values = (0..w * h)
            .map(|i| {
                let (r, c) = (i / w, i % w);
                let wall = (60..64).contains(&c) && r < 80;
                0.02 * 0.5 * c as f64 + if wall { 3.0 } else { 0.0 }
            })
            .collect();
        let mut d = dem(
            w,
            h,
            values,
            north_up(500_000.0, 4_300_000.0, 0.5, 0.5),
            false,
        );
        d.crs = Crs::from_epsg(32618).unwrap();
        let options = CostmapOptions {
            resolution_m: Some(1.0),
            ..CostmapOptions::default()
        };
        let vehicle = VehiclePreset::UGo.vehicle();
        let cm = build_costmap(&d, &vehicle, &options, None, &|_: Stage, _: f64| true).unwrap();
        let mut tif = std::io::Cursor::new(Vec::new());
        cm.write_geotiff(&mut tif).unwrap();
        let tif = tif.into_inner();
        let map = RouteMap::from_costmap_geotiff(&tif, Some(&d), &DemLimits::default()).unwrap();
        assert_eq!((map.grid().width(), map.grid().height()), (60, 50));
        // Block (r, c) of the 1 m grid is the mean of DEM cells 2r.., 2c..
        let z = map.height_at((10, 5)).unwrap();
        let expect = 0.02 * 0.5 * (10.0 + 11.0) / 2.0;
        assert!((z - expect).abs() < 1e-9, "{z} vs {expect}");
        let costs = map.grid().costs();
        assert_eq!(costs.len(), cm.cost.len());
        assert!(
            costs
                .iter()
                .zip(&cm.cost)
                .all(|(a, b)| a.is_nan() == b.is_nan())
        );
        let r = map
            .plan(
                &utm_of(&map, (10, 10)),
                &utm_of(&map, (10, 50)),
                &RouteOptions::default(),
                &|| false,
            )
            .unwrap();
        // Round the wall's end at row 40 of the 1 m grid.
        assert!(r.waypoints.iter().any(|p| p.row >= 40), "{:?}", r.waypoints);
        assert!(r.length_2d_m > 2.0 * 30.0);
        assert!(r.max_slope_deg.unwrap() < 5.0);
        // Without the DEM: no heights; with another DEM: refused.
        let bare = RouteMap::from_costmap_geotiff(&tif, None, &DemLimits::default()).unwrap();
        assert_eq!(bare.height_at((10, 5)), None);
        let mut shifted = d.clone();
        shifted.transform.origin_x += 7.0;
        assert!(matches!(
            RouteMap::from_costmap_geotiff(&tif, Some(&shifted), &DemLimits::default()),
            Err(MapRouteError::DemMismatch(_))
        ));
        assert!(matches!(
            RouteMap::from_costmap_geotiff(b"not a tiff", None, &DemLimits::default()),
            Err(MapRouteError::CostmapFile(_))
        ));

        // The class codes come back exactly from the Byte page, its nodata
        // (0) as unknown, and from the Float32 band 2 of costmaps written
        // before the class page.
        assert_eq!(bare.classes.as_deref(), Some(&cm.class[..]));
        assert!(cm.class.contains(&(Class::Unknown as u8)));
        let classes_f32: Vec<f32> = cm.class.iter().map(|&k| f32::from(k)).collect();
        let bands = [
            Band::new("cost", "", BandData::F32(&cm.cost)),
            Band::new("class", "", BandData::F32(&classes_f32)),
        ];
        let page = Page {
            bands: &bands,
            nodata: Some(f64::NAN),
        };
        let mut old = std::io::Cursor::new(Vec::new());
        write_geotiff(
            &mut old,
            cm.width,
            cm.height,
            &cm.transform,
            &cm.crs,
            &[page],
        )
        .unwrap();
        let map =
            RouteMap::from_costmap_geotiff(old.get_ref(), None, &DemLimits::default()).unwrap();
        assert_eq!(map.classes.as_deref(), Some(&cm.class[..]));

        // A class page on another grid is refused, naming both: page 2's
        // ModelTiepoint (the second copy, IFDs being written in page order)
        // moved by 1 m east.
        let mut moved = tif.clone();
        let t = cm.transform;
        let tiepoint: Vec<u8> = [0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0]
            .iter()
            .flat_map(|v: &f64| v.to_le_bytes())
            .collect();
        let at: Vec<usize> = moved
            .windows(tiepoint.len())
            .enumerate()
            .filter(|(_, w)| *w == &tiepoint[..])
            .map(|(i, _)| i)
            .collect();
        assert_eq!(at.len(), 2);
        moved[at[1] + 24..at[1] + 32].copy_from_slice(&(t.origin_x + 1.0).to_le_bytes());
        let e = RouteMap::from_costmap_geotiff(&moved, None, &DemLimits::default()).unwrap_err();
        assert!(
            matches!(&e, MapRouteError::CostmapFile(m) if m.contains("class page")),
            "{e}"
        );
    }
}
