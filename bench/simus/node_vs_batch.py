#!/usr/bin/env python3
"""BENCHMARKS.md, "SIMUS per frame: node vs batch": the `simus` node and the batch tool
`sonoflow simus` on the same scatterers, one thread each, interleaved on the same machine.

    bash nodes/python/test.sh          # once: builds the `sonoflow` package into target/python-venv
    cargo build --release -p sonoflow
    target/python-venv/bin/python bench/simus/node_vs_batch.py [--reps 3] [--frames 32] [--t-start 0.0101]

1. `launch/carotid.toml` at full resolution (0.15 mm SPH, ~26 300 blood scatterers), one packet of
   FRAMES frames from t = T_START, `simus.cpus=1`, recording the particle snapshots: the node's CPU
   per frame inside the whole graph (SPH, beamformers, … beside it).
2. REPS rounds, each running in turn (every run one thread, the same carotid scatterers, except
   the last):
   * the node alone (`replay` of those snapshots → `simus`, `cpus = 1`) with the fixed 2 mm plan
     margin (`plan_margin = 2e-3`, the launch files' value before 2026-12-05) and with the automatic
     margin (the default now);
   * the batch tool (`RAYON_NUM_THREADS=1`) on snapshots 0..BATCH_FRAMES−1 with MUST's per-call
     plan, and with each of the node's two plans (`options.plan = {mode = "max_distance", …}`):
     exactly the node's work;
   * the batch tool on §3's scene (26 000 scatterers uniform in a 40 × 40 mm box from 10 mm depth).
   Node: process CPU per frame (`compute_ns` of the stage statistics on `_stats`). Batch: wall time
   of `simulate` (the sidecar's `seconds`) and process CPU of the whole command (start-up, reading
   and writing the files included).
3. Prints a Markdown table: min and median per frame over every frame of every round.
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import sonoflow

ROOT = Path(__file__).resolve().parents[2]
ap = argparse.ArgumentParser()
ap.add_argument("--bin", default=os.environ.get("SONOFLOW_BIN", str(ROOT / "target/release/sonoflow")))
ap.add_argument("--reps", type=int, default=3)
ap.add_argument("--frames", type=int, default=32, help="frames of the packet (carotid.toml: 32)")
ap.add_argument("--batch-frames", type=int, default=3, help="snapshots the batch tool simulates per round")
ap.add_argument("--t-start", type=float, default=0.0101)
ap.add_argument("--recording", help="reuse this carotid recording (with `particles`) instead of step 1")
ap.add_argument("--out", default=tempfile.mkdtemp(prefix="simus-node-vs-batch-"))
a = ap.parse_args()
out = Path(a.out)
out.mkdir(parents=True, exist_ok=True)
PRF, PITCH, N_EL, C, FC = 10e3, 0.30e-3, 128, 1540.0, 5e6  # carotid.toml's simus: paper-5mhz
X_END = (N_EL - 1) / 2 * PITCH


def run(cmd, env=None):
    r = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if r.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed:\n{r.stdout}\n{r.stderr}")
    return r.stdout


def node_frames(recording):
    """Per-frame compute time (s) of the `simus` stage from the recorded stage statistics."""
    rec = sonoflow.Recording(recording)
    return [m.header["last_compute_ns"] / 1e9 for m in rec.messages("_stats")
            if bytes(m.data).decode() == "simus" and m.header["state"] == 0]


print(f"== load: {os.getloadavg()}; {a.bin}; out {out}", flush=True)
rec = a.recording
if rec is None:
    g = out / "carotid"
    run([a.bin, "run", ROOT / "launch/carotid.toml", "-q", "--out", g,
         "--set", "flow.schedule.n_packets=1", "--set", f"flow.schedule.packet_size={a.frames}",
         "--set", f"flow.schedule.t_start={a.t_start}", "--set", "simus.cpus=1",
         "--set", 'recorder.topics=["particles"]'])
    rec = str(g / "recording.mcap")
    in_graph = node_frames(rec)
else:
    in_graph = []

# the snapshots for the batch tool, and the node's plan distances (its rule, scan.rs)
snaps = [m for _, m in zip(range(a.frames), sonoflow.Recording(rec).messages("particles"))]
if len(snaps) < max(a.frames, a.batch_frames):
    sys.exit(f"{rec}: {len(snaps)} particle snapshots, need {max(a.frames, a.batch_frames)}")
frames = snaps[: a.frames]
# §3's scene for comparison: 26 000 scatterers uniform in a 40 × 40 mm box from 10 mm depth
rng = np.random.default_rng(2018)
box = np.stack([rng.uniform(-20e-3, 20e-3, 26000), rng.uniform(10e-3, 50e-3, 26000), rng.standard_normal(26000)], 1)
np.save(out / "box.npy", box)
for k, m in enumerate(snaps[: a.batch_frames]):
    d = m.data
    np.save(out / f"frame-{k}.npy", np.stack([d["x"], d["z"], d["amplitude"]], 1).astype(np.float64))
d0 = frames[0].data
x, z = d0["x"].astype(np.float64), d0["z"].astype(np.float64)
dist = np.sqrt(np.maximum(np.abs(x + X_END), np.abs(x - X_END)) ** 2 + z ** 2)
speed = np.hypot(d0["vx"], d0["vz"]).astype(np.float64)
T = (a.frames - 1) / PRF
auto = float(np.max(dist + speed * T) - dist.max() + C / FC)
margins = {"fixed 2 mm": 2e-3, "automatic": auto}
print(f"{len(d0)} scatterers, x {x.min()*1e3:.1f} … {x.max()*1e3:.1f} mm, "
      f"{int((np.abs(x) > X_END).sum())} beyond the array's ends; largest element distance "
      f"{dist.max()*1e3:.3f} mm; automatic margin {auto*1e3:.3f} mm", flush=True)
for name, m in margins.items():
    (out / f"opt-{m:.6e}.toml").write_text(f'[plan]\nmode = "max_distance"\nmax_distance = {float(dist.max() + m)!r}\n')

(out / "replay-simus.toml").write_text(f"""[graph]
name = "simus-replay"
description = "recorded particle snapshots → the simus node with carotid.toml's parameters"

[topics]
particles = {{ type = "ParticleSnapshotV1", max_elements = 30000, depth = 4 }}
rf = {{ type = "RfFrameV3", max_elements = 524288, depth = 4 }}

[nodes.replay]
kind = "replay"
outputs = {{ particles = "particles" }}
params = {{ path = "{rec}", rate = 0.0 }}

[nodes.simus]
kind = "simus"
inputs = {{ particles = "particles" }}
outputs = {{ rf = "rf" }}
cpus = 1
params = {{ probe = "paper-5mhz", tilts_deg = [0.0], prf = {PRF}, plan = "per-packet", field_figure = false }}

[nodes.recorder]
kind = "recorder"
params = {{ path = "recording.mcap", compression = "none", topics = [] }}
""")

times = {}
plans = {}
samples = {}  # the node's RF length per margin (from its bytes out), to check the batch runs' plans
env1 = dict(os.environ, RAYON_NUM_THREADS="1")


def batch(label, opts, scene=None):
    for k in range(a.batch_frames):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        scat = out / (scene or f"frame-{k}.npy")
        cmd = [a.bin, "simus", "--scatterers", scat, "--param", "paper-5mhz", "--out", out / "b.npy"]
        run(cmd + (["--options", opts] if opts else []), env=env1)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        side = json.loads((out / "b.json").read_text())
        cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
        times.setdefault(label + " (wall of simulate)", []).append(side["seconds"])
        times.setdefault(label + " (process CPU)", []).append(cpu)
        plans[label] = (side["scatterers"], side["plan"]["band_last"] + 1 - side["plan"]["band_first"], side["n_samples"])


for rep in range(a.reps):
    for name, m in margins.items():
        r = out / "replay"
        run(["rm", "-rf", r])
        sets = ["--set", f"simus.plan_margin={m!r}"] if name.startswith("fixed") else []
        run([a.bin, "run", out / "replay-simus.toml", "-q", "--out", r] + sets)
        v = node_frames(str(r / "recording.mcap"))
        times.setdefault(f"node, {name} margin", []).extend(v)
        st = next(n["stats"] for n in json.loads((r / "report.json").read_text())["nodes"] if n["name"] == "simus")
        samples[name] = st["bytes_out"] // (4 * N_EL * len(v))
    batch("batch, MUST's per-call plan", None)
    for name, m in margins.items():
        batch(f"batch, the node's plan ({name} margin)", out / f"opt-{m:.6e}.toml")
    batch("batch, §3's box scene (26 000 uniform scatterers, other positions), MUST's plan", None, "box.npy")
    print(f"round {rep + 1}/{a.reps} done, load {os.getloadavg()[0]:.2f}", flush=True)

for name in margins:
    n = plans[f"batch, the node's plan ({name} margin)"][2]
    if samples[name] != n:
        sys.exit(f"the node's RF ({name} margin) has {samples[name]} samples, the batch run with its plan {n}")
print()
print("| run (one thread) | scatterers | bins | samples | s / frame min | median | frames |")
print("|---|---:|---:|---:|---:|---:|---:|")
if in_graph:
    p = plans["batch, the node's plan (automatic margin)"]
    print(f"| node in launch/carotid.toml (automatic margin) | {p[0]} | {p[1]} | {p[2]} | "
          f"{min(in_graph):.3f} | {statistics.median(in_graph):.3f} | {len(in_graph)} |")
for label, v in times.items():
    key = next(k for k in plans if label.startswith(k)) if label.startswith("batch") else \
        "batch, the node's plan (" + label.split(", ")[1] + ")"
    p = plans[key]
    print(f"| {label} | {p[0]} | {p[1]} | {p[2]} | {min(v):.3f} | {statistics.median(v):.3f} | {len(v)} |")
