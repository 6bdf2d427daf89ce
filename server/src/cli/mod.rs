//! Command-line interface: `terraplan survey`, `terraplan costmap` and
//! `terraplan route` run the same planners as the service on files; `terraplan dem-info` reads a
//! DEM as the service does. Exit status: 0 success, 2 invalid input (the
//! message names the fault), 1 any other failure.
//!
//! This module parses the arguments and dispatches; each subcommand has
//! its own file, and the helpers they share (reading JSON and DEM files,
//! listing faults) are here.

use std::path::Path;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use planner_core::geo::Issue;
use planner_core::terrain::{Dem, DemLimits, TerrainError, read_dem};
use serde_json::Value;

use crate::config::ServeConfig;

mod costmap;
mod dem_info;
mod experiment;
mod route;
mod serve;
mod survey;

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
    Survey(survey::SurveyArgs),
    /// Read a DEM (GeoTIFF, ESRI ASCII grid, SRTM .hgt) and print its
    /// metadata as JSON: size, resolution, CRS, bounds, height range.
    DemInfo(dem_info::DemInfoArgs),
    /// Build the traversability costmap of a DEM for a ground vehicle and
    /// write costmap.tif (page 1 cost, page 2 class), preview.png,
    /// legend.svg, stats.json and layers/<name>.tif.
    Costmap(costmap::CostmapArgs),
    /// Plan the cheapest safe route for a ground robot across a costmap
    /// GeoTIFF and write route.json, route.geojson, route.csv and an
    /// ArduPilot Rover mission.waypoints.
    Route(route::RouteArgs),
    /// Reproducible experiments on embedded real data.
    #[command(subcommand)]
    Experiment(experiment::ExperimentCommand),
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
        Command::Serve(config) => serve::serve(config),
        Command::Survey(args) => survey::survey(&args),
        Command::DemInfo(args) => dem_info::dem_info(&args),
        Command::Costmap(args) => costmap::costmap(&args),
        Command::Route(args) => route::route(&args),
        Command::Experiment(command) => experiment::experiment(&command),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.status)
        }
    }
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
