//! The calibration image on the emulated ECU (firmware-qemu under QEMU): loaded into the
//! calibration flash sector, read and checked at boot, run bit for bit like the native core
//! with the same image; a corrupted image makes the firmware fall back to the paper defaults
//! with the calibration fault bit, and the host refuses to send one.
//!
//! Without `qemu-system-arm` these tests print why and pass, unless `HIL_REQUIRE_QEMU=1`
//! (tools/test.sh sets it), in which case they fail.
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use hil_host::pil::{self, LinkFaults};
use hil_host::run::{Scenario, Unit};
use model_core::ecu::calibration::{CalibrationImage, EcuCalibration, CALIBRATION_FAULT_BIT, IMAGE_BYTES};
use model_core::ecu::lockstep::EcuCoreConfig;

fn firmware() -> Option<PathBuf> {
    static ELF: OnceLock<Result<Option<PathBuf>, String>> = OnceLock::new();
    let r = ELF.get_or_init(|| {
        let required = std::env::var("HIL_REQUIRE_QEMU").is_ok_and(|v| v == "1");
        match pil::qemu_version() {
            Ok(_) => {}
            Err(e) if required => return Err(format!("HIL_REQUIRE_QEMU=1 but {e}")),
            Err(e) => {
                eprintln!("SKIPPED: the calibration PIL tests need {}: {e}", pil::QEMU);
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

/// A 0.1 s scenario (the shortest a scenario may be) at 4000 rpm, run for [`UNTIL_S`]: the
/// crank decoder syncs and valve events run.
/// Simulated seconds of each run (1200 lockstep steps).
const UNTIL_S: Option<f64> = Some(0.06);

fn scenario() -> Scenario {
    let text = r#"
name = "pil-calibration"
duration_s = 0.1
engine_rpm = [[0.0, 4000.0]]
p_supply_mpa = [[0.0, 6.0]]
cam_phase_setpoint_deg = [[0.0, 10.0], [0.03, 10.0], [0.0301, 30.0]]
"#;
    Scenario::from_toml(Path::new("pil-calibration.toml"), text).unwrap()
}

/// An image whose td tables are 0.6 ms longer than the paper's: every pilot edge moves.
fn image(dir: &Path) -> (PathBuf, Vec<u8>) {
    let mut cal = EcuCalibration::paper_defaults();
    for row in cal
        .ehvva_tables
        .td_open_ms
        .iter_mut()
        .chain(cal.ehvva_tables.td_close_ms.iter_mut())
    {
        for v in row {
            *v += 0.6;
        }
    }
    let mut bytes = vec![0u8; IMAGE_BYTES];
    CalibrationImage::serialize(&cal, &mut bytes).unwrap();
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join("calibration.bin");
    std::fs::write(&p, &bytes).unwrap();
    (p, bytes)
}

#[test]
fn the_emulated_ecu_runs_its_calibration_image_or_falls_back_with_the_fault_bit() {
    let Some(elf) = firmware() else { return };
    let dir = std::env::temp_dir().join(format!("pil-calibration-{}", std::process::id()));
    let (good, bytes) = image(&dir);
    let unit = Unit::default();

    // The image in the calibration sector: the PIL run equals the native core with the image.
    let r = pil::run_scenario_calibrated(
        &scenario(),
        &elf,
        LinkFaults::default(),
        UNTIL_S,
        true,
        &dir.join("good"),
        Some(&good),
        &unit,
    )
    .unwrap();
    assert!(r.first_difference.is_none(), "{}", r.text());
    assert!(!r.output.summary.calibration_fault);
    let pilot_on = |frames: &[(
        model_core::ecu::frame::SensorFrame,
        model_core::ecu::frame::ActuatorFrame,
    )]| {
        frames
            .iter()
            .position(|(_, a)| a.pilot != model_core::ecu::board::SolenoidCmd::Off)
    };
    let calibrated_first_edge = pilot_on(&r.output.frames).expect("no valve event");
    eprintln!("{}first pilot edge at step {calibrated_first_edge}", r.text());
    // ... and not the paper defaults: the longer td advances the first pilot edge.
    let paper = hil_host::run::run_with(
        &scenario(),
        &mut hil_host::run::NativeLink::new().unwrap(),
        &hil_host::run::RunOptions {
            until_s: UNTIL_S,
            keep_frames: true,
        },
    )
    .unwrap();
    let paper_first_edge = pilot_on(&paper.frames).expect("no valve event");
    assert!(
        calibrated_first_edge < paper_first_edge,
        "pilot edge at step {calibrated_first_edge} with the image, {paper_first_edge} without"
    );

    // A corrupted image: the host refuses to send it, naming the calibration.
    let mut bad = bytes.clone();
    bad[300] ^= 0x10;
    let bad_path = dir.join("corrupt.bin");
    std::fs::write(&bad_path, &bad).unwrap();
    let e = pil::run_scenario_calibrated(
        &scenario(),
        &elf,
        LinkFaults::default(),
        UNTIL_S,
        false,
        &dir.join("refused"),
        Some(&bad_path),
        &unit,
    )
    .err()
    .unwrap_or_default();
    assert!(e.contains("calibration image corrupted"), "{e}");

    // Loaded anyway: the firmware checks it at boot, runs the paper defaults (bit for bit the
    // native fall-back) and sets the calibration fault bit in every frame.
    let fallback = EcuCoreConfig {
        calibration_fault: true,
        ..EcuCoreConfig::default()
    };
    let r = pil::run_scenario_image(
        &scenario(),
        &elf,
        LinkFaults::default(),
        (UNTIL_S, true),
        &dir.join("fallback"),
        (Some(&bad_path), fallback),
        &unit,
    )
    .unwrap();
    assert!(r.first_difference.is_none(), "{}", r.text());
    assert!(r.output.summary.calibration_fault);
    assert!(r
        .output
        .frames
        .iter()
        .all(|(_, a)| a.faults & CALIBRATION_FAULT_BIT != 0));
    assert_eq!(pilot_on(&r.output.frames), Some(paper_first_edge));
    let _ = std::fs::remove_dir_all(&dir);
}
