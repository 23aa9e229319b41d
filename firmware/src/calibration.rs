//! The calibration image at boot: the calibration flash sector (`memory.x`, `CALIBRATION` at
//! 0x080E0000, sector 11, written with `probe-rs download --binary-format bin --base-address
//! 0x080E0000 --chip STM32F405RGTx calibration.bin`) read and checked whole by model-core
//! ([`boot_config`]): the image's tables when every check passes, else the paper defaults. An
//! image that was there but refused (bad CRC, version, a value outside its limits) sets
//! [`CALIBRATION_FAULT`] and is logged; an erased sector is no fault (an uncalibrated ECU).
use core::sync::atomic::{AtomicBool, Ordering};

use model_core::ecu::calibration::{boot_config, BootCalibration, IMAGE_BYTES};
use model_core::ecu::lockstep::EcuCoreConfig;

/// Set at boot when the calibration image was refused and the paper defaults run.
pub static CALIBRATION_FAULT: AtomicBool = AtomicBool::new(false);

extern "C" {
    /// The first byte of the calibration sector (memory.x).
    static _calibration_start: u8;
}

/// The image's bytes in the memory-mapped flash.
fn sector() -> &'static [u8] {
    // SAFETY: `_calibration_start` is the linker's address of the 128 KiB calibration flash
    // sector (memory.x); flash is mapped for reading and not written while the firmware runs,
    // and IMAGE_BYTES (about 1 KiB) lies well inside the sector.
    unsafe { core::slice::from_raw_parts(core::ptr::addr_of!(_calibration_start), IMAGE_BYTES) }
}

/// The tasks' configuration from the calibration sector (module doc), logged.
pub fn load() -> EcuCoreConfig {
    let (cfg, status) = boot_config(sector());
    match status {
        BootCalibration::Image => defmt::info!("calibration image read and checked"),
        BootCalibration::Absent => defmt::info!("no calibration image: paper defaults"),
        BootCalibration::Refused(e) => {
            let (check, name) = e.names();
            CALIBRATION_FAULT.store(true, Ordering::Relaxed);
            defmt::error!(
                "calibration image refused ({=str}: {=str}): paper defaults, calibration fault set",
                check,
                name
            );
        }
    }
    cfg
}
