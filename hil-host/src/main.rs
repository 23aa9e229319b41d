//! `hil-host`: the host tools' command line.
use std::process::ExitCode;

fn usage() -> &'static str {
    "usage: hil-host <command> [args]\n\
     commands:\n  \
       check <log.csv> [--plant P]   read a log strictly and summarise it\n"
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("check") => check(&args[1..]),
        _ => {
            eprint!("{}", usage());
            ExitCode::from(2)
        }
    }
}

fn check(args: &[String]) -> ExitCode {
    let Some(path) = args.first() else {
        eprint!("{}", usage());
        return ExitCode::from(2);
    };
    let plant = match args.iter().position(|a| a == "--plant").map(|i| args.get(i + 1)) {
        None => None,
        Some(Some(name)) => match hil_host::log::Plant::from_name(name) {
            Some(p) => Some(p),
            None => {
                eprintln!("error: --plant {name}: unknown plant (known: vacuum, ehvva, evvt, positioner)");
                return ExitCode::from(2);
            }
        },
        Some(None) => {
            eprintln!("error: --plant needs a value");
            return ExitCode::from(2);
        }
    };
    match hil_host::log::read_log(std::path::Path::new(path), plant) {
        Ok(log) => {
            println!("{}: plant {}, {} samples at {} s, columns {}", log.file, log.plant, log.len(), log.dt_s, log.order.join(", "));
            for n in &log.notices {
                println!("notice: {n}");
            }
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
