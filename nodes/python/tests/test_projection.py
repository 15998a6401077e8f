"""`sonoflow.look_projection`: the per-pixel Doppler projection of a look from its I/Q header,
against an independent numpy evaluation of the model the `doppler` node documents
(sonoflow_doppler::aperture): a = −(sin θt + ⟨sin θe⟩, cos θt + ⟨cos θe⟩)/2 over the elements of
the pixel's receive aperture (centred on the line through the pixel at the receive angle, width
z/(F cos θr)), each element weighted by its apodisation and, with an element width, by
|sinc(π w sin θe/λ) cos θe| r^−½. Tolerance 1e-6: the library rounds to float32 (6e-8 relative)."""
import numpy as np
import pytest

import sonoflow as sf

HANN = sf.node.CONSTANTS["APODIZATION_HANN"]


def header(**kw):
    h = {"n_elements": 64, "pitch": 0.3e-3, "fnumber": 1.5, "element_width": 0.0, "radius": float("inf"),
         "apodization": 0, "fc": 5e6, "c": 1540.0, "tx_angle": 0.0, "rx_angle": 0.0,
         "grid": {"x0": -12e-3, "z0": 2e-3, "dx": 0.4e-3, "dz": 0.5e-3, "nx": 61, "nz": 57}}
    h.update(kw)
    return h


def reference(h):
    g = h["grid"]
    ne, pitch, f = h["n_elements"], h["pitch"], h["fnumber"]
    xe = (np.arange(ne) - (ne - 1) / 2) * pitch
    x = g["x0"] + g["dx"] * np.arange(g["nx"])
    z = g["z0"] + g["dz"] * np.arange(g["nz"])
    zz, xx, ee = np.meshgrid(z, x, xe, indexing="ij")
    dx = xx - ee
    rx = h["rx_angle"]
    off = dx - zz * np.tan(rx)
    half = zz / np.cos(rx) / 2 / f
    r = np.hypot(dx, zz)
    inside = np.abs(off) <= half
    w = np.where(inside, 1.0, 0.0)
    if h["apodization"] == HANN:
        w = w * np.cos(np.pi * (-off / (2 * half))) ** 2
    sin_t, cos_t = dx / r, zz / r
    if h["element_width"] > 0:
        u = np.pi * h["element_width"] * sin_t / (h["c"] / h["fc"])
        w = w * np.abs(np.sinc(u / np.pi) * cos_t) / np.sqrt(r)
    sw = w.sum(axis=2)
    tx = h["tx_angle"]
    with np.errstate(invalid="ignore", divide="ignore"):
        ax = np.where(sw > 0, -(np.sin(tx) + (w * sin_t).sum(axis=2) / sw) / 2, 0.0)
        az = np.where(sw > 0, -(np.cos(tx) + (w * cos_t).sum(axis=2) / sw) / 2, 0.0)
    return np.stack([ax, az])


@pytest.mark.parametrize("kw", [
    {},
    {"rx_angle": np.deg2rad(-15), "tx_angle": np.deg2rad(10)},
    {"rx_angle": np.deg2rad(12), "apodization": HANN, "fnumber": 2.5},
    {"element_width": 0.27e-3, "rx_angle": np.deg2rad(-8), "apodization": HANN},
])
def test_look_projection_matches_an_independent_numpy_evaluation(kw):
    h = header(**kw)
    got = sf.look_projection(h)
    want = reference(h)
    assert got.dtype == np.float32 and got.shape == (2, h["grid"]["nz"], h["grid"]["nx"])
    assert np.max(np.abs(got - want)) < 1e-6
    # the steered look's lateral component differs from the nominal one near the array's ends
    # (the aperture loses its oblique elements there): the model is not the nominal constant
    if kw.get("rx_angle"):
        nominal = -(np.sin(h["tx_angle"]) + np.sin(h["rx_angle"])) / 2
        assert np.max(np.abs(got[0] - nominal)) > 0.01


def test_look_projection_without_an_aperture_and_bad_headers():
    assert sf.look_projection(header(n_elements=0)) is None
    with pytest.raises(TypeError, match="header"):
        sf.look_projection([1, 2])
    with pytest.raises(ValueError, match="missing field.*fnumber"):
        h = header()
        del h["fnumber"]
        sf.look_projection(h)
    with pytest.raises(ValueError, match="fnumber"):
        sf.look_projection(header(fnumber=-1.0))
    with pytest.raises(ValueError, match="rx_angle"):
        sf.look_projection(header(rx_angle=float("nan")))
    with pytest.raises(ValueError, match="fc"):
        sf.look_projection(header(fc=0.0))
    with pytest.raises(ValueError, match="grid"):
        sf.look_projection(header(grid={"x0": 0.0, "z0": 1e-3, "dx": 1e-4, "dz": 1e-4, "nx": 0, "nz": 4}))
