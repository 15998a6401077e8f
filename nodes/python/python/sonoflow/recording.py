"""Reading sonoflow recordings (MCAP) as numpy arrays: ``Recording(path)``.

Each raw record is the wire header exactly as in shared memory plus the payload (docs/recording.md);
the layout of every message type comes from the ``ros2msg`` schema that ``sonoflow-messages``
generates from the wire structs (``sonoflow._native.wire_layout``), so nothing here repeats it."""

import numpy as np

from . import _native

_PRIM = {
    "uint8": np.uint8, "uint16": np.uint16, "uint32": np.uint32, "uint64": np.uint64,
    "int8": np.int8, "int16": np.int16, "int32": np.int32, "int64": np.int64,
    "float32": np.float32, "float64": np.float64,
}


def _parse_schema(text):
    """ros2msg text → (top-level fields, {nested type: fields}); fields are (type, name)."""
    parts = text.split("=" * 80 + "\n")
    def fields(body):
        out = []
        for line in body.splitlines():
            line = line.split("#", 1)[0].strip()
            if line:
                t, n = line.split()[:2]
                out.append((t, n))
        return out
    top = fields(parts[0])
    nested = {}
    for p in parts[1:]:
        first, _, body = p.partition("\n")
        nested[first.replace("MSG:", "").strip()] = fields(body)
    return top, nested


def _dtype(t, nested):
    """numpy dtype of a ros2msg field type (fixed arrays and nested types; no sequences)."""
    shape = ()
    if t.endswith("]"):
        t, n = t[:-1].split("[")
        shape = (int(n),)
    if t in _PRIM:
        base = np.dtype(_PRIM[t])
    elif t in nested:
        f = nested[t]
        if [n for _, n in f] == ["re", "im"] and all(x == "float32" for x, _ in f):
            base = np.dtype(np.complex64)
        else:
            base = np.dtype([(n, _dtype(ft, nested)) for ft, n in f])
    else:
        raise ValueError(f"schema: unsupported field type {t!r}")
    return np.dtype((base, shape)) if shape else base


class _Layout:
    def __init__(self, schema):
        name, hsize, esize, text = _native.wire_layout(schema)
        top, nested = _parse_schema(text)
        (ht, _), (et, _) = top[0], top[1]
        self.name = name
        self.header = _dtype(ht, nested)
        self.elem = _dtype(et.rstrip("[]"), nested)
        if self.header.itemsize != hsize or self.elem.itemsize != esize:
            raise ValueError(f"{name}: schema sizes {self.header.itemsize}/{self.elem.itemsize} "
                             f"differ from the wire's {hsize}/{esize}")


def _to_python(v):
    """A numpy structured scalar as nested dicts; arrays stay arrays, numbers become Python's."""
    if isinstance(v, np.void) and v.dtype.names:
        return {n: _to_python(v[n]) for n in v.dtype.names}
    if isinstance(v, np.ndarray):
        return v.copy()
    if isinstance(v, np.generic):
        return v.item()
    return v


class Message:
    """One recorded message: ``topic``, ``type`` (wire type name), ``sequence``, ``log_time`` (ns),
    ``header`` (nested dict of the wire header's fields) and ``data`` (a read-only numpy view of
    the payload: float32, complex64 or a structured dtype, flat; see ``shape()``)."""

    __slots__ = ("topic", "type", "sequence", "log_time", "publish_time", "header", "data")

    def __init__(self, topic, type_, sequence, log_time, publish_time, header, data):
        self.topic, self.type, self.sequence = topic, type_, sequence
        self.log_time, self.publish_time, self.header, self.data = log_time, publish_time, header, data

    def __repr__(self):
        return f"Message({self.topic!r}, {self.type}, seq {self.sequence}, {self.data.size} elements)"


class Recording:
    """A sonoflow MCAP recording (also an unfinished one: the messages of its complete chunks).

        rec = sonoflow.Recording("runs/quickstart-…/recording.mcap")
        rec.topics()                       # {topic: (wire type, message count)}
        for m in rec.messages("regularised"):
            g = m.header["grid"]
            planes = m.data.reshape(m.header["n_planes"], g["nz"], g["nx"])
    """

    def __init__(self, path):
        self._r = _native.RecordingReader(str(path))
        self.path = str(path)
        self._layouts = {}

    @property
    def complete(self):
        """False for a file whose writer did not finish (read up to its last complete chunk)."""
        return self._r.is_complete()

    def topics(self):
        """{topic: (wire type name or schema, message count or None)} of the sonoflow topics."""
        out = {}
        for topic, schema, count in self._r.topics():
            layout = self._layout(schema)
            out[topic] = (layout.name if layout else schema, count)
        return out

    def metadata(self):
        """The metadata records as {name: {key: value}} (e.g. ``run``, ``recording_stats``)."""
        return {name: dict(kv) for name, kv in self._r.metadata()}

    def _layout(self, schema):
        if schema not in self._layouts:
            try:
                self._layouts[schema] = _Layout(schema)
            except ValueError:
                self._layouts[schema] = None  # not a sonoflow wire type (pictures, stats)
        return self._layouts[schema]

    def messages(self, topics=None, start=None, end=None):
        """Yields the ``Message``s of ``topics`` (a name, a list, or None = every sonoflow topic)
        with log time in [start, end) (ns), in log-time order. Pictures (``viz/…``) and other
        non-wire channels are skipped."""
        if isinstance(topics, str):
            topics = [topics]
        if topics is not None:
            known = {t for t, _, _ in self._r.topics()}
            missing = [t for t in topics if t not in known]
            if missing:
                raise ValueError(f"topics: {missing} not in the recording (it has {sorted(known)})")
        for topic, schema, seq, log_time, pub_time, data in self._r.messages(topics, start, end):
            layout = self._layout(schema)
            if layout is None:
                continue
            header = np.frombuffer(data, dtype=layout.header, count=1, offset=4)[0]
            hs = layout.header.itemsize
            n = int(np.frombuffer(data, dtype="<u4", count=1, offset=4 + hs)[0])
            payload = np.frombuffer(data, dtype=layout.elem, count=n, offset=8 + hs)
            yield Message(topic, layout.name, seq, log_time, pub_time, _to_python(header), payload)
