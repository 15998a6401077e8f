"""sonoflow.sptrack against PyMUST 0.1.9's sptrack on translated speckle images."""
import numpy as np
import pymust
import pytest
import scipy.ndimage as nd

import sonoflow as sf


def speckle(seed, shift, size=128, frames=2, sigma=2.0):
    """Band-limited random images translated by `shift` (rows, cols) pixels per frame, exactly
    (Fourier shift of a larger periodic image, cropped)."""
    rng = np.random.default_rng(seed)
    base = nd.gaussian_filter(rng.standard_normal((size + 40, size + 40)), sigma, mode="wrap")
    f = np.fft.fft2(base)
    imgs = [np.real(np.fft.ifft2(nd.fourier_shift(f, (k * shift[0], k * shift[1]))))[20:-20, 20:-20]
            for k in range(frames)]
    return np.stack(imgs, axis=2)


def pymust_sptrack(I, winsize, **fields):
    p = pymust.utils.Param()
    p.winsize = np.array(winsize)
    for k, v in fields.items():
        setattr(p, k, v)
    return pymust.sptrack(I, p)


@pytest.mark.parametrize("seed,shift", [(3, (1.3, -0.7)), (4, (-2.4, 0.35)), (5, (0.45, 3.2))])
def test_translation_against_pymust(seed, shift):
    I = speckle(seed, shift)
    win = [[32, 32], [16, 16]]
    dj, di, j, i = sf.sptrack(I, {"winsize": win})
    pdj, pdi, pj, pi = pymust_sptrack(I, win)
    # Same grid of windows, same output order (columns first) and sign; centres half a pixel
    # before PyMUST's (MATLAB's convention, documented).
    assert di.shape == pdi.shape == i.shape
    np.testing.assert_allclose(i, pi - 0.5)
    np.testing.assert_allclose(j, pj - 0.5)
    e_sf = np.hypot(np.mean(di) - shift[0], np.mean(dj) - shift[1])
    e_pm = np.hypot(np.nanmean(pdi) - shift[0], np.nanmean(pdj) - shift[1])
    print(f"seed {seed}: mean error sonoflow {e_sf:.4f} px, PyMUST {e_pm:.4f} px")
    # PyMUST's parabolic peak locks toward whole pixels (measured 0.03-0.12 px); the Fourier peak
    # does not (measured < 0.01 px).
    assert e_pm < 0.2
    assert e_sf < 0.02
    # Field-wise the two agree to PyMUST's bias.
    assert np.nanmedian(np.abs(di - pdi)) < 0.2 and np.nanmedian(np.abs(dj - pdj)) < 0.2
    # MUST's parabola in sonoflow: biased like PyMUST's, not like the Fourier peak.
    dj_pf, di_pf, _, _ = sf.sptrack(I, {"winsize": win, "subpix": "PF"})
    e_pf = np.hypot(np.mean(di_pf) - shift[0], np.mean(dj_pf) - shift[1])
    print(f"  sonoflow 'PF' {e_pf:.4f} px")
    assert e_pf < 0.2


def test_ensemble_roi_and_raw_output():
    # Five images, 0.8 px per image: iminc 2 measures 1.6 px over an ensemble of three pairs.
    I = speckle(6, (0.8, -0.5), frames=5)
    dj, di, _, _ = sf.sptrack(I, {"winsize": [32, 32], "iminc": 2, "overlap": 75})
    assert abs(np.mean(di) - 1.6) < 0.02 and abs(np.mean(dj) + 1.0) < 0.02
    roi = np.zeros(I.shape[:2], bool)
    roi[:, :64] = True
    dj, di, j, i = sf.sptrack(I, {"winsize": [32, 32], "iminc": 2, "ROI": roi}, smooth=False)
    assert np.all(np.isnan(di[j > 64])) and np.all(np.isfinite(di[j < 63]))


@pytest.mark.parametrize("param,I,needle", [
    ({}, None, "winsize"),
    ({"winsize": [[16, 16], [32, 32]]}, None, "windows"),
    ({"winsize": [[16, 16, 16]]}, None, "winsize"),
    ({"winsize": [256, 256]}, None, "winsize"),
    ({"winsize": [16, 16], "overlap": 100}, None, "overlap"),
    ({"winsize": [16, 16], "iminc": 2}, None, "iminc"),
    ({"winsize": [16, 16], "subpix": "OF"}, None, "subpix"),
    ({"winsize": [16, 16], "ROI": np.ones((3, 3), bool)}, None, "ROI"),
    ({"winsize": [16, 16]}, np.zeros((64, 64)), "3 axes"),
    ({"winsize": [16, 16]}, np.full((64, 64, 2), np.nan), "NaN"),
])
def test_bad_inputs_name_the_field(param, I, needle):
    I = speckle(1, (1.0, 1.0), size=64) if I is None else I
    with pytest.raises(ValueError, match=needle):
        sf.sptrack(I, param)
    with pytest.raises(TypeError, match="param"):
        sf.sptrack(speckle(1, (1.0, 1.0), size=64), [16, 16])
