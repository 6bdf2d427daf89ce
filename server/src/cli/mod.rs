//! Command-line interface: `terraplan survey`, `terraplan costmap` and
//! `terraplan route` run the same planners as the service on files; `terraplan dem-info` reads a
//! DEM as the service does. Exit status: 0 success, 2 invalid input (the
//! message names the fault), 1 any other failure.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use planner_core::cancel::{CancelToken, Cancelled};
use planner_core::geo::{Issue, Limits};
use planner_core::survey::{
    DEM_POINTER, NO_FLY_POINTER, PlanError, ROI_POINTER, SurveyRequest, plan_survey_over,
};
use planner_core::terrain::{Dem, DemInfo, DemLimits, TerrainError, read_dem};
use serde::Serialize;
use serde_json::{Value, json};

use crate::config::ServeConfig;

mod route;

#[derive(Parser)]
#[command(
    name = "terraplan",
    version,
    about = "Mission planning for UAV survey flocks and ground robots"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the HTTP service (REST API, OpenAPI document, API docs page).
    Serve(ServeConfig),
    /// Plan a photo survey of an area and write the mission files.
    Survey(SurveyArgs),
    /// Read a DEM (GeoTIFF, ESRI ASCII grid, SRTM .hgt) and print its
    /// metadata as JSON: size, resolution, CRS, bounds, height range.
    DemInfo(DemInfoArgs),
    /// Build the traversability costmap of a DEM for a ground vehicle and
    /// write costmap.tif (page 1 cost, page 2 class), preview.png,
    /// legend.svg, stats.json and layers/<name>.tif.
    Costmap(CostmapArgs),
    /// Plan the cheapest safe route for a ground robot across a costmap
    /// GeoTIFF and write route.json, route.geojson, route.csv and an
    /// ArduPilot Rover mission.waypoints.
    Route(route::RouteArgs),
    /// Reproducible experiments on embedded real data.
    #[command(subcommand)]
    Experiment(ExperimentCommand),
}

#[derive(Subcommand)]
enum ExperimentCommand {
    /// The thesis' flock experiment (§5.6): 12 cells, 3–8 UAVs, 10 starting
    /// formations, 60 trials, `competition` and `balanced` side by side;
    /// prints tables like thesis Tables 5.1–5.7.
    Flock {
        /// Also write trials.csv, uavs.csv and flocks.csv here.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
    },
}

#[derive(clap::Args)]
struct DemInfoArgs {
    /// The DEM file.
    #[arg(value_name = "FILE")]
    file: PathBuf,
    /// Horizontal CRS of the raster (`EPSG:32633` or `32633`): needed when
    /// the file does not say; overrides the file's.
    #[arg(long, value_name = "EPSG:CODE")]
    crs: Option<String>,
    /// Most pixels (width × height) accepted.
    #[arg(long, default_value_t = DemLimits::default().max_pixels)]
    max_pixels: u64,
}

/// What `dem-info` prints: the file, then the raster's metadata (the
/// fields `POST /api/v1/dems` answers with).
#[derive(Serialize)]
struct DemFileInfo<'a> {
    file_name: Option<String>,
    size_bytes: u64,
    #[serde(flatten)]
    info: &'a DemInfo,
}

#[derive(clap::Args)]
struct CostmapArgs {
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

#[derive(clap::Args)]
struct SurveyArgs {
    /// Region of interest: a GeoJSON Polygon, MultiPolygon, Feature or FeatureCollection (WGS84).
    #[arg(long, value_name = "FILE")]
    roi: PathBuf,
    /// No-fly zones (GeoJSON); may be given several times.
    #[arg(long = "no-fly", value_name = "FILE")]
    no_fly: Vec<PathBuf>,
    /// Survey parameters as JSON (same fields as the API request).
    #[arg(long, value_name = "FILE.json")]
    params: Option<PathBuf>,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Largest ROI accepted, km².
    #[arg(long, default_value_t = Limits::default().max_roi_area_km2)]
    max_roi_area_km2: f64,
    /// A DEM (GeoTIFF, ESRI ASCII grid, SRTM .hgt) to follow the terrain
    /// over (the params' `agl_tolerance_m`, `transit_clearance_m`, … apply).
    #[arg(long, value_name = "FILE")]
    dem: Option<PathBuf>,
    /// Horizontal CRS of the DEM (`EPSG:32633`), when the file does not say.
    #[arg(long, value_name = "EPSG:CODE", requires = "dem")]
    dem_crs: Option<String>,
    /// Stop planning after this many seconds (fractions allowed) and exit
    /// 1; no limit by default.
    #[arg(long, value_name = "SECONDS", value_parser = crate::config::parse_planning_timeout)]
    timeout_s: Option<f64>,
}

/// A failure with its exit status.
struct Failure {
    status: u8,
    message: String,
}

impl Failure {
    fn input(message: impl Into<String>) -> Self {
        Failure {
            status: 2,
            message: message.into(),
        }
    }
    fn other(message: impl Into<String>) -> Self {
        Failure {
            status: 1,
            message: message.into(),
        }
    }
}

pub fn run() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            // clap exits 2 on usage errors and 0 for --help/--version.
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    let result = match cli.command {
        Command::Serve(config) => serve(config),
        Command::Survey(args) => survey(&args),
        Command::DemInfo(args) => dem_info(&args),
        Command::Costmap(args) => costmap(&args),
        Command::Route(args) => route::route(&args),
        Command::Experiment(ExperimentCommand::Flock { out }) => experiment_flock(out.as_deref()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.status)
        }
    }
}

fn experiment_flock(out: Option<&Path>) -> Result<(), Failure> {
    let trials = crate::experiment::run_trials().map_err(Failure::other)?;
    print!("{}", crate::experiment::report(&trials));
    if let Some(dir) = out {
        for path in crate::experiment::write_csv(&trials, dir).map_err(Failure::other)? {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

fn serve(config: ServeConfig) -> Result<(), Failure> {
    crate::memory::tune_allocator();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::other(format!("cannot start the async runtime: {e}")))?;
    let result = runtime.block_on(crate::serve::serve(config));
    // A costmap run the shutdown cancelled may still be finishing a stage
    // on a blocking thread: do not wait for it.
    runtime.shutdown_timeout(std::time::Duration::from_secs(1));
    result.map_err(Failure::other)
}

fn read_json(path: &Path, what: &str) -> Result<Value, Failure> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Failure::input(format!("cannot read {what} file {}: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| {
        Failure::input(format!(
            "{what} file {} is not valid JSON: {e}",
            path.display()
        ))
    })
}

fn survey(args: &SurveyArgs) -> Result<(), Failure> {
    // Assemble the same request document the API takes, so both share one
    // parser and one set of JSON pointers.
    let mut doc = match &args.params {
        Some(p) => read_json(p, "params")?,
        None => json!({}),
    };
    let Some(obj) = doc.as_object_mut() else {
        return Err(Failure::input("the params file must hold a JSON object"));
    };
    for key in ["roi", "no_fly_zones"] {
        if obj.contains_key(key) {
            return Err(Failure::input(format!(
                "the params file may not contain {key:?}: give areas with --roi and --no-fly"
            )));
        }
    }
    obj.insert("roi".into(), read_json(&args.roi, "ROI")?);
    let zones = args
        .no_fly
        .iter()
        .map(|p| read_json(p, "no-fly"))
        .collect::<Result<Vec<_>, _>>()?;
    obj.insert("no_fly_zones".into(), Value::Array(zones));
    if obj.contains_key("dem_id") {
        return Err(Failure::input(
            "the params file may not contain \"dem_id\" (a DEM stored in the service): give the \
             DEM file with --dem",
        ));
    }
    let dem = match &args.dem {
        None => None,
        Some(path) => Some(
            read_dem_file(
                path,
                args.dem_crs.as_deref(),
                "--dem-crs",
                DemLimits::default(),
            )?
            .0,
        ),
    };

    let limits = Limits {
        max_roi_area_km2: args.max_roi_area_km2,
        ..Limits::default()
    };
    let describe = |issues: &[Issue]| describe_issues(issues, args);
    let req = SurveyRequest::from_document(&doc).map_err(|e| plan_failure(e, &describe))?;
    let token = match args.timeout_s {
        Some(s) => CancelToken::with_limit(std::time::Duration::from_secs_f64(s)),
        None => CancelToken::new(),
    };
    let plan = token
        .settle(token.scope(|| plan_survey_over(&req, &limits, dem.as_ref())))
        .map_err(|e| plan_failure(e, &describe))?;

    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", args.out.display())))?;
    let files = plan.files();
    let mut doc = serde_json::to_value(&plan).map_err(|e| Failure::other(e.to_string()))?;
    doc["files"] = json!(
        files
            .iter()
            .map(|f| json!({"name": f.name, "content_type": f.content_type}))
            .collect::<Vec<_>>()
    );
    let write = |name: &str, content: &str| {
        let path = args.out.join(name);
        std::fs::write(&path, content)
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    for f in &files {
        write(&f.name, &f.content)?;
    }
    let mut text = serde_json::to_string_pretty(&doc).map_err(|e| Failure::other(e.to_string()))?;
    text.push('\n');
    write("plan.json", &text)?;
    let s = &plan.stats;
    println!(
        "planned {} cells, {} lanes, {} UAV(s) ({} sorties, {}), {:.0} m, {} photos, makespan {:.0} \
         s, coverage {:.2} % -> {}",
        s.cell_count,
        s.lane_count,
        s.uav_count,
        s.sorties,
        s.assignment.name(),
        s.length_m,
        s.photos,
        s.makespan_s,
        s.coverage_ratio * 100.0,
        args.out.display()
    );
    for w in &plan.warnings {
        eprintln!("warning: {w}");
    }
    Ok(())
}

fn dem_info(args: &DemInfoArgs) -> Result<(), Failure> {
    let limits = DemLimits {
        max_pixels: args.max_pixels,
        ..DemLimits::default()
    };
    let (dem, file_name, size_bytes) =
        read_dem_file(&args.file, args.crs.as_deref(), "--crs", limits)?;
    let info = dem
        .info()
        .map_err(|e| Failure::input(format!("{}: {e}", args.file.display())))?;
    let doc = DemFileInfo {
        file_name,
        size_bytes,
        info: &info,
    };
    let text = serde_json::to_string_pretty(&doc).map_err(|e| Failure::other(e.to_string()))?;
    println!("{text}");
    Ok(())
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

fn costmap(args: &CostmapArgs) -> Result<(), Failure> {
    use planner_core::costmap::pipeline::{build_costmap_owned, check_against_dem};
    use planner_core::costmap::{
        CostmapError, CostmapOptions, Layer, Stage, VehiclePreset, VehicleSpec, legend_svg,
        preview_png,
    };

    let started = std::time::Instant::now();
    planner_core::buffer::keep_freed_grids();
    let presets = || {
        VehiclePreset::ALL
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    // The vehicle: a preset's name, or a file.
    let (source, spec) = match args.vehicle.as_deref() {
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
            let spec = crate::api::costmaps::deserialize_at::<VehicleSpec>(&doc, "/vehicle")
                .map_err(|i| {
                    Failure::input(describe_costmap_issues(
                        &[i],
                        &VehicleSource::File(path),
                        None,
                    ))
                })?;
            (VehicleSource::File(path), spec)
        }
    };
    let describe =
        |issues: &[Issue]| describe_costmap_issues(issues, &source, args.options.as_deref());
    let vehicle = spec
        .resolve("/vehicle")
        .map_err(|issues| Failure::input(describe(&issues)))?;

    let mut options = match &args.options {
        None => CostmapOptions::default(),
        Some(path) => {
            let doc = read_json(path, "options")?;
            crate::api::costmaps::deserialize_at::<CostmapOptions>(&doc, "/options")
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
                eprintln!("{}…", crate::costmap_jobs::stage_name(stage));
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

    let out = &args.out;
    let layers_dir = out.join("layers");
    std::fs::create_dir_all(out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", out.display())))?;
    let write = |path: &Path, content: &[u8]| {
        std::fs::write(path, content)
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    // GeoTIFFs straight to their files: a 4000 × 4000 costmap is 128 MB,
    // not worth holding in memory a second time.
    let tiff = |path: &Path,
                f: &dyn Fn(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<bool>|
     -> Result<bool, Failure> {
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
    };
    // The GeoTIFF is mostly writing, the preview mostly arithmetic: both
    // at once.
    let (written, preview) = std::thread::scope(|scope| {
        let preview = scope.spawn(|| preview_png(&map, crate::costmap_jobs::PREVIEW_MAX_SIDE));
        let written = tiff(&out.join("costmap.tif"), &|w| {
            map.write_geotiff(w).map(|()| true)
        });
        (written, preview.join())
    });
    written?;
    let preview = preview.map_err(|_| Failure::other("drawing the preview failed"))?;
    write(&out.join("preview.png"), &preview)?;
    write(&out.join("legend.svg"), legend_svg(&map).as_bytes())?;
    let mut kept = Vec::new();
    if !map.layers.is_empty() {
        std::fs::create_dir_all(&layers_dir)
            .map_err(|e| Failure::other(format!("cannot create {}: {e}", layers_dir.display())))?;
    }
    for (layer, _) in &map.layers {
        let path = layers_dir.join(format!("{}.tif", layer.name()));
        if tiff(&path, &|w| map.write_layer_geotiff(*layer, w))? {
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
    write(&out.join("stats.json"), text.as_bytes())?;

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
    Ok(())
}

/// Read a DEM file as the service reads an upload: (DEM, file name, size).
/// `crs_flag` names the option that gave `crs`, for messages.
fn read_dem_file(
    file: &Path,
    crs: Option<&str>,
    crs_flag: &str,
    limits: DemLimits,
) -> Result<(Dem, Option<String>, u64), Failure> {
    let path = file.display();
    let crs = crs
        .map(crate::api::dems::parse_epsg)
        .transpose()
        .map_err(|m| Failure::input(format!("{crs_flag}: {m}")))?;
    let bytes = std::fs::read(file)
        .map_err(|e| Failure::input(format!("cannot read DEM file {path}: {e}")))?;
    let file_name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    let describe = |e: TerrainError| {
        Failure::input(match e {
            TerrainError::UnknownCrs(why) => format!(
                "{path}: the raster's coordinate reference system cannot be determined ({why}); \
                 give it with {crs_flag}, e.g. {crs_flag} EPSG:32633"
            ),
            TerrainError::Invalid(m) => format!("{path} cannot be read as a DEM: {m}"),
            other => format!("{path}: {other}"),
        })
    };
    let dem = read_dem(&bytes, file_name.as_deref(), crs, &limits).map_err(describe)?;
    Ok((dem, file_name, bytes.len() as u64))
}

fn plan_failure(e: PlanError, describe: &dyn Fn(&[Issue]) -> String) -> Failure {
    match e {
        PlanError::Invalid(issues) => Failure::input(describe(&issues)),
        PlanError::Internal(m) => Failure::other(format!("planning failed: {m}")),
        PlanError::Cancelled(Cancelled::TimedOut { limit }) => Failure::other(format!(
            "the survey took longer than {} s (--timeout-s) and was stopped: survey a smaller \
             area, with fewer vertices or no-fly zones or a wider line spacing, or allow more time",
            limit.as_secs_f64()
        )),
        PlanError::Cancelled(c) => Failure::other(format!("planning stopped: {c}")),
    }
}

/// Issues with their pointers translated to the file they came from, e.g.
/// `field.geojson#/coordinates/0: ring self-intersects …`.
fn describe_issues(issues: &[Issue], args: &SurveyArgs) -> String {
    let locate = |ptr: &str| -> String {
        if let Some(rest) = ptr.strip_prefix(ROI_POINTER) {
            return format!("{}#{rest}", args.roi.display());
        }
        if let Some(rest) = ptr.strip_prefix(NO_FLY_POINTER) {
            let rest = rest.trim_start_matches('/');
            let (idx, tail) = rest.split_once('/').unwrap_or((rest, ""));
            if let Some(p) = idx.parse::<usize>().ok().and_then(|i| args.no_fly.get(i)) {
                let tail = if tail.is_empty() {
                    String::new()
                } else {
                    format!("/{tail}")
                };
                return format!("{}#{tail}", p.display());
            }
            return "no-fly zones".to_string();
        }
        if ptr == DEM_POINTER
            && let Some(dem) = &args.dem
        {
            return format!("DEM {}", dem.display());
        }
        let file = args
            .params
            .as_ref()
            .map_or("params".to_string(), |p| p.display().to_string());
        format!("{file}#{ptr}")
    };
    list_issues(issues, locate)
}

/// "invalid input: …" with each issue on its own line, its pointer turned
/// into a place the user knows by `locate`.
fn list_issues(issues: &[Issue], locate: impl Fn(&str) -> String) -> String {
    let lines: Vec<String> = planner_core::geo::cap_issues(issues.to_vec())
        .iter()
        .map(|i| format!("{}: {}", locate(&i.pointer), i.message))
        .collect();
    if lines.len() == 1 {
        format!("invalid input: {}", lines[0])
    } else {
        format!("invalid input:\n  {}", lines.join("\n  "))
    }
}
