//! The instruction-count bench (started with the semihosting argument `bench`).
//!
//! Each counted piece of work runs between a call to one of the `pil_begin_*` marker
//! functions and a call to `pil_end`; the host's TCG plugin (tools/qemu-plugin) counts the
//! instructions executed in between, leaving out the markers' own bodies, and writes one
//! line per interval: the label (the marker's name after `pil_begin_`) and the count. The
//! marker bodies differ (each stores its own number), so the linker cannot merge them, and
//! interrupts are masked while an interval is open, so no handler is counted.
//!
//! 1. Plants: [`PlantBench`] in f32 and in Q16.16 (the fixed-point type for FPU-less ECUs),
//!    `COUNTED_STEPS` counted steps of each model, then the final states as raw bits in a
//!    [`PLANT_REPORT_MAGIC`] record on the link. (Q32.32 is left out: its bench is 22 KB and
//!    the copies its construction makes overflow the stack into the statics.)
//! 2. Tasks: the lockstep link is served as usual, with every task of every step counted
//!    (`supervisor`, `ehvva`, `evvt`, `vacuum`) and the whole `EcuCore::step` (`core_step`,
//!    which includes the inner markers' call instructions).
use core::sync::atomic::{compiler_fence, AtomicU32, Ordering};

use model_core::ecu::frame::{crc16, ActuatorFrame, SensorFrame};
use model_core::ecu::lockstep::{EcuCore, StepPart};
use model_core::plant_bench::{PlantBench, COUNTED_STEPS, N_STATE};
use model_core::{Real, Q16};

use crate::board::Link;

/// Start of the plant-state record: `magic (2) | words u8 | words × u64 LE | CRC-16 LE`.
pub const PLANT_REPORT_MAGIC: [u8; 2] = [0x50, 0xB7];

/// The last marker passed (each marker's body: its own volatile store).
static MARK: AtomicU32 = AtomicU32::new(0);

macro_rules! markers {
    ($($name:ident = $id:expr),* $(,)?) => {$(
        #[no_mangle]
        #[inline(never)]
        pub extern "C" fn $name() {
            // Volatile: a plain store to a never-read static is optimised away, and the
            // then identical empty bodies are folded into one function by the linker.
            // SAFETY: an aligned word of a static; only markers write it, nothing reads it.
            unsafe { MARK.as_ptr().write_volatile($id) };
        }
    )*};
}

markers! {
    pil_begin_empty = 1,
    pil_begin_core_step = 2,
    pil_begin_supervisor = 3,
    pil_begin_ehvva = 4,
    pil_begin_evvt = 5,
    pil_begin_vacuum = 6,
    pil_begin_ehvva_plant_f32 = 7,
    pil_begin_evvt_plant_f32 = 9,
    pil_begin_vacuum_plant_f32 = 11,
    pil_begin_ehvva_lpv_plant_f32 = 13,
    pil_begin_positioner_plant_f32 = 15,
    pil_begin_ehvva_plant_fixed = 17,
    pil_begin_ehvva_lpv_plant_fixed = 18,
    pil_begin_evvt_plant_fixed = 19,
    pil_begin_vacuum_plant_fixed = 20,
    pil_begin_positioner_plant_fixed = 21,
    pil_end = 0xE0D,
}

/// `work` between `begin` and `pil_end`, interrupts masked.
#[inline(always)]
fn counted<T>(begin: extern "C" fn(), work: impl FnOnce() -> T) -> T {
    cortex_m::interrupt::free(|_| {
        begin();
        compiler_fence(Ordering::SeqCst);
        let out = core::hint::black_box(work());
        compiler_fence(Ordering::SeqCst);
        pil_end();
        out
    })
}

/// The begin markers of one number type's plant steps.
struct PlantMarkers {
    ehvva: extern "C" fn(),
    ehvva_lpv: extern "C" fn(),
    evvt: extern "C" fn(),
    vacuum: extern "C" fn(),
    positioner: extern "C" fn(),
}

/// The plant steps of one number type, counted; their final states. Not inlined: the two
/// benches (11 KB each, plus the copies `new` makes) then use the stack one after the other.
#[inline(never)]
fn plants<R: Real>(m: PlantMarkers) -> Result<[R; N_STATE], &'static str> {
    let mut b = PlantBench::<R>::new()?;
    // The order the host repeats natively (hil-host pil.rs, `plant_bench_native`); the next
    // engine speed is converted outside the counted EVVT step.
    for _ in 0..COUNTED_STEPS {
        let b = core::hint::black_box(&mut b);
        counted(m.ehvva, || b.step_ehvva());
        counted(m.ehvva_lpv, || b.step_ehvva_lpv());
        // black_box: without it the compiler moved the speed's soft-float conversion (about
        // 300 instructions in Q16.16) past the begin marker, into the counted step.
        let rpm = core::hint::black_box(b.next_engine_rpm());
        counted(m.evvt, || b.step_evvt(rpm));
        counted(m.vacuum, || b.step_vacuum());
        counted(m.positioner, || b.step_positioner());
    }
    Ok(b.state())
}

/// Runs the plant bench and sends its record (f32, then Q16.16 states); an empty interval
/// first (the host subtracts its count, the call instruction of `pil_end`, from every
/// interval).
pub fn run_plants(link: &mut Link) -> Result<(), &'static str> {
    for _ in 0..4 {
        counted(pil_begin_empty, || ());
    }
    let f = plants::<f32>(PlantMarkers {
        ehvva: pil_begin_ehvva_plant_f32,
        ehvva_lpv: pil_begin_ehvva_lpv_plant_f32,
        evvt: pil_begin_evvt_plant_f32,
        vacuum: pil_begin_vacuum_plant_f32,
        positioner: pil_begin_positioner_plant_f32,
    })?;
    let x = plants::<Q16>(PlantMarkers {
        ehvva: pil_begin_ehvva_plant_fixed,
        ehvva_lpv: pil_begin_ehvva_lpv_plant_fixed,
        evvt: pil_begin_evvt_plant_fixed,
        vacuum: pil_begin_vacuum_plant_fixed,
        positioner: pil_begin_positioner_plant_fixed,
    })?;
    let mut words = [0u64; 2 * N_STATE];
    for k in 0..N_STATE {
        words[k] = u64::from(f[k].to_bits());
        words[N_STATE + k] = x[k].to_bits() as u64;
    }
    let mut record = [0u8; 3 + 8 * 2 * N_STATE + 2];
    record[..2].copy_from_slice(&PLANT_REPORT_MAGIC);
    record[2] = words.len() as u8;
    for (k, w) in words.iter().enumerate() {
        record[3 + 8 * k..11 + 8 * k].copy_from_slice(&w.to_le_bytes());
    }
    let end = record.len() - 2;
    let crc = crc16(&record[2..end]);
    record[end..].copy_from_slice(&crc.to_le_bytes());
    link.write(&record);
    Ok(())
}

/// `EcuCore::step` with every task counted and the whole step counted around them.
pub fn counted_step(core: &mut EcuCore, s: &SensorFrame) -> ActuatorFrame {
    counted(pil_begin_core_step, || {
        core.step_probed(s, |part, begin| {
            if begin {
                match part {
                    StepPart::Supervisor => pil_begin_supervisor(),
                    StepPart::Ehvva => pil_begin_ehvva(),
                    StepPart::Evvt => pil_begin_evvt(),
                    StepPart::Vacuum => pil_begin_vacuum(),
                }
            } else {
                pil_end();
            }
        })
    })
}
