//! Latest-value cells between the tasks (copy in, copy out under a critical section: no
//! queues, no allocation), and the tasks' heartbeats for the watchdog.

use core::cell::Cell;
use core::sync::atomic::{AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use model_core::ecu::ehvva_task::{EngineSnapshot, ValveRequest};
use model_core::ecu::supervisor::{FaultSet, Measurements, SafeState};

type Shared<T> = Mutex<CriticalSectionRawMutex, Cell<T>>;

/// What the engine management asks for (until a bus interface writes these: fixed values).
#[derive(Clone, Copy)]
pub struct Setpoints {
    pub valve: ValveRequest,
    pub cam_phase_deg: f32,
    /// LPT, HPT, HPC positions.
    pub vacuum_x_pct: [f32; 3],
}

pub const DEFAULT_SETPOINTS: Setpoints = Setpoints {
    valve: ValveRequest {
        open_deg: 340.0,
        close_deg: 580.0,
        high_lift: true,
        soft_seat: true,
        enabled: true,
    },
    cam_phase_deg: 20.0,
    vacuum_x_pct: [0.0; 3],
};

/// Flags the vacuum task reports to the supervisor.
#[derive(Clone, Copy, Default)]
pub struct VacuumReport {
    pub stuck: bool,
    pub abnormal_leak: bool,
}

static SETPOINTS: Shared<Setpoints> = Mutex::new(Cell::new(DEFAULT_SETPOINTS));
static MEASUREMENTS: Shared<Option<Measurements>> = Mutex::new(Cell::new(None));
static FAULTS: Shared<FaultSet> = Mutex::new(Cell::new(FaultSet(0)));
static ENGINE: Shared<Option<EngineSnapshot>> = Mutex::new(Cell::new(None));
static VACUUM: Shared<VacuumReport> = Mutex::new(Cell::new(VacuumReport {
    stuck: false,
    abnormal_leak: false,
}));

/// Heartbeats: EHVVA, EVVT, vacuum. The supervisor pets the watchdog only while all move.
pub static HEARTBEATS: [AtomicU32; 3] = [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)];
pub const HB_EHVVA: usize = 0;
pub const HB_EVVT: usize = 1;
pub const HB_VACUUM: usize = 2;

pub fn beat(task: usize) {
    if let Some(h) = HEARTBEATS.get(task) {
        h.fetch_add(1, Ordering::Relaxed);
    }
}

pub fn setpoints() -> Setpoints {
    SETPOINTS.lock(|c| c.get())
}

/// Until the supervisor's first scan, the defaults (and its faults start empty, but every
/// task also starts in its safe state until the engine turns).
pub fn measurements() -> Measurements {
    MEASUREMENTS.lock(|c| c.get()).unwrap_or_default()
}
pub fn set_measurements(m: Measurements) {
    MEASUREMENTS.lock(|c| c.set(Some(m)));
}

pub fn faults() -> FaultSet {
    FAULTS.lock(|c| c.get())
}
pub fn safe() -> SafeState {
    faults().safe_state()
}
pub fn set_faults(f: FaultSet) {
    FAULTS.lock(|c| c.set(f));
}

pub fn engine() -> Option<EngineSnapshot> {
    ENGINE.lock(|c| c.get())
}
pub fn set_engine(e: EngineSnapshot) {
    ENGINE.lock(|c| c.set(Some(e)));
}

pub fn vacuum_report() -> VacuumReport {
    VACUUM.lock(|c| c.get())
}
pub fn set_vacuum_report(r: VacuumReport) {
    VACUUM.lock(|c| c.set(r));
}
