//! DEM reading throughput: `read_dem` on the largest shared DEMs (CODEM
//! Float64 1.6 MB, SRTM Int16 1000×1000, and a tiled Deflate COG), in MB of
//! file per second, next to `gdal_translate -of GTiff FILE out.tif`
//! (uncompressed output) on the same input when GDAL is installed, and an
//! in-process GDAL read (osgeo.gdal open + ReadAsArray as float64).
//!
//! `CARGO_TARGET_DIR=/tmp/bench-target cargo bench -p planner-core --bench dem_read`
//! (`TERRAPLAN_SHARED_DATA` as for the tests). gdal_translate's time includes
//! starting the process and writing the output file, as a user would see it.

use std::hint::black_box;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use planner_core::terrain::{DemLimits, read_dem};

#[path = "../tests/support/mod.rs"]
mod support;
use support::data_dir;

/// Run `f` at least `min_runs` times and for at least `min_time`; the
/// median time of one run.
fn time(min_runs: usize, min_time: Duration, mut f: impl FnMut()) -> Duration {
    f(); // warm-up
    let mut times = Vec::new();
    let start = Instant::now();
    while times.len() < min_runs || start.elapsed() < min_time {
        let t = Instant::now();
        f();
        times.push(t.elapsed());
    }
    times.sort();
    times[times.len() / 2]
}

fn mb_per_s(bytes: usize, t: Duration) -> f64 {
    bytes as f64 / 1e6 / t.as_secs_f64()
}

/// Median ms of an in-process GDAL read (open + ReadAsArray as float64,
/// Python's osgeo.gdal), for a comparison without process start-up.
fn osgeo_ms(path: &Path, runs: usize) -> Option<f64> {
    let script = r#"
import sys, time
from osgeo import gdal
gdal.UseExceptions()
gdal.SetCacheMax(0)
ts = []
for _ in range(int(sys.argv[2]) + 1):
    t = time.perf_counter()
    ds = gdal.Open(sys.argv[1])
    a = ds.GetRasterBand(1).ReadAsArray().astype('float64')
    ds = None
    ts.append(time.perf_counter() - t)
ts = sorted(ts[1:])
print(ts[len(ts) // 2] * 1e3)
"#;
    let python =
        std::env::var("TERRAPLAN_GDAL_PYTHON").unwrap_or_else(|_| "/usr/bin/python3".into());
    let out = Command::new(python)
        .arg("-c")
        .arg(script)
        .arg(path)
        .arg(runs.to_string())
        .stderr(Stdio::null())
        .output()
        .ok()?;
    String::from_utf8_lossy(&out.stdout).trim().parse().ok()
}

fn main() {
    // `cargo bench` passes --bench; `cargo test --benches` runs this once.
    let quick = !std::env::args().any(|a| a == "--bench");
    let dir = data_dir();
    let files = [
        "codem__AOI-DigitalSurfaceModel.tif",
        "demcompare__srtm_ref.tif",
        "opengeos_data__elevation_dsm.tif",
    ];
    let gdal = Command::new("gdal_translate")
        .arg("--version")
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let out = std::env::temp_dir().join(format!("terraplan-bench-{}.tif", std::process::id()));
    let limits = DemLimits::default();
    let (runs, min_time) = if quick {
        (1, Duration::ZERO)
    } else {
        (20, Duration::from_secs(2))
    };

    println!(
        "{:<40} {:>9} {:>12} {:>14} {:>12} {:>16} {:>12}",
        "file",
        "MB",
        "read_dem ms",
        "read_dem MB/s",
        "gdal ms",
        "gdal_translate MB/s",
        "osgeo MB/s"
    );
    for name in files {
        let path = dir.join(name);
        let Ok(bytes) = std::fs::read(&path) else {
            eprintln!("skipping {}: not found", path.display());
            continue;
        };
        let ours = time(runs, min_time, || {
            let dem = read_dem(black_box(&bytes), Some(name), None, &limits).expect("read_dem");
            black_box(dem);
        });
        let theirs = gdal.then(|| {
            time(runs.min(5), min_time, || {
                let ok = Command::new("gdal_translate")
                    .args(["-q", "-of", "GTiff"])
                    .arg(&path)
                    .arg(&out)
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .status()
                    .is_ok_and(|s| s.success());
                assert!(ok, "gdal_translate failed on {}", path.display());
            })
        });
        let in_process = osgeo_ms(&path, if quick { 1 } else { 20 });
        println!(
            "{:<40} {:>9.3} {:>12.2} {:>14.1} {:>12} {:>16} {:>12}",
            name,
            bytes.len() as f64 / 1e6,
            ours.as_secs_f64() * 1e3,
            mb_per_s(bytes.len(), ours),
            theirs.map_or("-".into(), |t| format!("{:.2}", t.as_secs_f64() * 1e3)),
            theirs.map_or("-".into(), |t| format!("{:.1}", mb_per_s(bytes.len(), t))),
            in_process.map_or("-".into(), |ms| format!(
                "{:.1}",
                bytes.len() as f64 / 1e3 / ms
            )),
        );
    }
    let _ = std::fs::remove_file(&out);
}
