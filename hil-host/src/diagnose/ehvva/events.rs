//! The events of an EHVVA log and their simulation: the log cut at each rising pilot command,
//! each event simulated from rest by model-core's reduced model (the module doc of
//! [`super`]).

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};

use model_core::ehvva::reduced::MAX_SUBSTEP_MS;
use model_core::ehvva::{EhvvaInputs, EhvvaParams, EhvvaPlant, EhvvaReduced};

use crate::log::Log;

/// Rest kept before each rising command edge (the segment start), ms.
pub const PRE_MS: f64 = 1.0;
/// The fits use at most this many estimation events (chosen by [`Events::for_fitting`]); the
/// validation data are always predicted whole. Ten or so parameters are well determined by a
/// few dozen events that cover every test condition, while the cost of each fit grows with
/// the events: a long bench record (hundreds of events of a repeated test matrix) adds time,
/// not information.
pub const MAX_FIT_EVENTS: usize = 64;

/// [`Event::held_short_of_stroke`]: how long before the command's falling edge the valve must
/// have stood, and how far below its stroke (a valve at its stop reads within a few hundredths
/// of a millimetre of it).
pub const HELD_WINDOW_MS: f64 = 2.0;
pub const HELD_SHORT_MM: f64 = 0.15;

/// Delay-line length of the simulated model: 2048 samples hold 20 ms even at a 0.01 ms step,
/// 102 ms at a 20 kHz log's 0.05 ms. A fit's trial may ask for far longer delays than a
/// unit has (a large direction-delay gain); 1024 samples refused one fit's 51.1 ms at 20 kHz,
/// and the model then failed where it was simulated outside the solver (session 27:
/// `calibrate` of generated pressure-delay unit 35 ended with `DelayLineTooShort`).
const DELAY_SAMPLES: usize = 2048;

/// One valve event of a log: the samples from rest before a pilot command to the next event.
#[derive(Clone, Debug)]
pub struct Event {
    /// Index of the first sample in the log.
    pub start: usize,
    pub u_pilot: Vec<bool>,
    /// Measured lift.
    pub lift_mm: Vec<f64>,
    /// The operating point (set-points, temperature, valve states).
    pub inputs: EhvvaInputs<f64>,
    /// Index (in the event) of the rising command edge and of the last falling one.
    pub on_index: usize,
    pub off_index: Option<usize>,
    /// Standard errors of the set-points in `inputs` (supply, back pressure), MPa: each is the
    /// mean of the rest samples before the command, so it carries their scatter over √n (or,
    /// where the rest samples do not scatter, the quantization error q/√12 of their column).
    pub setpoint_se_mpa: (f64, f64),
}

impl Event {
    pub fn stroke_mm(&self, p: &EhvvaParams) -> f64 {
        p.stroke_mm(self.inputs.lift_high)
    }

    /// Whether the measured valve is held open short of its stroke `stroke_mm` at the end of
    /// the command: over the last [`HELD_WINDOW_MS`] before the falling edge its lift (a
    /// quarter-millisecond mean at each end, so the sensor noise does not decide) stays
    /// between a tenth of the stroke and [`HELD_SHORT_MM`] below it, moving by less than 5 % of
    /// the stroke. That is the force balance of the spring against the pressures (a low supply,
    /// a high back pressure, a weak spring): a valve still opening moves faster than that
    /// while driven, one whose command ended before it moved is below a tenth.
    pub fn held_short_of_stroke(&self, stroke_mm: f64, dt_ms: f64) -> bool {
        let Some(off) = self.off_index else {
            return false;
        };
        let window = ((HELD_WINDOW_MS / dt_ms).round() as usize).max(2);
        let avg = ((0.25 / dt_ms).round() as usize).clamp(1, window / 2);
        if off < self.on_index + window {
            return false;
        }
        let mean = |r: std::ops::Range<usize>| self.lift_mm[r.clone()].iter().sum::<f64>() / r.len() as f64;
        let end = mean(off - avg..off);
        let begin = mean(off - window..off - window + avg);
        end > 0.1 * stroke_mm && end < stroke_mm - HELD_SHORT_MM && (end - begin).abs() < 0.05 * stroke_mm
    }
}

/// A log cut into valve events.
#[derive(Clone, Debug)]
pub struct Events {
    pub dt_ms: f64,
    pub events: Vec<Event>,
    /// Samples in the log (the events cover it from the first one's start).
    pub samples: usize,
    pub file: String,
    /// The model's longest sub-step in these events' simulations, ms:
    /// [`MAX_SUBSTEP_MS`](model_core::ehvva::reduced::MAX_SUBSTEP_MS) (the model's accuracy),
    /// or [`COARSE_SUBSTEP_MS`] for a fit's first approach ([`Events::coarse`]).
    pub max_substep_ms: f64,
}

/// The sub-step of a fit's first approach ([`Events::coarse`]): five times the model's, so
/// a 20 kHz sample takes two sub-steps instead of ten.
pub const COARSE_SUBSTEP_MS: f64 = 0.025;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

impl Events {
    pub fn from_log(log: &Log) -> Result<Self, String> {
        let col = |name: &str| log.col(name).ok_or_else(|| format!("{}: no `{name}` column", log.file));
        let (u, ph, pl, temp, high, snub, lift) = (
            col("u_pilot")?,
            col("p_supply_MPa")?,
            col("p_back_MPa")?,
            col("temp_C")?,
            col("lift_high")?,
            col("snubber_on")?,
            col("lift_mm")?,
        );
        let dt_ms = log.dt_s * 1e3;
        if !(dt_ms > 0.0 && dt_ms <= 0.1) {
            return Err(format!(
                "{}: sample period {} ms; the EHVVA models need 0.1 ms or less (10 kHz or more)",
                log.file, dt_ms
            ));
        }
        let n = lift.len();
        let pre = ((PRE_MS / dt_ms).round() as usize).max(1);
        // The columns' quantization steps, found (by sorting the column) only if some rest
        // window does not scatter.
        let (q_supply, q_back) = (std::cell::OnceCell::new(), std::cell::OnceCell::new());
        // A command already on at the first sample began before the log: not an edge.
        let rising: Vec<usize> = (1..n).filter(|&k| u[k] > 0.5 && u[k - 1] <= 0.5).collect();
        if rising.is_empty() {
            return Err(format!("{}: no valve event (u_pilot never rises)", log.file));
        }
        let skip = unsettled_prefix(u, lift, rising[0], pre);
        let mut starts: Vec<usize> = Vec::with_capacity(rising.len());
        for (i, &r) in rising.iter().enumerate() {
            let s = if i == 0 {
                skip
            } else {
                r.saturating_sub(pre).max(starts[i - 1] + 1)
            };
            starts.push(s);
        }
        let mut events = Vec::with_capacity(rising.len());
        for i in 0..rising.len() {
            let (s, e) = (starts[i], if i + 1 < starts.len() { starts[i + 1] } else { n });
            let on = rising[i] - s;
            // Set-points: the samples at rest before the edge (at most PRE_MS of them).
            let rest = rising[i].saturating_sub(pre).max(s)..rising[i];
            // The mean, not the median: the median of quantized samples is itself on the
            // quantizer's grid (±½ LSB), the mean of noisy ones resolves below it.
            let setpoint = |x: &[f64]| {
                if rest.len() >= 3 {
                    x[rest.clone()].iter().sum::<f64>() / rest.len() as f64
                } else {
                    let mut v: Vec<f64> = x[s..e].to_vec();
                    median(&mut v)
                }
            };
            let setpoint_se = |x: &[f64], q: &std::cell::OnceCell<f64>| {
                let v = &x[rest.clone()];
                let quantization = || *q.get_or_init(|| crate::diagnose::resolution(x)) / 12f64.sqrt();
                if v.len() < 3 {
                    return quantization();
                }
                let m = v.iter().sum::<f64>() / v.len() as f64;
                let var = v.iter().map(|y| (y - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
                if var > 0.0 {
                    (var / v.len() as f64).sqrt()
                } else {
                    quantization()
                }
            };
            let off_index = (s + on + 1..e)
                .rev()
                .find(|&k| u[k] <= 0.5 && u[k - 1] > 0.5)
                .map(|k| k - s);
            let inputs = EhvvaInputs {
                p_supply_mpa: setpoint(ph),
                p_back_mpa: setpoint(pl),
                temp_c: temp[s..e].iter().sum::<f64>() / (e - s) as f64,
                lift_high: high[rising[i]] > 0.5,
                snubber_on: snub[rising[i]] > 0.5,
            };
            events.push(Event {
                start: s,
                u_pilot: u[s..e].iter().map(|&v| v > 0.5).collect(),
                lift_mm: lift[s..e].to_vec(),
                inputs,
                on_index: on,
                off_index,
                setpoint_se_mpa: (setpoint_se(ph, &q_supply), setpoint_se(pl, &q_back)),
            });
        }
        Ok(Events {
            dt_ms,
            events,
            samples: n,
            file: log.file.clone(),
            max_substep_ms: MAX_SUBSTEP_MS,
        })
    }

    /// The same events simulated with the sub-step of a fit's first approach
    /// ([`COARSE_SUBSTEP_MS`]).
    pub fn coarse(&self) -> Events {
        Events {
            max_substep_ms: COARSE_SUBSTEP_MS,
            ..self.clone()
        }
    }

    /// Samples before the first event: the log began while the valve was still moving (e.g. a
    /// held-out tail cut from a longer record), a state the model cannot start from.
    pub fn skipped(&self) -> usize {
        self.events.first().map_or(0, |e| e.start)
    }

    /// The measured lift over the whole log (what `simulate_all` predicts).
    pub fn measured(&self) -> Vec<f64> {
        let mut y = vec![0.0; self.samples];
        for ev in &self.events {
            y[ev.start..ev.start + ev.lift_mm.len()].copy_from_slice(&ev.lift_mm);
        }
        y
    }

    /// Total samples covered by the events.
    pub fn covered(&self) -> usize {
        self.events.iter().map(|e| e.lift_mm.len()).sum()
    }

    /// A subset of the events (e.g. one test condition), keeping the period.
    pub fn subset(&self, keep: impl Fn(&Event) -> bool) -> Events {
        let events: Vec<Event> = self.events.iter().filter(|e| keep(e)).cloned().collect();
        let mut at = 0;
        let events = events
            .into_iter()
            .map(|mut e| {
                e.start = at;
                at += e.lift_mm.len();
                e
            })
            .collect();
        Events {
            dt_ms: self.dt_ms,
            events,
            samples: at,
            file: self.file.clone(),
            max_substep_ms: self.max_substep_ms,
        }
    }

    /// At most `max_events` of the events for a fit, the operating conditions represented.
    /// Conditions are nested: lift and snubber states, then temperature (to 10 °C), supply
    /// pressure (to 0.5 MPa) and back pressure (to 0.5 MPa). Each place goes to the event whose
    /// condition is least represented so far, coarsest level first (so every lift/snubber
    /// combination, then every temperature within it, is covered before finer differences),
    /// ties to the event farthest in the record from those already chosen (so a drift over a
    /// long run is sampled too). All events when there are not more.
    pub fn for_fitting(&self, max_events: usize) -> Events {
        if self.events.len() <= max_events {
            return self.clone();
        }
        let keep = self.fitting_choice(max_events);
        let starts: std::collections::HashSet<usize> = (0..self.events.len())
            .filter(|&k| keep[k])
            .map(|k| self.events[k].start)
            .collect();
        self.subset(|e| starts.contains(&e.start))
    }

    /// Which events [`Events::for_fitting`] keeps (a flag per event).
    pub(super) fn fitting_choice(&self, max_events: usize) -> Vec<bool> {
        let levels = |e: &Event| -> [[i64; 5]; 4] {
            let i = &e.inputs;
            let full = [
                i.lift_high as i64,
                i.snubber_on as i64,
                (i.temp_c / 10.0).round() as i64,
                (i.p_supply_mpa / 0.5).round() as i64,
                (i.p_back_mpa / 0.5).round() as i64,
            ];
            // Level l keeps the first 2 + l entries; the rest is masked.
            core::array::from_fn(|l| core::array::from_fn(|k| if k < 2 + l { full[k] } else { i64::MIN }))
        };
        let keys: Vec<[[i64; 5]; 4]> = self.events.iter().map(levels).collect();
        let mut counts: std::collections::HashMap<[i64; 5], usize> = std::collections::HashMap::new();
        let mut keep = vec![false; self.events.len()];
        let mut chosen: Vec<usize> = Vec::with_capacity(max_events);
        for _ in 0..max_events {
            let score = |k: usize| {
                let represented: [usize; 4] = core::array::from_fn(|l| counts.get(&keys[k][l]).copied().unwrap_or(0));
                let gap = chosen.iter().map(|&c| c.abs_diff(k)).min().unwrap_or(usize::MAX);
                (represented, std::cmp::Reverse(gap))
            };
            let Some(best) = (0..self.events.len()).filter(|&k| !keep[k]).min_by_key(|&k| score(k)) else {
                break;
            };
            keep[best] = true;
            chosen.push(best);
            for key in &keys[best] {
                *counts.entry(*key).or_insert(0) += 1;
            }
        }
        keep
    }

    pub(super) fn key(&self) -> u64 {
        let mut h = DefaultHasher::new();
        self.samples.hash(&mut h);
        self.dt_ms.to_bits().hash(&mut h);
        for e in &self.events {
            e.start.hash(&mut h);
            for v in &e.lift_mm {
                v.to_bits().hash(&mut h);
            }
        }
        h.finish()
    }
}

/// Lift band about the rest level inside which the valve counts as at rest, mm (a seated
/// valve's lift is sensor noise, σ ≤ 6 µm).
const REST_BAND_MM: f64 = 0.05;

/// How many leading samples precede the valve's rest before the first command edge `first_on`:
/// a log cut out of a longer record may begin with a command on or the valve still closing.
/// Those samples are left out of every event (0 when the log begins at rest). The rest level is
/// the mean lift over the `pre` samples before the edge.
fn unsettled_prefix(u: &[f64], lift: &[f64], first_on: usize, pre: usize) -> usize {
    let rest = first_on.saturating_sub(pre)..first_on;
    if rest.is_empty() {
        return 0;
    }
    let level = lift[rest.clone()].iter().sum::<f64>() / rest.len() as f64;
    (0..first_on)
        .rev()
        .find(|&k| u[k] > 0.5 || (lift[k] - level).abs() > REST_BAND_MM)
        .map_or(0, |k| k + 1)
}

/// Simulates one event from rest with model-core's reduced model, writing the lift into `out`
/// (same length as the event). The model runs from the event's first sample, its rest window
/// included: where the spring cannot hold the valve on its seat against the back pressure
/// ((At − Ab)·Pl > ks·ds) the valve leaves the seat before the command, as on the bench.
pub fn simulate_event(params: &EhvvaParams, ev: &Event, dt_ms: f64, out: &mut [f64]) -> Result<(), String> {
    simulate_events(params, core::slice::from_ref(ev), dt_ms, MAX_SUBSTEP_MS, ev.start, out)
}

/// How many events [`simulate_events`] steps side by side.
const LANES: usize = 4;

/// One event's simulation in progress: the model and when its valve has settled on the seat.
struct Lane<'a> {
    ev: &'a Event,
    model: EhvvaReduced<f64, DELAY_SAMPLES>,
    seated_for: usize,
}

impl<'a> Lane<'a> {
    fn new(params: &EhvvaParams, ev: &'a Event, dt_ms: f64, max_substep_ms: f64) -> Result<Self, String> {
        Ok(Self {
            ev,
            model: EhvvaReduced::with_max_substep(params, &ev.inputs, dt_ms, max_substep_ms)
                .map_err(|e| format!("{e:?}"))?,
            seated_for: 0,
        })
    }

    /// The lane on `ev`, its model back at rest for `ev`'s operating point: the same numbers
    /// as a new lane's, without building the unit's tables again.
    fn start(&mut self, ev: &'a Event) {
        self.ev = ev;
        self.model.rest_at(&ev.inputs);
        self.seated_for = 0;
    }

    /// The lift at the event's sample `k`. Once the valve has sat on its seat for `settle`
    /// samples after the command's end, it stays there: 0 without stepping the model.
    fn sample(&mut self, k: usize, settle: usize) -> Result<f64, String> {
        if self.seated_for >= settle {
            return Ok(0.0);
        }
        let y = self.model.step(self.ev.u_pilot[k], &self.ev.inputs);
        if !y.is_finite() {
            return Err(format!("simulation diverged at sample {}", self.ev.start + k));
        }
        let last_off = self.ev.off_index.unwrap_or(usize::MAX);
        self.seated_for = if k > last_off && y == 0.0 && self.model.velocity_m_s() == 0.0 {
            self.seated_for + 1
        } else {
            0
        };
        Ok(y)
    }
}

/// Simulates `events` (in order of their start) into `out`, which holds the log's samples
/// from `base` on, [`LANES`] events at a time stepped in turn sample by sample. Each event's
/// arithmetic is its own, so the numbers are those of one event after the other; but the
/// lanes' recurrences are independent, and the processor overlaps one lane's division (on its
/// recurrence's critical path, where a lone event waits for it) with the others' work.
fn simulate_events(
    params: &EhvvaParams,
    events: &[Event],
    dt_ms: f64,
    max_substep_ms: f64,
    base: usize,
    out: &mut [f64],
) -> Result<(), String> {
    let settle = ((2.0 / dt_ms).round() as usize).max(1);
    let (mut rest, mut rest_from) = (out, base);
    // Each lane's model is built once (a move of some 10 kB and the unit's tables) and put
    // back at rest for each next event.
    let mut lanes: Vec<Lane> = Vec::with_capacity(LANES);
    for group in events.chunks(LANES) {
        let mut outs: Vec<&mut [f64]> = Vec::with_capacity(LANES);
        for (i, ev) in group.iter().enumerate() {
            match lanes.get_mut(i) {
                Some(lane) => lane.start(ev),
                None => lanes.push(Lane::new(params, ev, dt_ms, max_substep_ms)?),
            }
            let gap = ev
                .start
                .checked_sub(rest_from)
                .ok_or("events out of order or overlapping")?;
            let (_, from_start) = std::mem::take(&mut rest).split_at_mut(gap);
            let (o, more) = from_start.split_at_mut(ev.lift_mm.len());
            outs.push(o);
            (rest, rest_from) = (more, ev.start + ev.lift_mm.len());
        }
        let longest = outs.iter().map(|o| o.len()).max().unwrap_or(0);
        for k in 0..longest {
            // zip stops at the group's events: a last group may use fewer lanes.
            for (lane, o) in lanes.iter_mut().zip(outs.iter_mut()) {
                if k < o.len() {
                    o[k] = lane.sample(k, settle)?;
                }
            }
        }
    }
    Ok(())
}

/// Simulates every event into `out` (the log's length); the samples before the first event
/// ([`Events::skipped`]) are set to 0, as [`Events::measured`] has them.
pub fn simulate_all(params: &EhvvaParams, set: &Events, out: &mut [f64]) -> Result<(), String> {
    out[..set.skipped()].fill(0.0);
    simulate_events(params, &set.events, set.dt_ms, set.max_substep_ms, 0, out)
}

/// As [`simulate_all`], with the events shared among `threads` runs on rayon's pool: they
/// are independent (each from rest), so the result is the same as on one; the events go in
/// contiguous runs of about equal sample counts. The pool's threads are started once and
/// stay on their cores: a diagnosis simulates thousands of times for a few ms each, and
/// threads started per simulation cost it a tenth of a second of wall time.
pub fn simulate_all_on(params: &EhvvaParams, set: &Events, out: &mut [f64], threads: usize) -> Result<(), String> {
    let threads = threads.clamp(1, set.events.len().max(1));
    if threads == 1 {
        return simulate_all(params, set, out);
    }
    let skip = set.skipped();
    out[..skip].fill(0.0);
    let per_thread = set.covered().div_ceil(threads);
    // Runs of events: (events, their output slice).
    let mut runs: Vec<(&[Event], &mut [f64])> = Vec::with_capacity(threads);
    let (mut rest_events, mut rest_out) = (&set.events[..], &mut out[skip..]);
    while !rest_events.is_empty() {
        let (mut count, mut len) = (0, 0);
        while count < rest_events.len() && (len < per_thread || runs.len() + 1 == threads) {
            len += rest_events[count].lift_mm.len();
            count += 1;
        }
        let (ev, more_ev) = rest_events.split_at(count);
        let (o, more_o) = std::mem::take(&mut rest_out).split_at_mut(len);
        runs.push((ev, o));
        (rest_events, rest_out) = (more_ev, more_o);
    }
    use rayon::prelude::*;
    runs.into_par_iter()
        .try_for_each(|(events, o)| simulate_events(params, events, set.dt_ms, set.max_substep_ms, events[0].start, o))
}
