# Sourced by the side-by-side benchmarks (bench/*/side_by_side.sh): sets ROOT (the repository)
# and VENV (a Python venv with pymust==0.1.9: PYMUST_VENV, default /tmp/pymust-venv, created if
# missing, which needs network once), and defines pymust_blas_threads, which limits the BLAS of
# the PyMUST run to PYMUST_THREADS threads (default 1).
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=${PYMUST_VENV:-/tmp/pymust-venv}
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c "import pymust" 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q pymust==0.1.9
fi

pymust_blas_threads() {
    export OPENBLAS_NUM_THREADS=${PYMUST_THREADS:-1} OMP_NUM_THREADS=${PYMUST_THREADS:-1} \
        MKL_NUM_THREADS=${PYMUST_THREADS:-1}
}
