#!/usr/bin/env python3
"""Write a DATA-FORMAT CSV log as an ASAM MDF 4 file with asammdf, the way loggers export.

Test tooling for hil-host's MF4 reader (hil-host/tests/mf4.rs): the same samples as the CSV, so
that reading either gives the same log. Options reproduce what real loggers do:

  --compression N      asammdf's save compression: 0 none, 1 deflate (DZ), 2 transposed deflate
  --rename OLD=NEW     store column OLD under the logger's channel name NEW (repeatable)
  --group2 A,B         put columns A and B in a second channel group with its own time base
  --group2-factor F    that group's rate relative to the CSV's: an integer F > 1 samples F times
                       faster (continuous channels linearly interpolated between the CSV's
                       samples, flags held), F < 0 samples every |F|-th CSV sample (slower)
  --flags A,B          columns stored as 8-bit unsigned integers (0/1 flags)
  --meta-as text|properties
                       metadata (`# key: value`) into the header comment as `key: value` lines
                       (default) or as <common_properties> entries
  --drop-meta K        leave metadata key K out of the file (repeatable; for the channel map test)
  --jitter F           the primary group's time stamps jitter by up to +-F/2 of the period (first and
                       last kept; values read at the jittered instants: signals interpolated,
                       flags held), as a logger's event-driven raster records them
  --text COL=TEXT0,TEXT1
                       store the 0/1 column COL as an 8-bit integer with a value-to-text conversion
                       (0 -> TEXT0, 1 -> TEXT1), as loggers record a digital state (repeatable)
  --unit COL=UNIT,FACTOR[,OFFSET]
                       store column COL in the logger's unit UNIT: samples * FACTOR + OFFSET
                       (repeatable; a logger recording pressure in bar, lift in m)

The time column `t_s` becomes each group's master channel.
"""
import argparse
import sys
from xml.sax.saxutils import escape

import numpy as np
from asammdf import MDF, Signal


def read_csv(path):
    meta, header, rows = [], None, []
    with open(path, encoding="utf-8") as f:
        for line in f:
            line = line.rstrip("\r\n")
            if not line.strip():
                continue
            if header is None and line.startswith("#"):
                body = line.lstrip("#").strip()
                if ":" in body:
                    k, v = body.split(":", 1)
                    meta.append((k.strip(), v.strip()))
                continue
            if header is None:
                header = [c.strip() for c in line.split(",")]
                continue
            rows.append([float(c) for c in line.split(",")])
    data = np.array(rows, dtype=np.float64)
    return meta, header, {name: data[:, i] for i, name in enumerate(header)}


def unit_of(name):
    for suffix, unit in (("_pct", "%"), ("_V", "V"), ("_kPa", "kPa"), ("_MPa", "MPa"), ("_C", "degC"),
                         ("_mm", "mm"), ("_m", "m"), ("_deg", "deg"), ("_rpm", "rpm"), ("_N", "N")):
        if name.endswith(suffix):
            return unit
    return ""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("csv")
    ap.add_argument("out")
    ap.add_argument("--compression", type=int, default=0)
    ap.add_argument("--rename", action="append", default=[])
    ap.add_argument("--group2", default="")
    ap.add_argument("--group2-factor", type=int, default=2)
    ap.add_argument("--flags", default="")
    ap.add_argument("--meta-as", choices=["text", "properties"], default="text")
    ap.add_argument("--drop-meta", action="append", default=[])
    ap.add_argument("--unit", action="append", default=[])
    ap.add_argument("--jitter", type=float, default=0.0)
    ap.add_argument("--text", action="append", default=[])
    a = ap.parse_args()

    meta, header, cols = read_csv(a.csv)
    rename = dict(r.split("=", 1) for r in a.rename)
    flags = set(filter(None, a.flags.split(",")))
    group2 = [c for c in filter(None, a.group2.split(",")) if c in cols]
    t = cols["t_s"]
    units = {}
    for u in a.unit:
        col, spec = u.split("=", 1)
        parts = spec.split(",")
        units[col] = (parts[0], float(parts[1]), float(parts[2]) if len(parts) > 2 else 0.0)

    texts = {}
    for x in a.text:
        col, spec = x.split("=", 1)
        texts[col] = spec.split(",", 1)

    def signal(name, samples, stamps):
        unit = unit_of(name)
        if name in units:
            unit, factor, offset = units[name]
            samples = samples * factor + offset
        conversion = None
        if name in texts:
            off, on = texts[name]
            samples = samples.astype(np.uint8)
            conversion = {"val_0": 0, "text_0": off, "val_1": 1, "text_1": on, "default": b""}
        if name in flags:
            samples = samples.astype(np.uint8)
        return Signal(samples=samples, timestamps=stamps, name=rename.get(name, name), unit=unit,
                      conversion=conversion)

    mdf = MDF(version="4.10")
    t1, at = t, {n: cols[n] for n in header}
    if a.jitter > 0:
        rng = np.random.default_rng(1)
        dt = (t[-1] - t[0]) / (len(t) - 1)
        t1 = t.copy()
        t1[1:-1] += (rng.random(len(t) - 2) - 0.5) * a.jitter * dt
        held = np.clip(np.searchsorted(t, t1, side="right") - 1, 0, len(t) - 1)
        at = {n: (cols[n][held] if n in flags else np.interp(t1, t, cols[n])) for n in header}
    primary = [signal(n, at[n], t1) for n in header if n != "t_s" and n not in group2]
    mdf.append(primary, comment="primary rate", common_timebase=True)
    if group2:
        f = a.group2_factor
        if f > 1:
            # F sub-steps per CSV step; the CSV's own instants are kept bit-exact.
            frac = np.arange(f) / f
            t2 = np.concatenate([(t[:-1, None] + frac[None, :] * np.diff(t)[:, None]).ravel(), t[-1:]])
            t2[::f] = t
            second = []
            for n in group2:
                y = cols[n]
                if n in flags:
                    y2 = np.repeat(y[:-1], f)
                    y2 = np.concatenate([y2, y[-1:]])
                else:
                    y2 = np.concatenate([(y[:-1, None] + frac[None, :] * np.diff(y)[:, None]).ravel(), y[-1:]])
                    y2[::f] = y
                second.append(signal(n, y2, t2))
        elif f < -1:
            k = -f
            second = [signal(n, cols[n][::k], t[::k]) for n in group2]
        else:
            sys.exit("--group2-factor must be > 1 or < -1")
        mdf.append(second, comment=f"second rate (factor {f})", common_timebase=True)

    kept = [(k, v) for k, v in meta if k not in a.drop_meta]
    if a.meta_as == "text":
        mdf.header.comment = "\n".join(f"{k}: {v}" for k, v in kept)
    else:
        props = "".join(f'<e name="{escape(k)}">{escape(v)}</e>' for k, v in kept)
        mdf.header.comment = (
            f"<HDcomment><TX>exported by write_mf4.py</TX><common_properties>{props}</common_properties></HDcomment>"
        )
    mdf.save(a.out, overwrite=True, compression=a.compression)


if __name__ == "__main__":
    main()
