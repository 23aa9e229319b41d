//! The calibration image at boot: the calibration flash sector (`memory.x`, `CALIBRATION` at
//! 0x080E0000; under QEMU, `hil-host pil --calibration` loads the image there with
//! `-device loader`) read and checked whole by model-core ([`boot_config`]): its values when
//! every check passes, else the paper defaults, with the calibration fault bit in every
//! actuator frame when an image was there but refused (bad CRC, version, limits).
use model_core::ecu::calibration::{boot_config, BootCalibration, IMAGE_BYTES};
use model_core::ecu::lockstep::EcuCoreConfig;

extern "C" {
    /// The first byte of the calibration sector (memory.x).
    static _calibration_start: u8;
}

/// The image's bytes in the memory-mapped flash.
fn sector() -> &'static [u8] {
    // SAFETY: `_calibration_start` is the linker's address of the 128 KiB calibration flash
    // sector (memory.x); flash is mapped for reading and never written while the firmware
    // runs, and IMAGE_BYTES (about 1 KiB) lies well inside the sector.
    unsafe { core::slice::from_raw_parts(core::ptr::addr_of!(_calibration_start), IMAGE_BYTES) }
}

/// The ECU core's configuration from the calibration sector (module doc), logged.
pub fn load() -> EcuCoreConfig {
    let (cfg, status) = boot_config(sector());
    match status {
        BootCalibration::Image => defmt::info!("calibration image v1 read and checked"),
        BootCalibration::Absent => defmt::info!("no calibration image: paper defaults"),
        BootCalibration::Refused(e) => {
            let (check, name) = e.names();
            defmt::error!(
                "calibration image refused ({=str}: {=str}): paper defaults, calibration fault set",
                check,
                name
            );
        }
    }
    cfg
}
