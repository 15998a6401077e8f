"""Scatterers off the imaging plane (issue 22 item 2): sonoflow.simus(x, y, z, RC, delaysTX, param)
with MUST's elevation model (3-D distances, the multi-Gaussian beam of the element height and
elevation focus on transmit and receive) against PyMUST 0.1.9 (nRMS ≤ 1e-4) on two probes, and
what it must do independently of PyMUST."""
import copy

import numpy as np
import pymust
import pytest

import sonoflow as sf


def nrms(a, b):
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def scene(seed, n, half_width, z0, z1, y_max):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-half_width, half_width, n), rng.uniform(-y_max, y_max, n), rng.uniform(z0, z1, n),
            rng.rayleigh(1.0, n))


@pytest.mark.parametrize("case", ["L11-5v steered", "L12-3v focused", "P4-2v diverging", "L11-5v planar",
                                  "P4-2v no elevation focus", "L12-3v other height"])
def test_simus_with_elevation_matches_pymust(case):
    probe, what = case.split(" ", 1)
    p = pymust.getparam(probe)
    deep = probe == "P4-2v"
    x, y, z, rc = scene(len(case), 40, 15e-3 if deep else 7e-3, 8e-3, 60e-3 if deep else 30e-3, 2.5e-3)
    d = pymust.txdelay(p, np.deg2rad(6))
    if what == "focused":
        d = pymust.txdelay(2e-3, 20e-3, p)
    elif what == "diverging":
        d = pymust.txdelay(0.0, -20e-3, p)
    elif what == "planar":
        y = np.full_like(x, 1e-8)  # MUST's branch for |y| below float32's epsilon everywhere
    elif what == "no elevation focus":
        del p["focus"]
    elif what == "other height":
        p.height, p.focus = 3e-3, 30e-3
    RF, _ = pymust.simus(x, y, z, rc, d, copy.deepcopy(p))
    rf, _ = sf.simus(x, y, z, rc, d, copy.deepcopy(p))
    assert rf.shape == RF.shape
    print(f"{case}: nRMS {nrms(rf, RF):.2e}")
    assert nrms(rf, RF) <= 1e-4


def test_elevation_is_symmetric_and_off_plane_echoes_are_weaker():
    p = pymust.getparam("L11-5v")  # height 5 mm, elevation focus 18 mm
    d = pymust.txdelay(p, 0.0)
    x, z, rc = np.array([0.0, 1e-3]), np.array([18e-3, 22e-3]), np.array([1.0, 1.0])
    on, _ = sf.simus(x, np.full(2, 1e-8), z, rc, d, copy.deepcopy(p))
    up, _ = sf.simus(x, np.full(2, 1.5e-3), z, rc, d, copy.deepcopy(p))
    down, _ = sf.simus(x, np.full(2, -1.5e-3), z, rc, d, copy.deepcopy(p))
    assert np.array_equal(up, down)
    # 1.5 mm off the plane at the elevation focus (beam width λ·z/h ≈ 0.7 mm): far weaker
    assert np.linalg.norm(up) < 0.2 * np.linalg.norm(on), (np.linalg.norm(up), np.linalg.norm(on))
    # y = 0 everywhere is the 2-D model, bit for bit
    flat, _ = sf.simus(x, z, rc, d, copy.deepcopy(p))
    zero, _ = sf.simus(x, np.zeros(2), z, rc, d, copy.deepcopy(p))
    assert np.array_equal(flat, zero)


def test_bad_elevation_inputs():
    p = pymust.getparam("L11-5v")
    d = pymust.txdelay(p, 0.0)
    x, z, rc = np.zeros(3), np.full(3, 0.02), np.ones(3)
    with pytest.raises(ValueError, match="y"):
        sf.simus(x, np.zeros(2), z, rc, d, copy.deepcopy(p))
    with pytest.raises(ValueError, match="y"):
        sf.simus(x, np.full(3, np.nan), z, rc, d, copy.deepcopy(p))
    q = copy.deepcopy(p)
    q.height = -1e-3
    with pytest.raises(ValueError, match="height"):
        sf.simus(x, np.full(3, 1e-3), z, rc, d, q)
