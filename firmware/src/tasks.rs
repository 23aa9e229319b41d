//! The task loops: a timer (or the crank edges), the part of the one composition
//! (`model_core::ecu::schedule`) that reads the board, computes and writes the board, and the
//! log lines. Periods, order, input assembly, the safe states and the watchdog decision are
//! the composition's; `hil-host run` and the QEMU image run the same parts' `run` methods in
//! lockstep (`model_core::ecu::lockstep::EcuCore`). The `#[embassy_executor::task]` wrappers in
//! `main.rs` bind these to the ECU board's types (embassy tasks cannot be generic).

use embassy_time::{Duration, Ticker};
use model_core::ecu::board::Clock;
use model_core::ecu::schedule::{
    AnalogBank, EhvvaPart, EvvtBoard, EvvtPart, SupervisorPart, VacuumBoard, VacuumPart, Watchdog, EVVT_PERIOD_US,
    SUPERVISOR_PERIOD_US, VACUUM_PERIOD_US,
};

use crate::board::EhvvaIo;
use crate::shared::{self, Shared};

fn ticker(period_us: u32) -> Ticker {
    Ticker::every(Duration::from_micros(u64::from(period_us)))
}

/// EHVVA: wakes on every crank edge and at the part's next deadline (a command angle or the
/// end of the peak), so the pilot edges land within a few µs of their computed instants.
pub async fn ehvva<B: EhvvaIo>(io: &mut B, mut part: EhvvaPart) -> ! {
    let mut wake_at_us = io.now_us();
    loop {
        io.wait_edge_or(wake_at_us).await;
        let now_us = io.now_us();
        let out = part.run(&mut Shared, io, &shared::setpoints().valve, now_us);
        if out.crank_lost_now {
            defmt::warn!("EHVVA: crank signal lost, pilot off");
        }
        wake_at_us = out.wake_at_us;
    }
}

/// EVVT: every `EVVT_PERIOD_US` (100 Hz).
pub async fn evvt(io: &mut impl EvvtBoard, clock: impl Clock, mut part: EvvtPart) -> ! {
    let mut ticker = ticker(EVVT_PERIOD_US);
    loop {
        ticker.next().await;
        part.run(&mut Shared, io, shared::setpoints().cam_phase_deg, clock.now_us());
    }
}

/// Vacuum valves: duty update every `VACUUM_PERIOD_US` (80 Hz; the PWM itself runs at
/// 300 Hz in hardware).
pub async fn vacuum(io: &mut impl VacuumBoard, clock: impl Clock, mut part: VacuumPart) -> ! {
    let mut ticker = ticker(VACUUM_PERIOD_US);
    loop {
        ticker.next().await;
        part.run(&mut Shared, io, shared::setpoints().vacuum_x_pct, clock.now_us());
    }
}

/// Supervisor: every `SUPERVISOR_PERIOD_US` (100 Hz) the ADC scan, range checks and faults,
/// the watchdog petted when every task ran since the last check (the part decides), a defmt
/// message per fault change and a status line every second.
pub async fn supervisor(
    adc: &mut impl AnalogBank,
    watchdog: &mut impl Watchdog,
    clock: impl Clock,
    mut part: SupervisorPart,
) -> ! {
    let mut ticker = ticker(SUPERVISOR_PERIOD_US);
    let mut scans = 0u32;
    loop {
        ticker.next().await;
        let tick = part.run(&mut Shared, adc, watchdog, clock.now_us());
        let out = tick.out;
        for f in out.newly_set.iter() {
            let s = f.reaction();
            defmt::error!(
                "fault: {=str} -> valves closed {}, cam parked {}, wastegate open {}, pump off {}",
                f.name(),
                s.ehvva_closed,
                s.evvt_parked,
                s.vacuum_spring_open,
                s.pump_off
            );
        }
        for f in out.newly_cleared.iter() {
            defmt::info!("fault cleared: {=str}", f.name());
        }
        scans = scans.wrapping_add(1);
        if scans.is_multiple_of(100) {
            let m = out.measurements;
            defmt::info!(
                "{=f32} V, Ph {=f32} MPa, oil {=f32} C, tank {=f32} kPa, ECU {=f32} C, faults {=u32:#x}",
                m.u_batt_v,
                m.p_supply_mpa,
                m.temp_oil_c,
                m.p_tank_kpa,
                m.temp_ecu_c,
                out.active.0
            );
        }
    }
}
