//! `terraplan route`: the cheapest safe route across a costmap GeoTIFF
//! (as `terraplan costmap` or the service writes it), and optionally a
//! D* Lite replan after blocking areas, with the files the service serves.

use std::path::{Path, PathBuf};
use std::time::Instant;

use geo_types::Polygon;
use planner_core::export::ground_route::{route_csv, route_geojson, rover_mission};
use planner_core::export::write_waypoints;
use planner_core::route::changes::{self, CellChanges, ChangeError, ChangedArea};
use planner_core::route::{
    ArcCost, BigRouteError, CoarseToFine, CoarseToFineOptions, DStarLite, Endpoint, MapRoute,
    MapRouteError, Position, RouteError, RouteMap, RouteOptions, WindowedMap, WindowedRouteError,
    astar,
};
use planner_core::terrain::{DemLimits, GeoTiffWindows, RasterWindows};
use serde_json::{Map, Value, json};

use super::common::{Failure, list_issues, read_dem_file, read_json};

#[derive(clap::Args)]
pub(super) struct RouteArgs {
    /// The costmap GeoTIFF (page 1 cost, page 2 class), as written by
    /// `terraplan costmap` or served as `costmap.tif`.
    #[arg(value_name = "COSTMAP.tif")]
    costmap: PathBuf,
    /// Start: `LON,LAT` (WGS84 degrees) or `utm:EASTING,NORTHING` in the
    /// UTM zone of the costmap's centre.
    #[arg(long, value_name = "LON,LAT", allow_hyphen_values = true)]
    from: String,
    /// Goal, as `--from`.
    #[arg(long, value_name = "LON,LAT", allow_hyphen_values = true)]
    to: String,
    /// Output directory (created if missing): route.json, route.geojson,
    /// route.csv, mission.waypoints (and replanned/ with `--block`).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The DEM the costmap was built from, for heights, 3D length and
    /// slopes along the route.
    #[arg(long, value_name = "FILE")]
    dem: Option<PathBuf>,
    /// Horizontal CRS of the DEM, when the file does not say.
    #[arg(long, value_name = "EPSG:CODE", requires = "dem")]
    dem_crs: Option<String>,
    /// Arc cost rule: `integrated` (step length × mean cost, as
    /// scikit-image's MCP_Geometric) or `thesis` (Algorithm 1).
    #[arg(long, value_name = "RULE", default_value = "integrated")]
    arc_cost: String,
    /// d_max of the `thesis` rule.
    #[arg(long, value_name = "D_MAX", default_value_t = ArcCost::DEFAULT_D_MAX)]
    d_max: f64,
    /// Heuristic weight ≥ 1: cost ≤ epsilon × the optimum, faster.
    #[arg(long, default_value_t = 1.0)]
    epsilon: f64,
    /// Keep the turning points of the cell path instead of smoothing.
    #[arg(long)]
    no_smooth: bool,
    /// Ground speed for the rover mission (DO_CHANGE_SPEED), m/s.
    #[arg(long, value_name = "M/S")]
    speed: Option<f64>,
    /// Areas to block after planning (GeoJSON polygons, WGS84); may be
    /// given several times. The route is then replanned from the start by
    /// D* Lite, reusing its search, and the replan written to
    /// DIR/replanned/ with its timing next to a search from scratch.
    #[arg(long, value_name = "FILE.geojson")]
    block: Vec<PathBuf>,
    /// Where the robot is when the areas are blocked (as `--from`; default
    /// the start): the replan goes from there to the goal.
    #[arg(
        long,
        value_name = "LON,LAT",
        allow_hyphen_values = true,
        requires = "block"
    )]
    replan_from: Option<String>,
    /// Most pixels (width × height) accepted: by default 64 M for a
    /// costmap read whole (plain A*, `--dem`, `--block`) and 4 G for one
    /// read by windows (coarse to fine).
    #[arg(long)]
    max_pixels: Option<u64>,
    /// Plan coarse to fine whatever the costmap's size: A* on 16 × 16
    /// block minima, then A* in a corridor around that route, widened
    /// until the route is proven optimal for the whole map. Without
    /// `--dem` the costmap is read a window at a time (no heights, the
    /// waypoints are the path's turning points); not with `--block`.
    #[arg(long, conflicts_with = "block")]
    coarse_to_fine: bool,
    /// Plan coarse to fine (as `--coarse-to-fine`) when the costmap has
    /// more cells than this.
    #[arg(long, value_name = "CELLS", default_value_t = COARSE_TO_FINE_ABOVE)]
    coarse_to_fine_above: u64,
    /// Most cells a coarse-to-fine corridor may cover (its search holds
    /// up to 13 bytes a cell: 2.6 GB at the default): beyond it the route
    /// found so far is written with how far from optimal it may be.
    #[arg(long, value_name = "CELLS", default_value_t = MAX_CORRIDOR_CELLS)]
    max_corridor_cells: u64,
}

/// Costmaps above this many cells (4000 × 4000) are planned coarse to
/// fine by default: plain A* holds 16 bytes for every cell.
const COARSE_TO_FINE_ABOVE: u64 = 16_000_000;

/// Most cells of a coarse-to-fine corridor, by default.
const MAX_CORRIDOR_CELLS: u64 = 200_000_000;

/// Most cells of a costmap read by windows, by default.
const WINDOWED_MAX_PIXELS: u64 = 4_000_000_000;

/// `LON,LAT` or `utm:E,N`.
fn parse_position(text: &str, flag: &str) -> Result<Position, Failure> {
    let bad = |why: &str| Failure::input(format!("{flag} {text:?}: {why}"));
    let (utm, numbers) = match text.trim().strip_prefix("utm:") {
        Some(rest) => (true, rest),
        None => (false, text.trim()),
    };
    let parts: Vec<&str> = numbers.split(',').map(str::trim).collect();
    let [a, b] = parts[..] else {
        return Err(bad("expected two numbers separated by a comma"));
    };
    let num = |s: &str| {
        s.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| bad(&format!("{s:?} is not a finite number")))
    };
    let (a, b) = (num(a)?, num(b)?);
    Ok(if utm {
        Position::Utm { utm: [a, b] }
    } else {
        Position::LonLat([a, b])
    })
}

fn map_failure(e: MapRouteError, args: &RouteArgs) -> Failure {
    let flag = |end: Endpoint| match end {
        Endpoint::Start => "--from",
        Endpoint::Goal => "--to",
    };
    match e {
        MapRouteError::Outside { end, .. }
        | MapRouteError::Blocked { end, .. }
        | MapRouteError::InvalidPosition { end, .. } => {
            Failure::input(format!("{}: {e}", flag(end)))
        }
        MapRouteError::CostmapFile(_)
        | MapRouteError::Grid(_)
        | MapRouteError::RotatedGrid
        | MapRouteError::LayerSize { .. } => {
            Failure::input(format!("{}: {e}", args.costmap.display()))
        }
        MapRouteError::DemMismatch(_) => Failure::input(format!(
            "--dem {}: {e}",
            args.dem.as_deref().unwrap_or(Path::new("")).display()
        )),
        MapRouteError::Unreachable | MapRouteError::InvalidArea { .. } => {
            Failure::input(e.to_string())
        }
        MapRouteError::Search(inner) => match inner {
            planner_core::route::RouteError::InvalidOptions(_) => Failure::input(inner.to_string()),
            other => Failure::other(other.to_string()),
        },
        MapRouteError::Crs(_) | MapRouteError::Heights(_) => Failure::other(e.to_string()),
    }
}

pub(super) fn route(args: &RouteArgs) -> Result<(), Failure> {
    let arc_cost = match args.arc_cost.as_str() {
        "integrated" => ArcCost::Integrated,
        "thesis" => ArcCost::Thesis { d_max: args.d_max },
        other => {
            return Err(Failure::input(format!(
                "--arc-cost {other:?}: expected integrated or thesis"
            )));
        }
    };
    let options = RouteOptions {
        arc_cost,
        epsilon: args.epsilon,
        smooth: !args.no_smooth,
        max_expansions: None,
    };
    if let Err(issues) = options.validate().map_err(|e| e.to_string()) {
        return Err(Failure::input(issues));
    }
    if let Some(s) = args.speed
        && !(s.is_finite() && s > 0.0)
    {
        return Err(Failure::input(format!("--speed {s}: must be a number > 0")));
    }
    let start = parse_position(&args.from, "--from")?;
    let goal = parse_position(&args.to, "--to")?;
    let mut blocked = Vec::new();
    for path in &args.block {
        let doc = read_json(path, "blocked area")?;
        let parsed = planner_core::geo::parse_polygons(&doc, "")
            .map_err(|issues| list_issues(&issues, |ptr| format!("{}#{ptr}", path.display())));
        blocked.extend(
            parsed
                .map_err(Failure::input)?
                .into_iter()
                .map(|p| (p.polygon, path.as_path())),
        );
    }

    let limits = DemLimits {
        max_pixels: args.max_pixels.unwrap_or(DemLimits::default().max_pixels),
        ..DemLimits::default()
    };
    if let Some(cells) = coarse_to_fine_size(args)? {
        let c2f = CoarseToFineOptions {
            max_corridor_cells: args.max_corridor_cells,
            ..CoarseToFineOptions::default()
        };
        return route_coarse_to_fine(args, &start, &goal, &options, &c2f, &limits, cells);
    }
    let bytes = std::fs::read(&args.costmap).map_err(|e| {
        Failure::input(format!(
            "cannot read costmap file {}: {e}",
            args.costmap.display()
        ))
    })?;
    let dem = match &args.dem {
        Some(path) => {
            Some(read_dem_file(path, args.dem_crs.as_deref(), "--dem-crs", limits.clone())?.0)
        }
        None => None,
    };
    let loaded = Instant::now();
    let mut map = RouteMap::from_costmap_geotiff(&bytes, dem.as_ref(), &limits)
        .map_err(|e| map_failure(e, args))?;
    drop((bytes, dem));
    let load_ms = loaded.elapsed().as_secs_f64() * 1e3;
    let planned = map
        .plan(&start, &goal, &options, &|| false)
        .map_err(|e| map_failure(e, args))?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", args.out.display())))?;
    let request =
        json!({"start": start, "goal": goal, "options": options, "speed_m_s": args.speed});
    write_route(&args.out, &planned, &request, args.speed)?;
    let g = map.grid();
    println!(
        "route {:.1} m ({} waypoints, 3D {}), cost {:.1}, {} cells expanded in {:.1} ms \
         on {}×{} cells (read in {load_ms:.0} ms) -> {}",
        planned.length_2d_m,
        planned.waypoints.len(),
        planned
            .length_3d_m
            .map_or("unknown".to_string(), |l| format!("{l:.1} m")),
        planned.cost,
        planned.expanded,
        planned.search_ms,
        g.width(),
        g.height(),
        args.out.display()
    );

    if blocked.is_empty() {
        return Ok(());
    }
    replan(
        args, &mut map, &planned, &start, &goal, &options, &blocked, request,
    )
}

/// The costmap's cells when it is to be planned coarse to fine (forced,
/// or above the size), read off its header; `None` for plain A*.
fn coarse_to_fine_size(args: &RouteArgs) -> Result<Option<u64>, Failure> {
    if !args.block.is_empty() {
        return Ok(None);
    }
    let windows = open_windows(args, 1, 1)?;
    let cells = windows.grid().width as u64 * windows.grid().height as u64;
    Ok((args.coarse_to_fine || cells > args.coarse_to_fine_above).then_some(cells))
}

fn open_windows(args: &RouteArgs, page: usize, band: usize) -> Result<GeoTiffWindows, Failure> {
    let path = &args.costmap;
    let file = std::fs::File::open(path)
        .map_err(|e| Failure::input(format!("cannot read costmap file {}: {e}", path.display())))?;
    let limits = DemLimits {
        max_pixels: args.max_pixels.unwrap_or(WINDOWED_MAX_PIXELS),
        ..DemLimits::default()
    };
    GeoTiffWindows::open_band(file, page, band, None, &limits)
        .map_err(|e| Failure::input(format!("{}: {e}", path.display())))
}

fn big_failure(e: WindowedRouteError, args: &RouteArgs) -> Failure {
    match e {
        WindowedRouteError::Map(e) => map_failure(e, args),
        WindowedRouteError::Search(BigRouteError::Route(RouteError::Unreachable)) => {
            map_failure(MapRouteError::Unreachable, args)
        }
        WindowedRouteError::Search(BigRouteError::Route(e)) => {
            map_failure(MapRouteError::Search(e), args)
        }
        WindowedRouteError::Search(BigRouteError::Source(e)) => {
            Failure::input(format!("{}: {e}", args.costmap.display()))
        }
        WindowedRouteError::Search(e @ BigRouteError::CorridorLimit { .. }) => {
            Failure::other(e.to_string())
        }
    }
}

/// A route planned coarse to fine: on the costmap read by windows, or read
/// whole when `--dem` asks for heights along it.
fn route_coarse_to_fine(
    args: &RouteArgs,
    start: &Position,
    goal: &Position,
    options: &RouteOptions,
    c2f: &CoarseToFineOptions,
    limits: &DemLimits,
    cells: u64,
) -> Result<(), Failure> {
    if options.epsilon != 1.0 {
        return Err(Failure::input(
            "coarse-to-fine routes are proven optimal: --epsilon must be 1 \
             (the costmap is planned coarse to fine above --coarse-to-fine-above cells)",
        ));
    }
    let loaded = Instant::now();
    let (planned, found, how) = if let Some(path) = &args.dem {
        let dem = read_dem_file(path, args.dem_crs.as_deref(), "--dem-crs", limits.clone())?.0;
        let bytes = std::fs::read(&args.costmap).map_err(|e| {
            Failure::input(format!(
                "cannot read costmap file {}: {e}",
                args.costmap.display()
            ))
        })?;
        let map = RouteMap::from_costmap_geotiff(&bytes, Some(&dem), limits)
            .map_err(|e| map_failure(e, args))?;
        drop((bytes, dem));
        let (planned, found) = map
            .plan_coarse_to_fine(start, goal, options, c2f, &|| false)
            .map_err(|e| big_failure(e, args))?;
        (planned, found, "read whole for the DEM's heights")
    } else {
        let costs = open_windows(args, 1, 1)?;
        // The class codes name what a blocked endpoint is on: page 2, or
        // band 2 of costmaps written before the class page.
        let classes = open_windows(args, 2, 1)
            .or_else(|_| open_windows(args, 1, 2))
            .ok();
        let map = WindowedMap::new(&costs, classes.as_ref().map(|c| c as &dyn RasterWindows))
            .map_err(|e| map_failure(e, args))?;
        let (planned, found) = map
            .plan(start, goal, options, c2f, &|| false)
            .map_err(|e| big_failure(e, args))?;
        (planned, found, "read by windows")
    };
    let total_ms = loaded.elapsed().as_secs_f64() * 1e3;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", args.out.display())))?;
    let request = json!({
        "start": start, "goal": goal, "options": options, "speed_m_s": args.speed,
        "search": search_report(&found),
    });
    write_route(&args.out, &planned, &request, args.speed)?;
    let s = &found.stats;
    let proof = if found.proven_optimal {
        "proven optimal".to_string()
    } else {
        format!(
            "NOT proven optimal: within {:.3} % of the optimum (lower bound {:.1})",
            100.0 * found.gap(),
            found.lower_bound
        )
    };
    println!(
        "route {:.1} m ({} waypoints), cost {:.1}, {proof}; coarse to fine on {} cells ({how}): \
         {} corridor(s), last {} blocks each side ({} cells, {} touched), {} cells expanded, \
         search state ≤ {:.0} MiB, {:.0} ms in all -> {}",
        planned.length_2d_m,
        planned.waypoints.len(),
        planned.path_cost,
        cells,
        s.corridors,
        s.halfwidth,
        s.corridor_cells,
        s.cells_touched,
        s.expanded,
        s.peak_bytes as f64 / (1024.0 * 1024.0),
        total_ms,
        args.out.display()
    );
    Ok(())
}

/// What route.json says of a coarse-to-fine search.
fn search_report(found: &CoarseToFine) -> Value {
    json!({
        "method": "coarse_to_fine",
        "proven_optimal": found.proven_optimal,
        "lower_bound": found.lower_bound,
        "gap": found.gap(),
        "stats": found.stats,
    })
}

/// Block `areas` (each with the file it came from), then replan from the
/// start with D* Lite reusing its first search, and time a from-scratch
/// A* on the changed map beside it.
#[allow(clippy::too_many_arguments)]
fn replan(
    args: &RouteArgs,
    map: &mut RouteMap,
    first: &MapRoute,
    start: &Position,
    goal: &Position,
    options: &RouteOptions,
    areas: &[(Polygon<f64>, &Path)],
    mut request: Value,
) -> Result<(), Failure> {
    let fail = |e| map_failure(e, args);
    if options.epsilon != 1.0 {
        return Err(Failure::input(
            "--block replans with D* Lite, which is optimal: --epsilon must be 1",
        ));
    }
    let s = map.locate(start, Endpoint::Start).map_err(fail)?;
    let g = map.locate(goal, Endpoint::Goal).map_err(fail)?;
    let robot = match &args.replan_from {
        None => s,
        Some(text) => {
            let p = parse_position(text, "--replan-from")?;
            map.locate(&p, Endpoint::Start)
                .map_err(|e| Failure::input(format!("--replan-from: {e}")))?
        }
    };
    let polygons: Vec<&Polygon<f64>> = areas.iter().map(|(p, _)| p).collect();
    let blocked = CellChanges::rasterise(map, &[], &polygons).map_err(|e| match e {
        ChangeError::Areas(faults) => match faults.first() {
            Some(f) if let ChangedArea::Blocked(index) = f.area => {
                fail(MapRouteError::InvalidArea {
                    index,
                    reason: f.reason.clone(),
                })
            }
            _ => Failure::other(ChangeError::Areas(faults).to_string()),
        },
        ChangeError::Map(e) => fail(e),
    })?;
    let changed = blocked.on(map.grid().costs());
    changes::check_ends(map, &polygons, map.grid().costs(), &changed, robot, g).map_err(
        |e| match e {
            changes::BlockedEnd::Goal { area } => match area.map(|i| areas[i].1) {
                Some(file) => Failure::input(format!("--block {}: {e}", file.display())),
                None => Failure::input(format!("--block: {e}")),
            },
            _ if args.replan_from.is_some() => Failure::input(format!("--replan-from: {e}")),
            _ => Failure::input(format!("--from: {e}")),
        },
    )?;
    let changes: Vec<(usize, f32)> = changed.into_iter().collect();
    let cells = blocked.blocked();

    let search = |e: planner_core::route::RouteError| fail(MapRouteError::Search(e));
    let t = Instant::now();
    let mut dstar = DStarLite::new(map.grid().clone(), s, g, options.clone()).map_err(search)?;
    let initial = dstar.plan(&|| false).map_err(search)?;
    let initial_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    dstar.move_start(robot).map_err(search)?;
    dstar.update_cells(&changes).map_err(search)?;
    let replanned = dstar.plan(&|| false);
    let replan_ms = t.elapsed().as_secs_f64() * 1e3;
    let changed = dstar.grid().clone();
    let t = Instant::now();
    let scratch = astar(&changed, robot, g, options, &|| false);
    let scratch_ms = t.elapsed().as_secs_f64() * 1e3;
    let replanned = replanned.map_err(|e| match e {
        planner_core::route::RouteError::Unreachable => fail(MapRouteError::Unreachable),
        other => search(other),
    })?;
    let scratch = scratch.map_err(search)?;
    map.set_grid(changed).map_err(fail)?;
    let described = map.describe(&replanned, replan_ms).map_err(fail)?;
    let dir = args.out.join("replanned");
    std::fs::create_dir_all(&dir)
        .map_err(|e| Failure::other(format!("cannot create {}: {e}", dir.display())))?;
    request["blocked_cells"] = json!(cells.len());
    write_route(&dir, &described, &request, args.speed)?;
    let timing = json!({
        "blocked_cells": cells.len(),
        "first_route_cost": first.path_cost,
        "dstar_lite": {
            "initial_ms": initial_ms, "initial_expanded": initial.expanded,
            "replan_ms": replan_ms, "replan_expanded": replanned.expanded,
            "replan_cost": replanned.cost,
        },
        "astar_from_scratch": {
            "ms": scratch_ms, "expanded": scratch.expanded, "cost": scratch.cost,
        },
    });
    write_json(&dir.join("timing.json"), &timing)?;
    println!(
        "replanned after blocking {} cells: {:.1} m, cost {:.1}; D* Lite {:.1} ms \
         ({} cells expanded; its first search {:.1} ms, {} cells), A* from scratch {:.1} ms \
         ({} cells, cost {:.1}) -> {}",
        cells.len(),
        described.length_2d_m,
        described.cost,
        replan_ms,
        replanned.expanded,
        initial_ms,
        initial.expanded,
        scratch_ms,
        scratch.expanded,
        scratch.cost,
        dir.display()
    );
    Ok(())
}

fn write_json(path: &Path, value: &Value) -> Result<(), Failure> {
    let mut text =
        serde_json::to_string_pretty(value).map_err(|e| Failure::other(e.to_string()))?;
    text.push('\n');
    write(path, text.as_bytes())
}

fn write(path: &Path, content: &[u8]) -> Result<(), Failure> {
    std::fs::write(path, content)
        .map_err(|e| Failure::other(format!("cannot write {}: {e}", path.display())))
}

/// route.json (the request and the route), route.geojson, route.csv and
/// mission.waypoints in `dir`.
fn write_route(
    dir: &Path,
    route: &MapRoute,
    request: &Value,
    speed: Option<f64>,
) -> Result<(), Failure> {
    let mut doc = serde_json::to_value(route).map_err(|e| Failure::other(e.to_string()))?;
    if let (Value::Object(d), Value::Object(r)) = (&mut doc, request) {
        for (k, v) in r {
            d.insert(k.clone(), v.clone());
        }
    }
    write_json(&dir.join("route.json"), &doc)?;
    write_json(
        &dir.join("route.geojson"),
        &route_geojson(route, Map::new()),
    )?;
    write(&dir.join("route.csv"), route_csv(route).as_bytes())?;
    write(
        &dir.join("mission.waypoints"),
        write_waypoints(&rover_mission(route, speed)).as_bytes(),
    )
}
