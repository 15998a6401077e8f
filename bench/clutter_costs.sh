#!/usr/bin/env bash
# BENCHMARKS.md §10: SIMUS and Doppler CPU per packet on the quickstart (2 packets × 32 frames),
# blood only, with tissue (`flow.tissue={}`: 40 dB, 10/mm² in 20 × 20 mm), and with tissue and a
# clutter filter (adaptive SVD; Butterworth order 4 at 0.05 PRF), with static tissue at 5× the
# blood's density (50/mm² in 16 × 16 mm: the particles topic holds 20 000), and with pulsating tissue (moving: simulated every frame). Three runs each.
# Usage: bash bench/clutter_costs.sh   (needs python3 with the `mcap` package)
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p sonoflow
out="${TMPDIR:-/tmp}/sonoflow-clutter-bench"
for cfg in none tissue tissue+svd tissue+iir tissue5x tissue+pulsation; do
  for _ in 1 2 3; do
    args=()
    case $cfg in
      tissue) args=(--set 'flow.tissue={}') ;;
      tissue+svd) args=(--set 'flow.tissue={}' --set 'doppler.clutter={type="svd"}') ;;
      tissue+iir) args=(--set 'flow.tissue={}' --set 'doppler.clutter={type="iir",order=4,cutoff=0.05}') ;;
      tissue5x) args=(--set 'flow.tissue={density_per_mm2=50, region=[-0.008, 0.008, 0.012, 0.028]}') ;;
      tissue+pulsation) args=(--set 'flow.tissue={pulsation={}}') ;;
    esac
    rm -rf "$out"
    target/release/sonoflow run launch/quickstart.toml "${args[@]}" --out "$out" >/dev/null 2>&1
    python3 - "$cfg" "$out" <<'PY'
import json, sys
from mcap.reader import make_reader
cfg, out = sys.argv[1], sys.argv[2]
nodes = {n["name"]: n["stats"] for n in json.load(open(out + "/report.json"))["nodes"]}
with open(out + "/recording.mcap", "rb") as f:
    first = next(make_reader(f).iter_messages(topics=["particles"]))[2].data
print(f"{cfg}: scatterers {(len(first) - 120) // 32}, SIMUS CPU {nodes['simus']['compute_ns_total'] / 2e9:.2f} s/packet, "
      f"Doppler CPU {nodes['doppler']['compute_ns_total'] / 2e9 * 1e3:.0f} ms/packet")
PY
  done
done
