"""sonoflow.pfield against PyMUST 0.1.9's pfield (issue 22: nRMS ≤ 1e-4) on two probes, for plane
(straight and steered), focused and diverging transmits, with apodisation, attenuation, a rigid
baffle, full-frequency directivity, MUST's quick options, and off the imaging plane (elevation:
element height, elevation focus); the frequency band (IDX) equal; bad inputs."""
import copy

import numpy as np
import pymust
import pytest

import sonoflow as sf


def nrms(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def pair(x, z, d, p, *extra):
    RP, _, IDX = pymust.pfield(x, None, z, d, copy.deepcopy(p), *copy.deepcopy(extra))
    rp, spect, idx = sf.pfield(x, None, z, d, p, *extra)
    assert spect is None and rp.shape == x.shape
    assert np.array_equal(np.asarray(IDX).ravel(), idx), "frequency band"
    return rp, RP


@pytest.mark.parametrize("probe", ["L11-5v", "P4-2v"])
@pytest.mark.parametrize("tx", ["plane", "steered", "focused", "diverging"])
def test_transmits_match_pymust(probe, tx):
    p = pymust.getparam(probe)
    x, z = np.meshgrid(np.linspace(-1.5e-2, 1.5e-2, 41), np.linspace(-1e-3, 4e-2, 33))
    d = {"plane": lambda: pymust.txdelay(p, 0),
         "steered": lambda: pymust.txdelay(p, np.deg2rad(-12)),
         "focused": lambda: pymust.txdelay(-0.004, 0.025, p),
         "diverging": lambda: pymust.txdelay(0.002, -0.015, p)}[tx]()
    rp, RP = pair(x, z, d, p)
    assert nrms(rp, RP) < 1e-4
    assert np.all(rp[z < 0] == 0) and np.all(RP[z < 0] == 0)


def test_focus_is_where_the_field_peaks():
    # an independent check: a focused transmit's RMS pressure peaks near its focus
    p = pymust.getparam("L11-5v")
    x, z = np.meshgrid(np.linspace(-5e-3, 5e-3, 41), np.linspace(5e-3, 35e-3, 61))
    rp, _, _ = sf.pfield(x, None, z, pymust.txdelay(0.002, 0.02, p), p)
    iz, ix = np.unravel_index(np.argmax(rp), rp.shape)
    assert abs(x[iz, ix] - 0.002) < 0.5e-3 and abs(z[iz, ix] - 0.02) < 5e-3, (x[iz, ix], z[iz, ix])


@pytest.mark.parametrize("variant", ["apodization", "attenuation", "rigid", "ffd", "quick", "splitting", "off"])
def test_parameters_match_pymust(variant):
    p = pymust.getparam("P4-2v")
    x, z = np.meshgrid(np.linspace(-2e-2, 2e-2, 31), np.linspace(5e-3, 6e-2, 27))
    d = pymust.txdelay(p, np.deg2rad(8))
    extra = ()
    if variant == "apodization":
        p.TXapodization = np.hanning(p.Nelements).astype(np.float32)
    elif variant == "attenuation":
        p.attenuation = 0.7
    elif variant == "rigid":
        p.baffle = "rigid"
    elif variant == "ffd":
        extra = (pymust.utils.Options(FullFrequencyDirectivity=True),)
    elif variant == "quick":
        extra = (True,)
    elif variant == "splitting":
        extra = (pymust.utils.Options(ElementSplitting=3),)
    elif variant == "off":
        d = d.astype(float).copy()
        d[0, 10:20] = np.nan
    rp, RP = pair(x, z, d, p, *extra)
    assert nrms(rp, RP) < 1e-4, variant


@pytest.mark.parametrize("args,exc,needle", [
    (lambda p, x, z, d: (x, np.ones(3) * 1e-3, z, d, p), ValueError, "y"),
    (lambda p, x, z, d: (x, np.full_like(x, np.nan), z, d, p), ValueError, "y"),
    (lambda p, x, z, d: (x, np.ones_like(x) * 1e-3, z, d, {**dict(p), "height": -1e-3}), ValueError, "height"),
    (lambda p, x, z, d: (x, None, z[:2], d, p), ValueError, "same shape"),
    (lambda p, x, z, d: (x, None, z, d[:, :10], p), ValueError, "delaysTX"),
    (lambda p, x, z, d: (x, None, z, -np.abs(d) - 1e-6, p), ValueError, "≥ 0"),
    (lambda p, x, z, d: (x * np.nan, None, z, d, p), ValueError, "x"),
    (lambda p, x, z, d: (x, None, z, d, {**dict(p), "radius": -0.05}), ValueError, "radius"),
    (lambda p, x, z, d: (x, None, z, d, p, {"dBThresh": 3}), ValueError, "dB"),
])
def test_bad_inputs(args, exc, needle):
    p = pymust.getparam("L11-5v")
    x, z = np.meshgrid(np.linspace(-1e-2, 1e-2, 5), np.linspace(1e-2, 2e-2, 4))
    d = pymust.txdelay(p, 0)
    with pytest.raises(exc) as e:
        sf.pfield(*args(p, x, z, d))
    assert needle in str(e.value), str(e.value)


@pytest.mark.parametrize("probe", ["L11-5v", "P4-2v"])
@pytest.mark.parametrize("case", ["plane", "focused", "planar-branch", "no-elevation-focus", "height"])
def test_elevation_matches_pymust(probe, case):
    # Points off the imaging plane (y ≠ 0): MUST's elevation model (3-D distances, 1/r, the
    # multi-Gaussian beam of the element height and elevation focus).
    p = pymust.getparam(probe)
    x, z = np.meshgrid(np.linspace(-1.2e-2, 1.2e-2, 25), np.linspace(2e-3, 5e-2, 29))
    y = np.linspace(-3e-3, 3e-3, x.size).reshape(x.shape)  # a different elevation at every point
    d = pymust.txdelay(p, np.deg2rad(5))
    if case == "focused":
        d = pymust.txdelay(0.003, 0.02, p)
    elif case == "planar-branch":
        y = np.full(x.shape, 1e-8)  # MUST's branch for |y| below float32's epsilon everywhere
    elif case == "no-elevation-focus":
        del p["focus"]
    elif case == "height":
        p.height = 2e-3
        p.focus = 0.03
    RP, _, IDX = pymust.pfield(x, y, z, d, copy.deepcopy(p))
    rp, _, idx = sf.pfield(x, y, z, d, p)
    assert np.array_equal(np.asarray(IDX).ravel(), idx), "frequency band"
    print(f"{probe} {case}: nRMS {nrms(rp, RP):.2e}")
    assert nrms(rp, RP) < 1e-4


def test_elevation_focus_narrows_the_beam_in_elevation():
    # Independent of PyMUST: at the elevation focus (18 mm, L11-5v) the field falls off faster
    # in y than at twice the depth relative to the beam width λz/h, and is symmetric in y.
    p = pymust.getparam("L11-5v")
    ys = np.linspace(-2e-3, 2e-3, 41)
    d = pymust.txdelay(p, 0)
    def profile(zf):
        x, z = np.zeros_like(ys), np.full_like(ys, zf)
        rp, _, _ = sf.pfield(x, ys, z, d, p)
        return rp / rp.max()
    at_focus, deep = profile(0.018), profile(0.036)
    np.testing.assert_allclose(at_focus, at_focus[::-1], rtol=1e-9)
    width = lambda prof: np.ptp(ys[prof >= 0.5])
    assert width(at_focus) < 0.75 * width(deep), (width(at_focus), width(deep))
