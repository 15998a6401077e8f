"""PyMUST-compatible functions: the names, argument order, conventions and ``param`` fields of
MUST/PyMUST 0.1.9, computed by sonoflow's Rust libraries (GIL released, threads set with
``sonoflow.set_threads``). Deliberate differences are stated in each docstring."""

import math

import numpy as np

from . import _native
from ._param import Options, Param, canonical, dumps, number, probe_json

__all__ = ["getparam", "txdelay", "simus", "rf2iq", "das", "dasmtx", "iq2doppler", "doppler_maps", "vector_doppler", "smoothn", "bmode", "tgc", "genscat", "pfield"]


def _array(a, name, dtype, *, ndim=None, allow_nan=False):
    """``a`` as a C-contiguous array of ``dtype`` (no copy when it already is one)."""
    if isinstance(a, (list, tuple)) or np.isscalar(a):
        a = np.asarray(a)
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name}: expected a numpy array, got {type(a).__name__}")
    kind = np.dtype(dtype).kind
    if a.dtype.kind not in ("b", "i", "u", "f") + (("c",) if kind == "c" else ()):
        raise TypeError(f"{name}: dtype {a.dtype} is not {'complex' if kind == 'c' else 'real'} numeric")
    if ndim is not None and a.ndim not in (ndim if isinstance(ndim, tuple) else (ndim,)):
        raise ValueError(f"{name}: expected {ndim} axes, got shape {a.shape}")
    a = np.ascontiguousarray(a, dtype=dtype)
    if not allow_nan and a.size and not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a


def getparam(probe):
    """Parameters of a probe preset (MUST ``getparam``): ``fc``, ``kerf``, ``width``, ``pitch``,
    ``Nelements``, ``bandwidth``, ``radius``, ``height``, ``focus``, and ``TXnow`` where the preset
    sets it (``'paper-5mhz'``, the probe of Shahriari & Garcia 2018). Names as in MUST
    (``'L11-5v'``, ``'L12-3v'``, ``'P4-2v'``, …; ``sonoflow.must.probes()`` lists them); convex
    probes (``'C5-2v'``) are refused until convex arrays are supported."""
    if not isinstance(probe, str):
        raise TypeError(f"probe: expected a preset name (str), got {type(probe).__name__}")
    import json

    p = json.loads(_native.probe_preset(probe))
    names = {"n_elements": "Nelements", "tx_now": "TXnow"}
    out = Param()
    for k, v in p.items():
        if v is None:
            continue
        out[names.get(k, k)] = v
    out.setdefault("radius", math.inf)
    if "kerf" in out and "width" not in out:
        out["width"] = out["pitch"] - out["kerf"]
    if "width" in out and "kerf" not in out:
        out["kerf"] = out["pitch"] - out["width"]
    return out


def probes():
    """The probe presets' names."""
    return [s.strip().split(" ")[0] for s in _native.probe_presets().split(",")]


def _set(param, key, value):
    try:
        param[key] = value
    except TypeError:
        pass


def txdelay(*args):
    """Transmit delays (s), MUST ``txdelay``, shape (n_laws, Nelements), each row shifted so that
    its smallest delay is 0; also sets ``param.TXdelay``:

    * ``txdelay(param, tilt)``: plane waves tilted by ``tilt`` (rad, scalar or vector);
    * ``txdelay(param, tilt, width)``: circular (diverging) waves of angular ``width`` (rad);
    * ``txdelay(x0, z0, param)``: focused at (x0, z0) (z0 > 0) or diverging from a virtual
      source (z0 < 0).

    Convex arrays (finite ``param.radius``) as MUST: a plane wave is the line tangent to the arc
    at ``tilt``; the circular form is not available (MUST neither). Difference: MUST calls a
    point focused on a convex array when ``hypot(x0, radius - z0) < radius``, so a focus deeper
    than twice the radius becomes diverging; here z0 > 0 is focused, z0 < 0 diverging."""
    if len(args) == 2:
        param, form = args[0], "plane"
    elif len(args) == 3 and hasattr(args[2], "keys"):
        param, form = args[2], "origo"
    elif len(args) == 3:
        param, form = args[0], "circular"
    else:
        raise TypeError("txdelay: use txdelay(param, tilt), txdelay(param, tilt, width) or txdelay(x0, z0, param)")
    p = canonical(param)
    pj = probe_json(p)
    js = dumps(pj)
    rows = []
    if form == "plane":
        tilt = np.atleast_1d(np.asarray(args[1], dtype=np.float64)).reshape(-1)
        for t in tilt:
            if not (np.isfinite(t) and abs(t) < math.pi / 2):
                raise ValueError(f"tilt = {t}: must verify |tilt| < pi/2")
            rows.append(_native.txdelay(js, "plane", float(t), 0.0))
    elif form == "origo":
        x0 = np.atleast_1d(np.asarray(args[0], dtype=np.float64)).reshape(-1)
        z0 = np.atleast_1d(np.asarray(args[1], dtype=np.float64)).reshape(-1)
        if x0.shape != z0.shape:
            raise ValueError(f"x0, z0: must have the same length ({x0.size} and {z0.size})")
        for a, b in zip(x0, z0):
            if not (np.isfinite(a) and np.isfinite(b)) or b == 0:
                raise ValueError(f"(x0, z0) = ({a}, {b}): must be finite with z0 != 0")
            rows.append(_native.txdelay(js, "focused" if b > 0 else "diverging", float(a), float(b)))
    else:
        if "radius" in pj:
            raise ValueError("txdelay(param, tilt, width) is not available for a convex array (param.radius finite)")
        tilt = np.atleast_1d(np.asarray(args[1], dtype=np.float64)).reshape(-1)
        width = np.atleast_1d(np.asarray(args[2], dtype=np.float64)).reshape(-1)
        if tilt.shape != width.shape:
            raise ValueError("tilt, width: must have the same length")
        if not np.all((width > 0) & (width < math.pi)):
            raise ValueError("width: must verify 0 < width < pi")
        L = (pj["Nelements"] - 1) * pj["pitch"]
        # MUST's angles2origo: the virtual source of a sector of this tilt and width.
        t = np.mod(-tilt + math.pi / 2, 2 * math.pi) - math.pi / 2
        sign = np.where(np.abs(t) > math.pi / 2, -1.0, 1.0)
        t = np.where(np.abs(t) > math.pi / 2, math.pi - t, t)
        z0 = sign * L / (np.tan(t - width / 2) - np.tan(t + width / 2))
        x0 = sign * z0 * np.tan(width / 2 - t) + L / 2
        for a, b in zip(x0, z0):
            rows.append(_native.txdelay(js, "diverging", float(a), float(b)))
    d = np.vstack(rows)
    _set(param, "TXdelay", d)
    return d


def _delays(delaysTX, n, name="delaysTX"):
    d = np.asarray(delaysTX, dtype=np.float64)
    if d.ndim == 2 and d.shape[0] == 1:
        d = d[0]
    if d.ndim != 1 or d.size != n:
        raise ValueError(f"{name}: expected {n} delays (one per element; NaN = element off), got shape {d.shape}")
    if np.all(np.isnan(d)):
        raise ValueError(f"{name}: every element is off (all NaN)")
    if np.any(np.isinf(d)):
        raise ValueError(f"{name}: contains infinite values")
    return np.ascontiguousarray(d)


def _options_json(options, simus=True):
    o = canonical(options, "options")
    # simus: sonoflow computes MUST's RF on the compact window unless told otherwise (see simus)
    out = {"window": "compact"} if simus else {}
    names = {"dBThresh": "db_thresh", "FrequencyStep": "frequency_step", "ElementSplitting": "element_splitting"}
    for k, v in o.items():
        if k in ("ParPool", "WaitBar", "CallFun"):
            continue
        if k == "FullFrequencyDirectivity":
            out["full_frequency_directivity"] = bool(v)
        elif k == "Window" and simus:
            # sonoflow's, not MUST's: "compact" halves the frequency bins for the same RF
            if not isinstance(v, str) or v.lower() not in ("must", "compact"):
                raise ValueError(f"options.Window: {v!r} is not 'compact' (the default) or 'must'")
            out["window"] = v.lower()
        elif k in names:
            out[names[k]] = number(o, k, "options", integer=k == "ElementSplitting")
        else:
            allowed = list(names) + ["FullFrequencyDirectivity"] + (["Window"] if simus else [])
            raise ValueError(f"options.{k}: unknown option (allowed: {', '.join(allowed)})")
    return out


def simus(*args):
    """RF signals of a linear or convex array (MUST ``simus``; convex: finite ``param.radius``): ``RF, spectrum = simus(x, z, RC, delaysTX,
    param[, options])`` or ``simus(x, y, z, RC, delaysTX, param[, options])`` with scatterers off
    the imaging plane (any |y| ≥ 1e-9 m: MUST's elevation model — 3-D distances, the
    multi-Gaussian beam of ``param.height`` focused at ``param.focus`` in elevation, on transmit and
    receive — computed with the exact float64 kernel, slower). ``x``, ``z``, ``RC`` any shape (flattened), ``delaysTX`` one row of
    ``txdelay``; RF has shape (n_samples, Nelements), sample k at k/fs (fs = ``param.fs``, default
    4 fc; ``param.fs`` is set as PyMUST does).

    ``options`` takes MUST's fields and sonoflow's ``Window``: ``"compact"`` (the default here) or
    ``"must"``. MUST's frequency step makes the RF's time window hold twice the longest round trip
    and keeps the first half; the compact window holds it once plus a pulse duration, so sonoflow
    computes about half the frequency bins for the same RF (same shape, times and gain; nRMS ~2e-6
    against MUST's window, ten times below the float32-vs-float64 difference from PyMUST;
    nodes/simus/README.md). ``{"Window": "must"}`` uses MUST's frequency grid exactly. With ``y`` off
    the plane MUST's window is used (its elevation factor is sampled on MUST's own grid);
    ``"compact"`` there is a ValueError.

    Differences: RF is float32 (PyMUST float64; the RFs agree to nRMS ~2e-5) and a
    Fortran-ordered view of sonoflow's element-major buffer (no copy); the second output is
    ``None`` (PyMUST's RF spectrum is not returned); chirps (``TXfreqsweep``) are refused. Convex
    arrays: nRMS 1.5e-5 – 2.8e-5 against PyMUST on C5-2v and a 30 mm-radius array (asserted < 6e-5,
    ``tests/test_convex.py``);
    scatterers behind the face (inside the arc's circle) are silent, as in MUST."""
    if len(args) not in (5, 6, 7):
        raise TypeError("simus: use simus(x, z, RC, delaysTX, param[, options]) or simus(x, y, z, RC, delaysTX, param[, options])")
    if len(args) == 7 or (len(args) == 6 and not hasattr(args[4], "keys")):
        x, y, z, rc, delays, param = args[:6]
        options = args[6] if len(args) == 7 else None
    else:
        x, z, rc, delays, param = args[:5]
        y, options = None, (args[5] if len(args) == 6 else None)
    xs = [_array(v, n, np.float32).reshape(-1) for v, n in ((x, "x"), (z, "z"), (rc, "RC"))]
    if not (np.shape(x) == np.shape(z) == np.shape(rc)):
        raise ValueError(f"x, z, RC: must have the same shape, got {np.shape(x)}, {np.shape(z)}, {np.shape(rc)}")
    ys = None
    if y is not None and np.size(y):
        if np.shape(y) != np.shape(x):
            raise ValueError(f"y: must have the shape of x, got {np.shape(y)}, {np.shape(x)}")
        ys = _array(y, "y", np.float32).reshape(-1)
    p = canonical(param)
    n = number(p, "Nelements", required=True, lo=1, integer=True)
    d = _delays(delays, n)
    pj = probe_json(p, delays=d)
    o = _options_json(options)
    off_plane = ys is not None and bool(np.any(np.abs(ys) >= 1e-9))  # as the library decides
    if off_plane and not (options is not None and "Window" in canonical(options, "options")):
        o["window"] = "must"  # MUST's elevation model samples MUST's own frequency grid
    rf, fs, t0 = _native.simus(xs[0], xs[1], xs[2], dumps(pj), dumps(o), ys)
    rf = rf.T
    if t0 > 0:
        lead = int(round(t0 * fs))
        rf = np.concatenate([np.zeros((lead, rf.shape[1]), dtype=rf.dtype), rf], axis=0)
    _set(param, "fs", fs)
    return rf, None


def rf2iq(RF, *args, B=None):
    """I/Q of RF signals (MUST ``rf2iq``): ``rf2iq(RF, param)`` (fc, fs, bandwidth, t0 from
    ``param``: low-pass cut-off bandwidth·fc/fs) or ``rf2iq(RF, fs, fc[, B])`` (cut-off
    min(2 fc/fs, 0.5), or B/100·fc/fs with the bandwidth B in %). RF is (n_samples, ...) real; the
    result has RF's shape, complex64, demodulated at fc and low-passed by a 5th-order Butterworth
    run forwards and backwards (as PyMUST's filtfilt, ×2).

    Differences: complex64 (PyMUST complex128); fc must be given (PyMUST estimates it from
    randomly chosen columns)."""
    rf = np.asarray(RF)
    if rf.ndim < 1 or rf.size == 0:
        raise ValueError(f"RF: expected (n_samples, n_channels[, ...]) samples, got shape {rf.shape}")
    if len(args) == 1:
        p = canonical(args[0])
        fc = number(p, "fc", required=True, lo=0, lo_open=True)
        fs = number(p, "fs", required=True, lo=0, lo_open=True)
        bw = number(p, "bandwidth", lo=0, lo_open=True)
        t0 = number(p, "t0", default=0.0)
    elif len(args) in (2, 3):
        fs, fc = (number({"v": v}, "v", n, required=True, lo=0, lo_open=True) for v, n in zip(args[:2], ("fs", "fc")))
        bw = None
        if len(args) == 3 or B is not None:
            bw = number({"B": args[2] if len(args) == 3 else B}, "B", "B", lo=0, hi=200, lo_open=True)
        t0 = 0.0
    else:
        raise TypeError("rf2iq: use rf2iq(RF, param) or rf2iq(RF, fs, fc[, B])")
    shape = rf.shape
    flat = _array(rf.reshape(shape[0], -1), "RF", np.float64, ndim=2)
    params = {"fc": fc, "fs": fs, "t0": t0}
    if bw is not None:
        params["bandwidth"] = bw
    iq = _native.rf2iq(flat, dumps(params)).T
    return iq.reshape(shape)


def _grid_from(x, z):
    """A regular grid (x0, dx, nx, z0, dz, nz) from MUST-style pixel coordinates ``x``, ``z``
    (``np.meshgrid`` of evenly spaced vectors), and whether the arrays are (nx, nz)."""
    x = np.asarray(x, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    if x.shape != z.shape or x.ndim != 2:
        raise ValueError(f"x, z: expected two 2-D arrays of the same shape (np.meshgrid), got {x.shape}, {z.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
        raise ValueError("x, z: contain NaN or infinite values")
    transposed = x.shape[1] == 1 or (x.shape[0] > 1 and np.ptp(x[:, 0]) > 0)
    if transposed:
        x, z = x.T, z.T
    xs, zs = x[0, :], z[:, 0]
    nz, nx = x.shape

    def step(v, name):
        if v.size == 1:
            return 1e-4
        d = np.diff(v)
        if not np.allclose(d, d[0], rtol=1e-6, atol=1e-12) or d[0] <= 0:
            raise ValueError(f"{name}: sonoflow's das needs a regular grid, increasing and evenly spaced "
                             f"(x, z = np.meshgrid(xvec, zvec))")
        # np.linspace's own step, so that x0 + i*step reproduces its values to the bit (the
        # f-number's aperture edge |x - xe| <= z/(2F) is decided on them).
        return float((v[-1] - v[0]) / (v.size - 1))

    dx, dz = step(xs, "x"), step(zs, "z")
    if not (np.allclose(x, xs[None, :], atol=1e-12) and np.allclose(z, zs[:, None], atol=1e-12)):
        raise ValueError("x, z: sonoflow's das needs a regular grid (x, z = np.meshgrid(xvec, zvec))")
    return {"x0": float(xs[0]), "dx": dx, "nx": int(nx), "z0": float(zs[0]), "dz": dz, "nz": int(nz)}, transposed


def das(SIG, x, z, delaysTX, param, method="linear", apodization="boxcar"):
    """Delay-and-sum (MUST ``das``; PyMUST's ``dasmtx(1j*SIG.shape, x, z, delaysTX, param, method)
    @ SIG``): ``SIG`` I/Q (n_samples, Nelements[, n_frames]) complex, ``x``, ``z`` the pixel
    positions (``np.meshgrid`` of evenly spaced vectors), ``delaysTX`` the transmit delays (s,
    NaN = off), ``param`` with fc, fs, pitch, Nelements, c, t0, fnumber (0 = full aperture, as
    MUST) and RXangle (rad; the receive aperture is steered, as MUST intends — PyMUST 0.1.9
    raises on it). ``method``: ``'linear'`` or ``'nearest'``. Returns the image of x's shape
    (``[..., n_frames]``), complex64.

    Differences: I/Q only (MUST also beamforms real RF); the grid must be regular;
    ``apodization='hann'`` is a sonoflow extension (MUST: boxcar)."""
    sig = np.asarray(SIG)
    if sig.dtype.kind != "c":
        raise TypeError(f"SIG: expected complex I/Q (rf2iq's output), got dtype {sig.dtype}")
    if sig.ndim not in (2, 3):
        raise ValueError(f"SIG: expected (n_samples, Nelements[, n_frames]), got shape {sig.shape}")
    if method not in ("linear", "nearest"):
        raise ValueError(f"method = {method!r}: allowed 'linear', 'nearest'")
    p = canonical(param)
    n = number(p, "Nelements", default=sig.shape[1], lo=1, integer=True)
    if n != sig.shape[1]:
        raise ValueError(f"SIG: {sig.shape[1]} channels but param.Nelements = {n}")
    grid, transposed = _grid_from(x, z)
    params = _das_params(p, n, method, apodization)
    frames = sig[:, :, None] if sig.ndim == 2 else sig
    stack = _array(np.transpose(frames, (2, 1, 0)), "SIG", np.complex64, allow_nan=False)
    d = _delays(delaysTX, n)
    img, _taps = _native.das(stack, dumps(params), dumps(grid), d)
    img = np.transpose(img, (1, 2, 0))  # (nz, nx, n_frames)
    if transposed:
        img = np.transpose(img, (1, 0, 2))
    return img[:, :, 0] if sig.ndim == 2 else img


def _radius(p):
    r = number(p, "radius", allow_inf=True, lo=0, lo_open=True)
    return {} if r is None or math.isinf(r) else {"radius": r}


def _das_params(p, n, method, apodization):
    if method not in ("linear", "nearest"):
        raise ValueError(f"method = {method!r}: allowed 'linear', 'nearest'")
    return {
        "fc": number(p, "fc", required=True, lo=0, lo_open=True),
        "c": number(p, "c", default=1540.0, lo=0, lo_open=True),
        "fs": number(p, "fs", required=True, lo=0, lo_open=True),
        "t0": number(p, "t0", default=0.0),
        "pitch": number(p, "pitch", required=True, lo=0, lo_open=True),
        "n_elements": n,
        **_radius(p),
        "fnumber": number(p, "fnumber", default=0.0, lo=0),
        "rx_angle": number(p, "RXangle", default=0.0),
        "interpolation": method,
        "apodization": apodization,
    }


def dasmtx(SIG, x, z, *args, apodization="boxcar"):
    """The delay-and-sum matrix (MUST/PyMUST ``dasmtx``): ``M = dasmtx(SIG, x, z, delaysTX,
    param[, method])`` or ``dasmtx(SIG, x, z, param[, method])`` (delays from ``param.TXdelay``).
    ``SIG`` is the I/Q (n_samples, Nelements) complex array or its size as ``1j*np.array([nl,
    nc])``. Returns a ``scipy.sparse.csr_matrix`` (x.size, nl·nc), complex64, such that
    ``(M @ SIG.flatten('F')).reshape(x.shape, order='F')`` is the image (as PyMUST's).

    Differences: I/Q only (a real SIG, MUST's RF matrix, is refused); a regular grid
    (``np.meshgrid``); ``method`` 'linear' or 'nearest'; RXangle works."""
    try:
        import scipy.sparse as sparse
    except ImportError as e:  # pragma: no cover
        raise ImportError("dasmtx returns a scipy.sparse matrix: pip install scipy") from e
    sig = np.asarray(SIG)
    if sig.dtype.kind != "c":
        raise TypeError(f"SIG: expected complex I/Q or 1j*[nl, nc], got dtype {sig.dtype}")
    if sig.ndim == 1 and sig.size == 2:
        nl, nc = int(round(sig[0].imag)), int(round(sig[1].imag))
        if nl < 2 or nc < 1:
            raise ValueError(f"SIG: size 1j*[{nl}, {nc}] needs nl >= 2, nc >= 1")
    elif sig.ndim == 2:
        nl, nc = sig.shape
    else:
        raise ValueError(f"SIG: expected (n_samples, Nelements) or 1j*[nl, nc], got shape {sig.shape}")
    if len(args) and hasattr(args[0], "keys"):
        param, rest = args[0], args[1:]
        p = canonical(param)
        if p.get("TXdelay") is None:
            raise ValueError("param.TXdelay is missing (give delaysTX or set it with txdelay)")
        delays = p["TXdelay"]
    elif len(args) >= 2:
        delays, param, rest = args[0], args[1], args[2:]
        p = canonical(param)
    else:
        raise TypeError("dasmtx: use dasmtx(SIG, x, z, delaysTX, param[, method]) or dasmtx(SIG, x, z, param[, method])")
    method = rest[0] if rest else "linear"
    n = number(p, "Nelements", default=nc, lo=1, integer=True)
    if n != nc:
        raise ValueError(f"SIG: {nc} channels but param.Nelements = {n}")
    grid, transposed = _grid_from(x, z)
    d = _delays(delays, n)
    offsets, index, w0, w1 = _native.dasmtx(nl, dumps(_das_params(p, n, method, apodization)), dumps(grid), d)
    nx, nz = grid["nx"], grid["nz"]
    ours = np.repeat(np.arange(nx * nz), np.diff(offsets.astype(np.int64)))
    # sonoflow's row iz·nx + ix → the pixel's index in x.flatten('F')
    rows = ours if transposed else (ours // nx) + (ours % nx) * nz
    idx = index.astype(np.int64)
    m = sparse.csr_matrix((np.concatenate([w0, w1]), (np.concatenate([rows, rows]), np.concatenate([idx, idx + 1]))),
                          shape=(nx * nz, nl * nc))
    m.eliminate_zeros()
    return m


def iq2doppler(IQ, param, M=1, lag=1, *, clutter=None, estimator="autocorrelation", dz=None, _all=False):
    """Doppler velocities (MUST ``iq2doppler``): ``VD, VarD = iq2doppler(IQ, param, M=1, lag=1)``
    with ``IQ`` (nz, nx, n_frames) complex, ``param`` with fc, c (1540) and PRF (or PRP), ``M`` the
    Hamming window size (scalar or [Mz, Mx]). VD > 0: towards the probe (m/s); VarD (m²/s²).

    Differences: float32 outputs (PyMUST float64). sonoflow extensions: ``clutter`` (a clutter
    filter before the estimator: ``{"type": "polynomial", "order": 2}``, ``{"type": "iir",
    "order": 4, "cutoff": 0.05}``, ``{"type": "svd"}``), ``estimator="loupas"`` (needs ``dz``)."""
    iq = np.asarray(IQ)
    if iq.ndim != 3:
        raise ValueError(f"IQ: expected (nz, nx, n_frames), got shape {iq.shape}")
    if iq.dtype.kind != "c":
        raise TypeError(f"IQ: expected complex I/Q, got dtype {iq.dtype}")
    iq = _array(iq, "IQ", np.complex64, allow_nan=True)  # NaN/inf refused by the native side
    p = canonical(param)
    prf = number(p, "PRF", lo=0, lo_open=True)
    if prf is None:
        prp = number(p, "PRP", lo=0, lo_open=True)
        if prp is None:
            raise ValueError("param.PRF (or param.PRP) is missing (required)")
        prf = 1.0 / prp
    m = np.atleast_1d(np.asarray(M)).reshape(-1)
    if m.size not in (1, 2) or not np.all(np.isfinite(m)) or np.any(m != np.round(m)) or np.any(m < 1) or np.any(m > 64):
        raise ValueError(f"M = {M}: a whole number or two in [1, 64]")
    window = [int(m[0]), int(m[-1])]
    lag_v = number({"lag": lag}, "lag", "lag", lo=1, hi=64, integer=True)
    params = {
        "fc": number(p, "fc", required=True, lo=0, lo_open=True),
        "c": number(p, "c", default=1540.0, lo=0, lo_open=True),
        "prf": prf,
        "lag": lag_v,
        "window": window,
        "estimator": estimator,
    }
    if estimator == "loupas":
        dz = number({"dz": dz}, "dz", "dz", required=True, lo=0, lo_open=True)
    v, var, power, flags = _native.iq2doppler(iq, dumps(params), dumps(clutter), float(dz or 1.0))
    if _all:
        return v, var, power, flags
    return v, var


def doppler_maps(IQ, param, M=1, lag=1, **kw):
    """``iq2doppler`` with every map of sonoflow's estimator: ``(velocity, variance, power,
    flags)``, each (nz, nx); power = Σ|IQ|² over the frames (after the clutter filter, if any),
    flags bit 0 = no estimate (zero power or zero autocorrelation), bit 1 = aliasing suspected.
    Keywords as ``iq2doppler``'s."""
    return iq2doppler(IQ, param, M, lag, _all=True, **kw)


def vector_doppler(VD, tx_angles, rx_angles, weights=None, flags=None):
    """Vector Doppler (paper 1 eq. 20): the least-squares (vx, vz) per pixel from Doppler maps of
    several (transmit, receive) angle pairs. ``VD``: a list of (nz, nx) maps or an array (n_looks,
    nz, nx), m/s, positive toward the probe (``iq2doppler``'s convention); ``tx_angles``,
    ``rx_angles``: one per map (rad; the transmit tilt, ``param.RXangle`` of the DAS); nominal
    plane-wave projection a = −(sin θt + sin θr, cos θt + cos θr)/2; ``weights``: one per map
    (inverse noise variances, e.g. fc²); ``flags``: maps' flags (bit 0: no estimate, left out).
    Returns (vx, vz, flags): vx along +x, vz along +z (deeper), float32; flags bit 0 where fewer
    than two maps were usable or the geometry is singular (then vx = vz = 0)."""
    vd = np.stack([np.asarray(m) for m in VD]) if isinstance(VD, (list, tuple)) else np.asarray(VD)
    if vd.ndim != 3 or vd.shape[0] < 2:
        raise ValueError(f"VD: expected at least two (nz, nx) maps, got shape {vd.shape}")
    vd = _array(vd, "VD", np.float32)
    tx = np.atleast_1d(np.asarray(tx_angles, dtype=np.float64)).reshape(-1)
    rx = np.atleast_1d(np.asarray(rx_angles, dtype=np.float64)).reshape(-1)
    if tx.size == 1:
        tx = np.repeat(tx, vd.shape[0])
    if tx.size != vd.shape[0] or rx.size != vd.shape[0]:
        raise ValueError(f"tx_angles, rx_angles: one per map ({vd.shape[0]}), got {tx.size} and {rx.size}")
    if not (np.all(np.isfinite(tx)) and np.all(np.isfinite(rx)) and np.all(np.abs(tx) < 1.4) and np.all(np.abs(rx) < 1.4)):
        raise ValueError("tx_angles, rx_angles: finite, |angle| < 80° (rad)")
    f = None
    if flags is not None:
        f = np.stack([np.asarray(m) for m in flags]) if isinstance(flags, (list, tuple)) else np.asarray(flags)
        f = np.ascontiguousarray(f, dtype=np.uint8)
    w = None if weights is None else [float(x) for x in np.asarray(weights, dtype=np.float64).reshape(-1)]
    return _native.vector_doppler(vd, tx.tolist(), rx.tolist(), f, w)


def smoothn(y, W=None, S=None, axis=None, TolZ=1e-3, MaxIter=100, Initial=None, Spacing=None,
            Order=2, Weight="bisquare", isrobust=False, *, flavour="pymust"):
    """Robust spline smoothing (Garcia 2010; MUST/PyMUST ``smoothn``): ``z, s, exitflag =
    smoothn(y, W=None, S=None, ..., isrobust=False)``. ``y`` an array (NaN = missing) or a list of
    arrays of one shape (a vector field, smoothed jointly). ``S`` None: chosen by GCV.

    ``flavour="pymust"`` (default here, for compatibility) reproduces PyMUST 0.1.9 including its
    deviations from Garcia's MATLAB code; ``flavour="matlab"`` follows the MATLAB code (sonoflow's
    default elsewhere; see docs/nodes.md). Complete data reproduce PyMUST to nRMS 1e-10 (S to
    1e-9). Differences: with missing values (NaN or ``W == 0``) the initial guess's
    nearest-neighbour fill breaks ties differently from scipy's ``distance_transform_edt``, and
    the result differs from PyMUST's by up to a few % (measured: nRMS 0.75 %, S 0.4 % on a
    48 × 40 field with 8 % missing); ``axis`` and ``Initial`` are not supported (a ValueError
    says so); the caller's array is never modified (PyMUST overwrites its NaNs with 0)."""
    if axis is not None:
        raise ValueError("axis: not supported (pass a list of components for a vector field)")
    if Initial is not None:
        raise ValueError("Initial: not supported")
    vector = isinstance(y, (list, tuple))
    if vector:
        comps = [np.asarray(c) for c in y]
        if not comps or any(c.shape != comps[0].shape for c in comps):
            raise ValueError("y: the components of a vector field must be arrays of one shape")
        arr = np.stack(comps)
        grid = list(comps[0].shape)
    else:
        arr = np.asarray(y)
        grid = list(arr.shape)
    if arr.size == 0:
        raise ValueError(f"y: empty array (shape {arr.shape})")
    data = _array(arr, "y", np.float64, allow_nan=True)
    infinite = np.isinf(data)
    if infinite.any():
        data = np.where(infinite, np.nan, data)
    if np.all(np.isnan(data)):
        raise ValueError("y: every value is NaN or infinite; nothing to smooth")
    weights = None
    if W is not None:
        weights = _array(W, "W", np.float64)
        if list(weights.shape) != grid:
            raise ValueError(f"W: shape {weights.shape}, expected the grid's {tuple(grid)}")
        if np.any(weights < 0):
            raise ValueError("W: weights must be >= 0")
    params = {
        "order": number({"Order": Order}, "Order", "Order", lo=1, hi=3, integer=True),
        "robust": bool(isrobust),
        "weight_function": str(Weight).lower(),
        "tol_z": number({"TolZ": TolZ}, "TolZ", "TolZ", lo=0, hi=1, lo_open=True),
        "max_iter": number({"MaxIter": MaxIter}, "MaxIter", "MaxIter", lo=1, integer=True),
        "flavour": flavour,
    }
    if S is not None:
        params["s"] = number({"S": S}, "S", "S", lo=0, lo_open=True)
    if Spacing is not None:
        sp = np.asarray(Spacing, dtype=np.float64).reshape(-1)
        if sp.size != len(grid) or not np.all(np.isfinite(sp) & (sp > 0)):
            raise ValueError(f"Spacing: expected {len(grid)} positive values, got {Spacing}")
        params["spacing"] = sp.tolist()
    z, s, converged, _outliers = _native.smoothn(data, grid, len(comps) if vector else 1, dumps(params), weights)
    if vector:
        return [z[i] for i in range(z.shape[0])], s, converged
    return z, s, converged


# Names a PyMUST user may look for.
Param = Param
Options = Options


def bmode(IQ, DR=40):
    """8-bit B-mode image of I/Q signals (MUST ``bmode``): ``|IQ|`` log-compressed over ``DR`` dB
    (``255·(20·log10(|IQ|/max) + DR)/DR``), or for ``DR < 1`` the power law ``255·(|IQ|/max)^DR``,
    clipped to [0, 255] and truncated to uint8; same shape as ``IQ``.

    Differences: computed in float64 whatever the input precision (PyMUST computes complex64 input
    in float32, so a pixel at a level boundary may differ by 1); an all-zero ``IQ`` gives zeros
    (PyMUST divides 0 by 0)."""
    iq = IQ if isinstance(IQ, np.ndarray) else np.asarray(IQ)
    if iq.dtype.kind != "c":
        raise TypeError(f"IQ: must be complex I/Q, got dtype {iq.dtype}")
    dr = number({"DR": DR}, "DR", "bmode", required=True, lo=0, lo_open=True)
    arr = _array(iq, "IQ", np.complex128)
    return _native.bmode(arr, dr).reshape(iq.shape)


def tgc(S):
    """Time-gain compensation (MUST ``tgc``): ``S, C = tgc(S)`` with ``S`` RF (real) or I/Q
    (complex), shape (n_samples, n_lines) or (n_samples,). The mean envelope over the lines (I/Q:
    ``|S|``; RF: ``|hilbert(S)|`` along time), a Theil–Sen line through its log over the middle
    80 % of the samples, and ``C = exp(a)/exp(a + b·k)`` of shape (n_samples, 1); returns ``S·C``
    (float64/complex128) and ``C``.

    Differences: computed in float64 (PyMUST keeps float32 RF in float32 through the Hilbert
    transform: gains ~1e-6 apart); PyMUST fits at most 200 randomly drawn samples (another fit on every call when
    there are more); this fits all of them (up to 2000, evenly spaced beyond), so the result is
    reproducible and equals PyMUST's whenever PyMUST uses all its samples (n_samples ≤ 250)."""
    s = S if isinstance(S, np.ndarray) else np.asarray(S)
    if s.ndim not in (1, 2):
        raise ValueError(f"S: expected (n_samples, n_lines) or (n_samples,), got shape {s.shape}")
    s2 = s.reshape(s.shape[0], -1)
    if s.dtype.kind == "c":
        gain = _native.tgc_gain_iq(_array(s2, "S", np.complex128), s2.shape[1])
    else:
        gain = _native.tgc_gain_rf(_array(s2, "S", np.float64), s2.shape[1])
    C = gain.reshape(-1, 1)
    return (s2 * C).reshape(s.shape), C


def genscat(roidim, meandist, I=None, g=None, *, seed=0, inclusions=None, z0=0.0):
    """A 2-D speckle phantom (MUST ``genscat``): ``xs, ys, zs, RC = genscat([width, height],
    meandist_or_param, I=None, g=None)``. Scatterers on a square grid of step
    ``meandist/sqrt(2/5)`` jittered by ± half a step, over x in (−width/2, width/2) and z in
    (z0, z0 + height) (MUST: z0 = 0), so the mean distance to the nearest neighbour is ≈
    ``meandist`` and the density 0.4/meandist²; ``meandist`` may be a ``param`` (MUST's
    ``c/(fc(1 + bandwidth/200))``, bandwidth 75 % and c 1540 m/s by default). ``RC`` is Rayleigh of
    mean 1, times the echogenicity image ``I`` (2-D, ≥ 0, rows = depth) when given, as MUST
    (``10^(g/20·(I/max − 1))`` for g > 1 dB, default 40; ``(I/max)^(1/g)`` for g ≤ 1); a NaN width or
    height is taken from I's aspect ratio. ``ys`` is zeros.

    sonoflow's additions: ``seed`` (the same seed gives the same phantom; another moves every
    scatterer: PyMUST draws from numpy's global generator), ``inclusions`` (a list of dicts
    ``{"x", "z", "radius", "level_db"}``, level in dB relative to the background, absent, None or
    −inf: anechoic; a later inclusion overrides an earlier one) and ``z0``. Differences: 2-D only;
    the image is sampled at pixel centres with its edge pixels extended (PyMUST's interpolation
    gives 0 in the outer half pixel and shifts x by half a pixel); the amplitudes are Rayleigh
    with or without an image (PyMUST multiplies an image's levels by hypot of two uniform
    numbers); no random reordering."""
    r = np.asarray(roidim, dtype=float).reshape(-1)
    if r.size == 3:
        raise ValueError("roidim: 3-D phantoms ([width, height, depth]) are not supported; give [width, height]")
    if r.size != 2:
        raise ValueError(f"roidim: expected [width, height] (m), got {roidim!r}")
    width, height = float(r[0]), float(r[1])
    if hasattr(meandist, "keys"):
        p = canonical(meandist, "param")
        fc = number(p, "fc", "param", required=True, lo=0.0, lo_open=True)
        bw = number(p, "bandwidth", "param", default=75.0, lo=0.0, hi=200.0, lo_open=True)
        c = number(p, "c", "param", default=1540.0, lo=0.0, lo_open=True)
        if bw >= 200.0:
            raise ValueError(f"param.bandwidth = {bw} must be in (0, 200) %")
        md = c / (fc * (1 + bw / 200))
    else:
        if isinstance(meandist, (bool, str, bytes)) or not np.isscalar(meandist):
            raise TypeError(f"meandist: expected a positive number or a param, got {type(meandist).__name__}")
        md = float(meandist)
        if not (math.isfinite(md) and md > 0):
            raise ValueError(f"meandist = {md} must be finite and > 0 (m)")
    image = None
    if I is not None:
        image = _array(I, "I", np.float64, ndim=2)
        if np.any(image < 0):
            raise ValueError("I: must be non-negative")
        m, n = image.shape
        if not math.isfinite(width) and math.isfinite(height):
            width = n * height / m
        elif not math.isfinite(height) and math.isfinite(width):
            height = m * width / n
    elif g is not None:
        raise ValueError("g: only used with an image I")
    for name, v in (("roidim[0] (width)", width), ("roidim[1] (height)", height)):
        if not math.isfinite(v):
            raise ValueError(f"{name} = {v}: must be finite (NaN only with an image I, the other finite)")
    incl = []
    for k, inc in enumerate(inclusions or []):
        if not hasattr(inc, "keys"):
            raise TypeError(f"inclusions[{k}]: expected a dict with x, z, radius, level_db")
        unknown = set(inc) - {"x", "z", "radius", "level_db"}
        if unknown:
            raise ValueError(f"inclusions[{k}]: unknown field(s) {sorted(unknown)} (x, z, radius, level_db)")
        d = {key: number(inc, key, f"inclusions[{k}]", required=True) for key in ("x", "z", "radius")}
        lv = inc.get("level_db")
        if lv is not None and not (isinstance(lv, (int, float)) and lv == -math.inf):
            d["level_db"] = number(inc, "level_db", f"inclusions[{k}]")
        incl.append(d)
    x, z, rc = _native.genscat(width, height, float(z0), md, int(seed), dumps(incl), image,
                               40.0 if g is None else float(g))
    return x, np.zeros_like(x), z, rc


def pfield(x, y, z, delaysTX, param, isQuick=False, options=None):
    """RMS pressure field of one transmit (MUST ``pfield``): ``RP, SPECT, IDX = pfield(x, y, z,
    delaysTX, param[, isQuick][, options])``. ``x``, ``z`` any shape (RP has it); ``y`` ``None``,
    empty or zeros: the 2-D field; a ``y`` of x's shape with any |y| ≥ 1e-9 m: MUST's elevation
    model (3-D distances, 1/r, the multi-Gaussian beam of an element of ``param.height`` focused at
    ``param.focus`` in elevation, both ∞ when unset); ``delaysTX`` one row of ``txdelay`` (s, NaN: element off),
    ``param`` with ``TXapodization``, ``attenuation``, ``baffle``… as in ``simus``; ``options``:
    ``dBThresh`` (−60), ``FrequencyStep``, ``FullFrequencyDirectivity``, ``ElementSplitting``;
    ``isQuick=True`` sets MUST's quick options (−20 dB, one sub-element, step 1.5). IDX: the
    frequencies of MUST's grid (0 … 2 fc) in the band.

    Differences: ``SPECT`` is ``None`` (the per-frequency field is not returned); phasors are
    stepped in float64 (PyMUST: complex64), so the fields agree to PyMUST's own float32 error
    (nRMS ~1e-6). Convex arrays (finite ``param.radius``): elements on the arc, zero field behind
    the face, as MUST (nRMS 2.4e-6 – 5.4e-6 against PyMUST on three convex probes, asserted < 2e-5)."""
    if isinstance(isQuick, dict) or hasattr(isQuick, "keys"):
        isQuick, options = False, isQuick
    xa = _array(x, "x", np.float64)
    za = _array(z, "z", np.float64)
    if xa.shape != za.shape:
        raise ValueError(f"x, z: must have the same shape, got {xa.shape}, {za.shape}")
    ya = None
    if y is not None and np.size(y):
        ya = _array(y, "y", np.float64)
        if ya.shape != xa.shape:
            raise ValueError(f"y: must have the shape of x, got {ya.shape}, {xa.shape}")
        if not np.any(np.abs(ya) >= 1e-9):
            ya = None  # PyMUST: the 2-D field
    p = canonical(param)
    d_in = _array(delaysTX, "delaysTX", np.float64, allow_nan=True)
    if d_in.ndim == 2 and d_in.shape[0] != 1:
        raise ValueError(f"delaysTX: one transmit (one row), got shape {d_in.shape}")
    if "Nelements" not in p:
        p["Nelements"] = d_in.size  # PyMUST: from the delays
    n = number(p, "Nelements", required=True, lo=1, integer=True)
    d = _delays(d_in, n)
    if np.any(d_in[np.isfinite(d_in)] < 0):
        raise ValueError("delaysTX: must be ≥ 0 s (NaN: element off)")
    pj = probe_json(p, delays=d)
    o = _options_json(options, simus=False)
    if isQuick:
        o.update(db_thresh=-20.0, element_splitting=1, full_frequency_directivity=False, frequency_step=1.5)
    o.setdefault("db_thresh", -60.0)
    yv = None if ya is None else ya.reshape(-1)
    rp, idx, _df = _native.pfield(xa.reshape(-1), yv, za.reshape(-1), dumps(pj), dumps(o))
    return rp.reshape(xa.shape), None, idx


def sptrack(I, param, *, smooth=True):
    """Speckle tracking (MUST ``sptrack``): ``Dj, Di, j, i = sptrack(I, param)``, the motion from
    image ``I[:, :, k]`` to ``I[:, :, k + iminc]`` (pixels; ``i`` rows, downward, ``j`` columns),
    by FFT cross-correlation of interrogation windows, with an ensemble correlation over every
    pair when ``I`` holds more than two images. Outputs are in PyMUST's order (columns first);
    ``j``, ``i`` are the window centres (0-based pixel centres, MATLAB's convention: PyMUST's are
    half a pixel further).

    ``param`` fields (a Param or a dict): ``winsize`` (REQUIRED, ``[rows, cols]`` or one row per
    pass, non-increasing, each 4 … 256), ``overlap`` (%, [0, 95], default 50), ``iminc`` (default
    1, < number of images), ``subpix`` (``'FI'``, default: the peak of the correlation's Fourier
    interpolant, unbiased for a translation; ``'PF'``: MUST's parabolic fit; ``'OF'`` is not
    supported), ``ROI`` (2-D bool of the image's size: estimates whose centre falls outside are
    NaN). ``smooth=True`` smooths the last pass robustly with ``smoothn`` weighted by
    √correlation, as MUST does (``smooth=False``: the raw estimates, NaN where rejected).

    Differences from PyMUST: between passes the estimates are validated by the normalised median
    test and a correlation threshold (0.2) instead of ``smoothn``; the correlation is divided by
    the Hann windows' autocorrelation (removes their pull toward zero); the second window is offset
    by half the predicted displacement on each side; NaN images are refused (use ``ROI``)."""
    a = np.asarray(I) if isinstance(I, (list, tuple)) else I
    if not isinstance(a, np.ndarray):
        raise TypeError(f"I: expected a numpy array (rows, columns, images), got {type(I).__name__}")
    if a.ndim != 3:
        raise ValueError(f"I: expected 3 axes (rows, columns, images), got shape {a.shape}")
    img = _array(a, "I", np.float64, ndim=3)
    m, n, nimg = img.shape
    if nimg < 2:
        raise ValueError(f"I: needs at least 2 images along the third axis, got {nimg}")
    if not hasattr(param, "keys"):
        raise TypeError(f"param: expected a Param or a dict, got {type(param).__name__}")
    p = {k.lower(): v for k, v in param.items()}
    if p.get("winsize") is None:
        raise ValueError("param.winsize is missing (required): [rows, cols] or one row per pass")
    w = np.asarray(p["winsize"])
    if w.ndim == 1:
        w = w.reshape(1, -1)
    if w.ndim != 2 or w.shape[1] != 2 or w.shape[0] < 1 or w.dtype.kind not in "iuf":
        raise ValueError(f"param.winsize must be a 2-column array of window sizes, got {p['winsize']!r}")
    if np.any(w != np.round(w)):
        raise ValueError(f"param.winsize must hold whole numbers, got {w.tolist()}")
    overlap = number(p, "overlap", "param", default=50.0, lo=0.0, hi=95.0)
    iminc = number(p, "iminc", "param", default=1, lo=1, integer=True)
    if iminc >= nimg:
        raise ValueError(f"param.iminc = {iminc} must be < the number of images ({nimg})")
    if iminc > 64:
        raise ValueError(f"param.iminc = {iminc} is out of range: must be [1, 64]")
    subpix = p.get("subpix", "FI")
    if subpix not in ("FI", "PF"):
        raise ValueError(f"param.subpix = {subpix!r}: 'FI' (Fourier, default) or 'PF' (parabolic); 'OF' is not supported")
    roi = p.get("roi")
    if roi is not None:
        roi = np.asarray(roi)
        if roi.dtype != bool or roi.shape != (m, n):
            raise ValueError(f"param.ROI must be a bool array of shape {(m, n)}, got {roi.dtype} {roi.shape}")
    for k, (r, c) in enumerate(w.astype(int)):
        if r > m or c > n:
            raise ValueError(f"param.winsize[{k}] = [{r}, {c}] is larger than the {m}×{n} images")
    import json
    params = {"windows": w.astype(int).tolist(), "overlap": overlap / 100.0, "lag": iminc,
              "subpixel": "fourier" if subpix == "FI" else "parabolic"}
    frames = np.ascontiguousarray(np.moveaxis(img, 2, 0))
    di, dj, rho, valid, ic, jc = _native.sptrack(frames, json.dumps(params))
    ok = valid > 0
    if smooth:
        z, _, _ = smoothn([np.where(ok, di, np.nan), np.where(ok, dj, np.nan)], np.sqrt(np.clip(rho, 0, 1)) * ok,
                          isrobust=True, flavour="matlab")
        di, dj = z[0], z[1]
    else:
        di, dj = np.where(ok, di, np.nan), np.where(ok, dj, np.nan)
    j, i = np.meshgrid(jc, ic)
    if roi is not None:
        inside = roi[np.clip(np.round(i).astype(int), 0, m - 1), np.clip(np.round(j).astype(int), 0, n - 1)]
        di, dj = np.where(inside, di, np.nan), np.where(inside, dj, np.nan)
    return dj, di, j, i
