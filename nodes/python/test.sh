#!/usr/bin/env bash
# Builds the `sonoflow` Python package into a virtual environment and runs its pytest suite
# (nodes/python/tests) against PyMUST 0.1.9 from PyPI. Part of the README's test command.
#
#   bash nodes/python/test.sh [pytest args]
#
# The venv is target/python-venv (SONOFLOW_PY_VENV overrides it; created if missing, which needs
# PyPI once). `maturin develop` builds with the dev profile into the workspace's target/, so after
# `cargo test --workspace` only the bindings crate and PyO3 are compiled. The graph tests use
# SONOFLOW_BIN, default target/debug/sonoflow (built by `cargo test`), else target/release's.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/../.." && pwd)
VENV=${SONOFLOW_PY_VENV:-$ROOT/target/python-venv}
if [ ! -x "$VENV/bin/python" ]; then
  python3 -m venv "$VENV" 2>/dev/null || { rm -rf "$VENV"; apt-get update -qq && apt-get install -y -qq python3-venv && python3 -m venv "$VENV"; }
fi
if ! "$VENV/bin/python" -c "import pymust, pytest, numpy, mcap, mcap_ros2" >/dev/null 2>&1 || [ ! -x "$VENV/bin/maturin" ]; then
  "$VENV/bin/pip" install --quiet --disable-pip-version-check "maturin>=1.7,<2" pytest numpy pymust==0.1.9 \
    mcap mcap-ros2-support
fi
# The graph tests (tests/test_graph.py) run the sonoflow executable: the workspace's own build.
if [ -z "${SONOFLOW_BIN:-}" ]; then
  for b in "$ROOT/target/debug/sonoflow" "$ROOT/target/release/sonoflow"; do
    if [ -x "$b" ]; then export SONOFLOW_BIN="$b"; break; fi
  done
fi
cd "$ROOT/nodes/python"
VIRTUAL_ENV="$VENV" PATH="$VENV/bin:$PATH" maturin develop --quiet --locked
cd "$ROOT"
"$VENV/bin/python" -m pytest -q nodes/python/tests "$@"
# The README's Python example, as written (the block after the `ci: python-example` marker).
awk '/ci: python-example/{f=1; next} f && /^```python/{g=1; next} g && /^```/{exit} g' "$ROOT/README.md" > "$ROOT/target/readme_example.py"
[ -s "$ROOT/target/readme_example.py" ] || { echo "README: python example not found"; exit 1; }
out=$("$VENV/bin/python" "$ROOT/target/readme_example.py")
echo "README example: $out"
"$VENV/bin/python" - "$out" <<'PY'
import re, sys
v = float(re.search(r"(-?\d+\.\d+) m/s", sys.argv[1]).group(1))
# 5 cm/s axial motion; the estimate reads ~5 % low (the pulse-echo spectrum's mean frequency sits
# below fc, which the estimator assumes): within 10 %.
assert abs(v - 0.05) <= 0.005, f"README example: {v} m/s, expected 0.05 ± 0.005"
PY
