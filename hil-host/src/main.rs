//! `hil-host`: the host tools' command line (clap; the commands are in `cli/`).
mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Help and --version print to stdout and exit 0; usage errors print the problem, a
    // suggestion where one fits, and exit 2.
    let args = cli::Cli::parse();
    match cli::commands::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(cli::commands::Failure(m)) => {
            eprintln!("error: {m}");
            ExitCode::FAILURE
        }
    }
}
