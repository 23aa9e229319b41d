#!/usr/bin/env python3
"""The vacuum baseline fit of `hil-host diagnose`, done by scipy's least_squares (issue #12.8's
peer comparison; docs/performance.md shows the figures side by side).

The same problem as `VacuumFamily::fit` with no effect (hil-host/src/diagnose/vacuum/mod.rs and
model.rs; the model is model-core's `VacuumValveActuator` with every catalogue effect off):

1. inputs: the logged duty, ambient pressure smoothed by a centred 1 s moving average, tank
   pressure by a 0.3 s one; each simulation starts at the steady state of the first inputs and
   its first 0.5 s (40 samples at 80 Hz) are not scored;
2. the valve map: the pressure parameters (eq. (2) k1, p01, k2, p02 or eq. (5) k1, p01, k3, u0,
   and tau) fitted on the chamber-pressure simulation error (eq. (4), exact first order; a
   linear recurrence, so `scipy.signal.lfilter`) from each of the three presets (LPT, HPT, HPC),
   the lowest cost kept;
3. the position map: the centre of the quasi-static (pressure, position) band per 1 kPa bin, a
   line through it, and an arctan fitted to it (least_squares again), kept only if it lowers
   the error by 20 % and the line misses by more than 1 %;
4. the rod stage: the position map, the mass and both damping coefficients fitted on the
   position simulation error with the pressure model held: the force balance eq. (7), spring
   from the inverse position map, semi-implicit Euler in 13 substeps of the 12.5 ms sample
   (at most 1 ms each, the chamber pressure interpolated across the sample), end stops.

Solver settings mirror the Rust ones: trust-region reflective, the same bounds, forward
differences with a relative step of 1e-6, scaling by the Jacobian's columns (x_scale='jac',
as the Rust solver scales by column norms), ftol 1e-5 (the Rust cost tolerance: relative
decrease of the cost), xtol 1e-7. Not done here (the Rust fit does them): the 95 % intervals of
the pressure stage at its optimum and the prediction of the validation log (one simulation).

The rod simulation is a Python loop over samples and substeps, as a user of scipy would write a
recurrence with state-dependent branches (it cannot be vectorised in time); the run prints how
many simulations each stage made and the time per simulation.

Usage: peer_vacuum_baseline.py estimation.csv [--repeat N] [--check name=value ...]
Prints one JSON object. `--check` evaluates the two costs at given parameters (e.g. the Rust
fit's) instead of fitting.
"""
import argparse
import json
import math
import time

import numpy as np
from scipy.optimize import least_squares

from peer_log import read_log
from scipy.signal import lfilter

P_AMB_REF = 100.0
THETA_MAX = 1.5
H_MAX_S = 0.001

BOUNDS = {
    "k1_kPa_per_pct": (-10.0, -0.01),
    "p01_kPa": (40.0, 1000.0),
    "k2_kPa_per_pct": (-10.0, -0.01),
    "p02_kPa": (40.0, 1000.0),
    "k3_kPa_per_pct3": (-0.05, -1e-7),
    "u0_pct": (0.0, 95.0),
    "tau_rise_s": (0.003, 2.0),
    "lin_k_pct_per_kPa": (-50.0, -0.05),
    "lin_x0_pct": (-2000.0, 5000.0),
    "a1_pct": (-50.0, 150.0),
    "a2_pct_per_rad": (5.0, 500.0),
    "a3_kPa": (0.0, 200.0),
    "a4_kPa": (0.3, 500.0),
    "mass_kPa_s2_per_pct": (1e-6, 5e-3),
    "damping_extend_kPa_s_per_pct": (1e-4, 1.0),
    "damping_retract_kPa_s_per_pct": (1e-4, 1.0),
}
DAMPING = ["mass_kPa_s2_per_pct", "damping_extend_kPa_s_per_pct", "damping_retract_kPa_s_per_pct"]


def presets():
    """The paper's LPT, HPT and HPC actuators with the effects off (model-core's presets)."""
    lpt = dict(valve="linear", rod="linear", k1_kPa_per_pct=-0.4, p01_kPa=107.0, k2_kPa_per_pct=-1.0,
               p02_kPa=122.0, tau_rise_s=0.04, lin_k_pct_per_kPa=-2.0, lin_x0_pct=180.0,
               mass_kPa_s2_per_pct=2.0e-4, damping_extend_kPa_s_per_pct=0.014,
               damping_retract_kPa_s_per_pct=0.028)
    hpt = dict(lpt, rod="arctan", k1_kPa_per_pct=-0.25, p01_kPa=102.5, k2_kPa_per_pct=-0.95,
               p02_kPa=123.5, tau_rise_s=0.05, a1_pct=50.0, a2_pct_per_rad=40.0, a3_kPa=70.0,
               a4_kPa=8.0, mass_kPa_s2_per_pct=1.0e-4, damping_extend_kPa_s_per_pct=0.006,
               damping_retract_kPa_s_per_pct=0.012)
    hpc = dict(lpt, valve="cubic", rod="arctan", k1_kPa_per_pct=-4.0, p01_kPa=420.0,
               k3_kPa_per_pct3=-3.2e-4, u0_pct=40.0, tau_rise_s=0.05, a1_pct=50.0,
               a2_pct_per_rad=38.0, a3_kPa=62.0, a4_kPa=8.0, mass_kPa_s2_per_pct=1.0e-4,
               damping_extend_kPa_s_per_pct=0.007, damping_retract_kPa_s_per_pct=0.014)
    return [lpt, hpt, hpc]


def pressure_names(m):
    if m["valve"] == "linear":
        return ["k1_kPa_per_pct", "p01_kPa", "k2_kPa_per_pct", "p02_kPa", "tau_rise_s"]
    return ["k1_kPa_per_pct", "p01_kPa", "k3_kPa_per_pct3", "u0_pct", "tau_rise_s"]


def rod_names(m):
    if m["rod"] == "linear":
        return ["lin_k_pct_per_kPa", "lin_x0_pct"] + DAMPING
    return ["a1_pct", "a2_pct_per_rad", "a3_kPa", "a4_kPa"] + DAMPING


def rod_map_valid(m):
    """model-core's check: the stroke 0..100 % inside the arctan's open range a1 ± 1.5 a2."""
    if m["rod"] == "linear":
        return abs(m["lin_k_pct_per_kPa"]) > 1e-3
    a1, a2 = m["a1_pct"], m["a2_pct_per_rad"]
    return a2 > 0 and m["a4_kPa"] > 0 and abs(a1 / a2) <= THETA_MAX and abs((100 - a1) / a2) <= THETA_MAX


def moving_average(y, seconds, dt):
    """Centred moving average over `seconds`, shorter at the ends."""
    half = int(math.floor(0.5 * seconds / dt + 0.5))
    n = len(y)
    c = np.concatenate(([0.0], np.cumsum(y)))
    k = np.arange(n)
    a = np.maximum(k - half, 0)
    b = np.minimum(k + half + 1, n)
    return (c[b] - c[a]) / (b - a)


class Problem:
    def __init__(self, cols):
        t = cols["t_s"]
        self.dt = (t[-1] - t[0]) / (len(t) - 1)
        self.duty = np.clip(cols["duty_pct"], 0.0, 100.0)
        self.p_amb = moving_average(cols["p_amb_kPa"], 1.0, self.dt)
        self.p_tank = moving_average(cols["p_tank_kPa"], 0.3, self.dt)
        self.p_low = np.minimum(self.p_tank, self.p_amb)
        self.x = cols["x_pct"]
        self.p = cols["p_act_kPa"]
        n = len(self.x)
        self.score_from = min(int(math.floor(0.5 / self.dt + 0.5)), n // 4)
        self.n_sub = int(min(max(math.ceil(self.dt / H_MAX_S * (1 - 1e-6)), 1), 2000))
        self.p_amb_list = self.p_amb.tolist()
        self.sims = {"pressure": 0, "rod": 0}

    def static_pressure(self, m):
        u = self.duty
        if m["valve"] == "linear":
            p = np.minimum(m["k1_kPa_per_pct"] * u + m["p01_kPa"], m["k2_kPa_per_pct"] * u + m["p02_kPa"])
        else:
            d = np.clip(u - m["u0_pct"], 0.0, 200.0)
            p = np.minimum(m["k1_kPa_per_pct"] * u + m["p01_kPa"], self.p_amb + m["k3_kPa_per_pct3"] * d**3)
        return np.minimum(np.maximum(p, self.p_low), self.p_amb)

    def pressure(self, m):
        """Eq. (4), exact over each sample: p[k+1] = p[k] + (p_stat[k] - p[k]) (1 - e^(-dt/tau)),
        p[0] = p_stat[0]; element k is the pressure before the step with inputs k."""
        self.sims["pressure"] += 1
        s = self.static_pressure(m)
        a = -math.expm1(-self.dt / m["tau_rise_s"])
        after = lfilter([a], [1.0, a - 1.0], s, zi=[(1.0 - a) * s[0]])[0]
        return np.concatenate(([s[0]], after[:-1])), after

    def position(self, m):
        """The valve position before each step: the rod's force balance eq. (7) integrated."""
        self.sims["rod"] += 1
        p_before, p_after = self.pressure(m)
        self.sims["pressure"] -= 1
        n_sub, dt = self.n_sub, self.dt
        h = dt / n_sub
        inv_m = 1.0 / m["mass_kPa_s2_per_pct"]
        den_ext = 1.0 + h * m["damping_extend_kPa_s_per_pct"] * inv_m
        den_ret = 1.0 + h * m["damping_retract_kPa_s_per_pct"] * inv_m
        hinv = h * inv_m
        linear = m["rod"] == "linear"
        if linear:
            k, x0 = m["lin_k_pct_per_kPa"], m["lin_x0_pct"]
        else:
            a1, a2, a3, a4 = m["a1_pct"], m["a2_pct_per_rad"], m["a3_kPa"], m["a4_kPa"]
        # Settled start: static position at the first pressure.
        p_map = P_AMB_REF - (self.p_amb[0] - p_before[0])
        x = k * p_map + x0 if linear else a1 + a2 * math.atan((a3 - p_map) / a4)
        x = min(max(x, 0.0), 100.0)
        v = 0.0
        out = [0.0] * len(p_before)
        pb = p_before.tolist()
        pa = p_after.tolist()
        for i, p_amb in enumerate(self.p_amb_list):
            out[i] = x
            p_sub = pb[i]
            dp = (pa[i] - p_sub) / n_sub
            for _ in range(n_sub):
                p_sub += dp
                if linear:
                    spring = P_AMB_REF - (x - x0) / k
                else:
                    theta = min(max((x - a1) / a2, -THETA_MAX), THETA_MAX)
                    spring = P_AMB_REF - (a3 - a4 * math.tan(theta))
                drive = (p_amb - p_sub) - spring
                v = (v + hinv * drive) / (den_ext if v >= 0.0 else den_ret)
                x += h * v
                if x <= 0.0:
                    x, v = 0.0, max(v, 0.0)
                elif x >= 100.0:
                    x, v = 100.0, min(v, 0.0)
        return np.asarray(out)

    def pressure_residual(self, m):
        return (self.pressure(m)[0] - self.p)[self.score_from:]

    def position_residual(self, m):
        if not rod_map_valid(m):
            return np.full(len(self.x) - self.score_from, np.inf)
        return (self.position(m) - self.x)[self.score_from:]


def lsq(fun, m, names):
    """least_squares on `names` of model `m`; the model at the optimum and the result."""
    def residual(theta):
        return fun(dict(m, **dict(zip(names, theta))))
    lo = [BOUNDS[n][0] for n in names]
    hi = [BOUNDS[n][1] for n in names]
    x0 = np.clip([m[n] for n in names], lo, hi)
    res = least_squares(residual, x0, bounds=(lo, hi), method="trf", diff_step=1e-6,
                        x_scale="jac", ftol=1e-5, xtol=1e-7)
    return dict(m, **dict(zip(names, res.x))), res


def rod_map_guess(pb, m):
    """Line and arctan through the centre of the quasi-static (pressure, position) band."""
    x, p, p_amb = pb.x, pb.p, pb.p_amb
    n = len(x)
    w = max(int(math.floor(0.05 / pb.dt + 0.5)), 1)
    idx = np.arange(n)
    rate = np.abs(p[np.minimum(idx + w, n - 1)] - p[np.maximum(idx - w, 0)])
    off_stops = (x > 1.0) & (x < 99.0)
    map_p = P_AMB_REF - (p_amb - p)
    pts = []
    for limit in (3.0, 8.0, math.inf):
        sel = off_stops & (rate < limit) & np.isfinite(map_p)
        bins = np.floor(map_p[sel]).astype(np.int64)
        xs_sel = x[sel]
        pts = []
        for b in np.unique(bins):
            xs = np.sort(xs_sel[bins == b])
            if len(xs) >= 5:
                q = lambda f: xs[int(math.floor((len(xs) - 1) * f + 0.5))]
                if q(0.05) > 3.0 and q(0.95) < 97.0:
                    pts.append((b + 0.5, 0.5 * (q(0.05) + q(0.95))))
        if len(pts) >= 10:
            break
    if len(pts) < 10:
        return m, None
    pm, xm = np.array(pts).T
    spp = np.sum((pm - pm.mean()) ** 2)
    k = min(np.sum((pm - pm.mean()) * (xm - xm.mean())) / spp, -0.05) if spp > 0 else -2.0
    lin = dict(m, rod="linear", lin_k_pct_per_kPa=k, lin_x0_pct=xm.mean() - k * pm.mean())
    sse_lin = float(np.sum((np.clip(k * pm + lin["lin_x0_pct"], 0, 100) - xm) ** 2))
    at = dict(m, rod="arctan", a1_pct=50.0, a2_pct_per_rad=40.0, a3_kPa=(50.0 - lin["lin_x0_pct"]) / k,
              a4_kPa=40.0 / -k)

    def band(mm):
        if not rod_map_valid(mm):
            return np.full(len(pm), np.inf)
        return np.clip(mm["a1_pct"] + mm["a2_pct_per_rad"] * np.arctan((mm["a3_kPa"] - pm) / mm["a4_kPa"]),
                       0, 100) - xm
    at, res = lsq(band, at, ["a1_pct", "a2_pct_per_rad", "a3_kPa", "a4_kPa"])
    if 2.0 * res.cost < 0.64 * sse_lin and sse_lin > len(pts):
        return at, res
    return lin, res


def fit(pb):
    t0 = time.perf_counter()
    best = None
    for start in presets():
        m, res = lsq(pb.pressure_residual, start, pressure_names(start))
        if best is None or res.cost < best[1].cost:
            best = (m, res)
    valve, pres = best
    t1 = time.perf_counter()
    model, _ = rod_map_guess(pb, valve)
    t2 = time.perf_counter()
    model, rres = lsq(pb.position_residual, model, rod_names(model))
    t3 = time.perf_counter()
    return model, pres, rres, (t1 - t0, t2 - t1, t3 - t2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("estimation")
    ap.add_argument("--repeat", type=int, default=2, help="runs; the fastest is reported")
    ap.add_argument("--check", nargs="+", metavar="NAME=VALUE",
                    help="costs at these parameters (valve and rod map shapes from the names)")
    a = ap.parse_args()
    _, cols = read_log(a.estimation)
    if a.check:
        given = {k: float(v) for k, v in (s.split("=") for s in a.check)}
        m = dict(presets()[0], **given)
        m["valve"] = "cubic" if "u0_pct" in given else "linear"
        m["rod"] = "arctan" if "a1_pct" in given else "linear"
        pb = Problem(cols)
        rp, rx = pb.pressure_residual(m), pb.position_residual(m)
        print(json.dumps({"pressure_cost": 0.5 * float(rp @ rp), "position_cost": 0.5 * float(rx @ rx)}))
        return
    runs = []
    for _ in range(a.repeat):
        pb = Problem(cols)
        t = time.perf_counter()
        model, pres, rres, stages = fit(pb)
        runs.append((time.perf_counter() - t, model, pres, rres, stages, dict(pb.sims)))
    total, model, pres, rres, stages, sims = min(runs, key=lambda r: r[0])
    # Time per simulation, measured apart on the fitted model.
    pb = Problem(cols)
    t = time.perf_counter()
    for _ in range(3):
        pb.position(model)
    per_rod = (time.perf_counter() - t) / 3
    t = time.perf_counter()
    for _ in range(20):
        pb.pressure(model)
    per_p = (time.perf_counter() - t) / 20
    names = pressure_names(model) + rod_names(model)
    print(json.dumps({
        "samples": len(cols["x_pct"]),
        "valve_map": model["valve"],
        "rod_map": model["rod"],
        "params": {n: model[n] for n in names},
        "pressure_cost_half_sum_sq": pres.cost,
        "position_cost_half_sum_sq": rres.cost,
        "rod_stage_status": int(rres.status),
        "rod_stage_nfev": int(rres.nfev),
        "rod_stage_njev": int(rres.njev),
        "pressure_sims": sims["pressure"],
        "rod_sims": sims["rod"],
        "pressure_stage_s": stages[0],
        "rod_map_guess_s": stages[1],
        "rod_stage_s": stages[2],
        "total_s": total,
        "per_rod_sim_ms": 1e3 * per_rod,
        "per_pressure_sim_ms": 1e3 * per_p,
        "runs_s": sorted(r[0] for r in runs),
    }, indent=1))


if __name__ == "__main__":
    main()
