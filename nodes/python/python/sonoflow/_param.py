"""MUST/PyMUST parameter structures: ``Param`` and ``Options`` (dicts with attribute access, as
PyMUST's), and the conversion of a PyMUST ``Param``, a ``sonoflow.Param`` or a plain ``dict`` into
the JSON objects the native functions read (sonoflow's field names, checked values)."""

import json
import math
import numbers

import numpy as np

# MUST's canonical spellings; a key is matched without regard to case (as PyMUST's
# ``ignoreCaseInFieldNames``, without its lost ``RXdelay``/``TXapodization`` aliases).
PARAM_FIELDS = (
    "fc", "pitch", "width", "kerf", "Nelements", "bandwidth", "radius", "focus", "height",
    "baffle", "c", "attenuation", "fs", "TXnow", "TXdelay", "TXapodization", "TXfreqsweep",
    "fnumber", "PRF", "PRP", "RXangle", "RXdelay", "t0", "Nsub",
)
OPTION_FIELDS = (
    "dBThresh", "FrequencyStep", "FullFrequencyDirectivity", "ElementSplitting", "ParPool",
    "WaitBar", "CallFun",
)
_CANON = {k.lower(): k for k in PARAM_FIELDS + OPTION_FIELDS}


class _Struct(dict):
    """A dict whose keys are also attributes (``p.fc`` is ``p["fc"]``)."""

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __setattr__(self, name, value):
        self[name] = value

    def __delattr__(self, name):
        try:
            del self[name]
        except KeyError:
            raise AttributeError(name) from None

    def __repr__(self):
        return f"{type(self).__name__}({dict.__repr__(self)})"


class Param(_Struct):
    """MUST's ``param`` structure (probe, medium, acquisition): ``fc``, ``pitch``, ``kerf``,
    ``width``, ``Nelements``, ``bandwidth``, ``c``, ``fs``, ``TXnow``, ``TXdelay``, ``PRF``,
    ``fnumber``, ``RXangle``, ``t0``… SI units. A PyMUST ``Param`` or a plain dict works too."""


class Options(_Struct):
    """MUST's ``options`` of ``simus``: ``dBThresh``, ``FrequencyStep``,
    ``FullFrequencyDirectivity``, ``ElementSplitting`` (``ParPool``, ``WaitBar`` are accepted and
    ignored: sonoflow's threads are set with ``sonoflow.set_threads``)."""


def canonical(param, name="param"):
    """The fields of a Param/dict under MUST's canonical names (case-insensitive match).
    Unknown fields are kept under their own name."""
    if param is None:
        return {}
    if not hasattr(param, "keys"):
        raise TypeError(f"{name}: expected a Param, an Options or a dict, got {type(param).__name__}")
    out = {}
    for k in param.keys():
        if not isinstance(k, str):
            raise TypeError(f"{name}: field names must be strings, got {k!r}")
        c = _CANON.get(k.lower(), k)
        if c in out:
            raise ValueError(f"{name}: field {c!r} is given twice ({k!r})")
        out[c] = param[k]
    return out


def number(p, key, name="param", *, required=False, default=None, lo=None, hi=None,
           lo_open=False, integer=False, allow_inf=False):
    """A finite real field (or ``default``), checked against [lo, hi] (``lo_open``: lo < v)."""
    v = p.get(key)
    if v is None:
        if required:
            raise ValueError(f"{name}.{key} is missing (required)")
        return default
    if isinstance(v, np.ndarray):
        if v.size != 1:
            raise ValueError(f"{name}.{key} must be a scalar, got an array of shape {v.shape}")
        v = v.reshape(-1)[0]
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name}.{key} must be a real number, got {type(v).__name__}")
    v = float(v)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"{name}.{key} = {v} must be finite")
    rng = f"[{lo}, {hi}]" if hi is not None else (f"> {lo}" if lo_open else f">= {lo}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name}.{key} = {v} is out of range: must be {rng}")
    if hi is not None and v > hi:
        raise ValueError(f"{name}.{key} = {v} is out of range: must be {rng}")
    if integer:
        if v != int(v):
            raise ValueError(f"{name}.{key} = {v} must be a whole number")
        return int(v)
    return v


def probe_json(p, name="param", delays=None):
    """sonoflow's MustParam JSON for SIMUS and txdelay (probe, medium, transmit)."""
    out = {
        "fc": number(p, "fc", name, required=True, lo=0, lo_open=True),
        "pitch": number(p, "pitch", name, required=True, lo=0, lo_open=True),
        "Nelements": number(p, "Nelements", name, required=True, lo=1, integer=True),
    }
    for key, k2 in (("width", "width"), ("kerf", "kerf"), ("bandwidth", "bandwidth"), ("c", "c"),
                    ("attenuation", "attenuation"), ("fs", "fs"), ("TXnow", "tx_now"),
                    ("focus", "focus"), ("height", "height")):
        v = number(p, key, name, allow_inf=key == "focus")
        if v is not None and not (key == "focus" and math.isinf(v)):
            out[k2] = v
    if "width" not in out and "kerf" not in out:
        raise ValueError(f"{name}.width or {name}.kerf is missing (one is required)")
    r = number(p, "radius", name, allow_inf=True, lo=0, lo_open=True)
    if r is not None and not math.isinf(r):
        out["radius"] = r
    b = p.get("baffle")
    if b is not None:
        out["baffle"] = b.lower() if isinstance(b, str) else number(p, "baffle", name, lo=0, lo_open=True)
    if p.get("TXfreqsweep") is not None and not (np.size(p["TXfreqsweep"]) == 1 and np.isnan(p["TXfreqsweep"])):
        raise ValueError(f"{name}.TXfreqsweep: chirp transmits are not supported (remove the field)")
    n = out["Nelements"]
    if delays is not None:
        out["TXdelay"] = [None if math.isnan(d) else float(d) for d in delays]
    apod = p.get("TXapodization")
    if apod is not None:
        a = np.asarray(apod, dtype=np.float64).reshape(-1)
        if a.size != n or not np.all(np.isfinite(a)):
            raise ValueError(f"{name}.TXapodization must hold {n} finite values")
        out["TXapodization"] = a.tolist()
    return out


def dumps(obj):
    return json.dumps(obj, allow_nan=False)
