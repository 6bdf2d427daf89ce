//! GIS imports end to end (issue 23 item 3): `terraplan import` and
//! `terraplan survey --roi/--no-fly/--corridor` on files written here by
//! GDAL's `ogr2ogr` (gdal-bin, installed by scripts/setup.sh) in a projected
//! CRS (EPSG:28992, Amersfoort / RD New) and on the real earthpy RMNP
//! Shapefile of `../shared/data/polygons`, each checked against the GeoJSON
//! it was made from by tests/validators/check_import.py (shapely, pyproj):
//! area within 1e-6 relative, at most 5 mm apart.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::{Value, json};
use terraplan_e2e::{
    Part, Server, assert_invalid_at, post_multipart, shared_data, terraplan, text, validator,
    write_json,
};

/// `ogr2ogr args…`, which must succeed.
fn ogr2ogr(args: &[&str]) {
    let o = Command::new("ogr2ogr")
        .args(args)
        .output()
        .expect("run ogr2ogr");
    assert!(o.status.success(), "ogr2ogr {args:?}: {}", text(&o.stderr));
}

/// A zip at `zip` of the files `members` in `dir` (Python's zipfile).
fn zip_files(dir: &Path, members: &[&str], zip: &Path) {
    let script = "import sys, zipfile, os\nz = zipfile.ZipFile(sys.argv[1], 'w', zipfile.ZIP_DEFLATED)\nfor m in sys.argv[3:]:\n    z.write(os.path.join(sys.argv[2], m), m)\nz.close()";
    let o = Command::new("python3")
        .args(["-c", script, zip.to_str().unwrap(), dir.to_str().unwrap()])
        .args(members)
        .output()
        .expect("run python3");
    assert!(o.status.success(), "zip: {}", text(&o.stderr));
}

/// `terraplan import file`, which must succeed; its output is written to
/// `out` and returned.
fn import(file: &Path, out: &Path) -> Value {
    let o = terraplan(&["import", file.to_str().unwrap()]);
    assert!(
        o.status.success(),
        "terraplan import {}: {}",
        file.display(),
        text(&o.stderr)
    );
    std::fs::write(out, &o.stdout).unwrap();
    serde_json::from_slice(&o.stdout).unwrap()
}

/// check_import.py of `imported` against `twin`; asserts it passes.
fn check(imported: &Path, twin: &Path, kind: &str) -> Value {
    let v = validator("check_import.py", &[imported, twin, Path::new(kind)]);
    assert!(
        v.status.success(),
        "check_import.py {} vs {}: {}{}",
        imported.display(),
        twin.display(),
        text(&v.stdout),
        text(&v.stderr)
    );
    serde_json::from_slice(&v.stdout).unwrap()
}

fn field() -> PathBuf {
    shared_data("polygons/fields2cover__test.json")
}

#[test]
fn rmnp_shapefile_matches_its_geojson_twin() {
    let dir = tempfile::tempdir().unwrap();
    let shp = shared_data("polygons/earthpy__rmnp.shp");
    let twin = shared_data("polygons/earthpy__rmnp.derived.geojson");
    let out = dir.path().join("bare.json");
    let doc = import(&shp, &out);
    assert_eq!(doc["messages"], json!([]));
    assert_eq!(
        doc["features"]["features"][0]["properties"]["UNITNAM"],
        "Rocky Mountain National Park"
    );
    let summary = check(&out, &twin, "polygon");
    // RMNP is about 1077 km².
    let area = summary["area_m2"][0].as_f64().unwrap();
    assert!((1.07e9..1.08e9).contains(&area), "{summary}");

    let zip = dir.path().join("rmnp.zip");
    let members = [
        "earthpy__rmnp.shp",
        "earthpy__rmnp.shx",
        "earthpy__rmnp.dbf",
        "earthpy__rmnp.prj",
    ];
    zip_files(shp.parent().unwrap(), &members, &zip);
    let out = dir.path().join("zipped.json");
    let zipped = import(&zip, &out);
    assert_eq!(zipped, doc);
}

#[test]
fn rd_new_files_written_by_gdal_match_their_source() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = field();
    let s = |p: &Path| p.to_str().unwrap().to_string();

    // A Shapefile in EPSG:28992, zipped.
    let shp = d.join("field.shp");
    ogr2ogr(&[
        "-t_srs",
        "EPSG:28992",
        "-f",
        "ESRI Shapefile",
        &s(&shp),
        &s(&src),
    ]);
    let zip = d.join("field.zip");
    zip_files(
        d,
        &["field.shp", "field.shx", "field.dbf", "field.prj"],
        &zip,
    );
    let out = d.join("shp.json");
    import(&zip, &out);
    let summary = check(&out, &src, "polygon");
    assert!(
        summary["area_rel_diff"].as_f64().unwrap() <= 1e-6,
        "{summary}"
    );

    // GeoJSON with a legacy crs member naming EPSG:28992.
    let rd = d.join("rd.geojson");
    ogr2ogr(&["-t_srs", "EPSG:28992", "-f", "GeoJSON", &s(&rd), &s(&src)]);
    let named: Value = serde_json::from_str(&std::fs::read_to_string(&rd).unwrap()).unwrap();
    assert_eq!(
        named["crs"]["properties"]["name"],
        "urn:ogc:def:crs:EPSG::28992"
    );
    let out = d.join("geojson.json");
    import(&rd, &out);
    check(&out, &src, "polygon");

    // A GeoPackage in EPSG:28992.
    let gpkg = d.join("field.gpkg");
    ogr2ogr(&["-t_srs", "EPSG:28992", "-f", "GPKG", &s(&gpkg), &s(&src)]);
    let out = d.join("gpkg.json");
    let doc = import(&gpkg, &out);
    assert_eq!(
        doc["features"]["features"][0]["properties"]["Name"],
        "test parcel"
    );
    check(&out, &src, "polygon");

    // KML, and the same as KMZ.
    let kml = d.join("field.kml");
    ogr2ogr(&["-f", "KML", &s(&kml), &s(&src)]);
    let out = d.join("kml.json");
    let from_kml = import(&kml, &out);
    check(&out, &src, "polygon");
    std::fs::copy(&kml, d.join("doc.kml")).unwrap();
    let kmz = d.join("field.kmz");
    zip_files(d, &["doc.kml"], &kmz);
    assert_eq!(import(&kmz, &d.join("kmz.json")), from_kml);

    // A GPX track along the parcel's west and south edges.
    let ring = &serde_json::from_str::<Value>(&std::fs::read_to_string(&src).unwrap()).unwrap()["features"]
        [0]["geometry"]["coordinates"][0];
    let edge: Vec<Value> = ring.as_array().unwrap()[..=10]
        .iter()
        .map(|c| json!([c[0], c[1]]))
        .collect();
    let line = write_json(
        d,
        "edge.geojson",
        &json!({"type": "Feature", "properties": {"name": "edge"},
                "geometry": {"type": "LineString", "coordinates": edge}}),
    );
    let gpx = d.join("edge.gpx");
    ogr2ogr(&[
        "-f",
        "GPX",
        "-lco",
        "FORCE_GPX_TRACK=YES",
        &s(&gpx),
        &s(&line),
    ]);
    let out = d.join("gpx.json");
    let doc = import(&gpx, &out);
    assert_eq!(
        doc["features"]["features"][0]["geometry"]["type"],
        "LineString"
    );
    check(&out, &line, "line");
}

/// `terraplan survey` of the field from its zipped RD New Shapefile plans
/// the survey its GeoJSON gives: same area within 1e-6, same lanes and
/// photos. A GeoJSON ROI in WGS84 is read exactly as before.
#[test]
fn survey_takes_a_zipped_shapefile_and_kml_no_fly_zones() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = field();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ogr2ogr(&[
        "-t_srs",
        "EPSG:28992",
        "-f",
        "ESRI Shapefile",
        &s(&d.join("field.shp")),
        &s(&src),
    ]);
    let zip = d.join("field.zip");
    zip_files(
        d,
        &["field.shp", "field.shx", "field.dbf", "field.prj"],
        &zip,
    );
    let zone = json!({"type": "Polygon", "coordinates": [[[6.0635, 51.5118], [6.0640, 51.5118],
        [6.0640, 51.5122], [6.0635, 51.5122], [6.0635, 51.5118]]]});
    let zone_json = write_json(d, "zone.geojson", &zone);
    let zone_kml = d.join("zone.kml");
    ogr2ogr(&["-f", "KML", &s(&zone_kml), &s(&zone_json)]);
    let params = write_json(d, "params.json", &json!({"line_spacing_m": 30}));

    let plan = |roi: &Path, zone: &Path, out: &str| -> Value {
        let out = d.join(out);
        let o = terraplan(&[
            "survey",
            "--roi",
            &s(roi),
            "--no-fly",
            &s(zone),
            "--params",
            &s(&params),
            "--out",
            &s(&out),
        ]);
        assert!(
            o.status.success(),
            "survey --roi {}: {}",
            roi.display(),
            text(&o.stderr)
        );
        serde_json::from_str(&std::fs::read_to_string(out.join("plan.json")).unwrap()).unwrap()
    };
    let a = plan(&src, &zone_json, "geojson");
    let b = plan(&zip, &zone_kml, "imported");
    let (sa, sb) = (&a["stats"], &b["stats"]);
    for key in ["area_m2", "free_area_m2", "length_m"] {
        let (x, y) = (sa[key].as_f64().unwrap(), sb[key].as_f64().unwrap());
        assert!((x - y).abs() <= 1e-6 * x, "{key}: {x} vs {y}");
    }
    assert!(
        sa["free_area_m2"].as_f64() < sa["area_m2"].as_f64(),
        "the zone cuts the field"
    );
    assert_eq!(sa["lane_count"], sb["lane_count"]);
    assert_eq!(sa["photos"], sb["photos"]);
}

fn failure(args: &[&str]) -> (i32, String) {
    let o: Output = terraplan(args);
    (o.status.code().unwrap_or(-1), text(&o.stderr))
}

/// Malformed files: exit 2 and a message naming the fault; never a panic.
#[test]
fn malformed_files_are_refused_with_the_fault_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ogr2ogr(&[
        "-t_srs",
        "EPSG:28992",
        "-f",
        "ESRI Shapefile",
        &s(&d.join("field.shp")),
        &s(&field()),
    ]);
    let no_prj = d.join("no_prj.zip");
    zip_files(d, &["field.shp", "field.shx", "field.dbf"], &no_prj);
    let (code, err) = failure(&["import", &s(&no_prj)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("field.shp has no .prj file"), "{err}");

    let full = d.join("full.zip");
    zip_files(
        d,
        &["field.shp", "field.shx", "field.dbf", "field.prj"],
        &full,
    );
    let bytes = std::fs::read(&full).unwrap();
    let cut = d.join("cut.zip");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (code, err) = failure(&["import", &s(&cut)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a readable zip file"), "{err}");

    // The same through survey --roi: the file is named.
    let params = write_json(d, "params.json", &json!({}));
    let out = s(&d.join("out"));
    let (code, err) = failure(&[
        "survey",
        "--roi",
        &s(&cut),
        "--params",
        &s(&params),
        "--out",
        &out,
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("ROI file") && err.contains("cut.zip"), "{err}");

    // A GPX line is no area.
    let gpx = d.join("line.gpx");
    std::fs::write(&gpx, r#"<gpx version="1.1" creator="t" xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg><trkpt lat="51.5" lon="6.06"/><trkpt lat="51.51" lon="6.07"/></trkseg></trk></gpx>"#).unwrap();
    let (code, err) = failure(&[
        "survey",
        "--roi",
        &s(&gpx),
        "--params",
        &s(&params),
        "--out",
        &out,
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("holds no polygon"), "{err}");

    let bad_crs = write_json(
        d,
        "bad.geojson",
        &json!({"type": "Polygon", "crs": {"type": "name", "properties": {"name": "EPSG:999999"}},
                "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}),
    );
    let (code, err) = failure(&["import", &s(&bad_crs)]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unknown CRS \"EPSG:999999\""), "{err}");

    let (code, err) = failure(&["import", &s(&params.with_extension("tif"))]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("unsupported file type"), "{err}");
}

fn upload(server: &Server, file_name: &str, data: &[u8]) -> terraplan_e2e::Reply {
    post_multipart(
        &server.url("/api/v1/imports"),
        &[Part {
            name: "file",
            file_name: Some(file_name),
            content_type: Some("application/octet-stream"),
            data,
        }],
    )
}

/// `POST /api/v1/imports` answers what `terraplan import` prints, and 422
/// at `/file` naming the fault for malformed files.
#[test]
fn the_service_imports_what_the_cli_does() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let server = Server::start(&d.join("data"), &[]);
    let shp = shared_data("polygons/earthpy__rmnp.shp");
    let zip = d.join("rmnp.zip");
    let members = [
        "earthpy__rmnp.shp",
        "earthpy__rmnp.dbf",
        "earthpy__rmnp.prj",
    ];
    zip_files(shp.parent().unwrap(), &members, &zip);
    let bytes = std::fs::read(&zip).unwrap();
    let r = upload(&server, "rmnp.zip", &bytes);
    assert_eq!(r.status, 200, "{}", r.text());
    let cli = import(&zip, &d.join("cli.json"));
    assert_eq!(r.json(), cli);
    let out = d.join("http.json");
    std::fs::write(&out, &r.body).unwrap();
    check(
        &out,
        &shared_data("polygons/earthpy__rmnp.derived.geojson"),
        "polygon",
    );

    let kml = br#"<kml><Document><Placemark><name>mast</name><Point><coordinates>6.06,51.51</coordinates></Point></Placemark>
      <Placemark><name>edge</name><LineString><coordinates>6.06,51.51 6.07,51.52</coordinates></LineString></Placemark></Document></kml>"#;
    let r = upload(&server, "lines.kml", kml);
    assert_eq!(r.status, 200, "{}", r.text());
    let doc = r.json();
    assert_eq!(doc["features"]["features"][0]["properties"]["name"], "edge");
    assert_eq!(doc["messages"].as_array().unwrap().len(), 1, "{doc}");
    assert!(
        doc["messages"][0]
            .as_str()
            .unwrap()
            .contains("Placemark 1 (\"mast\"): 1 Point(s) skipped"),
        "{doc}"
    );

    // A GeoPackage written by GDAL in EPSG:28992, whole and cut short.
    let gpkg = d.join("field.gpkg");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ogr2ogr(&[
        "-t_srs",
        "EPSG:28992",
        "-f",
        "GPKG",
        &s(&gpkg),
        &s(&field()),
    ]);
    let gpkg_bytes = std::fs::read(&gpkg).unwrap();
    let r = upload(&server, "field.gpkg", &gpkg_bytes);
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json(), import(&gpkg, &d.join("gpkg.json")));
    for cut in [0, 100, gpkg_bytes.len() / 2] {
        let r = upload(&server, "field.gpkg", &gpkg_bytes[..cut]);
        assert_invalid_at(&r, &format!("gpkg cut at {cut}"), "/file", "not a");
    }

    for cut in [0, 10, bytes.len() / 3, bytes.len() - 1] {
        let r = upload(&server, "rmnp.zip", &bytes[..cut]);
        assert_invalid_at(
            &r,
            &format!("zip cut at {cut}"),
            "/file",
            "not a readable zip file",
        );
    }
    let no_prj = d.join("no_prj.zip");
    zip_files(shp.parent().unwrap(), &members[..2], &no_prj);
    let r = upload(&server, "x.zip", &std::fs::read(&no_prj).unwrap());
    assert_invalid_at(&r, "no .prj", "/file", "has no .prj file");
    let r = upload(&server, "x.kml", b"<kml><Placemark><Polygon>");
    assert_invalid_at(&r, "cut KML", "/file", "ends inside <Polygon>");
    let r = upload(&server, "x.gpx", b"<gpx");
    assert_invalid_at(&r, "bad GPX", "/file", "not a readable GPX document");
    let r = upload(&server, "x.shp", &std::fs::read(&shp).unwrap());
    assert_invalid_at(&r, ".shp alone", "/file", "unsupported file type");
    let r = post_multipart(
        &server.url("/api/v1/imports"),
        &[Part {
            name: "file",
            file_name: None,
            content_type: None,
            data: b"{}",
        }],
    );
    assert_invalid_at(&r, "no filename", "/file", "has no filename");
}
