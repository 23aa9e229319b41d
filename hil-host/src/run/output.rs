//! A run's files: the DATA-FORMAT logs and the plots.

use std::path::{Path, PathBuf};

use super::*;

/// Writes `evvt.csv`, `vacuum.csv` (the wastegate), `vacuum-hpt.csv`, `vacuum-hpc.csv`,
/// `ehvva.csv` (DATA-FORMAT logs) and SVG plots into `dir`.
pub fn write_outputs(sc: &Scenario, o: &RunOutput, dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    // Times to the nanosecond: products of steps carry float noise a log should not show.
    let times = |t: &mut dyn Iterator<Item = f64>| -> Vec<f64> { t.map(|x| (x * 1e9).round() / 1e9).collect() };
    let flag = |b: bool| if b { 1.0 } else { 0.0 };
    // Only the format's known keys (`source` and `controller` are free text).
    let meta = |plant: &str, what: &str, rate: f64, controller: &str| {
        let mut source = format!("hil-host run, scenario `{}`{what} (lockstep: the ECU's EcuCore every {STEP_US} µs against model-core plants)", sc.name);
        if !o.summary.faults_injected.is_empty() {
            source += &format!("; faults injected: {}", o.summary.faults_injected.join(", "));
        }
        vec![
            ("plant".to_string(), plant.to_string()),
            ("source".into(), source),
            ("sample_rate_hz".into(), format!("{rate}")),
            ("controller".into(), controller.to_string()),
        ]
    };
    let mut written = Vec::new();
    let mut put = |name: &str, text: String| -> std::io::Result<()> {
        let p = dir.join(name);
        // Whole files only (a killed run leaves the old file or none), never over an input.
        crate::output::write_atomic(&p, text.as_bytes())?;
        written.push(p);
        Ok(())
    };

    let e = &o.evvt;
    let et = times(&mut e.iter().map(|r| r.t_s));
    let col = |f: &dyn Fn(&EvvtRow) -> f64| e.iter().map(f).collect::<Vec<f64>>();
    let (e_cmd, e_rpm, e_u, e_ref, e_ph) = (
        col(&|r| r.motor_cmd_rpm),
        col(&|r| r.engine_rpm),
        col(&|r| r.u_batt_v),
        col(&|r| r.phase_ref_deg),
        col(&|r| r.phase_deg),
    );
    put(
        "evvt.csv",
        format_log(
            &meta(
                "evvt",
                "",
                1e6 / (EVVT_LOG_EVERY as f64 * f64::from(STEP_US)),
                "model-core ecu::evvt_task (scheduled PI); motor_cmd_rpm = duty x 6000 rpm - ring speed",
            ),
            &[
                ("t_s", &et),
                ("motor_cmd_rpm", &e_cmd),
                ("engine_rpm", &e_rpm),
                ("u_batt_V", &e_u),
                ("phase_ref_deg", &e_ref),
                ("phase_deg", &e_ph),
            ],
        ),
    )?;

    let v = &o.vacuum;
    let vt = times(&mut v.iter().map(|r| r.t_s));
    let vcol = |f: &dyn Fn(&VacuumRow) -> f64| v.iter().map(f).collect::<Vec<f64>>();
    let (v_u, v_amb, v_tank) = (vcol(&|r| r.u_batt_v), vcol(&|r| r.p_amb_kpa), vcol(&|r| r.p_tank_kpa));
    let names = [
        ("vacuum.csv", "LPT wastegate"),
        ("vacuum-hpt.csv", "HPT bypass"),
        ("vacuum-hpc.csv", "HPC bypass"),
    ];
    for (i, (file, what)) in names.iter().enumerate() {
        let (duty, x, p) = (
            vcol(&|r| r.duty_pct[i]),
            vcol(&|r| r.x_pct[i]),
            vcol(&|r| r.p_act_kpa[i]),
        );
        put(
            file,
            format_log(
                &meta("vacuum", &format!(", {what}"), 1e6 / (VACUUM_LOG_EVERY as f64 * f64::from(STEP_US)), "model-core ecu::vacuum_task (inverse model + supply-voltage compensation + position PI, control::vacuum_position)"),
                &[("t_s", &vt), ("duty_pct", &duty), ("u_batt_V", &v_u), ("p_amb_kPa", &v_amb), ("p_tank_kPa", &v_tank), ("x_pct", &x), ("p_act_kPa", &p)],
            ),
        )?;
    }

    let w = &o.ehvva;
    let wt = times(&mut w.iter().map(|r| r.t_s));
    let wcol = |f: &dyn Fn(&EhvvaRow) -> f64| w.iter().map(f).collect::<Vec<f64>>();
    let (w_u, w_ph, w_pl, w_t, w_lh, w_sn, w_lift) = (
        wcol(&|r| flag(r.u_pilot)),
        wcol(&|r| r.p_supply_mpa),
        wcol(&|r| r.p_back_mpa),
        wcol(&|r| r.temp_c),
        wcol(&|r| flag(r.lift_high)),
        wcol(&|r| flag(r.snubber_on)),
        wcol(&|r| r.lift_mm),
    );
    put(
        "ehvva.csv",
        format_log(
            &meta("ehvva", "", 1e6 / f64::from(STEP_US), "model-core ecu::ehvva_task (crank-angle events advanced by td, pilot peak-and-hold); u_pilot = pilot valve open"),
            &[("t_s", &wt), ("u_pilot", &w_u), ("p_supply_MPa", &w_ph), ("p_back_MPa", &w_pl), ("temp_C", &w_t), ("lift_high", &w_lh), ("snubber_on", &w_sn), ("lift_mm", &w_lift)],
        ),
    )?;

    // Plots (crate::plot): every actuator, one axis per unit, fault and mode-change markers.
    for (name, svg) in crate::plot::run_svgs(sc, o) {
        put(&name, svg)?;
    }
    Ok(written)
}
