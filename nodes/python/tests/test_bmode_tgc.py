"""bmode and tgc against PyMUST 0.1.9 on two probes (L11-5v and P4-2v scenes that the Rust tests
do not use), and tgc's reproducible Theil–Sen fit against scipy's where PyMUST draws at random."""

import copy

import numpy as np
import pytest

import sonoflow as sf

pymust = pytest.importorskip("pymust")
scipy_stats = pytest.importorskip("scipy.stats")


def probe_scene(name, seed, n, x_half, z0, z1, **extra):
    """RF and I/Q of `n` random scatterers for a PyMUST preset, 0° plane wave, fs = 4 fc."""
    rng = np.random.default_rng(seed)
    x, z, rc = rng.uniform(-x_half, x_half, n), rng.uniform(z0, z1, n), rng.standard_normal(n)
    p = pymust.getparam(name)
    for k, v in extra.items():
        setattr(p, k, v)
    p.fs = 4 * p.fc
    dels = pymust.txdelay(p, 0.0)
    rf, _ = pymust.simus(x, z, rc, dels, copy.deepcopy(p))
    iq = pymust.rf2iq(rf, copy.deepcopy(p))
    return p, dels, rf, iq


@pytest.fixture(scope="module", params=["L11-5v", "P4-2v"])
def scene(request):
    if request.param == "L11-5v":
        return probe_scene("L11-5v", 3, 80, 8e-3, 4e-3, 20e-3)
    return probe_scene("P4-2v", 5, 40, 15e-3, 10e-3, 40e-3)


@pytest.mark.parametrize("dr", [40, 25.5, 0.5])
def test_bmode_equals_pymust(scene, dr):
    """A DAS image of the scene at three dynamic ranges (one a power law): every pixel equal
    (complex128 input, so both sides compute in float64), and a complex64 stack (PyMUST computes
    it in float32) within one level."""
    p, dels, rf, iq = scene
    q = copy.deepcopy(p)
    q.fnumber = 1.5
    x, z = np.meshgrid(np.linspace(-6e-3, 6e-3, 61), np.linspace(5e-3, 30e-3, 71))
    img = sf.das(iq.astype(np.complex64), x, z, dels, q).astype(np.complex128)
    got = sf.bmode(img, dr)
    want = pymust.bmode(img, dr)
    assert got.dtype == np.uint8 and got.shape == img.shape
    assert np.array_equal(got, want)
    assert 10 < np.count_nonzero(got) < got.size, "the image must use the range"
    stack = np.stack([img, 0.5 * img], axis=2).astype(np.complex64)
    d = np.abs(sf.bmode(stack, dr).astype(int) - pymust.bmode(stack, dr).astype(int))
    assert d.max() <= 1 and np.mean(d > 0) < 1e-3


def test_tgc_equals_pymust_where_pymust_uses_every_sample(scene):
    """RF and I/Q of 240 samples (PyMUST fits all 192 samples of the middle 80 %, so its fit is
    deterministic): gain and compensated signal equal to rounding for float64 RF and complex128
    I/Q; float32 RF (which PyMUST keeps in float32 through the Hilbert transform) within 1e-5."""
    p, dels, rf, iq = scene
    assert rf.dtype == np.float32
    np.testing.assert_allclose(sf.tgc(rf[:240])[1], pymust.tgc(rf[:240].copy())[1], rtol=1e-5)
    for s in (rf[:240].astype(np.float64), iq[:240]):
        got_s, got_c = sf.tgc(s)
        want_s, want_c = pymust.tgc(s.copy())
        assert got_c.shape == want_c.shape == (240, 1)
        np.testing.assert_allclose(got_c, want_c, rtol=1e-9)
        np.testing.assert_allclose(got_s, want_s, rtol=1e-9, atol=1e-12 * np.abs(want_s).max())


def test_tgc_fit_is_reproducible_theil_sen(scene):
    """A full-length trace (PyMUST would draw 200 samples at random): the slope is the median of
    all pairwise slopes (scipy's theilslopes), the intercept the median of the residuals."""
    p, dels, rf, iq = scene
    env = np.mean(np.abs(iq), axis=1)
    n = len(env)
    n1, n2 = int(np.ceil(n / 10)), int(np.floor(n * 9 / 10))
    k = np.arange(n1, n2)
    slope = scipy_stats.theilslopes(np.log(env[n1:n2]), k).slope
    intercept = np.median(np.log(env[n1:n2]) - slope * k)
    want = np.exp(intercept) / np.exp(intercept + slope * np.arange(n))
    _, c1 = sf.tgc(iq)
    _, c2 = sf.tgc(iq)
    assert np.array_equal(c1, c2)
    np.testing.assert_allclose(c1[:, 0], want, rtol=1e-9)


def test_bmode_and_tgc_refuse_bad_input():
    with pytest.raises(TypeError, match="IQ: must be complex"):
        sf.bmode(np.ones((4, 4)))
    with pytest.raises(ValueError, match="DR"):
        sf.bmode(np.ones((4, 4), np.complex64), 0)
    bad = np.ones((4, 4), np.complex64)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="IQ: contains NaN"):
        sf.bmode(bad)
    with pytest.raises(ValueError, match="S: expected"):
        sf.tgc(np.ones((4, 4, 4)))
    with pytest.raises(ValueError, match="at least 3 samples"):
        sf.tgc(np.ones((2, 3)))
    dead = np.ones((100, 2))
    dead[40] = 0.0
    with pytest.raises(ValueError, match="tgc"):
        sf.tgc(dead + 0j)
