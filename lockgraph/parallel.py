"""Threaded event processing: spatial domains, lock regions, verified causality.

T Python threads each call ``worker`` once per step; the kernel runs without
the GIL and processes events until the step is done (whole runs of events per
call).  Particles are stored in kD-tree order, so the tree's top splits cut the
slot range into T *domains* — spatial blocks.  Thread d owns domain d: its own
time-ordered queue (a tournament over its slots), its own lock.

Every event's lock regions (those of its two particles, from the lock graph or
the grid) are classified with ``bd``, the lock-graph distance to the nearest
region of another domain (0 for a region mixing domains):

* **interior** events (both regions in d, ``bd >= 4``): nothing any other
  thread does can reach what they read or write — other threads' events stay
  at distance >= 3 — so they run with no global lock at all;
* **boundary** events take the global lock ``G``, run only in global time order
  (not later than any other domain's next event: ``clock``) and only at
  lock-graph distance >= 3 from every other boundary event in flight (the
  paper's rule, free lock regions around the event, extended by one ring:
  ``held`` / ``near`` counters).

Interior events may run ahead of the other domains by at most ``window`` (s).

**Causality.**  Two events can interact only if their regions are within
distance one.  Each region keeps ``ts``, the latest time of an event that had
it as its own.  An event that is late (earlier than an event already processed
nearby: earlier than its domain's latest, or any boundary event) is checked:
a later time on its regions or their neighbours is a causality violation.
Under the exact policy the step then stops and is redone sequentially (a
repair); under the paper policy (distance >= 2, no time order, no window) it is
only counted.  A widened reach joining non-adjacent regions is a violation
too.  Without violations every event reads and writes exactly what it would in
the sequential engine, so the state is bitwise the sequential one.

A domain's clock is the time of the earliest event in its queue.  A boundary
event is taken out of the queue while it runs (so the clock moves on and other
boundary events may run beside it); an interior event stays in until it is
done, which holds the clock back for one event and spares a queue update.

Shared words: ``ctrl`` (G, ABORT, STATUS: one cache line each) and ``dctl``
(per domain: its lock; on a second line its clock; on a third the in-flight
flag and the progress count).
"""
import functools
import time

import numpy as np

from ._jit import kernel
from .atomics import bits_float, cpu_relax, cycles, float_bits, load, sched_yield, sleep_us
from .atomics import spin_lock, spin_unlock, store, cas
from .events import update_queue
from .predict import INF
from .kernels import (I_PAPER, NEED_JOURNAL, NEED_LOG, OK, P_DT, S_BLOCKED, S_CLAIMS, S_CONC,
                      S_VIOL, S_WAIT, STALL, VIOLATION, process_event)
from .neighbors import JCOUNT, LCOUNT

G, ABORT, STATUS = 0, 8, 16
JITTER = 17  # tests: a nonzero seed makes the workers pause at random (fault injection)
NCTRL = 24
# per-domain row of dctl: the lock, the clock (read by the other threads at
# every boundary event) and what only termination and stall checks read (in
# flight, progress) on three cache lines, so that a thread polling the clock
# does not make each of the owner's other stores a miss
DLOCK, DCLOCK, DINFL, DPROG = 0, 8, 16, 17
NDCTL = 32
# Regions this far (in lock-graph hops) from any other domain's are interior.  A
# boundary event's regions are at most one hop across the cut (its particles may
# meet), so 4 keeps every interior event >= 3 hops from every other thread's
# events: not even their next events can reach each other.
INTERIOR = 4
# a thread blocked for PARK_AFTER consecutive picks (~0.3-1 ms of yielding)
# sleeps PARK_US per further pick instead of yielding
PARK_AFTER = 2000
PARK_US = 50


@kernel
def _cycles_now():
    return cycles()


@functools.lru_cache(maxsize=None)
def cycles_per_second():
    """Calibrate the cycle counter against the wall clock (once per process)."""
    c0, t0 = _cycles_now(), time.perf_counter()
    time.sleep(0.05)
    c1, t1 = _cycles_now(), time.perf_counter()
    return (c1 - c0) / (t1 - t0)


@kernel
def classify_regions(lock_of, loff, ladj, dlo, dhi, dom, bd, queue, cap):
    """dom[r]: the domain of region r's particles (-1 if they span several, -2
    if it has none); bd[r]: lock-graph distance from r to the nearest region of
    another domain (0 for a mixed region; empty regions belong to no domain but
    paths run through them), by breadth-first search, capped at ``cap``: the
    search stops there, so it visits only the regions near the cuts.
    Returns the number of particles in regions at distance >= cap."""
    nreg = dom.shape[0]
    ndom = dlo.shape[0]
    for r in range(nreg):
        dom[r] = -2
        bd[r] = cap
    for d in range(ndom):
        for s in range(dlo[d], dhi[d]):
            r = lock_of[s]
            if dom[r] == -2:
                dom[r] = d
            elif dom[r] != d:
                dom[r] = -1
    head = 0
    tail = 0
    # the queue in order of distance (each region enters it once): mixed regions,
    # then those next to another domain's, then the search's
    for r in range(nreg):
        if dom[r] == -1:
            bd[r] = 0
            queue[tail] = r
            tail += 1
    for r in range(nreg):
        if dom[r] < 0:
            continue  # mixed: done; empty: no events of its own, the search passes through
        for k in range(loff[r], loff[r + 1]):
            y = dom[ladj[k]]
            if y != -2 and y != dom[r]:
                bd[r] = 1
                queue[tail] = r
                tail += 1
                break
    while head < tail:
        r = queue[head]
        head += 1
        if bd[r] + 1 >= cap:
            continue
        for k in range(loff[r], loff[r + 1]):
            x = ladj[k]
            if bd[x] > bd[r] + 1:
                bd[x] = bd[r] + 1
                queue[tail] = x
                tail += 1
    far = 0
    for s in range(lock_of.shape[0]):
        if bd[lock_of[s]] >= cap:
            far += 1
    return far


@kernel(inline=True)
def _clear(held, near, loff, ladj, a, far):
    """Region a at lock-graph distance >= 2 (far: >= 3) from every busy region?

    ``held[x]`` counts boundary events in flight owning region x, ``near[x]``
    those with x in the closed neighbourhood of one of their regions.
    """
    c = near if far else held
    if c[a] != 0:
        return False
    for k in range(loff[a], loff[a + 1]):
        if c[ladj[k]] != 0:
            return False
    return True


@kernel(inline=True)
def _busy(held, near, loff, ladj, a, d):
    held[a] += d
    near[a] += d
    for k in range(loff[a], loff[a + 1]):
        near[ladj[k]] += d


@kernel(inline=True)
def _busy_pair(held, near, loff, ladj, a1, a2, d):
    _busy(held, near, loff, ladj, a1, d)
    if a2 != a1:
        _busy(held, near, loff, ladj, a2, d)


@kernel(inline=True)
def _touched_later(ts, loff, ladj, a, tb):
    """Did an event later than tb have region a or a neighbour of a as its own?"""
    if ts[a] > tb:
        return True
    for k in range(loff[a], loff[a + 1]):
        if ts[ladj[k]] > tb:
            return True
    return False


@kernel(inline=True)
def _fail(ctrl, status):
    cas(ctrl, STATUS, OK, status)
    store(ctrl, ABORT, 1)


@kernel(inline=True)
def _publish(dctl, d, tour_t, tour_s):
    """Publish domain d's clock: the time of its next event (its queue's root)."""
    t = tour_t[1] if tour_s[1] >= 0 else INF
    store(dctl, d * NDCTL + DCLOCK, float_bits(t))


@kernel(inline=True)
def _others_clock(dctl, d, ndom):
    """The earliest next event of the other domains (bits of a float)."""
    m = float_bits(INF)
    for e in range(ndom):
        if e != d:
            c = load(dctl, e * NDCTL + DCLOCK)
            if c < m:
                m = c
    return m


@kernel(inline=True)
def _all_done(dctl, ndom, dtb):
    for e in range(ndom):
        if load(dctl, e * NDCTL + DCLOCK) < dtb:
            return False
        if load(dctl, e * NDCTL + DINFL) != 0:
            return False
    return True


@kernel(inline=True)
def _domain_of(dlo, x):
    d = dlo.shape[0] - 1
    while d > 0 and x < dlo[d]:
        d -= 1
    return d


@kernel(inline=True)
def _progress(dctl, ndom):
    """Events completed so far by all domains."""
    prog = 0
    for e in range(ndom):
        prog += load(dctl, e * NDCTL + DPROG)
    return prog


@kernel(inline=True)
def _all_idle(dctl, ndom):
    for e in range(ndom):
        if load(dctl, e * NDCTL + DINFL) != 0:
            return False
    return True


@kernel(inline=True)
def _pause(rng):
    """Fault injection for tests: one time in 8 spin for up to 2^16 cycles
    (~20 us, tens of events' worth; a pseudo-random length from the xorshift
    state rng); returns the next state."""
    rng ^= (rng << 13) & 0x7FFFFFFFFFFFFFFF
    rng ^= rng >> 7
    rng ^= (rng << 17) & 0x7FFFFFFFFFFFFFFF
    rng &= 0x7FFFFFFFFFFFFFFF
    if rng & 7 == 0:
        n = (rng >> 12) & 0xFFFF
        c = cycles()
        while cycles() - c < n:
            cpu_relax()
    return rng


@kernel
def worker(d, parts, step, tree, nbrs, evq, jour, cfg, st, locks, lstate, doms, ctrl, dctl,
           window, stall_cycles):
    """Thread d's share of a step: the events of domain d.  Returns its final status.

    ``lstate = (ts, held, near)`` per region; ``doms = (dom, bd, dlo, dhi,
    dtour_t, dtour_s)``: the regions' classification, the domains' slot
    ranges and their queues (row d is domain d's tournament).
    """
    ids = parts[7]
    ctr = nbrs[5]
    evt, evp, evc, tour_t_, tour_s_, hidden = evq
    jslot = jour[0]
    logt = jour[3]
    par = cfg[0]
    ipar = cfg[1]
    dt = par[P_DT]
    dtb = float_bits(dt)
    paper = ipar[I_PAPER] != 0
    far = not paper
    lock_of, loff, ladj = locks
    ts, held, near = lstate
    dom, bd, dlo, dhi, dtour_t, dtour_s = doms
    ndom = dlo.shape[0]
    lo = dlo[d]
    hi = dhi[d]
    tt = dtour_t[d]
    tsl = dtour_s[d]
    myl = d * NDCTL + DLOCK
    high = 0  # latest event time processed in this domain (bits)
    oclock = -INF  # the other domains' clock when last looked at
    waiting = False
    nblk = 0  # consecutive blocked picks of this thread
    wait_from = 0  # when this thread last saw progress while blocked (cycles)
    checked = 0  # when it last looked
    seen = -1
    rng = load(ctrl, JITTER) * (2 * d + 1)
    while True:
        if load(ctrl, ABORT) != 0:
            return OK
        # room in the journal and the log for one more event of every domain
        if ctr[JCOUNT] + 2 * ndom + 2 > jslot.shape[0] or (
                logt.shape[0] > 0 and ctr[LCOUNT] + ndom + 1 > logt.shape[0]):
            if _all_idle(dctl, ndom):
                _fail(ctrl, NEED_JOURNAL if ctr[JCOUNT] + 2 * ndom + 2 > jslot.shape[0]
                      else NEED_LOG)
                return OK
            go = False
        else:
            go = True
        spin_lock(dctl, myl)
        i = tsl[1]
        empty = i < 0 or not tt[1] < dt
        blocked = True
        boundary = False
        if go and not empty:
            t = tt[1]
            tb = float_bits(t)
            p = evp[i]
            j = p >> 5 if p >= 0 else -1
            a1 = lock_of[i]
            a2 = lock_of[j] if j >= 0 else a1
            if dom[a1] == d and dom[a2] == d and bd[a1] >= INTERIOR and bd[a2] >= INTERIOR:
                # the window bounds how far ahead interior events run (late events
                # nearby are checked whatever it is): an old reading of the others'
                # clocks will do until t passes it, which saves loading their lines
                if not paper and t > oclock + window:
                    oclock = bits_float(_others_clock(dctl, d, ndom))
                if paper or t <= oclock + window:
                    # not taken out of the queue (as boundary events are): the
                    # domain's clock stays t until the commit, which only holds
                    # back the others' boundary events later than t for one
                    # event, and saves a climb of the tournament
                    blocked = False
                    store(dctl, d * NDCTL + DINFL, 1)
            else:
                # a boundary event: look before taking the global lock
                boundary = paper or tb <= _others_clock(dctl, d, ndom)
        spin_unlock(dctl, myl)
        if boundary:
            blocked = True
            spin_lock(ctrl, G)
            spin_lock(dctl, myl)
            # under G nobody else changes this queue: look at its root again
            i = tsl[1]
            empty = i < 0 or not tt[1] < dt
            if not empty:
                t = tt[1]
                tb = float_bits(t)
                p = evp[i]
                j = p >> 5 if p >= 0 else -1
                a1 = lock_of[i]
                a2 = lock_of[j] if j >= 0 else a1
                ordered = paper or tb <= _others_clock(dctl, d, ndom)
                if ordered and _clear(held, near, loff, ladj, a1, far) and \
                        _clear(held, near, loff, ladj, a2, far):
                    blocked = False
                    _busy_pair(held, near, loff, ladj, a1, a2, 1)
                    hidden[i] = 1
                    update_queue(tt, tsl, evt, ids, hidden, lo, hi, i)
                    store(dctl, d * NDCTL + DINFL, 1)
                    _publish(dctl, d, tt, tsl)
            spin_unlock(dctl, myl)
            spin_unlock(ctrl, G)
        if blocked:
            if empty and _all_done(dctl, ndom, dtb):
                return OK
            if not empty:
                st[S_BLOCKED] += 1
            now = cycles()
            # progress is looked at when a wait begins and then every eighth of
            # stall_cycles (reading it at every pick would pull the line the
            # working threads write at every event): a stall is reported after
            # 1 to 1.125 stall_cycles without progress
            if not waiting:
                waiting = True
                wait_from = now
                checked = now
                seen = _progress(dctl, ndom)
            elif now - checked > stall_cycles >> 3:
                checked = now
                prog = _progress(dctl, ndom)
                if prog != seen:
                    seen = prog
                    wait_from = now
                elif now - wait_from > stall_cycles:
                    _fail(ctrl, STALL)
                    return STALL
            nblk += 1
            if nblk < PARK_AFTER:
                cpu_relax()
                sched_yield()
            else:
                # blocked this long: the threads it waits for may share its core
                # (more threads than free cores); sleeping lets them run
                sleep_us(PARK_US)
            st[S_WAIT] += cycles() - now
            continue
        waiting = False
        nblk = 0
        if rng != 0:  # holding the event's regions: the others run on meanwhile
            rng = _pause(rng)
        c0 = cycles()
        status = OK
        jw = -1
        # causality: an event later than one processed nearby is checked
        if (boundary or tb < high) and (_touched_later(ts, loff, ladj, a1, tb)
                                        or _touched_later(ts, loff, ladj, a2, tb)):
            st[S_VIOL] += 1
            if not paper:
                status = VIOLATION
        if status == OK:
            status, jw = process_event(i, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks)
        if ts[a1] < tb:
            ts[a1] = tb
        if ts[a2] < tb:
            ts[a2] = tb
        if tb > high:
            high = tb
        st[S_CONC] += cycles() - c0
        st[S_CLAIMS] += 1
        if rng != 0:
            rng = _pause(rng)
        # commit: the queues of the slots whose events changed
        if boundary:
            spin_lock(ctrl, G)
        spin_lock(dctl, myl)
        hidden[i] = 0
        update_queue(tt, tsl, evt, ids, hidden, lo, hi, i)
        if jw >= 0:
            e = _domain_of(dlo, jw)
            if e == d:
                update_queue(tt, tsl, evt, ids, hidden, lo, hi, jw)
            else:  # a partner across the cut: its domain's queue, under its lock
                spin_lock(dctl, e * NDCTL + DLOCK)
                update_queue(dtour_t[e], dtour_s[e], evt, ids, hidden, dlo[e], dhi[e], jw)
                _publish(dctl, e, dtour_t[e], dtour_s[e])
                spin_unlock(dctl, e * NDCTL + DLOCK)
        _publish(dctl, d, tt, tsl)
        store(dctl, d * NDCTL + DINFL, 0)
        store(dctl, d * NDCTL + DPROG, load(dctl, d * NDCTL + DPROG) + 1)
        spin_unlock(dctl, myl)
        if boundary:
            _busy_pair(held, near, loff, ladj, a1, a2, -1)
            spin_unlock(ctrl, G)
        if status != OK:
            _fail(ctrl, status)
            return status


@kernel
def idle_until_abort(ctrl):
    """Tests: a worker that never processes an event (its domain's clock stands
    still), so the others can only stall — and must say so."""
    while load(ctrl, ABORT) == 0:
        cpu_relax()
        sched_yield()
    return OK


class Workers:
    """A persistent pool of T Python threads that run ``worker`` for each step.

    The calling thread only waits (joins): it never competes for the GIL while
    the workers run.  An exception in a worker stops the others at their next
    event (through ``ABORT``) and is re-raised in the caller with its traceback.
    """

    def __init__(self, threads, window_events=8.0, stall_seconds=60.0):
        from concurrent.futures import ThreadPoolExecutor

        self.threads = threads
        self.window_events = float(window_events)
        self.stall_cycles = int(stall_seconds * cycles_per_second())
        self.pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lockgraph")
        self.ctrl = np.zeros(NCTRL, np.int64)
        self.dctl = np.zeros(threads * NDCTL, np.int64)
        self.fault = None  # tests: a thread that raises (d) or never works (("stall", d))
        self.jitter = 0  # tests: a nonzero seed makes the workers pause at random
        self.stacks = None  # per-thread search stacks (rows), sized on first use
        self.wall_s = 0.0
        self.inline_last = True  # map: the caller runs the last task (False: benchmarks compare)

    def close(self):
        self.pool.shutdown(wait=True)

    def map(self, fn, arglist):
        """[fn(*args) for args in arglist], all but the last on the pool's threads
        and the last on the calling thread (kernels release the GIL).

        Why the caller works too: handing a task to a sleeping pool thread and
        joining it costs ~0.1-0.25 ms each way (a futex wake and the GIL); the
        caller is awake already.  Nothing is left running when this returns or
        raises: on any exception (a task's, or an interrupt while waiting) the
        workers are told to stop (``ABORT``) and every task is waited for; an
        earlier task's exception is raised first, as in a loop, but an
        interrupt is raised as such."""
        from concurrent.futures import wait

        inline = self.inline_last
        futures = [self.pool.submit(fn, *a) for a in (arglist[:-1] if inline else arglist)]
        try:
            last = [fn(*arglist[-1])] if inline else []
            return [f.result() for f in futures] + last
        except BaseException as exc:
            self.ctrl[ABORT] = 1  # workers stop at their next event; other kernels just end
            wait(futures)
            if isinstance(exc, Exception):
                for f in futures:
                    if f.exception() is not None:
                        raise f.exception()
            raise

    def run(self, bundles, stt, locks, lstate, doms, window):
        """Run the workers until the step's events are done or one stops with a
        status; returns that status (OK when all is done)."""
        self.ctrl[:] = 0
        self.ctrl[JITTER] = self.jitter
        dom, bd, dlo, dhi, dtour_t, dtour_s = doms
        self.dctl[:] = 0
        for d in range(self.threads):  # each domain's clock: its next event
            t = dtour_t[d][1] if dtour_s[d][1] >= 0 else np.inf
            self.dctl[d * NDCTL + DCLOCK] = np.float64(t).view(np.int64)
        work = bundles[1][3]
        if self.stacks is None or self.stacks.shape[1] != work.shape[0]:
            self.stacks = np.zeros((self.threads, work.shape[0]), work.dtype)
        t0 = time.perf_counter()
        try:
            self.map(self._one, [(d, bundles, stt, locks, lstate, doms, window)
                                 for d in range(self.threads)])
        finally:
            self.wall_s += time.perf_counter() - t0
        return int(self.ctrl[STATUS])

    def _one(self, d, bundles, stt, locks, lstate, doms, window):
        try:
            if self.fault == d:
                raise RuntimeError(f"injected fault in worker thread {d}")
            if self.fault == ("stall", d):
                return idle_until_abort(self.ctrl)
            parts, step, tree, nbrs, evq, jour, cfg = bundles
            # the tree-search stack of ``grow`` is scratch: one per thread (a shared
            # one lets two threads' searches overwrite each other's nodes and miss pairs)
            step = step[:3] + (self.stacks[d],)
            return worker(d, parts, step, tree, nbrs, evq, jour, cfg, stt[d], locks, lstate, doms,
                          self.ctrl, self.dctl, window, self.stall_cycles)
        except BaseException:
            self.ctrl[ABORT] = 1  # the others stop at their next event
            raise
