"""sonoflow.genscat against PyMUST 0.1.9's genscat: both are random, so the comparison is of what
the distribution must have — the region, the count (the jittered grid makes it nearly fixed), the
mean nearest-neighbour distance and the amplitude statistics — on two probes, plus what sonoflow
adds (seed, inclusions, z0) and bad inputs."""
import math

import numpy as np
import pymust
import pytest
from scipy.spatial import cKDTree

import sonoflow as sf


def nn_mean(x, z):
    d, _ = cKDTree(np.c_[x, z]).query(np.c_[x, z], k=2)
    return d[:, 1].mean()


@pytest.mark.parametrize("probe,roi", [("L11-5v", [0.02, 0.012]), ("P4-2v", [0.04, 0.05])])
def test_distribution_matches_pymust(probe, roi):
    p = pymust.getparam(probe)
    meandist = (p.c or 1540.0) / (p.fc * (1 + p.bandwidth / 200))  # MUST's defaults: c 1540
    np.random.seed(11)
    xs, ys, zs, RC = pymust.genscat(np.array(roi), p)
    x, y, z, rc = sf.genscat(roi, p, seed=5)
    # the count: the same grid and jitter, so only the border nodes differ (each kept with
    # probability ~1/2: variance ~perimeter/(4a) per draw); within 5 sd of the difference
    a = meandist / math.sqrt(2 / 5)
    sd = math.sqrt(2 * 2 * (roi[0] + roi[1]) / a / 4)
    assert abs(len(x) - len(xs)) < 5 * sd, (len(x), len(xs), sd)
    assert abs(len(x) / (0.4 / meandist**2 * roi[0] * roi[1]) - 1) < 0.02
    # the region
    assert x.min() > -roi[0] / 2 and x.max() < roi[0] / 2 and z.min() > 0 and z.max() < roi[1]
    assert np.all(y == 0) and y.shape == x.shape
    # MUST's claim: mean nearest-neighbour distance ≈ meandist; both sides within 2 % of each other
    a, b = nn_mean(x, z), nn_mean(xs, zs)
    assert abs(a / b - 1) < 0.02, (a, b, meandist)
    assert abs(a / meandist - 1) < 0.05
    # amplitudes: Rayleigh of mean 1 on both sides (σ of the mean 0.52/√n < 1 %)
    for r in (rc, RC):
        assert abs(r.mean() - 1) < 0.03
        assert abs(np.mean(r**2) - 4 / np.pi) < 0.06
    assert x.dtype == np.float64 and rc.dtype == np.float64


def test_image_levels_and_aspect_match_pymust():
    # two halves: 1 (left) and 0.25 (right) of a 20 × 40 image; g = 30 dB → right 10^(1.5·(0.25 − 1))
    I = np.ones((20, 40))
    I[:, 20:] = 0.25
    np.random.seed(3)
    xs, _, zs, RC = pymust.genscat(np.array([np.nan, 0.01]), 1e-4, I, 30)
    x, _, z, rc = sf.genscat([np.nan, 0.01], 1e-4, I, 30, seed=3)
    # the width from the image's aspect ratio: 0.02 on both sides
    assert abs(x.max() - xs.max()) < 2e-4 and abs(x.min() - xs.min()) < 2e-4
    expect = 10 ** (30 / 20 * (0.25 - 1))
    right = (x > 0.003) & (x < 0.008)
    right_pm = (xs > 0.003) & (xs < 0.008)
    # sonoflow: Rayleigh of mean 1 × the level; PyMUST: hypot of two uniform numbers/√(π/2)
    # (mean 0.7652/1.2533 = 0.6106) × the level
    assert abs(rc[right].mean() / expect - 1) < 0.04
    assert abs(RC[right_pm].mean() / expect / 0.6106 - 1) < 0.04
    left = (x < -0.003) & (x > -0.008)
    assert abs(rc[left].mean() - 1) < 0.04


def test_seed_inclusions_and_z0():
    a = sf.genscat([0.01, 0.01], 1e-4, seed=1)
    b = sf.genscat([0.01, 0.01], 1e-4, seed=1)
    c = sf.genscat([0.01, 0.01], 1e-4, seed=2)
    for u, v in zip(a, b):
        np.testing.assert_array_equal(u, v)
    n = min(len(a[0]), len(c[0]))
    assert np.mean(a[0][:n] != c[0][:n]) > 0.99
    inc = [{"x": -0.002, "z": 0.025, "radius": 0.0015},
           {"x": 0.002, "z": 0.025, "radius": 0.0015, "level_db": 6.0},
           {"x": 0.0, "z": 0.021, "radius": 0.001, "level_db": -math.inf}]
    x, _, z, rc = sf.genscat([0.01, 0.01], 1e-4, seed=4, inclusions=inc, z0=0.02)
    assert z.min() > 0.02 and z.max() < 0.03
    assert not np.any(np.hypot(x + 0.002, z - 0.025) <= 0.0015)
    assert not np.any(np.hypot(x, z - 0.021) <= 0.001)
    bright = np.hypot(x - 0.002, z - 0.025) <= 0.0015
    bg = ~bright & (np.hypot(x + 0.002, z - 0.025) > 0.0015)
    db = 10 * np.log10(np.mean(rc[bright] ** 2) / np.mean(rc[bg] ** 2))
    assert abs(db - 6) < 1.0, db


@pytest.mark.parametrize("args,kw,exc,needle", [
    (([0.01, 0.01, 0.01], 1e-4), {}, ValueError, "3-D"),
    (([0.01], 1e-4), {}, ValueError, "roidim"),
    (([0.01, 0.01], 0.0), {}, ValueError, "meandist"),
    (([0.01, 0.01], "x"), {}, TypeError, "meandist"),
    (([0.01, 0.01], {"c": 1540}), {}, ValueError, "param.fc"),
    (([0.01, 0.01], {"fc": 5e6, "bandwidth": 250}), {}, ValueError, "param.bandwidth"),
    (([np.nan, 0.01], 1e-4), {}, ValueError, "roidim[0]"),
    (([0.01, 0.01], 1e-4, -np.ones((2, 2))), {}, ValueError, "I"),
    (([0.01, 0.01], 1e-4, None, 40), {}, ValueError, "g"),
    (([0.01, 0.01], 1e-4), {"inclusions": [{"x": 0, "z": 0.005, "radius": 0}]}, ValueError, "radius"),
    (([0.01, 0.01], 1e-4), {"inclusions": [{"x": 0, "z": 0.005, "r": 1e-3}]}, ValueError, "unknown"),
    (([2.0, 0.01], 1e-4), {}, ValueError, "phantom.width"),
    (([0.1, 0.1], 1e-7), {}, ValueError, "phantom.meandist"),
])
def test_bad_inputs(args, kw, exc, needle):
    with pytest.raises(exc) as e:
        sf.genscat(*args, **kw)
    assert needle in str(e.value), str(e.value)
