//! Processor in the loop under QEMU: the ECU core as firmware on the emulated STM32F405
//! (`firmware-qemu` on `netduinoplus2`) against the same core natively.
//!
//! Without `qemu-system-arm` these tests print why and pass, unless `HIL_REQUIRE_QEMU=1`
//! (tools/test.sh sets it), in which case they fail. The firmware image is built through cargo
//! in the workspace's target directory (tools/test.sh builds it before `cargo test`, so this
//! is a no-op there).
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::Duration;

use hil_host::pil::{self, LinkFaults, PilLink, PilOptions};
use hil_host::run::{run_with, NativeLink, RunOptions, Scenario};
use model_core::ecu::board::SolenoidCmd;
use model_core::ecu::frame::{
    crc16, encode, ActuatorFrame, Frame, FrameError, SensorFrame, FRAME_VERSION, MAX_FRAME_BYTES,
};

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
    closed_loop_frames().into_iter().take(n).collect()
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
            (
                a.seq,
                a.t_us,
                pilot,
                a.lift_valve_on,
                a.snubber_on,
                a.motor_duty.to_bits(),
                a.vacuum_duty.map(f32::to_bits),
                a.pump_on,
                a.faults,
            )
        };
        assert_eq!(bits(n), bits(&p), "step {k}: native {n:?}\n PIL {p:?}");
    }
}

/// A short closed-loop scenario: at 4000 rpm the crank decoder syncs and valve events run
/// within the first 0.1 s; phase and wastegate steps at 50 ms.
fn short_scenario() -> Scenario {
    let text = r#"
name = "pil-agreement"
duration_s = 0.15
engine_rpm = [[0.0, 4000.0]]
cam_phase_setpoint_deg = [[0.0, 10.0], [0.05, 10.0], [0.0501, 30.0]]
wastegate_setpoint_pct = [[0.0, 20.0], [0.05, 20.0], [0.0501, 60.0]]
"#;
    Scenario::from_toml(Path::new("pil-agreement.toml"), text).unwrap()
}

/// The sensor frames of the short scenario's native closed-loop run.
fn closed_loop_frames() -> Vec<SensorFrame> {
    static FRAMES: OnceLock<Vec<SensorFrame>> = OnceLock::new();
    FRAMES
        .get_or_init(|| {
            let out = run_with(
                &short_scenario(),
                &mut NativeLink::new().unwrap(),
                &RunOptions {
                    until_s: None,
                    keep_frames: true,
                },
            )
            .unwrap();
            out.frames.into_iter().map(|(s, _)| s).collect()
        })
        .clone()
}

/// f32 agreement: the core's arithmetic is IEEE-754 single precision on both sides (SSE on
/// the host, the Cortex-M4F's FPU under QEMU) with the same software exp/sin/atan/sqrt from
/// micromath and libm, and no fused multiply-add on either side: every actuator frame is
/// expected bit for bit, so the tolerance is zero.
#[test]
fn closed_loop_pil_run_equals_native_run_bit_for_bit() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let dir = std::env::temp_dir().join(format!("pil-agreement-{}", std::process::id()));
    let r = pil::run_scenario(&short_scenario(), &elf, LinkFaults::default(), None, true, &dir).unwrap();
    eprint!("{}", r.text());
    assert_eq!(r.stats.steps, 3000);
    assert_eq!(r.compared_steps, Some(3000));
    assert!(r.first_difference.is_none(), "{}", r.text());
    let pilots: Vec<SolenoidCmd> = r.output.frames.iter().map(|(_, a)| a.pilot).collect();
    assert!(
        pilots.contains(&SolenoidCmd::Full),
        "no valve event in the compared steps"
    );
    assert!(
        r.output.frames.iter().any(|(_, a)| a.motor_duty != 0.0),
        "EVVT never commanded"
    );
    assert_eq!(r.stats.ecu_bad_frames, 0);
    assert_eq!(r.stats.bad_frames_received, 0);
}

/// Instruction counts on the target, and the fixed-point paths bit-exact: the Q32 plant steps
/// on the emulated Cortex-M4 end in the same bits as on the host (integer arithmetic), and so
/// do the f32 ones (IEEE single precision, see above).
#[test]
fn target_bench_counts_every_task_and_plant_and_matches_the_host() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames: Vec<SensorFrame> = closed_loop_frames().into_iter().take(300).collect();
    let dir = std::env::temp_dir().join(format!("pil-bench-{}", std::process::id()));
    let b = pil::target_bench(&elf, &frames, &dir, true).unwrap();
    eprint!("{}", b.text());
    for (k, (name, _)) in pil::PLANT_NUMBERS.iter().enumerate() {
        assert!(b.plant_states_equal(k), "{name} plant states differ");
    }
    assert!(b.answers_equal_native);
    let count = |label: &str| {
        b.counts
            .iter()
            .find(|c| c.label == label)
            .unwrap_or_else(|| panic!("no {label} count: {:?}", b.counts))
            .clone()
    };
    for (label, n) in [
        ("core_step", 300),
        ("ehvva", 300),
        ("supervisor", 2),
        ("evvt", 2),
        ("vacuum", 2),
    ] {
        let c = count(label);
        assert_eq!(c.n, n, "{label}: {c:?}");
        assert!(c.min > 50, "{label}: {c:?}");
    }
    // The whole step holds its tasks.
    assert!(count("core_step").max >= count("vacuum").max + count("ehvva").min);
    for plant in model_core::plant_bench::BenchPlant::ALL {
        let label = plant.label();
        let (f, x) = (
            count(&format!("{label}_plant_f32")),
            count(&format!("{label}_plant_fixed")),
        );
        assert_eq!((f.n, x.n), (8, 8));
        assert!(f.min > 20 && x.min > 20, "{label}: f32 {f:?}, Q16 {x:?}");
    }
    // The per-address profile accounts for every counted instruction of a step that holds no
    // other counted interval: per label, its addresses sum to the raw intervals' counts.
    let sums = |file: &str, count_column: usize| {
        let text = std::fs::read_to_string(dir.join(file)).unwrap();
        let mut by_label = std::collections::HashMap::<String, u64>::new();
        for line in text.lines() {
            let cols: Vec<&str> = line.split_whitespace().collect();
            *by_label.entry(cols[0].to_string()).or_default() += cols[count_column].parse::<u64>().unwrap();
        }
        by_label
    };
    let (raw, by_address) = (sums("insn-counts.txt", 1), sums(pil::BY_ADDRESS_FILE, 2));
    for plant in model_core::plant_bench::BenchPlant::ALL {
        for number in ["f32", "fixed"] {
            let label = format!("{}_plant_{number}", plant.label());
            assert_eq!(by_address.get(&label), raw.get(&label), "{label}");
        }
    }
    let json = b.to_json();
    let rows = json["plant_steps"].as_array().unwrap();
    assert_eq!(rows.len(), 10, "{json}");
    assert!(rows
        .iter()
        .any(|r| r["plant"] == "ehvva-reduced" && r["number"] == "fixed"));
}

#[test]
fn corrupted_and_dropped_frames_are_counted_and_retransmitted_losslessly() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames = feed(400);
    let native = pil::run_frames_native(&frames).unwrap();
    let faults = LinkFaults {
        corrupt_every: Some(7),
        drop_every: Some(40),
    };
    let mut link = PilLink::start(
        &elf,
        PilOptions {
            faults,
            ..PilOptions::default()
        },
    )
    .unwrap();
    let run = pil::run_frames(&mut link, &frames).unwrap();
    let s = run.stats;
    eprintln!("{s:?}");
    assert_eq!(run.answers.len(), frames.len());
    assert_bit_exact(&native, &run.answers);
    // Every transmission counted: the k-th is corrupted when 7 | k, dropped when 40 | k.
    let attempts = s.transmissions + s.dropped_injected;
    assert_eq!(s.dropped_injected, attempts / 40);
    assert_eq!(s.corrupted_injected, attempts / 7 - attempts / 280);
    assert!(
        s.corrupted_injected >= 50 && s.dropped_injected >= 10,
        "too few faults injected: {s:?}"
    );
    // The firmware rejected exactly the corrupted frames and said so each time.
    assert_eq!(u64::from(s.ecu_bad_frames), s.corrupted_injected);
    assert_eq!(s.nacks_received, s.corrupted_injected);
    // Each dropped frame was sent again after the answer timeout (a slow host may add a few
    // spurious ones, never fewer).
    assert!(s.answer_timeouts >= s.dropped_injected, "{s:?}");
    assert_eq!(s.bad_frames_received, 0);
    // (No assertion on safe-state reports: the host waits 25 ms for an answer, far below
    // the firmware's 100 ms, but a loaded 2-core machine can stall QEMU longer than that;
    // a report is discarded by the host and does not disturb the core, as the bit-exact
    // comparison above shows.)
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
    assert!(
        r.t_us.wrapping_sub(last.t_us) >= 100_000,
        "reported after {} µs, before the 100 ms timeout",
        r.t_us.wrapping_sub(last.t_us)
    );
    assert_eq!(r.pilot, SolenoidCmd::Off);
    assert!(!r.lift_valve_on && !r.snubber_on && !r.pump_on);
    assert_eq!((r.motor_duty, r.vacuum_duty), (0.0, [0.0; 3]));
    // The core was not disturbed: the next frames step on as natively.
    let second = pil::run_frames(&mut link, &frames[150..]).unwrap();
    let mut all = first.answers;
    all.extend(second.answers);
    assert_bit_exact(&native, &all);
}

/// Frames that pass the CRC but not the other checks are rejected too: a wrong version and
/// an ADC count above 12 bits each get a Nack naming the reason, are counted, and change
/// nothing: the next valid frames are answered exactly as by a core that never saw them.
#[test]
fn well_formed_but_invalid_frames_are_answered_with_a_nack_and_never_used() {
    let Some(elf) = firmware() else { return };
    let _one = one_at_a_time();
    let frames = feed(40);
    let native = pil::run_frames_native(&frames).unwrap();
    let mut link = PilLink::start(&elf, PilOptions::default()).unwrap();
    let first = pil::run_frames(&mut link, &frames[..20]).unwrap();
    // Frame 21 as it should be, then spoiled two ways with a correct CRC.
    let mut wire = [0u8; MAX_FRAME_BYTES];
    let n = encode(&Frame::Sensor(frames[20]), &mut wire).unwrap();
    let reseal = |mut bytes: Vec<u8>| {
        let end = bytes.len() - 2;
        let crc = crc16(&bytes[2..end]);
        bytes[end..].copy_from_slice(&crc.to_le_bytes());
        bytes
    };
    let mut wrong_version = wire[..n].to_vec();
    wrong_version[2] = FRAME_VERSION + 1;
    // The first ADC count sits after seq, t_us, the edge count and the edges.
    let mut count_too_big = wire[..n].to_vec();
    let at = 5 + 9 + 5 * frames[20].n_edges as usize;
    count_too_big[at..at + 2].copy_from_slice(&4096u16.to_le_bytes());
    for (bytes, why, bad_so_far) in [
        (reseal(wrong_version), FrameError::BadVersion, 1),
        (reseal(count_too_big), FrameError::BadPayload, 2),
    ] {
        link.send_raw(&bytes).unwrap();
        match link.next_frame(Duration::from_secs(5)).unwrap() {
            Some(Ok(Frame::Nack(nack))) => {
                assert_eq!(nack.reason, why as u8);
                assert_eq!(nack.bad_frames, bad_so_far);
                assert_eq!(nack.seq_expected, frames[20].seq, "the ECU still expects frame 21");
            }
            other => panic!("expected a Nack for {why:?}, got {other:?}"),
        }
    }
    let second = pil::run_frames(&mut link, &frames[20..]).unwrap();
    assert_eq!(second.stats.ecu_bad_frames, 2);
    let mut all = first.answers;
    all.extend(second.answers);
    assert_bit_exact(&native, &all);
}
