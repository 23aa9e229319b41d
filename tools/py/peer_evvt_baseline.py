#!/usr/bin/env python3
"""The EVVT baseline fit of `hil-host diagnose`, done by scipy's least_squares (issue #12.8's
peer comparison; docs/performance.md shows the figures side by side).

The same problem as `EvvtFamily::baseline` in hil-host/src/diagnose/evvt.rs: the plant
alpha/(s(s+beta)) in exact zero-order hold at the log's step, in the logged closed loop
(motor_cmd = sat(kp (phase_ref - quantized simulated phase)) every control period, the
quantizer's levels joined by ramps half an LSB wide), phase clamped to the stops; the cost is
the simulation error of the phase over the whole estimation log. Start: the best point of the
same coarse (alpha, beta) grid; then least_squares (trust-region reflective, the bounds of the
Rust fit, forward differences, tolerances close to the Rust solver's).

The residual is a Python loop, as a user of scipy would write it for a recurrence with a
quantizer in the loop (it cannot be vectorised); the run prints how many simulations each
stage made and the time per simulation, so the solver's own overhead can be told apart.

Usage: peer_evvt_baseline.py estimation.csv [--repeat N]
Prints one JSON object: alpha, beta, cost, nfev, grid_s, lsq_s, total_s, per_sim_ms.
"""
import argparse
import json
import math
import time

import numpy as np
from scipy.optimize import least_squares

from peer_log import read_log


def zoh(alpha, beta, t):
    """Exact ZOH of x1' = x2, x2' = -beta x2 + alpha u (phase in deg, u in rpm)."""
    x = max(beta * t, 0.0)
    if x < 1e-6:
        phi1, phi2 = 1.0 - x / 2.0, 0.5 - x / 6.0
    else:
        phi1 = -math.expm1(-x) / x
        phi2 = (1.0 - phi1) / x
    e = 1.0 - x * phi1
    return t * phi1, alpha * t * t * phi2, e, alpha * t * phi1


def quantizer(x, lsb, ramp):
    u = x / lsb
    fl = math.floor(u)
    f = u - fl
    return (fl + min(max((f - 0.5) / min(ramp, 1.0) + 0.5, 0.0), 1.0)) * lsb


class Problem:
    def __init__(self, meta, cols):
        self.y = cols["phase_deg"].tolist()
        self.ref = cols["phase_ref_deg"].tolist()
        self.dt = float(np.median(np.diff(cols["t_s"])))
        self.kp = float(meta["kp"])
        self.cmd_max = float(meta.get("motor_cmd_max_rpm", "inf"))
        self.hold = max(1, round(float(meta.get("control_period_s", self.dt)) / self.dt))
        self.lsb, self.ramp = 1.0, 0.5
        self.stop_lo = min(min(self.y), 0.0)
        self.stop_hi = max(max(self.y), 40.0)
        self.sims = 0

    def residual(self, p):
        alpha, beta = p
        self.sims += 1
        ad12, bd1, ad22, bd2 = zoh(alpha, beta, self.dt)
        x1 = min(max(self.y[0], self.stop_lo), self.stop_hi)
        x2, u = 0.0, 0.0
        lo, hi, kp, cmax, hold = self.stop_lo, self.stop_hi, self.kp, self.cmd_max, self.hold
        out = [0.0] * len(self.y)
        for k, (yk, rk) in enumerate(zip(self.y, self.ref)):
            out[k] = x1 - yk
            if k % hold == 0:
                u = min(max(kp * (rk - quantizer(x1, self.lsb, self.ramp)), -cmax), cmax)
            x1, x2 = x1 + ad12 * x2 + bd1 * u, ad22 * x2 + bd2 * u
            if x1 >= hi:
                x1, x2 = hi, min(x2, 0.0)
            elif x1 <= lo:
                x1, x2 = lo, max(x2, 0.0)
        return np.asarray(out)


def fit(problem):
    t0 = time.perf_counter()
    best = (math.inf, 0.5, 5.0)
    for i in range(10):
        alpha = 0.02 * 2.0**i
        for beta in (0.5, 1.5, 4.0, 10.0, 25.0, 60.0):
            r = problem.residual((alpha, beta))
            cost = float(r @ r)
            if cost < best[0]:
                best = (cost, alpha, beta)
    grid_sims = problem.sims
    t1 = time.perf_counter()
    res = least_squares(
        problem.residual,
        x0=[best[1], best[2]],
        bounds=([1e-4, 0.0], [100.0, 500.0]),
        method="trf",
        diff_step=1e-6,
        ftol=1e-7,
        xtol=1e-9,
        max_nfev=200,
    )
    t2 = time.perf_counter()
    return res, grid_sims, t1 - t0, t2 - t1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("estimation")
    ap.add_argument("--repeat", type=int, default=3, help="runs; the fastest is reported")
    a = ap.parse_args()
    meta, cols = read_log(a.estimation)
    runs = []
    for _ in range(a.repeat):
        p = Problem(meta, cols)
        res, grid_sims, grid_s, lsq_s = fit(p)
        runs.append((grid_s + lsq_s, res, grid_sims, grid_s, lsq_s, p.sims))
    total, res, grid_sims, grid_s, lsq_s, sims = min(runs, key=lambda r: r[0])
    print(json.dumps({
        "samples": len(cols["phase_deg"]),
        "alpha": res.x[0],
        "beta": res.x[1],
        "cost_half_sum_sq": res.cost,
        "status": res.status,
        "grid_sims": grid_sims,
        "lsq_sims": sims - grid_sims,
        "grid_s": grid_s,
        "lsq_s": lsq_s,
        "total_s": total,
        "per_sim_ms": 1e3 * total / sims,
    }, indent=1))


if __name__ == "__main__":
    main()
