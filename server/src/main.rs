//! The `terraplan` binary: `serve` (the HTTP service) and the CLI
//! subcommands that run the same planner on files.

mod api;
mod app;
mod auth;
mod cli;
mod clock;
mod config;
mod conn;
mod conn_state;
mod db;
mod error;
mod guard;
mod imports;
mod jobs;
mod linger;
mod memory;
mod quota;
mod rate_limit;
mod serve;
mod state;
mod vehicle_link;
mod web_ui;

fn main() -> std::process::ExitCode {
    cli::run()
}
