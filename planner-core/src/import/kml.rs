//! KML and KMZ: Placemarks (in any Folder or Document) with Polygons
//! (outer and inner boundaries) and LineStrings, in WGS84 as KML always is.

use geo_types::{Coord, Geometry, LineString, MultiLineString, MultiPolygon, Polygon};
use quick_xml::Reader;
use quick_xml::events::Event;
use serde_json::{Map, Value};

use super::{ImportError, Imported, open_zip, read_bounded};

/// The KML inside the KMZ (zip) `bytes`: `doc.kml`, else its first `.kml`.
pub(super) fn read_kmz(bytes: &[u8]) -> Result<Imported, ImportError> {
    let (mut archive, names) = open_zip(bytes, "KMZ (zip) file")?;
    let mut kmls: Vec<String> = names
        .into_iter()
        .filter(|n| n.to_ascii_lowercase().ends_with(".kml"))
        .collect();
    kmls.sort_by_key(|n| (n != "doc.kml", n.matches('/').count(), n.clone()));
    let Some(name) = kmls.first() else {
        return Err(ImportError::Malformed("the KMZ holds no .kml file".into()));
    };
    let file = archive
        .by_name(name)
        .map_err(|e| ImportError::Malformed(format!("cannot read {name} in the KMZ: {e}")))?;
    read_kml(&read_bounded(file, name)?)
}

/// What one Placemark holds so far.
#[derive(Default)]
struct Placemark {
    name: Option<String>,
    polygons: Vec<Polygon<f64>>,
    lines: Vec<LineString<f64>>,
    points: usize,
    /// Rings of the Polygon being read: the outer first.
    outer: Option<LineString<f64>>,
    inners: Vec<LineString<f64>>,
}

/// The Placemarks of the KML document `bytes`.
pub(super) fn read_kml(bytes: &[u8]) -> Result<Imported, ImportError> {
    let mut reader = Reader::from_reader(bytes);
    let mut buf = Vec::new();
    let mut stack: Vec<String> = Vec::new();
    let mut text = String::new();
    let mut placemark: Option<Placemark> = None;
    // Placemarks are numbered from 1 in messages, as a reader counts them.
    let mut number = 1usize;
    let mut seen_kml = false;
    let mut out = Imported::default();
    let fault = |reader: &Reader<&[u8]>, m: String| {
        ImportError::Malformed(format!(
            "not a readable KML document (at byte {}): {m}",
            reader.buffer_position()
        ))
    };
    loop {
        let event = reader
            .read_event_into(&mut buf)
            .map_err(|e| fault(&reader, e.to_string()))?;
        match event {
            Event::Start(e) => {
                let name = e.local_name().as_ref().to_string();
                seen_kml |= stack.is_empty() && name == "kml";
                if name == "Placemark" {
                    placemark = Some(Placemark::default());
                }
                text.clear();
                stack.push(name);
            }
            Event::Text(t) => text.push_str(&t.xml_content(quick_xml::XmlVersion::Implicit1_0)),
            Event::CData(t) => text.push_str(&t),
            Event::GeneralRef(r) => {
                // The five predefined entities; others (and character
                // references) do not occur in coordinates.
                let s = match r.as_ref() {
                    "amp" => "&",
                    "lt" => "<",
                    "gt" => ">",
                    "quot" => "\"",
                    "apos" => "'",
                    _ => "",
                };
                text.push_str(s);
            }
            Event::End(_) => {
                let Some(name) = stack.pop() else {
                    return Err(fault(&reader, "an end tag without its start".into()));
                };
                if let Some(pm) = placemark.as_mut() {
                    end_in_placemark(pm, &name, &stack, &text)
                        .map_err(|m| fault(&reader, format!("Placemark {number}: {m}")))?;
                }
                if name == "Placemark"
                    && let Some(pm) = placemark.take()
                {
                    finish(pm, number, &mut out);
                    number += 1;
                }
                text.clear();
            }
            Event::Empty(e) if e.local_name().as_ref() == "Point" => {
                if let Some(pm) = placemark.as_mut() {
                    pm.points += 1;
                }
            }
            Event::Eof => break,
            _ => {}
        }
        buf.clear();
    }
    if let Some(open) = stack.last() {
        return Err(fault(
            &reader,
            format!("the document ends inside <{open}> (cut short?)"),
        ));
    }
    if !seen_kml {
        return Err(fault(&reader, "no <kml> root element".into()));
    }
    Ok(out)
}

/// Handle the end of element `name` (inside `stack`) in a Placemark.
fn end_in_placemark(
    pm: &mut Placemark,
    name: &str,
    stack: &[String],
    text: &str,
) -> Result<(), String> {
    let parent = stack.last().map(String::as_str);
    match name {
        "name" if parent == Some("Placemark") => pm.name = Some(text.trim().to_string()),
        "coordinates" => {
            let line = parse_coordinates(text)?;
            let in_polygon = stack.iter().any(|s| s == "Polygon");
            if in_polygon {
                if stack.iter().any(|s| s == "innerBoundaryIs") {
                    pm.inners.push(line);
                } else {
                    pm.outer = Some(line);
                }
            } else if parent == Some("LineString") || parent == Some("LinearRing") {
                pm.lines.push(line);
            }
        }
        "Polygon" => match pm.outer.take() {
            Some(outer) => pm
                .polygons
                .push(Polygon::new(outer, std::mem::take(&mut pm.inners))),
            None => return Err("a Polygon without an outerBoundaryIs".into()),
        },
        "Point" => pm.points += 1,
        _ => {}
    }
    Ok(())
}

/// KML `lon,lat[,alt]` tuples separated by whitespace.
fn parse_coordinates(text: &str) -> Result<LineString<f64>, String> {
    text.split_whitespace()
        .map(|tuple| {
            let mut parts = tuple.split(',').map(|s| s.trim().parse::<f64>());
            match (parts.next(), parts.next()) {
                (Some(Ok(x)), Some(Ok(y)))
                    if x.is_finite()
                        && y.is_finite()
                        && (-180.0..=180.0).contains(&x)
                        && (-90.0..=90.0).contains(&y) =>
                {
                    Ok(Coord { x, y })
                }
                _ => Err(format!(
                    "coordinates {tuple:?} are not lon,lat[,alt] in degrees"
                )),
            }
        })
        .collect::<Result<Vec<_>, _>>()
        .map(LineString)
}

/// The features of one finished Placemark: its polygons as one feature,
/// its lines as another.
fn finish(pm: Placemark, number: usize, out: &mut Imported) {
    let label = match &pm.name {
        Some(n) => format!("Placemark {number} ({n:?})"),
        None => format!("Placemark {number}"),
    };
    let mut properties = Map::new();
    if let Some(n) = &pm.name {
        properties.insert("name".into(), Value::from(n.as_str()));
    }
    if pm.points > 0 {
        out.messages.push(format!(
            "{label}: {} Point(s) skipped: points are not imported (only polygons and lines)",
            pm.points
        ));
    }
    let mut polygons = pm.polygons;
    if polygons.len() == 1 {
        out.push(&label, polygons.remove(0).into(), properties.clone());
    } else if !polygons.is_empty() {
        out.push(
            &label,
            Geometry::MultiPolygon(MultiPolygon(polygons)),
            properties.clone(),
        );
    }
    let mut lines = pm.lines;
    if lines.len() == 1 {
        out.push(&label, lines.remove(0).into(), properties);
    } else if !lines.is_empty() {
        out.push(
            &label,
            Geometry::MultiLineString(MultiLineString(lines)),
            properties,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) const KML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<kml xmlns="http://www.opengis.net/kml/2.2"><Document><Folder><name>areas</name>
  <Placemark><name>field &amp; wood</name>
    <Polygon><outerBoundaryIs><LinearRing><coordinates>
      5.0,52.0,0 5.01,52.0,0 5.01,52.01,0 5.0,52.01,0 5.0,52.0,0
    </coordinates></LinearRing></outerBoundaryIs>
    <innerBoundaryIs><LinearRing><coordinates>5.004,52.004 5.006,52.004 5.006,52.006 5.004,52.004</coordinates></LinearRing></innerBoundaryIs>
    </Polygon></Placemark>
  <Folder><Placemark><name>pipe</name><LineString><coordinates>5.0,52.0 5.02,52.03</coordinates></LineString></Placemark></Folder>
  <Placemark><name>mast</name><Point><coordinates>5.0,52.0</coordinates></Point></Placemark>
</Folder></Document></kml>"#;

    #[test]
    fn polygons_with_holes_and_lines_in_folders() {
        let imp = read_kml(KML.as_bytes()).unwrap();
        assert_eq!(imp.features.len(), 2, "{:?}", imp.messages);
        let Geometry::Polygon(p) = &imp.features[0].geometry else {
            panic!("the first Placemark is a Polygon");
        };
        assert_eq!(p.exterior().0.len(), 5);
        assert_eq!(p.interiors().len(), 1);
        assert_eq!(
            p.interiors()[0].0[1],
            Coord {
                x: 5.006,
                y: 52.004
            }
        );
        assert_eq!(imp.features[0].properties["name"], "field & wood");
        assert!(matches!(imp.features[1].geometry, Geometry::LineString(_)));
        assert_eq!(imp.messages.len(), 1);
        assert!(imp.messages[0].contains("Placemark 3 (\"mast\"): 1 Point(s) skipped"));
    }

    #[test]
    fn bad_coordinates_and_truncations_are_named() {
        let bad = KML.replace("5.02,52.03", "5.02;52.03");
        let e = read_kml(bad.as_bytes()).unwrap_err();
        assert!(
            e.to_string()
                .contains("Placemark 2: coordinates \"5.02;52.03\" are not lon,lat"),
            "{e}"
        );
        for cut in 0..KML.len() - 1 {
            assert!(read_kml(&KML.as_bytes()[..cut]).is_err(), "cut {cut}");
        }
        let e = read_kml(b"plain text").unwrap_err();
        assert!(e.to_string().contains("no <kml> root element"), "{e}");
    }

    #[test]
    fn kmz_reads_its_doc_kml() {
        use std::io::Write;
        let mut buf = std::io::Cursor::new(Vec::new());
        let mut w = zip::ZipWriter::new(&mut buf);
        let opts = zip::write::SimpleFileOptions::default();
        w.start_file("files/other.txt", opts).unwrap();
        w.write_all(b"x").unwrap();
        w.start_file("doc.kml", opts).unwrap();
        w.write_all(KML.as_bytes()).unwrap();
        w.finish().unwrap();
        let kmz = buf.into_inner();
        assert_eq!(read_kmz(&kmz).unwrap(), read_kml(KML.as_bytes()).unwrap());
        for cut in (0..kmz.len()).step_by(13) {
            assert!(read_kmz(&kmz[..cut]).is_err(), "cut {cut}");
        }
    }
}
