//! The `terraplan` binary: `serve` (the HTTP service) and the CLI
//! subcommands that run the same planner on files.

mod api;
mod app;
mod cli;
mod clock;
mod config;
mod conn;
mod db;
mod error;
/// Former home of the costmap jobs (`jobs`) and `now_millis` (`clock`),
/// for code not moved to them yet.
mod costmap_jobs {
    pub use crate::clock::now_millis;
    pub use crate::jobs::*;
}
mod jobs;
mod linger;
mod memory;
mod serve;
mod state;
mod web_ui;

fn main() -> std::process::ExitCode {
    cli::run()
}
