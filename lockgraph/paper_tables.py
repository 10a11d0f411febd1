"""Measuring the paper's Tables 1-4 here: traces, 2-thread runs and replays.

``run_case`` takes one scene in one state through the four stages described in
``benchmarks/paper_tables.py`` (trace, measured sequential and 2-thread runs,
calibration, replay at P threads) and returns a JSON-able dict; the benchmark
script and ``lockgraph report`` both print and chart from it.
"""
import math
import time

import numpy as np

from . import kernels as K
from .domains import PeriodicCube
from .engine import Engine
from .parallel import cycles_per_second
from .physics import Physics
from .replay import POLICIES, ReplayTrace
from .restitution import Constant
from .state import State

SCENES = ("ring", "ring_moonlet", "dish", "dish_marble")
STATES = ("early", "late")
SCALES = (1.2, 2.0, 4.0, 6.0, 8.0)
LOCKS = [("graph", s) for s in SCALES] + [("grid", None)]
THREADS = (2, 4, 8, 16, 32, 64)
SMALL_N = {"ring": 20000, "ring_moonlet": 20000, "dish": 2000, "dish_marble": 2001}
FULL_N = {"ring": 200000, "ring_moonlet": 200000, "dish": 200000, "dish_marble": 200001}
TITLES = {"ring": "Table 1: ring", "ring_moonlet": "Table 2: ring with moonlet",
          "dish": "Table 3: silicon grains (dish)", "dish_marble": "Table 4: dish with marble"}
# Lewis & Swords, Tables 1-4: seconds for 10 steps on 16 cores, ~200,000 particles
# (mean of 5 runs).  Rows SCALE 1.2, 2, 4, 6, 8, then the grid.
PAPER = {
    "ring": {"early": [44.4, 44.6, 42.0, 39.9, 39.2, 37.1],
             "late": [58.3, 57.0, 47.7, 43.7, 43.8, 42.0]},
    "ring_moonlet": {"early": [95.2, 136.4, 177.8, 112.2, 212.7, 93.0],
                     "late": [75.3, 75.5, 67.5, 66.2, 66.5, 57.9]},
    "dish": {"early": [21.0, 20.6, 20.7, 20.5, 19.3, 19.5],
             "late": [860, 859, 913, 936, 968, 1004]},
    "dish_marble": {"early": [647, 668, 686, 667, 2529, 2654],
                    "late": [667, 663, 705, 646, 2780, math.inf]},  # grid late: >> 150000 s
}


def key_name(key):
    kind, scale = key
    return f"graph {scale:g}" if kind == "graph" else kind


def timed_steps(eng, steps):
    """Wall time (s) of each of ``steps`` calls of eng.step(), and each step's
    S_ECYC (events-phase wall clock of threaded runs, s; 0 for sequential)."""
    times, events = [], []
    for _ in range(steps):
        t0 = time.perf_counter()
        st = eng.step()
        times.append(time.perf_counter() - t0)
        events.append(float(st[K.S_ECYC]) / cycles_per_second())
    return times, events


def thread_start_seconds(steps=40):
    """Median events-phase wall time of a 2-thread step with no events: starting
    and joining the workers (the replay's ``step_overhead``)."""
    pos = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    st = State(pos, np.zeros((2, 3)), np.full(2, 0.1), np.ones(2))
    eng = Engine(st, Physics(PeriodicCube(4.0), (), Constant(1.0)), 0.05, threads=2,
                 lock="graph")
    try:
        eng.step()
        _, ev = timed_steps(eng, steps)
    finally:
        eng.close()
    return float(np.median(ev))


def fitted(rt, key, measured, step_ovh, fit):
    """(value, status) of one calibration; status 'ok', 'floor' (the measured time
    is no longer than the replay with nothing to fit) or 'no events'."""
    if rt.events == 0:
        return 0.0, "no events"
    if measured <= rt.replay(key, 2, "exact", step_overhead=step_ovh)["time"]:
        return 0.0, "floor"
    return rt.calibrate(key, measured, threads=2, policy="exact", fit=fit,
                        step_overhead=step_ovh), "ok"


def run_case(sc, steps, p_table, warm, step_ovh, progress=None):
    """Trace, measure, calibrate and replay one scene in one state; ``progress(msg)``
    hears each stage."""
    say = progress or (lambda msg: None)
    out = {"n": int(sc.state.n), "steps": steps, "dt": float(sc.dt), "locks": {}}
    # 1. trace: untimed warm-up steps, then the steps that count
    t0 = time.perf_counter()
    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=LOCKS)
    for _ in range(warm + steps):
        eng.step()
    tr = eng.trace()
    tr["steps"] = tr["steps"][warm:]
    del eng
    rt = ReplayTrace(tr)
    out["events"] = rt.events
    out["events_per_step"] = [len(s["cost"]) for s in rt.steps]
    out["work_s"] = rt.work
    kinds = (np.concatenate([s["events"]["kind"] for s in tr["steps"]]) if rt.events
             else np.zeros(0))
    out["kinds"] = {k: int(np.count_nonzero(kinds == v))
                    for k, v in (("pair", 0), ("wall", 1), ("stale", 2))}
    say(f"  trace: {rt.events} events in {steps} steps, summed event costs "
        f"{rt.work * 1e3:.2f} ms ({time.perf_counter() - t0:.1f} s)")
    # 2. sequential, untraced
    eng = Engine(sc.state, sc.physics, sc.dt)
    for _ in range(warm):
        eng.step()
    seq, _ = timed_steps(eng, steps)
    del eng
    t_seq = float(sum(seq))
    t_other = t_seq - rt.work
    out.update(t_seq_s=t_seq, t_seq_steps=seq, t_other_s=t_other)
    say(f"  sequential: {t_seq * 1e3:.1f} ms, of which outside the traced events "
        f"{t_other * 1e3:.1f} ms")
    plist = sorted(set(THREADS) | {1, 2, p_table})
    for key in LOCKS:
        rec = {}
        # 3. a real 2-thread run
        eng = Engine(sc.state, sc.physics, sc.dt, threads=2, lock=key[0],
                     scale=key[1] if key[1] is not None else 4.0, policy="exact")
        try:
            for _ in range(warm):
                eng.step()
            repairs0 = eng.repairs
            viol0 = eng.totals[K.S_VIOL]
            par, direct = timed_steps(eng, steps)
            rec["repairs"] = int(eng.repairs - repairs0)
            rec["violations"] = int(eng.totals[K.S_VIOL] - viol0)
            rec["lock_stats"] = {k: (v.item() if isinstance(v, np.generic) else v)
                                 for k, v in (eng.lock_stats or {}).items()
                                 if isinstance(v, (int, float, str, np.integer, np.floating))}
        finally:
            eng.close()
        t_par = float(sum(par))
        sub = t_par - t_other
        use_direct = rec["repairs"] == 0 and all(d > 0 for d in direct)
        measured = float(sum(direct)) if use_direct else sub
        rec.update(t_par2_s=t_par, t_par2_steps=par, par2_events_s=measured,
                   par2_direct_s=float(sum(direct)), par2_sub_s=sub,
                   measure="workers" if use_direct else "subtraction")
        # 4. calibrate (both bounds on where per-event overhead goes), replay
        ovh, rec["fit"] = fitted(rt, key, measured, step_ovh, "overhead")
        per, rec["fit_per_event"] = fitted(rt, key, measured, step_ovh, "per_event")
        rec["overhead_s"], rec["per_event_s"] = ovh, per
        rec["replay"] = {}
        for policy in POLICIES:
            for p in plist:
                r = rt.replay(key, p, policy, ovh, step_overhead=step_ovh)
                q = rt.replay(key, p, policy, per_event=per, step_overhead=step_ovh)
                z = rt.replay(key, p, policy)
                rec["replay"][f"{policy}/{p}"] = {
                    "time_s": r["time"], "concurrency": r["concurrency"],
                    "blocked": r["blocked"], "stalls": r["stalls"], "passed": r["passed"],
                    "time_per_event_fit_s": q["time"],
                    "time_events_only_s": z["time"], "concurrency_events_only": z["concurrency"]}
        r16 = rec["replay"][f"exact/{p_table}"]
        say(f"  {key_name(key):9s}: 2 threads {t_par * 1e3:7.1f} ms, events phase "
            f"{measured * 1e3:7.2f} ms ({rec['measure']}), repairs {rec['repairs']}; fit "
            f"{ovh * 1e9:5.0f} ns/claim serialized ({rec['fit']}) or {per * 1e9:5.0f} ns/event "
            f"parallel; replay P={p_table}: {r16['time_s'] * 1e3:.2f} / "
            f"{r16['time_per_event_fit_s'] * 1e3:.2f} ms (events only "
            f"{r16['time_events_only_s'] * 1e3:.2f} ms, concurrency "
            f"{r16['concurrency_events_only']:.1f})")
        out["locks"][key_name(key)] = rec
    return out


def finite(obj):
    """JSON-safe copy: numpy scalars and arrays become Python numbers and lists,
    non-finite floats None (the paper's '>> 150000 s')."""
    if isinstance(obj, dict):
        return {(k if isinstance(k, str) else str(k)): finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return finite(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj
