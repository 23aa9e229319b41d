//! The command line, declared with clap: every command, its options, its help with examples.
//! Each command is a thin layer over a library function ([`commands`]).

pub mod commands;
pub mod progress;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use hil_host::log::Plant;

const MAIN_EXAMPLES: &str = "\
Examples:
  hil-host check ../shared/data/emps/emps-estimation.csv
  hil-host diagnose est.csv --validation val.csv --json report.json --plots plots/
  hil-host run scenarios/default.toml
  hil-host generate vacuum backlash --seed 3 --out cases/backlash-3
  hil-host identify evvt prbs/*.csv --json evvt.json
  hil-host pil --until 0.5 --compare-native
  hil-host completions bash > ~/.local/share/bash-completion/completions/hil-host

Exit status: 0 on success, 1 when a command fails, 2 for a usage error.";

/// Host tools for the engine actuators: logs, diagnosis, identification, closed-loop runs
/// (natively and with the ECU on QEMU).
#[derive(Debug, Parser)]
#[command(
    name = "hil-host",
    version,
    arg_required_else_help = true,
    propagate_version = true,
    after_help = MAIN_EXAMPLES
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// A plant of DATA-FORMAT.md.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PlantArg {
    Vacuum,
    Ehvva,
    Evvt,
    Positioner,
}

impl From<PlantArg> for Plant {
    fn from(p: PlantArg) -> Plant {
        match p {
            PlantArg::Vacuum => Plant::Vacuum,
            PlantArg::Ehvva => Plant::Ehvva,
            PlantArg::Evvt => Plant::Evvt,
            PlantArg::Positioner => Plant::Positioner,
        }
    }
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Read a log strictly and summarise it (plant, samples, step, columns)
    #[command(after_help = "Examples:\n  hil-host check bench.csv\n  hil-host check bench.csv --plant vacuum")]
    Check(CheckArgs),
    /// Name the cause of a model mismatch: calibrate the baseline, test its residuals, fit every
    /// catalogue effect, measure the gain on validation data
    #[command(after_help = "\
Without --validation the last 30 % of the estimation log is held out as validation data.

Examples:
  hil-host diagnose est.csv --validation val.csv
  hil-host diagnose est.csv --json report.json --plots plots/ --report report.html
  hil-host diagnose est.mf4 --validation val.mf4 --channel-map ecu.toml
  hil-host diagnose emps-estimation.csv --validation emps-validation.csv")]
    Diagnose(DiagnoseArgs),
    /// Closed loop of all three actuators natively: the ECU core against the plant models;
    /// logs and plots go to --out
    #[command(after_help = "\
Without a scenario file the built-in default scenario runs.

Examples:
  hil-host run
  hil-host run scenarios/fault-crank-lost.toml --out out/crank --report crank.html")]
    Run(RunArgs),
    /// Write a bench-like estimation and validation log pair with one hidden effect (the truth
    /// goes to truth.json beside them)
    #[command(after_help = generate_help())]
    Generate(GenerateArgs),
    /// Identify actuator models from bench logs
    #[command(subcommand)]
    Identify(IdentifyCommand),
    /// The ECU's calibration image from a unit's bench logs (any mix of plants):
    /// calibration.bin, calibration.a2l (ASAM MCD-2 MC) and calibration.json
    #[command(after_help = "\
EHVVA matrix logs go to `identify ehvva`, EVVT PRBS logs to `identify evvt`, vacuum logs to
`diagnose` (with the named extension); the rest keeps the paper defaults (calibration.json
says which). Flash the image with
  probe-rs download --binary-format bin --base-address 0x080E0000 --chip STM32F405RGTx calibration.bin

Examples:
  hil-host calibrate unit/estimation.csv --out cal
  hil-host calibrate ehvva-matrix.csv prbs/*.csv vacuum-hpt.csv --out cal
  hil-host run scenarios/calibration-sweep.toml --unit unit/truth.json --calibration cal/calibration.bin")]
    Calibrate(CalibrateArgs),
    /// Processor in the loop: the closed loop of `run` with the ECU core as firmware on QEMU's
    /// emulated STM32F405, in lockstep over its UART
    #[command(after_help = "\
The firmware image: --elf, else firmware-qemu next to the hil-host binary, else the
workspace's target/thumbv7em-none-eabihf/firmware/firmware-qemu (CARGO_TARGET_DIR honoured),
built first so it is current.

Examples:
  hil-host pil --until 0.5 --compare-native
  hil-host pil --until 0.2 --corrupt-every 7 --drop-every 40
  hil-host pil scenarios/default.toml --elf firmware-qemu.elf --out out/pil")]
    Pil(PilArgs),
    /// Instructions per task step and per plant step on the emulated Cortex-M4 (QEMU TCG
    /// plugin), with the results checked against the host
    #[command(after_help = "\
Examples:
  hil-host target-bench
  hil-host target-bench --steps 20000 --out out/bench
  hil-host target-bench --json out/target-bench.json")]
    TargetBench(TargetBenchArgs),
    /// Each model against its paper: one row per published value (paper, model, relative
    /// error, tolerance, pass); exit status 1 when a row fails
    #[command(after_help = "\
Examples:
  hil-host paper-check
  hil-host paper-check --json out/paper-check.json")]
    PaperCheck(PaperCheckArgs),
    /// Print a shell completion script
    #[command(after_help = "\
Examples:
  hil-host completions bash > ~/.local/share/bash-completion/completions/hil-host
  hil-host completions zsh > ~/.zfunc/_hil-host
  hil-host completions fish > ~/.config/fish/completions/hil-host.fish")]
    Completions {
        /// The shell
        shell: clap_complete::Shell,
    },
}

fn generate_help() -> String {
    let mut s = String::from("Effects by plant (or `none`, the control case):\n");
    for p in Plant::ALL {
        let effects: Vec<&str> = hil_host::generate::effects(p)
            .iter()
            .copied()
            .filter(|e| *e != "none")
            .collect();
        s += &format!("  {:<11} {}\n", p.name(), effects.join(", "));
    }
    s += "  evvt        prbs-grid: the nine closed-loop PRBS identification logs instead\n";
    s += "Several at once joined by `+` (e.g. supply-voltage+backlash); outside the catalogue:";
    for p in Plant::ALL {
        s += &format!(" {} {}", p.name(), hil_host::generate::outside_effects(p).join(", "));
        s += if p == Plant::ALL[Plant::ALL.len() - 1] {
            "\n"
        } else {
            ";"
        };
    }
    s += "\nExamples:\n  hil-host generate vacuum backlash --seed 3\n  hil-host generate positioner none --seed=7 --out cases/control\n  hil-host generate evvt prbs-grid --out prbs";
    s
}

/// `--channel-map`, as every command that reads logs takes it.
#[derive(Debug, Args)]
pub struct ChannelMapArg {
    /// Rename an MF4 file's channels or a CSV file's columns to DATA-FORMAT columns and add metadata and units (TOML:
    /// [channels] "Logger.Name" = "column", [meta] key = value, [units] column = "bar"; docs/data-format.md)
    #[arg(long, value_name = "FILE")]
    pub channel_map: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The log (DATA-FORMAT.md: CSV, or ASAM MDF 4 .mf4)
    pub log: PathBuf,
    /// The plant, when the log does not say
    #[arg(long, value_enum)]
    pub plant: Option<PlantArg>,
    #[command(flatten)]
    pub map: ChannelMapArg,
}

#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The estimation log
    pub estimation: PathBuf,
    /// A second log for validation (default: the estimation log's last 30 %)
    #[arg(long, value_name = "LOG")]
    pub validation: Option<PathBuf>,
    /// The plant, when the log does not say
    #[arg(long, value_enum)]
    pub plant: Option<PlantArg>,
    /// Write the JSON report here
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Write SVG plots into this directory
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
    /// Write one self-contained HTML page: verdict, evidence, plots, parameters, gain
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub map: ChannelMapArg,
    /// Write the plots into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Args)]
pub struct RunArgs {
    /// The scenario (TOML; default: the built-in default scenario)
    pub scenario: Option<PathBuf>,
    /// Directory for the logs and plots [default: out/<scenario name>]
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write one self-contained HTML page: summary and plots
    #[arg(long, value_name = "FILE")]
    pub report: Option<PathBuf>,
    /// Write into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
}

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// The unit's bench logs
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Directory for calibration.bin, calibration.a2l and calibration.json
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// The calibration sector's address in the ECU's flash (hex)
    #[arg(long, value_name = "ADDR", default_value = "0x080E0000")]
    pub flash_base: String,
    #[command(flatten)]
    pub map: ChannelMapArg,
    /// Write into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
}

/// `--calibration`, `--unit`, `--json` of `run` and `pil`.
#[derive(Debug, Args)]
pub struct CalibrationArgs {
    /// The ECU runs this calibration image (refused whole when any check fails)
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
    /// The plants are the unit `generate` described (its truth.json)
    #[arg(long, value_name = "FILE")]
    pub unit: Option<PathBuf>,
    /// Write the error figures per actuator here (ehvva.timing_error_deg_rms, ...)
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

#[derive(Debug, Args)]
pub struct GenerateArgs {
    /// The plant
    #[arg(value_enum)]
    pub plant: PlantArg,
    /// The hidden effect (catalogue name), `none`, or for evvt `prbs-grid`
    pub effect: String,
    /// Random seed (default: from the clock, printed)
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output directory [default: out/<plant>-<effect>-seed<N>]
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Run the experiment programme N times (new draws each time): long logs, e.g. an EHVVA
    /// bench pair of ~400 000 rows with --repeat 18
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub repeat: u32,
    /// Write into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Subcommand)]
pub enum IdentifyCommand {
    /// EVVT plant α/(s(s+β)) per operating point from closed-loop logs (Yang 2015; one PRBS
    /// experiment per point, or recordings over several points with any exciting reference) and
    /// the LPV tables α(N, V), β(N, V)
    #[command(after_help = "\
Examples:
  hil-host generate evvt prbs-grid --out prbs
  hil-host identify evvt prbs/*.csv --json evvt.json")]
    Evvt(IdentifyArgs),
    /// EHVVA calibration (Li 2018 Sec. 5.2): td(Ph, T), τp(Ph, T), Cd(T) from a test matrix of
    /// valve events, on the unit's own valve as `diagnose` fits it (or the paper's)
    #[command(after_help = "\
The per-condition fits run on the unit's valve: `diagnose` first fits its spring, preload,
friction, mass, areas and flow paths with the named extension (the second log as validation,
else the first one's last 30 %). With --paper-valve they run on the paper's valve, the paper's
method; on a unit whose valve is not the paper's, its other valve then goes into td, tau_p and Cd.

Examples:
  hil-host identify ehvva bench-*.csv --json ehvva.json
  hil-host identify ehvva bench.csv --paper-valve")]
    Ehvva(IdentifyEhvvaArgs),
}

#[derive(Debug, Args)]
pub struct IdentifyEhvvaArgs {
    #[command(flatten)]
    pub common: IdentifyArgs,
    /// Fit the conditions on the paper's valve (geometry, spring, mass) instead of the unit's
    #[arg(long)]
    pub paper_valve: bool,
}

#[derive(Debug, Args)]
pub struct IdentifyArgs {
    /// The logs
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Write the tables as JSON here
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    #[command(flatten)]
    pub map: ChannelMapArg,
}

#[derive(Debug, Args)]
pub struct PilArgs {
    /// The scenario (TOML; default: the built-in default scenario)
    pub scenario: Option<PathBuf>,
    /// The firmware-qemu image [default: found at run time, see below]
    #[arg(long, value_name = "PATH")]
    pub elf: Option<PathBuf>,
    /// Directory for the logs, plots and the firmware's defmt stream [default: out/<scenario name>-pil]
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Stop after this many simulated seconds
    #[arg(long, value_name = "S")]
    pub until: Option<f64>,
    /// Corrupt every n-th sensor frame (retransmitted: lossless)
    #[arg(long, value_name = "N")]
    pub corrupt_every: Option<u32>,
    /// Drop every m-th sensor frame (retransmitted: lossless)
    #[arg(long, value_name = "M")]
    pub drop_every: Option<u32>,
    /// Also run natively and compare every actuator frame
    #[arg(long)]
    pub compare_native: bool,
    /// Write into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub calibration: CalibrationArgs,
}

#[derive(Debug, Args)]
pub struct TargetBenchArgs {
    /// The scenario (TOML; default: the built-in default scenario)
    pub scenario: Option<PathBuf>,
    /// The firmware-qemu image [default: found at run time as for `pil`]
    #[arg(long, value_name = "PATH")]
    pub elf: Option<PathBuf>,
    /// Directory for the raw counts and QEMU's logs
    #[arg(long, value_name = "DIR", default_value = "out/target-bench")]
    pub out: PathBuf,
    /// Lockstep steps of the scenario to count
    #[arg(long, value_name = "N", default_value_t = 2000)]
    pub steps: u32,
    /// Also write the counts as JSON: `{"plant_steps": [{"plant", "number", "instructions_mean",
    /// ...}], "tasks": [...]}` (plants ehvva-reduced, ehvva-lpv, evvt, vacuum, positioner;
    /// numbers f32 and fixed = Q16.16)
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Also count by instruction address: `insn-by-address.txt` in the output directory, lines
    /// `label 0xADDRESS count` (map them with `addr2line -e ELF`); slower
    #[arg(long)]
    pub by_address: bool,
    /// Write into a directory that holds other files or another run's outputs
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Args)]
pub struct PaperCheckArgs {
    /// Also write the rows as JSON, `{"rows": [...]}`
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_command_line_is_consistent() {
        Cli::command().debug_assert();
    }
}
