#!/usr/bin/env python3
"""Generate PyMUST 0.1.9 reference data for the sonoflow-beamform tests (rf2iq, dasmtx, iq2doppler).

    python3 -m venv /tmp/pymust-venv && /tmp/pymust-venv/bin/pip install pymust==0.1.9
    /tmp/pymust-venv/bin/python bench/beamform/pymust_reference.py [OUT_DIR]

OUT_DIR defaults to nodes/beamform/tests/data. Written (all small, fixed seeds):
  rf.npy            float32 (n_samples, 128): PyMUST simus of 40 scatterers, paper probe, 0° plane wave
  iq_<case>.npy     complex64 (n_samples, len(iq_elements)): rf2iq outputs on a subset of elements
  das_<case>.npy    complex64 (nz, nx): dasmtx(1j*[nl, nc], X, Z, delays, param) @ IQ (IQ = rf2iq case "bw")
  packet.npy        complex64 (nz, nx, n): synthetic I/Q packet (the values PyMUST got, upcast)
  dop_<case>_v.npy, dop_<case>_var.npy  float64 (nz, nx): iq2doppler outputs
  reference.json    parameters of every case
The RXangle case uses dasmtx with its one-line bug patched (line 557: `z.tanRX.flatten()` ->
`z*tanRX` as a column, pymust-notes §7); nothing else of dasmtx is changed.
"""
import inspect
import json
import os
import sys

import numpy as np
import pymust
import importlib

dasmtx_mod = importlib.import_module("pymust.dasmtx")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "nodes", "beamform", "tests", "data")
os.makedirs(OUT, exist_ok=True)


def paper_param():
    p = pymust.utils.Param()
    p.fc, p.pitch, p.kerf, p.Nelements, p.bandwidth, p.TXnow, p.c = 5e6, 0.30e-3, 35e-6, 128, 75, 6, 1540
    p.width = p.pitch - p.kerf
    p.fs = 20e6
    return p


def dasmtx_fixed():
    """dasmtx with line 557 fixed (z.tanRX -> z*tanRX, both angle arrays as columns)."""
    src = inspect.getsource(dasmtx_mod.dasmtx)
    assert "z.tanRX.flatten()" in src
    src = src.replace("np.abs(dxT-z.tanRX.flatten())<=(z/cosRX.flatten()/2/fNum)",
                      "np.abs(dxT-z*tanRX.reshape((-1, 1)))<=(z/cosRX.reshape((-1, 1))/2/fNum)")
    ns = dict(dasmtx_mod.__dict__)
    exec(src, ns)
    return ns["dasmtx"]


meta = {}
rng = np.random.default_rng(44)
p = paper_param()
n_scat = 40
x = rng.uniform(-6e-3, 6e-3, n_scat).astype(np.float32)
z = rng.uniform(8e-3, 22e-3, n_scat).astype(np.float32)
rc = rng.standard_normal(n_scat).astype(np.float32)
dels0 = np.abs(pymust.txdelay(p, 0.0))
rf, _ = pymust.simus(x.reshape(1, -1), z.reshape(1, -1), rc.reshape(1, -1), dels0, p)
rf = rf.astype(np.float32)
np.save(f"{OUT}/rf.npy", np.ascontiguousarray(rf))
nl, nc = rf.shape
iq_elements = [0, 17, 63, 64, 127]
meta["rf"] = {"fc": p.fc, "fs": p.fs, "c": p.c, "pitch": p.pitch, "Nelements": 128, "n_samples": nl,
              "iq_elements": iq_elements, "x": x.tolist(), "z": z.tolist(), "rc": rc.tolist()}

# --- rf2iq: three call forms -------------------------------------------------------------------
cases = {}
q = paper_param()
iq_bw = pymust.rf2iq(rf, q)  # Wn = bandwidth/100*fc/fs, t0 = 0
cases["bw"] = {"fc": 5e6, "fs": 20e6, "bandwidth": 75.0, "t0": 0.0, "iq": iq_bw}
iq_nobw = pymust.rf2iq(rf, 20e6, 5e6)  # Wn = min(2 fc/fs, 0.5)
cases["nobw"] = {"fc": 5e6, "fs": 20e6, "bandwidth": None, "t0": 0.0, "iq": iq_nobw}
q = paper_param()
q.bandwidth = 60
q.t0 = 2.5e-6
iq_t0 = pymust.rf2iq(rf, q)
cases["t0"] = {"fc": 5e6, "fs": 20e6, "bandwidth": 60.0, "t0": 2.5e-6, "iq": iq_t0}
meta["rf2iq"] = {}
for name, cse in cases.items():
    np.save(f"{OUT}/iq_{name}.npy", np.ascontiguousarray(cse["iq"][:, iq_elements]).astype(np.complex64))
    meta["rf2iq"][name] = {k: v for k, v in cse.items() if k != "iq"}

# --- dasmtx: several transmits / apertures on a small grid ---------------------------------------
nx, nz = 41, 50
xg = np.linspace(-6e-3, 6e-3, nx)
zg = np.linspace(8e-3, 22e-3, nz)
X, Z = np.meshgrid(xg, zg)
meta["grid"] = {"x0": xg[0], "z0": zg[0], "dx": xg[1] - xg[0], "dz": zg[1] - zg[0], "nx": nx, "nz": nz}
das_cases = {
    "pw0_f3": {"tx": ("plane", 0.0), "fnumber": 3.0},
    "pw0_full": {"tx": ("plane", 0.0), "fnumber": 0.0},
    "pw10_f2": {"tx": ("plane", np.deg2rad(10.0)), "fnumber": 2.0},
    "div_f1.5": {"tx": ("diverging", 1e-3, -10e-3), "fnumber": 1.5},
    "pw0_f3_rx15": {"tx": ("plane", 0.0), "fnumber": 3.0, "rxangle": np.deg2rad(15.0)},
}
meta["das"] = {}
for name, cse in das_cases.items():
    q = paper_param()
    q.fnumber = cse["fnumber"]
    q.t0 = np.zeros(1)
    tx = cse["tx"]
    if tx[0] == "plane":
        d = pymust.txdelay(q, tx[1])
    else:
        d = pymust.txdelay(tx[1], tx[2], q)
    d = np.abs(d)  # -0.0 entries of the 0° law
    q.TXdelay = d
    fn = pymust.dasmtx
    if "rxangle" in cse:
        q.RXangle = cse["rxangle"]
        fn = dasmtx_fixed()
    M = fn(1j * np.array([nl, nc]), X, Z, d, q, "linear")
    img = (M @ iq_bw.flatten(order="F")).reshape(X.shape, order="F")
    np.save(f"{OUT}/das_{name}.npy", np.ascontiguousarray(img).astype(np.complex64))
    meta["das"][name] = {"tx": [tx[0]] + [float(v) for v in tx[1:]], "fnumber": cse["fnumber"],
                         "rx_angle": float(cse.get("rxangle", 0.0)), "delays": d.flatten().tolist(),
                         "nnz": int(M.nnz)}

# --- iq2doppler on a synthetic packet ------------------------------------------------------------
pz, px, pn = 24, 20, 12
ph = rng.uniform(-np.pi, np.pi, (pz, px, 1)) + np.arange(pn).reshape(1, 1, -1) * rng.uniform(-2.5, 2.5, (pz, px, 1))
packet = (rng.rayleigh(1.0, (pz, px, 1)) * np.exp(1j * ph) + 0.3 * (rng.standard_normal((pz, px, pn))
          + 1j * rng.standard_normal((pz, px, pn)))).astype(np.complex64)
np.save(f"{OUT}/packet.npy", packet)
pk = packet.astype(np.complex128)
meta["doppler"] = {"shape": [pz, px, pn], "fc": 5e6, "c": 1540.0, "PRF": 10e3, "cases": {}}
for name, (M, lag) in {"m1_l1": (1, 1), "m53_l1": (np.array([5, 3]), 1), "m44_l2": (np.array([4, 4]), 2)}.items():
    q = paper_param()
    q.PRF = 10e3
    v, var = pymust.iq2doppler(pk, q, M, lag)
    np.save(f"{OUT}/dop_{name}_v.npy", v)
    np.save(f"{OUT}/dop_{name}_var.npy", var)
    meta["doppler"]["cases"][name] = {"M": list(np.broadcast_to(M, 2).astype(int).tolist()), "lag": lag}

with open(f"{OUT}/reference.json", "w") as f:
    json.dump(meta, f, indent=1)
total = sum(os.path.getsize(os.path.join(OUT, n)) for n in os.listdir(OUT))
print(f"wrote {OUT}: {total / 1e6:.2f} MB, rf {rf.shape}")
