//! Tests of the EHVVA task (`ehvva_task.rs`).

use super::super::board::doubles::FakeSolenoid;
use super::super::board::SolenoidDriver;
use super::*;
use crate::ehvva::EhvvaParams;
use crate::peak_hold::{plan, RlCoil};

/// An engine turning with constant acceleration: cycle angle θ(t) = θ0 + ω0 t + ½ a t²
/// (t in µs, degrees), generating 60-2 crank edges and the cam edge at `cam_deg`.
struct SimEngine {
    theta0_deg: f64,
    w0_deg_per_us: f64,
    a_deg_per_us2: f64,

    wheel: TriggerWheel,
    /// Next tooth position (absolute angle, not wrapped) to emit.
    next_tooth_abs_deg: f64,
    next_cam_abs_deg: f64,
}

impl SimEngine {
    fn new(rpm: f64, accel_rpm_per_s: f64, cam_deg: f64) -> Self {
        let wheel = TriggerWheel::sixty_minus_two();
        Self {
            theta0_deg: 3.0,
            w0_deg_per_us: rpm * 6.0 / 1e6,
            a_deg_per_us2: accel_rpm_per_s * 6.0 / 1e12,

            wheel,
            next_tooth_abs_deg: 6.0,
            next_cam_abs_deg: cam_deg,
        }
    }
    fn angle_abs(&self, t_us: f64) -> f64 {
        self.theta0_deg + self.w0_deg_per_us * t_us + 0.5 * self.a_deg_per_us2 * t_us * t_us
    }
    fn time_of(&self, abs_deg: f64) -> f64 {
        let d = abs_deg - self.theta0_deg;
        if self.a_deg_per_us2.abs() < 1e-18 {
            d / self.w0_deg_per_us
        } else {
            let (a, w) = (self.a_deg_per_us2, self.w0_deg_per_us);
            (-w + (w * w + 2.0 * a * d).sqrt()) / a
        }
    }
    /// The next edge (time rounded to the capture's 1 µs).
    fn next_edge(&mut self) -> Edge {
        loop {
            let tooth_in_rev =
                ((self.next_tooth_abs_deg - self.wheel.first_tooth_deg as f64) / 6.0).round() as i64 % 60;
            if tooth_in_rev >= 58 {
                self.next_tooth_abs_deg += 6.0;
                continue;
            }
            break;
        }
        let t_tooth = self.time_of(self.next_tooth_abs_deg);
        let t_cam = self.time_of(self.next_cam_abs_deg);
        if t_cam < t_tooth {
            self.next_cam_abs_deg += 720.0;
            Edge {
                source: EdgeSource::CamSync,
                t_us: t_cam.round() as u32,
            }
        } else {
            self.next_tooth_abs_deg += 6.0;
            Edge {
                source: EdgeSource::CrankTooth,
                t_us: t_tooth.round() as u32,
            }
        }
    }
}

fn request(open_deg: f32, close_deg: f32) -> ValveRequest {
    ValveRequest {
        open_deg,
        close_deg,
        high_lift: true,
        soft_seat: false,
        enabled: true,
    }
}

fn inputs(req: ValveRequest, p_supply_mpa: f32, temp_c: f32) -> EhvvaStepInputs {
    EhvvaStepInputs {
        request: req,
        p_supply_mpa,
        temp_oil_c: temp_c,
        u_batt_v: 14.0,
        force_safe: false,
    }
}

/// Runs the task on `engine` until `t_end_us`, stepping on every edge, at every requested
/// wake-up and every 1 ms; `edit` may change the inputs or drop edges. Returns the pilot
/// solenoid log.
fn run<D: ActuationDelay>(
    task: &mut EhvvaTask<D>,
    engine: &mut SimEngine,
    inp: &mut EhvvaStepInputs,
    t_end_us: u32,
    mut edit: impl FnMut(u32, &mut EhvvaStepInputs) -> bool,
    mut on_out: impl FnMut(u32, &EhvvaStepOutputs),
) -> FakeSolenoid {
    let mut sol = FakeSolenoid::default();
    let mut edge = engine.next_edge();
    let mut wake = 0u32;
    let mut tick = 0u32;
    loop {
        let now = edge.t_us.min(wake).min(tick);
        if now >= t_end_us {
            break;
        }
        let keep_edges = edit(now, inp);
        while edge.t_us == now {
            if keep_edges {
                task.on_edge(edge);
            }
            edge = engine.next_edge();
        }
        let out = task.step(inp, now);
        sol.now_us = now;
        sol.apply(out.pilot);
        on_out(now, &out);
        wake = out.wake_at_us;
        if tick <= now {
            tick = now + 1000;
        }
    }
    sol
}

fn tables() -> EhvvaTables<f32> {
    EhvvaTables::new(&EhvvaParams::paper_default()).unwrap()
}

/// Largest |valve event angle − requested angle| over the events after sync, where the
/// valve event comes td plus the tabulated motion after the pilot edge (high lift).
fn worst_event_error_deg(rpm: f64, accel: f64, p_mpa: f32, temp_c: f32, open: f32, close: f32) -> (f64, usize) {
    let td = tables();
    let (td_vo, td_vc) = td.event_advances_ms(p_mpa, temp_c, true);
    let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), td).unwrap();
    let mut eng = SimEngine::new(rpm, accel, 450.0);
    let mut inp = inputs(request(open, close), p_mpa, temp_c);
    let t_end = (8.0 * 720.0 / (rpm * 6.0 / 1e6)) as u32;
    let log = run(&mut task, &mut eng, &mut inp, t_end, |_, _| true, |_, _| {});
    let mut worst: f64 = 0.0;
    let mut n = 0;
    for &(t, cmd) in log.log.iter() {
        let (td_ms, want) = match cmd {
            SolenoidCmd::Full => (td_vo, open),
            SolenoidCmd::Off => (td_vc, close),
            SolenoidCmd::Pwm(_) => continue,
        };
        let at = eng.angle_abs(t as f64 + td_ms as f64 * 1000.0).rem_euclid(720.0);
        let mut err = at - want as f64;
        if err > 360.0 {
            err -= 720.0;
        } else if err < -360.0 {
            err += 720.0;
        }
        worst = worst.max(err.abs());
        n += 1;
    }
    (worst, n)
}

#[test]
fn valve_moves_at_the_requested_angle_across_speeds_and_pressures() {
    // Constant speed: the td advance puts the valve motion within 0.1 crank degrees of the
    // request (1 µs capture and wake-up quantization over a ≥ 1 ms speed baseline;
    // measured: at most 0.007 deg at 600 rpm, 0.044 deg at 6000 rpm).
    for rpm in [600.0, 1500.0, 3000.0, 6000.0] {
        for (p, temp) in [(5.0, 22.0), (8.0, 22.0), (5.0, -20.0), (6.5, 100.0)] {
            let (worst, n) = worst_event_error_deg(rpm, 0.0, p, temp, 340.0, 580.0);
            assert!(n >= 8, "{rpm} rpm {p} MPa: only {n} pilot edges");
            assert!(worst < 0.1, "{rpm} rpm, {p} MPa, {temp} °C: valve off by {worst} deg");
        }
    }
    // Accelerating and decelerating at 3000 rpm/s: within 0.3 degree (measured 0.19 and
    // 0.16 deg: the speed is extrapolated over td without the acceleration term).
    for (rpm, accel) in [(2000.0, 3000.0), (4000.0, -3000.0)] {
        let (worst, n) = worst_event_error_deg(rpm, accel, 6.0, 60.0, 100.0, 300.0);
        assert!(n >= 8);
        assert!(worst < 0.3, "{rpm} rpm at {accel} rpm/s: {worst} deg");
    }
}

#[test]
fn without_the_td_advance_the_valve_would_be_late_by_omega_td() {
    // The same scheduler with zero delay commands at the requested angle; the valve then
    // moves td·ω late: 3.7 ms at 3000 rpm = 66.6 deg (the error the advance removes).
    let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), (0.0f32, 0.0f32)).unwrap();
    let mut eng = SimEngine::new(3000.0, 0.0, 450.0);
    let mut inp = inputs(request(340.0, 580.0), 5.0, 22.0);
    let log = run(&mut task, &mut eng, &mut inp, 100_000, |_, _| true, |_, _| {});
    let (td_vo, _) = tables().delays_ms(5.0, 22.0);
    let t_on = log.log.iter().find(|(_, c)| *c == SolenoidCmd::Full).unwrap().0;
    let late = eng.angle_abs(t_on as f64 + td_vo as f64 * 1000.0).rem_euclid(720.0) - 340.0;
    assert!((late - 66.6).abs() < 1.0, "late by {late} deg");
}

#[test]
fn peak_and_hold_sequence_on_the_solenoid_double() {
    // Each event: full voltage for the RL peak time at the measured battery voltage, then
    // the hold duty I_hold·R/U, then off; the coil current reaches the 3 A peak.
    for u_batt in [8.0f32, 14.0] {
        let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), tables()).unwrap();
        let mut eng = SimEngine::new(1200.0, 0.0, 450.0);
        let mut inp = inputs(request(200.0, 500.0), 6.0, 60.0);
        inp.u_batt_v = u_batt;
        let log = run(&mut task, &mut eng, &mut inp, 300_000, |_, _| true, |_, _| {});
        let expected = plan::<f32>(&SolenoidParams::pilot_default(), u_batt);
        let entries = &log.log;
        let mut events = 0;
        for w in entries.windows(3) {
            if let [(t_full, SolenoidCmd::Full), (t_hold, SolenoidCmd::Pwm(duty)), (t_off, SolenoidCmd::Off)] = *w {
                events += 1;
                let peak_us = (t_hold - t_full) as f32;
                assert!(
                    (peak_us - expected.t_peak_us).abs() <= 1.5,
                    "{u_batt} V: peak {peak_us} µs vs {}",
                    expected.t_peak_us
                );
                assert!((duty - 2.0 / u_batt).abs() < 1e-4, "hold duty {duty}");
                // The coil, driven like this, reaches the peak current at the switch-over.
                let mut coil = RlCoil::<f64>::new(&SolenoidParams::pilot_default());
                coil.step(u_batt as f64, peak_us as f64);
                assert!(
                    (coil.current_a - 3.0).abs() < 0.01,
                    "{u_batt} V: {} A at peak end",
                    coil.current_a
                );
                // The pilot stays on for the requested 300 deg minus the td difference.
                let dwell_deg = (t_off - t_full) as f64 * 1200.0 * 6.0 / 1e6;
                assert!(dwell_deg > 250.0 && dwell_deg < 320.0, "dwell {dwell_deg} deg");
            }
        }
        assert!(events >= 2, "{u_batt} V: {events} complete events in {entries:?}");
    }
}

#[test]
fn lost_crank_signal_stops_events_and_closes_the_valve() {
    let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), tables()).unwrap();
    let mut eng = SimEngine::new(1500.0, 0.0, 450.0);
    // A long event so that the signal is cut while the pilot is on.
    let mut inp = inputs(request(100.0, 600.0), 6.0, 60.0);
    let cut_at = core::cell::Cell::new(None::<u32>);
    let mut lost_at = None;
    let log = run(
        &mut task,
        &mut eng,
        &mut inp,
        600_000,
        // Cut the sensor once the pilot is on, 150 ms in.
        |now, _| cut_at.get().is_none_or(|c| now < c),
        |now, out| {
            if now >= 150_000 && cut_at.get().is_none() && matches!(out.pilot, SolenoidCmd::Full | SolenoidCmd::Pwm(_))
            {
                cut_at.set(Some(now + 1));
            }
            if out.crank_lost_now {
                lost_at = Some(now);
            }
        },
    );
    let (cut, lost) = (
        cut_at.get().expect("pilot on after 150 ms"),
        lost_at.expect("crank loss detected"),
    );
    // 1500 rpm: gap interval 2 ms, lost after 3 gap intervals (6 ms) + the next step.
    assert!(lost - cut < 8_000, "lost after {} µs", lost - cut);
    let off = log
        .log
        .iter()
        .find(|(t, c)| *t >= cut && *c == SolenoidCmd::Off)
        .expect("pilot off");
    assert!(off.0 <= lost);
    // No event after the loss.
    assert!(log.log.iter().all(|(t, c)| *t <= lost || *c == SolenoidCmd::Off));
    assert!(task.decoder().snapshot().crank_lost);
}

#[test]
fn safe_state_and_slow_valves() {
    let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), tables()).unwrap();
    let mut eng = SimEngine::new(1500.0, 0.0, 450.0);
    let mut inp = inputs(request(100.0, 400.0), 6.0, 60.0);
    inp.request.soft_seat = true;
    let mut lift_changes_while_open = 0;
    let mut pilot_on = false;
    let mut last_lift = false;
    let log = run(
        &mut task,
        &mut eng,
        &mut inp,
        400_000,
        |now, i| {
            // Toggle the lift request every 7 ms; go safe at 300 ms.
            i.request.high_lift = (now / 7000) % 2 == 0;
            i.force_safe = now >= 300_000;
            true
        },
        |now, out| {
            let on = out.pilot != SolenoidCmd::Off;
            if on && pilot_on && out.lift_valve_on != last_lift {
                lift_changes_while_open += 1;
            }
            pilot_on = on;
            last_lift = out.lift_valve_on;
            if now >= 300_000 {
                assert_eq!(out.pilot, SolenoidCmd::Off, "safe state at {now}");
                assert!(!out.lift_valve_on && !out.snubber_switch_on);
            }
        },
    );
    assert!(log.log.iter().any(|(_, c)| *c == SolenoidCmd::Full));
    assert_eq!(lift_changes_while_open, 0, "the lift sleeve switched during an event");
}

#[test]
fn decoder_syncs_on_gap_and_cam_and_measures_speed() {
    let mut dec = CrankDecoder::new(TriggerWheel::sixty_minus_two(), 200_000, 500.0);
    let mut eng = SimEngine::new(2400.0, 0.0, 450.0);
    let mut saw_crank_only = false;
    for _ in 0..200 {
        let e = eng.next_edge();
        dec.on_edge(e);
        saw_crank_only |= dec.sync() == SyncState::Crank;
        if dec.sync() == SyncState::Full {
            let a = dec.angle_at(e.t_us).unwrap() as f64;
            let truth = eng.angle_abs(e.t_us as f64).rem_euclid(720.0);
            let mut err = (a - truth).abs();
            err = err.min(720.0 - err);
            assert!(err < 0.1, "angle {a} vs {truth}");
        }
    }
    assert!(saw_crank_only);
    assert_eq!(dec.sync(), SyncState::Full);
    assert!((dec.rpm() - 2400.0).abs() < 5.0, "{}", dec.rpm());
    assert_eq!(dec.sync_errors, 0);
    // The cam edge angle is where the simulated cam edge is.
    let s = dec.snapshot();
    assert!((s.cam_edge_deg.unwrap() - 450.0).abs() < 0.2, "{:?}", s.cam_edge_deg);
    assert!(!s.cranking);
}

#[test]
fn missing_cam_is_flagged_and_drops_to_crank_sync() {
    let mut dec = CrankDecoder::new(TriggerWheel::sixty_minus_two(), 200_000, 500.0);
    let mut eng = SimEngine::new(1800.0, 0.0, 450.0);
    for _ in 0..300 {
        dec.on_edge(eng.next_edge());
    }
    assert_eq!(dec.sync(), SyncState::Full);
    for _ in 0..300 {
        let e = eng.next_edge();
        if e.source == EdgeSource::CrankTooth {
            dec.on_edge(e);
        }
    }
    assert!(dec.snapshot().cam_lost);
    assert_ne!(dec.sync(), SyncState::Full);
    assert!(dec.angle_at(0).is_none());
}

proptest::proptest! {
    /// Whatever the edges (noise, missing teeth, random cam), nothing panics and the pilot
    /// is never on without full sync.
    #[test]
    fn arbitrary_edges_never_fire_without_sync(edges in proptest::collection::vec((proptest::bool::ANY, 1u32..40_000), 0..300)) {
        let mut task = EhvvaTask::new(EhvvaTaskConfig::default(), (3.5f32, 3.0f32)).unwrap();
        let inp = inputs(request(100.0, 300.0), 6.0, 60.0);
        let mut t = 0u32;
        for (cam, dt) in edges {
            t = t.wrapping_add(dt);
            let source = if cam { EdgeSource::CamSync } else { EdgeSource::CrankTooth };
            task.on_edge(Edge { source, t_us: t });
            let out = task.step(&inp, t);
            if task.decoder().sync() != SyncState::Full {
                proptest::prop_assert_eq!(out.pilot, SolenoidCmd::Off);
            }
            proptest::prop_assert!(out.engine.rpm.is_finite() && out.engine.rpm >= 0.0);
        }
    }
}
