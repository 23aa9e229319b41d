//! Processor in the loop under QEMU: the ECU core as firmware on the emulated STM32F405
//! (`firmware-qemu` on `netduinoplus2`) against the same core natively.
//!
//! Without `qemu-system-arm` these tests print why and pass, unless `HIL_REQUIRE_QEMU=1`
//! (tools/test.sh sets it), in which case they fail. The firmware image is built through cargo
//! in the workspace's target directory (tools/test.sh builds it before `cargo test`, so this
//! is a no-op there).
use std::path::PathBuf;
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use hil_host::pil::{self, LinkFaults, OpenLoopFeed, PilLink, PilOptions};
use model_core::ecu::frame::{ActuatorFrame, SensorFrame};
use model_core::ecu::board::SolenoidCmd;

/// The firmware image, or `None` (with the reason printed) when QEMU is not installed.
fn firmware() -> Option<PathBuf> {
    static ELF: OnceLock<Result<Option<PathBuf>, String>> = OnceLock::new();
    let r = ELF.get_or_init(|| {
        let required = std::env::var("HIL_REQUIRE_QEMU").is_ok_and(|v| v == "1");
        match pil::qemu_version() {
            Ok(v) => eprintln!("PIL tests on {v}"),
            Err(e) if required => return Err(format!("HIL_REQUIRE_QEMU=1 but {e}")),
            Err(e) => {
                eprintln!("SKIPPED: the PIL tests need {}: {e}", pil::QEMU);
                return Ok(None);
            }
        }
        pil::build_firmware().map(Some)
    });
    match r {
        Ok(elf) => elf.clone(),
        Err(e) => panic!("{e}"),
    }
}

/// One QEMU at a time: the tests' timing (answer timeouts, the firmware's link timeout) holds
/// on a loaded 2-core machine only when they do not compete with each other.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

fn feed(n: usize) -> Vec<SensorFrame> {
    let mut f = OpenLoopFeed::new(3000.0);
    (0..n).map(|_| f.next_frame()).collect()
}

fn assert_bit_exact(native: &[ActuatorFrame], pil: &[ActuatorFrame]) {
    assert_eq!(native.len(), pil.len());
    for (k, (n, p)) in native.iter().zip(pil).enumerate() {
        // bad_frames is the link's count, not the core's output.
        let p = ActuatorFrame { bad_frames: 0, ..*p };
        let bits = |a: &ActuatorFrame| {
            let pilot = match a.pilot {
                SolenoidCmd::Off => (0, 0),
                SolenoidCmd::Full => (1, 0),
                SolenoidCmd::Pwm(d) => (2, d.to_bits()),
            };
            (a.seq, a.t_us, pilot, a.lift_valve_on, a.snubber_on, a.motor_duty.to_bits(), a.vacuum_duty.map(f32::to_bits), a.pump_on, a.faults)
        };
        assert_eq!(bits(n), bits(&p), "step {k}: native {n:?}\n PIL {p:?}");
    }
}

#[test]
fn pil_answers_equal_native_core_bit_for_bit() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames = feed(2000);
    let native = pil::run_frames_native(&frames).unwrap();
    let mut link = PilLink::start(&elf, PilOptions::default()).unwrap();
    let run = pil::run_frames(&mut link, &frames).unwrap();
    eprintln!("{} PIL steps in {:.2} s: {:.0} steps/s, {:?}", run.answers.len(), run.wall_s, run.steps_per_s(), run.stats);
    assert_bit_exact(&native, &run.answers);
    assert!(native.iter().any(|a| a.pilot == SolenoidCmd::Full), "no valve event in the compared steps");
    assert_eq!(run.stats.ecu_bad_frames, 0);
    assert_eq!(run.stats.bad_frames_received, 0);
}

#[test]
fn corrupted_and_dropped_frames_are_counted_and_retransmitted_losslessly() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames = feed(400);
    let native = pil::run_frames_native(&frames).unwrap();
    let faults = LinkFaults { corrupt_every: Some(7), drop_every: Some(40) };
    let mut link = PilLink::start(&elf, PilOptions { faults, ..PilOptions::default() }).unwrap();
    let run = pil::run_frames(&mut link, &frames).unwrap();
    let s = run.stats;
    eprintln!("{s:?}");
    assert_eq!(run.answers.len(), frames.len());
    assert_bit_exact(&native, &run.answers);
    // Every transmission counted: the k-th is corrupted when 7 | k, dropped when 40 | k.
    let attempts = s.transmissions + s.dropped_injected;
    assert_eq!(s.dropped_injected, attempts / 40);
    assert_eq!(s.corrupted_injected, attempts / 7 - attempts / 280);
    assert!(s.corrupted_injected >= 50 && s.dropped_injected >= 10, "too few faults injected: {s:?}");
    // The firmware rejected exactly the corrupted frames and said so each time.
    assert_eq!(u64::from(s.ecu_bad_frames), s.corrupted_injected);
    assert_eq!(s.nacks_received, s.corrupted_injected);
    // Each dropped frame was sent again after the answer timeout (a slow host may add a few
    // spurious ones, never fewer).
    assert!(s.answer_timeouts >= s.dropped_injected, "{s:?}");
    assert_eq!(s.bad_frames_received, 0);
    assert_eq!(s.safe_state_reports, 0, "a dropped frame must not trip the firmware's link timeout");
}

#[test]
fn a_silent_link_drives_the_safe_outputs_and_stepping_resumes() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames = feed(300);
    let native = pil::run_frames_native(&frames).unwrap();
    let mut link = PilLink::start(&elf, PilOptions::default()).unwrap();
    let first = pil::run_frames(&mut link, &frames[..150]).unwrap();
    // Outputs live before the silence: the vacuum valves are being driven.
    let last = first.answers.last().copied().unwrap();
    assert!(last.vacuum_duty.iter().any(|d| *d > 0.0), "{last:?}");
    let reports = link.stay_silent(Duration::from_millis(400)).unwrap();
    assert_eq!(reports.len(), 1, "one safe-state report per silence: {reports:?}");
    let r = reports[0];
    assert_eq!(r.seq, last.seq);
    assert!(r.t_us.wrapping_sub(last.t_us) >= 100_000, "reported after {} µs, before the 100 ms timeout", r.t_us.wrapping_sub(last.t_us));
    assert_eq!(r.pilot, SolenoidCmd::Off);
    assert!(!r.lift_valve_on && !r.snubber_on && !r.pump_on);
    assert_eq!((r.motor_duty, r.vacuum_duty), (0.0, [0.0; 3]));
    // The core was not disturbed: the next frames step on as natively.
    let second = pil::run_frames(&mut link, &frames[150..]).unwrap();
    let mut all = first.answers;
    all.extend(second.answers);
    assert_bit_exact(&native, &all);
}
