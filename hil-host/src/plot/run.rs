//! The run plots: every actuator's signals with the run's fault and mode-change markers.

use super::*;
use crate::run::{RunOutput, Scenario};

/// The run's fault and mode-change markers: faults injected by the scenario (start, end),
/// faults the ECU raised and cleared, EHVVA lift-mode and snubber switches.
pub fn run_markers(sc: &Scenario, o: &RunOutput) -> Vec<Marker> {
    let mut m = Vec::new();
    for f in &sc.faults {
        m.push(Marker {
            x: f.start_s,
            label: format!("{:.2} s injected {}", f.start_s, f.kind.name()),
            colour: ORANGE,
        });
        if let Some(end) = f.end_s {
            m.push(Marker {
                x: end,
                label: format!("{end:.2} s {} ends", f.kind.name()),
                colour: ORANGE,
            });
        }
    }
    for e in &o.summary.fault_events {
        m.push(Marker {
            x: e.t_s,
            label: format!(
                "{:.2} s ECU {} {}",
                e.t_s,
                if e.raised { "raised" } else { "cleared" },
                e.fault.name()
            ),
            colour: if e.raised { RED } else { GREEN },
        });
    }
    for w in o.ehvva.windows(2) {
        if w[1].lift_high != w[0].lift_high {
            m.push(Marker {
                x: w[1].t_s,
                label: format!("{:.2} s lift {}", w[1].t_s, if w[1].lift_high { "high" } else { "low" }),
                colour: PURPLE,
            });
        }
        if w[1].snubber_on != w[0].snubber_on {
            m.push(Marker {
                x: w[1].t_s,
                label: format!(
                    "{:.2} s snubber {}",
                    w[1].t_s,
                    if w[1].snubber_on { "on" } else { "off" }
                ),
                colour: PURPLE,
            });
        }
    }
    m.sort_by(|a, b| a.x.total_cmp(&b.x));
    m
}

/// The run's plots as (file name, SVG): the EVVT phase with its command, engine speed and
/// battery; each vacuum actuator (LPT wastegate, HPT and HPC bypass) with position, duty,
/// pressures and battery on their own axes; the EHVVA lift and pressures over the whole run;
/// the EHVVA lift against crank angle, one line per engine cycle. Every time plot carries
/// the fault and mode-change markers.
pub fn run_svgs(sc: &Scenario, o: &RunOutput) -> Vec<(String, String)> {
    let markers = run_markers(sc, o);
    let mut svgs = Vec::new();
    let e = &o.evvt;
    let col = |f: &dyn Fn(&crate::run::EvvtRow) -> f64| e.iter().map(f).collect::<Vec<f64>>();
    let et = col(&|r| r.t_s);
    let (e_ref, e_ph, e_cmd, e_rpm, e_u) = (
        col(&|r| r.phase_ref_deg),
        col(&|r| r.phase_deg),
        col(&|r| r.motor_cmd_rpm),
        col(&|r| r.engine_rpm),
        col(&|r| r.u_batt_v),
    );
    svgs.push((
        "evvt.svg".to_string(),
        panel_plot(
            &format!("EVVT cam phaser, scenario `{}`", sc.name),
            "time (s)",
            &[
                Panel {
                    y_label: "cam phase (crank deg)",
                    series: vec![
                        Series {
                            label: "set-point",
                            colour: "black",
                            x: &et,
                            y: &e_ref,
                        },
                        Series {
                            label: "plant",
                            colour: BLUE,
                            x: &et,
                            y: &e_ph,
                        },
                    ],
                    hlines: vec![],
                    band: None,
                },
                Panel {
                    y_label: "speed (rpm)",
                    series: vec![
                        Series {
                            label: "motor command",
                            colour: GREEN,
                            x: &et,
                            y: &e_cmd,
                        },
                        Series {
                            label: "engine",
                            colour: PURPLE,
                            x: &et,
                            y: &e_rpm,
                        },
                    ],
                    hlines: vec![],
                    band: None,
                },
                battery_panel(&et, &e_u),
            ],
            &markers,
        ),
    ));

    let v = &o.vacuum;
    let vcol = |f: &dyn Fn(&crate::run::VacuumRow) -> f64| v.iter().map(f).collect::<Vec<f64>>();
    let vt = vcol(&|r| r.t_s);
    let (v_u, v_tank, v_amb) = (vcol(&|r| r.u_batt_v), vcol(&|r| r.p_tank_kpa), vcol(&|r| r.p_amb_kpa));
    for (i, file, what) in [
        (0, "vacuum.svg", "LPT wastegate"),
        (1, "vacuum-hpt.svg", "HPT bypass"),
        (2, "vacuum-hpc.svg", "HPC bypass"),
    ] {
        let (set, x, duty, p) = (
            vcol(&|r| r.x_set_pct[i]),
            vcol(&|r| r.x_pct[i]),
            vcol(&|r| r.duty_pct[i]),
            vcol(&|r| r.p_act_kpa[i]),
        );
        svgs.push((
            file.to_string(),
            panel_plot(
                &format!("vacuum actuator: {what}, scenario `{}`", sc.name),
                "time (s)",
                &[
                    Panel {
                        y_label: "rod position (% stroke)",
                        series: vec![
                            Series {
                                label: "set-point",
                                colour: "black",
                                x: &vt,
                                y: &set,
                            },
                            Series {
                                label: "position",
                                colour: BLUE,
                                x: &vt,
                                y: &x,
                            },
                        ],
                        hlines: vec![],
                        band: None,
                    },
                    Panel {
                        y_label: "valve duty (%)",
                        series: vec![Series {
                            label: "PWM duty",
                            colour: GREEN,
                            x: &vt,
                            y: &duty,
                        }],
                        hlines: vec![],
                        band: None,
                    },
                    Panel {
                        y_label: "pressure (kPa)",
                        series: vec![
                            Series {
                                label: "actuator chamber",
                                colour: PURPLE,
                                x: &vt,
                                y: &p,
                            },
                            Series {
                                label: "vacuum tank",
                                colour: ORANGE,
                                x: &vt,
                                y: &v_tank,
                            },
                            Series {
                                label: "ambient",
                                colour: "#7f7f7f",
                                x: &vt,
                                y: &v_amb,
                            },
                        ],
                        hlines: vec![],
                        band: None,
                    },
                    battery_panel(&vt, &v_u),
                ],
                &markers,
            ),
        ));
    }

    let w = &o.ehvva;
    let wcol = |f: &dyn Fn(&crate::run::EhvvaRow) -> f64| w.iter().map(f).collect::<Vec<f64>>();
    let wt = wcol(&|r| r.t_s);
    let (lift, duty, ph, pl) = (
        wcol(&|r| r.lift_mm),
        wcol(&|r| r.pilot_duty),
        wcol(&|r| r.p_supply_mpa),
        wcol(&|r| r.p_back_mpa),
    );
    svgs.push((
        "ehvva.svg".to_string(),
        panel_plot(
            &format!(
                "EHVVA valve over the whole run ({} events), scenario `{}`",
                o.summary.ehvva_events, sc.name
            ),
            "time (s)",
            &[
                Panel {
                    y_label: "valve lift (mm)",
                    series: vec![Series {
                        label: "lift (envelope)",
                        colour: BLUE,
                        x: &wt,
                        y: &lift,
                    }],
                    hlines: vec![],
                    band: None,
                },
                Panel {
                    y_label: "pilot command (duty 0..1)",
                    series: vec![Series {
                        label: "pilot duty",
                        colour: "black",
                        x: &wt,
                        y: &duty,
                    }],
                    hlines: vec![],
                    band: None,
                },
                Panel {
                    y_label: "pressure (MPa)",
                    series: vec![
                        Series {
                            label: "supply Ph",
                            colour: RED,
                            x: &wt,
                            y: &ph,
                        },
                        Series {
                            label: "back Pl",
                            colour: GREEN,
                            x: &wt,
                            y: &pl,
                        },
                    ],
                    hlines: vec![],
                    band: None,
                },
            ],
            &markers,
        ),
    ));

    // Lift against crank angle: one line per engine cycle (the cycle angle wraps at 720).
    let mut cycles: Vec<(usize, usize)> = Vec::new();
    let mut start = 0;
    for k in 1..w.len() {
        if w[k].crank_deg < w[k - 1].crank_deg {
            cycles.push((start, k));
            start = k;
        }
    }
    if start < w.len() {
        cycles.push((start, w.len()));
    }
    let crank = wcol(&|r| r.crank_deg);
    let cycle_t0: Vec<f64> = cycles.iter().map(|c| wt[c.0]).collect();
    // At most about 600 points per cycle (a 720 deg cycle at 800 rpm is 3 000 steps).
    let stride = cycles.iter().map(|c| c.1 - c.0).max().unwrap_or(1).div_ceil(600).max(1);
    let (crank, lift): (Vec<f64>, Vec<f64>) = if stride > 1 {
        let mut keep = Vec::new();
        for c in cycles.iter_mut() {
            let from = keep.len();
            keep.extend((c.0..c.1).step_by(stride));
            *c = (from, keep.len());
        }
        (
            keep.iter().map(|&k| crank[k]).collect(),
            keep.iter().map(|&k| lift[k]).collect(),
        )
    } else {
        (crank, lift.clone())
    };

    // Colour by time through the run: early cycles blue, late ones red; labels on the first
    // and last cycle only.
    const RAMP: [&str; 6] = ["#1f77b4", "#3a8fb7", "#7a9cc6", "#c8748a", "#e0504a", "#d62728"];
    // Only cycles with a valve event; the first and the last of them are labelled.
    let with_event: Vec<usize> = (0..cycles.len())
        .filter(|&k| lift[cycles[k].0..cycles[k].1].iter().any(|&l| l > 0.05))
        .collect();
    let label_of = |k: Option<&usize>| {
        k.map(|&k| format!("cycle from {:.2} s", cycle_t0[k]))
            .unwrap_or_default()
    };
    let (first_label, last_label) = (label_of(with_event.first()), label_of(with_event.last()));
    let ne = with_event.len();
    let series: Vec<Series> = with_event
        .iter()
        .enumerate()
        .map(|(j, &k)| Series {
            label: if j == 0 {
                &first_label
            } else if j + 1 == ne {
                &last_label
            } else {
                ""
            },
            colour: RAMP[(j * (RAMP.len() - 1)) / ne.saturating_sub(1).max(1)],
            x: &crank[cycles[k].0..cycles[k].1],
            y: &lift[cycles[k].0..cycles[k].1],
        })
        .collect();
    svgs.push((
        "ehvva-crank.svg".to_string(),
        panel_plot(
            &format!(
                "EHVVA lift against crank angle, one line per engine cycle ({} cycles with an event; blue early, red late)",
                series.len()
            ),
            "crank angle in the cycle (deg, 0..720)",
            &[Panel {
                y_label: "valve lift (mm)",
                series,
                hlines: vec![],
                band: None,
            }],
            &[],
        ),
    ));
    svgs
}

/// The supply voltage's panel, shared by the actuators' plots.
fn battery_panel<'a>(t_s: &'a [f64], u_v: &'a [f64]) -> Panel<'a> {
    Panel {
        y_label: "battery (V)",
        series: vec![Series {
            label: "battery",
            colour: RED,
            x: t_s,
            y: u_v,
        }],
        hlines: vec![],
        band: None,
    }
}
