//! `terraplan costmap`: the traversability costmap of a DEM file, written
//! as the service serves it (GeoTIFF, preview, legend, stats, layers).

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use planner_core::costmap::pipeline::{build_costmap_owned, check_against_dem};
use planner_core::costmap::{
    Costmap, CostmapError, CostmapOptions, Layer, Stage, VehiclePreset, VehicleSpec, legend_svg,
    preview_png,
};
use planner_core::geo::{Issue, deserialize_at};
use planner_core::terrain::DemLimits;
use serde_json::json;

use super::common::{Failure, list_issues, read_dem_file, read_json};

#[derive(clap::Args)]
pub(super) struct CostmapArgs {
    /// The DEM file (GeoTIFF, ESRI ASCII grid, SRTM .hgt).
    #[arg(value_name = "DEM")]
    dem: PathBuf,
    /// The vehicle: a preset (u-go, small-wheeled, large-skid-steer) or a
    /// JSON file with the fields of the API's `vehicle` (a preset and any
    /// numbers overridden). Default u-go.
    #[arg(long, value_name = "FILE.json|PRESET")]
    vehicle: Option<String>,
    /// Pipeline options as JSON (the API's `options`). A land-cover
    /// `source` is a raster file, relative to the options file.
    #[arg(long, value_name = "FILE.json")]
    options: Option<PathBuf>,
    /// Horizontal CRS of the DEM (`EPSG:32633` or `32633`): needed when
    /// the file does not say; overrides the file's.
    #[arg(long, value_name = "EPSG:CODE")]
    crs: Option<String>,
    /// Horizontal CRS of the options' land-cover raster, when the file
    /// does not say.
    #[arg(long, value_name = "EPSG:CODE")]
    landcover_crs: Option<String>,
    /// Layers to write as well, comma-separated: slope, zcomp, step,
    /// inflation, roughness, negative_step, landcover (added to the
    /// options' `layers`).
    #[arg(long, value_name = "NAME,...", value_delimiter = ',')]
    layers: Vec<String>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Most pixels (width × height) accepted.
    #[arg(long, default_value_t = DemLimits::default().max_pixels)]
    max_pixels: u64,
}

/// Where the vehicle of `terraplan costmap` came from.
enum VehicleSource<'a> {
    Default,
    Preset(&'a str),
    File(&'a Path),
}

/// Issues of `terraplan costmap` with their pointers translated to the
/// file or flag they came from.
fn describe_costmap_issues(
    issues: &[Issue],
    vehicle: &VehicleSource<'_>,
    options: Option<&Path>,
) -> String {
    let locate = |ptr: &str| -> String {
        if let Some(rest) = ptr.strip_prefix("/vehicle") {
            return match vehicle {
                VehicleSource::File(p) => format!("{}#{rest}", p.display()),
                VehicleSource::Preset(name) => format!("--vehicle {name}{rest}"),
                VehicleSource::Default => format!("vehicle{rest}"),
            };
        }
        let rest = ptr.strip_prefix("/options").unwrap_or(ptr);
        if rest.starts_with("/layers") && options.is_none() {
            return "--layers".to_string();
        }
        match options {
            Some(p) => format!("{}#{rest}", p.display()),
            None => format!("options{rest}"),
        }
    };
    list_issues(issues, locate)
}

pub(super) fn costmap(args: &CostmapArgs) -> Result<(), Failure> {
    let started = std::time::Instant::now();
    planner_core::buffer::keep_freed_grids();
    let (source, spec) = read_vehicle(args)?;
    let describe =
        |issues: &[Issue]| describe_costmap_issues(issues, &source, args.options.as_deref());
    let vehicle = spec
        .resolve("/vehicle")
        .map_err(|issues| Failure::input(describe(&issues)))?;
    let options = read_options(args, &describe)?;

    let limits = DemLimits {
        max_pixels: args.max_pixels,
        ..DemLimits::default()
    };
    let (dem, _, _) = read_dem_file(&args.dem, args.crs.as_deref(), "--crs", limits.clone())?;
    // A land-cover source is a raster file, relative to the options file.
    let landcover = match &options.landcover {
        None => None,
        Some(l) => {
            let given = Path::new(&l.source);
            let path = match args.options.as_deref().and_then(Path::parent) {
                Some(dir) if given.is_relative() => dir.join(given),
                _ => given.to_path_buf(),
            };
            let crs = args.landcover_crs.as_deref();
            Some(read_dem_file(&path, crs, "--landcover-crs", limits)?.0)
        }
    };
    let issues = check_against_dem(&dem, &vehicle, &options, "/options");
    if !issues.is_empty() {
        return Err(Failure::input(describe(&issues)));
    }
    let (dem_w, dem_h) = (dem.width, dem.height);

    let show_progress = std::io::stderr().is_terminal();
    let last_stage = std::sync::Mutex::new(None::<Stage>);
    let progress = |stage: Stage, _done: f64| -> bool {
        if show_progress {
            let mut last = last_stage.lock().unwrap_or_else(|p| p.into_inner());
            if *last != Some(stage) {
                *last = Some(stage);
                eprintln!("{}…", crate::jobs::stage_name(stage));
            }
        }
        true
    };
    let map = build_costmap_owned(dem, &vehicle, &options, landcover.as_ref(), &progress).map_err(
        |e| match e {
            CostmapError::Invalid(issues) => Failure::input(describe(&issues)),
            CostmapError::Cancelled => Failure::other("the costmap was cancelled"),
        },
    )?;
    write_files(&map, &args.out)?;
    print_summary(&map, [dem_w, dem_h], started, &args.out);
    Ok(())
}

/// The vehicle: a preset's name, or a file.
fn read_vehicle(args: &CostmapArgs) -> Result<(VehicleSource<'_>, VehicleSpec), Failure> {
    let presets = || {
        VehiclePreset::ALL
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    Ok(match args.vehicle.as_deref() {
        None => (VehicleSource::Default, VehicleSpec::default()),
        Some(name) if VehiclePreset::ALL.iter().any(|p| p.name() == name) => {
            let preset = VehiclePreset::ALL.into_iter().find(|p| p.name() == name);
            (
                VehicleSource::Preset(name),
                VehicleSpec {
                    preset,
                    ..VehicleSpec::default()
                },
            )
        }
        Some(file) => {
            let path = Path::new(file);
            if !path.exists() {
                return Err(Failure::input(format!(
                    "--vehicle {file}: no such file, and not a preset ({})",
                    presets()
                )));
            }
            let doc = read_json(path, "vehicle")?;
            let spec = deserialize_at::<VehicleSpec>(&doc, "/vehicle").map_err(|i| {
                Failure::input(describe_costmap_issues(
                    &[i],
                    &VehicleSource::File(path),
                    None,
                ))
            })?;
            (VehicleSource::File(path), spec)
        }
    })
}

/// The options file with the `--layers` added, checked.
fn read_options(
    args: &CostmapArgs,
    describe: &dyn Fn(&[Issue]) -> String,
) -> Result<CostmapOptions, Failure> {
    let mut options = match &args.options {
        None => CostmapOptions::default(),
        Some(path) => {
            let doc = read_json(path, "options")?;
            deserialize_at::<CostmapOptions>(&doc, "/options")
                .map_err(|i| Failure::input(describe(&[i])))?
        }
    };
    for name in args
        .layers
        .iter()
        .map(|n| n.trim())
        .filter(|n| !n.is_empty())
    {
        let layer = Layer::from_name(name).ok_or_else(|| {
            Failure::input(format!(
                "--layers: unknown layer {name:?}: expected {}",
                Layer::ALL.map(Layer::name).join(", ")
            ))
        })?;
        if !options.layers.contains(&layer) {
            options.layers.push(layer);
        }
    }
    let issues = options.validate("/options");
    if !issues.is_empty() {
        return Err(Failure::input(describe(&issues)));
    }
    Ok(options)
}

/// costmap.tif, preview.png, legend.svg, layers/<name>.tif and stats.json
/// in `out`.
fn write_files(map: &Costmap, out: &Path) -> Result<(), Failure> {
    let layers_dir = out.join("layers");
    std::fs::create_dir_all(out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", out.display())))?;
    let write = |path: &Path, content: &[u8]| {
        std::fs::write(path, content)
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    // The GeoTIFF is mostly writing, the preview mostly arithmetic: both
    // at once.
    let (written, preview) = std::thread::scope(|scope| {
        let preview = scope.spawn(|| preview_png(map, crate::jobs::PREVIEW_MAX_SIDE));
        let written = write_tiff(&out.join("costmap.tif"), &|w| {
            map.write_geotiff(w).map(|()| true)
        });
        (written, preview.join())
    });
    written?;
    let preview = preview.map_err(|_| Failure::other("drawing the preview failed"))?;
    write(&out.join("preview.png"), &preview)?;
    write(&out.join("legend.svg"), legend_svg(map).as_bytes())?;
    let mut kept = Vec::new();
    if !map.layers.is_empty() {
        std::fs::create_dir_all(&layers_dir)
            .map_err(|e| Failure::other(format!("cannot create {}: {e}", layers_dir.display())))?;
    }
    for (layer, _) in &map.layers {
        let path = layers_dir.join(format!("{}.tif", layer.name()));
        if write_tiff(&path, &|w| map.write_layer_geotiff(*layer, w))? {
            kept.push(*layer);
        }
    }
    let doc = json!({
        "vehicle": map.vehicle,
        "params": map.params,
        "stats": map.stats,
        "warnings": map.warnings,
        "width": map.width,
        "height": map.height,
        "crs": map.crs,
        "layers": kept,
    });
    let mut text = serde_json::to_string_pretty(&doc).map_err(|e| Failure::other(e.to_string()))?;
    text.push('\n');
    write(&out.join("stats.json"), text.as_bytes())
}

/// A GeoTIFF written by `f` straight to its file (a 4000 × 4000 costmap is
/// 128 MB, not worth holding in memory a second time); removed when `f`
/// says it is not worth keeping (false).
fn write_tiff(
    path: &Path,
    f: &dyn Fn(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<bool>,
) -> Result<bool, Failure> {
    let failed =
        |e: std::io::Error| Failure::other(format!("cannot write {}: {e}", path.display()));
    let file = std::fs::File::create(path).map_err(failed)?;
    let mut w = std::io::BufWriter::with_capacity(1 << 20, file);
    let kept = f(&mut w).map_err(failed)?;
    w.flush().map_err(failed)?;
    if !kept {
        drop(w);
        let _ = std::fs::remove_file(path);
    }
    Ok(kept)
}

/// What was built, on stdout; its warnings on stderr.
fn print_summary(map: &Costmap, [dem_w, dem_h]: [usize; 2], started: Instant, out: &Path) {
    let s = &map.stats;
    let f = &s.class_fractions;
    let pct = |x: f64| format!("{:.1} %", x * 100.0);
    println!(
        "costmap {}×{} cells of {:.3} × {:.3} m (DEM {dem_w}×{dem_h}), vehicle {}",
        map.width,
        map.height,
        map.params.resolution_m[0],
        map.params.resolution_m[1],
        map.vehicle.name
    );
    println!(
        "classes: traversable {}, slope {}, step {}, enclosed {}, other {}, unknown {}",
        pct(f.traversable),
        pct(f.slope),
        pct(f.step),
        pct(f.enclosed),
        pct(f.other),
        pct(f.unknown)
    );
    match (s.cost_min, s.cost_max, s.cost_mean) {
        (Some(lo), Some(hi), Some(mean)) => println!(
            "cost {lo:.2} to {hi:.2} (mean {mean:.2}) on traversable cells; the weights allow \
             {} to {}",
            s.cost_range[0], s.cost_range[1]
        ),
        _ => println!("no traversable cell"),
    }
    println!(
        "built in {:.2} s -> {}",
        started.elapsed().as_secs_f64(),
        out.display()
    );
    for w in &map.warnings {
        eprintln!("warning: {w}");
    }
}
