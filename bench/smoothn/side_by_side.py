#!/usr/bin/env python3
"""Side-by-side timing: PyMUST 0.1.9 `smoothn` vs the Rust crate `sonoflow-regularise`, same field, same run.

Robust smoothing with automatic S (GCV) of a 2 × NY × NX vector field (smooth flow + N(0, 0.1²) noise
+ 10 % gross outliers uniform in ±2.5, seeded). The field is written to .npy, PyMUST is timed in this
process (best and median of --repeats calls), the Rust example `smoothn_bench` is run on the same
file (release build, one warm-up call, then --repeats calls on a reused workspace), and the script
prints both times, the speed-up and the RMS difference between the two outputs (the MATLAB-faithful
default and, for reference, the PyMUST-compatible flavour).

    /tmp/smoothn-venv/bin/python bench/smoothn/side_by_side.py [--ny 200 --nx 200 --repeats 20]

Run from the repository root (or anywhere: paths are resolved from this file). Set
RAYON_NUM_THREADS to pin the Rust thread count; PyMUST/SciPy run single-threaded.
"""
import argparse
import json
import os
import pathlib
import subprocess
import tempfile
import time

import numpy as np
import pymust

ROOT = pathlib.Path(__file__).resolve().parents[2]


def make_field(ny, nx, seed):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    y /= ny
    x /= nx
    u = np.cos(2 * np.pi * x) * np.sin(np.pi * y)
    v = np.sin(2 * np.pi * x) * np.cos(np.pi * y)
    truth = np.stack([u, v])
    f = truth + 0.1 * rng.standard_normal(truth.shape)
    m = rng.random((ny, nx)) < 0.1
    f[:, m] = (rng.random((2, int(m.sum()))) - 0.5) * 5
    return np.ascontiguousarray(f), truth


def vm_cpu_ticks():
    """Busy CPU ticks of the whole machine (all processes, /proc/stat), to flag a busy machine."""
    with open("/proc/stat") as fh:
        v = [int(x) for x in fh.readline().split()[1:]]
    return v[0] + v[1] + v[2] + v[5] + v[6] + v[7]


class Phase:
    """Measures how much CPU other processes used while a phase ran (in % of one core)."""

    def __enter__(self):
        self.t, self.vm, self.own = time.perf_counter(), vm_cpu_ticks(), os.times()
        return self

    def __exit__(self, *exc):
        wall = time.perf_counter() - self.t
        hz = os.sysconf("SC_CLK_TCK")
        own = os.times()
        own_s = sum(own[i] - self.own[i] for i in range(4))  # user, system, children user, children system
        self.other = max(0.0, (vm_cpu_ticks() - self.vm) / hz - own_s) / wall * 100


def time_pymust(f, repeats):
    times = []
    z = s = None
    for _ in range(repeats):
        t = time.perf_counter()
        z, s, _ = pymust.smoothn([f[0].copy(), f[1].copy()], isrobust=True)
        times.append(time.perf_counter() - t)
    return np.asarray(z).reshape(f.shape), float(s), times


def run_rust(field_path, out_path, repeats, flavour):
    cmd = ["cargo", "run", "--quiet", "--release", "-p", "sonoflow-regularise", "--example", "smoothn_bench", "--",
           "--in", str(field_path), "--out", str(out_path), "--repeats", str(repeats), "--flavour", flavour]
    res = subprocess.run(cmd, cwd=ROOT, check=True, capture_output=True, text=True)
    line = [l for l in res.stdout.splitlines() if l.startswith("{")][-1]
    return json.loads(line), np.load(out_path)


def rms(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ny", type=int, default=200)
    ap.add_argument("--nx", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()

    f, truth = make_field(args.ny, args.nx, args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        np.save(tmp / "field.npy", f)
        # Build first so that compilation is not timed; the example itself times only smoothing.
        subprocess.run(["cargo", "build", "--quiet", "--release", "-p", "sonoflow-regularise", "--example", "smoothn_bench"],
                       cwd=ROOT, check=True)
        time_pymust(f, 1)  # warm-up (imports, SciPy plans)
        with Phase() as ph_py:
            zp, sp, tp = time_pymust(f, args.repeats)
        with Phase() as ph_rs:
            rust, zr = run_rust(tmp / "field.npy", tmp / "rust.npy", args.repeats, "matlab")
        rust_pm, zr_pm = run_rust(tmp / "field.npy", tmp / "rust_pm.npy", args.repeats, "pymust")

    py_med, py_min = 1e3 * float(np.median(tp)), 1e3 * min(tp)
    print(f"field 2 x {args.ny} x {args.nx}, noise 0.1, 10 % outliers, robust, automatic S; {os.cpu_count()} CPUs; "
          f"other processes used {ph_py.other:.0f} % / {ph_rs.other:.0f} % of a core during the PyMUST / Rust timing")
    print(f"PyMUST {pymust.__version__ if hasattr(pymust, '__version__') else '0.1.9'} smoothn: "
          f"median {py_med:.2f} ms, best {py_min:.2f} ms over {args.repeats} (S = {sp:.4g})")
    for name, r in [("Rust (MATLAB flavour)", rust), ("Rust (PyMUST flavour)", rust_pm)]:
        print(f"{name}: median {r['median_ms']:.2f} ms, best {r['min_ms']:.2f} ms, {r['threads']} thread(s) "
              f"(S = {r['s']:.4g}, {r['iterations']} iterations, {r['gcv_evaluations']} GCV evaluations, "
              f"outliers {100 * r['outlier_fraction']:.1f} %)")
        print(f"  speed-up vs PyMUST: median {py_med / r['median_ms']:.1f}x, best {py_min / r['min_ms']:.1f}x")
    print(f"RMS(Rust MATLAB flavour - PyMUST) = {rms(zr, zp):.3e}   (field RMS {np.sqrt(np.mean(zp ** 2)):.3f})")
    print(f"RMS(Rust PyMUST flavour - PyMUST) = {rms(zr_pm, zp):.3e}")
    print(f"RMS error vs truth: PyMUST {rms(zp, truth):.4f}, Rust {rms(zr, truth):.4f}, noisy input {rms(f, truth):.4f}")


if __name__ == "__main__":
    main()
