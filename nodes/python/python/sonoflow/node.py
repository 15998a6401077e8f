"""Graph nodes written in Python: ``sonoflow.Node``.

A launch file runs a Python node as an ``exec`` node (its own process, like any external node):

    [nodes.doppler.variants.python]
    exec = "python3"                     # an interpreter that can import sonoflow
    args = ["estimator.py"]              # relative to the launch file's folder
    ports = { iq = "IqFrameV3", vector = "VectorFieldV2", maps = "DopplerMapV2" }

and the program speaks the wire format through this package (the node kit's ports; headers as
the dicts ``Recording`` yields, laid out by the wire structs' own schemas):

    node = sonoflow.Node()                       # ports and params from the launcher
    for m in node.messages("iq"):                # until end of stream
        ...
        node.publish("vector", header, data)     # header: dict (node.header("vector") as a start)
    node.finish()                                # end of stream on every output
"""

import json
import time

import numpy as np

from . import _native
from .recording import Message, _Layout, _to_python

CONSTANTS = _native.wire_constants()


def _fill(arr, value, path):
    """Writes a (nested) dict / sequence / number into the 0-d structured ``arr``."""
    if isinstance(value, dict):
        names = arr.dtype.names or ()
        for k, v in value.items():
            if k not in names:
                raise ValueError(f"header: {path}{k} is not a field of {arr.dtype} (fields: {', '.join(names)})")
            _fill(arr[k], v, f"{path}{k}.")
        return
    target = arr
    v = np.asarray(value)
    if target.shape and v.shape != target.shape:
        if v.ndim != 1 or v.size > target.size:
            raise ValueError(f"header: {path[:-1]} takes at most {target.size} values, got shape {v.shape}")
        target[...] = 0
        target[: v.size] = v
    else:
        target[...] = v


def _header_number(header, path, integer=False):
    """``header[a][b]…`` for the dotted ``path`` as a finite float (or a whole int), else an error
    naming ``header.<path>``."""
    v = header
    for k in path.split("."):
        if not isinstance(v, dict) or k not in v:
            raise ValueError(f"header.{path}: missing (an IqFrameV3 header is needed)")
        v = v[k]
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise TypeError(f"header.{path}: expected a number, got {type(v).__name__}")
    if integer:
        if not float(v).is_integer() or v < 0:
            raise ValueError(f"header.{path} = {v!r}: expected a whole number >= 0")
        return int(v)
    return float(v)


def look_projection(header):
    """The per-pixel Doppler projection vectors of the look an I/Q frame header describes: float32
    (2, nz, nx), ``a_x`` then ``a_z``, the velocity the look measures being ``a · (vx, vz)``,
    through the receive aperture the header carries (pitch, elements, f-number, element width,
    convex radius, apodisation) — what the built-in ``doppler`` node uses with its default
    ``projection = "aperture"``. ``None`` when the header carries no aperture (``n_elements`` 0):
    then the nominal plane-wave projection ``-(sin θt + sin θr, cos θt + cos θr)/2`` applies.
    A missing, non-numeric or out-of-range field raises ``ValueError``/``TypeError`` naming it."""
    if not isinstance(header, dict):
        raise TypeError(f"header: expected the dict of an IqFrameV3 message, got {type(header).__name__}")
    n_elements = _header_number(header, "n_elements", integer=True)
    if n_elements == 0:
        return None
    apod = _header_number(header, "apodization", integer=True)
    if apod not in (0, CONSTANTS["APODIZATION_HANN"]):
        raise ValueError(f"header.apodization = {apod}: 0 (boxcar) or {CONSTANTS['APODIZATION_HANN']} (Hann)")
    values = {k: _header_number(header, k) for k in ("pitch", "fnumber", "element_width", "radius", "fc", "c", "tx_angle", "rx_angle")}
    grid = {k: _header_number(header, f"grid.{k}") for k in ("x0", "z0", "dx", "dz")}
    grid.update({k: _header_number(header, f"grid.{k}", integer=True) for k in ("nx", "nz")})
    for k, v in list(values.items()) + [(f"grid.{k}", v) for k, v in grid.items()]:
        if k != "radius" and not np.isfinite(v):
            raise ValueError(f"header.{k} = {v}: must be finite")
    width, radius = values["element_width"], values["radius"]
    aperture = {
        "pitch": values["pitch"],
        "n_elements": n_elements,
        "fnumber": values["fnumber"],
        "width": width if width > 0 else None,
        "radius": radius if np.isfinite(radius) and radius > 0 else None,
        "apodization": "hann" if apod == CONSTANTS["APODIZATION_HANN"] else "boxcar",
    }
    return _native.aperture_projection(json.dumps(aperture), values["fc"], values["c"], values["tx_angle"],
                                       values["rx_angle"], json.dumps(grid))


class Node:
    """This process as a node of the running graph (see the module's doc)."""

    def __init__(self):
        self._k = _native.NodeKit()
        self.name = self._k.name()
        p = json.loads(self._k.params())
        self.params = p if isinstance(p, dict) else {}
        self.inputs, self.outputs = self._k.ports()
        self._layouts = {}
        self._last_t = 0.0
        self._done = False

    def _layout(self, kind):
        if kind not in self._layouts:
            self._layouts[kind] = _Layout(kind)
        return self._layouts[kind]

    def messages(self, port, poll_s=0.0005):
        """Yields the ``Message``s of input ``port`` until its end of stream (SIGINT/SIGTERM raise
        KeyboardInterrupt). The payload is a read-only numpy view of the received bytes."""
        if port not in self.inputs:
            raise ValueError(f"port: {port!r} is not an input of node {self.name!r} (inputs: {sorted(self.inputs)})")
        layout = self._layout(self.inputs[port])
        while True:
            r = self._k.try_receive(port)
            if r is None:
                self._k.check_termination()
                time.sleep(poll_s)
                continue
            if r is False:
                return
            hb, pb = r
            header = _to_python(np.frombuffer(hb, dtype=layout.header, count=1)[0])
            data = np.frombuffer(pb, dtype=layout.elem)
            c = header["common"]
            self._last_t = max(self._last_t, c["t_valid"])
            yield Message(port, layout.name, c["seq"], c["t_pub_ns"], c["t_pub_ns"], header, data)

    def header(self, port):
        """A zeroed header of output ``port``'s message type, as a nested dict to fill in."""
        if port not in self.outputs:
            raise ValueError(f"port: {port!r} is not an output of node {self.name!r} (outputs: {sorted(self.outputs)})")
        return _to_python(np.zeros(1, dtype=self._layout(self.outputs[port]).header)[0])

    def publish(self, port, header, data):
        """Publishes ``header`` (a nested dict; missing fields are 0) and ``data`` (converted to
        the port's element type, flattened) on output ``port``."""
        if port not in self.outputs:
            raise ValueError(f"port: {port!r} is not an output of node {self.name!r} (outputs: {sorted(self.outputs)})")
        layout = self._layout(self.outputs[port])
        h = np.zeros((), dtype=layout.header)
        _fill(h, header, "")
        payload = np.ascontiguousarray(np.asarray(data).reshape(-1), dtype=layout.elem)
        c = h["common"]
        self._k.publish(port, h.tobytes(), payload.tobytes(), int(c["frame_id"]), float(c["t_valid"]),
                        int(c["compute_ns"]))

    def finish(self):
        """Sends end of stream on every output and ends the node (its statistics reach the
        report). Called by ``with Node() as node:`` on a normal exit."""
        if not self._done:
            self._done = True
            self._k.finish(self._last_t)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.finish()
        return False
