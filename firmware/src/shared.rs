//! What the tasks share: the composition's [`EcuShared`] (measurements, faults, safe state,
//! engine view, the vacuum part's reports, heartbeats) in one cell behind a critical-section
//! mutex, and the set-points. A part copies the cell in and out under the lock (about 130
//! bytes, well under a microsecond), never while it computes, so the EHVVA task on the
//! interrupt executor is never held up by a slower task's step.

use core::cell::Cell;

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use model_core::ecu::ehvva_task::ValveRequest;
use model_core::ecu::schedule::{EcuShared, Setpoints, SharedAccess};

/// What the engine management asks for (until a bus interface writes these: fixed values).
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

static SHARED: Mutex<CriticalSectionRawMutex, Cell<EcuShared>> = Mutex::new(Cell::new(EcuShared::BOOT));
static SETPOINTS: Mutex<CriticalSectionRawMutex, Cell<Setpoints>> = Mutex::new(Cell::new(DEFAULT_SETPOINTS));

/// The parts' access to the shared cell.
pub struct Shared;

impl SharedAccess for Shared {
    fn with<R>(&mut self, f: impl FnOnce(&mut EcuShared) -> R) -> R {
        SHARED.lock(|c| {
            let mut v = c.get();
            let r = f(&mut v);
            c.set(v);
            r
        })
    }
}

pub fn setpoints() -> Setpoints {
    SETPOINTS.lock(|c| c.get())
}
