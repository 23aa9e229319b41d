"""The DATA-FORMAT CSV log as the peer scripts read it: `# key: value` metadata lines, a header
row, then numbers. Shared by peer_evvt_baseline.py, peer_vacuum_baseline.py and
peer_ehvva_baseline.py (Python puts a script's own directory on sys.path, so they find it)."""
import numpy as np


def read_log(path):
    """(metadata dict, {column name: numpy array})."""
    meta, header, rows = {}, None, []
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                key, _, value = line[1:].partition(":")
                meta[key.strip()] = value.strip()
            elif header is None:
                header = line.strip().split(",")
            elif line.strip():
                rows.append([float(v) for v in line.split(",")])
    data = np.array(rows)
    return meta, {name: data[:, i] for i, name in enumerate(header)}
