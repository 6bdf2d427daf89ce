//! The `terraplan` binary: the CLI subcommands over planner-core.

mod cli;

fn main() -> std::process::ExitCode {
    cli::run()
}
