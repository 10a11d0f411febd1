"""What a domain split with a particle band could gain at best on the events.

    python benchmarks/band_bound.py [--cases dish_marble_dem] [--steps 6]
                                    [--levels 1,2,3] [--depths 0,1,2,4] [--cut cost]
                                    [--sync 0,2e-7] [--domains 2,4,8] [--threads 2]
                                    [--pool-runs known,seen,fixed,regions]

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

Then the same trace on ``--threads`` virtual threads shared by ``--domains``
domains (``band_replay.pool_schedule``): each domain runs its events in key
order; an event waits only for the domains within two candidate hops of its
particles (the depth that keeps the sequential order, tested), until none of
theirs with a smaller key is pending or running; a thread whose domains wait
takes another.  ``known``: every event is known from the start (the bound);
``seen``: an event exists only once the event that last wrote one of its
particles has finished, as in an engine that reads its neighbours' queues
(with the events then run against the sequential order, ``clashes``); with
the domains free to go to any thread, or thread k keeping domains k, k + T,
... (``d mod T``).  Also with the waits by lock region (``regions``: the domains within two hops of
the event's regions in the lock graph at SCALE 4, as an engine that knows
only regions would wait; ``band_replay.region_waits``).

Cuts (in the tree's storage order, so each domain is a run of tree nodes):
``cost`` at equal shares of the step's traced event cost (the best balance
any cut could have: known only after the step), ``count`` at the median slot
(K domains: equal slot counts, the engine's tree nodes of one depth).  And
one the engine cannot make (its domains are runs of slots): ``height``,
slabs across the longest axis of the particles' box (z on the bed), at
equal shares of the traced event cost.  ``--pool-runs`` picks the pool's
rows (each a replay of every step: about a minute and a half a step on the
bed).

The trace's costs are the events' own (advance, resolve, predict again), not
the queue updates: what the model says is how much of the events' work two
threads can overlap, not the engine's wall time.  A cost above ``OUTLIER``
(1,000) times its step's median counts as the median: the host's pause, not
the event's work.
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from benchmarks.parallel_speedup import add_case_options, load_case, parse_cases, say  # noqa: E402
from lockgraph.band_replay import (  # noqa: E402
    MAX_DOMAINS, band_schedule, creators, domain_masks, event_domains, event_waits,
    order_conflicts, particle_levels, pool_schedule, region_waits)
from lockgraph.engine import Engine  # noqa: E402
from lockgraph.simulation import compile_kernels  # noqa: E402

# the candidate list entries hold the slot above 5 flag bits (neighbors.py)
SLOT_SHIFT = 5
# the pool's waits reach this many candidate hops: an event writes its own
# particles and reads their candidates, so two events sharing a particle that
# one writes have particles within two hops (tests/test_band_replay.py)
POOL_LEVELS = 2
# the lock graph recorded for the pool's waits by region (the engine's default SCALE)
REGION_SCALE = 4.0
# an event's traced cost above this many times its step's median is taken as the
# host's (an interrupt, a preemption) and counted as the median: one event of 8 ms
# (the median 0.5 us; the next longest 160 us) in a traced step of the bed put the
# replay's 16 domains at 1.67x, where other traces of that step give 2.00x (2026-12-06)
OUTLIER = 1000.0


def record(name, n, steps, bed_code, bed_steps, bed_ranks=2):
    """Per step: (events structured array, slot of each id, noff, candidate slots,
    (lock region of each slot, loff, ladj) of the lock graph at SCALE
    REGION_SCALE, positions (N, 3) by slot as the events begin), and the cycle
    counter's frequency."""
    sc = load_case(name, n, bed_code, bed_steps, bed_ranks)
    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=[("graph", REGION_SCALE)])
    lists = []
    inner = eng._events_sequential

    def events(*args, **kw):
        # the candidate lists as the step's events begin (after the search)
        slot = np.empty(eng.n, np.int64)
        slot[eng.ids] = np.arange(eng.n)
        noff = eng.noff[:eng.n + 1].astype(np.int64)
        lists.append((slot, noff, eng.nent[:noff[-1]].astype(np.int64) >> SLOT_SHIFT,
                      eng.pos[:eng.n].copy()))
        return inner(*args, **kw)
    eng._events_sequential = events
    try:
        for s in range(steps):
            eng.step()
            say(f"{name}: step {s + 1}/{steps}: {int(eng.last_events)} events")
        tr = eng.trace()
    finally:
        eng.close()
    out = []
    for st, (slot, noff, nent, pos) in zip(tr["steps"], lists):
        by_id, loff, ladj = st["locks"][("graph", REGION_SCALE)]
        region = np.empty(slot.shape[0], np.int64)
        region[slot] = by_id
        out.append((st["events"], slot, noff, nent, (region, loff, ladj), pos))
    return out, tr["cycles_per_second"]


def cut_domains(n, si, sj, cost, how, k=2, pos=None):
    """Domain (0 .. k - 1) of each slot: k runs of slots ("count", "cost"), or
    k slabs across the longest axis of the box of ``pos`` (N, 3) by slot
    ("height")."""
    if how == "count":
        cuts = n * np.arange(1, k) // k
        return np.searchsorted(cuts, np.arange(n), side="right").astype(np.int64)
    # the order the runs follow: the slots' own, or by height along the axis
    order = np.arange(n)
    if how == "height":
        axis = int(np.argmax(np.ptp(pos, axis=0)))
        order = np.argsort(pos[:, axis], kind="stable")
    rank = np.empty(n, np.int64)
    rank[order] = np.arange(n)
    load = np.zeros(n)
    np.add.at(load, rank[si], 0.5 * cost)
    has = sj >= 0
    np.add.at(load, rank[sj[has]], 0.5 * cost[has])
    cum = np.cumsum(load)
    cuts = np.searchsorted(cum, cum[-1] * np.arange(1, k) / k)
    return np.searchsorted(cuts, rank, side="right").astype(np.int64)


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


def in_slots(ev, slot, cps):
    """A step's events as (slot of i, slot of j or -1, cost in seconds); a
    cost above ``OUTLIER`` times the step's median is the host's, not the
    event's, and counts as the median."""
    sj = np.where(ev["j"] >= 0, slot[np.maximum(ev["j"], 0)], -1)
    cost = ev["cycles"] / cps
    if cost.shape[0]:
        med = np.median(cost)
        cost = np.where(cost > OUTLIER * med, med, cost)
    return slot[ev["i"]], sj, cost


# the pool's replays (``--pool-runs``): name -> (waits by, events seen only
# once created, domains fixed to threads)
POOL_RUNS = {"known": ("particles", False, False), "seen": ("particles", True, False),
             "fixed": ("particles", False, True), "regions": ("regions", False, False)}


def pool(trace, cps, cut, syncs, domains, threads, runs=tuple(POOL_RUNS)):
    """The pool's rows: (domains, sync, waits by, known/seen, fixed) -> summed
    (1-thread cost, makespan, waiting events, events, clash steps, clashes)."""
    rows = {}
    for ev, slot, noff, nent, (region, loff, ladj), pos in trace:
        si, sj, cost = in_slots(ev, slot, cps)
        made = creators(si, sj, ev["kind"]) if "seen" in runs else None
        for k in domains:
            dom = cut_domains(slot.shape[0], si, sj, cost, cut, k, pos)
            waits = {"particles": event_waits(si, sj, dom,
                                              domain_masks(noff, nent, dom, POOL_LEVELS))}
            if "regions" in runs:
                waits["regions"] = region_waits(si, sj, dom, region, loff, ladj, POOL_LEVELS)
            for sync in syncs:
                # (the events seen only once created: by particles; they waited
                # as if known in every run tried)
                for by, seen, fixed in (POOL_RUNS[r] for r in runs):
                    edom, wait = waits[by]
                    span, start, fin = pool_schedule(edom, wait, cost, threads,
                                                     made if seen else None, sync, fixed)
                    nc = order_conflicts(si, sj, ev["kind"], noff, nent, start, fin)
                    r = rows.setdefault((k, sync, by, seen, fixed), np.zeros(6))
                    r += [cost.sum(), span, np.count_nonzero(wait), len(cost), nc > 0, nc]
    return rows


def bound(name, n, steps, levels, depths, cut, syncs, bed_code, bed_steps, domains, threads,
          bed_ranks=2, runs=tuple(POOL_RUNS)):
    trace, cps = record(name, n, steps, bed_code, bed_steps, bed_ranks)
    rows = {}
    for ev, slot, noff, nent, _, pos in trace:
        si, sj, cost = in_slots(ev, slot, cps)
        dom = cut_domains(slot.shape[0], si, sj, cost, cut, pos=pos)
        for lv in levels:
            lvl = particle_levels(noff, nent, dom, lv + max(depths, default=0))
            edom, band = event_domains(si, sj, dom, np.minimum(lvl, lv + 1), lv)
            halves = max(cost[edom == d].sum() for d in (0, 1))
            for sync in syncs:
                for depth in [None] + depths:
                    if depth is None:  # the band rule alone
                        span, _, fin, start = band_schedule(edom, band, cost, False, sync,
                                                            finish=True)
                    else:  # free events at least `depth` hops beyond the band run ahead
                        _, deeper = event_domains(si, sj, dom, np.minimum(lvl, lv + depth + 1),
                                                  lv + depth)
                        span, _, fin, start = band_schedule(edom, band, cost, True, sync,
                                                            finish=True, ahead=~deeper)
                    nc = order_conflicts(si, sj, ev["kind"], noff, nent, start, fin)
                    r = rows.setdefault((lv, sync, -1 if depth is None else depth), np.zeros(8))
                    r += [cost.sum(), span, halves, band.sum(), len(cost), nc > 0, nc,
                          ran_ahead(edom, band, start)]
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
    if not domains:
        return
    what = "slabs cut by height" if cut == "height" else f"runs of slots cut by {cut}"
    print(f"\n{name}: the same steps on {threads} virtual threads shared by K domains ({what}); "
          f"an event waits for the domains within {POOL_LEVELS} hops "
          f"of its particles, or of their lock regions at SCALE {REGION_SCALE:g} (waiting "
          f"events), with every event known from the start or seen only once its creator "
          f"finished; clash steps and clashes as above")
    print(f"  {'domains':>7s} {'sync ns':>8s} {'waits by':>10s} {'waiting events':>15s} "
          f"{'events are':>11s} {'domains on':>11s} {'1 thread ms':>12s} "
          f"{f'{threads} threads':>10s} {'clash steps':>12s} {'clashes/step':>13s}")
    for (dk, sync, by, seen, fixed), (seq, span, nw, ne, bad, nc) in sorted(
            pool(trace, cps, cut, syncs, domains, threads, runs).items()):
        print(f"  {dk:7d} {sync * 1e9:8.0f} {by:>10s} {nw / ne:15.1%} "
              f"{'seen' if seen else 'known':>11s} {'d mod T' if fixed else 'any':>11s} "
              f"{seq / k * 1e3:12.2f} {seq / span:9.2f}x {bad:8.0f}/{k} {nc / k:13.0f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_case_options(ap, "dish_marble_dem")
    ap.add_argument("--steps", type=int, default=6)
    ap.add_argument("--levels", default="1,2,3", help="band depths in candidate-list hops")
    ap.add_argument("--depths", default="0,1,2,4",
                    help="run-ahead depths: free events this many hops beyond the band")
    ap.add_argument("--cut", default="cost", choices=("cost", "count", "height"))
    ap.add_argument("--sync", default="0,2e-7", help="seconds added to each band event")
    ap.add_argument("--domains", default="2,4,8",
                    help="domain counts for the pool of threads ('' for none)")
    ap.add_argument("--threads", type=int, default=2, help="the pool's threads")
    ap.add_argument("--pool-runs", default=",".join(POOL_RUNS),
                    help=f"the pool's replays, a subset of {','.join(POOL_RUNS)}")
    args = ap.parse_args()
    runs = tuple(r for r in args.pool_runs.split(",") if r)
    if not runs or not set(runs) <= set(POOL_RUNS):
        ap.error(f"--pool-runs takes a subset of {','.join(POOL_RUNS)} (got {args.pool_runs!r})")
    names, sizes = parse_cases(ap, args.cases, args.n)
    levels = [int(x) for x in args.levels.split(",")]
    syncs = [float(x) for x in args.sync.split(",")]
    depths = [int(x) for x in args.depths.split(",")] if args.depths else []
    domains = [int(x) for x in args.domains.split(",")] if args.domains else []
    if args.steps < 1 or min(levels) < 1 or min(syncs) < 0 or min(depths + [0]) < 0:
        ap.error("--steps and --levels must be >= 1, --sync and --depths >= 0")
    if args.threads < 1 or not all(1 <= k <= MAX_DOMAINS for k in domains):
        ap.error(f"--threads must be >= 1 and --domains 1..{MAX_DOMAINS}")
    compile_kernels()
    for name in names:
        bound(name, sizes[name], args.steps, levels, depths, args.cut, syncs, args.bed_code,
              args.bed_steps, domains, args.threads, args.bed_ranks, runs)


if __name__ == "__main__":
    main()
