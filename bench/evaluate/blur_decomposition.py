#!/usr/bin/env python3
"""Splits the error of a recorded vector field into blur and the rest (an independent check of the
evaluator's wall-distance table; README, "The paper's experiment").

The true field of the first packet is blurred by a Gaussian *inside the vessel mask*
(b = G*(m v) / G*m: the Doppler estimate is a power-weighted mean over the resolution cell and
there are no scatterers outside the vessel). For each (σ_z, σ_x) it prints the blurred truth's own
error against the truth and the estimate's error against the blurred truth (|e|75 in % of v_max,
over the truth mask eroded by 2 px as the evaluator does), and the gain by wall-distance ring.

usage: blur_decomposition.py RECORDING.mcap [TOPIC ...]   (default: regularised regularised_sf)
needs: pip install mcap numpy scipy
"""
import sys

import numpy as np
from mcap.reader import make_reader
from scipy import ndimage

MSG_HEADER = [
    ("seq", "<u8"), ("frame_id", "<u8"), ("t_valid", "<f8"), ("t_pub_ns", "<u8"),
    ("compute_ns", "<u8"), ("incarnation", "<u4"), ("flags", "<u4"), ("source_id", "<u4"),
    ("schema_minor", "<u4"), ("reserved", "<u4", (2,)),
]
GRID = [("x0", "<f8"), ("z0", "<f8"), ("dx", "<f8"), ("dz", "<f8"), ("nx", "<u4"), ("nz", "<u4")]
VF = np.dtype([
    ("common", np.dtype(MSG_HEADER)), ("grid", np.dtype(GRID)), ("s", "<f8"), ("outl", "<f8"),
    ("clutter_cutoff", "<f8"), ("clutter_removed_energy", "<f8"),
    ("n_planes", "<u4"), ("source", "<u4"), ("packet", "<u4"), ("conv", "<u4"),
    ("clutter_filter", "<u4"), ("clutter_order", "<u4"), ("n_looks", "<u4"), ("rejected_looks", "<u4"),
    ("plane_ids", "<u4", (8,)),
])
assert VF.itemsize == 200  # VectorFieldHeaderV2


def decode(data):
    # CDR: 4-byte encapsulation, the header, a u32 length, then the f32 planes
    h = np.frombuffer(data, dtype=VF, count=1, offset=4)[0]
    n = int(np.frombuffer(data, dtype="<u4", count=1, offset=4 + VF.itemsize)[0])
    p = np.frombuffer(data, dtype="<f4", count=n, offset=8 + VF.itemsize)
    return h, p.reshape(int(h["n_planes"]), int(h["grid"]["nz"]), int(h["grid"]["nx"]))


def first_packet(path, topics):
    out = {}
    with open(path, "rb") as f:
        for _, ch, m in make_reader(f).iter_messages(topics=list(topics)):
            h, p = decode(m.data)
            if int(h["packet"]) == 0 and ch.topic not in out:
                out[ch.topic] = (h, p.astype(float))
    return out


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    topics = sys.argv[2:] or ["regularised", "regularised_sf"]
    d = first_packet(sys.argv[1], ["truth", *topics])
    if "truth" not in d:
        sys.exit("no truth topic in the recording")
    h, t = d["truth"]
    m = t[2] > 0.5
    g = h["grid"]
    px = float(g["dz"])
    vmax = np.hypot(t[0], t[1])[m].max()
    ev = ndimage.binary_erosion(m, structure=np.ones((3, 3), bool), iterations=2)
    # distance to the nearest pixel outside the vessel, as the evaluator's bands
    wall = ndimage.distance_transform_edt(m, sampling=(float(g["dz"]), float(g["dx"])))
    rings = [ev & (wall >= a) & (wall < b) for a, b in [(0, 1e-3), (1e-3, 2e-3), (2e-3, 3e-3), (3e-3, np.inf)]]

    def blur(f, sz, sx):
        num = ndimage.gaussian_filter(np.where(m, f, 0.0), (sz, sx), mode="constant")
        den = ndimage.gaussian_filter(m.astype(float), (sz, sx), mode="constant")
        return np.where(den > 1e-9, num / np.maximum(den, 1e-12), 0.0)

    def p75(a, b, c):
        return 100 * np.percentile(np.abs((a[c] - b[c])[ev]), 75) / vmax

    def gains(v, c):
        return " ".join("%.3f" % ((v[c][r] * t[c][r]).sum() / (t[c][r] ** 2).sum()) for r in rings)

    print(f"grid {int(g['nx'])} x {int(g['nz'])}, {1e3 * px:.2f} mm; v_max {vmax:.3f} m/s; ring gains 0-1, 1-2, 2-3, >= 3 mm from the wall")
    for top in topics:
        if top not in d:
            continue
        v = d[top][1]
        print(f"{top}: |e|75 x {p75(v, t, 0):.2f} %, z {p75(v, t, 1):.2f} %; ring gains x {gains(v, 0)}, z {gains(v, 1)}")
    for sz_mm, sx_mm in [(0.4, 0.4), (0.6, 0.4), (0.8, 0.4)]:
        b = np.stack([blur(t[0], sz_mm * 1e-3 / px, sx_mm * 1e-3 / px), blur(t[1], sz_mm * 1e-3 / px, sx_mm * 1e-3 / px)])
        line = f"blur sz {sz_mm} mm sx {sx_mm} mm: ring gains x {gains(b, 0)}, z {gains(b, 1)}; blurred-truth |e|75 x {p75(b, t, 0):.2f} z {p75(b, t, 1):.2f}"
        for top in topics:
            if top in d:
                v = d[top][1]
                line += f"; {top}-blurred x {p75(v, b, 0):.2f} z {p75(v, b, 1):.2f}"
        print(line)


if __name__ == "__main__":
    main()
