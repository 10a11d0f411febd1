"""Tables 1-4 of Lewis & Swords, by scheduling replay of recorded traces.

    python benchmarks/paper_tables.py [--steps 3] [--scenes ring,dish] [--states early,late]
                                      [--n ring=5000] [--full] [--p 16] [--policy exact]
                                      [--out out/paper_tables]

For each scene (ring, ring_moonlet, dish, dish_marble) and state (early, late):

1. **Trace.**  A sequential run records its events (``Engine(trace_locks=...)``)
   with the lock regions of the lock graph at SCALE 1.2, 2, 4, 6, 8 and of the
   2-D grid (the paper's grid: x-y cells).  Every engine below starts from the
   same state and first takes one untimed step (numba's kernels loaded, pools
   and journals grown to size); the next ``--steps`` steps are traced or
   timed.  Under the exact policy all of them process the same events.
2. **Measured.**  An untraced sequential run of those steps gives ``T_seq``;
   a real 2-thread run per lock configuration (``threads=2``, exact policy)
   gives ``T_par``.  Both are wall times of ``Engine.step`` (perf_counter).
3. **Events phase.**  The replay models only the events, so only the events
   phase of the 2-thread run is compared: the worker threads' wall time per
   step, from dispatch to join (``S_ECYC`` of the step statistics), summed
   over the steps (``par2_events_s``).  It leaves out the tree, the pair
   search, the kicks, the first predictions and building the lock structure
   and the thread domains; it includes what the traced event costs do not:
   the queue updates after each event (the fit below absorbs them) and
   starting and joining the threads (``step_overhead`` below).  A step with a repair (a violation, redone
   sequentially) loses its worker time; the run then falls back to
   ``T_par - T_other`` with ``T_other = T_seq - W`` (W the trace's summed event
   costs, T_seq an untraced sequential run of the same steps) and says so in
   ``measure``.  That estimate is always reported too (``par2_sub_s``): it
   counts the lock-structure build, which the sequential run does not do, as
   events time.
4. **Calibrate and replay.**  The cost of starting and joining the two worker
   threads is measured once on a 2-thread step with no events and passed to
   every replay as ``step_overhead``.  ``lockgraph.replay.calibrate`` then
   fits the rest of the measured excess twice — as per-claim queue overhead,
   serialized (``overhead_s``, the model's main knob), and as per-event work
   that runs in parallel (``per_event_s``): one measurement cannot tell them
   apart, and the two bracket the truth — so that the 2-thread replay (exact
   policy) lasts the measured events phase.  With each fit, and with no
   overhead at all ("events only": what the lock structure alone allows), the
   trace is replayed at P = 1, 2, 4, 8, 16, 32, 64 under both policies.

Printed (stdout), for P = 16 (``--p``) and the exact policy (``--policy``):
tables shaped like the paper's — rows SCALE and grid, columns early and late
— with those replays, the measured 2-thread events phase and the paper's
published times (16 cores, 10 steps, ~200,000 particles, whole runs).
Absolute values are not comparable (sizes, steps, machines, what is timed);
the "/grid" columns (each time over the grid's in the same column) compare the
shape.  Progress goes to stderr.  Results: ``DIR/paper_tables.csv`` (one row
per scene, state, lock configuration, policy and P) and
``DIR/paper_tables.json`` (everything, also the lock structures' statistics).

Default sizes are small (ring and ring_moonlet 20,000, dish 2,000, dish_marble
2,001 particles; all scenes take under a minute once the late states are
cached in $LOCKGRAPH_CACHE, generating them takes a few minutes more).
``--full`` uses the paper's ~200,000 particles: expect generating those late
states to take hours (not measured here).  The 2-thread timings share this machine's two cores with
whatever else runs: treat them, and the fitted overheads, as noisy (10-30 %).
"""
import argparse
import csv
import json
import math
import os
import sys
import time


HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from lockgraph import scenarios  # noqa: E402
from lockgraph.paper_tables import (FULL_N, LOCKS, PAPER, SCENES, SMALL_N, STATES,  # noqa: E402
                                    THREADS, TITLES, finite, key_name, run_case,
                                    thread_start_seconds)
from lockgraph.parallel import cycles_per_second  # noqa: E402
from lockgraph.replay import POLICIES  # noqa: E402


def say(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def fmt(x, width=7):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return f"{'-':>{width}s}"
    if isinstance(x, float) and math.isinf(x):
        return f"{'>>1e5':>{width}s}"
    if abs(x) >= 100:
        return f"{x:{width}.0f}"
    if abs(x) >= 10:
        return f"{x:{width}.1f}"
    return f"{x:{width}.2f}"


def ratio(x, g):
    if x is None or g is None or not g or math.isinf(g) or math.isinf(x):
        return None
    return x / g


# printed table columns: (title, value key, with "/grid" columns)
COLUMNS = [("replay, serialized fit", "time_s", True),
           ("per-event fit", "time_per_event_fit_s", False),
           ("events only", "time_events_only_s", False),
           ("2 threads", "measured", False),
           ("paper (s)", "paper", True)]


def print_table(scene, res, p, policy, step_ovh):
    """One paper-shaped table: rows SCALE + grid, columns early / late per block."""
    states = [s for s in STATES if s in res]
    print(f"\n{TITLES[scene]}  ({res[states[0]]['steps']} steps; replay P={p}, {policy} policy; "
          f"ms unless marked)")
    for s in states:
        r = res[s]
        print(f"  {s}: N={r['n']}, {r['events']} events ({r['kinds']['pair']} pair, "
              f"{r['kinds']['wall']} wall, {r['kinds']['stale']} stale), event costs "
              f"{r['work_s'] * 1e3:.2f} ms, sequential steps {r['t_seq_s'] * 1e3:.1f} ms")
    rows = [key_name(k) for k in LOCKS]

    def val(state, r, what):
        if what == "paper":
            return float(PAPER[scene][state][rows.index(r)])
        if state not in res:
            return None
        rec = res[state]["locks"][r]
        if what == "measured":
            return rec["par2_events_s"] * 1e3
        return rec["replay"][f"{policy}/{p}"][what] * 1e3

    widths = [(7 + 6) * 2 if g else 7 * 2 + 1 for _, _, g in COLUMNS]
    print(f"{'':6s}" + "".join(f"|{t:^{w}s}" for (t, _, _), w in zip(COLUMNS, widths)))
    sub = f"{'SCALE':6s}"
    for (_, _, g), w in zip(COLUMNS, widths):
        cells = "".join(f"{s:>7s}" + (f"{'/grid':>6s}" if g else "") for s in ("early", "late"))
        sub += "|" + cells.rjust(w)
    print(sub)
    for r in rows:
        line = f"{(r.replace('graph ', '') if r != 'grid' else 'grid'):6s}"
        for (_, what, g), w in zip(COLUMNS, widths):
            cells = ""
            for state in STATES:
                v = val(state, r, what)
                cells += fmt(v)
                if g:
                    cells += fmt(ratio(v, val(state, "grid", what)), 6)
            line += "|" + cells.rjust(w)
        print(line)


def write_csv(path, results, step_ovh):
    cols = ["scene", "state", "n", "steps", "events", "work_s", "t_seq_s", "t_other_s", "lock",
            "scale", "t_par2_s", "par2_events_s", "measure", "par2_direct_s", "par2_sub_s",
            "repairs", "violations", "step_overhead_s", "overhead_s", "fit", "per_event_s",
            "fit_per_event", "policy", "threads", "replay_s", "concurrency", "blocked",
            "stalls", "replay_per_event_fit_s", "replay_events_only_s", "paper_s"]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for scene, by_state in results.items():
            for state, res in by_state.items():
                for k, key in enumerate(LOCKS):
                    rec = res["locks"][key_name(key)]
                    for name, r in rec["replay"].items():
                        policy, p = name.split("/")
                        w.writerow([scene, state, res["n"], res["steps"], res["events"],
                                    res["work_s"], res["t_seq_s"], res["t_other_s"], key[0],
                                    key[1] if key[1] is not None else "", rec["t_par2_s"],
                                    rec["par2_events_s"], rec["measure"], rec["par2_direct_s"],
                                    rec["par2_sub_s"], rec["repairs"], rec["violations"],
                                    step_ovh, rec["overhead_s"], rec["fit"], rec["per_event_s"],
                                    rec["fit_per_event"], policy, p, r["time_s"],
                                    r["concurrency"], r["blocked"], r["stalls"],
                                    r["time_per_event_fit_s"], r["time_events_only_s"],
                                    PAPER[scene][state][k]])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=3, help="timed and traced steps (default 3)")
    ap.add_argument("--scenes", default=",".join(SCENES),
                    help=f"comma-separated subset of {','.join(SCENES)}")
    ap.add_argument("--states", default="early,late", help="early, late or both")
    ap.add_argument("--full", action="store_true", help="paper scale, ~200,000 particles")
    ap.add_argument("--n", action="append", default=[], metavar="SCENE=N",
                    help="particle count of one scene (repeatable)")
    ap.add_argument("--p", type=int, default=16, help="threads shown in the tables (16)")
    ap.add_argument("--policy", choices=POLICIES, default="exact",
                    help="replay policy shown in the tables (both are in the files)")
    ap.add_argument("--warm", type=int, default=1, help="untimed steps first (default 1)")
    ap.add_argument("--out", default="out/paper_tables", help="output directory")
    args = ap.parse_args()
    scenes = [s for s in args.scenes.split(",") if s]
    states = [s for s in args.states.split(",") if s]
    for s in scenes:
        if s not in SCENES:
            ap.error(f"unknown scene {s!r}; one of {', '.join(SCENES)}")
    for s in states:
        if s not in STATES:
            ap.error(f"unknown state {s!r}; early or late")
    if args.steps < 1 or args.warm < 0 or args.p < 1:
        ap.error("--steps and --p must be >= 1, --warm >= 0")
    sizes = dict(FULL_N if args.full else SMALL_N)
    for item in args.n:
        name, _, val = item.partition("=")
        if name not in SCENES or not val.isdigit():
            ap.error(f"--n takes SCENE=N, got {item!r}")
        sizes[name] = int(val)
    os.makedirs(args.out, exist_ok=True)
    t_start = time.perf_counter()
    say("measuring thread start/join of an empty 2-thread step")
    step_ovh = thread_start_seconds()
    say(f"  {step_ovh * 1e6:.0f} us per step")
    results = {}
    for scene in scenes:
        results[scene] = {}
        for state in states:
            say(f"{scene} {state}: loading N={sizes[scene]}")
            sc = scenarios.load(scene, state, n=sizes[scene], progress=say)
            say(f"{scene} {state}: {args.steps} steps of dt={sc.dt:g} s")
            results[scene][state] = run_case(sc, args.steps, args.p, args.warm, step_ovh, say)
            # partial results survive an interrupted run
            with open(os.path.join(args.out, "paper_tables.json"), "w") as fh:
                json.dump(finite({"results": results}), fh, indent=1)
    for scene in scenes:
        print_table(scene, results[scene], args.p, args.policy, step_ovh)
    print(f"\nTimes are events phases over the steps, in ms; the paper's are whole runs of 10 "
          f"steps on 16 cores, in s (Table 4 late grid: '>> 150000 s').  /grid: over the "
          f"grid's time in the same column.\n2 threads: measured, the worker threads' wall "
          f"time.  Replays include {step_ovh * 1e3:.3f} ms per step of thread start/join; "
          f"serialized fit: the rest of the\n2-thread excess as per-claim queue overhead; "
          f"per-event fit: as parallel per-event work; events only: no overheads at all.")
    meta = {"cycles_per_second": cycles_per_second(), "sizes": {s: sizes[s] for s in scenes},
            "steps": args.steps, "warm": args.warm, "threads": list(THREADS),
            "step_overhead_s": step_ovh, "paper": PAPER,
            "wall_s": time.perf_counter() - t_start}
    with open(os.path.join(args.out, "paper_tables.json"), "w") as fh:
        json.dump(finite({"meta": meta, "results": results}), fh, indent=1)
    write_csv(os.path.join(args.out, "paper_tables.csv"), results, step_ovh)
    say(f"done in {meta['wall_s']:.0f} s; wrote {args.out}/paper_tables.csv and .json")


if __name__ == "__main__":
    main()
