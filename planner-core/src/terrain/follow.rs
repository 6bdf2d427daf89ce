//! Terrain following (SPEC §3.3–3.4, thesis §5.4): flown altitudes above a
//! dilated DEM, with waypoints added along a 2D path wherever the straight
//! segment between two waypoints would leave the allowed height band.
//!
//! Heights here are in the DEM's vertical datum (metres); positions are in
//! the planning CRS (a UTM zone) and transformed into the DEM's CRS to be
//! sampled.

use geo_types::{Coord, Rect};
use proj::Proj;

use super::{Crs, Dem, DemFormat, GeoTransform, TerrainError, dilate};

/// Most samples along all the paths of one survey: bounds time and memory
/// on huge surveys over fine DEMs (the step grows instead, and the safe
/// surface with it).
const MAX_SURVEY_SAMPLES: f64 = 4.0e6;
/// Share of the tolerance used when choosing waypoints: the terrain between
/// two samples is bilinear, not linear, so keep a little in reserve.
const BAND_RESERVE: f64 = 0.9;

/// A flown position: planning-CRS metres and altitude in the DEM's datum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Point3 {
    pub fn xy(&self) -> Coord<f64> {
        Coord {
            x: self.x,
            y: self.y,
        }
    }
}

/// How one stretch of path is flown: `offset` metres above the dilated
/// terrain, within ±`band` of that, with optional rate limits expressed as
/// metres of climb/descent per metre flown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightRule {
    pub offset_m: f64,
    pub band_m: f64,
    pub max_climb_per_m: Option<f64>,
    pub max_descent_per_m: Option<f64>,
}

/// The DEM around a survey, in the form terrain following needs: the raw
/// heights (for reporting and for home) and the safe surface flown over.
///
/// The safe surface at a point is the highest point of the DEM's bilinear
/// surface within the dilation radius, computed on a square grid of blocks
/// in the planning CRS: each block holds the maximum of the bilinear surface
/// over it (exact: that maximum lies at a DEM cell centre inside the block
/// or on the block's edges, which are sampled at half a cell), and the
/// blocks are dilated (grey-scale, over a disk grown by the blocks' size so
/// that it covers every point within the radius). Working on the bilinear
/// surface rather than on the DEM's cells makes the result independent of
/// the DEM's grid: a geographic DEM and a projected copy of it give the same
/// surface.
pub struct TerrainModel {
    raw: Dem,
    /// Dilated block maxima, a grid in the planning CRS.
    dilated: Dem,
    to_dem: Option<Proj>,
    /// Height used where the DEM has no data: the highest dilated height in
    /// the model, so unknown terrain is never assumed low.
    fallback_m: f64,
    /// Sampling step along paths, metres (half a block, more on huge
    /// surveys).
    step_m: f64,
    dilation_radius_m: f64,
}

impl std::fmt::Debug for TerrainModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TerrainModel({}×{}, radius {} m)",
            self.raw.width, self.raw.height, self.dilation_radius_m
        )
    }
}

/// Most blocks of the safe-surface grid (bounds its time and memory).
const MAX_BLOCKS: f64 = 2.0e6;
/// Most block-edge samples for the safe surface.
const MAX_EDGE_SAMPLES: f64 = 1.6e7;
/// Blocks per dilation radius (the finer, the closer the disk).
const BLOCKS_PER_RADIUS: f64 = 10.0;

impl TerrainModel {
    /// The part of `dem` under `extent` (planning-CRS metres, EPSG
    /// `planning_epsg`) plus a margin, and its safe surface for
    /// `dilation_radius_m`. `path_length_m` is about how much will be
    /// flown: the sampling step is half a block, coarser if the paths would
    /// need more than a few million samples.
    pub fn new(
        dem: &Dem,
        planning_epsg: u32,
        extent: Rect<f64>,
        dilation_radius_m: f64,
        path_length_m: f64,
    ) -> Result<Self, TerrainError> {
        let crs_err = |e: proj::ProjCreateError| {
            TerrainError::Crs(format!("transformation to the DEM's CRS: {e}"))
        };
        let planning = format!("EPSG:{planning_epsg}");
        let (to_dem, from_dem) = if dem.crs.epsg == planning_epsg {
            (None, None)
        } else {
            (
                Some(Proj::new_known_crs(&planning, &dem.crs.proj_id(), None).map_err(crs_err)?),
                Some(Proj::new_known_crs(&dem.crs.proj_id(), &planning, None).map_err(crs_err)?),
            )
        };
        let res = dem.resolution_m();
        if !(res[0].min(res[1]).is_finite() && res[0].min(res[1]) > 0.0) {
            return Err(TerrainError::Invalid(
                "the DEM's cell size is not positive".into(),
            ));
        }
        let radius = dilation_radius_m.max(0.0);
        let margin = radius + 3.0 * res[0].max(res[1]);
        let window = pixel_window(dem, to_dem.as_ref(), extent, margin)?;
        let raw = match window {
            Some((c0, r0, c1, r1)) => dem.window(c0, r0, c1 - c0, r1 - r0),
            // The extent misses the DEM entirely: an empty model where every
            // sample is unknown.
            None => dem.window(0, 0, 0, 0),
        };
        // Cell size where the survey is (for a geographic DEM the metres per
        // degree of the window's latitude, not the whole raster's).
        let local = if raw.width > 0 && raw.height > 0 {
            raw.resolution_m()
        } else {
            res
        };
        let cell = local[0].min(local[1]);
        let cell = if cell.is_finite() && cell > 0.0 {
            cell
        } else {
            res[0].min(res[1])
        };
        let (min, max) = (extent.min(), extent.max());
        let area = (max.x - min.x + 2.0 * margin) * (max.y - min.y + 2.0 * margin);
        let g = (radius / BLOCKS_PER_RADIUS)
            .max((area / MAX_BLOCKS).sqrt())
            .max(0.25);
        // Paths are checked every half block, where the safe surface (a
        // bilinear surface on the blocks) is sampled finely enough; tied to
        // the blocks, not to the DEM's cells, so that two DEMs of one area
        // give one flight.
        let step_m = (g / 2.0).max(path_length_m.max(0.0) / MAX_SURVEY_SAMPLES);
        let blocks = BlockGrid::around(extent, margin + 2.0 * g, g, planning_epsg, &dem.crs.name);
        let maxima = blocks.maxima(&raw, to_dem.as_ref(), from_dem.as_ref(), cell);
        // Every point within `radius` of a point p lies in a block whose
        // centre is within radius + 1.5·√2·g of the centres around p; a
        // block's maximum may sit on its edge, next to the neighbouring
        // block's cells (one more g); and paths are checked every `step`,
        // so a point between two samples is within step/2 of one (one more
        // step, conservatively).
        let dilated = dilate(&maxima, radius + step_m + 3.0 * g)?;
        let fallback_m = dilated
            .values
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f64::NEG_INFINITY, f64::max);
        Ok(TerrainModel {
            raw,
            dilated,
            to_dem,
            fallback_m,
            step_m,
            dilation_radius_m: radius,
        })
    }

    pub fn dilation_radius_m(&self) -> f64 {
        self.dilation_radius_m
    }

    /// Smallest sampling step along paths, metres.
    pub fn step_m(&self) -> f64 {
        self.step_m
    }

    /// The DEM's cell size under the model, metres (the smaller side).
    pub fn cell_m(&self) -> f64 {
        let r = self.raw.resolution_m();
        r[0].min(r[1])
    }

    /// True when no DEM cell lies under the model's extent.
    pub fn is_empty(&self) -> bool {
        self.fallback_m == f64::NEG_INFINITY
    }

    fn dem_xy(&self, p: Coord<f64>) -> Option<(f64, f64)> {
        match &self.to_dem {
            None => Some((p.x, p.y)),
            Some(t) => t.convert((p.x, p.y)).ok(),
        }
    }

    /// Bilinear DEM height at `p`; `None` on nodata or outside.
    pub fn terrain(&self, p: Coord<f64>) -> Option<f64> {
        let (x, y) = self.dem_xy(p)?;
        self.raw.sample(x, y)
    }

    /// Height of the dilated (safe) surface at `p`; `None` on nodata or
    /// outside.
    pub fn safe_terrain(&self, p: Coord<f64>) -> Option<f64> {
        self.dilated.sample(p.x, p.y)
    }

    /// [`TerrainModel::safe_terrain`], or the highest height of the model
    /// where it is unknown.
    fn safe_or_fallback(&self, p: Coord<f64>) -> f64 {
        self.safe_terrain(p).unwrap_or(self.fallback_m)
    }

    /// Points along `path` at most `step` apart (every vertex included),
    /// with their distance from the start.
    pub fn densify(&self, path: &[Coord<f64>]) -> Vec<(f64, Coord<f64>)> {
        self.densify_marking_vertices(path).0
    }

    /// [`TerrainModel::densify`], plus the index of each of `path`'s
    /// vertices among the samples.
    fn densify_marking_vertices(
        &self,
        path: &[Coord<f64>],
    ) -> (Vec<(f64, Coord<f64>)>, Vec<usize>) {
        let step = self.step_m;
        let mut out = Vec::new();
        let mut vertices = Vec::with_capacity(path.len());
        let Some(&first) = path.first() else {
            return (out, vertices);
        };
        out.push((0.0, first));
        vertices.push(0);
        let mut s0 = 0.0;
        for w in path.windows(2) {
            let len = dist(w[0], w[1]);
            let n = (len / step).ceil().max(1.0) as usize;
            for k in 1..n {
                let t = k as f64 / n as f64;
                out.push((s0 + len * t, lerp(w[0], w[1], t)));
            }
            s0 += len;
            // The vertex itself, exactly (not re-computed by lerp).
            out.push((s0, w[1]));
            vertices.push(out.len() - 1);
        }
        (out, vertices)
    }

    /// The 3D waypoints flying `path` under `rule`: every vertex of `path`
    /// (where the track turns) plus the points needed to keep the straight
    /// segments between waypoints within the band, checked every
    /// [`TerrainModel::step_m`]. The first and last points are `path`'s ends.
    pub fn follow(&self, path: &[Coord<f64>], rule: &HeightRule) -> Vec<Point3> {
        self.follow_marked(path, rule).0
    }

    /// [`TerrainModel::follow`], plus for each vertex of `path` its index
    /// among the returned waypoints.
    pub fn follow_marked(
        &self,
        path: &[Coord<f64>],
        rule: &HeightRule,
    ) -> (Vec<Point3>, Vec<usize>) {
        if path.is_empty() {
            return (Vec::new(), Vec::new());
        }
        let (samples, vertex_idx) = self.densify_marking_vertices(path);
        let mut target: Vec<f64> = samples
            .iter()
            .map(|&(_, p)| self.safe_or_fallback(p) + rule.offset_m)
            .collect();
        apply_rate_limits(&samples, &mut target, rule);
        // Waypoints sit on every vertex of the 2D path (where it turns);
        // between two vertices, as few as the band allows.
        let band = rule.band_m * BAND_RESERVE;
        let mut keep = vec![vertex_idx[0]];
        for w in vertex_idx.windows(2) {
            simplify(&samples, &target, w[0], w[1], band, &mut keep);
        }
        let points = keep
            .iter()
            .map(|&i| Point3 {
                x: samples[i].1.x,
                y: samples[i].1.y,
                z: target[i],
            })
            .collect();
        // `keep` is increasing and holds every vertex's sample.
        let mut marks = Vec::with_capacity(vertex_idx.len());
        let mut k = 0;
        for &v in &vertex_idx {
            while keep[k] < v {
                k += 1;
            }
            marks.push(k);
        }
        (points, marks)
    }

    /// Fraction of `points` (e.g. a grid over the free space) with a DEM
    /// height, in [0, 1]; 1 for no points.
    pub fn known_fraction(&self, points: &[Coord<f64>]) -> f64 {
        if points.is_empty() {
            return 1.0;
        }
        let known = points
            .iter()
            .filter(|&&p| self.terrain(p).is_some())
            .count();
        known as f64 / points.len() as f64
    }
}

/// Raise `target` so that no climb or descent is steeper than allowed:
/// descending late and climbing early keeps the flight above the targets.
fn apply_rate_limits(samples: &[(f64, Coord<f64>)], target: &mut [f64], rule: &HeightRule) {
    if let Some(d) = rule.max_descent_per_m {
        for i in 1..target.len() {
            let ds = samples[i].0 - samples[i - 1].0;
            target[i] = target[i].max(target[i - 1] - d * ds);
        }
    }
    if let Some(c) = rule.max_climb_per_m {
        for i in (0..target.len().saturating_sub(1)).rev() {
            let ds = samples[i + 1].0 - samples[i].0;
            target[i] = target[i].max(target[i + 1] - c * ds);
        }
    }
}

/// Greedy waypoint choice on one straight piece `from..=to`: from each
/// waypoint, the farthest sample whose straight line to it stays within
/// ±`band` of every target in between (a funnel of allowed slopes).
fn simplify(
    samples: &[(f64, Coord<f64>)],
    target: &[f64],
    from: usize,
    to: usize,
    band: f64,
    keep: &mut Vec<usize>,
) {
    let mut k = from;
    while k < to {
        let (sk, zk) = (samples[k].0, target[k]);
        let mut lo = f64::NEG_INFINITY;
        let mut hi = f64::INFINITY;
        let mut best = k + 1;
        for j in k + 1..=to {
            let ds = samples[j].0 - sk;
            if ds <= 1e-9 {
                best = j;
                continue;
            }
            let slope = (target[j] - zk) / ds;
            if slope >= lo - 1e-12 && slope <= hi + 1e-12 {
                best = j;
            }
            lo = lo.max((target[j] - band - zk) / ds);
            hi = hi.min((target[j] + band - zk) / ds);
            if lo > hi {
                break;
            }
        }
        keep.push(best);
        k = best;
    }
}

/// A square grid in the planning CRS, row 0 at the top.
struct BlockGrid {
    x0: f64,
    y1: f64,
    g: f64,
    nx: usize,
    ny: usize,
    epsg: u32,
    name: String,
}

impl BlockGrid {
    /// Blocks of `g` metres over `extent` grown by `margin`, aligned on
    /// multiples of `g` (so two DEMs of one area share the grid).
    fn around(extent: Rect<f64>, margin: f64, g: f64, epsg: u32, name: &str) -> BlockGrid {
        let x0 = ((extent.min().x - margin) / g).floor() * g;
        let y0 = ((extent.min().y - margin) / g).floor() * g;
        let x1 = ((extent.max().x + margin) / g).ceil() * g;
        let y1 = ((extent.max().y + margin) / g).ceil() * g;
        BlockGrid {
            x0,
            y1,
            g,
            nx: ((x1 - x0) / g).round().max(1.0) as usize,
            ny: ((y1 - y0) / g).round().max(1.0) as usize,
            epsg,
            name: name.to_string(),
        }
    }

    /// The maximum of `raw`'s bilinear surface over each block (`NaN` where
    /// the block has no DEM data): DEM cell centres inside the block, and
    /// the block edges sampled every half `cell_m` (at most 256 per edge).
    fn maxima(
        &self,
        raw: &Dem,
        to_dem: Option<&Proj>,
        from_dem: Option<&Proj>,
        cell_m: f64,
    ) -> Dem {
        let (nx, ny, g) = (self.nx, self.ny, self.g);
        let mut v = vec![f64::NAN; nx * ny];
        if raw.width == 0 || raw.height == 0 {
            return self.grid(v);
        }
        let mut raise = |i: usize, j: usize, h: f64| {
            let slot = &mut v[j * nx + i];
            if slot.is_nan() || h > *slot {
                *slot = h;
            }
        };
        let sample = |x: f64, y: f64| -> Option<f64> {
            let (dx, dy) = match to_dem {
                None => (x, y),
                Some(t) => t.convert((x, y)).ok()?,
            };
            raw.sample(dx, dy)
        };
        // Edge samples per block side: every half DEM cell, within a budget
        // for the whole grid (where cells are much finer than blocks, the
        // cell centres inside carry the maxima anyway).
        let budget = (MAX_EDGE_SAMPLES / (2.0 * nx as f64 * ny as f64)).max(1.0);
        let m = (g / (cell_m / 2.0)).ceil().clamp(1.0, budget.min(256.0)) as usize;
        let s = g / m as f64;
        // Horizontal edges (y = y1 − j·g) and vertical ones (x = x0 + i·g);
        // a sample on an edge belongs to the blocks on both sides.
        for j in 0..=ny {
            let y = self.y1 - j as f64 * g;
            for k in 0..=nx * m {
                let Some(h) = sample(self.x0 + k as f64 * s, y) else {
                    continue;
                };
                for jj in [j.wrapping_sub(1), j] {
                    if jj >= ny {
                        continue;
                    }
                    let i = k / m;
                    if i < nx {
                        raise(i, jj, h);
                    }
                    if k % m == 0 && i >= 1 && i - 1 < nx {
                        raise(i - 1, jj, h);
                    }
                }
            }
        }
        for i in 0..=nx {
            let x = self.x0 + i as f64 * g;
            for k in 0..=ny * m {
                let Some(h) = sample(x, self.y1 - k as f64 * s) else {
                    continue;
                };
                for ii in [i.wrapping_sub(1), i] {
                    if ii >= nx {
                        continue;
                    }
                    let j = k / m;
                    if j < ny {
                        raise(ii, j, h);
                    }
                    if k % m == 0 && j >= 1 && j - 1 < ny {
                        raise(ii, j - 1, h);
                    }
                }
            }
        }
        // DEM cell centres: the bilinear surface's peaks.
        for r in 0..raw.height {
            for c in 0..raw.width {
                let h = raw.values[r * raw.width + c];
                if h.is_nan() {
                    continue;
                }
                let (dx, dy) = raw.transform.apply(c as f64 + 0.5, r as f64 + 0.5);
                let Some((x, y)) = (match from_dem {
                    None => Some((dx, dy)),
                    Some(t) => t.convert((dx, dy)).ok(),
                }) else {
                    continue;
                };
                let fi = ((x - self.x0) / g).floor();
                let fj = ((self.y1 - y) / g).floor();
                if fi >= 0.0 && fj >= 0.0 && (fi as usize) < nx && (fj as usize) < ny {
                    raise(fi as usize, fj as usize, h);
                }
            }
        }
        self.grid(v)
    }

    /// The grid as a raster holding `values`.
    fn grid(&self, values: Vec<f64>) -> Dem {
        let (nx, ny, g) = (self.nx, self.ny, self.g);
        Dem {
            width: nx,
            height: ny,
            values,
            nodata: None,
            transform: GeoTransform {
                origin_x: self.x0,
                pixel_width: g,
                row_rotation: 0.0,
                origin_y: self.y1,
                col_rotation: 0.0,
                pixel_height: -g,
            },
            crs: Crs {
                epsg: self.epsg,
                name: self.name.clone(),
                geographic: false,
                // An internal grid: nothing reads its PROJ.4 string.
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }
}

/// Pixel window (col0, row0, col1, row1), end-exclusive, of `dem` covering
/// `extent` (planning CRS) grown by `margin_m`; `None` if it misses the DEM.
fn pixel_window(
    dem: &Dem,
    to_dem: Option<&Proj>,
    extent: Rect<f64>,
    margin_m: f64,
) -> Result<Option<(usize, usize, usize, usize)>, TerrainError> {
    let (min, max) = (extent.min(), extent.max());
    let (x0, y0, x1, y1) = (
        min.x - margin_m,
        min.y - margin_m,
        max.x + margin_m,
        max.y + margin_m,
    );
    // The box's outline, densified: a projected box is curved in a
    // geographic DEM's coordinates.
    const N: usize = 32;
    let mut cmin = f64::INFINITY;
    let mut cmax = f64::NEG_INFINITY;
    let mut rmin = f64::INFINITY;
    let mut rmax = f64::NEG_INFINITY;
    for k in 0..=N {
        let t = k as f64 / N as f64;
        let x = x0 + (x1 - x0) * t;
        let y = y0 + (y1 - y0) * t;
        for p in [(x, y0), (x, y1), (x0, y), (x1, y)] {
            let q = match to_dem {
                None => p,
                Some(tr) => tr.convert(p).map_err(|e| {
                    TerrainError::Crs(format!("transformation to the DEM's CRS: {e}"))
                })?,
            };
            let Some((c, r)) = dem.transform.invert(q.0, q.1) else {
                return Err(TerrainError::Invalid(
                    "the DEM's geotransform is singular".into(),
                ));
            };
            cmin = cmin.min(c);
            cmax = cmax.max(c);
            rmin = rmin.min(r);
            rmax = rmax.max(r);
        }
    }
    if !(cmin.is_finite() && cmax.is_finite() && rmin.is_finite() && rmax.is_finite()) {
        return Ok(None);
    }
    let c0 = (cmin.floor() - 1.0).max(0.0);
    let r0 = (rmin.floor() - 1.0).max(0.0);
    let c1 = (cmax.ceil() + 1.0).min(dem.width as f64);
    let r1 = (rmax.ceil() + 1.0).min(dem.height as f64);
    if c0 >= c1 || r0 >= r1 {
        return Ok(None);
    }
    Ok(Some((c0 as usize, r0 as usize, c1 as usize, r1 as usize)))
}

fn dist(a: Coord<f64>, b: Coord<f64>) -> f64 {
    (b.x - a.x).hypot(b.y - a.y)
}

fn lerp(a: Coord<f64>, b: Coord<f64>, t: f64) -> Coord<f64> {
    Coord {
        x: a.x + (b.x - a.x) * t,
        y: a.y + (b.y - a.y) * t,
    }
}

/// Length of a 3D polyline, metres.
pub fn length_3d(points: &[Point3]) -> f64 {
    points
        .windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            ((b.x - a.x).powi(2) + (b.y - a.y).powi(2) + (b.z - a.z).powi(2)).sqrt()
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::{Crs, DemFormat, GeoTransform};

    /// A projected DEM (EPSG:32631) with 1 m cells whose height is f(x, y)
    /// at cell centres.
    fn dem(w: usize, h: usize, f: impl Fn(f64, f64) -> f64) -> Dem {
        let transform = GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 1.0,
            row_rotation: 0.0,
            origin_y: 5_000_000.0 + h as f64,
            col_rotation: 0.0,
            pixel_height: -1.0,
        };
        let mut values = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let (x, y) = transform.apply(c as f64 + 0.5, r as f64 + 0.5);
                values.push(f(x, y));
            }
        }
        Dem {
            width: w,
            height: h,
            values,
            nodata: None,
            transform,
            crs: Crs {
                epsg: 32631,
                name: "WGS 84 / UTM zone 31N".into(),
                geographic: false,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    fn extent(dem: &Dem) -> Rect<f64> {
        let (x0, y1) = dem.transform.apply(0.0, 0.0);
        let (x1, y0) = dem.transform.apply(dem.width as f64, dem.height as f64);
        Rect::new(Coord { x: x0, y: y0 }, Coord { x: x1, y: y1 })
    }

    fn rule(offset: f64, band: f64) -> HeightRule {
        HeightRule {
            offset_m: offset,
            band_m: band,
            max_climb_per_m: None,
            max_descent_per_m: None,
        }
    }

    fn z_at(wps: &[Point3], s_of: impl Fn(Coord<f64>) -> f64, s: f64) -> f64 {
        for w in wps.windows(2) {
            let (sa, sb) = (s_of(w[0].xy()), s_of(w[1].xy()));
            if s >= sa - 1e-9 && s <= sb + 1e-9 {
                let t = if sb > sa { (s - sa) / (sb - sa) } else { 0.0 };
                return w[0].z + (w[1].z - w[0].z) * t;
            }
        }
        panic!("{s} outside the waypoints");
    }

    #[test]
    fn flat_terrain_needs_only_the_ends() {
        let d = dem(200, 50, |_, _| 120.0);
        let m = TerrainModel::new(&d, 32631, extent(&d), 5.0, 1000.0).unwrap();
        let a = Coord {
            x: 500_010.0,
            y: 5_000_025.0,
        };
        let b = Coord {
            x: 500_190.0,
            y: 5_000_025.0,
        };
        let wps = m.follow(&[a, b], &rule(60.0, 5.0));
        assert_eq!(wps.len(), 2);
        assert!((wps[0].z - 180.0).abs() < 1e-9 && (wps[1].z - 180.0).abs() < 1e-9);
    }

    #[test]
    fn hill_stays_within_band_above_dilated_terrain() {
        // A 40 m Gaussian hill: waypoints must be added over it.
        let hill = |x: f64, y: f64| {
            let (dx, dy) = (x - 500_100.0, y - 5_000_025.0);
            100.0 + 40.0 * (-(dx * dx + dy * dy) / (2.0 * 20.0f64.powi(2))).exp()
        };
        let d = dem(200, 50, hill);
        let m = TerrainModel::new(&d, 32631, extent(&d), 4.0, 1000.0).unwrap();
        let a = Coord {
            x: 500_005.0,
            y: 5_000_025.0,
        };
        let b = Coord {
            x: 500_195.0,
            y: 5_000_025.0,
        };
        let (agl, tol) = (50.0, 3.0);
        let wps = m.follow(&[a, b], &rule(agl, tol));
        assert!(wps.len() > 4, "{} waypoints", wps.len());
        assert_eq!(wps[0].xy(), a);
        assert_eq!(wps.last().unwrap().xy(), b);
        // Checked at 0.1 m (finer than the planner's own samples).
        let mut s = 0.0;
        while s <= 190.0 {
            let p = Coord { x: a.x + s, y: a.y };
            let z = z_at(&wps, |c| c.x - a.x, s);
            let safe = m.safe_terrain(p).unwrap();
            let raw = m.terrain(p).unwrap();
            assert!(
                z - safe >= agl - tol - 1e-6,
                "at {s}: {} above the safe surface",
                z - safe
            );
            assert!(
                z - safe <= agl + tol + 1e-6,
                "at {s}: {} above the safe surface",
                z - safe
            );
            assert!(raw <= safe + 1e-9, "raw above dilated at {s}");
            s += 0.1;
        }
    }

    /// A single tall cell on coarse cells with almost no dilation: the
    /// flight must clear the bilinear surface between its own samples too.
    #[test]
    fn spikes_between_samples_are_cleared() {
        let transform = GeoTransform {
            origin_x: 500_000.0,
            pixel_width: 10.0,
            row_rotation: 0.0,
            origin_y: 5_000_200.0,
            col_rotation: 0.0,
            pixel_height: -10.0,
        };
        let mut d = dem(20, 20, |_, _| 0.0);
        d.transform = transform;
        d.values = vec![100.0; 400];
        d.values[10 * 20 + 10] = 160.0; // centre at (500 105, 5 000 095)
        let (agl, tol) = (30.0, 0.5);
        for offset in [0.0, 1.3, 2.5, 3.7, 5.0] {
            let m = TerrainModel::new(&d, 32631, extent(&d), 0.5, 1000.0).unwrap();
            let y = 5_000_095.0 + offset;
            let a = Coord { x: 500_012.3, y };
            let b = Coord { x: 500_187.7, y };
            let wps = m.follow(&[a, b], &rule(agl, tol));
            let mut s = 0.0;
            while s <= b.x - a.x {
                let p = Coord { x: a.x + s, y };
                let z = z_at(&wps, |c| c.x - a.x, s);
                let raw = m.terrain(p).unwrap();
                assert!(
                    z - raw >= agl - tol - 1e-9,
                    "offset {offset}, at {s}: {} above the DEM",
                    z - raw
                );
                s += 0.05;
            }
        }
    }

    #[test]
    fn rate_limits_hold_and_keep_the_flight_above_the_targets() {
        // A 30 m cliff: with a 0.2 m/m climb limit the climb starts early.
        let d = dem(300, 20, |x, _| if x < 500_150.0 { 100.0 } else { 130.0 });
        let m = TerrainModel::new(&d, 32631, extent(&d), 2.0, 1000.0).unwrap();
        let a = Coord {
            x: 500_005.0,
            y: 5_000_010.0,
        };
        let b = Coord {
            x: 500_295.0,
            y: 5_000_010.0,
        };
        let r = HeightRule {
            offset_m: 40.0,
            band_m: 2.0,
            max_climb_per_m: Some(0.2),
            max_descent_per_m: Some(0.1),
        };
        let wps = m.follow(&[a, b, a], &r);
        for w in wps.windows(2) {
            let ds = dist(w[0].xy(), w[1].xy());
            if ds > 1e-9 {
                let slope = (w[1].z - w[0].z) / ds;
                assert!((-0.1 - 1e-9..=0.2 + 1e-9).contains(&slope), "slope {slope}");
            }
        }
        for &(s, p) in &m.densify(&[a, b]) {
            let z = z_at(
                &wps[..wps.iter().position(|w| w.xy() == b).unwrap() + 1],
                |c| c.x - a.x,
                s,
            );
            assert!(z >= m.safe_terrain(p).unwrap() + 40.0 - 2.0 - 1e-6);
        }
    }

    #[test]
    fn unknown_terrain_is_flown_at_the_highest_known_height() {
        let mut d = dem(100, 10, |x, _| 100.0 + (x - 500_000.0) * 0.1);
        for r in 0..10 {
            for c in 40..60 {
                d.values[r * 100 + c] = f64::NAN;
            }
        }
        let m = TerrainModel::new(&d, 32631, extent(&d), 1.0, 1000.0).unwrap();
        let p = Coord {
            x: 500_050.0,
            y: 5_000_005.0,
        };
        assert!(m.terrain(p).is_none());
        let wps = m.follow(
            &[
                p,
                Coord {
                    x: 500_051.0,
                    y: 5_000_005.0,
                },
            ],
            &rule(10.0, 1.0),
        );
        let highest = m
            .dilated
            .values
            .iter()
            .copied()
            .filter(|v| !v.is_nan())
            .fold(f64::MIN, f64::max);
        assert!((wps[0].z - (highest + 10.0)).abs() < 1e-9);
        let grid: Vec<Coord<f64>> = (0..100)
            .map(|c| Coord {
                x: 500_000.5 + c as f64,
                y: 5_000_005.0,
            })
            .collect();
        assert!((m.known_fraction(&grid) - 0.8).abs() < 1e-9);
    }

    #[test]
    fn extent_outside_the_dem_gives_an_empty_model() {
        let d = dem(10, 10, |_, _| 5.0);
        let far = Rect::new(
            Coord {
                x: 600_000.0,
                y: 5_100_000.0,
            },
            Coord {
                x: 600_100.0,
                y: 5_100_100.0,
            },
        );
        let m = TerrainModel::new(&d, 32631, far, 1.0, 1000.0).unwrap();
        assert!(m.is_empty());
        assert!(
            m.terrain(Coord {
                x: 600_050.0,
                y: 5_100_050.0
            })
            .is_none()
        );
    }
}
