//! Heights at points: bilinear interpolation between cell centres
//! ([`bilinear`], behind [`Dem::sample`]) and [`TerrainSampler`], which
//! transforms points from another CRS into the DEM's before sampling.

use geo_types::Coord;
use proj::Proj;

use super::{Dem, TerrainError};

/// Fractional pixel positions this close to a cell centre (or to the
/// raster's outer edge) are snapped onto it, so that a point computed as
/// a cell centre through `GeoTransform::apply` and back is that cell's
/// value exactly and never needs its (possibly nodata) neighbour.
const SNAP_PX: f64 = 1e-9;

/// Samples a DEM at points given in another CRS (e.g. the survey's UTM
/// zone). Cheap per call: one PROJ transformation (none when the CRSs are
/// equal) and four cell reads, no allocation.
///
/// Holds a PROJ object, so it is neither `Send` nor `Sync`: build one per
/// thread.
pub struct TerrainSampler<'a> {
    pub dem: &'a Dem,
    /// Source CRS → the DEM's CRS (lon/lat, easting/northing axis order);
    /// `None` when they are the same CRS.
    transform: Option<Proj>,
    from_epsg: u32,
}

impl std::fmt::Debug for TerrainSampler<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TerrainSampler(EPSG:{} → EPSG:{}, {}×{})",
            self.from_epsg, self.dem.crs.epsg, self.dem.width, self.dem.height
        )
    }
}

impl<'a> TerrainSampler<'a> {
    /// Points will be given in `EPSG:from_epsg` (for a geographic CRS as
    /// lon/lat, for a projected one as easting/northing, whatever the
    /// CRS's official axis order).
    pub fn new(dem: &'a Dem, from_epsg: u32) -> Result<Self, TerrainError> {
        let transform = if from_epsg == dem.crs.epsg {
            None
        } else {
            let from = format!("EPSG:{from_epsg}");
            let to = dem.crs.proj_id();
            Some(Proj::new_known_crs(&from, &to, None).map_err(|e| {
                TerrainError::Crs(format!(
                    "no transformation from {from} to the DEM's CRS {to}: {e}"
                ))
            })?)
        };
        Ok(TerrainSampler {
            dem,
            transform,
            from_epsg,
        })
    }

    /// Points will be given as WGS84 lon/lat degrees (`EPSG:4326`).
    pub fn wgs84(dem: &'a Dem) -> Result<Self, TerrainError> {
        Self::new(dem, 4326)
    }

    /// The EPSG code of the CRS points are given in.
    pub fn from_epsg(&self) -> u32 {
        self.from_epsg
    }

    /// `p` (in the sampler's source CRS) in the DEM's CRS; `None` when the
    /// transformation fails (e.g. outside the projection's domain).
    pub fn to_dem(&self, p: Coord<f64>) -> Option<(f64, f64)> {
        let (x, y) = match &self.transform {
            None => (p.x, p.y),
            Some(t) => t.convert((p.x, p.y)).ok()?,
        };
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }

    /// Bilinear height at `p` (in the sampler's source CRS); `None` on
    /// nodata or outside (see [`Dem::sample`]).
    pub fn height(&self, p: Coord<f64>) -> Option<f64> {
        let (x, y) = self.to_dem(p)?;
        bilinear(self.dem, x, y)
    }

    /// The DEM's cell size in metres [x, y] (see [`Dem::resolution_m`]).
    pub fn resolution_m(&self) -> [f64; 2] {
        self.dem.resolution_m()
    }
}

/// Bilinear height at DEM-CRS coordinates; see [`Dem::sample`].
///
/// Pixel (c, r)'s value sits at pixel position (c + 0.5, r + 0.5). Points
/// in the half-cell border between the outer edge and the outermost
/// centres take the edge row/column's values (no extrapolation); points
/// beyond the outer edge are `None`. Only the cells with a nonzero weight
/// are read, so a point on a cell centre next to nodata is valid.
pub(super) fn bilinear(dem: &Dem, x: f64, y: f64) -> Option<f64> {
    let (w, h) = (dem.width, dem.height);
    if w == 0 || h == 0 || dem.values.len() < w * h {
        return None;
    }
    let (col, row) = dem.transform.invert(x, y)?;
    // Written so that NaN fails the test.
    if !(col >= -SNAP_PX
        && col <= w as f64 + SNAP_PX
        && row >= -SNAP_PX
        && row <= h as f64 + SNAP_PX)
    {
        return None;
    }
    let (c0, tx) = axis(col - 0.5, w);
    let (r0, ty) = axis(row - 0.5, h);
    let v = |c: usize, r: usize| -> Option<f64> {
        let v = dem.values[r * w + c];
        (!v.is_nan()).then_some(v)
    };
    let v00 = v(c0, r0)?;
    if tx == 0.0 && ty == 0.0 {
        return Some(v00);
    }
    if ty == 0.0 {
        let v10 = v(c0 + 1, r0)?;
        return Some(v00 * (1.0 - tx) + v10 * tx);
    }
    if tx == 0.0 {
        let v01 = v(c0, r0 + 1)?;
        return Some(v00 * (1.0 - ty) + v01 * ty);
    }
    let v10 = v(c0 + 1, r0)?;
    let v01 = v(c0, r0 + 1)?;
    let v11 = v(c0 + 1, r0 + 1)?;
    let top = v00 * (1.0 - tx) + v10 * tx;
    let bottom = v01 * (1.0 - tx) + v11 * tx;
    Some(top * (1.0 - ty) + bottom * ty)
}

/// Index of the lower cell centre and the weight of the next one along one
/// axis, for fractional centre coordinate `f` (cell centres at integers)
/// and `n` ≥ 1 cells: clamped to [0, n − 1]; the weight is 0 when no next
/// cell is needed.
#[inline]
fn axis(f: f64, n: usize) -> (usize, f64) {
    let last = (n - 1) as f64;
    if f <= 0.0 {
        return (0, 0.0);
    }
    if f >= last {
        return (n - 1, 0.0);
    }
    let i = f.floor();
    let t = f - i;
    let i = i as usize;
    if t < SNAP_PX {
        (i, 0.0)
    } else if t > 1.0 - SNAP_PX {
        (i + 1, 0.0)
    } else {
        (i, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::terrain::{Crs, DemFormat, GeoTransform};

    const NAN: f64 = f64::NAN;

    /// A north-up `w`×`h` DEM with `cell`-metre cells whose top-left corner
    /// is at (x0, y0), in EPSG:`epsg`.
    fn dem(w: usize, h: usize, values: Vec<f64>, x0: f64, y0: f64, cell: f64, epsg: u32) -> Dem {
        assert_eq!(values.len(), w * h);
        Dem {
            width: w,
            height: h,
            values,
            nodata: None,
            transform: GeoTransform {
                origin_x: x0,
                pixel_width: cell,
                row_rotation: 0.0,
                origin_y: y0,
                col_rotation: 0.0,
                pixel_height: -cell,
            },
            crs: Crs {
                epsg,
                name: String::new(),
                geographic: epsg == 4326,
                proj4: String::new(),
            },
            format: DemFormat::GeoTiff,
        }
    }

    /// 3×3 DEM, cells of 10 m, corner at (1000, 2000); values 0..9.
    fn grid3() -> Dem {
        dem(
            3,
            3,
            (0..9).map(f64::from).collect(),
            1000.0,
            2000.0,
            10.0,
            32633,
        )
    }

    /// Centre of pixel (c, r).
    fn centre(d: &Dem, c: f64, r: f64) -> (f64, f64) {
        d.transform.apply(c + 0.5, r + 0.5)
    }

    #[test]
    fn exact_on_centres() {
        let d = grid3();
        for r in 0..3 {
            for c in 0..3 {
                let (x, y) = centre(&d, c as f64, r as f64);
                assert_eq!(bilinear(&d, x, y), Some((r * 3 + c) as f64));
            }
        }
    }

    #[test]
    fn interpolates_between_centres() {
        let d = grid3();
        // Halfway between (0,0)=0 and (1,0)=1.
        let (x, y) = centre(&d, 0.5, 0.0);
        assert!((bilinear(&d, x, y).unwrap() - 0.5).abs() < 1e-12);
        // Middle of the four centres 0, 1, 3, 4.
        let (x, y) = centre(&d, 0.5, 0.5);
        assert!((bilinear(&d, x, y).unwrap() - 2.0).abs() < 1e-12);
        // The values form the plane v = c + 3r, reproduced exactly by
        // bilinear interpolation anywhere between the centres.
        for (c, r) in [(0.25, 1.75), (1.9, 0.1), (1.3, 1.6)] {
            let (x, y) = centre(&d, c, r);
            assert!((bilinear(&d, x, y).unwrap() - (c + 3.0 * r)).abs() < 1e-9);
        }
    }

    #[test]
    fn half_cell_border_clamps_and_outside_is_none() {
        let d = grid3();
        // Left border, level with the middle of row 1: column 0's value.
        let (x, y) = d.transform.apply(0.2, 1.5);
        assert!((bilinear(&d, x, y).unwrap() - 3.0).abs() < 1e-12);
        // Top-left corner of the raster exactly: pixel (0, 0).
        assert_eq!(bilinear(&d, 1000.0, 2000.0), Some(0.0));
        // Bottom-right outer corner: pixel (2, 2).
        assert_eq!(bilinear(&d, 1030.0, 1970.0), Some(8.0));
        // Bottom border between columns 0 and 1: 6.5.
        let (x, y) = d.transform.apply(1.0, 2.9);
        assert!((bilinear(&d, x, y).unwrap() - 6.5).abs() < 1e-12);
        // Just outside each edge.
        assert_eq!(bilinear(&d, 999.9, 1985.0), None);
        assert_eq!(bilinear(&d, 1030.1, 1985.0), None);
        assert_eq!(bilinear(&d, 1015.0, 2000.1), None);
        assert_eq!(bilinear(&d, 1015.0, 1969.9), None);
        assert_eq!(bilinear(&d, f64::NAN, 1985.0), None);
        assert_eq!(bilinear(&d, 1015.0, f64::INFINITY), None);
    }

    #[test]
    fn nodata_only_where_it_has_weight() {
        // 0 1 2
        // 3 N 5
        // 6 7 8
        let mut d = grid3();
        d.values[4] = NAN;
        // On the centres next to the hole: valid.
        for (c, r, v) in [
            (1.0, 0.0, 1.0),
            (0.0, 1.0, 3.0),
            (2.0, 1.0, 5.0),
            (1.0, 2.0, 7.0),
        ] {
            let (x, y) = centre(&d, c, r);
            assert_eq!(bilinear(&d, x, y), Some(v), "centre ({c}, {r})");
        }
        // Along the top row between centres (0,0) and (1,0): the hole has
        // zero weight.
        let (x, y) = centre(&d, 0.5, 0.0);
        assert!((bilinear(&d, x, y).unwrap() - 0.5).abs() < 1e-12);
        // Anywhere the hole has weight: None.
        for (c, r) in [(0.5, 0.5), (1.0, 0.5), (1.5, 1.5), (1.0, 1.0), (0.5, 1.0)] {
            let (x, y) = centre(&d, c, r);
            assert_eq!(bilinear(&d, x, y), None, "({c}, {r})");
        }
        // Half-cell border beside a nodata edge cell.
        let mut d = grid3();
        d.values[3] = NAN;
        let (x, y) = d.transform.apply(0.1, 1.5);
        assert_eq!(bilinear(&d, x, y), None);
        let (x, y) = d.transform.apply(0.1, 0.5);
        assert_eq!(bilinear(&d, x, y), Some(0.0));
    }

    #[test]
    fn single_cell_and_empty() {
        let d = dem(1, 1, vec![42.0], 0.0, 10.0, 10.0, 32633);
        assert_eq!(bilinear(&d, 5.0, 5.0), Some(42.0));
        assert_eq!(bilinear(&d, 0.0, 0.0), Some(42.0));
        assert_eq!(bilinear(&d, 10.5, 5.0), None);
        let d = dem(0, 0, vec![], 0.0, 10.0, 10.0, 32633);
        assert_eq!(bilinear(&d, 5.0, 5.0), None);
    }

    #[test]
    fn south_up_and_rotated_transforms() {
        // South-up (pixel_height > 0): row 0 is the southern row.
        let mut d = grid3();
        d.transform.origin_y = 1970.0;
        d.transform.pixel_height = 10.0;
        assert_eq!(bilinear(&d, 1005.0, 1975.0), Some(0.0));
        assert_eq!(bilinear(&d, 1005.0, 1995.0), Some(6.0));
        // Rotated 90°: columns run north, rows run east.
        let mut d = grid3();
        d.transform = GeoTransform {
            origin_x: 0.0,
            pixel_width: 0.0,
            row_rotation: 10.0,
            origin_y: 0.0,
            col_rotation: 10.0,
            pixel_height: 0.0,
        };
        // Pixel (c=1, r=2) centre: x = 2.5·10, y = 1.5·10.
        assert_eq!(bilinear(&d, 25.0, 15.0), Some(7.0));
    }

    #[test]
    fn sampler_same_crs_is_plain_bilinear() {
        let d = grid3();
        let s = TerrainSampler::new(&d, 32633).unwrap();
        let (x, y) = centre(&d, 1.25, 0.5);
        assert_eq!(s.to_dem(Coord { x, y }), Some((x, y)));
        assert_eq!(s.height(Coord { x, y }), bilinear(&d, x, y));
        assert_eq!(s.height(Coord { x: 0.0, y: 0.0 }), None);
    }

    #[test]
    fn sampler_transforms_lonlat_into_utm() {
        // A plane z = 0.01·E − 0.02·N + c over a 100 m-cell UTM 33N DEM near
        // 15°E 45°N, sampled from lon/lat.
        let to_utm = Proj::new_known_crs("EPSG:4326", "EPSG:32633", None).unwrap();
        let (e0, n0): (f64, f64) = to_utm.convert((15.0, 45.0)).unwrap();
        let (x0, y0) = (
            (e0 / 100.0).floor() * 100.0 - 5000.0,
            (n0 / 100.0).floor() * 100.0 + 5000.0,
        );
        let (w, h) = (100, 100);
        let plane = |e: f64, n: f64| 0.01 * (e - x0) - 0.02 * (n - y0) + 500.0;
        let mut values = Vec::with_capacity(w * h);
        for r in 0..h {
            for c in 0..w {
                let (e, n) = (x0 + (c as f64 + 0.5) * 100.0, y0 - (r as f64 + 0.5) * 100.0);
                values.push(plane(e, n));
            }
        }
        let d = dem(w, h, values, x0, y0, 100.0, 32633);
        let s = TerrainSampler::wgs84(&d).unwrap();
        assert_eq!(s.from_epsg(), 4326);
        for (lon, lat) in [(15.0, 45.0), (15.01, 45.02), (14.97, 44.99)] {
            let (e, n): (f64, f64) = to_utm.convert((lon, lat)).unwrap();
            let (x, y) = s.to_dem(Coord { x: lon, y: lat }).unwrap();
            assert!((x - e).abs() < 1e-6 && (y - n).abs() < 1e-6);
            let z = s.height(Coord { x: lon, y: lat }).unwrap();
            // Planes are reproduced exactly by bilinear interpolation.
            assert!((z - plane(e, n)).abs() < 1e-6, "{z} vs {}", plane(e, n));
        }
        // Far away: outside the raster.
        assert_eq!(s.height(Coord { x: 16.0, y: 45.0 }), None);
    }

    #[test]
    fn sampler_into_geographic_dem() {
        // A lon/lat DEM (0.001° cells) sampled from UTM 33N.
        let d = dem(200, 200, vec![7.0; 40_000], 14.9, 45.1, 0.001, 4326);
        let s = TerrainSampler::new(&d, 32633).unwrap();
        let to_utm = Proj::new_known_crs("EPSG:4326", "EPSG:32633", None).unwrap();
        let (e, n): (f64, f64) = to_utm.convert((15.0, 45.0)).unwrap();
        let (lon, lat) = s.to_dem(Coord { x: e, y: n }).unwrap();
        assert!((lon - 15.0).abs() < 1e-9 && (lat - 45.0).abs() < 1e-9);
        assert_eq!(s.height(Coord { x: e, y: n }), Some(7.0));
    }

    #[test]
    fn sampler_unknown_crs_is_an_error() {
        let d = grid3();
        assert!(matches!(
            TerrainSampler::new(&d, 999_999),
            Err(TerrainError::Crs(_))
        ));
    }
}
