//! The task loops, written against the board traits only: read the board, call the
//! model-core step, write the outputs. The `#[embassy_executor::task]` wrappers in `main.rs`
//! bind them to the ECU board's types (embassy tasks cannot be generic).

use core::sync::atomic::Ordering;

use embassy_futures::yield_now;
use embassy_time::{Duration, Ticker};
use model_core::ecu::board::{AnalogIn, Clock, PwmOut, SolenoidDriver, SwitchOut};
use model_core::ecu::ehvva_task::{ActuationDelay, EhvvaStepInputs, EhvvaTask};
use model_core::ecu::evvt_task::{EvvtTask, EvvtTaskInputs};
use model_core::ecu::supervisor::{Supervisor, TaskReports, N_CHANNELS};
use model_core::ecu::vacuum_task::{VacuumTask, VacuumTaskInputs};

use crate::board::{AnalogBank, EhvvaIo};
use crate::shared;

/// EHVVA: wakes on every crank edge and at the task's next deadline (a command angle or the
/// end of the peak), so the pilot edges land within a few µs of their computed instants.
pub async fn ehvva<B: EhvvaIo, D: ActuationDelay>(io: &mut B, mut task: EhvvaTask<D>) -> ! {
    let mut wake_at_us = io.now_us();
    loop {
        io.wait_edge_or(wake_at_us).await;
        while let Some(edge) = io.next_edge() {
            task.on_edge(edge);
        }
        let m = shared::measurements();
        let inputs = EhvvaStepInputs {
            request: shared::setpoints().valve,
            p_supply_mpa: m.p_supply_mpa,
            temp_oil_c: m.temp_oil_c,
            u_batt_v: m.u_batt_v,
            force_safe: shared::safe().ehvva_closed,
        };
        let out = task.step(&inputs, io.now_us());
        io.pilot().apply(out.pilot);
        io.lift_valve().set(out.lift_valve_on);
        io.snubber_valve().set(out.snubber_switch_on);
        shared::set_engine(out.engine);
        if out.crank_lost_now {
            defmt::warn!("EHVVA: crank signal lost, pilot off");
        }
        shared::beat(shared::HB_EHVVA);
        wake_at_us = out.wake_at_us;
    }
}

/// EVVT: 100 Hz.
pub async fn evvt(
    motor: &mut impl PwmOut,
    driver_fault: impl Fn() -> bool,
    clock: impl Clock,
    mut task: EvvtTask,
) -> ! {
    let mut ticker = Ticker::every(Duration::from_millis(10));
    loop {
        ticker.next().await;
        let Some(engine) = shared::engine() else {
            motor.set_duty(0.0);
            shared::beat(shared::HB_EVVT);
            continue;
        };
        let inputs = EvvtTaskInputs {
            engine,
            setpoint_deg: shared::setpoints().cam_phase_deg,
            u_batt_v: shared::measurements().u_batt_v,
            faults: shared::faults(),
            motor_driver_fault: driver_fault(),
        };
        let out = task.step(&inputs, clock.now_us());
        motor.set_duty(out.motor_duty);
        shared::beat(shared::HB_EVVT);
    }
}

/// Vacuum valves: duty update at 80 Hz (the PWM itself runs at 300 Hz in hardware).
pub async fn vacuum(
    valves: &mut [impl PwmOut; 3],
    pump: &mut impl SwitchOut,
    clock: impl Clock,
    mut task: VacuumTask,
) -> ! {
    let mut ticker = Ticker::every(Duration::from_micros(12_500));
    loop {
        ticker.next().await;
        let m = shared::measurements();
        let inputs = VacuumTaskInputs {
            x_set_pct: shared::setpoints().vacuum_x_pct,
            x_meas_pct: m.x_pct,
            p_tank_kpa: m.p_tank_kpa,
            p_amb_kpa: m.p_amb_kpa,
            u_batt_v: m.u_batt_v,
            safe: shared::safe(),
        };
        let out = task.step(&inputs, clock.now_us());
        for (valve, duty) in valves.iter_mut().zip(out.duty) {
            valve.set_duty(duty);
        }
        pump.set(out.pump_on);
        shared::set_vacuum_report(shared::VacuumReport {
            stuck: out.stuck.iter().any(|s| *s),
            abnormal_leak: out.abnormal_leak,
        });
        shared::beat(shared::HB_VACUUM);
    }
}

/// Supervisor: 100 Hz ADC scan (one channel per yield), range checks and faults, a defmt
/// message per fault change, and the watchdog: petted only while every task is alive.
pub async fn supervisor(
    adc: &mut impl AnalogBank,
    mut pet_watchdog: impl FnMut(),
    clock: impl Clock,
    mut sup: Supervisor,
) -> ! {
    let mut ticker = Ticker::every(Duration::from_millis(10));
    let mut last_beats = [0u32; 3];
    let mut scans = 0u32;
    loop {
        ticker.next().await;
        let mut counts = [0u16; N_CHANNELS];
        for (k, c) in counts.iter_mut().enumerate() {
            *c = adc.analog(k).read_counts();
            yield_now().await;
        }
        let engine = shared::engine();
        let vacuum = shared::vacuum_report();
        let reports = TaskReports {
            crank_lost: engine.is_some_and(|e| e.crank_lost),
            cam_lost: engine.is_some_and(|e| e.cam_lost),
            vacuum_stuck: vacuum.stuck,
            abnormal_leak: vacuum.abnormal_leak,
        };
        let out = sup.step(&counts, &reports, clock.now_us());
        shared::set_measurements(out.measurements);
        shared::set_faults(out.active);
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
        // Every 50 ms: all three tasks must have run since the last check.
        scans = scans.wrapping_add(1);
        if scans.is_multiple_of(5) {
            let beats = shared::HEARTBEATS.each_ref().map(|h| h.load(Ordering::Relaxed));
            if beats.iter().zip(last_beats.iter()).all(|(now, then)| now != then) {
                pet_watchdog();
            }
            last_beats = beats;
        }
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
