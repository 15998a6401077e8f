#!/usr/bin/env python3
"""Robust smoothn (GCV, two components) of `sonoflow` against PyMUST 0.1.9 over grid sizes, in one
process, one thread each (BENCHMARKS.md §11). The field is side_by_side.py's smoothn case at each
size: sin/cos + N(0, 0.1²) noise + 10 % outliers of +3, seed 0.

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 \\
        /tmp/sbs/bin/python bench/python/smoothn_sizes.py [--sizes 64 128 200 256] [--budget 2]

Each time is the best of at least 3 calls and of as many more as fit in `--budget` seconds (at
most 200), on both sides alike; nRMS is sonoflow's result against PyMUST's.
"""
import argparse
import time

import numpy as np
import pymust

import sonoflow as sf

ap = argparse.ArgumentParser()
ap.add_argument("--sizes", type=int, nargs="+", default=[64, 128, 200, 256])
ap.add_argument("--budget", type=float, default=2.0)
a = ap.parse_args()
sf.set_threads(1)


def best(fn):
    times, t0 = [], time.perf_counter()
    while len(times) < 3 or (time.perf_counter() - t0 < a.budget and len(times) < 200):
        t = time.perf_counter()
        r = fn()
        times.append(time.perf_counter() - t)
    return min(times), r


print("| grid | PyMUST 0.1.9 (s) | sonoflow (s) | ratio | nRMS |")
print("|---|---:|---:|---:|---:|")
for n in a.sizes:
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:n, 0:n]
    u = np.sin(xx / 9) * np.cos(yy / 13) + 0.1 * rng.standard_normal((n, n))
    v = np.cos(xx / 11) + 0.1 * rng.standard_normal((n, n))
    for f in (u, v):
        f[rng.random(f.shape) < 0.1] += 3
    tp, (zp, _, _) = best(lambda: pymust.smoothn([u.copy(), v.copy()], isrobust=True))
    ts, (zs, _, _) = best(lambda: sf.smoothn([u, v], isrobust=True))
    zp, zs = np.stack(zp), np.stack(zs)
    e = np.sqrt(np.mean((zs - zp) ** 2) / np.mean(zp**2))
    print(f"| {n} × {n} × 2 | {tp:.4f} | {ts:.4f} | {tp / ts:.1f}× | {e:.1e} |", flush=True)
