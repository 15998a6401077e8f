"""Running sonoflow graphs from Python: ``sonoflow.run(launch_file, set=..., swap=..., out=...)``.

A graph is a set of node processes started by the ``sonoflow`` executable (the launcher and every
built-in node kind are that one binary), so ``run`` calls it: ``SONOFLOW_BIN`` if set, else
``sonoflow`` on the PATH. Build it with ``cargo build --release -p sonoflow``."""

import json
import os
import re
import shutil
import subprocess
import sys


def _binary():
    b = os.environ.get("SONOFLOW_BIN") or shutil.which("sonoflow")
    if not b:
        raise FileNotFoundError(
            "the sonoflow executable was not found: set SONOFLOW_BIN to it or put it on the PATH "
            "(build: cargo build --release -p sonoflow → target/release/sonoflow)")
    if not os.access(b, os.X_OK):
        raise FileNotFoundError(f"SONOFLOW_BIN = {b!r} is not an executable file")
    return b


def _toml_value(v, key):
    """A Python value as the TOML value of a ``--set`` (strings quoted, lists as arrays)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError(f"set[{key!r}] = {v}: must be finite")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x, key) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x, key)}" for k, x in v.items()) + "}"
    raise TypeError(f"set[{key!r}]: {type(v).__name__} has no TOML form (use str, number, bool, list, dict)")


def run(launch_file, set=None, swap=None, out=None, quiet=True, echo=True, live=None):
    """Runs the graph of ``launch_file`` and returns ``{"report": <report.json as a dict>,
    "evaluations": {label: <evaluation[-label].json as a dict>}, "out": folder, "report_md": path,
    "recording": path or None}`` (the scene's evaluators: unlabelled ``""``).

    ``set``: ``{"flow.seed": 2, "doppler.clutter": {"type": "svd"}}`` (Python values, as the CLI's
    ``--set NODE.PARAM=VALUE``) or a list of ``"NODE.PARAM=VALUE"`` strings; ``swap``:
    ``{"doppler": "external"}`` or a list of ``"NODE=VARIANT"``; ``out``: the output folder
    (default ``runs/<graph>-<date-time>`` under the working directory); ``live``: watch the run
    in Foxglove (``True``: ``ws://127.0.0.1:8765``, or an address ``"HOST:PORT"``; its URL is
    printed, and the node is ``live`` for ``set``, e.g. ``{"live.linger_s": 30}``). The launcher's lines are
    passed through to stderr (``echo=False``: kept quiet). A failed run raises ``RuntimeError``
    with the launcher's last lines; a bad file or parameter is reported before anything starts."""
    if not os.path.isfile(launch_file):
        raise FileNotFoundError(f"launch_file: {launch_file!r} does not exist")
    args = [_binary(), "run", str(launch_file)]
    if quiet:
        args.append("--quiet")
    sets = []
    if isinstance(set, dict):
        sets = [f"{k}={_toml_value(v, k)}" for k, v in set.items()]
    elif set is not None:
        sets = [str(s) for s in set]
    for s in sets:
        args += ["--set", s]
    swaps = [f"{k}={v}" for k, v in swap.items()] if isinstance(swap, dict) else list(swap or [])
    for s in swaps:
        args += ["--swap", s]
    if out is not None:
        args += ["--out", str(out)]
    if live is True:
        args.append("--live")
    elif live not in (None, False):
        if not isinstance(live, str):
            raise TypeError(f"live: expected True or an address 'HOST:PORT', got {type(live).__name__}")
        args += ["--live", live]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line.rstrip("\n"))
        if echo:
            sys.stderr.write(line)
    rc = proc.wait()
    if rc != 0:
        tail = "\n".join(lines[-15:])
        raise RuntimeError(f"sonoflow run {launch_file} failed (exit status {rc}):\n{tail}")
    text = "\n".join(lines)
    report_md = re.findall(r"^report: (.+)$", text, re.M)
    recording = re.findall(r"^recording: (.+)$", text, re.M)
    if not report_md:
        raise RuntimeError(f"sonoflow run {launch_file}: no report line in its output:\n{text[-2000:]}")
    folder = os.path.dirname(report_md[-1])
    with open(os.path.join(folder, "report.json"), encoding="utf-8") as f:
        report = json.load(f)
    evaluations = {}
    for name in sorted(os.listdir(folder)):
        m = re.fullmatch(r"evaluation(?:-(.+))?\.json", name)
        if m:
            with open(os.path.join(folder, name), encoding="utf-8") as f:
                evaluations[m.group(1) or ""] = json.load(f)
    return {"report": report, "evaluations": evaluations, "out": folder, "report_md": report_md[-1],
            "recording": recording[-1] if recording else None}
