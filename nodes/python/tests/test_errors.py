"""Bad input raises ValueError/TypeError naming the argument or field: never a panic or a crash
across the FFI, never a NaN carried silently."""

import math

import numpy as np
import pytest

import sonoflow as sf


def param(**extra):
    p = sf.getparam("L11-5v")
    p.update(extra)
    return p


def scene(n=5):
    rng = np.random.default_rng(1)
    return rng.uniform(-5e-3, 5e-3, n), rng.uniform(5e-3, 20e-3, n), rng.standard_normal(n)


def test_param_accepts_pymust_spellings_in_any_case_and_plain_dicts():
    p = dict(param())
    p["nelements"] = p.pop("Nelements")
    d = sf.txdelay(p, 0.1)
    assert d.shape == (1, 128)
    assert p["TXdelay"] is d
    q = sf.Param(p)
    assert q.fc == p["fc"]
    with pytest.raises(AttributeError):
        _ = q.no_such_field


@pytest.mark.parametrize(
    "bad, pattern, exc",
    [
        ({"fc": -5e6}, r"param\.fc = -5000000\.0 is out of range", ValueError),
        ({"fc": float("nan")}, r"param\.fc = nan must be finite", ValueError),
        ({"fc": "5 MHz"}, r"param\.fc must be a real number", TypeError),
        ({"Nelements": 12.5}, r"param\.Nelements = 12\.5 must be a whole number", ValueError),
        ({"radius": -0.04}, r"param\.radius = -0\.04 is out of range", ValueError),
        ({"radius": 0.005}, r"probe\.n_elements.*holds at most", ValueError),
        ({"TXfreqsweep": 1e6}, r"TXfreqsweep", ValueError),
        ({"c": 0.0}, r"param: invalid parameter `medium.c` = 0: must be finite and > 0", ValueError),
    ],
)
def test_bad_param_fields_are_named(bad, pattern, exc):
    p = param(**bad)
    x, z, rc = scene()
    with pytest.raises(exc, match=pattern):
        sf.simus(x, z, rc, np.zeros(128), p)


def test_missing_fields_are_named():
    p = param()
    del p["pitch"]
    with pytest.raises(ValueError, match=r"param\.pitch is missing"):
        sf.txdelay(p, 0.0)
    with pytest.raises(ValueError, match=r"param\.fs is missing"):
        sf.rf2iq(np.zeros((100, 4)), param())
    with pytest.raises(ValueError, match=r"param\.PRF \(or param\.PRP\) is missing"):
        sf.iq2doppler(np.ones((4, 4, 8), np.complex64), param())


def test_library_validation_reaches_python_as_value_error():
    """A value only the Rust library checks (fs below 4 fc for SIMUS) comes back as ValueError
    with the library's message, not a panic."""
    x, z, rc = scene()
    with pytest.raises(ValueError, match="fs"):
        sf.simus(x, z, rc, np.zeros(128), param(fs=2e6))


def test_bad_arrays_are_named():
    x, z, rc = scene()
    p = param()
    with pytest.raises(ValueError, match="x, z, RC: must have the same shape"):
        sf.simus(x, z[:-1], rc, np.zeros(128), p)
    with pytest.raises(ValueError, match="x: contains NaN"):
        sf.simus(np.where(x > 0, np.nan, x), z, rc, np.zeros(128), p)
    with pytest.raises(TypeError, match="RC: dtype"):
        sf.simus(x, z, rc.astype(str), np.zeros(128), p)
    with pytest.raises(ValueError, match="delaysTX: expected 128 delays"):
        sf.simus(x, z, rc, np.zeros(64), p)
    with pytest.raises(ValueError, match="delaysTX: every element is off"):
        sf.simus(x, z, rc, np.full(128, np.nan), p)
    with pytest.raises(ValueError, match="tilt = 2.0"):
        sf.txdelay(p, 2.0)
    with pytest.raises(ValueError, match=r"\(x0, z0\) = \(0.0, 0.0\)"):
        sf.txdelay(0.0, 0.0, p)


def test_bad_beamforming_and_doppler_input_is_named():
    p = param(fs=4 * 7.6e6, PRF=5e3)
    rf = np.zeros((200, 128))
    with pytest.raises(ValueError, match="RF: contains NaN"):
        sf.rf2iq(np.where(rf == 0, np.nan, rf), p)
    iq = sf.rf2iq(rf, p)
    x, z = np.meshgrid(np.linspace(-2e-3, 2e-3, 5), np.linspace(5e-3, 8e-3, 4))
    with pytest.raises(TypeError, match="SIG: expected complex"):
        sf.das(rf, x, z, np.zeros(128), p)
    with pytest.raises(ValueError, match="SIG: 64 channels but param.Nelements = 128"):
        sf.das(iq[:, :64], x, z, np.zeros(64), p)
    with pytest.raises(ValueError, match="regular grid"):
        sf.das(iq, x ** 2, z, np.zeros(128), p)
    with pytest.raises(ValueError, match="method = 'cubic'"):
        sf.das(iq, x, z, np.zeros(128), p, "cubic")
    with pytest.raises(ValueError, match="IQ: expected \\(nz, nx, n_frames\\)"):
        sf.iq2doppler(np.ones((4, 8), np.complex64), p)
    bad = np.ones((4, 4, 8), np.complex64)
    bad[2, 1, 5] = complex(1.0, np.inf)
    with pytest.raises(ValueError, match="IQ: contains NaN or infinite"):
        sf.iq2doppler(bad, p)
    with pytest.raises(ValueError, match="IQ: 2 frame\\(s\\); lag 2 needs at least 3"):
        sf.iq2doppler(np.ones((4, 4, 2), np.complex64), p, 1, 2)
    with pytest.raises(ValueError, match="M = 0"):
        sf.iq2doppler(np.ones((4, 4, 8), np.complex64), p, 0)
    with pytest.raises(ValueError, match="clutter"):
        sf.iq2doppler(np.ones((4, 4, 8), np.complex64), p, clutter={"type": "polynomial", "order": 99})
    with pytest.raises(ValueError, match="clutter"):
        sf.iq2doppler(np.ones((4, 4, 8), np.complex64), p, clutter={"type": "wavelet"})


def test_bad_smoothn_input_is_named():
    with pytest.raises(ValueError, match="y: every value is NaN"):
        sf.smoothn(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="W: shape"):
        sf.smoothn(np.ones((4, 4)), W=np.ones((3, 4)))
    with pytest.raises(ValueError, match="S = -1.0 is out of range"):
        sf.smoothn(np.ones((4, 4)), S=-1)
    with pytest.raises(ValueError, match="Order = 5"):
        sf.smoothn(np.ones((4, 4)), Order=5)
    with pytest.raises(ValueError, match="weight_function|Weight"):
        sf.smoothn(np.ones((4, 4)), Weight="huber")
    with pytest.raises(ValueError, match="components of a vector field"):
        sf.smoothn([np.ones((4, 4)), np.ones((3, 4))])


def test_set_threads_rejects_bad_counts():
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="n = "):
            sf.set_threads(bad)
    assert math.isfinite(sf.threads())


def test_bad_vector_doppler_input_is_named():
    with pytest.raises(ValueError, match="VD: expected at least two"):
        sf.vector_doppler(np.zeros((1, 4, 4)), [0.0], [0.0])
    with pytest.raises(ValueError, match="one per map"):
        sf.vector_doppler(np.zeros((3, 4, 4)), [0.0, 0.0], [0.1, 0.2])
    with pytest.raises(ValueError, match="flags: shape"):
        sf.vector_doppler(np.zeros((2, 4, 4)), [0.0, 0.0], [0.1, -0.1], flags=np.zeros((2, 4, 5)))
    with pytest.raises(ValueError, match="vector weights"):
        sf.vector_doppler(np.zeros((2, 4, 4)), [0.0, 0.0], [0.1, -0.1], weights=[1.0, -1.0])
    with pytest.raises(ValueError, match="VD: contains NaN"):
        sf.vector_doppler(np.full((2, 4, 4), np.nan), [0.0, 0.0], [0.1, -0.1])


def test_a_node_outside_a_graph_says_how_it_is_started(monkeypatch):
    monkeypatch.delenv("SONOFLOW_NODE_CONFIG", raising=False)
    with pytest.raises(RuntimeError, match="SONOFLOW_NODE_CONFIG is not set: node processes are started by `sonoflow run`"):
        sf.Node()
    monkeypatch.setenv("SONOFLOW_NODE_CONFIG", "{not json")
    with pytest.raises(RuntimeError, match="SONOFLOW_NODE_CONFIG"):
        sf.Node()


def test_node_headers_refuse_unknown_fields_and_overlong_arrays():
    import numpy as np
    from sonoflow.node import _fill
    from sonoflow.recording import _Layout

    h = np.zeros((), dtype=_Layout("VectorFieldV2").header)
    _fill(h, {"grid": {"nx": 3, "nz": 2}, "plane_ids": [5, 6], "n_planes": 2}, "")
    assert (int(h["grid"]["nx"]), int(h["grid"]["nz"]), list(h["plane_ids"][:3])) == (3, 2, [5, 6, 0])
    with pytest.raises(ValueError, match="header: grid.nope is not a field"):
        _fill(h, {"grid": {"nope": 1}}, "")
    with pytest.raises(ValueError, match="header: plane_ids takes at most"):
        _fill(h, {"plane_ids": list(range(100))}, "")
