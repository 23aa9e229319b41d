//! What a run reports: the logs' rows and the summary of its error figures and faults.

use super::*;

/// EVVT log row, 100 Hz (on the ECU's 10 ms grid).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvvtRow {
    pub t_s: f64,
    /// Motor speed command output, 0..1.
    pub motor_duty: f64,
    /// The plant's command: motor speed minus ring-gear speed.
    pub motor_cmd_rpm: f64,
    pub engine_rpm: f64,
    pub u_batt_v: f64,
    pub phase_ref_deg: f64,
    /// The plant's cam phase (with the belt disturbance).
    pub phase_deg: f64,
}

/// Vacuum log row, 400 Hz (the ECU's 12.5 ms ticks fall on it); LPT, HPT, HPC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VacuumRow {
    pub t_s: f64,
    pub duty_pct: [f64; 3],
    pub pump_on: bool,
    pub u_batt_v: f64,
    pub p_amb_kpa: f64,
    pub p_tank_kpa: f64,
    pub x_set_pct: [f64; 3],
    /// Rod positions (a stuck rod's frozen position).
    pub x_pct: [f64; 3],
    pub p_act_kpa: [f64; 3],
}

/// EHVVA log row, one per 50 µs step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EhvvaRow {
    pub t_s: f64,
    /// The pilot valve is open (the plant's input).
    pub u_pilot: bool,
    /// The commanded pilot voltage as a duty: 1 = peak (full battery), hold duty, 0 = off.
    pub pilot_duty: f64,
    pub coil_a: f64,
    pub p_supply_mpa: f64,
    pub p_back_mpa: f64,
    pub temp_c: f64,
    pub lift_high: bool,
    pub snubber_on: bool,
    pub lift_mm: f64,
    /// Cycle angle 0..720.
    pub crank_deg: f64,
}

/// A fault the ECU raised or cleared (from the actuator frames' fault bits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultEvent {
    pub t_s: f64,
    pub fault: Fault,
    pub raised: bool,
}

/// What the run measured.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub evvt_rms_error_deg: f64,
    /// For each phase set-point step: (time, settling time into ±1 deg).
    pub evvt_settling_s: Vec<(f64, Option<f64>)>,
    /// LPT wastegate.
    pub vacuum_rms_error_pct: f64,
    /// For each wastegate set-point step: (time, settling time into ±2 %).
    pub vacuum_settling_s: Vec<(f64, Option<f64>)>,
    pub vacuum_pump_on_fraction: f64,
    /// RMS position error of each actuator (LPT, HPT, HPC) and of the three together.
    pub vacuum_rms_error_pct_each: [f64; 3],
    pub vacuum_position_error_pct_rms: f64,
    pub ehvva_events: usize,
    /// Pilot cycles whose valve was below 99 % of its stroke at the closing command (no
    /// closing time; `LIFT_FRACTION`).
    pub ehvva_stop_not_held_events: usize,
    /// Closings timed (the rest of the events: no held stop, or the run ended first).
    pub ehvva_closings: usize,
    /// RMS of every opening and closing timing error, crank degrees.
    pub ehvva_timing_error_deg_rms: f64,
    /// An actuator frame carried the calibration fault bit (the ECU refused its image).
    pub calibration_fault: bool,
    /// (mean, largest magnitude) in crank degrees.
    pub ehvva_open_error_deg: (f64, f64),
    pub ehvva_close_error_deg: (f64, f64),
    pub ehvva_seating_velocity_m_s: Option<f64>,
    pub faults_injected: Vec<String>,
    pub fault_events: Vec<FaultEvent>,
    pub simulated_s: f64,
    /// Wall time of the stepping loop.
    pub wall_s: f64,
}

impl Summary {
    pub fn text(&self, name: &str) -> String {
        let mut s = format!(
            "scenario `{name}`: {:.1} s simulated in {:.2} s wall ({:.1} simulated s per wall s), ECU in lockstep every {STEP_US} µs\n",
            self.simulated_s,
            self.wall_s,
            self.simulated_s / self.wall_s.max(1e-9)
        );
        s += &format!(
            "EVVT   cam phase tracking: RMS error {:.2} deg\n",
            self.evvt_rms_error_deg
        );
        for (t, settle) in &self.evvt_settling_s {
            match settle {
                Some(d) => s += &format!("       step at {t:.2} s settled (±1 deg) in {d:.2} s\n"),
                None => s += &format!("       step at {t:.2} s did not settle (±1 deg)\n"),
            }
        }
        s += &format!(
            "vacuum wastegate tracking: RMS error {:.2} %, pump on {:.0} % of the time\n",
            self.vacuum_rms_error_pct,
            100.0 * self.vacuum_pump_on_fraction
        );
        for (t, settle) in &self.vacuum_settling_s {
            match settle {
                Some(d) => s += &format!("       step at {t:.2} s settled (±2 %) in {d:.2} s\n"),
                None => s += &format!("       step at {t:.2} s did not settle (±2 %)\n"),
            }
        }
        if self.ehvva_events == 0 {
            // No event, no timing error to average (a stopped engine, or a run shorter than a cycle).
            s += "EHVVA  no valve events\n";
        } else {
            let closing = if self.ehvva_closings == 0 {
                "no closing timed".to_string()
            } else {
                format!(
                    "closing error mean {:+.2} / max |{:.2}| crank deg",
                    self.ehvva_close_error_deg.0, self.ehvva_close_error_deg.1
                )
            };
            s += &format!(
                "EHVVA  {} valve events: opening error mean {:+.2} / max |{:.2}| crank deg, {closing}\n",
                self.ehvva_events, self.ehvva_open_error_deg.0, self.ehvva_open_error_deg.1
            );
            if self.ehvva_stop_not_held_events > 0 {
                s += &format!(
                    "       {} of them below 99 % of the stroke at the closing command (the stop not reached or not held): no closing time\n",
                    self.ehvva_stop_not_held_events
                );
            }
        }
        if let Some(v) = self.ehvva_seating_velocity_m_s {
            s += &format!("       seating velocity {:.2} m/s (largest)\n", v);
        }
        if self.faults_injected.is_empty() {
            s += "faults injected: none\n";
        } else {
            s += &format!("faults injected: {}\n", self.faults_injected.join(", "));
        }
        if self.fault_events.is_empty() {
            s += "faults raised by the ECU: none\n";
        }
        for e in &self.fault_events {
            s += &format!(
                "       {:.3} s {} {}\n",
                e.t_s,
                if e.raised { "raised " } else { "cleared" },
                e.fault.name()
            );
        }
        s
    }

    /// The error figures per actuator (`--json`): `ehvva.timing_error_deg_rms`,
    /// `evvt.phase_error_deg_rms`, `vacuum.position_error_pct_rms` and their details.
    pub fn json(&self, name: &str) -> serde_json::Value {
        let num = |x: f64| {
            if x.is_finite() {
                serde_json::json!(x)
            } else {
                serde_json::Value::Null
            }
        };
        serde_json::json!({
            "scenario": name,
            "simulated_s": self.simulated_s,
            "ehvva": {
                "timing_error_deg_rms": num(self.ehvva_timing_error_deg_rms),
                "events": self.ehvva_events,
                "stop_not_held_events": self.ehvva_stop_not_held_events,
                "closings": self.ehvva_closings,
                "open_error_deg_mean": num(self.ehvva_open_error_deg.0),
                "open_error_deg_max_abs": num(self.ehvva_open_error_deg.1),
                "close_error_deg_mean": num(self.ehvva_close_error_deg.0),
                "close_error_deg_max_abs": num(self.ehvva_close_error_deg.1),
                "seating_velocity_m_s_max": self.ehvva_seating_velocity_m_s.map(num),
            },
            "evvt": {
                "phase_error_deg_rms": num(self.evvt_rms_error_deg),
                "settling_s": self.evvt_settling_s.iter().map(|(t, s)| serde_json::json!({"step_s": t, "settled_s": s})).collect::<Vec<_>>(),
            },
            "vacuum": {
                "position_error_pct_rms": num(self.vacuum_position_error_pct_rms),
                "lpt_position_error_pct_rms": num(self.vacuum_rms_error_pct_each[0]),
                "hpt_position_error_pct_rms": num(self.vacuum_rms_error_pct_each[1]),
                "hpc_position_error_pct_rms": num(self.vacuum_rms_error_pct_each[2]),
                "pump_on_fraction": num(self.vacuum_pump_on_fraction),
            },
            "calibration_fault": self.calibration_fault,
            "faults_raised": self.fault_events.iter().filter(|e| e.raised).map(|e| e.fault.name()).collect::<Vec<_>>(),
        })
    }

    /// The first time `fault` was raised.
    pub fn raised_at(&self, fault: Fault) -> Option<f64> {
        self.fault_events
            .iter()
            .find(|e| e.fault == fault && e.raised)
            .map(|e| e.t_s)
    }
}
