//! The `terraplan` binary: `serve` (the HTTP service) and the CLI
//! subcommands that run the same planner on files.

mod api;
mod app;
mod cli;
mod config;
mod conn;
mod costmap_jobs;
mod db;
mod error;
mod experiment;
mod linger;
mod memory;
mod serve;
mod web_ui;

fn main() -> std::process::ExitCode {
    cli::run()
}
