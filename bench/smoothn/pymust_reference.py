#!/usr/bin/env python3
"""Reference outputs of PyMUST 0.1.9 `smoothn` for the Rust crate `sonoflow-regularise`.

Writes small cases (inputs, weights, outputs as float64 .npy, C order, shape (components, ny, nx)
or (components, *grid)) and `cases.json` (parameters, S and exitflag returned by PyMUST) to
nodes/regularise/tests/data/. The Rust test `tests/pymust_reference.rs` reads them.

Run with a Python that has PyMUST 0.1.9:
    python3 -m venv /tmp/smoothn-venv && /tmp/smoothn-venv/bin/pip install pymust==0.1.9
    /tmp/smoothn-venv/bin/python bench/smoothn/pymust_reference.py
"""
import json
import pathlib

import numpy as np
import pymust

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "nodes" / "smoothn" / "tests" / "data"


def field(ny, nx, ncomp, seed, noise=0.1, outliers=0.0, missing=0.0):
    """Smooth vector field + Gaussian noise + uniform gross outliers (+ NaN holes), shape (ncomp, ny, nx)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:ny, 0:nx].astype(float)
    y /= ny
    x /= nx
    base = [np.cos(2 * np.pi * x) * np.sin(np.pi * y), np.sin(2 * np.pi * x) * np.cos(1.5 * np.pi * y) + 0.3]
    f = np.stack(base[:ncomp]) + noise * rng.standard_normal((ncomp, ny, nx))
    if outliers > 0:
        m = rng.random((ny, nx)) < outliers
        f[:, m] = (rng.random((ncomp, int(m.sum()))) - 0.5) * 5
    if missing > 0:
        m = rng.random((ny, nx)) < missing
        f[:, m] = np.nan
    return f


def run(name, y, cases, weights=None, **kw):
    """Calls PyMUST on a copy of y (it overwrites NaNs in its input) and stores everything."""
    args = [c.copy() for c in y] if y.shape[0] > 1 else y[0].copy()
    z, s, exitflag = pymust.smoothn(args, W=None if weights is None else weights.copy(), **kw)
    z = np.asarray(z, dtype=float).reshape(y.shape)
    np.save(OUT / f"{name}_in.npy", np.ascontiguousarray(y))
    if weights is not None:
        np.save(OUT / f"{name}_w.npy", np.ascontiguousarray(weights))
    np.save(OUT / f"{name}_out.npy", np.ascontiguousarray(z))
    spacing = kw.get("Spacing")
    cases.append(
        {
            "name": name,
            "shape": list(y.shape[1:]),
            "components": int(y.shape[0]),
            "weights": weights is not None,
            "s_given": kw.get("S"),
            "robust": bool(kw.get("isrobust", False)),
            "order": int(kw.get("Order", 2)),
            "spacing": None if spacing is None else [float(v) for v in spacing],
            "s": float(s),
            "exitflag": bool(exitflag),
        }
    )
    print(f"{name:28s} shape {y.shape}  S = {float(s):.6g}  exitflag = {bool(exitflag)}")


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    cases = []
    ny, nx = 40, 32
    clean = field(ny, nx, 2, seed=1)
    dirty = field(ny, nx, 2, seed=2, outliers=0.1)
    # Fixed S, no robust weights, no missing data: defined exactly, must agree to rounding.
    run("fixed_s_2d", clean, cases, S=10.0)
    run("fixed_s_2d_order1", clean, cases, S=3.0, Order=1)
    run("fixed_s_2d_spacing", clean, cases, S=5.0, Spacing=np.array([1.0, 2.5]))
    run("fixed_s_1d", field(1, 50, 1, seed=3)[:, 0, :], cases, S=20.0)
    f3 = np.random.default_rng(4).standard_normal((1, 9, 8, 7))
    run("fixed_s_3d", f3, cases, S=2.0)
    # Where PyMUST deviates from MATLAB.
    run("robust_fixed_s", dirty, cases, S=10.0, isrobust=True)
    run("auto_s", clean, cases)
    run("robust_auto_s", dirty, cases, isrobust=True)
    w = np.random.default_rng(5).random((ny, nx))
    w[w < 0.1] = 0.0
    run("weighted_fixed_s", clean[:1], cases, weights=w, S=10.0)
    run("missing_robust_auto_s", field(ny, nx, 2, seed=6, outliers=0.05, missing=0.05), cases, isrobust=True)
    (OUT / "cases.json").write_text(json.dumps({"pymust": pymust.__version__ if hasattr(pymust, "__version__") else "0.1.9",
                                                "numpy": np.__version__, "cases": cases}, indent=1) + "\n")
    total = sum(p.stat().st_size for p in OUT.iterdir())
    print(f"wrote {len(cases)} cases, {total / 1024:.0f} KiB, to {OUT}")


if __name__ == "__main__":
    main()
