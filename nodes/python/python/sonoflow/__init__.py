"""sonoflow from Python: PyMUST-compatible ultrasound simulation and flow estimation computed by
sonoflow's Rust libraries, numpy arrays in and out.

    import numpy as np, sonoflow as sf
    param = sf.getparam("L11-5v")
    dels = sf.txdelay(param, 0.0)
    rf, _ = sf.simus(x, z, rc, dels, param)

Functions (MUST/PyMUST names, argument order and ``param`` fields): ``getparam``, ``txdelay``,
``simus``, ``rf2iq``, ``das``, ``iq2doppler``, ``smoothn``; ``Param`` and ``Options`` are dicts
with attribute access (a PyMUST ``Param`` or a plain dict works as well). The GIL is released
while they compute; ``set_threads(n)`` sets the worker threads (0 = one per core).

Graphs and recordings: ``run(launch_file, set=..., swap=..., out=...)`` runs a graph with the
``sonoflow`` executable and returns its report; ``Recording(path)`` reads a recording's messages
as numpy arrays with their decoded headers; ``Node()`` makes the running program a node of a
graph (a launch file's ``exec`` node: an estimator written in Python); ``look_projection(header)``
gives such an estimator the built-in ``doppler`` node's per-pixel projections of a look.
"""

from . import _native
from ._param import Options, Param
from .graph import run
from .must import (bmode, das, dasmtx, doppler_maps, genscat, getparam, iq2doppler, pfield, probes, rf2iq, simus,
                   smoothn, sptrack, tgc, txdelay, vector_doppler)
from .node import Node, look_projection
from .recording import Message, Recording

__all__ = ["Param", "Options", "getparam", "probes", "txdelay", "simus", "rf2iq", "das", "dasmtx", "iq2doppler",
           "doppler_maps", "vector_doppler", "smoothn", "bmode", "tgc", "genscat", "pfield", "sptrack", "set_threads", "threads", "run", "Recording", "Message", "Node",
           "look_projection"]


def set_threads(n):
    """Worker threads of every later call (0 = one per core, the default)."""
    if isinstance(n, bool) or not isinstance(n, int) or n < 0:
        raise ValueError(f"n = {n!r}: a whole number >= 0 (0 = one thread per core)")
    _native.set_threads(n)


def threads():
    """The number of worker threads a call uses now."""
    return _native.threads()
