"""`sonoflow.look_projection`: the per-pixel Doppler projection of a look from its I/Q header,
against a numpy evaluation (vectorised, written from the documentation) of the model the `doppler`
node documents (sonoflow_doppler::aperture; the model itself is checked there against the DAS
plan's delay gradients):  a = −(sin θt + ⟨sin θe⟩, cos θt + ⟨cos θe⟩)/2 over the elements of
the pixel's receive aperture (centred on the line through the pixel at the receive angle, width
z/(F cos θr); F = 0: every element), each element weighted by its apodisation and, with an element
width, by |sinc(π w sin θe/λ) cos θe| r^−½. This checks the header → aperture mapping, the plane
order and layout. Tolerance 1e-6: the library rounds |a| ≤ 1 to float32 (≤ 6e-8)."""
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
    half = zz / np.cos(rx) / 2 / f if f > 0 else np.full(zz.shape, np.inf)
    r = np.hypot(dx, zz)
    inside = np.abs(off) <= half
    w = np.where(inside, 1.0, 0.0)
    if h["apodization"] == HANN and f > 0:
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
    {"radius": 0.0, "rx_angle": np.deg2rad(15)},  # the beamformer writes radius 0 for a linear array
    {"fnumber": 0.0, "element_width": 0.2e-3},    # f-number 0: the whole array at every pixel
])
def test_look_projection_matches_an_independent_numpy_evaluation(kw):
    h = header(**kw)
    got = sf.look_projection(h)
    want = reference(h)
    assert got.dtype == np.float32 and got.shape == (2, h["grid"]["nz"], h["grid"]["nx"])
    assert np.max(np.abs(got - want)) < 1e-6
    # where elements reach the pixel, the steered look's lateral component differs from the
    # nominal one near the array's ends (the aperture loses its oblique elements there)
    if kw.get("rx_angle"):
        reached = (got != 0).any(axis=0)
        assert reached.sum() > got[0].size / 2
        nominal = -(np.sin(h["tx_angle"]) + np.sin(h["rx_angle"])) / 2
        assert np.max(np.abs(got[0][reached] - nominal)) > 0.05


def test_look_projection_on_a_convex_array_is_mirror_symmetric():
    # A convex array (radius 40 mm) with an unsteered look on a grid symmetric about x = 0: the
    # lateral component is odd in x and the axial one even (to float32 rounding), axial
    # components toward the probe (a_z < 0), and away from the axis the lateral one is not zero.
    g = {"x0": -15e-3, "z0": 12e-3, "dx": 0.5e-3, "dz": 0.5e-3, "nx": 61, "nz": 50}
    h = header(radius=0.04, pitch=0.5e-3, n_elements=96, fnumber=1.0, grid=g)
    a = sf.look_projection(h)
    assert a.shape == (2, 50, 61)
    assert np.max(np.abs(a[0] + a[0][:, ::-1])) < 1e-6
    assert np.max(np.abs(a[1] - a[1][:, ::-1])) < 1e-6
    reached = (a != 0).any(axis=0)
    assert reached.sum() > a[0].size / 2 and np.all(a[1][reached] < 0)
    assert np.max(np.abs(a[0][reached])) > 0.1


def test_look_projection_without_an_aperture_and_bad_headers():
    assert sf.look_projection(header(n_elements=0)) is None
    with pytest.raises(TypeError, match="header"):
        sf.look_projection([1, 2])
    with pytest.raises(ValueError, match="header.fnumber: missing"):
        h = header()
        del h["fnumber"]
        sf.look_projection(h)
    with pytest.raises(ValueError, match="header.grid.nz: missing"):
        h = header()
        del h["grid"]["nz"]
        sf.look_projection(h)
    with pytest.raises(TypeError, match="header.pitch"):
        sf.look_projection(header(pitch="0.3 mm"))
    with pytest.raises(ValueError, match="header.pitch"):
        sf.look_projection(header(pitch=float("nan")))
    with pytest.raises(ValueError, match="header.n_elements"):
        sf.look_projection(header(n_elements=0.5))
    with pytest.raises(ValueError, match="header.apodization"):
        sf.look_projection(header(apodization=7))
    with pytest.raises(ValueError, match="fnumber"):
        sf.look_projection(header(fnumber=-1.0))
    with pytest.raises(ValueError, match="rx_angle"):
        sf.look_projection(header(rx_angle=float("nan")))
    with pytest.raises(ValueError, match="fc"):
        sf.look_projection(header(fc=0.0))
    with pytest.raises(ValueError, match="grid"):
        sf.look_projection(header(grid={"x0": 0.0, "z0": 1e-3, "dx": 1e-4, "dz": 1e-4, "nx": 0, "nz": 4}))
