#!/usr/bin/env bash
# Side-by-side benchmark of the beamforming chain: PyMUST 0.1.9 vs sonoflow-beamform on the
# paper configuration (128 elements, 5 MHz, fs 20 MHz, 1600 samples; DAS on a 200 x 200 grid
# x in [-19, 19] mm, z in [5, 45] mm, F-number 3, 0° plane wave, linear interpolation; Doppler
# lag 1, no window, on a 200 x 200 x 32 packet), in the same run on the same machine.
#
#   bench/beamform/side_by_side.sh [REPS]        (default 20)
#
# Creates /tmp/pymust-venv with pymust==0.1.9 if it does not exist (needs network once).
# The Rust example writes its RF, image, packet and velocities to a temporary directory; PyMUST
# then processes the same data (single-threaded BLAS unless PYMUST_THREADS is set) and the script
# prints both timings, the ratios, and the differences between the outputs. Do not run it while
# another heavy job is running.
set -euo pipefail
REPS=${1:-20}
# ROOT, VENV (pymust 0.1.9), pymust_blas_threads
source "$(dirname "$0")/../pymust_env.sh"
OUT=$(mktemp -d /tmp/beamform-sbs.XXXXXX)
echo "== load: $(uptime)"
echo "== Rust (cargo run --release -p sonoflow-doppler --example beamform_bench)"
(cd "$ROOT" && cargo run --quiet --release -p sonoflow-doppler --example beamform_bench -- --reps "$REPS" --write "$OUT")
echo "== PyMUST 0.1.9 (same data)"
pymust_blas_threads
"$VENV/bin/python" - "$OUT" "$REPS" <<'PY'
import json, sys, time
import numpy as np
import pymust

out, reps = sys.argv[1], int(sys.argv[2])
rf = np.load(f"{out}/rf.npy")
nl, nc = rf.shape
p = pymust.utils.Param()
p.fc, p.pitch, p.kerf, p.Nelements, p.bandwidth, p.c, p.fs = 5e6, 0.30e-3, 35e-6, 128, 75, 1540, 20e6
p.width = p.pitch - p.kerf
p.fnumber = 3
p.t0 = np.zeros(1)
def best(f, n):
    ts = []
    for _ in range(n):
        t = time.perf_counter(); r = f(); ts.append(time.perf_counter() - t)
    return float(np.median(ts)), r
t_iq, iq = best(lambda: pymust.rf2iq(rf, p), max(3, reps // 4))
x = np.linspace(-19e-3, 19e-3, 200); z = np.linspace(5e-3, 45e-3, 200)
X, Z = np.meshgrid(x, z)
d = np.abs(pymust.txdelay(p, 0.0)); p.TXdelay = d
t_setup, M = best(lambda: pymust.dasmtx(1j * np.array([nl, nc]), X, Z, d, p, "linear"), 3)
M = M.tocsr()  # the apply below uses CSR (faster than COO); conversion not timed
iqf = iq.flatten(order="F")
t_apply, img = best(lambda: (M @ iqf).reshape(X.shape, order="F"), reps)
packet = np.load(f"{out}/packet.npy").astype(np.complex128)
q = pymust.utils.Param(); q.fc, q.c, q.PRF = 5e6, 1540, 10e3
t_dop, (v, var) = best(lambda: pymust.iq2doppler(packet, q), reps)
rust = json.load(open(f"{out}/rust.json"))
img_rs = np.load(f"{out}/das.npy")
v_rs = np.load(f"{out}/velocity.npy")
nrms = np.linalg.norm(img_rs - img) / np.linalg.norm(img)
VN = 1540 * 10e3 / 4 / 5e6
print(f"PyMUST rf2iq          {t_iq*1e3:8.3f} ms/frame")
print(f"PyMUST dasmtx         {t_setup*1e3:8.3f} ms (nnz {M.nnz}; Rust taps x2 = {2*rust['taps']})")
print(f"PyMUST apply (CSR)    {t_apply*1e3:8.3f} ms/frame")
print(f"PyMUST iq2doppler     {t_dop*1e3:8.3f} ms/packet")
print(f"output check: DAS nRMS(rust, pymust) = {nrms:.2e}; Doppler max |dv|/VN = {np.max(np.abs(v_rs - v))/VN:.2e}")
r = rust
print("speed-up (PyMUST / Rust, Rust with %d threads):" % r["threads"])
print(f"  rf2iq                 {t_iq / r['rf2iq_s']:7.1f}x")
print(f"  DAS set-up + 1 frame  {(t_setup + t_apply) / (r['das_setup_s'] + r['das_apply_s']):7.1f}x")
print(f"  DAS set-up            {t_setup / r['das_setup_s']:7.1f}x")
print(f"  DAS apply per frame   {t_apply / r['das_apply_s']:7.1f}x")
print(f"  Doppler per packet    {t_dop / r['doppler_s']:7.1f}x")
PY
rm -rf "$OUT"
