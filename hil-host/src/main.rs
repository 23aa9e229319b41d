//! `hil-host`: the host tools' command line (clap; the commands are in `cli/`).
mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // Help and --version print to stdout and exit 0; usage errors print the problem, a
    // suggestion where one fits, and exit 2.
    let args = cli::Cli::parse();
    // `HIL_HOST_PEAK_RSS` set: the process's peak resident memory goes to stderr before and
    // after the command (how tests/memory.rs measures the bytes a log row costs).
    let peak_rss = std::env::var_os("HIL_HOST_PEAK_RSS").is_some();
    if peak_rss {
        eprintln!("peak RSS before the command: {} kB", peak_rss_kb().unwrap_or(0));
    }
    let code = match cli::commands::run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(cli::commands::Failure(m)) => {
            eprintln!("error: {m}");
            ExitCode::FAILURE
        }
    };
    if peak_rss {
        eprintln!("peak RSS: {} kB", peak_rss_kb().unwrap_or(0));
    }
    code
}

/// The process's peak resident set (Linux `VmHWM` in /proc/self/status), if known.
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}
