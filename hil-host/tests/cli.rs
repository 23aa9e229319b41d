//! The command line as a user meets it: help, version, `--opt=value`, suggestions, completions,
//! exit codes; outputs that never replace an input, never land in another run's directory
//! without --force, and are never left half-written; reports without NaN, inf or null.
use std::path::{Path, PathBuf};

use assert_cmd::Command;
use predicates::prelude::*;

fn hil_host() -> Command {
    Command::cargo_bin("hil-host").unwrap()
}

/// A fresh scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hil-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn read(p: &Path) -> String {
    std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

#[test]
fn version_and_help_of_every_command() {
    hil_host()
        .arg("--version")
        .assert()
        .success()
        .stdout(format!("hil-host {}\n", env!("CARGO_PKG_VERSION")));
    let commands: [&[&str]; 10] = [
        &["check"],
        &["diagnose"],
        &["run"],
        &["generate"],
        &["identify"],
        &["identify", "evvt"],
        &["identify", "ehvva"],
        &["pil"],
        &["target-bench"],
        &["completions"],
    ];
    for c in commands {
        let usage = format!("Usage: hil-host {}", c.join(" "));
        let a = hil_host().args(c).arg("--help").assert().success();
        let a = a.stdout(predicate::str::contains(usage));
        if c != ["identify"] {
            a.stdout(predicate::str::contains("Examples:\n  hil-host "));
        }
    }
    // No command: the help, as a usage error.
    hil_host()
        .assert()
        .code(2)
        .stderr(predicate::str::contains("Usage: hil-host <COMMAND>"));
}

#[test]
fn check_dash_h_is_help_not_a_file() {
    hil_host()
        .args(["check", "-h"])
        .assert()
        .success()
        .stdout(predicate::str::contains("Usage: hil-host check [OPTIONS] <LOG>"));
}

#[test]
fn typos_are_usage_errors_with_a_suggestion() {
    hil_host().args(["diagnos", "x.csv"]).assert().code(2).stderr(
        predicate::str::contains("unrecognized subcommand 'diagnos'").and(predicate::str::contains("'diagnose'")),
    );
    hil_host()
        .args(["generate", "positioner", "none", "--sed=3"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--seed"));
    hil_host()
        .args(["generate", "vacum", "none"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("'vacuum'"));
    hil_host()
        .args(["generate", "positioner", "none", "--seed=three"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("invalid value 'three' for '--seed <SEED>'"));
}

#[test]
fn completions_for_bash_zsh_and_fish() {
    for shell in ["bash", "zsh", "fish"] {
        hil_host()
            .args(["completions", shell])
            .assert()
            .success()
            .stdout(predicate::str::contains("hil-host").and(predicate::str::contains("target-bench")));
    }
    hil_host().args(["completions", "tcsh"]).assert().code(2);
}

/// `--seed=3` and `--seed 3` are the same option: the same logs, the seed in truth.json.
#[test]
fn seed_with_equals_sign() {
    let d = scratch("seed");
    hil_host()
        .args(["generate", "positioner", "none", "--seed=3", "--out"])
        .arg(d.join("a"))
        .assert()
        .success()
        .stdout(predicate::str::starts_with("seed 3: wrote"));
    hil_host()
        .args(["generate", "positioner", "none", "--seed", "3", "--out"])
        .arg(d.join("b"))
        .assert()
        .success();
    assert_eq!(read(&d.join("a/estimation.csv")), read(&d.join("b/estimation.csv")));
    let truth: serde_json::Value = serde_json::from_str(&read(&d.join("a/truth.json"))).unwrap();
    assert_eq!(truth["seed"], 3);
    let manifest: serde_json::Value = serde_json::from_str(&read(&d.join("a/hil-host-manifest.json"))).unwrap();
    assert_eq!(manifest["command"], "generate");
    assert_eq!(manifest["complete"], true);
    assert_eq!(
        manifest["files"],
        serde_json::json!(["estimation.csv", "validation.csv", "truth.json"])
    );
    std::fs::remove_dir_all(&d).ok();
}

/// `diagnose in.csv --json in.csv` (or any other spelling of the same file) is refused and the
/// log is untouched.
#[test]
fn an_output_never_replaces_an_input() {
    let d = scratch("inputs");
    hil_host()
        .args(["generate", "positioner", "none", "--seed=5", "--out"])
        .arg(d.join("g"))
        .assert()
        .success();
    let est = d.join("g/estimation.csv");
    let before = read(&est);
    let alias = d.join("g/../g/./estimation.csv");
    let link = d.join("hard-link.csv");
    std::fs::hard_link(&est, &link).unwrap();
    for out in [&est, &alias, &link] {
        hil_host()
            .arg("diagnose")
            .arg(&est)
            .arg("--json")
            .arg(out)
            .assert()
            .code(1)
            .stderr(predicate::str::contains("refusing to write").and(predicate::str::contains("it is the input")));
    }
    // The validation log is an input too.
    hil_host()
        .arg("diagnose")
        .arg(&est)
        .arg("--validation")
        .arg(d.join("g/validation.csv"))
        .arg("--json")
        .arg(d.join("g/validation.csv"))
        .assert()
        .code(1);
    assert_eq!(read(&est), before);
    std::fs::remove_dir_all(&d).ok();
}

/// A directory of other files, or of another run's outputs, is refused without --force; the
/// same run again is fine.
#[test]
fn force_is_needed_for_a_foreign_directory() {
    let d = scratch("force");
    std::fs::write(d.join("notes.txt"), "someone's notes").unwrap();
    hil_host()
        .args(["generate", "positioner", "none", "--seed=1", "--out"])
        .arg(&d)
        .assert()
        .code(1)
        .stderr(predicate::str::contains("notes.txt").and(predicate::str::contains("--force")));
    assert!(!d.join("estimation.csv").exists());
    hil_host()
        .args(["generate", "positioner", "none", "--seed=1", "--force", "--out"])
        .arg(&d)
        .assert()
        .success();
    assert_eq!(read(&d.join("notes.txt")), "someone's notes");

    let g = d.join("g");
    let generate = |seed: &str| {
        let mut c = hil_host();
        c.args(["generate", "positioner", "none", "--seed", seed, "--out"])
            .arg(&g);
        c
    };
    generate("1").assert().success();
    generate("1").assert().success();
    let first = read(&g.join("estimation.csv"));
    generate("2").assert().code(1).stderr(predicate::str::contains(
        "holds the outputs of `hil-host generate` (positioner none --seed 1)",
    ));
    assert_eq!(read(&g.join("estimation.csv")), first);
    std::fs::remove_dir_all(&d).ok();
}

/// A generate killed while writing (the file size limit sends SIGXFSZ in the middle of the
/// ~1 MB estimation log) leaves the earlier log whole, no truth.json that would belong to
/// another set, and a manifest that says the set is incomplete.
#[test]
fn a_killed_write_leaves_the_old_file_whole() {
    let d = scratch("atomic");
    let g = d.join("g");
    hil_host()
        .args(["generate", "positioner", "none", "--seed=4", "--out"])
        .arg(&g)
        .assert()
        .success();
    let old = read(&g.join("estimation.csv"));
    assert!(old.len() > 400_000, "the log must exceed the limit below");
    // `ulimit -f` counts 512- or 1024-byte blocks by shell: 256 blocks is at most 256 KiB.
    let bin = assert_cmd::cargo::cargo_bin("hil-host");
    let status = std::process::Command::new("sh")
        .arg("-c")
        .arg("ulimit -f 256 && exec \"$0\" \"$@\"")
        .arg(&bin)
        .args(["generate", "positioner", "none", "--seed=9", "--force", "--out"])
        .arg(&g)
        .status()
        .unwrap();
    assert!(
        !status.success(),
        "the write should have been stopped by the size limit"
    );
    assert_eq!(read(&g.join("estimation.csv")), old, "the old log is whole");
    assert!(
        !g.join("truth.json").exists(),
        "no truth.json beside logs it may not belong to"
    );
    let manifest: serde_json::Value = serde_json::from_str(&read(&g.join("hil-host-manifest.json"))).unwrap();
    assert_eq!(manifest["complete"], false);
    // The next run completes the set.
    hil_host()
        .args(["generate", "positioner", "none", "--seed=9", "--force", "--out"])
        .arg(&g)
        .assert()
        .success();
    assert!(g.join("truth.json").exists());
    std::fs::remove_dir_all(&d).ok();
}

/// A vacuum log without excitation (every column held at its first value): the report says
/// the fit cannot be computed and why, instead of `gain NaN %` and `fit 100.0 %`; its JSON has
/// no NaN, inf or null.
#[test]
fn a_log_without_excitation_is_reported_as_not_computable() {
    let d = scratch("flat");
    let case = hil_host::generate::generate(hil_host::log::Plant::Vacuum, "none", 2).unwrap();
    let mut flat = String::new();
    let mut first: Option<Vec<String>> = None;
    let mut header_seen = false;
    for line in case.estimation_csv.lines() {
        if line.starts_with('#') || !header_seen {
            header_seen |= !line.starts_with('#');
            flat += line;
        } else {
            let values: Vec<String> = line.split(',').map(String::from).collect();
            let f = first.get_or_insert_with(|| values.clone());
            // Time runs on; everything else stays at the first sample.
            flat += &std::iter::once(values[0].as_str())
                .chain(f[1..].iter().map(String::as_str))
                .collect::<Vec<_>>()
                .join(",");
        }
        flat.push('\n');
    }
    let log = d.join("flat.csv");
    std::fs::write(&log, flat).unwrap();
    let json = d.join("report.json");
    let out = hil_host()
        .arg("diagnose")
        .arg(&log)
        .arg("--json")
        .arg(&json)
        .assert()
        .success()
        .get_output()
        .clone();
    let stdout = String::from_utf8_lossy(&out.stdout);
    for bad in ["NaN", "inf", "fit 100.0 %"] {
        assert!(!stdout.contains(bad), "`{bad}` in\n{stdout}");
    }
    assert!(
        stdout.contains("fit not computable") && stdout.contains("no excitation in duty_pct"),
        "{stdout}"
    );
    let text = read(&json);
    for bad in ["null", "NaN", "inf"] {
        assert!(!text.contains(bad), "`{bad}` in {text}");
    }
    let r: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(r["baseline"].get("fit_pct").is_none());
    let why = r["baseline"]["not_computable"]["fit_pct"].as_str().unwrap();
    assert!(why.contains("x_pct does not vary") && why.contains("duty_pct"), "{why}");
    assert_eq!(r["cause"], "none");
    assert_eq!(r["gain_pct"], 0.0);
    // The verdict says why nothing can be judged; it does not claim physics outside the
    // catalogue against a floor of 0.
    assert_eq!(r["verdict"], "unexplained");
    let rest = r["remainder"]["evidence"].to_string();
    assert!(rest.contains("does not vary on the validation data"), "{rest}");
    assert!(
        !stdout.contains("physics outside the catalogue") && !stdout.contains("not comparable"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&d).ok();
}

#[test]
fn a_missing_firmware_image_is_named() {
    hil_host()
        .args(["pil", "--elf", "/nonexistent/firmware-qemu", "--out"])
        .arg(scratch("elf").join("out"))
        .assert()
        .code(1)
        .stderr(predicate::str::contains(
            "--elf /nonexistent/firmware-qemu: no such firmware image",
        ));
}

/// The workspace (for the firmware image and the QEMU plugin) is found at run time from the
/// current directory: cargo runs this test in hil-host/, inside it.
#[test]
fn the_workspace_is_found_at_run_time() {
    let root = hil_host::pil::workspace_root().expect("inside the workspace");
    let expected = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .canonicalize()
        .unwrap();
    assert_eq!(root.canonicalize().unwrap(), expected);
    assert!(hil_host::pil::firmware_elf_path(&root).ends_with("thumbv7em-none-eabihf/firmware/firmware-qemu"));
}
