//! `identify evvt` (Yang 2015): closed-loop PRBS logs generated from known α, β (sensor noise,
//! 1-degree quantization, phase sampled per cam event and held) give α and β back; the
//! 9-point family gives LPV tables whose step responses match the generating table; bad logs
//! give errors that name the file and what is missing.

use std::path::{Path, PathBuf};

use hil_host::generate::evvt::{identification_log, IdentificationExperiment, PhaseSampling};
use hil_host::identify::evvt::{identify_log, lpv_table, EvvtIdentifyOptions, EvvtPointResult};
use hil_host::log::{format_log, parse_log};
use model_core::evvt::{EvvtLpvTable, EvvtParams, EvvtPlant};

fn experiment(table: EvvtLpvTable, engine_rpm: f64, u_batt_v: f64, seed: u64) -> IdentificationExperiment {
    IdentificationExperiment {
        params: EvvtParams {
            lpv: table,
            ..EvvtParams::default()
        },
        engine_rpm,
        u_batt_v,
        seed,
        ..Default::default()
    }
}

fn identify_text(name: &str, text: &str) -> Result<EvvtPointResult, String> {
    let log = parse_log(name, text, None).map_err(|e| e.to_string())?;
    identify_log(&log, &EvvtIdentifyOptions::default())
}

fn rel_err_pct(x: f64, truth: f64) -> f64 {
    100.0 * (x / truth - 1.0)
}

/// The four corners and the middle of the design table, cam-event sampling (4 per cycle),
/// 0.3 deg noise and 1 deg quantization, plus the slowest corner with the phase sampled every
/// control period: α and β within 5 %.
#[test]
fn known_alpha_beta_come_back_within_5_percent() {
    let design = EvvtLpvTable::PAPER_DESIGN;
    let cases = [(0, 0, 11), (0, 2, 12), (2, 0, 13), (2, 2, 14), (1, 1, 15)];
    let mut worst: f64 = 0.0;
    for &(i, j, seed) in &cases {
        let (n, v) = (design.engine_speed_rpm[i], design.battery_voltage_v[j]);
        let (a, b) = (design.alpha_deg_per_s2_rpm[i][j], design.beta_per_s[i][j]);
        let text = identification_log(&experiment(EvvtLpvTable::uniform(a, b), n, v, seed)).unwrap();
        let r = identify_text(&format!("{n}rpm-{v}V.csv"), &text).unwrap();
        let (ea, eb) = (rel_err_pct(r.alpha, a), rel_err_pct(r.beta, b));
        println!("{n} rpm {v} V: alpha {:.4} (true {a}, {ea:+.2} %), beta {:.4} (true {b}, {eb:+.2} %), order {}, pole map {:+.2} % / {:+.2} %", r.alpha, r.beta, r.order, rel_err_pct(r.alpha_map, a), rel_err_pct(r.beta_map, b));
        assert!(ea.abs() < 5.0 && eb.abs() < 5.0, "{}", r.report);
        // The multi-rate data were recognised: PRBS clock, operating point, cam hold.
        assert_eq!(r.prbs_hold_periods, 10);
        assert!((r.engine_rpm - n).abs() < 2.0 && (r.u_batt_v - v).abs() < 0.02);
        assert!(
            (r.measurement_delay_s - 15.0 / n).abs() < 1e-3 * 15.0 / n,
            "τ = half the cam period 30/N"
        );
        // A dominant pair: the order is chosen at a clear gap of the Hankel singular values.
        assert!(r.order >= 2 && r.hankel_sv[r.order - 1] > 5.0 * r.hankel_sv[r.order]);
        assert!(r.realization_vaf_pct > 98.0);
        worst = worst.max(ea.abs()).max(eb.abs());
    }
    // Phase fresh at every control instant (no cam hold, τ = 0), slowest corner.
    let (a, b) = (design.alpha_deg_per_s2_rpm[2][0], design.beta_per_s[2][0]);
    let x = IdentificationExperiment {
        phase_sampling: PhaseSampling::ControlPeriod,
        ..experiment(EvvtLpvTable::uniform(a, b), 1400.0, 9.5, 16)
    };
    let r = identify_text("fresh.csv", &identification_log(&x).unwrap()).unwrap();
    assert_eq!(r.measurement_delay_s, 0.0);
    let (ea, eb) = (rel_err_pct(r.alpha, a), rel_err_pct(r.beta, b));
    println!("1400 rpm 9.5 V, phase every control period: {ea:+.2} % / {eb:+.2} %");
    assert!(ea.abs() < 5.0 && eb.abs() < 5.0, "{}", r.report);
    println!("worst |error| over the cam-sampled points: {worst:.2} %");
}

/// The multi-rate generator: with cam-event sampling the logged (held) phase can only change
/// at cam events, at 800 rpm every 37.5 ms, so never in rows fewer than 3 apart; sampled every
/// control period it does change in consecutive rows. Both obey the stated control law.
#[test]
fn cam_event_sampling_holds_the_phase_between_events() {
    let change_gaps = |sampling: PhaseSampling| {
        let x = IdentificationExperiment {
            phase_sampling: sampling,
            prbs_periods: 0.2,
            ..experiment(EvvtLpvTable::PAPER_DESIGN, 800.0, 14.0, 3)
        };
        let log = parse_log("g.csv", &identification_log(&x).unwrap(), None).unwrap();
        let (c, r, y) = (
            log.col("motor_cmd_rpm").unwrap(),
            log.col("phase_ref_deg").unwrap(),
            log.col("phase_deg").unwrap(),
        );
        let kp = log.meta_f64("kp").unwrap().unwrap();
        for k in 0..log.len() {
            assert_eq!(c[k], (kp * (r[k] - y[k])).clamp(-1000.0, 1000.0));
            assert_eq!(y[k], y[k].round());
        }
        let changes: Vec<usize> = (1..y.len()).filter(|&k| y[k] != y[k - 1]).collect();
        assert!(changes.len() > 100, "the phase moves");
        changes.windows(2).map(|w| w[1] - w[0]).min().unwrap_or(0)
    };
    assert!(change_gaps(PhaseSampling::CamEvents { events_per_cycle: 4 }) >= 3);
    assert_eq!(change_gaps(PhaseSampling::ControlPeriod), 1);
}

/// Unit-step phase response of the plant built from `table` at (N, V) over 0.5 s (model-core
/// EvvtPlant, 1 ms steps, 1 rpm command).
fn step_response(table: &EvvtLpvTable, n: f64, v: f64) -> Vec<f64> {
    let mut plant = EvvtPlant::<f64>::new(&EvvtParams {
        lpv: *table,
        initial_phase_deg: 20.0,
        ..EvvtParams::default()
    })
    .unwrap();
    (0..500).map(|_| plant.step(1.0, n, v, 0.001) - 20.0).collect()
}

fn hil_host_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_hil-host"))
}

/// The nine test points of Section IV-B (800/1100/1400 rpm × 9.5/11.5/14 V) from the design
/// table, through the command line (`identify evvt <9 logs> --json`): the JSON has the
/// stated fields, the table forms the 3×3 grid, and at the grid points and four points
/// between them the unit-step phase response of the identified table matches the generating
/// one: max |y_id − y_true| over 0.5 s below 5 % of the true final slope times 0.5 s.
#[test]
fn nine_point_family_gives_tables_with_matching_step_responses() {
    let design = EvvtLpvTable::PAPER_DESIGN;
    let dir = std::env::temp_dir().join(format!("identify-evvt-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut files = Vec::new();
    for i in 0..3 {
        for j in 0..3 {
            let (n, v) = (design.engine_speed_rpm[i], design.battery_voltage_v[j]);
            let text = identification_log(&experiment(design, n, v, 100 + 3 * i as u64 + j as u64)).unwrap();
            let path = dir.join(format!("prbs-{n}rpm-{v}V.csv"));
            std::fs::write(&path, text).unwrap();
            files.push(path);
        }
    }
    let json_path = dir.join("evvt.json");
    let out = std::process::Command::new(hil_host_bin())
        .arg("identify")
        .arg("evvt")
        .args(&files)
        .arg("--json")
        .arg(&json_path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}\n{}",
        stdout,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("Hankel singular values") && stdout.contains("EvvtLpvTable {"),
        "{stdout}"
    );
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    let points = doc["points"].as_array().unwrap();
    assert_eq!(points.len(), 9);
    // Rebuild the points from the JSON (what a user of the file gets) and form the table.
    let mut results = Vec::new();
    for p in points {
        for key in ["engine_rpm", "u_batt_V", "alpha", "beta", "order"] {
            assert!(p[key].is_number(), "field {key} in {p}");
        }
        let log_path = p["file"].as_str().unwrap();
        let log = hil_host::log::read_log(Path::new(log_path), None).unwrap();
        let r = identify_log(&log, &EvvtIdentifyOptions::default()).unwrap();
        // The JSON carries 6 significant digits (hil_host::numbers::JSON_DIGITS).
        for (got, json) in [(r.alpha, &p["alpha"]), (r.beta, &p["beta"])] {
            let json = json.as_f64().unwrap();
            assert!((got - json).abs() <= 1e-5 * got.abs(), "{got} vs JSON {json}");
        }
        results.push(r);
    }
    let table = lpv_table(&results).unwrap();
    for k in 0..3 {
        assert!((table.engine_speed_rpm[k] - design.engine_speed_rpm[k]).abs() < 2.0);
        assert!((table.battery_voltage_v[k] - design.battery_voltage_v[k]).abs() < 0.02);
    }
    let mut worst = (0.0f64, 0.0, 0.0);
    let mut worst_param: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            worst_param = worst_param
                .max(rel_err_pct(table.alpha_deg_per_s2_rpm[i][j], design.alpha_deg_per_s2_rpm[i][j]).abs())
                .max(rel_err_pct(table.beta_per_s[i][j], design.beta_per_s[i][j]).abs());
        }
    }
    let mut checks: Vec<(f64, f64)> = design
        .engine_speed_rpm
        .iter()
        .flat_map(|&n| design.battery_voltage_v.iter().map(move |&v| (n, v)))
        .collect();
    checks.extend([(950.0, 10.5), (950.0, 12.75), (1250.0, 10.5), (1250.0, 12.75)]);
    for (n, v) in checks {
        let truth = step_response(&design, n, v);
        let ident = step_response(&table, n, v);
        let (a, b) = EvvtPlant::<f64>::new(&EvvtParams {
            lpv: design,
            ..EvvtParams::default()
        })
        .unwrap()
        .alpha_beta(n, v);
        let scale = a / b * 0.5;
        let err = truth.iter().zip(&ident).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max) / scale;
        println!(
            "{n} rpm {v} V: step response error {:.2} % of slope × 0.5 s",
            100.0 * err
        );
        if err > worst.0 {
            worst = (err, n, v);
        }
    }
    println!(
        "nine-point family: worst α/β error {worst_param:.2} %, worst step-response error {:.2} % at {} rpm, {} V",
        100.0 * worst.0,
        worst.1,
        worst.2
    );
    assert!(worst_param < 5.0, "table entry off by {worst_param:.2} %");
    assert!(
        worst.0 < 0.05,
        "step responses differ by {:.2} % at {} rpm {} V",
        100.0 * worst.0,
        worst.1,
        worst.2
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad logs: no kp, no reference column (open loop), a command that does not follow the
/// stated law, a step-test reference instead of a PRBS. Each error names the file and what
/// is missing.
#[test]
fn bad_logs_give_errors_naming_file_and_what_is_missing() {
    let x = IdentificationExperiment {
        prbs_periods: 0.5,
        ..experiment(EvvtLpvTable::PAPER_DESIGN, 1100.0, 11.5, 7)
    };
    let good = identification_log(&x).unwrap();
    assert!(identify_text("good.csv", &good).is_ok());

    let no_kp: String = good
        .lines()
        .filter(|l| !l.starts_with("# kp:"))
        .map(|l| format!("{l}\n"))
        .collect();
    let e = identify_text("no-kp.csv", &no_kp).unwrap_err();
    assert!(e.starts_with("no-kp.csv:") && e.contains("`# kp:`"), "{e}");

    // Open loop: the bench log without the reference column.
    let log = parse_log("x.csv", &good, None).unwrap();
    let cols = ["t_s", "motor_cmd_rpm", "engine_rpm", "u_batt_V", "phase_deg"];
    let data: Vec<(&str, &[f64])> = cols.iter().map(|c| (*c, log.col(c).unwrap())).collect();
    let meta: Vec<(String, String)> = log.meta.clone();
    let e = identify_text("open-loop.csv", &format_log(&meta, &data)).unwrap_err();
    assert!(
        e.starts_with("open-loop.csv:") && e.contains("phase_ref_deg") && e.contains("open-loop"),
        "{e}"
    );

    // The reference column is there but the command is an open-loop PRBS of its own.
    let cmd: Vec<f64> = log
        .col("phase_ref_deg")
        .unwrap()
        .iter()
        .map(|r| 20.0 * (r - 25.0))
        .collect();
    let mut data: Vec<(&str, &[f64])> = cols.iter().map(|c| (*c, log.col(c).unwrap())).collect();
    data[1] = ("motor_cmd_rpm", &cmd);
    data.push(("phase_ref_deg", log.col("phase_ref_deg").unwrap()));
    let e = identify_text("not-closed.csv", &format_log(&meta, &data)).unwrap_err();
    assert!(
        e.starts_with("not-closed.csv:") && e.contains("does not follow kp"),
        "{e}"
    );

    // A step/ramp validation log of the diagnosis generator: closed loop, but not a PRBS.
    let case = hil_host::generate::evvt::generate("none", 4).unwrap();
    let e = identify_text("steps.csv", &case.validation_csv).unwrap_err();
    assert!(e.starts_with("steps.csv:") && e.contains("two-level PRBS"), "{e}");

    // Through the command line: a missing file is named.
    let out = std::process::Command::new(hil_host_bin())
        .args(["identify", "evvt", "/nonexistent/prbs.csv"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/prbs.csv"));
}

/// The long sweep (README numbers): the nine design points × 10 seeds, cam-event sampling,
/// noise and quantization; prints the worst and RMS α, β errors per point and overall.
/// `cargo test -p hil-host --test identify_evvt -- --ignored --nocapture`
#[test]
#[ignore]
fn sweep_nine_points_ten_seeds() {
    let design = EvvtLpvTable::PAPER_DESIGN;
    let (mut worst_a, mut worst_b, mut sum2, mut count) = (0.0f64, 0.0f64, 0.0, 0);
    for i in 0..3 {
        for j in 0..3 {
            let (n, v) = (design.engine_speed_rpm[i], design.battery_voltage_v[j]);
            let (a, b) = (design.alpha_deg_per_s2_rpm[i][j], design.beta_per_s[i][j]);
            let (mut wa, mut wb) = (0.0f64, 0.0f64);
            for seed in 0..10 {
                let text =
                    identification_log(&experiment(design, n, v, 1000 + 37 * seed + 3 * i as u64 + j as u64)).unwrap();
                let r = identify_text("sweep.csv", &text).unwrap();
                let (ea, eb) = (rel_err_pct(r.alpha, a), rel_err_pct(r.beta, b));
                wa = wa.max(ea.abs());
                wb = wb.max(eb.abs());
                sum2 += ea * ea + eb * eb;
                count += 2;
            }
            println!("{n} rpm {v} V: worst |α error| {wa:.2} %, worst |β error| {wb:.2} % over 10 seeds");
            worst_a = worst_a.max(wa);
            worst_b = worst_b.max(wb);
        }
    }
    let rms = (sum2 / count as f64).sqrt();
    println!("all 90 logs: worst |α error| {worst_a:.2} %, worst |β error| {worst_b:.2} %, RMS {rms:.2} %");
    assert!(worst_a < 5.0 && worst_b < 5.0);
}

/// Section IV-B / Fig. 8: the timing-belt vibration (a phase disturbance locked to crank
/// angle) shows in the identified model as an extra lightly damped pole pair at its frequency,
/// which the Hankel singular values report as order 4 (the paper's 4th-order model with "the
/// small spike"); α and β, fitted around crossover, stay within 5 %.
#[test]
fn belt_vibration_shows_as_a_4th_order_mode_without_biasing_alpha_beta() {
    let (a, b) = (0.34, 4.7);
    let mut x = experiment(EvvtLpvTable::uniform(a, b), 1100.0, 11.5, 21);
    x.params.belt_vibration_amplitude_deg = 1.0;
    x.params.belt_vibration_order = 0.5;
    let r = identify_text("belt.csv", &identification_log(&x).unwrap()).unwrap();
    let (ea, eb) = (rel_err_pct(r.alpha, a), rel_err_pct(r.beta, b));
    let belt_hz = 0.5 * 1100.0 / 60.0;
    let pole_hz: Vec<f64> = r
        .closed_loop_poles_z
        .iter()
        .map(|p| p.1.atan2(p.0).abs() / (2.0 * std::f64::consts::PI * r.control_period_s))
        .collect();
    println!("belt vibration 1 deg at {belt_hz:.2} Hz: order {}, pole frequencies {pole_hz:.2?} Hz, α {ea:+.2} %, β {eb:+.2} %", r.order);
    assert_eq!(r.order, 4, "{}", r.report);
    assert!(
        pole_hz.iter().filter(|f| (*f / belt_hz - 1.0).abs() < 0.02).count() == 2,
        "{}",
        r.report
    );
    assert!(ea.abs() < 5.0 && eb.abs() < 5.0, "{}", r.report);
}
