#!/usr/bin/env python3
"""The EHVVA four-knob baseline fit of `hil-host diagnose`, done by scipy's least_squares
(issue #12.8's peer comparison; docs/performance.md shows the figures side by side).

The same problem as `EhvvaFamily::fit` with no effect and `unit_baseline: false` (the paper's
calibration: hil-host/src/diagnose/ehvva/{mod,events,knobs}.rs):

- the log is cut into valve events at each rising pilot command, each from 1 ms before it (the
  first from where the valve is last seen at rest); each event is simulated from rest at its
  set-points (supply and back pressure: the mean of the 1 ms at rest before the command; oil
  temperature: the event's mean; lift and snubber switches at the command); before the command
  the lift is 0, and once the valve has sat 2 ms on its seat after the last command it stays 0;
- the model is model-core's reduced model, eq. (12) (model-core/src/ehvva/reduced.rs, piston.rs,
  tables.rs) with every catalogue effect off: Pmo by implicit Euler towards u (Ph - Pl) + Pl
  with tau_p(Ph, T), read by the piston td(7 MPa, T) later from a delay line of Pmo pushed once a
  sample and read with linear interpolation inside it; the piston's velocity semi-implicit
  (friction and the quadratic orifice losses of the main valve, the top snubber's fixed orifices
  when closing, the bottom port and notch, all over Cd²), lift by symplectic Euler, end stops,
  accumulators by explicit Euler; 10 sub-steps of the 0.05 ms sample; the tables interpolated
  linearly, clamped at their ends;
- the knobs: td at 7 MPa / 22 °C scales both td tables, Cd at 22 °C the Cd table, tau_p at
  6.5 MPa / 22 °C the tau_p table, and the moving mass; the start: the paper's values with td
  shifted by the mean difference of the lift onsets (1 % of the stroke, lift smoothed over
  ±0.25 ms) between the log and one simulation at the paper's values;
- the cost: the lift simulation error over every sample of the estimation log.

Solver settings mirror the Rust ones: the knobs' bounds, forward differences with a relative
step of 1e-5, scaling by the Jacobian's columns (x_scale='jac'), ftol 1e-6 (the Rust cost
tolerance), xtol 1e-9, at most 150 evaluations besides the Jacobians'. The method is scipy's
`dogbox` by default: on this log the optimum has tau_p on its lower bound (0.02 ms), which
dogbox lands on (the Rust optimum, cost within 1e-5); `trf` (--method trf), whose reflective
steps stay strictly inside the box, stops at tau_p 0.0201 with a cost 0.04 % higher, with
ftol 1e-6 as with 1e-9. Not done here (the Rust fit does them): the 95 % intervals and the
prediction of the validation log (one simulation).

The simulation is a Python loop over samples and sub-steps (a recurrence with end stops and a
delay line; it cannot be vectorised in time); the run prints the number of simulations and the
time per simulation.

Usage: peer_ehvva_baseline.py estimation.csv [--repeat N] [--method dogbox|trf] [--ftol F]
       peer_ehvva_baseline.py estimation.csv --check TD CD TAU MASS
Prints one JSON object. `--check` prints the cost at the given knobs (e.g. the Rust fit's)
instead of fitting.
"""
import argparse
import json
import math
import time

import numpy as np
from scipy.optimize import least_squares

from peer_log import read_log

# The paper's parameters (model-core's EhvvaParams::paper_default, effects off).
MASS_KG = 0.183
AREA_TOP = 60.8
AREA_BOTTOM = 4.1
SPRING = 7.67
PRELOAD = 32.9
FRICTION = 0.2
LIFT_HIGH = 7.5
LIFT_LOW = 4.0
DENSITY = 850.0
AREA_MAIN = 11.6
AREA_TOP_ORIFICE = 0.30
AREA_TOP_SWITCH = 0.33
AREA_TOP_NOTCH = 1.86
AREA_BOTTOM_PORT = 0.593
AREA_BOTTOM_NOTCH = 0.122
AREA_BOTTOM_MIN = 0.0245
SNUB_BOTTOM_LEN = 1.5
CAP_HIGH = 3500.0
CAP_LOW = 2000.0
PUMP = 20.0
RELIEF_HIGH = 200.0
RELIEF_LOW = 200.0
P_NOMINAL = 7.0

TD_P = [5.0, 6.0, 7.0, 8.0]
TD_T = [-20.0, 0.0, 22.0, 60.0, 100.0]
VO_5MPA = [4.2, 3.9, 3.7, 3.5, 3.2]
VC_5MPA = [4.0, 3.35, 3.0, 2.98, 2.96]
TD_FACTOR = [1.0, 0.90, 0.82, 0.76]
TD_OPEN = [[v * f for v in VO_5MPA] for f in TD_FACTOR]
TD_CLOSE = [[v * f for v in VC_5MPA] for f in TD_FACTOR]
TAU_P = [5.0, 8.0]
TAU_T = [-20.0, 22.0, 100.0]
TAU = [[0.140, 0.135, 0.132], [0.078, 0.075, 0.073]]
CD_T = [-20.0, 22.0, 60.0, 100.0]
CD = [0.21, 0.40, 0.65, 0.70]

KNOBS = ["td_ms_at_7MPa_22C", "cd_at_22C", "tau_p_ms_at_6p5MPa_22C", "mass_kg"]
LO = [1.0, 0.1, 0.02, 0.02]
HI = [7.0, 0.9, 0.5, 0.6]

DELAY_SAMPLES = 1024
MAX_SUBSTEP_MS = 0.005


def locate(axis, x):
    """Segment and weight of x on a breakpoint axis, clamped at its ends."""
    if x <= axis[0]:
        return 0, 0.0
    if x >= axis[-1]:
        return len(axis) - 2, 1.0
    i = 0
    while i + 2 < len(axis) and x >= axis[i + 1]:
        i += 1
    return i, (x - axis[i]) * (1.0 / (axis[i + 1] - axis[i]))


def interp1(axis, y, x):
    i, w = locate(axis, x)
    return y[i] + w * (y[i + 1] - y[i])


def slice_at(z, axis_y, y):
    """Rows of a 2-D table interpolated at y (the table at one temperature)."""
    j, w = locate(axis_y, y)
    return [row[j] + w * (row[j + 1] - row[j]) for row in z]


def bilinear(axis_x, axis_y, z, x, y):
    return interp1(axis_x, slice_at(z, axis_y, y), x)


def reference_values():
    td = 0.5 * (bilinear(TD_P, TD_T, TD_OPEN, 7.0, 22.0) + bilinear(TD_P, TD_T, TD_CLOSE, 7.0, 22.0))
    return td, interp1(CD_T, CD, 22.0), bilinear(TAU_P, TAU_T, TAU, 6.5, 22.0)


TD_REF, CD_REF, TAU_REF = reference_values()


def cut_events(cols):
    """The valve events of a log (hil-host's Events::from_log)."""
    t = cols["t_s"]
    dt_ms = (t[-1] - t[0]) / (len(t) - 1) * 1e3
    u, ph, pl, temp = cols["u_pilot"], cols["p_supply_MPa"], cols["p_back_MPa"], cols["temp_C"]
    high, snub, lift = cols["lift_high"], cols["snubber_on"], cols["lift_mm"]
    n = len(lift)
    pre = max(int(math.floor(1.0 / dt_ms + 0.5)), 1)
    rising = [k for k in range(1, n) if u[k] > 0.5 and u[k - 1] <= 0.5]
    # The first event starts where the valve was last seen away from its rest.
    first = rising[0]
    rest = range(max(first - pre, 0), first)
    skip = 0
    if len(rest):
        level = float(np.mean(lift[rest.start:rest.stop]))
        for k in range(first - 1, -1, -1):
            if u[k] > 0.5 or abs(lift[k] - level) > 0.05:
                skip = k + 1
                break
    starts = []
    for i, r in enumerate(rising):
        starts.append(skip if i == 0 else max(max(r - pre, 0), starts[i - 1] + 1))
    events = []
    for i, r in enumerate(rising):
        s = starts[i]
        e = starts[i + 1] if i + 1 < len(starts) else n
        a = max(max(r - pre, 0), s)

        def setpoint(x):
            if r - a >= 3:
                return float(np.sum(x[a:r]) / (r - a))
            v = np.sort(x[s:e])
            return float(v[len(v) // 2])
        # The last falling command edge of the event.
        off = None
        for k in range(e - 1, r, -1):
            if u[k] <= 0.5 and u[k - 1] > 0.5:
                off = k - s
                break
        events.append(dict(
            start=s, on=r - s, off=off,
            u=[bool(v > 0.5) for v in u[s:e]],
            lift=lift[s:e].copy(),
            p_supply=setpoint(ph), p_back=setpoint(pl),
            temp=float(np.sum(temp[s:e]) / (e - s)),
            lift_high=bool(high[r] > 0.5), snubber=bool(snub[r] > 0.5),
        ))
    return dt_ms, n, events


def simulate_event(knobs, ev, dt_ms, out):
    """One event by the reduced model eq. (12) (model-core's EhvvaReduced::step, f64)."""
    td_knob, cd_knob, tau_knob, mass = knobs
    temp = ev["temp"]
    # The tables at the event's temperature, the knobs' scales applied.
    s_td = td_knob / TD_REF
    vo = interp1(TD_P, slice_at([[v * s_td for v in row] for row in TD_OPEN], TD_T, temp), P_NOMINAL)
    vc = interp1(TD_P, slice_at([[v * s_td for v in row] for row in TD_CLOSE], TD_T, temp), P_NOMINAL)
    td = max(0.5 * (vo + vc), 0.0)
    s_tau = tau_knob / TAU_REF
    tau_row = slice_at([[v * s_tau for v in row] for row in TAU], TAU_T, temp)
    cd = max(min(CD[1] * (cd_knob / CD_REF), 0.99), 0.05)
    inv_cd2 = 1.0 / (cd * cd)

    n_sub = min(max(math.ceil(dt_ms / MAX_SUBSTEP_MS), 1), 64)
    h = dt_ms / n_sub
    inv_n = 1.0 / n_sub
    apn = 1.0 / (1000.0 * mass)
    half_rho = 0.5 * DENSITY * 1e-6
    rho_at3 = half_rho * AREA_TOP * AREA_TOP * AREA_TOP
    rho_ab3 = half_rho * AREA_BOTTOM * AREA_BOTTOM * AREA_BOTTOM
    inv_a2_main = 1.0 / (AREA_MAIN * AREA_MAIN)
    fixed = AREA_TOP_ORIFICE if ev["snubber"] else AREA_TOP_ORIFICE + AREA_TOP_SWITCH
    # With the snubber effect off its zone has no length: closing always sees the open path.
    inv_a2_top_closing = inv_a2_main + 1.0 / (fixed + AREA_TOP_NOTCH) ** 2
    inv_a2_port = 1.0 / (AREA_BOTTOM_PORT * AREA_BOTTOM_PORT)
    inv_a2_bottom_open = inv_a2_port + 1.0 / (AREA_BOTTOM_MIN + AREA_BOTTOM_NOTCH) ** 2
    stroke = LIFT_HIGH if ev["lift_high"] else LIFT_LOW
    p_set_h, p_set_l = ev["p_supply"], ev["p_back"]
    crack = p_set_h - PUMP / RELIEF_HIGH
    d = td * (1.0 / dt_ms)

    # At rest: seated, Pmo = Pl, accumulators at their set-points; the delay line full of Pl.
    lift = vel = 0.0
    p_high, p_low, p_mo = p_set_h, p_set_l, p_set_l
    hist = [p_set_l] * DELAY_SAMPLES
    settle = max(int(math.floor(2.0 / dt_ms + 0.5)), 1)
    seated_for = 0
    last_off = ev["off"] if ev["off"] is not None else math.inf
    u_pilot = ev["u"]
    for k in range(len(out)):
        if k < ev["on"] or seated_for >= settle:
            out[k] = 0.0
            continue
        tau = max(interp1(TAU_P, tau_row, p_high), 0.01)
        lag = h / tau
        inv_1_lag = 1.0 / (1.0 + lag)
        hist.append(p_mo)
        back = 0.0
        u = u_pilot[k]
        for _ in range(n_sub):
            # Delayed Pmo at the start of the sub-step, eq. (11).
            dd = d - back
            dd = 0.0 if not dd > 0.0 else min(dd, DELAY_SAMPLES - 1.0)
            whole = int(dd)
            frac = dd - whole
            newer = hist[-1 - whole]
            p_top = newer if (whole >= DELAY_SAMPLES - 1 or frac <= 0.0) else newer + frac * (hist[-2 - whole] - newer)
            back += inv_n
            # Eq. (10), implicit.
            p_mo = (p_mo + lag * (p_high if u else p_low)) * inv_1_lag
            # Quadratic losses, eqs. (5)-(6).
            to_go = stroke - lift
            if to_go >= SNUB_BOTTOM_LEN:
                inv_a2_bottom = inv_a2_bottom_open
            else:
                a = AREA_BOTTOM_MIN + AREA_BOTTOM_NOTCH * min(max(to_go / SNUB_BOTTOM_LEN, 0.0), 1.0)
                inv_a2_bottom = inv_a2_port + 1.0 / (a * a)
            top = inv_a2_top_closing if vel < 0.0 else inv_a2_main
            kq = (rho_at3 * top + rho_ab3 * inv_a2_bottom) * inv_cd2
            force = AREA_TOP * p_top - AREA_BOTTOM * p_low - SPRING * (lift + PRELOAD)
            # Velocity semi-implicit, lift symplectic, end stops.
            vel = (vel + h * apn * force) / (1.0 + h * apn * (FRICTION + kq * abs(vel)))
            lift += h * vel
            if lift <= 0.0:
                lift, vel = 0.0, max(vel, 0.0)
            elif lift >= stroke:
                lift, vel = stroke, min(vel, 0.0)
            # Accumulators, eqs. (7)-(8).
            dph = (PUMP - RELIEF_HIGH * max(p_high - crack, 0.0) - AREA_TOP * max(vel, 0.0)) / CAP_HIGH
            dpl = (AREA_BOTTOM * max(vel, 0.0) + (AREA_TOP - AREA_BOTTOM) * max(-vel, 0.0)
                   - RELIEF_LOW * (p_low - p_set_l)) / CAP_LOW
            p_high += h * dph
            p_low += h * dpl
        if not math.isfinite(lift):
            raise FloatingPointError("diverged")
        out[k] = lift
        seated_for = seated_for + 1 if (k > last_off and lift == 0.0 and vel == 0.0) else 0


class Problem:
    def __init__(self, cols):
        self.dt_ms, self.n, self.events = cut_events(cols)
        self.measured = np.zeros(self.n)
        for ev in self.events:
            self.measured[ev["start"]:ev["start"] + len(ev["lift"])] = ev["lift"]
        self.sims = 0

    def simulate(self, knobs):
        self.sims += 1
        out = np.zeros(self.n)
        for ev in self.events:
            seg = [0.0] * len(ev["lift"])
            simulate_event(knobs, ev, self.dt_ms, seg)
            out[ev["start"]:ev["start"] + len(seg)] = seg
        return out

    def residual(self, knobs):
        try:
            return self.simulate(knobs) - self.measured
        except FloatingPointError:
            return np.full(self.n, np.inf)


def edge_onset_ms(lift, on, stroke, dt_ms):
    """Time from the command to the lift (smoothed over ±0.25 ms) crossing 1 % of the stroke."""
    half = max(int(math.floor(0.25 / dt_ms + 0.5)), 1)
    n = len(lift)
    c = np.concatenate(([0.0], np.cumsum(lift)))
    k = np.arange(n)
    a, b = np.maximum(k - half, 0), np.minimum(k + half + 1, n)
    sm = (c[b] - c[a]) / (b - a)
    level = 0.01 * stroke
    for k in range(max(on, 1), n):
        if sm[k - 1] < level <= sm[k]:
            return ((k - 1) + (level - sm[k - 1]) / (sm[k] - sm[k - 1]) - on) * dt_ms
    return None


def start(pb):
    x = [TD_REF, CD_REF, TAU_REF, MASS_KG]
    sim = pb.simulate(x)
    shifts = []
    for ev in pb.events:
        stroke = LIFT_HIGH if ev["lift_high"] else LIFT_LOW
        s0 = ev["start"]
        m = edge_onset_ms(ev["lift"], ev["on"], stroke, pb.dt_ms)
        s = edge_onset_ms(sim[s0:s0 + len(ev["lift"])], ev["on"], stroke, pb.dt_ms)
        if m is not None and s is not None:
            shifts.append(m - s)
    if shifts:
        x[0] = min(max(TD_REF + sum(shifts) / len(shifts), LO[0]), HI[0])
    return x


def fit(pb, ftol, method):
    t0 = time.perf_counter()
    x0 = start(pb)
    t1 = time.perf_counter()
    res = least_squares(pb.residual, x0, bounds=(LO, HI), method=method, diff_step=1e-5,
                        x_scale="jac", ftol=ftol, xtol=1e-9, max_nfev=30 * 5)
    t2 = time.perf_counter()
    return x0, res, t1 - t0, t2 - t1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("estimation")
    ap.add_argument("--repeat", type=int, default=1, help="runs; the fastest is reported")
    ap.add_argument("--ftol", type=float, default=1e-6,
                    help="least_squares' ftol (1e-6: the Rust cost tolerance)")
    ap.add_argument("--method", default="dogbox", choices=["trf", "dogbox"],
                    help="least_squares' method (dogbox reaches the optimum on the bound; see above)")
    ap.add_argument("--check", nargs=4, type=float, metavar=("TD", "CD", "TAU", "MASS"))
    a = ap.parse_args()
    _, cols = read_log(a.estimation)
    if a.check:
        pb = Problem(cols)
        t = time.perf_counter()
        r = pb.residual(a.check)
        print(json.dumps({"events": len(pb.events), "samples": pb.n, "cost_half_sum_sq": 0.5 * float(r @ r),
                          "sim_s": time.perf_counter() - t}))
        return
    runs = []
    for _ in range(a.repeat):
        pb = Problem(cols)
        t = time.perf_counter()
        x0, res, start_s, lsq_s = fit(pb, a.ftol, a.method)
        runs.append((time.perf_counter() - t, x0, res, start_s, lsq_s, pb.sims))
    total, x0, res, start_s, lsq_s, sims = min(runs, key=lambda r: r[0])
    print(json.dumps({
        "samples": pb.n,
        "events": len(pb.events),
        "start": dict(zip(KNOBS, x0)),
        "params": dict(zip(KNOBS, res.x)),
        "cost_half_sum_sq": res.cost,
        "method": a.method,
        "ftol": a.ftol,
        "status": int(res.status),
        "nfev": int(res.nfev),
        "njev": int(res.njev),
        "sims": sims,
        "start_s": start_s,
        "lsq_s": lsq_s,
        "total_s": total,
        "per_sim_ms": 1e3 * total / sims,
        "runs_s": sorted(r[0] for r in runs),
    }, indent=1))


if __name__ == "__main__":
    main()
