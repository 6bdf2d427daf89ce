//! Command-line interface: `terraplan survey`, `terraplan costmap` and
//! `terraplan route` run the same planners as the service on files; `terraplan dem-info` reads a
//! DEM as the service does; `terraplan user` manages the service's users. Exit status: 0 success, 2 invalid input (the
//! message names the fault), 3 a vehicle link failure (`upload`), 1 any other failure.
//!
//! This module parses the arguments and dispatches; each subcommand has
//! its own file, and what they share is in `common`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::config::ServeConfig;

mod common;
mod costmap;
mod dem_info;
mod experiment;
mod import;
mod route;
mod serve;
mod survey;
mod upload;
mod user;
mod worker;

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
    /// Run costmap jobs of a PostgreSQL database shared with `serve`
    /// replicas, serving no HTTP (takes `serve`'s options; those of HTTP
    /// are not used). SIGTERM: stop taking jobs, give back the running
    /// ones, exit 0.
    Worker(ServeConfig),
    /// Plan a photo survey of an area and write the mission files.
    Survey(survey::SurveyArgs),
    /// Read a DEM (GeoTIFF, ESRI ASCII grid, SRTM .hgt) and print its
    /// metadata as JSON: size, resolution, CRS, bounds, height range.
    DemInfo(dem_info::DemInfoArgs),
    /// Read a GIS file (zipped Shapefile, .shp, KML, KMZ, GPX, GeoJSON in
    /// any named CRS) and print its polygons and lines as WGS84 GeoJSON:
    /// `{"features": FeatureCollection, "messages": [what was skipped]}`.
    Import(import::ImportArgs),
    /// Build the traversability costmap of a DEM for a ground vehicle and
    /// write costmap.tif (page 1 cost, page 2 class), preview.png,
    /// legend.svg, stats.json and layers/<name>.tif.
    Costmap(costmap::CostmapArgs),
    /// Plan the cheapest safe route for a ground robot across a costmap
    /// GeoTIFF and write route.json, route.geojson, route.csv and an
    /// ArduPilot Rover mission.waypoints.
    Route(route::RouteArgs),
    /// Send a mission (`.waypoints` or `.plan`), fence and rally points to
    /// a vehicle over MAVLink, then read them back and compare item by
    /// item. Exit status 3 when the link or the vehicle fails.
    Upload(upload::UploadArgs),
    /// Manage the service's users and their API tokens (on the database
    /// of `serve`'s `--data-dir` / `DATABASE_URL`).
    #[command(subcommand)]
    User(user::UserCommand),
    /// Reproducible experiments on embedded real data.
    #[command(subcommand)]
    Experiment(experiment::ExperimentCommand),
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
        Command::Worker(config) => worker::worker(config),
        Command::Survey(args) => survey::survey(&args),
        Command::DemInfo(args) => dem_info::dem_info(&args),
        Command::Import(args) => import::import(&args),
        Command::Costmap(args) => costmap::costmap(&args),
        Command::Route(args) => route::route(&args),
        Command::Upload(args) => upload::upload(&args),
        Command::Experiment(command) => experiment::experiment(&command),
        Command::User(command) => user::user(command),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.status)
        }
    }
}
