"""Scheduling replay: how long would a recorded sequential trace take on P threads?

A sequential run with ``Engine(..., trace_locks=[...])`` records every event it
processed (``Engine.trace()``, see there for the format): the particles, what
the event cost in CPU cycles, and each step's lock regions for several lock
structures.  This module runs a *virtual* P-thread schedule of those events —
a discrete-event simulation of the scheduler, not of the physics — so that lock
structures, SCALEs and thread counts (including more threads than this machine
has cores) can be compared on the same work.

Model, per step (steps are separated by a barrier, and the run's time is the
sum of the step times):

* **Cost.**  Event e takes ``c_e = cycles / cycles_per_second`` seconds — the
  time the sequential engine spent in that event (advance, resolve, predict
  again).  Everything else a step does is outside the replay: the half kicks,
  search radii, building or re-sorting the tree, the pair search, the first
  predictions, building the lock structure and the final drift, and also the
  queue update after each event (it is not inside the traced cycles).
* **Creation dependencies.**  An event exists only once the events that last
  changed its particles are done: e waits for the latest earlier event (in
  trace order) that *wrote* particle i and the latest one that wrote particle
  j (when j >= 0).  A pair collision (kind 0) writes both particles; a wall
  collision (kind 1) and a stale event (kind 2: the partner collided since the
  prediction, so only i is predicted again) write only i.  A stale event still
  waits for j's latest writer: that is the collision that made it stale, and
  it reads j's collision counter.  Events with no such predecessor are ready at
  time 0.  (Taking only the most recent of all earlier events that involve i
  or j — ``ReplayTrace(trace, dependencies="latest")``, kept for comparison —
  would let e start before the other particle's last writer has finished, or
  even started: events of one particle could run out of order.)
* **Locks.**  Event e holds the lock regions A_e = {region[i], region[j]}
  ({region[i]} for walls) from its claim to its finish.  A waiting event is
  *clear* of a running one when, for policy ``"paper"``, none of its regions is
  equal or adjacent to a running event's region (lock-graph distance >= 2, the
  paper's rule), and for ``"exact"`` when their closed neighbourhoods do not
  meet (distance >= 3: what ``lockgraph.parallel`` asks of boundary events).
  The replay enforces neither time order nor the real engine's domains: it
  models only lock exclusion, creation order and queue contention.
* **Threads.**  A thread free at virtual time T takes, among the events ready by
  T and not yet started, the earliest in trace order that is clear of every
  running event; it may pass over at most ``lookahead`` blocked ready events.
  If none qualifies it waits for the next event to finish.
* **Queue contention.**  Every claim holds one global queue lock for
  ``overhead`` seconds, and claims are serialized (one cannot begin before the
  previous claim released the lock); the event runs after its claim.  So at
  P = 1 a step takes sum(c_e) + m * overhead for its m events, and for any P
  it takes at least m * overhead.
* **Other overheads** (optional, zero by default).  ``per_event`` is added to
  every event's cost on its own thread — per-event work that runs in parallel
  (the opposite assumption to ``overhead``); ``step_overhead`` is added to
  every step (starting and joining the threads).

Comparing with a measured run: compare *events phases* only, never whole
steps.  The convention here and in ``benchmarks/paper_tables.py``:

* preferred: the run's own events-phase wall time — for a threaded run the
  worker threads' time from dispatch to join, ``S_ECYC`` in each step's
  statistics (it is lost for a step that had a repair);
* otherwise ``T_events = T_run - T_other`` with ``T_other = T_seq - sum(c_e)``:
  the wall time of an untraced sequential run of the same steps minus the
  trace's summed event costs.  This counts everything the threaded run does
  per step and the sequential one does not (building the lock structure and
  the domains) as events time.

``calibrate`` finds the ``overhead`` that makes the replay at P threads last
``T_events``; that overhead then also absorbs what the threaded run spends per
event beyond ``c_e`` (queue updates, lock checks, shared cache lines) — the
point of fitting it rather than guessing it.  Measure the per-step cost of
starting and joining the threads separately (a threaded step with no events)
and pass it as ``step_overhead``; otherwise it too is spread over the claims,
which with few events per step makes the fitted overhead large.  One
measurement cannot tell serialized per-event cost from parallel per-event
cost: ``calibrate(fit="per_event")`` gives the other bound.  A 2-thread run
slower than the sequential one, fitted as serialized overhead, makes the
replay flat in P (the claims are the bottleneck); fitted as ``per_event`` it
scales.

The inner loops are numba kernels (``lockgraph._jit.kernel``: no NRT, no
allocation), fed with work arrays allocated here: a step of 2e5 events replays
in about 0.05 s.
"""
import math

import numpy as np

from ._jit import kernel

KIND_PAIR, KIND_WALL, KIND_STALE = 0, 1, 2
POLICIES = ("exact", "paper")
FITS = ("overhead", "per_event")
DEPENDENCIES = ("writers", "latest")
# out[] slots of _simulate
O_TIME, O_BLOCKED, O_PASSED, O_STALLS, O_CLAIMS, O_ERR = range(6)
NOUT = 8


# ---- kernels -------------------------------------------------------------------

@kernel
def _dependencies(ev_i, ev_j, ev_kind, single, last, parents, pend, coff, cadj):
    """Creation dependencies of one step's events, as a child list.

    single: the "latest" rule (one parent: the latest earlier event naming i or
    j, stale events counting as writing j) instead of the "writers" rule.

    ev_i, ev_j, ev_kind (m,) int64: the events in trace order (j = -1: wall).
    last (n,) int64: work, the latest writer of each particle (set to -1 here).
    parents (m, 2) int64: out, the latest earlier writer of i and of j (-1: none).
    pend (m,) int64: out, how many distinct parents each event has (0, 1 or 2).
    coff (m+1,) int64, cadj (2m,) int64: out, CSR of each event's children.
    Returns the number of child entries.
    """
    m = ev_i.shape[0]
    for p in range(last.shape[0]):
        last[p] = -1
    for e in range(m + 1):
        coff[e] = 0
    for e in range(m):
        i = ev_i[e]
        j = ev_j[e]
        pa = last[i]
        pb = last[j] if j >= 0 else -1
        if single:
            pa = max(pa, pb)
            pb = -1
        if pb == pa:
            pb = -1
        parents[e, 0] = pa
        parents[e, 1] = pb
        k = 0
        if pa >= 0:
            coff[pa + 1] += 1
            k += 1
        if pb >= 0:
            coff[pb + 1] += 1
            k += 1
        pend[e] = k
        # only what an event changes makes later events wait for it
        last[i] = e
        if j >= 0 and (ev_kind[e] == KIND_PAIR or single):
            last[j] = e
    for e in range(m):
        coff[e + 1] += coff[e]
    # fill: parents[] row order keeps each child list in trace order
    for e in range(m):
        for q in range(2):
            p = parents[e, q]
            if p >= 0:
                # coff[p] is used as the cursor, restored below
                cadj[coff[p]] = e
                coff[p] += 1
    # undo the cursor shift: coff[p] now holds the old coff[p + 1]
    for e in range(m, 0, -1):
        coff[e] = coff[e - 1]
    coff[0] = 0
    return coff[m]


@kernel
def _heap_push(heap, hn, e):
    """Min-heap of trace indices in heap[:hn]; returns the new size."""
    k = hn
    heap[k] = e
    while k > 0:
        p = (k - 1) >> 1
        if heap[p] <= heap[k]:
            break
        x = heap[p]
        heap[p] = heap[k]
        heap[k] = x
        k = p
    return hn + 1


@kernel
def _heap_pop(heap, hn):
    """Remove the smallest entry of heap[:hn]; returns (entry, new size)."""
    top = heap[0]
    hn -= 1
    x = heap[hn]
    k = 0
    while True:
        c = 2 * k + 1
        if c >= hn:
            break
        if c + 1 < hn and heap[c + 1] < heap[c]:
            c += 1
        if x <= heap[c]:
            break
        heap[k] = heap[c]
        k = c
    if hn > 0:
        heap[k] = x
    return top, hn


@kernel
def _region_clear(cnt, loff, ladj, a):
    """No busy count on region a or any region adjacent to it."""
    if cnt[a] != 0:
        return False
    for k in range(loff[a], loff[a + 1]):
        if cnt[ladj[k]] != 0:
            return False
    return True


@kernel
def _mark(held, near, loff, ladj, a, d):
    """held[x]: running events owning region x; near[x]: running events with x in
    the closed neighbourhood of one of their regions."""
    held[a] += d
    near[a] += d
    for k in range(loff[a], loff[a + 1]):
        near[ladj[k]] += d


@kernel
def _simulate(ra, rb, cost, pend, coff, cadj, loff, ladj, held, near, heap, tmp, run_ev,
              run_fin, start, far, overhead, out):
    """Virtual schedule of one step's events on len(run_ev) threads.

    ra, rb (m,) int32: each event's two lock regions (rb = ra for walls).
    cost (m,) float64: each event's run time, s.
    pend (m,) int64: parents not yet finished (consumed: decremented to 0).
    coff, cadj: children CSR from ``_dependencies``.
    loff (R+1,) int64, ladj (E,) int32: the regions' adjacency.
    held, near (R,) int64: work, zero on entry and on return.
    heap (m,) int64, tmp (lookahead+1,) int64, run_ev (P,) int64, run_fin (P,)
    float64: work.  start (m,) float64: out, each event's start time (s, after
    its claim).  far: exact policy (distance >= 3) instead of the paper's (>= 2).
    overhead: s per claim under the one queue lock.
    out (NOUT,) float64: the step's time (s) and counters, see O_*.
    """
    m = ra.shape[0]
    threads = run_ev.shape[0]
    lookahead = tmp.shape[0] - 1
    hn = 0
    for e in range(m):
        if pend[e] == 0:
            hn = _heap_push(heap, hn, e)
    nrun = 0
    done = 0
    now = 0.0
    lock_free = 0.0  # when the queue lock is next free
    makespan = 0.0
    # stuck: the last pick found nothing clear; nothing can change until a finish
    stuck = False
    blocked = 0
    passed = 0
    stalls = 0
    claims = 0
    while done < m:
        # retire everything finished by now: free its regions, release its children
        k = 0
        while k < nrun:
            if run_fin[k] <= now:
                e = run_ev[k]
                _mark(held, near, loff, ladj, ra[e], -1)
                if rb[e] != ra[e]:
                    _mark(held, near, loff, ladj, rb[e], -1)
                for q in range(coff[e], coff[e + 1]):
                    c = cadj[q]
                    pend[c] -= 1
                    if pend[c] == 0:
                        hn = _heap_push(heap, hn, c)
                done += 1
                nrun -= 1
                run_ev[k] = run_ev[nrun]
                run_fin[k] = run_fin[nrun]
                stuck = False
            else:
                k += 1
        if done == m:
            break
        idle = nrun < threads
        if idle and hn > 0 and not stuck and lock_free <= now:
            # pick: the earliest clear ready event among the first lookahead + 1
            npop = 0
            found = -1
            while hn > 0 and npop <= lookahead:
                e, hn = _heap_pop(heap, hn)
                ok = _region_clear(near if far else held, loff, ladj, ra[e])
                if ok and rb[e] != ra[e]:
                    ok = _region_clear(near if far else held, loff, ladj, rb[e])
                if ok:
                    found = e
                    break
                tmp[npop] = e
                npop += 1
            for q in range(npop):
                hn = _heap_push(heap, hn, tmp[q])
            if npop > 0:
                blocked += 1
            if found >= 0:
                passed += npop
                claims += 1
                e = found
                _mark(held, near, loff, ladj, ra[e], 1)
                if rb[e] != ra[e]:
                    _mark(held, near, loff, ladj, rb[e], 1)
                lock_free = now + overhead
                start[e] = lock_free
                fin = lock_free + cost[e]
                run_ev[nrun] = e
                run_fin[nrun] = fin
                nrun += 1
                if fin > makespan:
                    makespan = fin
                continue  # another idle thread may claim (after the lock is free)
            stuck = True
            stalls += 1
        # advance virtual time to the next thing that can change the picture
        nxt = math.inf
        for k in range(nrun):
            if run_fin[k] < nxt:
                nxt = run_fin[k]
        if idle and hn > 0 and not stuck and lock_free > now and lock_free < nxt:
            nxt = lock_free
        if nxt == math.inf:
            out[O_ERR] = 1.0  # nothing running and nothing ready: bad dependencies
            return
        now = nxt
    out[O_TIME] = makespan
    out[O_BLOCKED] = blocked
    out[O_PASSED] = passed
    out[O_STALLS] = stalls
    out[O_CLAIMS] = claims
    out[O_ERR] = 0.0


# ---- Python layer ----------------------------------------------------------------

def lock_key(key):
    """Normalize a lock key: ("graph", 4) -> ("graph", 4.0); "grid" -> ("grid", None)."""
    if isinstance(key, str):
        return (key, None)
    kind, scale = key
    return (kind, float(scale) if kind == "graph" else None)


class ReplayTrace:
    """A trace prepared for replays: event costs (s) and creation dependencies
    per step, computed once; lock regions per lock key on first use.

    ``trace`` is the dict of ``Engine.trace()``: ``steps`` (list of {"events":
    structured array t, cycles, i, j, kind; "locks": {key: (region (N,) int32,
    loff (R+1,) int64, ladj (E,) int32)}}), ``cycles_per_second``, ``n``, ``dt``.
    ``dependencies``: "writers" (default: wait for the latest writers of i and
    of j) or "latest" (wait for the one latest event naming i or j); see the
    module docstring.
    """

    def __init__(self, trace, dependencies="writers"):
        if dependencies not in DEPENDENCIES:
            raise ValueError(f"dependencies must be one of {DEPENDENCIES}, "
                             f"got {dependencies!r}")
        self.dependencies = dependencies
        self.cps = float(trace["cycles_per_second"])
        if not self.cps > 0:
            raise ValueError(f"cycles_per_second must be > 0, got {self.cps!r}")
        self.raw = trace["steps"]
        n = int(trace["n"])
        self.n = n
        last = np.zeros(max(n, 1), np.int64)
        self.steps = []
        for s, step in enumerate(self.raw):
            ev = step["events"]
            m = len(ev)
            ei = np.ascontiguousarray(ev["i"], np.int64)
            ej = np.ascontiguousarray(ev["j"], np.int64)
            ek = np.ascontiguousarray(ev["kind"], np.int64)
            if m and (ei.min() < 0 or ei.max() >= n or ej.max() >= n or ej.min() < -1):
                raise ValueError(f"step {s}: particle ids outside 0..{n - 1}")
            cost = np.ascontiguousarray(ev["cycles"], np.float64) / self.cps
            parents = np.zeros((m, 2), np.int64)
            pend = np.zeros(m, np.int64)
            coff = np.zeros(m + 1, np.int64)
            cadj = np.zeros(max(2 * m, 1), np.int64)
            _dependencies(ei, ej, ek, dependencies == "latest", last, parents, pend, coff,
                          cadj)
            self.steps.append({"i": ei, "j": ej, "cost": cost, "pend": pend, "coff": coff,
                               "cadj": cadj, "parents": parents, "regions": {}})

    @property
    def events(self):
        return sum(len(st["cost"]) for st in self.steps)

    @property
    def work(self):
        """Summed event costs over all steps, s."""
        return float(sum(st["cost"].sum() for st in self.steps))

    def keys(self):
        return list(self.raw[0]["locks"]) if self.raw else []

    def _regions(self, s, key):
        st = self.steps[s]
        if key not in st["regions"]:
            locks = self.raw[s]["locks"]
            if key not in locks:
                raise KeyError(f"lock structure {key!r} not in the trace (it has "
                               f"{sorted(locks, key=str)})")
            region, loff, ladj = locks[key]
            region = np.ascontiguousarray(region, np.int32)
            ra = region[st["i"]] if len(st["i"]) else np.zeros(0, np.int32)
            rb = ra.copy()
            w = st["j"] >= 0
            rb[w] = region[st["j"][w]]
            st["regions"][key] = (np.ascontiguousarray(ra), np.ascontiguousarray(rb),
                                  np.ascontiguousarray(loff, np.int64),
                                  np.ascontiguousarray(ladj, np.int32))
        return st["regions"][key]

    def replay(self, key, threads, policy="exact", overhead=0.0, lookahead=8, schedule=False,
               per_event=0.0, step_overhead=0.0):
        """See ``replay``."""
        key = lock_key(key)
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
        threads = int(threads)
        if threads < 1:
            raise ValueError(f"threads must be >= 1, got {threads}")
        for name, v in (("overhead", overhead), ("per_event", per_event),
                        ("step_overhead", step_overhead)):
            if not (v >= 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        lookahead = int(lookahead)
        if lookahead < 0:
            raise ValueError(f"lookahead must be >= 0, got {lookahead}")
        far = policy == "exact"
        tmp = np.zeros(lookahead + 1, np.int64)
        run_ev = np.zeros(threads, np.int64)
        run_fin = np.zeros(threads, np.float64)
        out = np.zeros(NOUT)
        step_times, starts = [], []
        totals = np.zeros(NOUT)
        for s, st in enumerate(self.steps):
            ra, rb, loff, ladj = self._regions(s, key)
            m = len(ra)
            nreg = loff.shape[0] - 1
            if m and max(int(ra.max()), int(rb.max())) >= nreg:
                raise ValueError(f"step {s}: a region index is >= the {nreg} regions of {key}")
            held = np.zeros(max(nreg, 1), np.int64)
            near = np.zeros(max(nreg, 1), np.int64)
            heap = np.zeros(max(m, 1), np.int64)
            start = np.full(m, np.nan)
            cost = st["cost"] + per_event if per_event else st["cost"]
            out[:] = 0.0
            if m:
                _simulate(ra, rb, cost, st["pend"].copy(), st["coff"], st["cadj"], loff,
                          ladj, held, near, heap, tmp, run_ev, run_fin, start, far,
                          float(overhead), out)
                if out[O_ERR]:
                    raise RuntimeError(f"step {s}: replay stuck (inconsistent dependencies)")
            step_times.append(float(out[O_TIME]) + step_overhead)
            totals += out
            if schedule:
                starts.append(start)
        total = float(sum(step_times))
        work = self.work
        res = {"time": total, "step_times": step_times,
               "concurrency": work / total if total > 0 else 1.0,
               "blocked": int(totals[O_BLOCKED]), "passed": int(totals[O_PASSED]),
               "stalls": int(totals[O_STALLS]), "events": int(totals[O_CLAIMS]),
               "work": work, "threads": threads, "policy": policy, "overhead": float(overhead),
               "per_event": float(per_event), "step_overhead": float(step_overhead),
               "lookahead": lookahead, "lock": key}
        if schedule:
            res["start"] = starts
        return res

    def calibrate(self, key, measured_seconds, threads=2, policy="exact", lookahead=8,
                  rtol=1e-4, fit="overhead", step_overhead=0.0, max_iter=100):
        """See ``calibrate``."""
        measured = float(measured_seconds)
        if not (measured > 0 and math.isfinite(measured)):
            raise ValueError(f"measured_seconds must be a finite number > 0, got {measured!r}")
        if fit not in FITS:
            raise ValueError(f"fit must be one of {FITS}, got {fit!r}")

        def t(x):
            kw = {"overhead": x} if fit == "overhead" else {"per_event": x}
            return self.replay(key, threads, policy, lookahead=lookahead,
                               step_overhead=step_overhead, **kw)["time"]

        m = self.events
        if m == 0:
            raise ValueError("the trace has no events: nothing to calibrate on")
        if t(0.0) >= measured:
            return 0.0  # the run was no slower than contention-free locking allows
        # A step of k events lasts at least k * overhead (claims are serialized), and
        # at least per_event * k / P: either way hi below gives a replay >= measured.
        lo, hi = 0.0, measured / m * (1 if fit == "overhead" else threads)
        for _ in range(max_iter):
            mid = 0.5 * (lo + hi)
            tm = t(mid)
            if abs(tm - measured) <= rtol * measured:
                return mid
            if tm < measured:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


def _prepared(trace):
    return trace if isinstance(trace, ReplayTrace) else ReplayTrace(trace)


def replay(trace, lock_key, threads, policy="exact", overhead=0.0, lookahead=8, schedule=False,
           per_event=0.0, step_overhead=0.0):
    """Replay a recorded trace on ``threads`` virtual threads (see the module docstring).

    trace: the dict of ``Engine.trace()`` or a ``ReplayTrace`` (prepare once
    when replaying the same trace many times).
    lock_key: ("graph", SCALE), ("grid", None), ("grid3d", None) or "grid".
    policy: "exact" (regions at lock-graph distance >= 3) or "paper" (>= 2).
    overhead: s a claim holds the global queue lock (claims are serialized).
    lookahead: how many blocked ready events a thread may pass over.
    schedule: also return "start", per step an (m,) array of event start times
    (s from the step start, after the claim).
    per_event: s added to every event's cost, on its own thread (not serialized):
    the other bound on where per-event overhead goes.
    step_overhead: s added to every step (starting and joining the threads).

    Returns a dict: "time" (s, sum of the step times), "step_times" (s, per
    step: when its last event finished, plus step_overhead), "concurrency"
    (summed event costs / time), "blocked" (picks whose earliest ready event
    was blocked), "passed" (blocked events passed over by successful picks),
    "stalls" (picks that found nothing clear: the idle threads then wait),
    "events", "work" (summed costs, s) and the inputs.
    """
    return _prepared(trace).replay(lock_key, threads, policy, overhead, lookahead, schedule,
                                   per_event, step_overhead)


def calibrate(trace, lock_key, measured_seconds, threads=2, policy="exact", lookahead=8,
              rtol=1e-4, fit="overhead", step_overhead=0.0):
    """The per-claim overhead (s) that makes the replay on ``threads`` threads last
    ``measured_seconds``, by bisection (to ``rtol`` of the measured time).

    ``measured_seconds`` must be the events phase of the measured run over the
    same steps as the trace (see the module docstring).  ``fit="per_event"``
    fits ``per_event`` (unserialized, see ``replay``) instead of the serialized
    ``overhead``; ``step_overhead`` is passed to every replay.  Returns 0.0 if
    even zero gives a replay at least as long as the measured time (the model
    cannot go lower); raises ValueError for a trace without events.
    """
    return _prepared(trace).calibrate(lock_key, measured_seconds, threads, policy, lookahead,
                                      rtol, fit, step_overhead)
