"""What coordinating two event loops costs on this machine, per event.

    python benchmarks/clock_handoff.py [--event-ns 300,600] [--events 200000]
                                       [--repeats 5]

Two threads each run a loop of stand-in events (a spin of ``--event-ns``
nanoseconds that touches no shared memory) at once, with each kind of
coordination a domain-split engine could use, and report the median cost of
an event against the loop with none, measured side by side in one run:

* ``publish``: after every event the thread stores its clock (an atomic
  store to a cache line the other thread reads);
* ``read k``: as publish, and every k-th event (a band event) loads the other
  thread's clock and waits while it is far behind (it never is: the loops
  run at the same pace) -- what ``band_replay.pool_schedule``'s ``sync``
  stands for;
* ``locks k``: as read k, and every event takes and drops its own domain's
  spin lock twice (pick and commit, as ``parallel.worker`` does), every k-th
  also the other domain's (a collision across the cut updates the other
  queue).

The stand-in events hide nothing of the coordination's latency that a real
event would hide, and share no data: the figures are the coordination's own
cost, not the waits a schedule has (those are ``bench band``'s replay).
"""
import argparse
import os
import sys
import threading

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from numba import njit  # noqa: E402

from lockgraph.atomics import cpu_relax, cycles, load, spin_lock, spin_unlock, store  # noqa: E402
from lockgraph.parallel import cycles_per_second  # noqa: E402

# words of the shared array: a thread's clock and its lock, each on a cache
# line of its own (16 int64 = 128 bytes: also apart from the adjacent-line
# prefetcher's pair)
LINE = 16
CLOCK, LOCK = 0, 2


@njit(cache=True, nogil=True)
def event_loop(me, other, shared, n, work, every, publish, locks, out):
    """n stand-in events of ``work`` cycles; returns the cycles taken in out[me]."""
    mine = me * 4 * LINE
    theirs = other * 4 * LINE
    c0 = cycles()
    for e in range(n):
        if locks:  # pick
            spin_lock(shared, mine + LOCK * LINE)
            spin_unlock(shared, mine + LOCK * LINE)
        s = cycles()
        while cycles() - s < work:
            cpu_relax()
        if every > 0 and e % every == 0:
            # a band event: the other clock must not be far behind
            while load(shared, theirs + CLOCK * LINE) < e - 100000:
                cpu_relax()
        if locks:  # commit, and every k-th the other queue
            spin_lock(shared, mine + LOCK * LINE)
            spin_unlock(shared, mine + LOCK * LINE)
            if every > 0 and e % every == 0:
                spin_lock(shared, theirs + LOCK * LINE)
                spin_unlock(shared, theirs + LOCK * LINE)
        if publish:
            store(shared, mine + CLOCK * LINE, e)
    out[me] = cycles() - c0


def both(n, work, every, publish, locks):
    """Cycles per event of the slower of the two loops run at once."""
    shared = np.zeros(8 * 4 * LINE, np.int64)
    out = np.zeros(2, np.int64)
    threads = [threading.Thread(target=event_loop,
                                args=(k, 1 - k, shared, n, work, every, publish, locks, out))
               for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return out.max() / n


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--event-ns", default="300,600", help="stand-in event lengths (ns)")
    ap.add_argument("--events", type=int, default=200000, help="events per loop")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    lengths = [float(x) for x in args.event_ns.split(",")]
    if min(lengths) <= 0 or args.events < 1 or args.repeats < 1:
        ap.error("--event-ns, --events and --repeats must be positive")
    cps = cycles_per_second()
    modes = [("none", 0, False, False), ("publish", 0, True, False),
             ("read 3", 3, True, False), ("read 1", 1, True, False),
             ("locks 3", 3, True, True), ("locks 1", 1, True, True)]
    event_loop(0, 1, np.zeros(8 * 4 * LINE, np.int64), 10, 10, 1, True, True,
               np.zeros(2, np.int64))  # compile
    print(f"two threads at once, {args.events} stand-in events each, median of "
          f"{args.repeats} interleaved repeats; extra: ns an event over 'none'")
    print(f"  {'event ns':>8s} {'coordination':>13s} {'ns an event':>12s} {'extra':>7s} "
          f"{'ratio':>7s}")
    for ns in lengths:
        work = int(ns * 1e-9 * cps)
        runs = {m[0]: [] for m in modes}
        for _ in range(args.repeats):
            for name, every, publish, locks in modes:
                runs[name].append(both(args.events, work, every, publish, locks) / cps * 1e9)
        base = float(np.median(runs["none"]))
        for name, *_ in modes:
            med = float(np.median(runs[name]))
            print(f"  {ns:8.0f} {name:>13s} {med:12.0f} {med - base:7.0f} {med / base:6.2f}x")


if __name__ == "__main__":
    main()
