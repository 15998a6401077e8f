#!/usr/bin/env bash
# Side-by-side benchmark of SIMUS: PyMUST 0.1.9 vs sonoflow-simus on the paper scene
# (128-element 5 MHz probe, 0° plane wave, N scatterers uniform in a 40 x 40 mm box from 10 mm
# depth, Gaussian amplitudes, fixed seed), in the same run on the same machine.
#
#   bench/simus/side_by_side.sh [N_SCATTERERS] [RUST_FRAMES]        (defaults 26000, 5)
#
# Creates /tmp/pymust-venv with pymust==0.1.9 if it does not exist (needs network once).
# The Rust example generates the scene and writes it with its RF to a temporary directory;
# PyMUST then simulates the same scatterers (one frame, single-threaded BLAS unless
# PYMUST_THREADS is set) and the script prints both times, the ratio and the nRMS between the
# two RFs (‖rust − pymust‖ / ‖pymust‖). Do not run it while another heavy job is running.
set -euo pipefail
N=${1:-26000}
FRAMES=${2:-5}
# ROOT, VENV (pymust 0.1.9), pymust_blas_threads
source "$(dirname "$0")/../pymust_env.sh"
OUT=$(mktemp -d /tmp/simus-sbs.XXXXXX)
echo "== load: $(uptime)"
echo "== Rust (cargo run --release -p sonoflow-simus --example simus_bench)"
(cd "$ROOT" && cargo run --quiet --release -p sonoflow-simus --example simus_bench -- \
    --scatterers "$N" --frames "$FRAMES" --write "$OUT")
echo "== PyMUST 0.1.9 (same scatterers)"
pymust_blas_threads
"$VENV/bin/python" - "$OUT" <<'EOF'
import json, sys, time
import numpy as np
import pymust

out = sys.argv[1]
x, z, rc = (np.load(f"{out}/{k}.npy") for k in ("x", "z", "rc"))
p = pymust.utils.Param()
p.fc, p.pitch, p.kerf, p.Nelements, p.bandwidth, p.TXnow, p.c = 5e6, 0.30e-3, 35e-6, 128, 75, 6, 1540
p.width = p.pitch - p.kerf
dels = np.abs(pymust.txdelay(p, 0.0))  # zeros; also sets the defaults (radius) simus needs
t = time.perf_counter()
rf_py, spect = pymust.simus(x.reshape(1, -1), z.reshape(1, -1), rc.reshape(1, -1), dels, p)
t_py = time.perf_counter() - t
rust = json.load(open(f"{out}/rust.json"))
rf_rs = np.load(f"{out}/rf.npy")
print(f"PyMUST: {t_py:.2f} s/frame, RF {rf_py.shape}, Nf {spect.shape[0]}")
if rf_py.shape != rf_rs.shape:
    print(f"shape mismatch: rust {rf_rs.shape} vs pymust {rf_py.shape}")
    sys.exit(1)
a, b = rf_rs.astype(np.float64), rf_py.astype(np.float64)
nrms = np.linalg.norm(a - b) / np.linalg.norm(b)
t_rs = rust["seconds_per_frame"]
print(f"Rust:   {t_rs:.3f} s/frame ({rust['threads']} threads, {rust['kernel']}), "
      f"{rust['gflop_per_frame'] / t_rs:.1f} GFLOP/s (model count)")
print(f"speed-up: {t_py / t_rs:.1f}x   nRMS(rust, pymust) = {nrms:.3e}")
EOF
rm -rf "$OUT"
