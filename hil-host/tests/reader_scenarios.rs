//! Scenario validation (issue #16): values outside their physical range, too short runs and
//! names that are paths are refused before a run, naming the file, the line and the key; a
//! scenario at the corners of every range runs and writes logs that `check` accepts.

use std::path::{Path, PathBuf};

use hil_host::log::read_log;
use hil_host::run::{run, Scenario, MIN_DURATION_S};

fn parse(text: &str) -> Result<Scenario, String> {
    Scenario::from_toml(Path::new("s.toml"), text)
}

#[test]
fn the_shipped_scenarios_pass() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            Scenario::from_toml(&path, &text).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 8, "{n} scenarios in {}", dir.display());
}

/// Was: 1e6 V, a 1e-9 s run and a negative engine speed ran, writing logs that `check`
/// refused or a summary of NaN.
#[test]
fn out_of_range_values_are_refused_naming_file_line_and_key() {
    for (body, line, needle) in [
        ("duration_s = 1.0\nu_batt_v = [[0.0, 1e6]]\n", 3, "profile `u_batt_v` at 0 s: 1000000 V is outside 0..32 V"),
        ("duration_s = 1e-9\n", 2, "duration_s = 0.000000001 must lie in 0.1..120 s"),
        ("duration_s = 1.0\nengine_rpm = [[0.0, 800.0], [0.5, -100.0]]\n", 3, "`engine_rpm` at 0.5 s: -100 rpm"),
        ("duration_s = 1.0\ntemp_c = [[0.0, nan]]\n", 3, "`temp_c` has a non-finite value"),
        ("duration_s = 1.0\np_supply_mpa = [[0.0, 1e3]]\n", 3, "p_supply_mpa"),
        ("duration_s = 1.0\np_back_mpa = [[0.0, 1.0], [0.5, 4.0]]\np_supply_mpa = [[0.0, 7.0], [0.5, 3.0]]\n", 3, "back pressure"),
        ("duration_s = 1.0\nwastegate_setpoint_pct = [[-1.0, 20.0]]\n", 3, "before the start"),
        ("duration_s = 1.0\nvalve_close_deg = [[0.0, 900.0]]\n", 3, "valve_close_deg"),
        ("duration_s = 1.0\np_tank_initial_kpa = 0.0\n", 3, "p_tank_initial_kpa"),
        ("duration_s = 1.0\n\n[[fault]]\nkind = \"crank_lost\"\nstart_s = 0.5\n[[fault]]\nkind = \"crank_lost\"\nstart_s = 5.0\n", 7, "fault #2 (`crank_lost`): start_s = 5 is not within the run"),
    ] {
        let text = format!("name = \"x\"\n{body}");
        let e = parse(&text).unwrap_err();
        assert!(e.starts_with(&format!("s.toml:{line}: ")), "{body}: {e}");
        assert!(e.contains(needle), "{body}: {e}");
    }
    let many: Vec<String> = (0..10_001).map(|i| format!("[{i}.0, 10.0]")).collect();
    let e = parse(&format!(
        "name = \"x\"\nduration_s = 1.0\ntemp_c = [{}]\n",
        many.join(", ")
    ))
    .unwrap_err();
    assert!(e.contains("at most 10000"), "{e}");
}

/// Was: `name = "../../../x"` wrote outside `out/`.
#[test]
fn a_name_is_a_name_not_a_path() {
    for bad in [
        "../../../x",
        "a/b",
        "a\\b",
        "",
        ".",
        "..",
        ".hidden",
        "/abs",
        "two words",
        "tab\there",
        &"n".repeat(65),
    ] {
        let e = parse(&format!("name = {bad:?}\nduration_s = 1.0\n")).unwrap_err();
        assert!(e.starts_with("s.toml:1: name = "), "{bad:?}: {e}");
    }
    for good in ["fault-battery-sag", "run_1.2", "Prüfstand-7"] {
        assert_eq!(
            parse(&format!("name = {good:?}\nduration_s = 1.0\n")).unwrap().name,
            good
        );
    }
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("reader-scenarios-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// The corners of every range: the shortest run at the lowest and at the highest values
/// runs, its summary is finite and `check` (the log reader) accepts every log it writes.
#[test]
fn a_run_at_the_range_corners_writes_logs_that_check_accepts() {
    let corners = [
        ("low", "engine_rpm = [[0.0, 0.0]]\nu_batt_v = [[0.0, 0.0]]\ntemp_c = [[0.0, -40.0]]\ntemp_ecu_c = [[0.0, -40.0]]\np_supply_mpa = [[0.0, 0.5]]\np_back_mpa = [[0.0, 0.0]]\np_amb_kpa = [[0.0, 50.0]]\np_tank_initial_kpa = 1.0\ncam_phase_setpoint_deg = [[0.0, -30.0]]\nwastegate_setpoint_pct = [[0.0, 0.0]]\nvalve_open_deg = [[0.0, 0.0]]\nvalve_close_deg = [[0.0, 0.0]]\n"),
        ("high", "engine_rpm = [[0.0, 12000.0]]\nu_batt_v = [[0.0, 32.0]]\ntemp_c = [[0.0, 150.0]]\ntemp_ecu_c = [[0.0, 125.0]]\np_supply_mpa = [[0.0, 25.0]]\np_back_mpa = [[0.0, 5.0]]\np_amb_kpa = [[0.0, 110.0]]\np_tank_initial_kpa = 110.0\ncam_phase_setpoint_deg = [[0.0, 90.0]]\nwastegate_setpoint_pct = [[0.0, 100.0]]\nhpt_bypass_setpoint_pct = [[0.0, 100.0]]\nhpc_bypass_setpoint_pct = [[0.0, 100.0]]\nvalve_open_deg = [[0.0, 720.0]]\nvalve_close_deg = [[0.0, 720.0]]\nlift_high = true\nsnubber_on = true\n"),
    ];
    for (tag, body) in corners {
        let text = format!("name = \"corner-{tag}\"\nduration_s = {MIN_DURATION_S}\n{body}");
        let sc = parse(&text).unwrap_or_else(|e| panic!("{tag}: {e}"));
        let dir = temp_dir(tag);
        let summary = run(&sc, Some(&dir)).unwrap_or_else(|e| panic!("{tag}: {e}"));
        let mut numbers = vec![
            summary.evvt_rms_error_deg,
            summary.vacuum_rms_error_pct,
            summary.vacuum_pump_on_fraction,
        ];
        // Valve timing errors are averages over the events; without events there are none.
        if summary.ehvva_events > 0 {
            numbers.extend([summary.ehvva_open_error_deg.0, summary.ehvva_open_error_deg.1]);
        }
        // Closings are timed only where the valve held its stop at the pilot's falling edge.
        if summary.ehvva_closings > 0 {
            numbers.extend([summary.ehvva_close_error_deg.0, summary.ehvva_close_error_deg.1]);
        }
        assert!(numbers.iter().all(|x| x.is_finite()), "{tag}: {numbers:?}");
        assert!(!summary.text(&sc.name).contains("NaN"), "{tag}");
        let mut logs = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "csv") {
                let log = read_log(&path, None).unwrap_or_else(|e| panic!("{tag}: {e}"));
                assert!(log.len() >= 2);
                logs += 1;
            }
        }
        assert!(logs >= 3, "{tag}: {logs} logs");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
