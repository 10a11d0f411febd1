"""What a domain split with a particle band could gain at best on the events.

    python benchmarks/band_bound.py [--cases dish_marble_dem] [--steps 6]
                                    [--levels 1,2,3] [--depths 0,1,2,4] [--cut cost]
                                    [--sync 0,2e-7]

Records a sequential trace (every event, its cost in cycles) and each step's
candidate lists, cuts each step's particles into two domains, and re-plays the
events on two virtual threads under the particle-band rule with no
coordination cost (``lockgraph.band_replay``): an event with a particle near
the cut (a band event) waits until the other domain has finished every event
before it in the sequential order; the others run as soon as their thread is
free.  Printed per case, level count and sync cost: the band's share of the
events and the events phase's 2-thread speedup over the trace's one-thread
cost, without and with free events running ahead of a waiting band event
(an upper bound for a design that checks them), with the events a schedule
ran against the sequential order on a particle they share (``clashes``) and
the share of events that started before an earlier band event of their own
domain (``ran ahead``: what such a design must be able to undo).
``sync`` is added to every band event (a clock handed between cores).

Cuts (in the tree's storage order, so each domain is a run of tree nodes):
``cost`` at equal shares of the step's traced event cost (the best balance
any cut could have: known only after the step), ``count`` at the median slot.

The trace's costs are the events' own (advance, resolve, predict again), not
the queue updates: what the model says is how much of the events' work two
threads can overlap, not the engine's wall time.
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from benchmarks.parallel_speedup import add_case_options, load_case, parse_cases, say  # noqa: E402
from lockgraph.band_replay import band_schedule, event_domains, order_conflicts, particle_levels  # noqa: E402
from lockgraph.engine import Engine  # noqa: E402
from lockgraph.simulation import compile_kernels  # noqa: E402

# the candidate list entries hold the slot above 5 flag bits (neighbors.py)
SLOT_SHIFT = 5


def record(name, n, steps, bed_code, bed_steps):
    """Per step: (events structured array, slot of each id, noff, candidate slots),
    and the cycle counter's frequency."""
    sc = load_case(name, n, bed_code, bed_steps)
    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=[("graph", 4.0)])
    lists = []
    inner = eng._events_sequential

    def events(*args, **kw):
        # the candidate lists as the step's events begin (after the search)
        slot = np.empty(eng.n, np.int64)
        slot[eng.ids] = np.arange(eng.n)
        noff = eng.noff[:eng.n + 1].astype(np.int64)
        lists.append((slot, noff, eng.nent[:noff[-1]].astype(np.int64) >> SLOT_SHIFT))
        return inner(*args, **kw)
    eng._events_sequential = events
    try:
        for s in range(steps):
            eng.step()
            say(f"{name}: step {s + 1}/{steps}: {int(eng.last_events)} events")
        tr = eng.trace()
    finally:
        eng.close()
    return [(st["events"],) + lst for st, lst in zip(tr["steps"], lists)], tr["cycles_per_second"]


def cut_domains(n, si, sj, cost, how):
    """Domain (0 or 1) of each slot."""
    if how == "count":
        c = n // 2
    else:
        load = np.zeros(n)
        np.add.at(load, si, 0.5 * cost)
        has = sj >= 0
        np.add.at(load, sj[has], 0.5 * cost[has])
        cum = np.cumsum(load)
        c = int(np.searchsorted(cum, 0.5 * cum[-1]))
    return (np.arange(n) >= c).astype(np.int64)


def ran_ahead(edom, band, start):
    """Events started before a band event of their domain that precedes them
    in the sequential order (what a run-ahead design must be able to undo)."""
    n = 0
    for d in np.unique(edom):
        idx = np.flatnonzero(edom == d)  # key order
        bstart = np.where(band[idx], start[idx], -np.inf)
        # the latest start among the domain's earlier band events
        before = np.maximum.accumulate(np.r_[-np.inf, bstart[:-1]])
        n += int(np.count_nonzero(before > start[idx]))
    return n


def bound(name, n, steps, levels, depths, cut, syncs, bed_code, bed_steps):
    trace, cps = record(name, n, steps, bed_code, bed_steps)
    rows = {}
    for ev, slot, noff, nent in trace:
        si = slot[ev["i"]]
        sj = np.where(ev["j"] >= 0, slot[np.maximum(ev["j"], 0)], -1)
        cost = ev["cycles"] / cps
        dom = cut_domains(slot.shape[0], si, sj, cost, cut)
        for lv in levels:
            lvl = particle_levels(noff, nent, dom, lv + max(depths))
            edom, band = event_domains(si, sj, dom, np.minimum(lvl, lv + 1), lv)
            halves = max(cost[edom == d].sum() for d in (0, 1))
            for sync in syncs:
                cost_s = cost + np.where(band, sync, 0.0)
                for depth in [None] + depths:
                    if depth is None:  # the band rule alone
                        span, _, fin = band_schedule(edom, band, cost, False, sync, finish=True)
                    else:  # free events at least `depth` hops beyond the band run ahead
                        _, deeper = event_domains(si, sj, dom, np.minimum(lvl, lv + depth + 1),
                                                  lv + depth)
                        span, _, fin = band_schedule(edom, band, cost, True, sync, finish=True,
                                                     ahead=~deeper)
                    nc = order_conflicts(si, sj, ev["kind"], noff, nent, fin - cost_s, fin)
                    r = rows.setdefault((lv, sync, -1 if depth is None else depth), np.zeros(8))
                    r += [cost.sum(), span, halves, band.sum(), len(cost), nc > 0, nc,
                          ran_ahead(edom, band, fin - cost_s)]
    k = len(trace)
    print(f"\n{name}: N = {n}, {k} steps recorded, cut by {cut}; the events phase on 2 "
          f"virtual threads with no coordination cost but `sync` per band event; "
          f"ahead: free events that many hops beyond the band run ahead of a waiting one "
          f"(-: none); clash steps: steps with an event run against the sequential order, "
          f"clashes: such events; ran ahead: events started before an earlier band event "
          f"of their domain")
    print(f"  {'levels':>6s} {'sync ns':>8s} {'band events':>12s} {'1 thread ms':>12s} "
          f"{'halves alone':>13s} {'ahead':>6s} {'2 threads':>10s} {'clash steps':>12s} "
          f"{'clashes/step':>13s} {'ran ahead':>10s}")
    for (lv, sync, depth), (seq, span, half, nb, ne, bad, nc, ra) in sorted(rows.items()):
        print(f"  {lv:6d} {sync * 1e9:8.0f} {nb / ne:12.1%} {seq / k * 1e3:12.2f} "
              f"{seq / half:12.2f}x {'-' if depth < 0 else depth:>6} {seq / span:9.2f}x "
              f"{bad:8.0f}/{k} {nc / k:13.0f} {ra / ne:10.1%}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_options(ap, "dish_marble_dem")
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--levels", default="1,2,3", help="band depths in candidate-list hops")
    ap.add_argument("--depths", default="0,1,2,4",
                    help="run-ahead depths: free events this many hops beyond the band")
    ap.add_argument("--cut", default="cost", choices=("cost", "count"))
    ap.add_argument("--sync", default="0,2e-7", help="seconds added to each band event")
    args = ap.parse_args()
    names, sizes = parse_cases(ap, args.cases, args.n)
    levels = [int(x) for x in args.levels.split(",")]
    syncs = [float(x) for x in args.sync.split(",")]
    depths = [int(x) for x in args.depths.split(",")] if args.depths else []
    if args.steps < 1 or min(levels) < 1 or min(syncs) < 0 or min(depths + [0]) < 0:
        ap.error("--steps and --levels must be >= 1, --sync and --depths >= 0")
    compile_kernels()
    for name in names:
        bound(name, sizes[name], args.steps, levels, depths, args.cut, syncs, args.bed_code,
              args.bed_steps)


if __name__ == "__main__":
    main()
