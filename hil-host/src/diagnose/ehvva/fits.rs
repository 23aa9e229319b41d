//! The calibration problem of eqs. (16)-(20) and its restarts: the knobs fitted on the lift
//! simulation error of a set of events, restarted where the trust region collapsed in a curved
//! valley or where τp ended in the pilot-lag valley; and the edge delays that place td's start.

use model_core::ehvva::EhvvaParams;

use super::{
    apply_knobs, lift_scale_per_c, reference_values, scale_lift_with_temperature, simulate_all_on, Events, Knob,
    BASELINE_KNOBS,
};
use crate::lsq::{solve, LsqOptions, LsqResult, StopReason};

/// Fits `knobs` (starting at `x0`) on the lift simulation error of `set` by the trust-region
/// solver: the calibration problem of eqs. (16)-(20), in two stages. The approach runs on the
/// model with five times its sub-step ([`Events::coarse`]: a fifth of the sub-steps, a third
/// of the time) while its steps lower the cost by at least [`APPROACH_COST_TOLERANCE`]; the
/// fit then goes on from there on the model as it is, and ends where that one stops (same
/// solver, same tolerances). A start far from the optimum (an effect switched in at the
/// paper's gain) spends most of its iterations on the way, at a third of the cost; the slow
/// end of a fit, where the coarse model's own optimum would lead it astray, is left to the
/// model. A first stage that fails (its model diverging from the start) leaves the whole fit
/// to the second.
pub fn calibrate(
    base: &EhvvaParams,
    knobs: &[Knob],
    x0: &[f64],
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    let approach = approach(base, knobs, x0, set, opts);
    finish(base, knobs, x0, approach, set, opts)
}

/// [`calibrate`]'s first stage: the approach on the coarse model (no intervals at its end).
fn approach(
    base: &EhvvaParams,
    knobs: &[Knob],
    x0: &[f64],
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    let approach_opts = LsqOptions {
        cost_tolerance: APPROACH_COST_TOLERANCE,
        // Only the approach's end is used: no Jacobian there for intervals.
        intervals: false,
        ..opts.clone()
    };
    calibrate_with(base, knobs, x0, &set.coarse(), &approach_opts, &|_| Ok(()))
}

/// [`calibrate`]'s second stage: on the model as it is from the approach's end (from `x0`
/// where the approach failed), the counts of both stages summed.
fn finish(
    base: &EhvvaParams,
    knobs: &[Knob],
    x0: &[f64],
    approach: Result<LsqResult, String>,
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    let start = approach.as_ref().map_or(x0, |a| &a.x[..]);
    let r = calibrate_with(base, knobs, start, set, opts, &|_| Ok(()))?;
    Ok(match approach {
        Ok(a) => LsqResult {
            iterations: a.iterations + r.iterations,
            evaluations: a.evaluations + r.evaluations,
            ..r
        },
        Err(_) => r,
    })
}

/// Two approaches whose costs differ by less than this (relative) are taken to have ended in
/// the same valley, where the fit from the second would repeat the first's (on a clean unit's
/// log the two starts of each extension end their approaches 1e-6 to 1e-5 apart and their
/// fits at the same optimum, a fifth of the diagnosis's simulations). Ten times finer than
/// the approach's own stop ([`APPROACH_COST_TOLERANCE`]), so two valleys that differ by what
/// the approach resolves are both followed.
const SAME_APPROACH_END: f64 = 1e-4;

/// The approaches to follow, by index into `costs` (their ends' costs), lowest cost first:
/// each but those within [`SAME_APPROACH_END`] of one already chosen. An approach that failed
/// (cost infinite) is always followed (from its start).
fn ends_to_follow(costs: &[f64]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..costs.len()).collect();
    order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
    let mut chosen: Vec<usize> = Vec::new();
    for i in order {
        let c = costs[i];
        let same = c.is_finite()
            && chosen
                .iter()
                .any(|&j| (c - costs[j]).abs() <= SAME_APPROACH_END * costs[j].abs());
        if !same {
            chosen.push(i);
        }
    }
    chosen
}

/// The best of [`calibrate_restarted`] from each of `starts`, each start's approach run
/// first and the fits then followed from the approaches' ends in the order of their costs,
/// skipping an end within [`SAME_APPROACH_END`] of one already followed. The counts are
/// those of the kept fit.
pub(super) fn calibrate_best_of(
    base: &EhvvaParams,
    knobs: &[Knob],
    starts: &[Vec<f64>],
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    let approaches: Vec<Result<LsqResult, String>> =
        starts.iter().map(|x0| approach(base, knobs, x0, set, opts)).collect();
    let costs: Vec<f64> = approaches
        .iter()
        .map(|a| a.as_ref().map_or(f64::INFINITY, |r| r.cost))
        .collect();
    let follow = ends_to_follow(&costs);
    let mut approaches: Vec<Option<Result<LsqResult, String>>> = approaches.into_iter().map(Some).collect();
    let mut best: Option<LsqResult> = None;
    for i in follow {
        let Some(a) = approaches[i].take() else { continue };
        let r = restarted(base, knobs, finish(base, knobs, &starts[i], a, set, opts)?, set, opts)?;
        if best.as_ref().is_none_or(|b| r.cost < b.cost) {
            best = Some(r);
        }
    }
    best.ok_or_else(|| format!("{}: no start to fit from", set.file))
}

/// The approach on the coarse model ends at the first step that lowers the cost by less than
/// this (relative). Run to its own optimum, it crawled along valleys whose floor lies
/// elsewhere on the model, and the second stage then crawled back (viscosity units' 20-event
/// logs 5.2 -> 8.3 s); stopped at 1 %, the extension of seed 88109's direction-delay unit
/// no longer left the τp-td valley (unit test
/// `an_extension_stopped_in_the_pilot_lag_valley_is_restarted_with_the_lag_held`).
const APPROACH_COST_TOLERANCE: f64 = 1e-3;

/// [`calibrate`], restarted from its end when it stopped on a collapsed step or trust region,
/// again while a restart lowers the cost by more than 0.1 %: in the unit fits' curved
/// valleys (spring rate against preload, orifice areas against each other) the trust region
/// shrinks on the way and a fresh one from the same point goes on. At most three runs.
pub(super) fn calibrate_restarted(
    base: &EhvvaParams,
    knobs: &[Knob],
    x0: &[f64],
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    restarted(base, knobs, calibrate(base, knobs, x0, set, opts)?, set, opts)
}

/// [`calibrate_restarted`]'s restarts after the fit `r`.
fn restarted(
    base: &EhvvaParams,
    knobs: &[Knob],
    mut r: LsqResult,
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    for _ in 0..2 {
        if !matches!(r.stop, StopReason::StepConverged | StopReason::RegionCollapsed) {
            break;
        }
        // From where the last run stopped: no second approach.
        let again = calibrate_with(base, knobs, &r.x, set, opts, &|_| Ok(()))?;
        let went_on = again.cost < 0.999 * r.cost;
        if again.cost < r.cost {
            r = LsqResult {
                iterations: r.iterations + again.iterations,
                evaluations: r.evaluations + again.evaluations,
                initial_cost: r.initial_cost,
                ..again
            };
        }
        if !went_on {
            break;
        }
    }
    Ok(r)
}

/// The pilot lag's knob (τp at 6.5 MPa, 22 °C, [`BASELINE_KNOBS`]).
pub(super) const TAU_P: &str = BASELINE_KNOBS[2].name;

/// A fit whose τp ended further than this factor from the paper's value gets the τp profile
/// start ([`with_tau_profile_start`]). Units differ from the paper's τp by tens of percent
/// (the paper's own Table 2 spread, a generator's ±15 %); an end beyond 1.5x is more often the
/// valley below than the unit.
const TAU_P_PROFILE_RATIO: f64 = 1.5;

/// `r`, or a better end from a second start: τp held at the paper's value while every other
/// knob is fitted from `r`'s end, then everything released from there.
///
/// τp and td both set when the lift leaves its seat, and the cost has long valleys along
/// their trade in which the solver stops far from the optimum: a baseline that absorbed a
/// delay effect into τp (seed 88109's direction-delay unit: τp 0.41 ms, the unit's 0.098) hands
/// its extensions a start on the wrong side, and the direction-delay fit stopped at 130x the
/// optimum's cost (τp 0.23), which it reached from a start with τp at 0.08-0.10 but not at
/// 0.11. With τp held, the rest settles without the trade (cost 0.13 at the paper's 0.105) and
/// the released fit reaches the optimum. Done only where `r`'s τp ended far from the paper's,
/// so a unit near the paper's pays nothing.
pub(super) fn with_tau_profile_start(
    knobs: &[Knob],
    r: LsqResult,
    set: &Events,
    opts: &LsqOptions,
) -> Result<LsqResult, String> {
    let Some(i) = knobs.iter().position(|k| k.name == TAU_P) else {
        return Ok(r);
    };
    let tau_ref = reference_values().2;
    let ratio = r.x[i] / tau_ref;
    if (1.0 / TAU_P_PROFILE_RATIO..=TAU_P_PROFILE_RATIO).contains(&ratio) {
        return Ok(r);
    }
    let mut held_base = EhvvaParams::baseline();
    (knobs[i].apply)(&mut held_base, tau_ref);
    let others: Vec<Knob> = knobs
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != i)
        .map(|(_, k)| *k)
        .collect();
    let x0: Vec<f64> =
        r.x.iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, v)| *v)
            .collect();
    let held = calibrate_restarted(&held_base, &others, &x0, set, opts)?;
    let mut x = held.x.clone();
    x.insert(i, tau_ref);
    let released = calibrate_restarted(&EhvvaParams::baseline(), knobs, &x, set, opts)?;
    Ok(if released.cost < r.cost {
        LsqResult {
            iterations: r.iterations + held.iterations + released.iterations,
            evaluations: r.evaluations + held.evaluations + released.evaluations,
            initial_cost: r.initial_cost,
            ..released
        }
    } else {
        r
    })
}

/// As [`calibrate`], with `derive` completing the parameters from the knobs before each
/// simulation (`identify` sets td from the lift onset there).
pub fn calibrate_with(
    base: &EhvvaParams,
    knobs: &[Knob],
    x0: &[f64],
    set: &Events,
    opts: &LsqOptions,
    derive: &(dyn Fn(&mut EhvvaParams) -> Result<(), String> + Sync),
) -> Result<LsqResult, String> {
    let measured = set.measured();
    let lo: Vec<f64> = knobs.iter().map(|k| k.lo).collect();
    let hi: Vec<f64> = knobs.iter().map(|k| k.hi).collect();
    // The threads go to the events of each simulation, not to the Jacobian's columns: the
    // solver's serial evaluations (start, trial steps) run on all of them too, and 4-5
    // columns on 2 threads leave one idle every other round.
    let residual = |x: &[f64], out: &mut [f64]| -> Result<(), String> {
        let mut p = apply_knobs(base, knobs, x);
        derive(&mut p)?;
        simulate_all_on(&p, set, out, opts.threads)?;
        scale_lift_with_temperature(set, out, lift_scale_per_c(knobs, x));
        for (o, y) in out.iter_mut().zip(&measured) {
            *o -= y;
        }
        Ok(())
    };
    let serial = LsqOptions {
        threads: 1,
        ..opts.clone()
    };
    solve(residual, x0, &lo, &hi, set.samples, &serial).map_err(|e| format!("{}: {e}", set.file))
}

/// Times at which the lift crosses 1 % of the stroke after the rising edge and 99 % after the
/// falling edge (first crossing, linearly interpolated), in ms from the respective edge. The
/// lift is first smoothed by a centred moving average over ±0.25 ms: the first passage of a
/// noisy signal through a level comes early where the lift leaves its stop slowly, and
/// measured and simulated lifts are treated alike.
pub fn edge_delays_ms(
    lift: &[f64],
    on_index: usize,
    off_index: Option<usize>,
    stroke_mm: f64,
    dt_ms: f64,
) -> (Option<f64>, Option<f64>) {
    let half = ((0.25 / dt_ms).round() as usize).max(1);
    let n = lift.len();
    let mut prefix = vec![0.0; n + 1];
    for (k, v) in lift.iter().enumerate() {
        prefix[k + 1] = prefix[k] + v;
    }
    let lift: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(n));
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect();
    let cross = |from: usize, level: f64, rising: bool| -> Option<f64> {
        (from.max(1)..lift.len()).find_map(|k| {
            let (a, b) = (lift[k - 1], lift[k]);
            let hit = if rising {
                a < level && b >= level
            } else {
                a >= level && b < level
            };
            hit.then(|| (k - 1) as f64 + (level - a) / (b - a))
        })
    };
    let open = cross(on_index, 0.01 * stroke_mm, true).map(|k| (k - on_index as f64) * dt_ms);
    let close = off_index.and_then(|off| cross(off, 0.99 * stroke_mm, false).map(|k| (k - off as f64) * dt_ms));
    (open, close)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn approaches_ending_in_one_valley_are_followed_once_the_lowest_first() {
        // Two extensions' approaches on the 400 000-row pair's clean unit: 1.6e-6 apart.
        assert_eq!(ends_to_follow(&[0.3811854, 0.3811848]), vec![1]);
        // Apart by more than the threshold (5e-4): two valleys, both followed, lowest first.
        assert_eq!(ends_to_follow(&[0.40, 0.3811848, 0.3813754]), vec![1, 2, 0]);
        // Just inside and just outside 1e-4 of the first chosen.
        assert_eq!(ends_to_follow(&[1.0, 1.0 + 0.9e-4]), vec![0]);
        assert_eq!(ends_to_follow(&[1.0, 1.0 + 1.1e-4]), vec![0, 1]);
        // Failed approaches are each followed from their start.
        assert_eq!(ends_to_follow(&[f64::INFINITY, 2.0, f64::INFINITY]), vec![1, 0, 2]);
    }
}
