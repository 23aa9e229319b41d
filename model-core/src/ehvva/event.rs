//! Running one valve event (open at t0, close after the dwell) on any EHVVA model and measuring
//! it as the paper does: opening and closing durations "between 1 % and 99 % of the stroke"
//! (Sec. 2, Fig. 2), the full closing time (lift back to 0), the seating velocity (Fig. 2:
//! 0.25 vs 0.69 m/s), the delay from the command edge and the lift area.

use super::params::EhvvaInputs;
use crate::real::Real;

/// What the event runner needs from a model.
pub trait EhvvaPlant<R: Real> {
    /// Advances one step of the model's fixed `dt_ms`; returns the lift in mm.
    fn step(&mut self, u_pilot: bool, inputs: &EhvvaInputs<R>) -> R;
    /// The fixed step, ms.
    fn dt_ms(&self) -> R;
    fn lift_mm(&self) -> R;
    /// Valve velocity, mm/ms = m/s (positive opening).
    fn velocity_m_s(&self) -> R;
    /// The velocity just before the last seat impact (negative), cleared on read.
    fn take_seat_velocity(&mut self) -> Option<R>;
}

/// One valve event: the pilot is on from `t_open_ms` for `dwell_ms`; the run lasts `t_end_ms`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ValveEvent {
    pub t_open_ms: f64,
    pub dwell_ms: f64,
    pub t_end_ms: f64,
}

impl ValveEvent {
    /// The paper's event for a Table 1 dwell: command at 1 ms, run until 25 ms after closing.
    pub fn with_dwell(dwell_ms: f64) -> Self {
        Self {
            t_open_ms: 1.0,
            dwell_ms,
            t_end_ms: 1.0 + dwell_ms + 25.0,
        }
    }
}

/// Measured event. Times are absolute (same clock as [`ValveEvent`]); `None` where the lift
/// never crossed the level.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EventMetrics {
    pub stroke_mm: f64,
    pub max_lift_mm: f64,
    pub t_command_on_ms: f64,
    pub t_command_off_ms: f64,
    /// Lift rises through 1 % of the stroke.
    pub t_open_1pct_ms: Option<f64>,
    /// Lift rises through 99 % of the stroke.
    pub t_open_99pct_ms: Option<f64>,
    /// Lift falls through 99 % of the stroke.
    pub t_close_99pct_ms: Option<f64>,
    /// Lift falls through 1 % of the stroke.
    pub t_close_1pct_ms: Option<f64>,
    /// The valve is seated again (lift 0).
    pub t_seated_ms: Option<f64>,
    /// Speed just before seating, m/s (positive).
    pub seating_velocity_m_s: Option<f64>,
    /// ∫ lift dt over the run, mm·ms.
    pub lift_area_mm_ms: f64,
}

impl EventMetrics {
    /// Opening duration, 1 % to 99 % of the stroke (Sec. 2).
    pub fn opening_time_ms(&self) -> Option<f64> {
        Some(self.t_open_99pct_ms? - self.t_open_1pct_ms?)
    }
    /// Closing duration, 99 % to 1 % of the stroke (Sec. 2).
    pub fn closing_time_ms(&self) -> Option<f64> {
        Some(self.t_close_1pct_ms? - self.t_close_99pct_ms?)
    }
    /// Command-off to the valve seated: the "full closing time" of Fig. 10.
    pub fn full_closing_ms(&self) -> Option<f64> {
        Some(self.t_seated_ms? - self.t_command_off_ms)
    }
    /// Command-on to 1 % lift.
    pub fn opening_delay_ms(&self) -> Option<f64> {
        Some(self.t_open_1pct_ms? - self.t_command_on_ms)
    }
    /// Command-off to 99 % lift on the way down.
    pub fn closing_delay_ms(&self) -> Option<f64> {
        Some(self.t_close_99pct_ms? - self.t_command_off_ms)
    }
}

/// Time at which the straight line from (t0, y0) to (t1, y1) crosses `level`.
fn crossing(t0: f64, y0: f64, t1: f64, y1: f64, level: f64) -> f64 {
    let dy = y1 - y0;
    if dy.abs() < 1e-15 {
        t1
    } else {
        t0 + (level - y0) / dy * (t1 - t0)
    }
}

/// Runs `event` on `plant` (which should be at rest) at the operating point `inputs`, calling
/// `on_sample(t_ms, lift_mm)` after every step, and measures it. `stroke_mm` is the nominal
/// stroke the 1 %/99 % levels refer to. Heapless: the trace goes to the callback only.
pub fn run_event<R: Real, P: EhvvaPlant<R>>(
    plant: &mut P,
    event: &ValveEvent,
    inputs: &EhvvaInputs<R>,
    stroke_mm: f64,
    mut on_sample: impl FnMut(f64, f64),
) -> EventMetrics {
    run_event_with(plant, event, |_| *inputs, stroke_mm, |t, y, _| on_sample(t, y))
}

/// Like [`run_event`] with inputs that vary with time (`inputs_at(t_ms)`, e.g. measured Ph
/// and Pl for the LPV model) and a callback that also gets the step index.
pub fn run_event_with<R: Real, P: EhvvaPlant<R>>(
    plant: &mut P,
    event: &ValveEvent,
    mut inputs_at: impl FnMut(usize) -> EhvvaInputs<R>,
    stroke_mm: f64,
    mut on_sample: impl FnMut(f64, f64, usize),
) -> EventMetrics {
    let dt = plant.dt_ms().to_f64();
    let off_ms = event.t_open_ms + event.dwell_ms;
    let lo = 0.01 * stroke_mm;
    let hi = 0.99 * stroke_mm;
    let mut m = EventMetrics {
        stroke_mm,
        t_command_on_ms: event.t_open_ms,
        t_command_off_ms: off_ms,
        ..EventMetrics::default()
    };
    let steps = if dt > 0.0 {
        libm::ceil(event.t_end_ms / dt) as usize
    } else {
        0
    };
    let mut last_t = 0.0;
    let mut last_y = plant.lift_mm().to_f64();
    let _ = plant.take_seat_velocity();
    for k in 0..steps {
        // The command is sampled at the start of the step.
        let t_start = k as f64 * dt;
        let u = t_start + 1e-9 >= event.t_open_ms && t_start + 1e-9 < off_ms;
        let inputs = inputs_at(k);
        let y = plant.step(u, &inputs).to_f64();
        let t = t_start + dt;
        let seat = plant.take_seat_velocity();
        on_sample(t, y, k);
        m.max_lift_mm = m.max_lift_mm.max(y);
        m.lift_area_mm_ms += 0.5 * (y + last_y) * dt;
        if m.t_open_1pct_ms.is_none() && t_start >= event.t_open_ms && last_y < lo && y >= lo {
            m.t_open_1pct_ms = Some(crossing(last_t, last_y, t, y, lo));
        }
        if m.t_open_1pct_ms.is_some() && m.t_open_99pct_ms.is_none() && last_y < hi && y >= hi {
            m.t_open_99pct_ms = Some(crossing(last_t, last_y, t, y, hi));
        }
        if t_start >= off_ms && m.t_open_1pct_ms.is_some() {
            if m.t_close_99pct_ms.is_none() && last_y >= hi && y < hi {
                m.t_close_99pct_ms = Some(crossing(last_t, last_y, t, y, hi));
            }
            if m.t_close_1pct_ms.is_none() && last_y >= lo && y < lo {
                m.t_close_1pct_ms = Some(crossing(last_t, last_y, t, y, lo));
            }
            if m.t_seated_ms.is_none() && y <= 0.0 {
                m.t_seated_ms = Some(t);
                m.seating_velocity_m_s = seat.map(|v| v.to_f64().abs());
            }
        }
        last_t = t;
        last_y = y;
    }
    m
}

/// A recorded event: the lift trace sampled every step and its metrics.
#[cfg(feature = "std")]
#[derive(Clone, Debug, Default)]
pub struct EventTrace {
    pub t_ms: std::vec::Vec<f64>,
    pub lift_mm: std::vec::Vec<f64>,
    pub metrics: EventMetrics,
}

/// Host helper: runs `event` and returns the trace and the metrics.
#[cfg(feature = "std")]
pub fn run_event_trace<R: Real, P: EhvvaPlant<R>>(
    plant: &mut P,
    event: &ValveEvent,
    inputs: &EhvvaInputs<R>,
    stroke_mm: f64,
) -> EventTrace {
    let mut trace = EventTrace::default();
    let metrics = run_event(plant, event, inputs, stroke_mm, |t, y| {
        trace.t_ms.push(t);
        trace.lift_mm.push(y);
    });
    trace.metrics = metrics;
    trace
}

/// Mean relative error of two lift traces, in % of the stroke: mean |a − b| over the samples
/// from the command edge to the end of the event window (`from_ms..=to_ms`) divided by the
/// stroke. This is how the tests read the paper's MRE (Table 2): mean absolute lift error
/// over the valve event relative to the lift.
pub fn mean_relative_error_pct(
    t_ms: &[f64],
    a_mm: &[f64],
    b_mm: &[f64],
    from_ms: f64,
    to_ms: f64,
    stroke_mm: f64,
) -> f64 {
    let mut sum = 0.0;
    let mut n = 0usize;
    for ((&t, &a), &b) in t_ms.iter().zip(a_mm).zip(b_mm) {
        if t >= from_ms && t <= to_ms {
            sum += (a - b).abs();
            n += 1;
        }
    }
    if n == 0 || stroke_mm <= 0.0 {
        0.0
    } else {
        100.0 * sum / (n as f64 * stroke_mm)
    }
}
