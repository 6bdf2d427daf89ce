//! The costmaps resource end to end over HTTP, against the real binary
//! and the real DTM `opengeos_data__elevation_dtm.tif` (283 × 259 cells of
//! 2 m, NAD83 / UTM 18N): a job from request to files, the GeoTIFF read
//! back by GDAL (`gdalinfo`, `gdal_translate`, `gdallocationinfo`) and
//! checked against the resource's statistics and its own layers, progress
//! as Server-Sent Events, 409 while not done, cancel by delete, a failed
//! job, 422s naming pointers, jobs surviving a crash and a graceful stop;
//! and `terraplan costmap`. Runs on SQLite, and on PostgreSQL when the
//! test command sets `TERRAPLAN_TEST_DATABASE_URL`.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde_json::{Value, json};
use terraplan_e2e::{
    JOB_DEADLINE, Reply, Server, assert_invalid_at, assert_problem, band_values, class_page, close,
    costmap_job, delete, dtm, gdalinfo, get, get_streaming, get_with_headers, get_with_timeout,
    pixel_values, png_size, post, post_json, slow_costmap_options, sse_events, terraplan, text,
    upload_dem, wait_costmap_finished,
};

/// POST a costmap request: 202 with a Location and the job.
fn create(server: &Server, body: &Value) -> Value {
    let r = post_json(&server.url("/api/v1/costmaps"), body);
    assert_eq!(r.status, 202, "{}", r.text());
    let job = r.json();
    let id = job["id"].as_str().expect("id");
    assert_eq!(
        r.header("location"),
        Some(format!("/api/v1/costmaps/{id}").as_str())
    );
    job
}

fn wait_done(server: &Server, id: &str) -> Value {
    let job = wait_costmap_finished(server, id);
    assert_eq!(job["status"], "done", "{job}");
    job
}

fn file(server: &Server, url: &str) -> Reply {
    get(&server.url(url))
}

// ---------------------------------------------------------------- GDAL

fn epsg_of(info: &Value) -> Option<u64> {
    info["stac"]["proj:epsg"].as_u64()
}

/// Save a download next to the test's files.
fn save(dir: &Path, name: &str, r: &Reply) -> PathBuf {
    assert_eq!(r.status, 200, "{name}: {}", r.text());
    let path = dir.join(name);
    std::fs::write(&path, &r.body).unwrap();
    path
}

/// The costmap GeoTIFF as GDAL reads it agrees with the DEM's grid and
/// CRS and with the job's statistics; the layers agree with the classes.
fn check_geotiff(dir: &Path, server: &Server, job: &Value) {
    let dem = gdalinfo(&dtm());
    let tif = save(
        dir,
        "costmap.tif",
        &file(server, job["urls"]["costmap_tif"].as_str().unwrap()),
    );
    let info = gdalinfo(&tif);
    assert_eq!(info["driverShortName"], "GTiff");
    assert_eq!(info["size"], dem["size"], "same grid as the DEM");
    assert_eq!(info["size"], json!([job["width"], job["height"]]));
    assert_eq!(info["geoTransform"], dem["geoTransform"]);
    assert_eq!(epsg_of(&info), Some(26918));
    assert_eq!(epsg_of(&info), epsg_of(&dem));
    // Page 1, the file itself: the cost, Float32 with NaN nodata, in unit
    // "cost"; page 2 (GTIFF_DIR:2) the class codes, Byte with nodata 0
    // (unknown) and no unit, on the same grid.
    let bands = info["bands"].as_array().unwrap();
    assert_eq!(bands.len(), 1, "{info}");
    assert_eq!(bands[0]["type"], "Float32", "{info}");
    assert_eq!(bands[0]["description"], "cost");
    assert_eq!(bands[0]["unit"], "cost");
    assert_eq!(bands[0]["noDataValue"], "NaN");
    let subdatasets = &info["metadata"]["SUBDATASETS"];
    assert_eq!(subdatasets.as_object().map(|o| o.len()), Some(4), "{info}");
    let page2 = class_page(&tif);
    assert_eq!(subdatasets["SUBDATASET_2_NAME"], page2.to_str().unwrap());
    let class_info = gdalinfo(&page2);
    assert_eq!(class_info["size"], dem["size"]);
    assert_eq!(class_info["geoTransform"], dem["geoTransform"]);
    assert_eq!(epsg_of(&class_info), Some(26918));
    let class_bands = class_info["bands"].as_array().unwrap();
    assert_eq!(class_bands.len(), 1, "{class_info}");
    assert_eq!(class_bands[0]["type"], "Byte", "{class_info}");
    assert_eq!(class_bands[0]["description"], "class");
    assert_eq!(class_bands[0]["noDataValue"], 0.0);
    assert!(class_bands[0].get("unit").is_none(), "{class_info}");
    assert_eq!(class_bands[0]["metadata"][""]["CLASS_3"], "step");

    let cost = band_values(&tif, 1);
    let class = band_values(&page2, 1);
    let cells = (job["width"].as_u64().unwrap() * job["height"].as_u64().unwrap()) as usize;
    assert_eq!(cost.len(), cells);
    assert_eq!(class.len(), cells);
    let stats = &job["stats"];
    assert_eq!(stats["cells"].as_u64(), Some(cells as u64));
    // Class codes, and their fractions as the resource reports them.
    let names = [
        "unknown",
        "traversable",
        "slope",
        "step",
        "enclosed",
        "other",
    ];
    let mut counts = [0usize; 6];
    for &k in &class {
        assert!(k.fract() == 0.0 && (0.0..=5.0).contains(&k), "class {k}");
        counts[k as usize] += 1;
    }
    for (i, name) in names.iter().enumerate() {
        let f = stats["class_fractions"][name].as_f64().unwrap();
        assert!(
            close(f, counts[i] as f64 / cells as f64, 1e-9),
            "{name}: {f} vs {} of {cells}",
            counts[i]
        );
    }
    assert!(counts[1] > cells / 2, "mostly traversable: {counts:?}");
    // The cost is a number exactly on traversable cells, within the range.
    let (mut lo, mut hi, mut sum, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
    for (&c, &k) in cost.iter().zip(&class) {
        assert_eq!(c.is_finite(), k == 1.0, "cost {c} on class {k}");
        if c.is_finite() {
            lo = lo.min(c);
            hi = hi.max(c);
            sum += c;
            n += 1;
        }
    }
    assert!(close(lo, stats["cost_min"].as_f64().unwrap(), 1e-4), "{lo}");
    assert!(close(hi, stats["cost_max"].as_f64().unwrap(), 1e-4), "{hi}");
    let mean = stats["cost_mean"].as_f64().unwrap();
    assert!(close(sum / n as f64, mean, 1e-3 * mean), "{mean}");
    let range = &stats["cost_range"];
    assert!(lo >= range[0].as_f64().unwrap() - 1e-6);
    assert!(hi <= range[1].as_f64().unwrap() + 1e-6);

    // Single pixels through gdallocationinfo agree with the band dump.
    let w = job["width"].as_u64().unwrap() as usize;
    let pixels: Vec<(usize, usize)> = (0..cells).step_by(997).map(|i| (i % w, i / w)).collect();
    assert!(pixels.len() > 50);
    for (page, values) in [(&tif, &cost), (&page2, &class)] {
        for ((c, r), got) in pixels.iter().zip(pixel_values(page, 1, &pixels)) {
            let want = values[r * w + c];
            assert!(
                (want.is_nan() && got.is_nan()) || close(got, want, 1e-4),
                "{} pixel {c},{r}: {got} vs {want}",
                page.display()
            );
        }
    }

    // Layers: one Float32 band on the same grid, and consistent with the
    // classes: Zcomp = cos(slope); slope obstacles are steeper than the
    // vehicle's max_slope, traversable cells are not; step obstacles have
    // a step over max_step, traversable cells do not.
    let max_slope = job["vehicle"]["max_slope_deg"].as_f64().unwrap();
    let max_step = job["vehicle"]["max_step_m"].as_f64().unwrap();
    let layer = |name: &str| -> Vec<f64> {
        let url = job["urls"]["layers"][name].as_str().unwrap();
        let path = save(dir, &format!("{name}.tif"), &file(server, url));
        let info = gdalinfo(&path);
        assert_eq!(info["bands"].as_array().unwrap().len(), 1, "{name}");
        assert_eq!(info["bands"][0]["type"], "Float32", "{name}");
        assert_eq!(info["bands"][0]["description"], name);
        let unit = match name {
            "slope" => "deg",
            "zcomp" => "1",
            _ => "m",
        };
        assert_eq!(info["bands"][0]["unit"], unit, "{name}");
        assert_eq!(info["bands"][0]["noDataValue"], "NaN", "{name}");
        assert_eq!(info["geoTransform"], dem["geoTransform"], "{name}");
        assert_eq!(epsg_of(&info), Some(26918), "{name}");
        band_values(&path, 1)
    };
    let slope = layer("slope");
    let zcomp = layer("zcomp");
    let step = layer("step");
    let mut checked = [0usize; 3];
    for i in 0..cells {
        let k = class[i];
        if slope[i].is_finite() && zcomp[i].is_finite() {
            assert!(
                close(slope[i].to_radians().cos(), zcomp[i], 1e-3),
                "cell {i}: slope {} zcomp {}",
                slope[i],
                zcomp[i]
            );
            checked[0] += 1;
        }
        if k == 1.0 {
            assert!(slope[i] <= max_slope + 1e-3, "cell {i}: {}", slope[i]);
            assert!(step[i] <= max_step + 1e-6, "cell {i}: step {}", step[i]);
            checked[1] += 1;
        }
        if k == 2.0 {
            assert!(slope[i] >= max_slope - 1e-3, "cell {i}: {}", slope[i]);
            checked[2] += 1;
        }
        if k == 3.0 {
            assert!(step[i] > max_step - 1e-6, "cell {i}: step {}", step[i]);
        }
    }
    assert!(checked.iter().all(|&n| n > 0), "{checked:?}");
}

// ---------------------------------------------------------------- tests

/// A costmap of the real DTM from request to files: the job, its
/// statistics, the GeoTIFF and layers through GDAL, the preview and
/// legend, the event stream of a finished job, listing and delete; the
/// CLI builds the same file from the same request.
#[test]
fn dtm_costmap_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let dem_id = upload_dem(&server, &dtm());
    let job = create(
        &server,
        &json!({
            "name": "dtm u-go",
            "dem_id": dem_id,
            "options": {"layers": ["zcomp", "slope", "step"]},
        }),
    );
    let id = job["id"].as_str().unwrap().to_string();
    assert_eq!(job["name"], "dtm u-go");
    assert_eq!(job["dem_id"], dem_id.as_str());
    assert!(
        ["queued", "running", "done"].contains(&job["status"].as_str().unwrap()),
        "{job}"
    );
    assert_eq!(job["vehicle"]["name"], "u-go");
    assert_eq!(job["vehicle"]["max_step_m"], 0.15);
    assert_eq!(job["vehicle"]["max_slope_deg"], 25.0);
    assert_eq!(job["vehicle"]["w_infl"], 10.0);
    assert_eq!(job["vehicle"]["w_slope"], 1.0);
    assert_eq!(job["layers"], json!(["slope", "zcomp", "step"]));
    let base = format!("/api/v1/costmaps/{id}");
    assert_eq!(job["urls"]["self"], base.as_str());
    assert_eq!(job["urls"]["events"], format!("{base}/events"));
    assert_eq!(job["urls"]["costmap_tif"], format!("{base}/costmap.tif"));
    assert_eq!(
        job["urls"]["layers"]["slope"],
        format!("{base}/layers/slope.tif")
    );

    let done = wait_done(&server, &id);
    assert_eq!(done["progress"], 1.0);
    assert_eq!(done["created_at"], job["created_at"]);
    assert!(done["error"].is_null(), "{done}");
    assert_eq!(done["width"], 283);
    assert_eq!(done["height"], 259);
    assert_eq!(done["crs"]["epsg"], 26918);
    // The PROJ.4 definition the web page places the preview with: the DEM's.
    let dem = get(&server.url(&format!("/api/v1/dems/{dem_id}"))).json();
    assert!(
        done["crs"]["proj4"]
            .as_str()
            .is_some_and(|s| s.starts_with("+proj=utm +zone=18 ")),
        "{done}"
    );
    assert_eq!(done["crs"], dem["crs"]);
    // The DTM's own extent (2 m cells from (321498, 4298018)).
    assert_eq!(
        done["bounds"],
        json!([321_498.0, 4_297_500.0, 322_064.0, 4_298_018.0])
    );
    let ll = done["bounds_wgs84"].as_array().unwrap();
    let dem_ll = [-77.0559199, 38.8081989, -77.0492711, 38.8129784];
    for (a, b) in ll.iter().zip(dem_ll) {
        assert!((a.as_f64().unwrap() - b).abs() < 1e-6, "{ll:?}");
    }
    assert_eq!(done["options"]["layers"], json!(["zcomp", "slope", "step"]));
    assert_eq!(done["layers"], json!(["slope", "zcomp", "step"]));
    assert_eq!(done["params"]["resolution_m"], json!([2.0, 2.0]));
    assert_eq!(done["params"]["resample_factor"], json!([1, 1]));
    assert!(done["warnings"].is_array(), "{done}");
    let fractions = done["stats"]["class_fractions"].as_object().unwrap();
    assert_eq!(fractions.len(), 6);
    let sum: f64 = fractions.values().map(|v| v.as_f64().unwrap()).sum();
    assert!(close(sum, 1.0, 1e-9), "fractions sum to {sum}");

    check_geotiff(dir.path(), &server, &done);

    // Preview and legend.
    let png = file(&server, done["urls"]["preview_png"].as_str().unwrap());
    assert_eq!(png.status, 200);
    assert_eq!(png.header("content-type"), Some("image/png"));
    let (pw, ph) = png_size(&png.body);
    assert_eq!((pw, ph), (283, 259), "not shrunk below 1024");
    let svg = file(&server, done["urls"]["legend_svg"].as_str().unwrap());
    assert_eq!(svg.status, 200);
    assert_eq!(svg.header("content-type"), Some("image/svg+xml"));
    assert!(svg.text().contains("<svg"), "{}", svg.text());
    // Downloads are cacheable for good.
    let tif_url = server.url(&format!("{base}/costmap.tif"));
    let tif = get(&tif_url);
    assert_eq!(tif.header("content-type"), Some("image/tiff"));
    assert!(
        tif.header("content-disposition")
            .is_some_and(|d| d.contains("attachment") && d.contains(".tif")),
        "{:?}",
        tif.headers
    );
    let etag = tif.header("etag").expect("ETag").to_string();
    let again = get_with_headers(&tif_url, &[("If-None-Match", &etag)]);
    assert_eq!(again.status, 304);
    assert!(again.body.is_empty());

    // Layers not kept, or not layers at all: 404 naming the kept ones.
    for name in ["inflation.tif", "nope.tif", "slope.png", "slope"] {
        let r = file(&server, &format!("{base}/layers/{name}"));
        let p = assert_problem(&r, 404, name);
        assert!(
            p["detail"]
                .as_str()
                .unwrap()
                .contains("slope.tif, zcomp.tif, step.tif"),
            "{p}"
        );
    }

    // The events of a finished job: just the last one.
    let r = get_with_timeout(&server.url(&format!("{base}/events")), JOB_DEADLINE);
    assert_eq!(r.status, 200);
    assert!(
        r.header("content-type")
            .is_some_and(|c| c.starts_with("text/event-stream")),
        "{:?}",
        r.headers
    );
    let events = sse_events(&r.text());
    assert_eq!(events.len(), 1, "{}", r.text());
    assert_eq!(events[0].0, "done");
    assert_eq!(events[0].1["status"], "done");
    assert_eq!(events[0].1["progress"], 1.0);

    // The CLI builds the very same file from the same request.
    let out = dir.path().join("cli");
    let o = terraplan(&[
        "costmap",
        dtm().to_str().unwrap(),
        "--layers",
        "zcomp,slope,step",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(
        std::fs::read(out.join("costmap.tif")).unwrap(),
        std::fs::read(dir.path().join("costmap.tif")).unwrap(),
        "CLI and service GeoTIFFs differ"
    );
    let cli_stats: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!(cli_stats["stats"], done["stats"]);
    assert_eq!(cli_stats["params"], done["params"]);
    assert_eq!(cli_stats["warnings"], done["warnings"]);

    // Listed; deleted with its files.
    let mut offset = 0;
    let listed = loop {
        let page = get(&server.url(&format!("/api/v1/costmaps?limit=100&offset={offset}"))).json();
        assert!(page["total"].as_i64().unwrap() >= 1);
        let items = page["items"].as_array().unwrap();
        assert!(!items.is_empty(), "costmap {id} not listed");
        if let Some(item) = items.iter().find(|i| i["id"] == id.as_str()) {
            break item.clone();
        }
        offset += 100;
    };
    assert_eq!(listed, costmap_job(&server, &id));
    assert_problem(
        &get(&server.url("/api/v1/costmaps?limit=0")),
        400,
        "limit 0",
    );
    assert_eq!(delete(&server.url(&base)).status, 204);
    for path in [
        base.clone(),
        format!("{base}/costmap.tif"),
        format!("{base}/preview.png"),
        format!("{base}/legend.svg"),
        format!("{base}/layers/slope.tif"),
        format!("{base}/events"),
    ] {
        assert_problem(&get(&server.url(&path)), 404, "no costmap");
    }
    assert_problem(&delete(&server.url(&base)), 404, "no costmap");
}

/// Progress as Server-Sent Events while a job runs, ending in `done`;
/// files are 409 until then; deleting a running job cancels it and frees
/// its slot for the next; a job whose DEM is deleted before it runs fails
/// with a reason.
#[test]
fn progress_events_conflicts_cancel_and_failure() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &["--costmap-jobs", "1"]);
    let dem_id = upload_dem(&server, &dtm());
    let slow = create(
        &server,
        &json!({"dem_id": dem_id, "options": slow_costmap_options()}),
    );
    let slow_id = slow["id"].as_str().unwrap().to_string();
    let events_url = server.url(&format!("/api/v1/costmaps/{slow_id}/events"));
    let stream = get_streaming(&events_url, JOB_DEADLINE);
    assert_eq!(stream.status(), 200);

    // While it runs, its files are a 409 saying how far it got.
    let r = file(&server, slow["urls"]["costmap_tif"].as_str().unwrap());
    if r.status == 409 {
        let p = assert_problem(&r, 409, "the costmap is");
        let detail = p["detail"].as_str().unwrap();
        assert!(
            detail.contains("still running (stage") || detail.contains("queued"),
            "{detail}"
        );
    } else {
        // A machine fast enough to finish already.
        assert_eq!(r.status, 200, "{}", r.text());
    }

    let r = stream.finish();
    assert_eq!(r.status, 200);
    let events = sse_events(&r.text());
    let (last, progress) = events.split_last().expect("events");
    assert_eq!(last.0, "done", "{}", r.text());
    assert_eq!(last.1["status"], "done");
    assert!(!progress.is_empty(), "no progress events: {}", r.text());
    let mut previous = 0.0;
    let mut stages = Vec::new();
    for (name, data) in progress {
        assert_eq!(name, "progress", "{data}");
        assert!(
            ["queued", "running"].contains(&data["status"].as_str().unwrap()),
            "{data}"
        );
        let p = data["progress"].as_f64().unwrap();
        assert!(
            (0.0..=1.0).contains(&p) && p >= previous,
            "{p} after {previous}"
        );
        previous = p;
        if let Some(s) = data["stage"].as_str()
            && !stages.contains(&s)
        {
            stages.push(s);
        }
    }
    assert!(stages.len() >= 2, "stages seen: {stages:?} in {}", r.text());
    wait_done(&server, &slow_id);

    // One slot: a slow job runs, the next waits queued (409 "queued").
    let first = create(
        &server,
        &json!({"dem_id": dem_id, "options": slow_costmap_options()}),
    );
    let first_id = first["id"].as_str().unwrap().to_string();
    let second = create(&server, &json!({"dem_id": dem_id, "name": "second"}));
    let second_id = second["id"].as_str().unwrap().to_string();
    let r = file(&server, second["urls"]["preview_png"].as_str().unwrap());
    if r.status == 409 {
        assert_problem(&r, 409, "queued");
        assert_eq!(costmap_job(&server, &second_id)["status"], "queued");
    }
    // Delete the running job: cancelled, gone, and the queued one runs.
    // The stream is open before the delete (after it, there is nothing to
    // follow: a 404).
    let events_url = server.url(&format!("/api/v1/costmaps/{first_id}/events"));
    let stream = get_streaming(&events_url, JOB_DEADLINE);
    assert_eq!(stream.status(), 200);
    let deleted_at = Instant::now();
    assert_eq!(
        delete(&server.url(&format!("/api/v1/costmaps/{first_id}"))).status,
        204
    );
    let r = stream.finish();
    let events = sse_events(&r.text());
    let last = events.last().expect("events");
    assert!(
        last.0 == "failed" && last.1["error"].as_str().unwrap().contains("deleted")
            || last.0 == "done",
        "{}",
        r.text()
    );
    assert_problem(
        &get(&server.url(&format!("/api/v1/costmaps/{first_id}"))),
        404,
        "no costmap",
    );
    wait_done(&server, &second_id);
    assert!(
        deleted_at.elapsed() < Duration::from_secs(60),
        "the slot was not freed by the delete"
    );

    // A job whose DEM is gone before it runs fails, saying so.
    let other_dem = upload_dem(&server, &dtm());
    let blocker = create(
        &server,
        &json!({"dem_id": dem_id, "options": slow_costmap_options()}),
    );
    let doomed = create(&server, &json!({"dem_id": other_dem}));
    let doomed_id = doomed["id"].as_str().unwrap().to_string();
    assert_eq!(
        delete(&server.url(&format!("/api/v1/dems/{other_dem}"))).status,
        204
    );
    // The slow job holds the only slot for seconds: this one is still
    // queued when its DEM goes.
    let job = wait_costmap_finished(&server, &doomed_id);
    assert_eq!(job["status"], "failed", "{job}");
    let error = job["error"].as_str().unwrap();
    assert!(
        error.contains("deleted") && error.contains(&other_dem),
        "{error}"
    );
    assert!(job["stats"].is_null() && job["params"].is_null(), "{job}");
    let r = file(&server, job["urls"]["costmap_tif"].as_str().unwrap());
    assert_problem(&r, 409, "failed");
    let r = get_with_timeout(
        &server.url(job["urls"]["events"].as_str().unwrap()),
        JOB_DEADLINE,
    );
    let events = sse_events(&r.text());
    assert_eq!(events.len(), 1, "{}", r.text());
    assert_eq!(events[0].0, "failed");
    assert!(events[0].1["error"].as_str().unwrap().contains("deleted"));
    wait_done(&server, blocker["id"].as_str().unwrap());
    assert_eq!(get(&server.url("/healthz")).status, 200);
}

/// Faults of a costmap request are 422s naming each by JSON pointer,
/// including those that depend on the DEM; malformed bodies are 400/415.
/// A land-cover raster uploaded like a DEM (an ESRI ASCII grid of class
/// codes in the DTM's CRS, two 283 m columns): its table's cost is added
/// on grass, water is lethal (class 5), and the `landcover` layer holds
/// the per-cell cost, as GDAL reads them back.
#[test]
fn landcover_raster_costs_and_lethal_classes() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let dem_id = upload_dem(&server, &dtm());
    let grid = "ncols 2\nnrows 2\nxllcorner 321498\nyllcorner 4297500\ncellsize 283\n\
                NODATA_value -9999\n1 9\n1 9\n";
    let r = post(
        &server.url("/api/v1/dems?crs=EPSG:26918&file_name=classes.asc&name=landcover"),
        "text/plain",
        grid.as_bytes(),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let classes_id = r.json()["id"].as_str().unwrap().to_string();
    let job = create(
        &server,
        &json!({"dem_id": dem_id, "options": {
            "landcover": {"source": classes_id, "classes": [
                {"code": 1, "cost": 3.0, "name": "grass"},
                {"code": 9, "lethal": true, "name": "water"}
            ]},
            "layers": ["landcover"]
        }}),
    );
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&server, id);
    assert!(
        done["stats"]["class_fractions"]["other"].as_f64().unwrap() > 0.3,
        "{done}"
    );
    let tif = save(
        dir.path(),
        "c.tif",
        &file(&server, &format!("/api/v1/costmaps/{id}/costmap.tif")),
    );
    let layer = save(
        dir.path(),
        "l.tif",
        &file(
            &server,
            &format!("/api/v1/costmaps/{id}/layers/landcover.tif"),
        ),
    );
    let (class, lc) = (band_values(&class_page(&tif), 1), band_values(&layer, 1));
    assert_eq!(gdalinfo(&layer)["bands"][0]["unit"], "cost");
    let width = 283;
    let (mut grass, mut water) = (0, 0);
    for (i, (&k, &v)) in class.iter().zip(&lc).enumerate() {
        let col = i % width;
        if col <= 139 {
            assert!(v == 3.0, "cell {i}: land-cover cost {v}");
            grass += usize::from(k == 1.0);
        } else if col >= 143 {
            assert!(v.is_nan(), "cell {i}: lethal water has no cost, got {v}");
            assert!(k != 1.0, "cell {i}: water is never traversable");
            water += usize::from(k == 5.0);
        }
    }
    assert!(grass > 20_000 && water > 20_000, "{grass} {water}");

    // A raster in another CRS PROJ relates to the DEM's (WGS 84 / UTM 18N
    // against NAD83 / UTM 18N) passes the CRS check made at once.
    let r = post(
        &server.url("/api/v1/dems?crs=EPSG:32618&file_name=classes.asc&name=landcover-wgs84"),
        "text/plain",
        grid.as_bytes(),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    let wgs84_id = r.json()["id"].as_str().unwrap().to_string();
    let job = create(
        &server,
        &json!({"dem_id": dem_id, "options": {
            "landcover": {"source": wgs84_id, "classes": [{"code": 1, "cost": 3.0}]}
        }}),
    );
    let url = server.url(job["urls"]["self"].as_str().unwrap());
    assert_eq!(delete(&url).status, 204);
}

/// `GET /api/v1/vehicles` lists the presets with their numbers, the
/// thesis' U-Go first, and each listed name is accepted as a preset.
#[test]
fn vehicle_presets_are_listed_and_accepted() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("data"), &[]);
    let r = get(&server.url("/api/v1/vehicles"));
    assert_eq!(r.status, 200, "{}", r.text());
    let items = r.json()["items"].as_array().unwrap().clone();
    let names: Vec<&str> = items.iter().map(|v| v["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["u-go", "small-wheeled", "large-skid-steer"]);
    assert_eq!(items[0]["max_step_m"], 0.15);
    assert_eq!(items[0]["max_slope_deg"], 25.0);
    assert_eq!(items[0]["w_infl"], 10.0);
    assert_eq!(items[0]["w_slope"], 1.0);
    let dem_id = upload_dem(&server, &dtm());
    for name in names {
        let job = create(
            &server,
            &json!({"dem_id": dem_id, "vehicle": {"preset": name}}),
        );
        assert_eq!(job["vehicle"]["name"], name);
    }
}

#[test]
fn costmap_request_faults() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let dem_id = upload_dem(&server, &dtm());
    let url = server.url("/api/v1/costmaps");
    let invalid = |what: &str, body: Value, pointer: &str, says: &str| {
        assert_invalid_at(&post_json(&url, &body), what, pointer, says);
    };
    invalid(
        "unknown DEM",
        json!({"dem_id": "00000000-0000-0000-0000-000000000000"}),
        "/dem_id",
        "no DEM",
    );
    invalid("no DEM", json!({}), "/dem_id", "required");
    invalid("DEM id type", json!({"dem_id": 7}), "/dem_id", "id");
    invalid(
        "steep",
        json!({"dem_id": dem_id, "vehicle": {"max_slope_deg": 95}}),
        "/vehicle/max_slope_deg",
        "95",
    );
    invalid(
        "preset",
        json!({"dem_id": dem_id, "vehicle": {"preset": "tank"}}),
        "/vehicle/preset",
        "tank",
    );
    invalid(
        "vehicle field",
        json!({"dem_id": dem_id, "vehicle": {"wheels": 6}}),
        "/vehicle/wheels",
        "wheels",
    );
    invalid(
        "finer than the DEM",
        json!({"dem_id": dem_id, "options": {"resolution_m": 0.5}}),
        "/options/resolution_m",
        "finer than the DEM",
    );
    invalid(
        "unknown field",
        json!({"dem_id": dem_id, "colour": "red"}),
        "/colour",
        "colour",
    );
    invalid(
        "unknown option",
        json!({"dem_id": dem_id, "options": {"colour": "red"}}),
        "/options/colour",
        "colour",
    );
    invalid(
        "option type",
        json!({"dem_id": dem_id, "options": {"pca_radius_m": "wide"}}),
        "/options/pca_radius_m",
        "wide",
    );
    invalid(
        "unknown layer",
        json!({"dem_id": dem_id, "options": {"layers": ["slope", "colour"]}}),
        "/options/layers/1",
        "colour",
    );
    invalid(
        "layer without its option",
        json!({"dem_id": dem_id, "options": {"layers": ["roughness"]}}),
        "/options/layers/0",
        "roughness",
    );
    invalid(
        "land cover",
        json!({"dem_id": dem_id, "options": {"landcover": {
            "source": "no-such-raster",
            "classes": [{"code": 1, "cost": 2}],
        }}}),
        "/options/landcover/source",
        "no-such-raster",
    );
    // A fault of the DEM itself is named at /dem_id, not under /options.
    let tiny = post(
        &server.url("/api/v1/dems?crs=EPSG:26918&file_name=tiny.asc&name=tiny"),
        "text/plain",
        b"ncols 2\nnrows 2\nxllcorner 321498\nyllcorner 4297500\ncellsize 2\n1 2\n3 4\n",
    );
    assert_eq!(tiny.status, 201, "{}", tiny.text());
    let tiny_id = tiny.json()["id"].as_str().unwrap().to_string();
    let r = post_json(&url, &json!({"dem_id": tiny_id}));
    assert_invalid_at(&r, "2 × 2 DEM", "/dem_id", "2 × 2");
    let p = r.json();
    assert_eq!(p["errors"].as_array().unwrap().len(), 1, "{p}");
    invalid(
        "name",
        json!({"dem_id": dem_id, "name": "n".repeat(201)}),
        "/name",
        "200 characters",
    );
    // Every fault at once.
    let r = post_json(
        &url,
        &json!({
            "dem_id": dem_id,
            "vehicle": {"max_step_m": 0, "w_infl": -1},
            "options": {"resolution_m": -2},
            "extra": true,
        }),
    );
    let p = assert_problem(&r, 422, "problems");
    let pointers: Vec<&str> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["pointer"].as_str().unwrap())
        .collect();
    assert_eq!(
        pointers,
        [
            "/extra",
            "/vehicle/max_step_m",
            "/vehicle/w_infl",
            "/options/resolution_m"
        ]
    );
    assert_problem(
        &post(&url, "application/json", b"{\"dem_id\":"),
        400,
        "not valid JSON",
    );
    assert_problem(&post(&url, "text/plain", b"{}"), 415, "Content-Type");
    assert_problem(&post_json(&url, &json!([1])), 422, "JSON object");
    let none = server.url("/api/v1/costmaps/00000000-0000-0000-0000-000000000000");
    for path in ["", "/costmap.tif", "/events", "/layers/slope.tif"] {
        assert_problem(&get(&format!("{none}{path}")), 404, "no costmap");
    }
    assert_problem(&delete(&none), 404, "no costmap");
    // Nothing was queued by the faults.
    let page = get(&server.url("/api/v1/costmaps?limit=100")).json();
    assert!(
        page["items"]
            .as_array()
            .unwrap()
            .iter()
            .all(|i| i["dem_id"] != dem_id.as_str()),
        "{page}"
    );
}

/// Jobs left queued or running by a killed server are run again by the
/// next one on the same data; a graceful stop does not wait for a running
/// job and gives it back for the next start.
#[test]
fn unfinished_jobs_survive_a_crash_and_a_stop() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let server = Server::start(&data, &["--costmap-jobs", "1"]);
    let dem_id = upload_dem(&server, &dtm());
    let mut ids = Vec::new();
    for i in 0..3 {
        let options = if i == 0 {
            slow_costmap_options()
        } else {
            json!({})
        };
        let job = create(
            &server,
            &json!({"dem_id": dem_id, "name": format!("job {i}"), "options": options}),
        );
        ids.push(job["id"].as_str().unwrap().to_string());
    }
    let before: Vec<String> = ids
        .iter()
        .map(|id| {
            costmap_job(&server, id)["status"]
                .as_str()
                .unwrap()
                .to_string()
        })
        .collect();
    assert!(
        before.iter().any(|s| s == "queued"),
        "one slot and a slow first job: {before:?}"
    );
    server.kill();

    let server = Server::start(&data, &["--costmap-jobs", "2"]);
    for (i, id) in ids.iter().enumerate() {
        let job = wait_done(&server, id);
        assert_eq!(job["name"], format!("job {i}"));
        assert_eq!(job["progress"], 1.0);
        let r = file(&server, job["urls"]["costmap_tif"].as_str().unwrap());
        assert_eq!(r.status, 200, "{}", r.text());
        assert!(r.body.starts_with(b"II*\0") || r.body.starts_with(b"MM\0*"));
    }

    // A graceful stop with a job running: quick, clean, and the job is
    // finished by the next server.
    let job = create(
        &server,
        &json!({"dem_id": dem_id, "options": slow_costmap_options()}),
    );
    let id = job["id"].as_str().unwrap().to_string();
    let start = Instant::now();
    while costmap_job(&server, &id)["status"] == "queued" && start.elapsed() < JOB_DEADLINE {
        std::thread::sleep(Duration::from_millis(20));
    }
    let stopping = Instant::now();
    assert!(server.stop().success(), "graceful shutdown exits 0");
    assert!(
        stopping.elapsed() < Duration::from_secs(10),
        "shutdown waited {:?} for the job",
        stopping.elapsed()
    );
    let server = Server::start(&data, &[]);
    let done = wait_done(&server, &id);
    assert!(done["error"].is_null(), "{done}");
}

/// `terraplan costmap` writes the costmap, preview, legend, statistics
/// and layers; bad input exits 2 naming the fault.
#[test]
fn costmap_cli() {
    let dir = tempfile::tempdir().unwrap();
    let dem = dtm();
    let dem = dem.to_str().unwrap();
    let out = dir.path().join("out");
    let o = terraplan(&[
        "costmap",
        dem,
        "--vehicle",
        "large-skid-steer",
        "--layers",
        "slope,step",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stdout = text(&o.stdout);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(stdout.contains("283×259"), "{stdout}");
    assert!(stdout.contains("traversable"), "{stdout}");
    for f in [
        "costmap.tif",
        "preview.png",
        "legend.svg",
        "stats.json",
        "layers/slope.tif",
        "layers/step.tif",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(!out.join("layers/zcomp.tif").exists());
    let stats: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["vehicle"]["name"], "large-skid-steer");
    assert_eq!(stats["vehicle"]["max_slope_deg"], 30.0);
    assert_eq!(stats["layers"], json!(["slope", "step"]));
    assert!(stats["warnings"].is_array());
    let sum: f64 = stats["stats"]["class_fractions"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_f64().unwrap())
        .sum();
    assert!(close(sum, 1.0, 1e-9));
    let info = gdalinfo(&out.join("costmap.tif"));
    assert_eq!(info["bands"].as_array().unwrap().len(), 1);
    assert_eq!(epsg_of(&info), Some(26918));
    let class_info = gdalinfo(&class_page(&out.join("costmap.tif")));
    assert_eq!(class_info["bands"][0]["type"], "Byte");
    assert_eq!(epsg_of(&class_info), Some(26918));
    assert_eq!(
        png_size(&std::fs::read(out.join("preview.png")).unwrap()),
        (283, 259)
    );

    // A vehicle file and an options file.
    let vehicle = dir.path().join("vehicle.json");
    std::fs::write(
        &vehicle,
        r#"{"preset": "small-wheeled", "max_slope_deg": 15}"#,
    )
    .unwrap();
    let options = dir.path().join("options.json");
    std::fs::write(&options, r#"{"resolution_m": 4, "layers": ["zcomp"]}"#).unwrap();
    let out2 = dir.path().join("out2");
    let o = terraplan(&[
        "costmap",
        dem,
        "--vehicle",
        vehicle.to_str().unwrap(),
        "--options",
        options.to_str().unwrap(),
        "--out",
        out2.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stats: Value =
        serde_json::from_str(&std::fs::read_to_string(out2.join("stats.json")).unwrap()).unwrap();
    assert_eq!(stats["vehicle"]["max_slope_deg"], 15.0);
    assert_eq!(stats["vehicle"]["max_step_m"], 0.05);
    assert_eq!(stats["params"]["resample_factor"], json!([2, 2]));
    assert_eq!(stats["width"], 141);
    assert!(out2.join("layers/zcomp.tif").is_file());

    let write = |name: &str, content: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, content).unwrap();
        p.to_str().unwrap().to_string()
    };
    let steep = write("steep.json", r#"{"max_slope_deg": 95}"#);
    let garbage = write("garbage.json", "{not json");
    let wheels = write("wheels.json", r#"{"wheels": 6}"#);
    let fine = write("fine.json", r#"{"resolution_m": 0.5}"#);
    let unknown = write("unknown.json", r#"{"colour": "red"}"#);
    let missing = dir.path().join("nothing.tif");
    let o = out.to_str().unwrap();
    for (args, says) in [
        (vec![dem, "--vehicle", &steep], "steep.json#/max_slope_deg"),
        (vec![dem, "--vehicle", &garbage], "garbage.json"),
        (vec![dem, "--vehicle", &wheels], "wheels"),
        (vec![dem, "--vehicle", "tank"], "preset"),
        (vec![dem, "--options", &fine], "fine.json#/resolution_m"),
        (vec![dem, "--options", &unknown], "colour"),
        (vec![dem, "--layers", "slope,colour"], "colour"),
        (vec![dem, "--layers", "roughness"], "roughness"),
        (vec![missing.to_str().unwrap()], "nothing.tif"),
        (vec![dem, "--crs", "EPSG:nope"], "EPSG code"),
    ] {
        let mut all = vec!["costmap"];
        all.extend(args.iter().copied());
        all.extend(["--out", o]);
        let r = terraplan(&all);
        let err = text(&r.stderr);
        assert_eq!(r.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: expected {says:?} in {err}");
        assert!(r.stdout.is_empty(), "{args:?}");
    }
}

/// The costmap operations and their schemas are in the OpenAPI document.
#[test]
fn costmaps_in_the_openapi_document() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(dir.path(), &[]);
    let doc = get(&server.url("/api/v1/openapi.json")).json();
    let paths = doc["paths"].as_object().unwrap();
    for (path, methods) in [
        ("/api/v1/costmaps", &["get", "post"][..]),
        ("/api/v1/costmaps/{id}", &["get", "delete"]),
        ("/api/v1/costmaps/{id}/events", &["get"]),
        ("/api/v1/costmaps/{id}/costmap.tif", &["get"]),
        ("/api/v1/costmaps/{id}/preview.png", &["get"]),
        ("/api/v1/costmaps/{id}/legend.svg", &["get"]),
        ("/api/v1/costmaps/{id}/layers/{file}", &["get"]),
        ("/api/v1/vehicles", &["get"]),
    ] {
        for m in methods {
            let op = &paths[path][m];
            assert!(
                op.is_object(),
                "{m} {path} missing from the OpenAPI document"
            );
            assert_eq!(op["tags"], json!(["costmaps"]), "{m} {path}");
        }
    }
    let post = &paths["/api/v1/costmaps"]["post"];
    assert!(post["responses"]["202"].is_object());
    assert!(post["responses"]["422"].is_object());
    // Reading a DEM not in memory waits for a planner thread, and gives up
    // with a 503 when none frees in time.
    assert!(post["responses"]["503"].is_object());
    assert!(paths["/api/v1/costmaps/{id}/costmap.tif"]["get"]["responses"]["409"].is_object());
    assert!(
        paths["/api/v1/costmaps/{id}/events"]["get"]["responses"]["200"]["content"]
            ["text/event-stream"]
            .is_object()
    );
    let schemas = &doc["components"]["schemas"];
    assert_eq!(schemas["CreateCostmap"]["required"], json!(["dem_id"]));
    for field in ["vehicle", "options", "name"] {
        assert!(
            schemas["CreateCostmap"]["properties"][field].is_object(),
            "{field}"
        );
    }
    assert_eq!(
        schemas["JobStatus"]["enum"],
        json!(["queued", "running", "done", "failed"])
    );
    for s in [
        "CostmapResponse",
        "VehicleSpec",
        "CostmapOptions",
        "CostmapStats",
    ] {
        assert!(schemas[s].is_object(), "schema {s} missing");
    }
}
