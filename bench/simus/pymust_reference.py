#!/usr/bin/env python3
"""Generate PyMUST 0.1.9 reference RF for the sonoflow-simus tests.

Installs nothing. Run with a Python that has pymust 0.1.9, e.g.

    python3 -m venv /tmp/pymust-venv && /tmp/pymust-venv/bin/pip install pymust==0.1.9
    /tmp/pymust-venv/bin/python bench/simus/pymust_reference.py [OUT_DIR]

OUT_DIR defaults to nodes/simus/tests/data (relative to the repository root). For each scene
a sub-directory is written with
  x.npy, z.npy, rc.npy  float32 (n,) scatterer positions (m) and amplitudes, exactly as PyMUST got them
  rf.npy                float32 (n_samples, n_elements), PyMUST's simus() output
  scene.json            the MUST param/options used (TXdelay as the float32 values PyMUST used,
                        NaN written as null), plus PyMUST's frequency grid (Nf, kept band, df)
Fixed seeds (numpy default_rng); the scenes are small so the committed data stays < 3 MB.
Optional argument after OUT_DIR: a scene name to regenerate only that scene.
"""
import json
import os
import sys
import time

import numpy as np
import pymust


def paper_param(n_elements=128):
    """The paper probe (Shahriari & Garcia 2018): 5 MHz, pitch 0.30 mm, kerf 35 um, 75 %, TXnow 6."""
    p = pymust.utils.Param()
    p.fc = 5e6
    p.pitch = 0.30e-3
    p.kerf = 35e-6
    p.width = p.pitch - p.kerf
    p.Nelements = n_elements
    p.bandwidth = 75
    p.TXnow = 6
    p.c = 1540
    p.baffle = "soft"
    return p


def preset_param(name):
    p = pymust.getparam(name)
    if "width" not in p:
        p.width = p.pitch - p.kerf
    p.c = 1540
    return p


def random_scene(rng, n, xlim, zlim):
    x = rng.uniform(xlim[0], xlim[1], n).astype(np.float32)
    z = rng.uniform(zlim[0], zlim[1], n).astype(np.float32)
    rc = rng.standard_normal(n).astype(np.float32)
    return x, z, rc


def scenes():
    out = []
    # 1. one scatterer, 128 elements, 0 deg plane wave, soft baffle
    p = paper_param(128)
    dels = pymust.txdelay(p, 0.0)
    out.append(("single_pw0", p, np.array([2e-3], np.float32), np.array([15e-3], np.float32),
                np.array([1.0], np.float32), dels, {}))
    # 2. 50 scatterers, 64 elements, 10 deg plane wave, soft baffle, fs = 22 MHz (non-integer fs/2fc)
    rng = np.random.default_rng(1)
    p = paper_param(64)
    p.fs = 22e6
    dels = pymust.txdelay(p, np.deg2rad(10.0))
    x, z, rc = random_scene(rng, 50, (-8e-3, 8e-3), (5e-3, 20e-3))
    out.append(("s50_pw10_fs22", p, x, z, rc, dels, {}))
    # 3. 500 scatterers, 64 elements, focused at (0, 15 mm), rigid baffle, 0.5 dB/cm/MHz,
    #    Hann transmit apodisation
    rng = np.random.default_rng(2)
    p = paper_param(64)
    p.baffle = "rigid"
    p.attenuation = 0.5
    p.TXapodization = np.hanning(66)[1:-1].reshape(1, -1).astype(np.float64)
    dels = pymust.txdelay(0.0, 15e-3, p)
    x, z, rc = random_scene(rng, 500, (-8e-3, 8e-3), (5e-3, 20e-3))
    out.append(("s500_focused_rigid_att", p, x, z, rc, dels, {}))
    # 4. 200 scatterers (2 of them behind the array, z < 0), 64 elements, diverging wave
    #    (virtual source at z = -10 mm), numeric baffle 1.7, two elements switched off (NaN delay)
    rng = np.random.default_rng(3)
    p = paper_param(64)
    p.baffle = 1.7
    dels = pymust.txdelay(2e-3, -10e-3, p)
    dels[0, 5] = np.nan
    dels[0, 40] = np.nan
    x, z, rc = random_scene(rng, 200, (-12e-3, 12e-3), (2e-3, 18e-3))
    z[7] = -1e-3
    z[11] = -0.2e-3
    out.append(("s200_diverging_baffle17", p, x, z, rc, dels, {}))
    # 5. L11-5v preset (TXnow 1, 77 %), 30 scatterers, -5 deg plane wave, dB threshold -60
    rng = np.random.default_rng(4)
    p = preset_param("L11-5v")
    dels = pymust.txdelay(p, np.deg2rad(-5.0))
    x, z, rc = random_scene(rng, 30, (-10e-3, 10e-3), (3e-3, 12e-3))
    out.append(("l11_5v_s30_pwm5", p, x, z, rc, dels, {"dBThresh": -60}))
    # 6. P4-2v preset (phased array, M = 1 sub-element), 40 scatterers, 0 deg plane wave
    rng = np.random.default_rng(5)
    p = preset_param("P4-2v")
    dels = pymust.txdelay(p, 0.0)
    x, z, rc = random_scene(rng, 40, (-15e-3, 15e-3), (10e-3, 25e-3))
    out.append(("p4_2v_s40_pw0", p, x, z, rc, dels, {}))
    # 7. 26 000 scatterers (the paper's count; 64 elements and a 20 x 20 mm box to keep the data
    #    small), 0 deg plane wave
    rng = np.random.default_rng(6)
    p = paper_param(64)
    dels = pymust.txdelay(p, 0.0)
    x, z, rc = random_scene(rng, 26000, (-10e-3, 10e-3), (10e-3, 30e-3))
    out.append(("s26000_paper64_pw0", p, x, z, rc, dels, {}))
    return out


def jsonable(v):
    if isinstance(v, np.ndarray):
        return [None if not np.isfinite(a) else float(a) for a in v.ravel()]
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def main():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    out_dir = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "nodes", "simus", "tests", "data")
    os.makedirs(out_dir, exist_ok=True)
    only = sys.argv[2] if len(sys.argv) > 2 else None
    for name, p, x, z, rc, dels, opts in scenes():
        if only is not None and name != only:
            continue
        dels = np.abs(dels.astype(np.float64))  # txdelay gives -0.0 for zero delays
        used_delays = dels.astype(np.float32)  # pfield casts the delays to float32
        apod = np.array(p.get("TXapodization", np.ones((1, p.Nelements))), np.float64).ravel()
        param_json = {k: jsonable(p[k]) for k in ("fc", "pitch", "width", "kerf", "Nelements", "bandwidth",
                                                 "baffle", "c", "TXnow") if k in p}
        param_json["fs"] = float(p.get("fs", 4 * p.fc))
        param_json["attenuation"] = float(p.get("attenuation", 0.0))
        param_json["TXdelay"] = jsonable(used_delays.astype(np.float64))
        param_json["TXapodization"] = jsonable(apod)
        options = pymust.utils.Options()
        for k, v in opts.items():
            options[k] = v
        t = time.perf_counter()
        rf, spect = pymust.simus(x.reshape(1, -1), z.reshape(1, -1), rc.reshape(1, -1), dels, p, options)
        elapsed = time.perf_counter() - t
        rows = np.nonzero(np.any(spect != 0, axis=1))[0]
        nf = spect.shape[0]
        meta = {
            "scene": name,
            "generator": "bench/simus/pymust_reference.py, pymust " + getattr(pymust, "__version__", "0.1.9"),
            "param": param_json,
            "options": {"dBThresh": float(opts.get("dBThresh", -100))},
            "n_scatterers": int(x.size),
            "pymust": {"Nf": int(nf), "band_first": int(rows[0]), "band_last": int(rows[-1]),
                       "df": float(2 * p.fc / (nf - 1)), "n_samples": int(rf.shape[0]),
                       "seconds": elapsed},
        }
        d = os.path.join(out_dir, name)
        os.makedirs(d, exist_ok=True)
        np.save(os.path.join(d, "x.npy"), x.astype(np.float32))
        np.save(os.path.join(d, "z.npy"), z.astype(np.float32))
        np.save(os.path.join(d, "rc.npy"), rc.astype(np.float32))
        np.save(os.path.join(d, "rf.npy"), np.ascontiguousarray(rf.astype(np.float32)))
        with open(os.path.join(d, "scene.json"), "w") as f:
            json.dump(meta, f, indent=1)
        print(f"{name}: {x.size} scatterers, RF {rf.shape} {rf.dtype}, Nf {nf}, band {rows[0]}..{rows[-1]}, "
              f"{elapsed:.2f} s")


if __name__ == "__main__":
    main()
