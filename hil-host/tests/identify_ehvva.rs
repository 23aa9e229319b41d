//! `identify ehvva` on bench logs over a Table 1-like matrix (4 supply pressures × 5
//! temperatures; low lift at 1 MPa back pressure with the switch valve off and on (dwell 8 and
//! 20 ms), low lift at 3 MPa back pressure (dwell 8 and 20 ms), high lift from 6 MPa, 50 kHz,
//! lift noise 3 µm). Two readings of td (identify's module doc): pass 1, td from the command
//! to the lift onset with τp and Cd fitted under it (the method), and pass 2, td fitted
//! jointly with τp and Cd.
//! - From the reduced model (eq. (12)), whose parameters τp, Cd and td are exactly the tables:
//!   with exact or with the bench's noisy pressure and temperature channels both td readings,
//!   τp and Cd within 5 % per condition and on the tables' breakpoints (the supply set-point's
//!   error moves the solution along the td-τp ridge, correlation about −0.99: two
//!   raised-back-pressure events per condition instead of one hold τp to 3.2 % instead of 5.1 %).
//! - From the ninth-order model (EhvvaFull, eq. (9); matrix without the raised back pressure,
//!   which the reduced model does not follow at 5 MPa and −20/0 °C, with the 1 MPa low-lift
//!   tests repeated at the other dwell), which has no τp of its own: its explicit delays are
//!   the table's td less its solenoid/pilot/main chain's own lag (linear in Ph), calibrated
//!   (model-core `full_model_dynamic_lag_is_calibrated`) so that its main-valve pressure is
//!   half-way td + ln2·τp after the command, as the reduced model's delayed Pmo is. Its
//!   generating tables are td(Ph, T) and Cd(T): the onset td and Cd within 5 % per condition;
//!   the joint fit's td + ln2·τp within 6 % (its td alone slides along the ridge: τp is the
//!   reduced model's equivalent of the main valve's metering ramp), τp in range, the paper's
//!   trends.
use std::f64::consts::LN_2;

use hil_host::diagnose::ehvva::Events;
use hil_host::generate::ehvva::{log_text, run_bench, BenchPlant, Sensors, Test};
use hil_host::generate::Rng;
use hil_host::identify::ehvva::{default_options, identify, Identified};
use hil_host::log::parse_log;

use model_core::ehvva::{EhvvaFull, EhvvaInputs, EhvvaParams, EhvvaReduced, EhvvaTableData, EhvvaTables};

/// The raised back pressure of one event per condition, MPa.
const BACK_HIGH_MPA: f64 = 3.0;
/// Log period of the bench, ms (50 kHz).
const DT_MS: f64 = 0.02;

/// The test matrix (module doc); high lift from 6 MPa only, as in Table 1 (at 5 MPa the
/// valve would float short of its 7.5 mm stop). `repeated`: the two low-lift tests at 1 MPa
/// again with the other dwell (a bench repeats tests to average the noise).
fn matrix(raised_back: bool, repeated: bool) -> Vec<Test> {
    let mut tests = Vec::new();
    for ph in [5.0, 6.0, 7.0, 8.0] {
        for t in [-20.0, 0.0, 22.0, 60.0, 100.0] {
            let at = |p_back_mpa: f64, lift_high: bool, snubber_on: bool, dwell_ms: f64| Test {
                inputs: EhvvaInputs {
                    p_supply_mpa: ph,
                    p_back_mpa,
                    temp_c: t,
                    lift_high,
                    snubber_on,
                },
                dwell_ms,
            };
            tests.push(at(1.0, false, false, 8.0));
            tests.push(at(1.0, false, true, 20.0));
            if repeated {
                tests.push(at(1.0, false, false, 20.0));
                tests.push(at(1.0, false, true, 8.0));
            }
            // A raised back pressure moves the fraction of the pressure rise at which the
            // piston starts: the onset moves by a different multiple of τp than at 1 MPa,
            // which separates τp from td.
            if raised_back {
                tests.push(at(BACK_HIGH_MPA, false, false, 8.0));
                tests.push(at(BACK_HIGH_MPA, false, false, 20.0));
            }
            if ph >= 6.0 {
                tests.push(at(1.0, true, true, 8.0));
                tests.push(at(1.0, true, false, 20.0));
            }
        }
    }
    tests
}

/// The bench's sensors: lift 3 µm noise on 2 µm steps; pressures 0.01 MPa on 5 kPa steps and
/// temperature 0.3 °C on 0.1 °C steps unless `exact_setpoints`.
fn sensors(exact_setpoints: bool) -> Sensors {
    let s = Sensors {
        lift_sigma_mm: 0.003,
        lift_lsb_mm: 0.002,
        p_sigma_mpa: 0.01,
        p_lsb_mpa: 0.005,
        temp_sigma_c: 0.3,
        temp_lsb_c: 0.1,
    };
    if exact_setpoints {
        Sensors {
            p_sigma_mpa: 0.0,
            p_lsb_mpa: 0.0,
            temp_sigma_c: 0.0,
            temp_lsb_c: 0.0,
            ..s
        }
    } else {
        s
    }
}

fn identify_bench<P: BenchPlant>(
    sensors: Sensors,
    raised_back: bool,
    repeated: bool,
    make: impl FnMut(&EhvvaInputs<f64>) -> Result<P, String>,
) -> Identified {
    let cols = run_bench(&matrix(raised_back, repeated), DT_MS, &sensors, &mut Rng::new(7), make).unwrap();
    let log = parse_log("bench.csv", &log_text("bench", DT_MS, &cols), None).unwrap();
    let set = Events::from_log(&log).unwrap();
    let id = identify(std::slice::from_ref(&set), &default_options(), &mut |_, _| {}).unwrap();
    print!("{}", id.text());
    assert_eq!(id.conditions.len(), 20, "one condition per (Ph, T) of the matrix");
    for c in &id.conditions {
        assert!(
            c.iterations > 0 && c.cost <= c.initial_cost && c.cd_ci95.is_some(),
            "solver evidence at {} MPa {} °C: {c:?}",
            c.p_supply_mpa,
            c.temp_c
        );
    }
    id
}

/// Largest relative deviation per condition of td from the lift onset (pass 1, the issue's
/// td), of Cd (both passes) and of τp (joint fit) from the generating tables at the
/// condition's (Ph, T), with its name.
fn worst_onset_and_cd(id: &Identified, p: &EhvvaParams) -> [(f64, String); 3] {
    let tables = EhvvaTables::<f64>::new(p).unwrap();
    let mut w = [(0.0, String::new()), (0.0, String::new()), (0.0, String::new())];
    for c in &id.conditions {
        let (vo, vc) = tables.t_delay_pair_ms(c.p_supply_mpa, c.temp_c);
        let at = format!("at {:.2} MPa, {:.1} °C", c.p_supply_mpa, c.temp_c);
        for (k, name, got, want) in [
            (0, "onset td VO", c.td_open_onset_ms, vo),
            (0, "onset td VC", c.td_close_onset_ms, vc),
            (1, "Cd", c.cd, tables.cd(c.temp_c)),
            (1, "Cd pass 1", c.cd_onset, tables.cd(c.temp_c)),
            (2, "tau_p", c.tau_p_ms, tables.tau_p_ms(c.p_supply_mpa, c.temp_c)),
        ] {
            let r = (got / want - 1.0).abs();
            if r > w[k].0 {
                w[k] = (r, format!("{name} {at}: {got:.4} vs {want:.4}"));
            }
        }
    }
    println!(
        "worst per condition: onset td {:.1} % ({}), Cd {:.1} % ({}), tau_p {:.1} % ({})",
        100.0 * w[0].0,
        w[0].1,
        100.0 * w[1].0,
        w[1].1,
        100.0 * w[2].0,
        w[2].1
    );
    w
}

/// Largest relative deviation of the (td, τp, Cd) entries, with its name.
fn worst(got: &EhvvaTableData, want: &EhvvaTableData) -> [(f64, String); 3] {
    let mut w = [(0.0, String::new()), (0.0, String::new()), (0.0, String::new())];
    let mut check = |k: usize, name: String, a: f64, b: f64| {
        let r = (a / b - 1.0).abs();
        if r > w[k].0 {
            w[k] = (r, format!("{name}: {a:.4} vs {b:.4}"));
        }
    };
    for i in 0..4 {
        for j in 0..5 {
            check(
                0,
                format!("td VO at {} MPa, {} °C", want.td_p_supply_mpa[i], want.td_temp_c[j]),
                got.td_open_ms[i][j],
                want.td_open_ms[i][j],
            );
            check(
                0,
                format!("td VC at {} MPa, {} °C", want.td_p_supply_mpa[i], want.td_temp_c[j]),
                got.td_close_ms[i][j],
                want.td_close_ms[i][j],
            );
        }
    }
    for i in 0..2 {
        for j in 0..3 {
            check(
                1,
                format!("tau_p at {} MPa, {} °C", want.tau_p_supply_mpa[i], want.tau_temp_c[j]),
                got.tau_ms[i][j],
                want.tau_ms[i][j],
            );
        }
    }
    for k in 0..4 {
        check(2, format!("Cd at {} °C", want.cd_temp_c[k]), got.cd[k], want.cd[k]);
    }
    println!(
        "worst td {:.1} % ({}), tau_p {:.1} % ({}), Cd {:.1} % ({})",
        100.0 * w[0].0,
        w[0].1,
        100.0 * w[1].0,
        w[1].1,
        100.0 * w[2].0,
        w[2].1
    );
    w
}

/// With exact pressure and temperature channels (lift noise as on the bench) the joint fit
/// recovers all three tables within 5 %: τp is identifiable from the lift although td and τp
/// correlate at about −0.99 (the raised back-pressure event and the closing edges separate
/// them), and the solver's CIs hold.
#[test]
fn tables_from_reduced_model_logs_match_the_generating_ones() {
    let p = EhvvaParams::paper_default();
    let id = identify_bench(sensors(true), true, false, |i| {
        EhvvaReduced::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    });
    let [td, tau, cd] = worst(&id.table_data(), &p.tables);
    assert!(td.0 < 0.05, "{}", td.1);
    assert!(tau.0 < 0.05, "{}", tau.1);
    assert!(cd.0 < 0.05, "{}", cd.1);
    let [onset, cd_condition, tau_condition] = worst_onset_and_cd(&id, &p);
    assert!(onset.0 < 0.05, "{}", onset.1);
    assert!(cd_condition.0 < 0.05, "{}", cd_condition.1);
    assert!(tau_condition.0 < 0.05, "{}", tau_condition.1);
    for c in &id.conditions {
        let r = c.corr_td_open_tau_p.expect("JᵀJ regular");
        assert!(r < -0.8, "td VO and tau_p trade off (later onset = slower rise): r {r}");
    }
}

/// With the bench's noisy pressure channels, the supply set-point read before each command
/// carries an error the fit cannot see (errors in variables) and along the td-τp ridge it moves
/// τp: 12 % off with a set-point per event, 5.1 % with one per condition (the events pooled)
/// and one raised-back-pressure event, 3.2 % with two (dwell 8 and 20 ms).
#[test]
fn tables_from_noisy_reduced_model_logs() {
    let p = EhvvaParams::paper_default();
    let id = identify_bench(sensors(false), true, false, |i| {
        EhvvaReduced::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    });
    let [td, tau, cd] = worst(&id.table_data(), &p.tables);
    assert!(td.0 < 0.05, "{}", td.1);
    assert!(tau.0 < 0.05, "{}", tau.1);
    assert!(cd.0 < 0.05, "{}", cd.1);
    let [onset, cd_condition, tau_condition] = worst_onset_and_cd(&id, &p);
    assert!(onset.0 < 0.05, "{}", onset.1);
    assert!(cd_condition.0 < 0.05, "{}", cd_condition.1);
    assert!(tau_condition.0 < 0.05, "{}", tau_condition.1);
}

#[test]
fn tables_from_ninth_order_logs_match_the_generating_ones() {
    let p = EhvvaParams::paper_default();
    let id = identify_bench(sensors(false), false, true, |i| {
        EhvvaFull::<f64, 1024>::new(&p, i, DT_MS).map_err(|e| format!("{e:?}"))
    });
    let got = id.table_data();
    let [td, _, cd] = worst(&got, &p.tables);
    assert!(cd.0 < 0.05, "{}", cd.1);
    let [onset, cd_condition, _] = worst_onset_and_cd(&id, &p);
    assert!(cd_condition.0 < 0.05, "{}", cd_condition.1);
    // td from the command to the lift onset with τp and Cd fitted under it (pass 1, the
    // issue's method): the generating td table within 5 % at every condition (4.0 % measured).
    // The joint fit's td is not: it moves along the td-τp ridge (below).
    assert!(onset.0 < 0.05, "{}", onset.1);
    // EhvvaFull has no τp: its explicit delays are set (less its chain's own lag) so that its
    // main-valve pressure is half-way where the reduced model's delayed Pmo is, td + ln2·τp
    // after the command (model-core `full_model_dynamic_lag_is_calibrated`). That half-way time
    // is what a ninth-order log generates; td and τp alone slide along the fit's td-τp ridge.
    let tables = EhvvaTables::<f64>::new(&p).unwrap();
    let mut worst_half = (0.0f64, String::new());
    for c in &id.conditions {
        let (vo, vc) = tables.t_delay_pair_ms(c.p_supply_mpa, c.temp_c);
        let ln2_tau = LN_2 * tables.tau_p_ms(c.p_supply_mpa, c.temp_c);
        for (edge, fit, want) in [("VO", c.td_open_ms, vo + ln2_tau), ("VC", c.td_close_ms, vc + ln2_tau)] {
            let got = fit + LN_2 * c.tau_p_ms;
            let r = (got / want - 1.0).abs();
            if r > worst_half.0 {
                worst_half = (
                    r,
                    format!(
                        "td + ln2 tau_p {edge} at {:.1} MPa, {:.0} °C: {got:.3} vs {want:.3} ms",
                        c.p_supply_mpa, c.temp_c
                    ),
                );
            }
        }
    }
    println!(
        "worst half-way time {:.1} % ({}); td alone {:.1} % ({})",
        100.0 * worst_half.0,
        worst_half.1,
        100.0 * td.0,
        td.1
    );
    // 5.4 % measured: the reduced model's first-order lag stands in for the ninth-order main
    // valve's metering ramp (flow starts as the spool opens, before the pressure is half-way).
    assert!(worst_half.0 < 0.06, "{}", worst_half.1);
    for row in got.tau_ms {
        for tau in row {
            assert!((0.02..0.3).contains(&tau), "tau_p {tau} ms");
        }
    }
    for c in &id.conditions {
        assert!(
            (0.02..0.3).contains(&c.tau_p_onset_ms),
            "pass 1 tau_p {} ms at {} MPa, {} °C",
            c.tau_p_onset_ms,
            c.p_supply_mpa,
            c.temp_c
        );
    }
    // The tables keep the paper's trends: td falls with supply pressure and with temperature
    // (VO), Cd rises with temperature.
    for j in 0..5 {
        for i in 1..4 {
            assert!(
                got.td_open_ms[i][j] < got.td_open_ms[i - 1][j] && got.td_close_ms[i][j] < got.td_close_ms[i - 1][j]
            );
        }
    }
    for i in 0..4 {
        for j in 1..5 {
            assert!(got.td_open_ms[i][j] < got.td_open_ms[i][j - 1]);
        }
    }
    assert!(got.cd.windows(2).all(|w| w[1] > w[0]));
}

/// A unit drawn like a real one (`generate ehvva none`: spring, preload, friction, mass, areas
/// and orifices off the paper's): `identify ehvva` fits the conditions on the unit's valve as
/// `diagnose` fits it, and its td at 7 MPa, 22 °C is the unit's within 10 % for VO and VC. On
/// the paper's valve (`--paper-valve`) the unit's other valve goes into td: the tables then
/// spread over several milliseconds between neighbouring conditions (reported, not asserted
/// as a number: that is the paper's method on the wrong valve).
#[test]
fn a_real_units_tables_are_identified_on_its_own_valve() {
    let dir = std::env::temp_dir().join(format!("hil-identify-unit-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let bin = env!("CARGO_BIN_EXE_hil-host");
    let run = |args: &[&str]| {
        let out = std::process::Command::new(bin).args(args).output().unwrap();
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let unit = dir.join("unit");
    run(&[
        "generate",
        "ehvva",
        "none",
        "--seed",
        "2",
        "--out",
        unit.to_str().unwrap(),
    ]);
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(unit.join("truth.json")).unwrap()).unwrap();
    let td_true = truth["params"]["td_ms_at_7MPa_22C"].as_f64().unwrap();
    let est = unit.join("estimation.csv");
    let json = dir.join("id.json");
    let text = run(&[
        "identify",
        "ehvva",
        est.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(text.starts_with("valve: the unit's, as diagnose fitted it"), "{text}");
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(j["valve"]["from"], "diagnose");
    // Both valves were tried; the unit's reproduces the lift far better and is kept.
    assert_eq!(j["valve"]["kept"], "unit");
    let (on_unit, on_paper) = (
        j["valve"]["cost_unit"].as_f64().unwrap(),
        j["valve"]["cost_paper"].as_f64().unwrap(),
    );
    assert!(
        on_unit < 0.5 * on_paper,
        "cost on the unit's valve {on_unit}, on the paper's {on_paper}"
    );
    // The lift cannot see the common scale of mass, areas, spring and friction (the top area
    // is held at the paper's): the spring per top area is the unit's.
    let fitted = j["valve"]["params"]["spring_N_per_mm"].as_f64().unwrap() / EhvvaParams::paper_default().area_top_mm2;
    let unit_own =
        truth["params"]["spring_N_per_mm"].as_f64().unwrap() / truth["params"]["area_top_mm2"].as_f64().unwrap();
    assert!(
        (fitted / unit_own - 1.0).abs() < 0.1,
        "spring per top area {fitted}, truth {unit_own}"
    );
    for table in ["td_open_ms", "td_close_ms"] {
        let td = j["ehvva_table_data"][table][2][2].as_f64().unwrap();
        assert!(
            (td / td_true - 1.0).abs() < 0.1,
            "{table} {td:.3} ms at 7 MPa / 22 °C, truth {td_true:.3} ms"
        );
    }
    let paper = run(&["identify", "ehvva", est.to_str().unwrap(), "--paper-valve"]);
    assert!(paper.starts_with("valve: the paper's (--paper-valve)"), "{paper}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The fallback: when the valve handed in as the unit's is wrong (here a spring three times
/// the paper's and twice its mass), the paper's valve reproduces the lift better and its tables
/// are the ones kept.
#[test]
fn a_wrong_unit_valve_loses_to_the_papers() {
    use hil_host::identify::ehvva::identify_unit_or_paper;
    let case = hil_host::generate::generate(hil_host::log::Plant::Ehvva, "none", 4).unwrap();
    let log = parse_log("estimation.csv", &case.estimation_csv, None).unwrap();
    let sets = vec![Events::from_log(&log).unwrap()];
    let mut wrong = EhvvaParams::paper_default();
    wrong.spring_n_per_mm *= 3.0;
    wrong.mass_kg *= 2.0;
    let (_, choice) = identify_unit_or_paper(&wrong, &sets, &default_options(), &mut |_, _| {}).unwrap();
    assert!(!choice.kept_unit, "{}", choice.text());
    assert!(choice.paper_cost < choice.unit_cost);
}

/// A test condition whose valve never opens (its lift stays at the seat: a unit near force
/// balance, as generated pressure-delay unit 37 at 6 MPa / 100 °C was) has no delay to read:
/// it is left out and named, and the other conditions are identified (before: the whole
/// identification failed with "the valve never opens").
#[test]
fn a_condition_whose_valve_never_opens_is_left_out_and_named() {
    let case = hil_host::generate::generate(hil_host::log::Plant::Ehvva, "none", 4).unwrap();
    let log = parse_log("estimation.csv", &case.estimation_csv, None).unwrap();
    let mut set = Events::from_log(&log).unwrap();
    let shut = &mut set.events[0];
    let (p, t) = (shut.inputs.p_supply_mpa, shut.inputs.temp_c);
    shut.lift_mm.iter_mut().for_each(|y| *y = 0.001);
    let n = set.events.len();
    let id = identify(&[set], &default_options(), &mut |_, _| {}).unwrap();
    assert_eq!(id.not_opening.len(), 1, "{:?}", id.not_opening);
    assert!(
        id.not_opening[0].starts_with(&format!("{p:.2} MPa / {t:.1} °C")),
        "{:?}",
        id.not_opening
    );
    assert_eq!(id.conditions.len(), n - 1);
    assert!(id.text().contains("not identified (the valve never opened"));
}

/// A log too short for the diagnosis (one valve event: nothing to hold out for validation):
/// `identify ehvva` fits the conditions on the paper's valve and says why, and `calibrate`
/// still writes its image (before: both failed on the diagnosis's error).
#[test]
fn a_log_too_short_to_diagnose_is_identified_on_the_papers_valve() {
    let dir = std::env::temp_dir().join(format!("hil-identify-short-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let case = hil_host::generate::generate(hil_host::log::Plant::Ehvva, "none", 4).unwrap();
    // The metadata, the header and the first event's 40 ms (20 kHz).
    let mut rows = 0;
    let short: String = case
        .estimation_csv
        .lines()
        .take_while(|l| {
            if !l.starts_with('#') {
                rows += 1;
            }
            rows <= 1 + 800
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let log = dir.join("one-event.csv");
    std::fs::write(&log, short).unwrap();
    let bin = env!("CARGO_BIN_EXE_hil-host");
    let json = dir.join("id.json");
    let out = std::process::Command::new(bin)
        .args([
            "identify",
            "ehvva",
            log.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(
        text.starts_with("valve: the paper's (the diagnosis could not fit the unit's"),
        "{text}"
    );
    let j: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(j["valve"]["from"], "paper");
    let cal = std::process::Command::new(bin)
        .args([
            "calibrate",
            log.to_str().unwrap(),
            "--out",
            dir.join("cal").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(cal.status.success(), "{}", String::from_utf8_lossy(&cal.stderr));
    assert!(dir.join("cal/calibration.bin").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}
