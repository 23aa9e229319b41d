//! One function per command: read the inputs, call the library, write the outputs safely
//! (hil_host::output: atomic files, inputs never overwritten, output directories claimed).

use std::path::{Path, PathBuf};

use hil_host::diagnose::{self, report, Rules};
use hil_host::log::{read_log_mapped, Log, Plant};
use hil_host::mf4::ChannelMap;
use hil_host::numbers::{sig, tidy_json};
use hil_host::output::{self, Claim, OutputDir};
use hil_host::run::Scenario;

use super::progress::{self, Counter, Spinner};
use super::{
    CalibrateArgs, CalibrationArgs, CheckArgs, Cli, Command, DiagnoseArgs, GenerateArgs, IdentifyArgs, IdentifyCommand,
    IdentifyEhvvaArgs, PaperCheckArgs, PilArgs, RunArgs, TargetBenchArgs,
};

/// A failed command (exit status 1); usage errors are clap's (exit status 2).
pub struct Failure(pub String);

macro_rules! failure_from {
    ($($t:ty),*) => {$(
        impl From<$t> for Failure {
            fn from(e: $t) -> Self {
                Failure(e.to_string())
            }
        }
    )*};
}
failure_from!(
    hil_host::output::OutputError,
    hil_host::log::LogError,
    std::io::Error,
    serde_json::Error
);

type Result<T> = std::result::Result<T, Failure>;

fn fail(message: impl Into<String>) -> Failure {
    Failure(message.into())
}

/// Runs the parsed command.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Check(a) => check(a),
        Command::Diagnose(a) => diagnose(a),
        Command::Run(a) => run_scenario(a),
        Command::Generate(a) => generate(a),
        Command::Identify(IdentifyCommand::Evvt(a)) => identify_evvt(a),
        Command::Identify(IdentifyCommand::Ehvva(a)) => identify_ehvva(a),
        Command::Pil(a) => pil(a),
        Command::Calibrate(a) => calibrate(a),
        Command::TargetBench(a) => target_bench(a),
        Command::PaperCheck(a) => paper_check(a),
        Command::Completions { shell } => {
            use clap::CommandFactory;
            clap_complete::generate(shell, &mut Cli::command(), "hil-host", &mut std::io::stdout());
            Ok(())
        }
    }
}

/// Reads a log (CSV or MF4) with a spinner (big logs take seconds), renamed by the channel
/// map when one is given.
fn read(path: &Path, plant: Option<Plant>, map: Option<&ChannelMap>) -> Result<Log> {
    let _spinner = progress::reading(path);
    Ok(read_log_mapped(path, plant, map)?)
}

/// The `--channel-map` file, read and checked.
fn channel_map(path: Option<&Path>) -> Result<Option<ChannelMap>> {
    Ok(path.map(ChannelMap::read).transpose()?)
}

/// A JSON report, rounded and free of nulls, written atomically (never over an input).
fn write_json(path: &Path, mut value: serde_json::Value) -> Result<()> {
    tidy_json(&mut value);
    let text = serde_json::to_string_pretty(&value)? + "\n";
    output::write_atomic(path, text.as_bytes()).map_err(|e| fail(format!("{}: {e}", path.display())))
}

fn check(a: CheckArgs) -> Result<()> {
    let map = channel_map(a.map.channel_map.as_deref())?;
    let log = read(&a.log, a.plant.map(Plant::from), map.as_ref())?;
    println!(
        "{}: plant {}, {} samples at {} s, columns {}",
        log.file,
        log.plant,
        log.len(),
        sig(log.dt_s, 6),
        log.order.join(", ")
    );
    for n in &log.notices {
        println!("notice: {n}");
    }
    Ok(())
}

fn diagnose(a: DiagnoseArgs) -> Result<()> {
    let inputs: Vec<&PathBuf> = std::iter::once(&a.estimation).chain(&a.validation).collect();
    output::protect_inputs(&inputs);
    // Refuse a bad output before the fits run, not after.
    if let Some(json) = &a.json {
        output::check_not_input(json)?;
    }
    if let Some(page) = &a.report {
        output::check_not_input(page)?;
    }
    let map = channel_map(a.map.channel_map.as_deref())?;
    let plant = a.plant.map(Plant::from);
    let est_full = read(&a.estimation, plant, map.as_ref())?;
    let plant = est_full.plant;
    let family = diagnose::family_for(plant).map_err(fail)?;
    // What the fits do not use of a long estimation record is not held through them (nor
    // while the validation log is read), its time stamps included (the fits use the period).
    let (est, val, tail) = match &a.validation {
        Some(v) => {
            let est = family.estimation_part(est_full).map_err(fail)?.without_time_stamps();
            (est, read(v, Some(plant), map.as_ref())?, false)
        }
        None => {
            // Moved, not copied: the held-out tail costs no second copy of the log.
            let (e, v) = est_full.split_tail(0.3);
            (family.estimation_part(e).map_err(fail)?.without_time_stamps(), v, true)
        }
    };
    for n in est.notices.iter().chain(&val.notices) {
        eprintln!("notice: {n}");
    }
    // The validation log's time stamps serve only the plots' time axis.
    let val = if a.plots.is_none() && a.report.is_none() {
        val.without_time_stamps()
    } else {
        val
    };
    let plots = match &a.plots {
        Some(dir) => {
            let identity = format!("plots of {}", canonical(&a.estimation));
            Some(OutputDir::open(dir, Claim::new("diagnose", identity), a.force)?)
        }
        None => None,
    };
    let mut line = diagnose::progress::ProgressLine::for_stderr();
    let mut show = |p: &diagnose::Progress| {
        if let Some(text) = line.render(p) {
            eprint!("{text}");
        }
    };
    // The estimation log is given away: it is freed once the fits are done.
    let d = diagnose::diagnose_owned(family.as_ref(), est, &val, tail, &Rules::default(), &mut show);
    if let Some(text) = line.finish() {
        eprint!("{text}");
    }
    let d = d.map_err(fail)?;
    print!("{}", report::summary(&d));
    if let Some(out) = &a.json {
        write_json(out, report::to_json(&d))?;
        eprintln!("report written to {}", out.display());
    }
    // The validation time of the samples the diagnosis scored (a part, when it left a regime
    // out: `validation_scope`).
    let t_s: Option<Vec<f64>> = val.col("t_s").map(|t| match &d.validation_scope {
        Some(s) => s.kept_rows.iter().flat_map(|r| t[r.clone()].iter().copied()).collect(),
        None => t.to_vec(),
    });
    if let Some(mut dir) = plots {
        let written = hil_host::plot::diagnosis_plots_timed(&d, t_s.as_deref().unwrap_or(&[]), dir.dir())
            .map_err(|e| fail(format!("{}: {e}", dir.dir().display())))?;
        for w in &written {
            dir.record(w);
            eprintln!("plot written to {}", w.display());
        }
        dir.finish()?;
    }
    if let Some(page) = &a.report {
        let plots = hil_host::plot::diagnosis_svgs(&d, t_s.as_deref());
        let mut json = report::to_json(&d);
        tidy_json(&mut json);
        let html = hil_host::html::diagnosis_page(&json, &report::summary(&d), &plots);
        output::write_atomic(page, html.as_bytes()).map_err(|e| fail(format!("{}: {e}", page.display())))?;
        eprintln!("report written to {}", page.display());
    }
    Ok(())
}

fn canonical(p: &Path) -> String {
    p.canonicalize()
        .unwrap_or_else(|_| p.to_path_buf())
        .display()
        .to_string()
}

/// The scenario file (protected as an input), or the built-in default.
fn load_scenario(file: Option<&Path>) -> Result<Scenario> {
    match file {
        None => Ok(Scenario::default_scenario()),
        Some(f) => {
            output::protect_inputs(&[f]);
            let text = std::fs::read_to_string(f).map_err(|e| fail(format!("{}: {e}", f.display())))?;
            Scenario::from_toml(f, &text).map_err(fail)
        }
    }
}

fn run_scenario(a: RunArgs) -> Result<()> {
    use hil_host::run::{run_with_unit, write_outputs, NativeLink, RunOptions};
    let scenario = load_scenario(a.scenario.as_deref())?;
    let (ecu, unit) = calibration_inputs(&a.calibration)?;
    let out = a.out.unwrap_or_else(|| PathBuf::from(format!("out/{}", scenario.name)));
    let mut dir = OutputDir::open(&out, Claim::new("run", format!("scenario {}", scenario.name)), a.force)?;
    let o = {
        let _s = Spinner::start(&format!("running scenario `{}`", scenario.name), true);
        let mut link = NativeLink::with_config(ecu).map_err(fail)?;
        run_with_unit(&scenario, &mut link, &RunOptions::default(), &unit).map_err(fail)?
    };
    let written = write_outputs(&scenario, &o, &out).map_err(|e| fail(format!("{}: {e}", out.display())))?;
    for w in &written {
        dir.record(w);
    }
    dir.finish()?;
    if let Some(page) = &a.report {
        let plots = hil_host::plot::run_svgs(&scenario, &o);
        let html = hil_host::html::run_page(&scenario.name, &o.summary.text(&scenario.name), &plots);
        output::write_atomic(page, html.as_bytes()).map_err(|e| fail(format!("{}: {e}", page.display())))?;
        eprintln!("report written to {}", page.display());
    }
    print!("{}", o.summary.text(&scenario.name));
    println!("logs (DATA-FORMAT) and plots in {}", out.display());
    summary_json(&a.calibration, &o.summary, &scenario.name)
}

fn generate(a: GenerateArgs) -> Result<()> {
    let plant = Plant::from(a.plant);
    let seed = a.seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_nanos() as u64)
    });
    let out = a
        .out
        .unwrap_or_else(|| PathBuf::from(format!("out/{}-{}-seed{seed}", plant.name(), a.effect)));
    let repeat = if a.repeat > 1 {
        format!(" --repeat {}", a.repeat)
    } else {
        String::new()
    };
    let claim = Claim::new(
        "generate",
        format!("{} {} --seed {seed}{repeat}", plant.name(), a.effect),
    );
    let known = hil_host::generate::effects(plant);
    let prbs_grid = plant == Plant::Evvt && a.effect == "prbs-grid";
    // One catalogue effect, several joined by `+`, or physics outside the catalogue.
    if !(known.contains(&a.effect.as_str()) || hil_host::generate::parse_effects(plant, &a.effect).is_ok() || prbs_grid)
    {
        use clap::CommandFactory;
        let mut cmd = Cli::command();
        cmd.build();
        let msg = format!(
            "invalid value '{}' for '<EFFECT>': {} has no such effect\n  [possible values: {}{}]",
            a.effect,
            plant.name(),
            known.join(", "),
            if plant == Plant::Evvt { ", prbs-grid" } else { "" }
        );
        let sub = cmd.find_subcommand_mut("generate").map(|c| c.clone());
        sub.unwrap_or(cmd)
            .error(clap::error::ErrorKind::InvalidValue, msg)
            .exit();
    }
    // The directory is judged before the (seconds of) generation.
    let mut dir = OutputDir::open(&out, claim, a.force)?;
    if plant == Plant::Evvt && a.effect == "prbs-grid" {
        let logs = {
            let _s = Spinner::start("generating the EVVT PRBS identification logs", true);
            hil_host::generate::evvt::identification_grid(seed).map_err(fail)?
        };
        for (name, text) in logs {
            dir.write(&name, text.as_bytes())?;
        }
        dir.finish()?;
        println!(
            "seed {seed}: wrote the nine EVVT PRBS identification logs (design table) to {}",
            out.display()
        );
        return Ok(());
    }
    let case = {
        let _s = Spinner::start(&format!("generating {} {}", plant.name(), a.effect), true);
        hil_host::generate::generate_repeated(plant, &a.effect, seed, a.repeat as usize).map_err(fail)?
    };
    let truth: serde_json::Map<String, serde_json::Value> = case
        .truth
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect();
    let mut truth = serde_json::json!({"plant": plant.name(), "effect": case.effect, "seed": seed, "params": truth});
    tidy_json(&mut truth);
    // The set as a whole: the old truth goes first and the new one comes last, so no reader
    // sees new logs next to an old truth.json; the manifest says when the set is complete.
    dir.remove_old("truth.json")?;
    dir.write("estimation.csv", case.estimation_csv.as_bytes())?;
    dir.write("validation.csv", case.validation_csv.as_bytes())?;
    dir.write("truth.json", (serde_json::to_string_pretty(&truth)? + "\n").as_bytes())?;
    dir.finish()?;
    println!(
        "seed {seed}: wrote {}/estimation.csv, validation.csv and truth.json",
        out.display()
    );
    Ok(())
}

fn identify_evvt(a: IdentifyArgs) -> Result<()> {
    use hil_host::identify::evvt;
    output::protect_inputs(&a.logs);
    if let Some(json) = &a.json {
        output::check_not_input(json)?;
    }
    let map = channel_map(a.map.channel_map.as_deref())?;
    let opts = evvt::EvvtIdentifyOptions::default();
    let counter = Counter::new("identify evvt: log", a.logs.len() as u64);
    let mut points = Vec::new();
    for (k, path) in a.logs.iter().enumerate() {
        counter.step(k as u64 + 1, a.logs.len() as u64);
        let log = read(path, Some(Plant::Evvt), map.as_ref())?;
        for n in &log.notices {
            eprintln!("notice: {}: {n}", log.file);
        }
        let rec = evvt::identify_recording(&log, &opts).map_err(fail)?;
        print!("{}", rec.report);
        for p in rec.segments {
            print!("{}", p.report);
            points.push(p);
        }
    }
    drop(counter);
    print!("{}", evvt::tables_text(&points));
    if let Some(out) = &a.json {
        write_json(out, evvt::to_json(&points))?;
        eprintln!("tables written to {}", out.display());
    }
    Ok(())
}

fn identify_ehvva(args: IdentifyEhvvaArgs) -> Result<()> {
    use hil_host::diagnose::ehvva::Events;
    use hil_host::identify::ehvva;
    let a = args.common;
    output::protect_inputs(&a.logs);
    if let Some(json) = &a.json {
        output::check_not_input(json)?;
    }
    let map = channel_map(a.map.channel_map.as_deref())?;
    let mut logs = Vec::new();
    for path in &a.logs {
        let log = read(path, Some(Plant::Ehvva), map.as_ref())?;
        for n in &log.notices {
            eprintln!("notice: {}: {n}", log.file);
        }
        logs.push(log);
    }
    let sets = logs
        .iter()
        .map(Events::from_log)
        .collect::<std::result::Result<Vec<_>, String>>()
        .map_err(fail)?;
    // Where the diagnosis cannot run (a log too short to hold out validation events), the
    // conditions are fitted on the paper's valve and the report says why.
    let (unit, no_unit) = if args.paper_valve {
        (None, "--paper-valve".to_string())
    } else {
        let _s = Spinner::start("diagnose ehvva: the unit's valve", true);
        match ehvva::unit_valve(&logs) {
            Ok(u) => (Some(u), String::new()),
            Err(e) => (None, format!("the diagnosis could not fit the unit's: {e}")),
        }
    };
    drop(logs);
    let counter = Counter::new("condition", 1);
    let mut tick = |k: usize, n: usize| counter.step(k as u64, n as u64);
    let (id, choice) = match &unit {
        None => {
            let id = ehvva::identify(&sets, &ehvva::default_options(), &mut tick).map_err(fail)?;
            (id, None)
        }
        Some(u) => {
            let (id, c) =
                ehvva::identify_unit_or_paper(&u.params, &sets, &ehvva::default_options(), &mut tick).map_err(fail)?;
            (id, Some(c))
        }
    };
    drop(counter);
    match (&unit, &choice) {
        (Some(u), Some(c)) => println!("{}{}\n", u.text(), c.text()),
        _ => println!("valve: the paper's ({no_unit})"),
    }
    print!("{}", id.text());
    if let Some(out) = &a.json {
        let mut j = id.json();
        j["valve"] = match (&unit, &choice) {
            (Some(u), Some(c)) => {
                let mut v = u.json();
                v["kept"] = serde_json::json!(if c.kept_unit { "unit" } else { "paper" });
                v["cost_unit"] = ehvva::ValveChoice::cost_json(c.unit_cost);
                v["cost_paper"] = ehvva::ValveChoice::cost_json(c.paper_cost);
                v
            }
            _ => serde_json::json!({"from": "paper", "why": no_unit}),
        };
        write_json(out, j)?;
        eprintln!("tables written to {}", out.display());
    }
    Ok(())
}

/// `pil`: the scenario with the ECU core on QEMU (hil_host::pil).
fn pil(a: PilArgs) -> Result<()> {
    use hil_host::pil::{self, LinkFaults};
    let scenario = load_scenario(a.scenario.as_deref())?;
    let out = a
        .out
        .unwrap_or_else(|| PathBuf::from(format!("out/{}-pil", scenario.name)));
    let elf = pil::find_firmware(a.elf.as_deref()).map_err(fail)?;
    output::protect_inputs(&[&elf]);
    let mut dir = OutputDir::open(&out, Claim::new("pil", format!("scenario {}", scenario.name)), a.force)?;
    let faults = LinkFaults {
        corrupt_every: a.corrupt_every,
        drop_every: a.drop_every,
    };
    let r = {
        let _s = Spinner::start(&format!("PIL run of `{}` on QEMU", scenario.name), true);
        let (_, unit) = calibration_inputs(&a.calibration)?;
        let image = a.calibration.calibration.as_deref();
        pil::run_scenario_calibrated(&scenario, &elf, faults, a.until, a.compare_native, &out, image, &unit)
            .map_err(fail)?
    };
    print!("{}", r.output.summary.text(&scenario.name));
    print!("{}", r.text());
    let written = hil_host::run::write_outputs(&scenario, &r.output, &out)
        .map_err(|e| fail(format!("{}: {e}", out.display())))?;
    for w in written
        .iter()
        .chain(&[out.join("defmt.bin"), out.join("qemu-stderr.txt")])
    {
        dir.record(w);
    }
    dir.finish()?;
    println!(
        "logs (DATA-FORMAT), plots and the firmware's defmt stream (defmt.bin: defmt-print -e {} < defmt.bin) in {} ({} files)",
        elf.display(),
        out.display(),
        written.len()
    );
    summary_json(&a.calibration, &r.output.summary, &scenario.name)?;
    if r.first_difference.is_some() {
        return Err(fail("the PIL run differs from the native run"));
    }
    Ok(())
}

/// `target-bench`: instruction counts on the emulated target (hil_host::pil::target_bench).
fn target_bench(a: TargetBenchArgs) -> Result<()> {
    use hil_host::pil;
    use hil_host::run::{run_with, NativeLink, RunOptions};
    let scenario = load_scenario(a.scenario.as_deref())?;
    let elf = pil::find_firmware(a.elf.as_deref()).map_err(fail)?;
    output::protect_inputs(&[&elf]);
    if let Some(json) = &a.json {
        output::check_not_input(json)?;
    }
    let mut dir = OutputDir::open(
        &a.out,
        Claim::new("target-bench", format!("scenario {}", scenario.name)),
        a.force,
    )?;
    // The sensor frames of the scenario's first `steps` lockstep steps, closed loop natively;
    // the target then steps its core on the same frames with every task counted.
    let until_s = f64::from(a.steps) * f64::from(model_core::ecu::lockstep::STEP_US) * 1e-6;
    let native = {
        let _s = Spinner::start(&format!("native run of the first {} steps", a.steps), true);
        run_with(
            &scenario,
            &mut NativeLink::new().map_err(fail)?,
            &RunOptions {
                until_s: Some(until_s),
                keep_frames: true,
            },
        )
        .map_err(fail)?
    };
    let frames: Vec<_> = native.frames.iter().map(|(s, _)| *s).collect();
    let b = {
        let _s = Spinner::start("counting instructions on the emulated Cortex-M4", true);
        pil::target_bench(&elf, &frames, &a.out, a.by_address).map_err(fail)?
    };
    for name in ["insn-counts.txt", "defmt.bin", "qemu-stderr.txt"] {
        dir.record(&a.out.join(name));
    }
    if a.by_address {
        dir.record(&a.out.join(pil::BY_ADDRESS_FILE));
    }
    dir.finish()?;
    print!("{}", b.text());
    println!("raw counts in {}", a.out.join("insn-counts.txt").display());
    if let Some(json) = &a.json {
        write_json(json, b.to_json())?;
    }
    // The fixed-point states must match bit for bit (integer arithmetic on both sides).
    if !(1..pil::PLANT_NUMBERS.len()).all(|k| b.plant_states_equal(k)) || !b.answers_equal_native {
        return Err(fail("the target's results differ from the host's"));
    }
    Ok(())
}

/// `--calibration` (the ECU's image, refused whole when bad) and `--unit` (a generated unit's
/// truth.json) of `run` and `pil`.
fn calibration_inputs(a: &CalibrationArgs) -> Result<(model_core::ecu::lockstep::EcuCoreConfig, hil_host::run::Unit)> {
    use hil_host::calibrate::{ecu_config_from_image, unit_from_truth};
    let ecu = match &a.calibration {
        Some(p) => ecu_config_from_image(p).map_err(fail)?,
        None => Default::default(),
    };
    let unit = match &a.unit {
        Some(p) => unit_from_truth(p).map_err(fail)?,
        None => Default::default(),
    };
    Ok((ecu, unit))
}

/// `--json`: the run's error figures per actuator.
fn summary_json(a: &CalibrationArgs, s: &hil_host::run::Summary, name: &str) -> Result<()> {
    if let Some(path) = &a.json {
        output::check_not_input(path).map_err(|e| fail(format!("{}: {e}", path.display())))?;
        write_json(path, s.json(name))?;
        println!("error figures written to {}", path.display());
    }
    Ok(())
}

/// `calibrate`: the unit's logs to calibration.bin, .a2l, .json (hil_host::calibrate).
fn calibrate(a: CalibrateArgs) -> Result<()> {
    use hil_host::calibrate::{self as cal, parse_flash_base};
    let flash_base = parse_flash_base(&a.flash_base).map_err(fail)?;
    let map = channel_map(a.map.channel_map.as_deref())?;
    output::protect_inputs(&a.logs);
    // The run is its logs: another unit's calibration in the same directory needs --force,
    // so one unit's image never silently replaces another's.
    let logs: Vec<String> = a
        .logs
        .iter()
        .map(|p| {
            std::fs::canonicalize(p)
                .unwrap_or_else(|_| p.clone())
                .display()
                .to_string()
        })
        .collect();
    let mut dir = OutputDir::open(
        &a.out,
        Claim::new("calibrate", format!("logs {}", logs.join(", "))),
        a.force,
    )?;
    let o = {
        let _s = Spinner::start("calibrating from the logs", true);
        cal::calibrate_mapped(&a.logs, map.as_ref(), &mut |_| {}).map_err(fail)?
    };
    for n in &o.notes {
        println!("{n}");
    }
    for p in cal::write_outputs(&o, &a.out, flash_base).map_err(fail)? {
        println!("wrote {}", p.display());
        dir.record(&p);
    }
    dir.finish()?;
    let learned = o.sources.iter().filter(|s| !s.logs.is_empty()).count();
    println!(
        "{learned} of {} characteristics learned from the logs, the rest paper defaults; image {} bytes for 0x{flash_base:08X}",
        model_core::ecu::calibration::CHARACTERISTICS.len(),
        model_core::ecu::calibration::IMAGE_BYTES
    );
    Ok(())
}

/// `paper-check`: every model against its paper (hil_host::paper_check).
fn paper_check(a: PaperCheckArgs) -> Result<()> {
    if hil_host::paper_check::run(a.json.as_deref()).map_err(fail)? {
        Ok(())
    } else {
        Err(fail("paper-check: some rows fail (marked FAIL above)"))
    }
}
