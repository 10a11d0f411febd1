"""Ideal band schedules: how fast could a domain split run a recorded trace?

The bound behind issue 3's bed: a recorded sequential trace (``Engine(...,
trace_locks=...)``, see ``Engine.trace``) is re-played on T virtual threads,
one per domain, under the *particle-band* rule with every coordination cost
set to zero.  This is an upper bound for any engine that splits the step's
particles into domains and keeps the sequential order by waiting only at a
band about the cuts (the branch ``particle-band`` built one; see the README's
Threads section).

Model, per step:

* **Domains** are given per particle; an event belongs to the domain of its
  first particle (the one whose queue slot holds it).
* **Levels** (``particle_levels``): 1 for a particle with a candidate in
  another domain, l + 1 for one next to level l, up to ``levels``; free
  beyond.  An event is a *band* event when one of its particles is not free.
* **Order key**: the trace's position (the sequential engine processes in
  (time, key) order, so position is that order with ties broken).
* **Band rule**: a thread runs its domain's events in key order; a band event
  e starts only once every other domain has *finished* all its events with
  keys before e (its clock is past e).  Free events start when their thread
  is free.  With ``runahead`` a thread whose next band event must wait may
  run its later free events meanwhile (or those of them marked ``ahead``);
  a band event still waits for its own domain's earlier events.  Events run
  ahead can clash with the sequential order; ``order_conflicts`` counts the
  events of a schedule that did.
* **Cost**: an event costs what it cost in the sequential run (its traced
  cycles: advance, resolve, predict again; the queue update is not inside),
  plus ``sync`` seconds for a band event (handing a clock from core to core).

Nothing else a step does (tree, search, first predictions) is modelled.

**More domains than threads** (``pool_schedule``): the step's particles are
cut into K domains and T < K threads take whichever domain can go on.  Each
domain runs its events one at a time in key order; an event waits only for
the domains within ``levels`` candidate hops of its particles
(``domain_masks``, ``event_waits``), not for all of them: there, until no
event of theirs with a smaller key is pending or running.  With ``creator``
an event exists only once the event that last wrote one of its particles
(``creators``) has finished, as in an engine whose threads see each other's
queues: a domain then runs its earliest event that exists, and waits only for
neighbours' events that exist (``order_conflicts`` counts what that let
through).  Two hops suffice for the sequential order: two events that share a
particle, one writing it, have particles within two hops of each other (an
event writes its own particles and reads their candidates).  An engine that
knows only lock regions waits by region instead (``region_waits``: the
domains within two lock-graph hops of the event's regions): coarser, so
more events wait.
"""
import heapq

import numpy as np

from .replay import _dependencies

__all__ = ["particle_levels", "event_domains", "band_schedule", "order_conflicts",
           "domain_masks", "region_waits", "event_waits", "creators", "pool_schedule"]

# domains a wait mask (uint64) can name
MAX_DOMAINS = 64


def particle_levels(noff, nent, domain, levels):
    """Level of each particle (N,) int64: 1 with a candidate in another domain,
    l + 1 next to level l (up to ``levels``), ``levels + 1`` (free) beyond.

    noff: (N + 1,) CSR offsets and nent: (noff[-1],) candidate indices, the
    step's candidate lists (in the same indexing as ``domain``, (N,) ints).
    """
    noff = np.asarray(noff, np.int64)
    nent = np.asarray(nent, np.int64)
    domain = np.asarray(domain)
    n = domain.shape[0]
    if noff.shape != (n + 1,) or nent.shape[0] != noff[-1]:
        raise ValueError(f"noff must have shape ({n + 1},) and nent noff[-1] entries")
    if levels < 1:
        raise ValueError(f"levels must be >= 1, got {levels}")
    owner = np.repeat(np.arange(n), np.diff(noff))
    free = levels + 1
    lvl = np.full(n, free, np.int64)
    lvl[owner[domain[owner] != domain[nent]]] = 1
    for level in range(2, levels + 1):
        nxt = (lvl[nent] == level - 1) & (lvl[owner] == free)
        lvl[owner[nxt]] = level
    return lvl


def event_domains(ev_i, ev_j, domain, lvl, levels):
    """(domain of each event, band flag of each event) for events of particles
    ev_i and ev_j (ev_j < 0: a wall)."""
    ev_i = np.asarray(ev_i, np.int64)
    ev_j = np.asarray(ev_j, np.int64)
    free = levels + 1
    has_j = ev_j >= 0
    jj = np.where(has_j, ev_j, 0)
    band = (lvl[ev_i] != free) | (has_j & (lvl[jj] != free))
    return np.asarray(domain)[ev_i], band


def band_schedule(ev_domain, band, cost, runahead=False, sync=0.0, finish=False, ahead=None):
    """Makespan (s) of the trace's events on one virtual thread per domain.

    ev_domain: (E,) domain of each event, band: (E,) bool, cost: (E,) seconds,
    all in key (trace) order.  Returns (makespan, per-domain busy seconds),
    and with ``finish`` also each event's finish and start times (E,) each
    (the start as scheduled: the finish less the cost need not round back to
    it, and an order check needs it exactly).  ``ahead`` (E,) bool, with
    ``runahead``: the events that may run ahead of a waiting band event (free
    ones only; default all free events); the other free events keep their
    place in key order among the band events.
    """
    ev_domain = np.asarray(ev_domain, np.int64)
    band = np.asarray(band, bool)
    cost = np.asarray(cost, np.float64) + np.where(band, float(sync), 0.0)
    ndom = int(ev_domain.max()) + 1 if ev_domain.size else 1
    lists = [np.flatnonzero(ev_domain == d) for d in range(ndom)]
    fin = np.zeros(cost.shape[0])
    sta = np.zeros(cost.shape[0])
    ready = [0.0] * ndom
    # per domain: its events' finish times in key order, prefix maxima filled
    # lazily (only over events already finished)
    pmax = [np.zeros(len(lists[d])) for d in range(ndom)]
    filled = [0] * ndom

    def finished_before(o, e):
        """The latest finish among domain o's events with key < e."""
        k = int(np.searchsorted(lists[o], e))
        while filled[o] < k:
            m = filled[o]
            f = fin[lists[o][m]]
            pmax[o][m] = f if m == 0 else max(pmax[o][m - 1], f)
            filled[o] = m + 1
        return pmax[o][k - 1] if k > 0 else 0.0

    if not runahead:
        ptr = [0] * ndom

        def done_before(o, e):
            return ptr[o] >= int(np.searchsorted(lists[o], e))
    else:
        deep = ~band if ahead is None else np.asarray(ahead, bool) & ~band
        free_l = [lst[deep[lst]] for lst in lists]
        band_l = [lst[~deep[lst]] for lst in lists]
        fp = [0] * ndom
        bp = [0] * ndom

        def done_before(o, e):
            return (fp[o] >= int(np.searchsorted(free_l[o], e))
                    and bp[o] >= int(np.searchsorted(band_l[o], e)))

    def blockers(d, e):
        """(all other domains' events with key < e simulated?, their latest
        finish, earliest ready time of a domain still holding one)."""
        latest, pending = 0.0, np.inf
        for o in range(ndom):
            if o != d:
                if done_before(o, e):
                    latest = max(latest, finished_before(o, e))
                else:
                    pending = min(pending, ready[o])
        return pending == np.inf, latest, pending

    def run(d, e, start):
        sta[e] = start
        fin[e] = start + cost[e]
        ready[d] = fin[e]

    def advance(d):
        """Start domain d's next event if that can be decided now; True if done."""
        if not runahead:
            e = lists[d][ptr[d]]
            start = ready[d]
            if band[e]:
                ok, latest, _ = blockers(d, e)
                if not ok:
                    return False
                start = max(start, latest)
            run(d, e, start)
            ptr[d] += 1
            return True
        has_free = fp[d] < len(free_l[d])
        if bp[d] < len(band_l[d]):
            e = band_l[d][bp[d]]
            if not (has_free and free_l[d][fp[d]] < e):
                if not band[e]:  # a free event that may not run ahead: in order
                    run(d, e, ready[d])
                    bp[d] += 1
                    return True
                ok, latest, pending = blockers(d, e)
                if ok and (latest <= ready[d] or not has_free):
                    run(d, e, max(ready[d], latest))
                    bp[d] += 1
                    return True
                # waiting for a finish after ready[d] (a known one, or an event
                # not yet started by a domain that is not behind this one):
                # run a free event meanwhile; otherwise undecided for now
                if not has_free or (not ok and pending < ready[d]):
                    return False
        e = free_l[d][fp[d]]
        run(d, e, ready[d])
        fp[d] += 1
        return True

    def has_work(d):
        if not runahead:
            return ptr[d] < len(lists[d])
        return fp[d] < len(free_l[d]) or bp[d] < len(band_l[d])

    remaining = cost.shape[0]
    while remaining:
        # the domains in order of ready time: the first that can start an
        # event does (the event with the least key can always start)
        for d in sorted((d for d in range(ndom) if has_work(d)), key=lambda d: ready[d]):
            if advance(d):
                remaining -= 1
                break
        else:
            raise RuntimeError("band_schedule: no event can start")
    busy = np.array([cost[lst].sum() for lst in lists])
    span = max(ready) if cost.shape[0] else 0.0
    return (span, busy, fin, sta) if finish else (span, busy)


def order_conflicts(ev_i, ev_j, ev_kind, noff, nent, start, fin):
    """Events a schedule ran against the sequential order: the number of events
    that write a particle while another event touching it (reading or
    writing) and earlier in key order had not finished, or later in key order
    had started.

    Reads and writes as the engine makes them: a pair collision (kind 0)
    writes i and j, a wall collision (1) and a stale event (2: only i is
    predicted again) write i; an event reads what it writes, j for a stale
    event, and the candidates of every particle it writes (predicting again).
    ev_*: (E,) in key order (particle indices as in ``noff``/``nent``, the
    step's candidate lists); start, fin: (E,) seconds.  Pairs added to the
    lists during the step are not in ``noff``/``nent`` and not counted.
    """
    ev_i = np.asarray(ev_i, np.int64)
    ev_j = np.asarray(ev_j, np.int64)
    kind = np.asarray(ev_kind, np.int64)
    noff = np.asarray(noff, np.int64)
    nent = np.asarray(nent, np.int64)
    e_all = ev_i.shape[0]
    if e_all == 0:
        return 0
    ev = np.arange(e_all)
    pair = (kind == 0) & (ev_j >= 0)
    # the written particles: (event, particle)
    w_ev = np.concatenate([ev, ev[pair]])
    w_p = np.concatenate([ev_i, ev_j[pair]])
    # touches: writes, a stale event's partner, and the candidates of writes
    cnt = noff[w_p + 1] - noff[w_p]
    c_ev = np.repeat(w_ev, cnt)
    starts = np.repeat(noff[w_p], cnt)
    c_p = nent[starts + (np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt))]
    stale = (kind == 2) & (ev_j >= 0)
    t_ev = np.concatenate([w_ev, ev[stale], c_ev])
    t_p = np.concatenate([w_p, ev_j[stale], c_p])
    t_w = np.concatenate([np.ones(w_ev.shape[0], bool), np.zeros(int(stale.sum()) + c_ev.shape[0],
                                                                 bool)])
    # one touch per (particle, event), a write if any of its touches is one
    o = np.lexsort((~t_w, t_ev, t_p))
    t_p, t_ev, t_w = t_p[o], t_ev[o], t_w[o]
    first = np.ones(t_p.shape[0], bool)
    first[1:] = (t_p[1:] != t_p[:-1]) | (t_ev[1:] != t_ev[:-1])
    t_p, t_ev, t_w = t_p[first], t_ev[first], t_w[first]
    st = np.asarray(start, np.float64)[t_ev]
    fn = np.asarray(fin, np.float64)[t_ev]
    bad = np.zeros(e_all, bool)
    bounds = np.flatnonzero(np.r_[True, t_p[1:] != t_p[:-1], True])
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a < 2 or not t_w[a:b].any():
            continue
        s_, f_ = st[a:b], fn[a:b]
        # latest finish of the earlier touches, earliest start of the later ones
        before = np.maximum.accumulate(np.r_[-np.inf, f_[:-1]])
        after = np.minimum.accumulate(np.r_[s_[1:], np.inf][::-1])[::-1]
        w = t_w[a:b]
        hit = w & ((before > s_) | (after < f_))
        bad[t_ev[a:b][hit]] = True
    return int(bad.sum())


def domain_masks(noff, nent, domain, levels):
    """(N,) uint64: bit d set for each domain d with a particle within
    ``levels`` candidate hops of the particle (its own domain included).

    noff, nent: the step's candidate lists (CSR); domain: (N,) ints < 64.
    """
    domain = _check_domains(domain)
    n = domain.shape[0]
    noff = np.asarray(noff, np.int64)
    if noff.shape != (n + 1,):
        raise ValueError(f"noff must have shape ({n + 1},) and nent noff[-1] entries")
    return _spread(noff, nent, np.left_shift(np.uint64(1), domain.astype(np.uint64)), levels)


def region_waits(ev_i, ev_j, domain, region, loff, ladj, hops=2):
    """``event_waits`` with the waits by lock region, as an engine that knows
    only its regions would wait: for the other domains with a particle in a
    region within ``hops`` lock-graph hops of either particle's region.

    region: (N,) the region of each particle; loff (R + 1,), ladj: the lock
    graph (CSR)."""
    domain = _check_domains(domain)
    region = np.asarray(region, np.int64)
    loff = np.asarray(loff, np.int64)
    if region.shape != domain.shape or (region.size and not 0 <= region.min() <= region.max()
                                        < loff.shape[0] - 1):
        raise ValueError("region must give each particle a region of the lock graph")
    own = np.zeros(loff.shape[0] - 1, np.uint64)
    np.bitwise_or.at(own, region, np.left_shift(np.uint64(1), domain.astype(np.uint64)))
    return event_waits(ev_i, ev_j, domain, _spread(loff, ladj, own, hops)[region])


def _check_domains(domain):
    domain = np.asarray(domain, np.int64)
    if domain.size and not 0 <= domain.min() <= domain.max() < MAX_DOMAINS:
        raise ValueError(f"domains must be 0..{MAX_DOMAINS - 1}")
    return domain


def _spread(off, ent, mask, hops):
    """mask OR-ed over ``hops`` hops of the graph (CSR off, ent)."""
    off = np.asarray(off, np.int64)
    ent = np.asarray(ent, np.int64)
    if ent.shape[0] != off[-1]:
        raise ValueError("the graph's entries must number its offsets' last")
    if hops < 0:
        raise ValueError(f"levels (hops) must be >= 0, got {hops}")
    owner = np.repeat(np.arange(off.shape[0] - 1), np.diff(off))
    for _ in range(hops):
        grown = mask.copy()
        np.bitwise_or.at(grown, owner, mask[ent])
        mask = grown
    return mask


def event_waits(ev_i, ev_j, domain, masks):
    """(domain of each event, its wait mask): the other domains within reach
    of either particle (``masks`` from ``domain_masks``; ev_j < 0: a wall)."""
    ev_i = np.asarray(ev_i, np.int64)
    ev_j = np.asarray(ev_j, np.int64)
    edom = np.asarray(domain, np.int64)[ev_i]
    wait = masks[ev_i] | np.where(ev_j >= 0, masks[np.maximum(ev_j, 0)], np.uint64(0))
    return edom, wait & ~np.left_shift(np.uint64(1), edom.astype(np.uint64))


def creators(ev_i, ev_j, ev_kind):
    """(E,) for each event the latest earlier event that wrote one of its
    particles (a pair collision, kind 0, writes i and j; the others i), -1
    for none: the event that predicted it (or one before; -1: the step's
    first predictions).  The later of its two parents under ``replay``'s
    "writers" rule."""
    ev_i = np.ascontiguousarray(ev_i, np.int64)
    ev_j = np.ascontiguousarray(ev_j, np.int64)
    m = ev_i.shape[0]
    if m == 0:
        return np.zeros(0, np.int64)
    parents = np.zeros((m, 2), np.int64)
    _dependencies(ev_i, ev_j, np.ascontiguousarray(ev_kind, np.int64), False,
                  np.zeros(int(max(ev_i.max(), ev_j.max())) + 1, np.int64), parents,
                  np.zeros(m, np.int64), np.zeros(m + 1, np.int64), np.zeros(2 * m, np.int64))
    return parents.max(axis=1)


def pool_schedule(ev_domain, wait, cost, threads, creator=None, sync=0.0, fixed=False):
    """(makespan, start (E,), finish (E,)) of the events on ``threads``
    virtual threads shared by the domains (with ``fixed``, thread k runs
    only domains k, k + T, ...).

    ev_domain: (E,) domain of each event, wait: (E,) uint64 mask of the
    domains it waits for, cost: (E,) seconds (plus ``sync`` when it waits
    for any), all in key order.  A thread that is free takes, among the
    domains running nothing, the one whose next event has the least key and
    may start; a domain's next event is its earliest that exists (with
    ``creator`` (E,): once its creator has finished, -1 from the start;
    without, every event from the start); it may start when every domain of
    its mask has no existing event with a smaller key unfinished.
    """
    ev_domain = np.asarray(ev_domain, np.int64)
    wait = np.asarray(wait, np.uint64)
    cost = np.asarray(cost, np.float64) + np.where(wait != 0, float(sync), 0.0)
    e_all = cost.shape[0]
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    cr = np.full(e_all, -1, np.int64) if creator is None else np.asarray(creator, np.int64)
    if cr.shape != (e_all,) or (cr >= np.arange(e_all)).any():
        raise ValueError("creator must give (E,) events each before its own")
    ndom = int(ev_domain.max()) + 1 if e_all else 0
    lists = [np.flatnonzero(ev_domain == d) for d in range(ndom)]
    fin = np.full(e_all, np.inf)
    sta = np.full(e_all, np.inf)
    started = np.zeros(e_all, bool)
    base = [0] * ndom  # every event of lists[d][:base[d]] has started
    running = [False] * ndom
    chunk = 4096

    def exists(idx, t):
        c = cr[idx]
        return (c < 0) | (fin[np.maximum(c, 0)] <= t)

    def next_of(d, t):
        lst = lists[d]
        b = base[d]
        while b < len(lst) and started[lst[b]]:
            b += 1
        base[d] = b
        while b < len(lst):
            seg = lst[b:b + chunk]
            k = np.flatnonzero(~started[seg] & exists(seg, t))
            if k.size:
                return int(seg[k[0]])
            b += chunk
        return -1

    def may_start(e, d, t):
        w = int(wait[e])
        for o in range(ndom):
            if o != d and (w >> o) & 1:
                seg = lists[o][base[o]:int(np.searchsorted(lists[o], e))]
                if seg.size == 0:
                    continue
                done = started[seg]
                if (~done & exists(seg, t)).any() or (fin[seg[done]] > t).any():
                    return False
        return True

    t = 0.0
    idle = list(range(threads))
    heap = []
    left = e_all
    while left:
        while idle:
            # the least-key event that may start on an idle thread (any one,
            # unless fixed: then the thread its domain belongs to)
            best_k, best_d, best_e = -1, -1, -1
            for k in (idle if fixed else idle[:1]):
                for d in range(k if fixed else 0, ndom, threads if fixed else 1):
                    if running[d]:
                        continue
                    e = next_of(d, t)
                    if e >= 0 and (best_e < 0 or e < best_e) and may_start(e, d, t):
                        best_k, best_d, best_e = k, d, e
            if best_e < 0:
                break
            sta[best_e] = t
            fin[best_e] = t + cost[best_e]
            started[best_e] = True
            running[best_d] = True
            idle.remove(best_k)
            left -= 1
            heapq.heappush(heap, (fin[best_e], best_d, best_k))
        if not heap:
            raise RuntimeError("pool_schedule: no event can start")
        t, d, k = heapq.heappop(heap)
        running[d] = False
        idle.append(k)
        while heap and heap[0][0] <= t:
            _, d, k = heapq.heappop(heap)
            running[d] = False
            idle.append(k)
    return (float(fin.max()) if e_all else 0.0), sta, fin
