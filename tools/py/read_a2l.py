#!/usr/bin/env python3
"""Read an A2L file with pya2ldb (an ASAP2 parser independent of the Rust `a2lfile` crate that
writes ours) and write what a calibration tool takes from it as JSON (the parser itself logs on stdout).

Test tooling for `hil-host calibrate` (hil-host/tests/calibrate.rs): the test compares every
object's address, layout, conversion, limits and axes with the image and its JSON.

    read_a2l.py calibration.a2l out.json

pya2ldb imports the file into an SQLite database written beside it, so the file is copied to a
scratch directory first: the A2L given is only read. Its validator's messages (ASAP2 rules:
names defined twice, missing MOD_COMMON entries, EPK) are listed under `diagnostics`.
"""
import json
import logging
import shutil
import sys
import tempfile
from pathlib import Path

import pya2l
from pya2l import model
from pya2l.api.validate import Validator


def record_layout_datatypes(session):
    out = {}
    for r in session.query(model.RecordLayout).all():
        fnc = r.fnc_values
        axis = r.axis_pts_x
        out[r.name] = {
            "fnc_values": fnc.datatype if fnc is not None else None,
            "fnc_index_mode": fnc.indexMode if fnc is not None else None,
            "axis_pts_x": axis.datatype if axis is not None else None,
        }
    return out


def main(argv):
    if len(argv) != 3:
        print("usage: read_a2l.py FILE.a2l OUT.json", file=sys.stderr)
        return 2
    # pya2l logs its progress at INFO; only its findings matter here.
    logging.disable(logging.INFO)
    with tempfile.TemporaryDirectory() as tmp:
        a2l = Path(tmp) / "image.a2l"
        shutil.copyfile(argv[1], a2l)
        session = pya2l.import_a2l(str(a2l))
        diagnostics = [
            {"level": m.type.name, "code": m.diag_code.name, "text": m.text} for m in Validator(session)()
        ]
        layouts = record_layout_datatypes(session)
        compu = [
            {"name": c.name, "type": c.conversionType, "unit": c.unit}
            for c in session.query(model.CompuMethod).all()
        ]
        chars = []
        for c in session.query(model.Characteristic).all():
            chars.append(
                {
                    "name": c.name,
                    "type": c.type,
                    "address": c.address,
                    "record_layout": c.deposit,
                    "conversion": c.conversion,
                    "lower": c.lowerLimit,
                    "upper": c.upperLimit,
                    "matrix_dim": list(c.matrix_dim.numbers) if c.matrix_dim is not None else None,
                    "axes": [
                        {
                            "attribute": ax.attribute,
                            "conversion": ax.conversion,
                            "max_axis_points": ax.maxAxisPoints,
                            "axis_pts_ref": ax.axis_pts_ref.axisPoints if ax.axis_pts_ref is not None else None,
                        }
                        for ax in c.axis_descr
                    ],
                }
            )
        axis_pts = [
            {
                "name": a.name,
                "address": a.address,
                "record_layout": a.depositAttr,
                "conversion": a.conversion,
                "max_axis_points": a.maxAxisPoints,
                "lower": a.lowerLimit,
                "upper": a.upperLimit,
            }
            for a in session.query(model.AxisPts).all()
        ]
        modules = session.query(model.Module).all()
        mod_common = modules[0].mod_common if modules else None
        mod_par = modules[0].mod_par if modules else None
        segments = []
        epk, addr_epk = None, []
        if mod_par is not None:
            segments = [
                {"name": s.name, "address": s.address, "size": s.size, "memory_type": s.memoryType}
                for s in mod_par.memory_segment
            ]
            epk = mod_par.epk.identifier if mod_par.epk is not None else None
            addr_epk = [a.address for a in mod_par.addr_epk]
        out = {
            "diagnostics": diagnostics,
            "byte_order": mod_common.byte_order.byteOrder
            if mod_common is not None and mod_common.byte_order is not None
            else None,
            "epk": epk,
            "addr_epk": addr_epk,
            "memory_segments": segments,
            "record_layouts": layouts,
            "compu_methods": compu,
            "characteristics": chars,
            "axis_pts": axis_pts,
        }
        session.close()
    Path(argv[2]).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
