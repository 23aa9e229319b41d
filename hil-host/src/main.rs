//! `hil-host`: the host tools' command line.
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use hil_host::diagnose::{self, report, Rules};
use hil_host::log::{read_log, Plant};

const USAGE: &str = "usage: hil-host <command> [args]
commands:
  check <log.csv> [--plant P]
      read a log strictly and summarise it
  diagnose <estimation.csv> [--validation <validation.csv>] [--plant P] [--json out.json] [--plots dir]
      calibrate the baseline model, test its residuals, fit every catalogue effect, name the
      cause and measure the gain on validation data (the last 30 % of the file when no
      --validation is given)
  run [scenario.toml] [--out dir]
      closed loop of all three actuators (model-core controllers against the plant models,
      natively); without a file, the built-in default scenario; logs and plots go to --out
      (default: out/<scenario name>)
  generate <plant> <effect|none> [--seed N] [--out dir]
      write a bench-like estimation and validation log pair from the plant model with one
      hidden effect (the truth goes to truth.json beside them, not into the logs);
      `generate evvt prbs-grid` writes the nine closed-loop PRBS identification logs instead
  identify evvt <closed-loop log>... [--json out.json]
      EVVT plant α/(s(s+β)) per operating point from closed-loop PRBS logs (Yang 2015: q-Markov
      cover of the closed loop, open loop by G = H(I-H)^-1 K^-1, integrator pole at zero) and
      the LPV tables α(N, V), β(N, V)
  identify ehvva <bench log>... [--json out.json]
      EHVVA calibration (Li 2018 Sec. 5.2) over a test matrix of valve events: per (Ph, T)
      condition td (VO, VC) from the command edges to the lift response, τp and Cd by
      trust-region least squares on the lift; the tables td(Ph, T), τp(Ph, T), Cd(T)
  pil [scenario.toml] [--elf path] [--out dir] [--until s] [--corrupt-every n] [--drop-every m] [--compare-native]
      processor in the loop: the same closed loop as `run`, with the ECU core as firmware on
      QEMU's emulated STM32F405 (netduinoplus2) in lockstep over its UART; builds firmware-qemu
      when no --elf is given; prints PIL steps per second and the link's bad-frame counters;
      --corrupt-every/--drop-every inject faults on sensor frames (retransmitted: lossless);
      --compare-native also runs natively and compares every actuator frame
  target-bench [scenario.toml] [--elf path] [--out dir] [--steps N]
      instructions per task step (the scenario's first N lockstep steps, default 2000) and
      per plant step (f32, Q32) on the emulated Cortex-M4 (QEMU TCG plugin tools/qemu-plugin),
      with the plant states and actuator frames checked against the host
  paper-check [--json FILE]
      each model against its paper: one row per published value (paper, model, relative error,
      tolerance, pass); exits non-zero when a row fails
plants: vacuum, ehvva, evvt, positioner
";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("check") => check(&args[1..]),
        Some("diagnose") => run_diagnose(&args[1..]),
        Some("generate") => run_generate(&args[1..]),
        Some("run") => run_scenario(&args[1..]),
        Some("identify") => run_identify(&args[1..]),
        Some("pil") => run_pil(&args[1..]),
        Some("target-bench") => run_target_bench(&args[1..]),
        Some("paper-check") => run_paper_check(&args[1..]),
        Some("-h") | Some("--help") | Some("help") => {
            print!("{USAGE}");
            Ok(())
        }
        _ => Err(CliError::Usage("no command given".into())),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::Usage(m)) => {
            eprintln!("error: {m}\n\n{USAGE}");
            ExitCode::from(2)
        }
        Err(CliError::Failed(m)) => {
            eprintln!("error: {m}");
            ExitCode::FAILURE
        }
    }
}

enum CliError {
    Usage(String),
    Failed(String),
}

/// Options of the form `--name value`, and positional arguments.
struct Args {
    positional: Vec<String>,
    options: Vec<(String, String)>,
}

fn parse_args(args: &[String], known: &[&str]) -> Result<Args, CliError> {
    let mut positional = Vec::new();
    let mut options = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if let Some(name) = a.strip_prefix("--") {
            if !known.contains(&name) {
                return Err(CliError::Usage(format!("unknown option --{name}")));
            }
            let v = it
                .next()
                .ok_or_else(|| CliError::Usage(format!("--{name} needs a value")))?;
            options.push((name.to_string(), v.clone()));
        } else {
            positional.push(a.clone());
        }
    }
    Ok(Args { positional, options })
}

impl Args {
    fn get(&self, name: &str) -> Option<&str> {
        self.options
            .iter()
            .rev()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
    fn plant(&self) -> Result<Option<Plant>, CliError> {
        match self.get("plant") {
            None => Ok(None),
            Some(n) => Plant::from_name(n)
                .map(Some)
                .ok_or_else(|| CliError::Usage(format!("--plant {n}: unknown plant"))),
        }
    }
}

fn check(args: &[String]) -> Result<(), CliError> {
    let a = parse_args(args, &["plant"])?;
    let [path] = a.positional.as_slice() else {
        return Err(CliError::Usage("check takes one log file".into()));
    };
    let log = read_log(Path::new(path), a.plant()?).map_err(|e| CliError::Failed(e.to_string()))?;
    println!(
        "{}: plant {}, {} samples at {} s, columns {}",
        log.file,
        log.plant,
        log.len(),
        log.dt_s,
        log.order.join(", ")
    );
    for n in &log.notices {
        println!("notice: {n}");
    }
    Ok(())
}

fn run_diagnose(args: &[String]) -> Result<(), CliError> {
    let a = parse_args(args, &["validation", "plant", "json", "plots"])?;
    let [est_path] = a.positional.as_slice() else {
        return Err(CliError::Usage(
            "diagnose takes one estimation log (and --validation for a second)".into(),
        ));
    };
    let plant = a.plant()?;
    let failed = |e: hil_host::log::LogError| CliError::Failed(e.to_string());
    let est_full = read_log(Path::new(est_path), plant).map_err(failed)?;
    let plant = est_full.plant;
    let (est, val, tail) = match a.get("validation") {
        Some(v) => {
            let val = read_log(Path::new(v), Some(plant)).map_err(failed)?;
            (est_full, val, false)
        }
        None => {
            let (e, v) = diagnose::split_tail(&est_full, 0.3);
            (e, v, true)
        }
    };
    for n in est.notices.iter().chain(&val.notices) {
        eprintln!("notice: {n}");
    }
    let family = diagnose::family_for(plant).map_err(CliError::Failed)?;
    // A bar redrawn in place on a terminal, plain lines per fit otherwise.
    let mut line = diagnose::progress::ProgressLine::for_stderr();
    let mut progress = |p: &diagnose::Progress| {
        if let Some(text) = line.render(p) {
            eprint!("{text}");
        }
    };
    let d = diagnose::diagnose(family.as_ref(), &est, &val, tail, &Rules::default(), &mut progress);
    if let Some(text) = line.finish() {
        eprint!("{text}");
    }
    let d = d.map_err(CliError::Failed)?;
    print!("{}", report::summary(&d));
    if let Some(out) = a.get("json") {
        let text = serde_json::to_string_pretty(&report::to_json(&d)).map_err(|e| CliError::Failed(e.to_string()))?;
        std::fs::write(out, text + "\n").map_err(|e| CliError::Failed(format!("{out}: {e}")))?;
        eprintln!("report written to {out}");
    }
    if let Some(dir) = a.get("plots") {
        let dir = PathBuf::from(dir);
        let written = hil_host::plot::diagnosis_plots(&d, &dir)
            .map_err(|e| CliError::Failed(format!("{}: {e}", dir.display())))?;
        for w in written {
            eprintln!("plot written to {}", w.display());
        }
    }
    Ok(())
}

fn run_generate(args: &[String]) -> Result<(), CliError> {
    let a = parse_args(args, &["seed", "out"])?;
    let [plant, effect] = a.positional.as_slice() else {
        return Err(CliError::Usage("generate takes a plant and an effect (or none)".into()));
    };
    let plant = Plant::from_name(plant).ok_or_else(|| CliError::Usage(format!("unknown plant `{plant}`")))?;
    let seed = match a.get("seed") {
        Some(s) => s
            .parse::<u64>()
            .map_err(|_| CliError::Usage(format!("--seed {s}: not a whole number")))?,
        None => std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64),
    };
    if plant == Plant::Evvt && effect == "prbs-grid" {
        return generate_evvt_prbs_grid(seed, &PathBuf::from(a.get("out").unwrap_or(".")));
    }
    let case = hil_host::generate::generate(plant, effect, seed).map_err(CliError::Failed)?;
    let dir = PathBuf::from(a.get("out").unwrap_or("."));
    std::fs::create_dir_all(&dir).map_err(|e| CliError::Failed(format!("{}: {e}", dir.display())))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text).map_err(|e| CliError::Failed(format!("{}: {e}", dir.join(name).display())))
    };
    write("estimation.csv", &case.estimation_csv)?;
    write("validation.csv", &case.validation_csv)?;
    let truth: serde_json::Map<String, serde_json::Value> = case
        .truth
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect();
    let truth = serde_json::json!({"plant": plant.name(), "effect": case.effect, "seed": seed, "params": truth});
    write(
        "truth.json",
        &(serde_json::to_string_pretty(&truth).unwrap_or_default() + "\n"),
    )?;
    println!(
        "seed {seed}: wrote {}/estimation.csv, validation.csv and truth.json",
        dir.display()
    );
    Ok(())
}

fn run_scenario(args: &[String]) -> Result<(), CliError> {
    use hil_host::run::{run, Scenario};
    let a = parse_args(args, &["out"])?;
    let scenario = match a.positional.as_slice() {
        [] => Scenario::default_scenario(),
        [file] => {
            let text = std::fs::read_to_string(file).map_err(|e| CliError::Failed(format!("{file}: {e}")))?;
            Scenario::from_toml(Path::new(file), &text).map_err(CliError::Failed)?
        }
        _ => return Err(CliError::Usage("run takes at most one scenario file".into())),
    };
    let out = PathBuf::from(
        a.get("out")
            .map(String::from)
            .unwrap_or_else(|| format!("out/{}", scenario.name)),
    );
    let summary = run(&scenario, Some(&out)).map_err(CliError::Failed)?;
    print!("{}", summary.text(&scenario.name));
    println!("logs (DATA-FORMAT) and plots in {}", out.display());
    Ok(())
}

/// `pil`: the scenario with the ECU core on QEMU (hil_host::pil).
fn run_pil(args: &[String]) -> Result<(), CliError> {
    use hil_host::pil::{self, LinkFaults};
    use hil_host::run::Scenario;
    // --compare-native takes no value: strip it before the `--name value` parser.
    let compare_native = args.iter().any(|a| a == "--compare-native");
    let rest: Vec<String> = args.iter().filter(|a| *a != "--compare-native").cloned().collect();
    let a = parse_args(&rest, &["elf", "out", "until", "corrupt-every", "drop-every"])?;
    let scenario = match a.positional.as_slice() {
        [] => Scenario::default_scenario(),
        [file] => {
            let text = std::fs::read_to_string(file).map_err(|e| CliError::Failed(format!("{file}: {e}")))?;
            Scenario::from_toml(Path::new(file), &text).map_err(CliError::Failed)?
        }
        _ => return Err(CliError::Usage("pil takes at most one scenario file".into())),
    };
    let number = |name: &str| -> Result<Option<u32>, CliError> {
        a.get(name)
            .map(|v| {
                v.parse::<u32>()
                    .map_err(|_| CliError::Usage(format!("--{name} {v}: not a whole number")))
            })
            .transpose()
    };
    let faults = LinkFaults {
        corrupt_every: number("corrupt-every")?,
        drop_every: number("drop-every")?,
    };
    let until_s = a
        .get("until")
        .map(|v| {
            v.parse::<f64>()
                .map_err(|_| CliError::Usage(format!("--until {v}: not a number")))
        })
        .transpose()?;
    let out = PathBuf::from(
        a.get("out")
            .map(String::from)
            .unwrap_or_else(|| format!("out/{}-pil", scenario.name)),
    );
    let elf = match a.get("elf") {
        Some(e) => PathBuf::from(e),
        None => pil::build_firmware().map_err(CliError::Failed)?,
    };
    let r = pil::run_scenario(&scenario, &elf, faults, until_s, compare_native, &out).map_err(CliError::Failed)?;
    print!("{}", r.output.summary.text(&scenario.name));
    print!("{}", r.text());
    let written = hil_host::run::write_outputs(&scenario, &r.output, &out)
        .map_err(|e| CliError::Failed(format!("{}: {e}", out.display())))?;
    println!("logs (DATA-FORMAT), plots and the firmware's defmt stream (defmt.bin: defmt-print -e {} < defmt.bin) in {} ({} files)", elf.display(), out.display(), written.len());
    if r.first_difference.is_some() {
        return Err(CliError::Failed("the PIL run differs from the native run".into()));
    }
    Ok(())
}

/// `target-bench`: instruction counts on the emulated target (hil_host::pil::target_bench).
fn run_target_bench(args: &[String]) -> Result<(), CliError> {
    use hil_host::pil;
    use hil_host::run::{run_with, NativeLink, RunOptions, Scenario};
    let a = parse_args(args, &["elf", "out", "steps"])?;
    let scenario = match a.positional.as_slice() {
        [] => Scenario::default_scenario(),
        [file] => {
            let text = std::fs::read_to_string(file).map_err(|e| CliError::Failed(format!("{file}: {e}")))?;
            Scenario::from_toml(Path::new(file), &text).map_err(CliError::Failed)?
        }
        _ => return Err(CliError::Usage("target-bench takes at most one scenario file".into())),
    };
    let steps = match a.get("steps") {
        Some(v) => v
            .parse::<u32>()
            .map_err(|_| CliError::Usage(format!("--steps {v}: not a whole number")))?,
        None => 2000,
    };
    let out = PathBuf::from(a.get("out").unwrap_or("out/target-bench"));
    let elf = match a.get("elf") {
        Some(e) => PathBuf::from(e),
        None => pil::build_firmware().map_err(CliError::Failed)?,
    };
    // The sensor frames of the scenario's first `steps` lockstep steps, closed loop natively;
    // the target then steps its core on the same frames with every task counted.
    let until_s = f64::from(steps) * f64::from(model_core::ecu::lockstep::STEP_US) * 1e-6;
    let native = run_with(
        &scenario,
        &mut NativeLink::new().map_err(CliError::Failed)?,
        &RunOptions {
            until_s: Some(until_s),
            keep_frames: true,
        },
    )
    .map_err(CliError::Failed)?;
    let frames: Vec<_> = native.frames.iter().map(|(s, _)| *s).collect();
    let b = pil::target_bench(&elf, &frames, &out).map_err(CliError::Failed)?;
    print!("{}", b.text());
    println!("raw counts in {}", out.join("insn-counts.txt").display());
    let n = model_core::plant_bench::N_STATE;
    if b.plant_bits_target[n..] != b.plant_bits_host[n..] || !b.answers_equal_native {
        return Err(CliError::Failed("the target's results differ from the host's".into()));
    }
    Ok(())
}

/// `generate evvt prbs-grid`: the nine closed-loop PRBS identification logs of the design
/// table (for `identify evvt`).
fn generate_evvt_prbs_grid(seed: u64, dir: &Path) -> Result<(), CliError> {
    std::fs::create_dir_all(dir).map_err(|e| CliError::Failed(format!("{}: {e}", dir.display())))?;
    for (name, text) in hil_host::generate::evvt::identification_grid(seed).map_err(CliError::Failed)? {
        std::fs::write(dir.join(&name), text)
            .map_err(|e| CliError::Failed(format!("{}: {e}", dir.join(&name).display())))?;
    }
    println!(
        "seed {seed}: wrote the nine EVVT PRBS identification logs (design table) to {}",
        dir.display()
    );
    Ok(())
}

fn run_identify(args: &[String]) -> Result<(), CliError> {
    match args.first().map(String::as_str) {
        Some("evvt") => identify_evvt(&args[1..]),
        Some("ehvva") => identify_ehvva(&args[1..]),
        _ => Err(CliError::Usage("identify takes an actuator: evvt or ehvva".into())),
    }
}

fn identify_evvt(args: &[String]) -> Result<(), CliError> {
    use hil_host::identify::evvt;
    let a = parse_args(args, &["json"])?;
    if a.positional.is_empty() {
        return Err(CliError::Usage(
            "identify evvt takes one or more closed-loop PRBS logs".into(),
        ));
    }
    let opts = evvt::EvvtIdentifyOptions::default();
    let mut points = Vec::new();
    for path in &a.positional {
        let log = read_log(Path::new(path), Some(Plant::Evvt)).map_err(|e| CliError::Failed(e.to_string()))?;
        for n in &log.notices {
            eprintln!("notice: {}: {n}", log.file);
        }
        let p = evvt::identify_log(&log, &opts).map_err(CliError::Failed)?;
        print!("{}", p.report);
        points.push(p);
    }
    print!("{}", evvt::tables_text(&points));
    if let Some(out) = a.get("json") {
        let text =
            serde_json::to_string_pretty(&evvt::to_json(&points)).map_err(|e| CliError::Failed(e.to_string()))?;
        std::fs::write(out, text + "\n").map_err(|e| CliError::Failed(format!("{out}: {e}")))?;
        eprintln!("tables written to {out}");
    }
    Ok(())
}

fn identify_ehvva(args: &[String]) -> Result<(), CliError> {
    use hil_host::diagnose::ehvva::Events;
    use hil_host::identify::ehvva;
    let a = parse_args(args, &["json"])?;
    if a.positional.is_empty() {
        return Err(CliError::Usage(
            "identify ehvva takes one or more bench logs of valve events".into(),
        ));
    }
    let mut sets = Vec::new();
    for path in &a.positional {
        let log = read_log(Path::new(path), Some(Plant::Ehvva)).map_err(|e| CliError::Failed(e.to_string()))?;
        for n in &log.notices {
            eprintln!("notice: {}: {n}", log.file);
        }
        sets.push(Events::from_log(&log).map_err(CliError::Failed)?);
    }
    let id = ehvva::identify(&sets, &ehvva::default_options(), &mut |k, n| {
        eprintln!("condition {k}/{n} ...")
    })
    .map_err(CliError::Failed)?;
    print!("{}", id.text());
    if let Some(out) = a.get("json") {
        let text = serde_json::to_string_pretty(&id.json()).map_err(|e| CliError::Failed(e.to_string()))?;
        std::fs::write(out, text + "\n").map_err(|e| CliError::Failed(format!("{out}: {e}")))?;
        eprintln!("tables written to {out}");
    }
    Ok(())
}

fn run_paper_check(args: &[String]) -> Result<(), CliError> {
    let json = match args {
        [] => None,
        [flag, file] if flag == "--json" => Some(PathBuf::from(file)),
        _ => return Err(CliError::Usage("paper-check takes only --json FILE".into())),
    };
    match hil_host::paper_check::run(json.as_deref()).map_err(CliError::Failed)? {
        true => Ok(()),
        false => Err(CliError::Failed("paper-check: some rows fail (see FAIL above)".into())),
    }
}
