//! ECU firmware entry. For now this proves that model-core builds and links for the target:
//! it runs the pilot peak-and-hold planner and the vacuum PWM compensator in a loop. The
//! embassy tasks per actuator replace this loop (firmware issue).
#![no_std]
#![no_main]

use core::panic::PanicInfo;

use cortex_m_rt::entry;
use model_core::peak_hold::{PeakHoldDriver, SolenoidParams};
use model_core::pwm_comp::PwmCompensator;

#[entry]
fn main() -> ! {
    let mut pilot = match PeakHoldDriver::<f32>::new(SolenoidParams::pilot_default()) {
        Ok(d) => d,
        Err(_) => safe_state(),
    };
    let comp = match PwmCompensator::<f32>::new(13.5, 6.0, 0.0, 100.0) {
        Ok(c) => c,
        Err(_) => safe_state(),
    };
    let mut u_batt_v = 14.0f32;
    loop {
        pilot.set(true, u_batt_v);
        let duty = pilot.tick(10.0, None) + comp.apply(40.0, u_batt_v).duty_pct;
        u_batt_v = if duty > 0.0 { 13.9 } else { 14.0 };
        cortex_m::asm::nop();
    }
}

/// Outputs are not driven yet; park the core.
fn safe_state() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_info: &PanicInfo) -> ! {
    safe_state()
}
