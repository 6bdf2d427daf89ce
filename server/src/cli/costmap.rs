//! `terraplan costmap`: the traversability costmap of a DEM file, written
//! as the service serves it (GeoTIFF, preview, legend, stats, layers).
//!
//! A GeoTIFF DEM of more than [`TILED_ABOVE_CELLS`] cells (or any DEM with
//! `--tile-size`) is mapped tile by tile
//! ([`planner_core::costmap::build_costmap_tiled`]): the DEM is read a
//! window at a time from the file, the costmap and its layers are written
//! as tiled GeoTIFFs a tile at a time, so memory is bounded by the tile
//! size, not the map's; the result is the same as the whole-raster run's.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use planner_core::costmap::pipeline::{build_costmap_owned, check_against_dem};
use planner_core::costmap::tiled_tiff::TiledTiffFiles;
use planner_core::costmap::{
    CostmapError, CostmapOptions, CostmapStats, Layer, ResolvedParams, Stage, TiledError,
    TiledOptions, Vehicle, VehiclePreset, VehicleSpec, build_costmap_tiled, legend_svg_of,
    preview_png,
};
use planner_core::geo::{Issue, deserialize_at};
use planner_core::terrain::{DemLimits, DemWindows, GeoTiffWindows, RasterWindows, TerrainError};
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
    /// Most pixels (width × height) accepted. Default 64 000 000 for a
    /// DEM read whole, 1 000 000 000 for one mapped tile by tile.
    #[arg(long)]
    max_pixels: Option<u64>,
    /// Map tile by tile, tiles of N × N working cells (a multiple of 16,
    /// 16 to 8192): memory is bounded by the tiles (a GeoTIFF DEM is read
    /// a window at a time; other formats are still read whole). Without
    /// it, GeoTIFF DEMs of more than 64 000 000 cells are mapped in tiles
    /// of 1024.
    #[arg(long, value_name = "N")]
    tile_size: Option<usize>,
    /// Where a tiled run keeps its scratch file of classes (one byte per
    /// working cell, removed at the end); default the output directory.
    #[arg(long, value_name = "DIR")]
    scratch_dir: Option<PathBuf>,
}

/// GeoTIFF DEMs with more cells than this are mapped tile by tile (the
/// largest DEM the whole-raster run accepts by default).
pub(super) const TILED_ABOVE_CELLS: u64 = 64_000_000;

/// The tile side of an automatic tiled run.
const DEFAULT_TILE: usize = 1024;

/// Most cells of a DEM mapped tile by tile, unless `--max-pixels` says.
const TILED_MAX_PIXELS: u64 = 1_000_000_000;

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
    if let Some(n) = args.tile_size
        && (!n.is_multiple_of(16) || !(16..=8192).contains(&n))
    {
        return Err(Failure::input(format!(
            "--tile-size {n}: tiles are a multiple of 16 cells, from 16 to 8192"
        )));
    }

    let limits = DemLimits {
        max_pixels: args.max_pixels.unwrap_or(DemLimits::default().max_pixels),
        ..DemLimits::default()
    };
    let tiled_limits = DemLimits {
        max_pixels: args.max_pixels.unwrap_or(TILED_MAX_PIXELS),
        ..DemLimits::default()
    };
    // Without --tile-size, a GeoTIFF the window reader refuses (e.g. one
    // strip for a whole large image) is left to the whole-raster reader,
    // which says what it thinks of it.
    let windows = match open_geotiff_windows(&args.dem, args.crs.as_deref(), &tiled_limits) {
        Ok(w) => w,
        Err(_) if args.tile_size.is_none() => None,
        Err(e) => return Err(e),
    };
    let tile = match (&windows, args.tile_size) {
        (_, Some(n)) => Some(n),
        (Some(w), None) => {
            let g = w.grid();
            ((g.width as u64).saturating_mul(g.height as u64) > TILED_ABOVE_CELLS)
                .then_some(DEFAULT_TILE)
        }
        (None, None) => None,
    };
    let landcover = read_landcover(args, &options, limits.clone())?;
    if let Some(tile) = tile {
        return costmap_tiled(
            args, windows, tile, &vehicle, &options, landcover, &describe, started,
        );
    }
    let (dem, _, _) = read_dem_file(&args.dem, args.crs.as_deref(), "--crs", limits)?;
    let issues = check_against_dem(&dem, &vehicle, &options, "/options");
    if !issues.is_empty() {
        return Err(Failure::input(describe(&issues)));
    }
    let (dem_w, dem_h) = (dem.width, dem.height);

    let progress = stage_printer();
    let map = build_costmap_owned(dem, &vehicle, &options, landcover.as_ref(), &progress).map_err(
        |e| match e {
            CostmapError::Invalid(issues) => Failure::input(describe(&issues)),
            CostmapError::Cancelled => Failure::other("the costmap was cancelled"),
        },
    )?;
    write_files(&map, &args.out)?;
    let summary = Summary {
        width: map.width,
        height: map.height,
        params: &map.params,
        vehicle: &map.vehicle,
        stats: &map.stats,
        warnings: &map.warnings,
    };
    print_summary(&summary, [dem_w, dem_h], started, &args.out, None);
    Ok(())
}

/// The options' land-cover raster, read whole (relative to the options
/// file).
fn read_landcover(
    args: &CostmapArgs,
    options: &CostmapOptions,
    limits: DemLimits,
) -> Result<Option<planner_core::terrain::Dem>, Failure> {
    Ok(match &options.landcover {
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
    })
}

/// The stage names on stderr as they begin, when it is a terminal.
fn stage_printer() -> impl Fn(Stage, f64) -> bool + Sync {
    let show_progress = std::io::stderr().is_terminal();
    let last_stage = std::sync::Mutex::new(None::<Stage>);
    move |stage: Stage, _done: f64| -> bool {
        if show_progress {
            let mut last = last_stage.lock().unwrap_or_else(|p| p.into_inner());
            if *last != Some(stage) {
                *last = Some(stage);
                eprintln!("{}…", crate::jobs::stage_name(stage));
            }
        }
        true
    }
}

/// The DEM as a GeoTIFF read a window at a time; `None` when the file is
/// not a TIFF (other formats are read whole).
fn open_geotiff_windows(
    path: &Path,
    crs: Option<&str>,
    limits: &DemLimits,
) -> Result<Option<GeoTiffWindows>, Failure> {
    use std::io::Read;
    let shown = path.display();
    let cannot = |e: std::io::Error| Failure::input(format!("cannot read DEM file {shown}: {e}"));
    let mut file = std::fs::File::open(path).map_err(cannot)?;
    let mut magic = [0u8; 4];
    let got = file.read(&mut magic).map_err(cannot)?;
    if got < 4 || !matches!(&magic, b"II*\0" | b"MM\0*" | b"II+\0" | b"MM\0+") {
        return Ok(None);
    }
    let crs = crs
        .map(crate::api::dems::parse_epsg)
        .transpose()
        .map_err(|m| Failure::input(format!("--crs: {m}")))?;
    GeoTiffWindows::open(file, crs, limits)
        .map(Some)
        .map_err(|e| Failure::input(describe_dem_fault(path, e)))
}

/// A DEM's fault as `read_dem_file` words it.
fn describe_dem_fault(path: &Path, e: TerrainError) -> String {
    let path = path.display();
    match e {
        TerrainError::UnknownCrs(why) => format!(
            "{path}: the raster's coordinate reference system cannot be determined ({why}); \
             give it with --crs, e.g. --crs EPSG:32633"
        ),
        TerrainError::Invalid(m) => format!("{path} cannot be read as a DEM: {m}"),
        other => format!("{path}: {other}"),
    }
}

/// The costmap of the DEM tile by tile: read from `windows` (a GeoTIFF
/// read a window at a time) or else from the DEM read whole; the files
/// written as the tiles come.
#[allow(clippy::too_many_arguments)]
fn costmap_tiled(
    args: &CostmapArgs,
    windows: Option<GeoTiffWindows>,
    tile: usize,
    vehicle: &Vehicle,
    options: &CostmapOptions,
    landcover: Option<planner_core::terrain::Dem>,
    describe: &dyn Fn(&[Issue]) -> String,
    started: Instant,
) -> Result<(), Failure> {
    let whole;
    let source: &dyn RasterWindows = match &windows {
        Some(w) => w,
        None => {
            let limits = DemLimits {
                max_pixels: args.max_pixels.unwrap_or(DemLimits::default().max_pixels),
                ..DemLimits::default()
            };
            whole = read_dem_file(&args.dem, args.crs.as_deref(), "--crs", limits)?.0;
            &DemWindows::new(&whole)
        }
    };
    let (dem_w, dem_h) = (source.grid().width, source.grid().height);
    let out = &args.out;
    let layers_dir = out.join("layers");
    create_dir(out)?;
    let kept: Vec<Layer> = Layer::ALL
        .into_iter()
        .filter(|l| options.layers.contains(l))
        .collect();
    if !kept.is_empty() {
        create_dir(&layers_dir)?;
    }
    let create = |path: &Path| {
        std::fs::File::create(path)
            .map(|f| std::io::BufWriter::with_capacity(1 << 20, f))
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    let costmap_path = out.join("costmap.tif");
    let layer_paths: Vec<(Layer, PathBuf)> = kept
        .iter()
        .map(|l| (*l, layers_dir.join(format!("{}.tif", l.name()))))
        .collect();
    let mut files = TiledTiffFiles::new(
        create(&costmap_path)?,
        layer_paths
            .iter()
            .map(|(l, p)| create(p).map(|w| (*l, w)))
            .collect::<Result<Vec<_>, _>>()?,
    );
    let tiled = TiledOptions {
        tile,
        scratch_dir: args.scratch_dir.clone().unwrap_or_else(|| out.clone()),
        preview_max_side: crate::jobs::PREVIEW_MAX_SIDE,
    };
    let progress = stage_printer();
    let result = build_costmap_tiled(
        source,
        vehicle,
        options,
        landcover.as_ref(),
        &tiled,
        &progress,
        &mut files,
    );
    let map = match result {
        Ok(map) => map,
        Err(e) => {
            // Nothing half-written is left behind.
            drop(files);
            let _ = std::fs::remove_file(&costmap_path);
            for (_, p) in &layer_paths {
                let _ = std::fs::remove_file(p);
            }
            return Err(match e {
                TiledError::Costmap(CostmapError::Invalid(issues)) => {
                    Failure::input(describe(&issues))
                }
                TiledError::Costmap(CostmapError::Cancelled) => {
                    Failure::other("the costmap was cancelled")
                }
                TiledError::Read(e) => Failure::input(describe_dem_fault(&args.dem, e)),
                other => Failure::other(format!("the tiled costmap failed: {other}")),
            });
        }
    };
    files
        .finish()
        .and_then(|(mut c, layers)| {
            c.flush()?;
            for (_, mut w) in layers {
                w.flush()?;
            }
            Ok(())
        })
        .map_err(|e| Failure::other(format!("cannot write {}: {e}", costmap_path.display())))?;
    write_preview_and_legend(out, &map.preview_png, &map.stats, &map.vehicle.name)?;
    let summary = Summary {
        width: map.width,
        height: map.height,
        params: &map.params,
        vehicle: &map.vehicle,
        stats: &map.stats,
        warnings: &map.warnings,
    };
    let doc = json!({
        "vehicle": map.vehicle,
        "params": map.params,
        "stats": map.stats,
        "warnings": map.warnings,
        "width": map.width,
        "height": map.height,
        "crs": map.crs,
        "layers": kept,
        "tiles": {
            "size": map.tile,
            "halo_surface": map.halos.surface,
            "halo_inflation": map.halos.inflation,
        },
    });
    write_stats(out, &doc)?;
    print_summary(&summary, [dem_w, dem_h], started, out, Some(map.tile));
    Ok(())
}

fn create_dir(dir: &Path) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", dir.display())))
}

/// preview.png (as drawn) and legend.svg (of `stats`) in `out`.
fn write_preview_and_legend(
    out: &Path,
    preview_png: &[u8],
    stats: &CostmapStats,
    vehicle_name: &str,
) -> Result<(), Failure> {
    let write = |path: &Path, content: &[u8]| {
        std::fs::write(path, content)
            .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
    };
    write(&out.join("preview.png"), preview_png)?;
    write(
        &out.join("legend.svg"),
        legend_svg_of(stats, vehicle_name).as_bytes(),
    )
}

/// stats.json in `out`.
fn write_stats(out: &Path, doc: &serde_json::Value) -> Result<(), Failure> {
    let mut text = serde_json::to_string_pretty(doc).map_err(|e| Failure::other(e.to_string()))?;
    text.push('\n');
    let path = out.join("stats.json");
    std::fs::write(&path, text)
        .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
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
fn write_files(map: &planner_core::costmap::Costmap, out: &Path) -> Result<(), Failure> {
    let layers_dir = out.join("layers");
    std::fs::create_dir_all(out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", out.display())))?;
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
    write_preview_and_legend(out, &preview, &map.stats, &map.vehicle.name)?;
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
    write_stats(out, &doc)
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

/// What a summary tells of a costmap (whole or tiled).
struct Summary<'a> {
    width: usize,
    height: usize,
    params: &'a ResolvedParams,
    vehicle: &'a Vehicle,
    stats: &'a CostmapStats,
    warnings: &'a [String],
}

/// What was built, on stdout; its warnings on stderr.
fn print_summary(
    map: &Summary<'_>,
    [dem_w, dem_h]: [usize; 2],
    started: Instant,
    out: &Path,
    tile: Option<usize>,
) {
    let s = map.stats;
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
    let tiles = tile.map_or(String::new(), |t| format!(" in tiles of {t}"));
    println!(
        "built{tiles} in {:.2} s -> {}",
        started.elapsed().as_secs_f64(),
        out.display()
    );
    for w in map.warnings {
        eprintln!("warning: {w}");
    }
}
