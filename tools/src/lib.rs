//! The `scaledp` command line and what it runs that belongs to no library: the benchmarks, the
//! demo, the interactive recorder front end.
//!
//! Exit codes: 0 success; 1 error; 2 bad usage; 3 finished, but data was lost (dropped
//! messages, failed episodes) — see [`cli::ExitStatus`].

pub mod cli;
mod commands;
#[cfg(test)]
mod docs_commands;
mod shared;
mod ui;

use clap::Parser;

/// Parses the command line, runs the command, reports errors, and returns the exit code.
pub fn run() -> std::process::ExitCode {
    ui::quiet_on_closed_stdout();
    let args = cli::Cli::parse();
    ui::init_logging(args.verbose, args.quiet);
    match commands::dispatch(args.command) {
        Ok(status) => status.into(),
        Err(e) => {
            eprintln!("error: {e:#}");
            cli::ExitStatus::Error.into()
        }
    }
}
