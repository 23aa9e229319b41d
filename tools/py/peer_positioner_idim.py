#!/usr/bin/env python3
"""The positioner's Coulomb-friction fit of `hil-host diagnose` (IDIM-LS on the EMPS data) done
with scipy (issue #12.8's peer comparison; docs/performance.md shows both figures).

The same pipeline as `PositionerFamily::fit` in hil-host/src/diagnose/positioner.rs, with
scipy's own filters: the position low-passed by a 4th-order Butterworth at 80 Hz forwards and
backwards (odd padding of 4 fs/fc samples), differentiated twice by central differences; the
regressors (acceleration, velocity, the sign of the velocity beyond 0.1 mm/s, 1) and the force
low-passed by an 8th-order Butterworth at 80 % of the new Nyquist frequency, kept every 20th
sample, the filter's settling span dropped at both ends; then force = M a + Fv v + Fc sign(v)
+ offset by `least_squares` (and by `numpy.linalg.lstsq` for reference), and the validation
log predicted with it. The filters are scipy's (second-order sections), not a copy of the
Rust ones, so the parameters agree closely, not to the last digit.

Usage: peer_positioner_idim.py estimation.csv validation.csv [--repeat N]
Prints one JSON object: parameters, least_squares time, whole pipeline time.
"""
import argparse
import json
import math
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, sosfiltfilt


def read_log(path):
    header, rows = None, []
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                continue
            if header is None:
                header = line.strip().split(",")
            elif line.strip():
                rows.append([float(v) for v in line.split(",")])
    data = np.array(rows)
    return {name: data[:, i] for i, name in enumerate(header)}


def lowpass(x, order, fc, fs):
    sos = butter(order, fc, fs=fs, output="sos")
    pad = min(math.ceil(4.0 * fs / fc), len(x) - 1)
    return sosfiltfilt(sos, x, padtype="odd", padlen=pad)


def regression(cols, dt, nd=20, still=1e-4):
    fs = 1.0 / dt
    q = lowpass(cols["pos_m"], 4, min(80.0, 0.4 * fs), fs)
    vel = np.gradient(q, dt)
    acc = np.gradient(vel, dt)
    fc = 0.8 * 0.5 * fs / nd
    trim = math.ceil(math.ceil(4.0 * fs / fc) / nd)

    def decimate(x):
        v = lowpass(x, 8, fc, fs)[::nd]
        return v[trim:len(v) - trim] if len(v) > 4 * trim else v

    sign = (vel > still).astype(float) - (vel < -still).astype(float)
    a = np.column_stack([decimate(acc), decimate(vel), decimate(sign), decimate(np.ones_like(vel))])
    return a, decimate(cols["force_N"])


def fit(est, val):
    t0 = time.perf_counter()
    dt = float(np.median(np.diff(est["t_s"])))
    a, y = regression(est, dt)
    t1 = time.perf_counter()
    res = least_squares(lambda th: a @ th - y, x0=np.zeros(a.shape[1]), method="trf")
    t2 = time.perf_counter()
    va, vy = regression(val, dt)
    pred = va @ res.x
    t3 = time.perf_counter()
    return res, pred, vy, t2 - t1, t3 - t0, a, y


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("estimation")
    ap.add_argument("validation")
    ap.add_argument("--repeat", type=int, default=5, help="runs; the fastest is reported")
    a = ap.parse_args()
    est, val = read_log(a.estimation), read_log(a.validation)
    runs = [fit(est, val) for _ in range(a.repeat)]
    res, pred, vy, lsq_s, total_s, ea, ey = min(runs, key=lambda r: r[4])
    lstsq = np.linalg.lstsq(ea, ey, rcond=None)[0]
    print(json.dumps({
        "rows": [len(est["t_s"]), len(val["t_s"])],
        "params": dict(zip(["M_kg", "Fv_Ns_per_m", "Fc_N", "offset_N"], res.x.tolist())),
        "lstsq_params": lstsq.tolist(),
        "validation_rmse_N": float(np.sqrt(np.mean((vy - pred) ** 2))),
        "least_squares_s": min(r[3] for r in runs),
        "pipeline_s": total_s,
        "nfev": int(res.nfev),
    }, indent=1))


if __name__ == "__main__":
    main()
