//! GeoPackage geometry blobs (GeoPackage 1.3 §2.1.3: the `GP` header,
//! an optional envelope, then ISO WKB) read into geo-types; the SQLite
//! side of GeoPackages is the server's.

use geo_types::{
    Coord, Geometry, LineString, MultiLineString, MultiPoint, MultiPolygon, Point, Polygon,
};

/// The geometry of one GeoPackage blob; `None` for an empty geometry.
pub fn read_gpkg_geometry(blob: &[u8]) -> Result<Option<Geometry<f64>>, String> {
    if blob.len() < 8 || &blob[..2] != b"GP" {
        return Err("not a GeoPackage geometry blob (no \"GP\" header)".into());
    }
    let flags = blob[3];
    if flags & 0b0010_0000 != 0 {
        return Err("an extended GeoPackage geometry, which is not read".into());
    }
    let envelope = match (flags >> 1) & 0b111 {
        0 => 0,
        1 => 32,
        2 | 3 => 48,
        4 => 64,
        e => return Err(format!("envelope indicator {e} is invalid")),
    };
    if flags & 0b0001_0000 != 0 {
        return Ok(None);
    }
    let start = 8 + envelope;
    let wkb = blob.get(start..).ok_or("the blob ends inside its header")?;
    let mut r = Wkb { buf: wkb, at: 0 };
    r.geometry(0).map(Some)
}

/// Most nesting of collections followed (a blob is untrusted).
const MAX_DEPTH: usize = 8;

struct Wkb<'a> {
    buf: &'a [u8],
    at: usize,
}

impl Wkb<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let bytes = self
            .buf
            .get(self.at..self.at + N)
            .ok_or_else(|| format!("the WKB ends at byte {} (cut short?)", self.buf.len()))?;
        self.at += N;
        Ok(bytes.try_into().expect("N bytes"))
    }

    fn u32(&mut self, little: bool) -> Result<u32, String> {
        let b = self.take::<4>()?;
        Ok(if little {
            u32::from_le_bytes(b)
        } else {
            u32::from_be_bytes(b)
        })
    }

    fn f64(&mut self, little: bool) -> Result<f64, String> {
        let b = self.take::<8>()?;
        Ok(if little {
            f64::from_le_bytes(b)
        } else {
            f64::from_be_bytes(b)
        })
    }

    /// A count of items at least `min_bytes` each: bounded by the bytes
    /// left, so a forged count cannot reserve memory.
    fn count(&mut self, little: bool, min_bytes: usize) -> Result<usize, String> {
        let n = self.u32(little)? as usize;
        if n.saturating_mul(min_bytes) > self.buf.len() - self.at {
            return Err(format!("a count of {n} items is more than the blob holds"));
        }
        Ok(n)
    }

    fn coords(&mut self, little: bool, dims: usize) -> Result<LineString<f64>, String> {
        let n = self.count(little, 8 * dims)?;
        let mut line = Vec::with_capacity(n);
        for _ in 0..n {
            line.push(self.coord(little, dims)?);
        }
        Ok(LineString(line))
    }

    fn coord(&mut self, little: bool, dims: usize) -> Result<Coord<f64>, String> {
        let x = self.f64(little)?;
        let y = self.f64(little)?;
        for _ in 2..dims {
            self.f64(little)?;
        }
        Ok(Coord { x, y })
    }

    fn polygon(&mut self, little: bool, dims: usize) -> Result<Polygon<f64>, String> {
        let n = self.count(little, 4)?;
        let mut rings = Vec::with_capacity(n);
        for _ in 0..n {
            rings.push(self.coords(little, dims)?);
        }
        let mut rings = rings.into_iter();
        let outer = rings.next().unwrap_or_else(|| LineString(Vec::new()));
        Ok(Polygon::new(outer, rings.collect()))
    }

    /// The members of a Multi* geometry: each a whole WKB geometry.
    fn members(&mut self, little: bool, depth: usize) -> Result<Vec<Geometry<f64>>, String> {
        let n = self.count(little, 9)?;
        (0..n).map(|_| self.geometry(depth + 1)).collect()
    }

    fn geometry(&mut self, depth: usize) -> Result<Geometry<f64>, String> {
        if depth > MAX_DEPTH {
            return Err("geometries nested too deep".into());
        }
        let little = match self.take::<1>()?[0] {
            0 => false,
            1 => true,
            b => return Err(format!("byte order {b} is neither 0 nor 1")),
        };
        let raw = self.u32(little)?;
        // EWKB flags Z, M and SRID in the high bits (PostGIS's), else ISO
        // WKB: 1000s for Z, 2000s for M, 3000s for ZM.
        let flags = raw & 0xE000_0000;
        let code = raw & !0xE000_0000;
        if flags & 0x2000_0000 != 0 {
            self.u32(little)?;
        }
        let extra = (flags & 0x8000_0000 != 0) as usize + (flags & 0x4000_0000 != 0) as usize;
        let dims = extra
            + match code / 1000 {
                0 => 2,
                1 | 2 => 3,
                3 => 4,
                _ => return Err(format!("WKB geometry type {raw} is not known")),
            };
        let kind = code % 1000;
        let wrong = |what: &str| format!("a {what} holds another geometry type");
        Ok(match kind {
            1 => Point(self.coord(little, dims)?).into(),
            2 => self.coords(little, dims)?.into(),
            3 => self.polygon(little, dims)?.into(),
            4 => MultiPoint(
                self.members(little, depth)?
                    .into_iter()
                    .map(|g| Point::try_from(g).map_err(|_| wrong("MultiPoint")))
                    .collect::<Result<_, _>>()?,
            )
            .into(),
            5 => MultiLineString(
                self.members(little, depth)?
                    .into_iter()
                    .map(|g| LineString::try_from(g).map_err(|_| wrong("MultiLineString")))
                    .collect::<Result<_, _>>()?,
            )
            .into(),
            6 => MultiPolygon(
                self.members(little, depth)?
                    .into_iter()
                    .map(|g| Polygon::try_from(g).map_err(|_| wrong("MultiPolygon")))
                    .collect::<Result<_, _>>()?,
            )
            .into(),
            7 => Geometry::GeometryCollection(geo_types::GeometryCollection(
                self.members(little, depth)?,
            )),
            other => return Err(format!("WKB geometry type {other} is not read")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A GeoPackage blob (little-endian, no envelope) of a WKB polygon.
    pub(crate) fn square_blob() -> Vec<u8> {
        let mut b = b"GP\x00\x01".to_vec();
        b.extend(28992i32.to_le_bytes());
        b.push(1);
        b.extend(3u32.to_le_bytes());
        b.extend(1u32.to_le_bytes());
        b.extend(4u32.to_le_bytes());
        for (x, y) in [(0.0f64, 0.0f64), (10.0, 0.0), (10.0, 10.0), (0.0, 0.0)] {
            b.extend(x.to_le_bytes());
            b.extend(y.to_le_bytes());
        }
        b
    }

    #[test]
    fn reads_a_polygon_blob_and_refuses_damage() {
        let blob = square_blob();
        let Some(Geometry::Polygon(p)) = read_gpkg_geometry(&blob).unwrap() else {
            panic!("a polygon");
        };
        assert_eq!(p.exterior().0[1], Coord { x: 10.0, y: 0.0 });
        for cut in 0..blob.len() {
            assert!(read_gpkg_geometry(&blob[..cut]).is_err(), "cut {cut}");
        }
        // A forged ring count is refused, not allocated.
        let mut forged = blob.clone();
        forged[17..21].copy_from_slice(&u32::MAX.to_le_bytes());
        let e = read_gpkg_geometry(&forged).unwrap_err();
        assert!(e.contains("more than the blob holds"), "{e}");
        let mut rng = crate::test_rng::Lcg(5);
        for _ in 0..500 {
            let mut b = blob.clone();
            let at = (rng.next() * b.len() as f64) as usize;
            b[at] = (rng.next() * 256.0) as u8;
            let _ = read_gpkg_geometry(&b);
        }
    }
}
