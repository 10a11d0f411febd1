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
import os
import resource
import time

import numpy as np

from ._jit import kernel
from .atomics import (bits_float, cpu_relax, cycles, float_bits, load, sched_yield,
                      sleep_us)
from .atomics import spin_lock, spin_unlock, store, cas
from .errors import InputError
from .events import update_queue, update_queue_pair
from .predict import INF
from .kernels import (I_PAPER, NEED_JOURNAL, NEED_LOG, OK, P_DT, S_BLOCKED, S_CLAIMS, S_CONC,
                      S_VIOL, S_WAIT, STALL, VIOLATION, journal_room, process_event)
from .neighbors import LCOUNT

G, ABORT, STATUS = 0, 8, 16
JITTER = 17  # tests: a nonzero seed makes the workers pause at random (fault injection)
NOWAIT = 18  # tests: nonzero makes pool events run without waiting (its checks alone order them)
# set by the caller's share of a phase as it begins (its GIL released): a pool
# thread posted that phase returns to Python only then (``_await_task``)
STARTED = 19
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
# The threads time one event in TIME_EVERY (the first of each run of that many)
# and count it TIME_EVERY times, in the cycles inside the events (``S_CONC``: the
# mean concurrency; the pool's band cut).  The cycle counter costs more than its
# own instruction here: timing every event made the pool's loop on one thread
# 1.19 times the sequential events on the bed, against 1.04 untimed (README,
# Benchmarks: "The cycle counter's cost").
TIME_EVERY = 16


def cache_aligned(shape, dtype=np.float64, fill=0):
    """A new array filled with ``fill`` whose data begin on a 64-byte boundary,
    so that rows written by different threads (each a whole number of cache
    lines long) share no line; numpy aligns small arrays to 16 bytes only."""
    dtype = np.dtype(dtype)
    nbytes = int(np.prod(shape)) * dtype.itemsize
    buf = np.empty(nbytes + 64, np.uint8)
    off = -buf.ctypes.data % 64
    out = buf[off:off + nbytes].view(dtype).reshape(shape)
    out.fill(fill)
    return out


class AlignedScratch:
    """``cache_aligned`` arrays kept from one step to the next, one per name:
    ``get(name, shape, dtype, fill)`` refills the kept array (a new one when
    the shape or type changed).  Why: a step of the pool schedule made 17 of
    them, 0.55 ms of the caller's Python a step on the ring (N = 2e5, 31 ms
    steps on two threads), where the threads wait for it.  An array is
    valid until the next ``get`` of its name: each is used within one phase."""

    def __init__(self):
        self._kept = {}

    def get(self, name, shape, dtype=np.float64, fill=0):
        a = self._kept.get(name)
        if a is None or a.shape != shape or a.dtype != dtype:
            a = self._kept[name] = cache_aligned(shape, dtype, fill)
        else:
            a.fill(fill)
        return a


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
    for r in range(dom.shape[0]):
        dom[r] = -2
    for d in range(dlo.shape[0]):
        for s in range(dlo[d], dhi[d]):
            r = lock_of[s]
            if dom[r] == -2:
                dom[r] = d
            elif dom[r] != d:
                dom[r] = -1
    _hop_distances(loff, ladj, dom, bd, queue, cap)
    far = 0
    for s in range(lock_of.shape[0]):
        if bd[lock_of[s]] >= cap:
            far += 1
    return far


@kernel
def classify_ranges(rlo, rhi, loff, ladj, dlo, dhi, dom, bd, queue, cap):
    """``classify_regions`` for regions that are slot ranges rlo[r]..rhi[r]-1
    (the lock graph's: tree nodes) in O(regions), not O(N): 0.3-0.4 ms a step
    saved at N = 2e5, on the one thread."""
    for r in range(dom.shape[0]):
        if rlo[r] >= rhi[r]:
            dom[r] = -2
        else:
            d = _domain_of(dlo, rlo[r])
            dom[r] = d if _domain_of(dlo, rhi[r] - 1) == d else -1
    _hop_distances(loff, ladj, dom, bd, queue, cap)
    far = 0
    for r in range(dom.shape[0]):
        if bd[r] >= cap:
            far += rhi[r] - rlo[r]
    return far


@kernel(inline=True)
def _hop_distances(loff, ladj, dom, bd, queue, cap):
    """bd from dom, by the breadth-first search of ``classify_regions``."""
    nreg = dom.shape[0]
    for r in range(nreg):
        bd[r] = cap
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
def _progress(dctl, ndom, stride=NDCTL, at=DPROG):
    """Events completed so far by all domains (each domain's count at word
    ``at`` of its row of ``stride`` words)."""
    prog = 0
    for e in range(ndom):
        prog += load(dctl, e * stride + at)
    return prog


@kernel(inline=True)
def wait_blocked(dctl, ndom, stride, at, st, waiting, wait_from, checked, seen, nblk,
                 stall_cycles):
    """One wait of a thread whose pick was blocked: spin, then yield, then
    (blocked this long: the threads it waits for may share its core — more
    threads than free cores — sleeping lets them run) sleep.  Progress
    (``_progress``) is looked at when a wait begins and then every eighth of
    stall_cycles (reading it at every pick would pull the line the working
    threads write at every event): a stall is reported after 1 to 1.125
    stall_cycles without progress.  Returns (wait_from, checked, seen, nblk,
    stalled); the caller's wait is then under way."""
    now = cycles()
    if not waiting:
        wait_from = now
        checked = now
        seen = _progress(dctl, ndom, stride, at)
    elif now - checked > stall_cycles >> 3:
        checked = now
        prog = _progress(dctl, ndom, stride, at)
        if prog != seen:
            seen = prog
            wait_from = now
        elif now - wait_from > stall_cycles:
            return wait_from, checked, seen, nblk, True
    nblk += 1
    if nblk < PARK_AFTER:
        cpu_relax()
        sched_yield()
    else:
        sleep_us(PARK_US)
    st[S_WAIT] += cycles() - now
    return wait_from, checked, seen, nblk, False


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
    lock_of, loff, ladj, _ = locks
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
    nev = 0  # this call's events (which of them are timed: TIME_EVERY)
    rng = load(ctrl, JITTER) * (2 * d + 1)
    while True:
        if load(ctrl, ABORT) != 0:
            return OK
        # room in the journal and the log for one more event of every domain
        jroom = journal_room(st, ctr, jslot.shape[0], ndom)
        if not jroom or (logt.shape[0] > 0 and ctr[LCOUNT] + ndom + 1 > logt.shape[0]):
            if _all_idle(dctl, ndom):
                _fail(ctrl, NEED_LOG if jroom else NEED_JOURNAL)
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
            wait_from, checked, seen, nblk, stalled = wait_blocked(
                dctl, ndom, NDCTL, DPROG, st, waiting, wait_from, checked, seen, nblk,
                stall_cycles)
            waiting = True
            if stalled:
                _fail(ctrl, STALL)
                return STALL
            continue
        waiting = False
        nblk = 0
        if rng != 0:  # holding the event's regions: the others run on meanwhile
            rng = _pause(rng)
        timed = nev % TIME_EVERY == 0
        nev += 1
        c0 = cycles() if timed else 0
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
        if timed:  # it stands for TIME_EVERY events
            st[S_CONC] += (cycles() - c0) * TIME_EVERY
        st[S_CLAIMS] += 1
        if rng != 0:
            rng = _pause(rng)
        # commit: the queues of the slots whose events changed
        if boundary:
            spin_lock(ctrl, G)
        spin_lock(dctl, myl)
        hidden[i] = 0
        e = _domain_of(dlo, jw) if jw >= 0 else -1
        if e == d:
            update_queue_pair(tt, tsl, evt, ids, hidden, lo, hi, i, jw)
        else:
            update_queue(tt, tsl, evt, ids, hidden, lo, hi, i)
        if jw >= 0 and e != d:  # a partner across the cut: its domain's queue, under its lock
            spin_lock(dctl, e * NDCTL + DLOCK)
            update_queue(dtour_t[e], dtour_s[e], evt, ids, hidden, dlo[e], dhi[e], jw)
            _publish(dctl, e, dtour_t[e], dtour_s[e])
            spin_unlock(dctl, e * NDCTL + DLOCK)
        _publish(dctl, d, tt, tsl)
        if status != OK:
            # posted while still in flight: a thread that waits for every domain
            # to be idle (a full journal or log) must not post its status first,
            # or a violation would be lost and the step resumed, not redone
            _fail(ctrl, status)
        store(dctl, d * NDCTL + DINFL, 0)
        store(dctl, d * NDCTL + DPROG, load(dctl, d * NDCTL + DPROG) + 1)
        spin_unlock(dctl, myl)
        if boundary:
            _busy_pair(held, near, loff, ladj, a1, a2, -1)
            spin_unlock(ctrl, G)
        if status != OK:
            return status


@kernel
def idle_until_abort(ctrl):
    """Tests: a worker that never processes an event (its domain's clock stands
    still), so the others can only stall — and must say so."""
    while load(ctrl, ABORT) == 0:
        cpu_relax()
        sched_yield()
    return OK


# the pool's hand-over words: one cache line per pool thread (the task
# generation posted, the generation done, asleep, hold for the caller's
# ``STARTED``)
W_GEN, W_DONE, W_ASLEEP, W_HOLD = 0, 1, 2, 3
NWSYNC = 8
# a pool thread spins this long for its next task before it sleeps (or until
# the step is over, ``Workers.rest``): a step's parallel phases follow each
# other within this, the gap between steps may not
SPIN_SECONDS = 0.002
# a spinning pool thread that finds it was descheduled for this long (another
# program or thread wanted its core) sleeps instead, and does not spin for
# its next BUSY_WAITS waits: spinning on a busy machine slowed the tests 2x
JUMP_SECONDS = 0.0001
BUSY_WAITS = 256
# ... unless the thread was not switched out in this machine (its involuntary
# context switches, ``_switches``): then it spins on, up to this many times
JUMP_TRIES = 8
# the caller's wait for the pool is a loop of kernel calls this long, so that
# Python can take a Ctrl-C between them
WAIT_SECONDS = 0.05


@kernel(inline=True)
def pause_spin(spins):
    """One look of a wait for another thread: a pause, and after 256 looks a
    yield (with more threads than cores the one waited for may need this
    core).  Returns the looks so far."""
    if spins < 256:
        cpu_relax()
    else:
        sched_yield()
    return spins + 1


@kernel(inline=True)
def say_started(ctrl, me, nthr):
    """At the start of a phase kernel's share: on its last thread, the one
    ``Workers.map`` runs on the calling thread, set ``ctrl[STARTED]`` (the
    caller has let the GIL go: ``_await_task``)."""
    if me == nthr - 1:
        store(ctrl, STARTED, 1)


@kernel
def _await_task(sync, at, old, rest, spin_cycles, jump_cycles, ctrl):
    """A pool thread's wait for its next task: spin on ``sync[at]`` until it
    differs from ``old``, ``spin_cycles`` pass or ``sync[rest]`` is set (the
    step is over); the value seen.  After a short pure spin it yields at
    every look, so that on a busy machine the thread that is to post the
    task (or another program) gets the core; if a yield took longer than
    ``jump_cycles`` (another program ran) it returns -2 at once.

    It first marks task generation ``old`` done (``W_DONE``), here rather
    than in Python, so that the caller, which then takes the GIL, finds it
    free: taking it from a thread still in Python is a sleep and a wake-up
    (0.03-0.1 ms on this machine).  For the same reason, a task posted with
    ``W_HOLD`` set is returned only once the caller's own share has begun
    (``ctrl[STARTED]``: the caller has let the GIL go) or three
    ``jump_cycles`` have passed (ring N = 2e5: the pool thread began its
    share of a phase 11-35 us after the caller, against 33-81 us when it
    took the GIL at once and slept on it)."""
    store(sync, at - W_GEN + W_DONE, old)
    c0 = cycles()
    prev = c0
    spins = 0
    while True:
        v = load(sync, at)
        now = cycles()
        if v != old and load(sync, at - W_GEN + W_HOLD) != 0:
            # the caller holds the GIL until its own share begins: wait for that
            # here, not asleep on the GIL (a wake-up 0.03-0.05 ms late)
            while load(ctrl, STARTED) == 0 and cycles() - now < 3 * jump_cycles:
                cpu_relax()
            return v
        if v != old or now - c0 > spin_cycles or load(sync, rest) != 0:
            return v
        if now - prev > jump_cycles:
            return -2
        prev = now
        spins = pause_spin(spins)


@kernel
def _await_done(sync, n, gen, wait_cycles, jump_cycles):
    """The caller's wait: True once pool threads 0..n-1 have done task
    generation ``gen``, False if ``wait_cycles`` pass first.  It spins, then
    yields (the pool threads may need this core), and once a look took
    longer than ``jump_cycles`` (the machine is busy) and the wait has
    lasted ten times that, it sleeps between looks instead, leaving the
    core to the threads it waits for.  (A sleep wakes 0.05-0.1 ms late:
    slept at once, the ends of a ring step's phases came that late, the
    host having paused the caller once in the wait.)"""
    c0 = cycles()
    prev = c0
    spins = 0
    busy = False
    while True:
        done = True
        for k in range(n):
            if load(sync, k * NWSYNC + W_DONE) != gen:
                done = False
                break
        if done:
            return True
        now = cycles()
        if now - c0 > wait_cycles:
            return False
        if now - prev > jump_cycles:
            busy = True
        prev = now
        spins += 1
        if spins < 256:
            cpu_relax()
        elif busy and now - c0 > 10 * jump_cycles:
            sleep_us(PARK_US)
            prev = cycles()  # the sleep itself is no sign of a busy machine
        else:
            sched_yield()


_RUSAGE_THREAD = getattr(resource, "RUSAGE_THREAD", None)


def _switches():
    """The calling thread's involuntary context switches so far: times this
    machine's scheduler took its core for other work.  (Where the count per
    thread is not available, a new value every call: any pause counts.)"""
    if _RUSAGE_THREAD is None:
        return time.perf_counter_ns()
    return resource.getrusage(_RUSAGE_THREAD).ru_nivcsw


class Workers:
    """A persistent pool of T Python threads that run ``worker`` for each step
    (and the step's other parallel phases, ``map``).

    The calling thread runs the last share itself and then waits in a nogil
    kernel, so it does not compete for the GIL with the workers.  An exception
    in a worker stops the others at their next event (through ``ABORT``) and
    is re-raised in the caller with its traceback.  ``close()`` ends the
    threads.
    """

    def __init__(self, threads, window_events=8.0, stall_seconds=60.0):
        import threading

        self.threads = threads
        self.window_events = float(window_events)
        self.stall_cycles = int(stall_seconds * cycles_per_second())
        self.ctrl = np.zeros(NCTRL, np.int64)
        self.dctl = np.zeros(threads * NDCTL, np.int64)
        self.fault = None  # tests: a thread that raises (d) or never works (("stall", d))
        self.jitter = 0  # tests: a nonzero seed makes the workers pause at random
        self.no_wait = False  # tests: pool events do not wait (the checks must catch it all)
        self.stacks = None  # per-thread search stacks (rows), sized on first use
        self.scratch = AlignedScratch()  # the step's control words (run_pool)
        self.wall_s = 0.0
        self.inline_last = True  # map: the caller runs the last task (False: benchmarks compare)
        # the pool: T threads (T - 1 busy when the caller runs the last task)
        self._sync = np.zeros((threads + 1) * NWSYNC, np.int64)  # last line: W_REST
        self._rest = threads * NWSYNC
        self._tasks = [None] * threads
        self._results = [None] * threads
        self._gen = 0
        self._wakes = 0  # wake(): bumped to wake the threads asleep
        # passive (no spinning, the caller sleeps between looks) when asked
        # (LOCKGRAPH_WAIT_POLICY=passive, like OMP_WAIT_POLICY) or when the
        # threads outnumber the cores this process may use
        policy = os.environ.get("LOCKGRAPH_WAIT_POLICY", "active")
        if policy not in ("active", "passive"):
            raise InputError("LOCKGRAPH_WAIT_POLICY", f"must be 'active' or 'passive' "
                             f"(got {policy!r})")
        self.passive = policy == "passive" or threads > len(os.sched_getaffinity(0))
        self._spin = 0 if self.passive else int(SPIN_SECONDS * cycles_per_second())
        self._wait = int(WAIT_SECONDS * cycles_per_second())
        self._jump = 0 if self.passive else int(JUMP_SECONDS * cycles_per_second())
        self._cv = threading.Condition()
        self._pool = [threading.Thread(target=self._serve, args=(k,), daemon=True,
                                       name=f"lockgraph-{k}") for k in range(threads)]
        for th in self._pool:
            th.start()

    def close(self):
        """Stop the pool's threads (idempotent)."""
        if self._gen >= 0:
            self._gen = -1
            with self._cv:
                self._sync[W_GEN:self._rest:NWSYNC] = -1
                self._cv.notify_all()
            for th in self._pool:
                th.join()

    def _serve(self, k):
        """Pool thread k: run each task posted to it, spinning a while for the
        next one (a step's phases come in quick succession), then sleeping."""
        at = k * NWSYNC
        last = 0
        calm = 0  # waits left without spinning: the machine was seen busy
        while True:
            spin = self._spin if calm == 0 else 0
            gen = int(_await_task(self._sync, at + W_GEN, last, self._rest, spin, self._jump,
                                  self.ctrl))
            calm = max(calm - 1, 0)
            tries = 0
            switched = -1
            while gen == -2 and tries < JUMP_TRIES:
                # off its core for a while: if not switched out in this machine,
                # the virtual machine's host paused it (ring N = 2e5: 185 of 240
                # hand-overs found the thread asleep, 0.1-0.2 ms each, when every
                # such pause counted as a busy machine); spin on.  The switches
                # are read at the first pause, not before every wait: inside a
                # step ``getrusage`` took 12 us (median, ring N = 2e5), on the
                # way from one task's end to its mark as done
                now = _switches()
                if switched >= 0 and now != switched:
                    break
                switched = now
                tries += 1
                gen = int(_await_task(self._sync, at + W_GEN, last, self._rest, spin,
                                      self._jump, self.ctrl))
            if gen == -2:  # switched out while spinning: other work wants the cores
                calm = BUSY_WAITS
                gen = last
            if gen == last:
                with self._cv:  # idle: sleep until posted to or woken (the caller
                    self._sync[at + W_ASLEEP] = 1  # looks at W_ASLEEP under the lock)
                    woken = self._wakes
                    while self._sync[at + W_GEN] == last and self._wakes == woken:
                        self._cv.wait()
                    self._sync[at + W_ASLEEP] = 0
                    gen = int(self._sync[at + W_GEN])
                if gen == last:  # woken for a step about to begin: spin for its task
                    continue
            if gen < 0:
                return
            last = gen
            fn, jobs = self._tasks[k]
            self._tasks[k] = None  # the next is posted only once these are done
            for i, args in jobs:  # more tasks than threads: several, in order
                try:
                    self._results[i] = (True, fn(*args))
                except BaseException as exc:  # reported to the caller by map
                    self.ctrl[ABORT] = 1  # the others stop at their next event
                    self._results[i] = (False, exc)
            # done: marked by the next _await_task, with no Python before it (the
            # caller waits for the mark)

    def wake(self):
        """A step begins: pool threads asleep since the last one wake now and
        spin for its first task, so that their wake-up (0.1-0.2 ms) overlaps
        the caller's work before it."""
        if self._gen < 0 or self.passive:
            return
        self._sync[self._rest] = 0
        with self._cv:
            if any(self._sync[k * NWSYNC + W_ASLEEP] for k in range(self.threads)):
                self._wakes += 1
                self._cv.notify_all()

    def map(self, fn, arglist, signals=False):
        """[fn(*args) for args in arglist], all but the last on the pool's threads
        and the last on the calling thread (kernels release the GIL).

        Why this pool and not concurrent.futures: handing a task to a sleeping
        thread and joining it cost ~0.1-0.25 ms each way (a futex wake and the
        GIL), a dozen times a step; here a pool thread spins (without the GIL)
        for its next task for SPIN_SECONDS before it sleeps, and the caller,
        awake already, runs a share itself.  Nothing is left running when
        this returns or raises: on any exception (a task's, or an interrupt
        while waiting) the workers are told to stop (``ABORT``) and every task
        is waited for; an earlier task's exception is raised first, as in a
        loop, but an interrupt is raised as such.

        ``signals``: fn stores 1 in ``ctrl[STARTED]`` as the calling thread's
        share begins (the kernels of a step's phases, on their last thread),
        and the pool threads hold until then before they take the GIL
        (``_await_task``)."""
        if self._gen < 0:
            raise RuntimeError("Workers.map after close()")
        inline = self.inline_last and len(arglist) > 0
        posted = len(arglist) - 1 if inline else len(arglist)
        n = min(posted, self.threads)  # pool threads used; task i goes to thread i % n
        self._gen += 1
        gen = self._gen
        self._results = [None] * len(arglist)
        self._sync[self._rest] = 0
        self.ctrl[ABORT] = 0  # set by a failed task of an earlier call
        self.ctrl[STARTED] = 0
        hold = int(signals and inline)
        for k in range(n):
            self._tasks[k] = (fn, [(i, arglist[i]) for i in range(k, posted, n)])
            self._sync[k * NWSYNC + W_HOLD] = hold
            self._sync[k * NWSYNC + W_GEN] = gen
        with self._cv:  # wake those asleep (under the lock: see _serve)
            if any(self._sync[k * NWSYNC + W_ASLEEP] for k in range(n)):
                self._cv.notify_all()
        try:
            if inline:
                self._results[-1] = (True, fn(*arglist[-1]))
            while not _await_done(self._sync, n, gen, self._wait, self._jump):
                pass
        except BaseException as exc:
            self.ctrl[ABORT] = 1  # workers stop at their next event; other kernels just end
            while not _await_done(self._sync, n, gen, self._wait, self._jump):
                pass
            if isinstance(exc, Exception):
                for k in range(posted):
                    ok, val = self._results[k]
                    if not ok:
                        raise val
            raise
        out = []
        for ok, val in self._results:
            if not ok:
                raise val
            out.append(val)
        return out

    def rest(self):
        """The step is over: pool threads sleep now instead of spinning for a
        next task that may be a while coming."""
        self._sync[self._rest] = 1

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

    def run_pool(self, bundles, stt, locks, pst, doms, pctl, window, masks, runs=False):
        """``schedule="pool"``: run ``pool.pool_worker`` on every thread until the
        step's events are done or one stops with a status; returns that status.
        ``pctl`` (domains x ``pool.NPCTL``, cache-aligned) keeps each domain's
        latest event time across calls within a step (a call after a grown
        journal resumes the step); its clocks and owners are set here, and
        after the domains' rows and the step's row, a row per thread: the
        domains it claims first and those it may claim (``masks``, from
        ``pool.claim_masks``), and ``runs``: each holds its own domains and
        never claims (``Engine.pool_claim = "runs"``)."""
        from .pool import NTCTL, POWNER, pool_rows

        dlo, dhi, dtour_t, dtour_s = doms
        pc = pctl.reshape(-1)
        npc = pctl.shape[1]
        pool_rows(pctl, len(dlo), dtour_t, dtour_s, masks[0], masks[1], int(runs), self.ctrl,
                  self.jitter, int(self.no_wait))
        if isinstance(self.fault, tuple) and self.fault[0] == "stall":
            pctl[0, POWNER] = 1 << 20  # taken before any worker can (hold_until_abort)
        tctl = self.scratch.get("tctl", (self.threads * NTCTL,), np.int64)
        work = bundles[1][3]
        if self.stacks is None or self.stacks.shape[1] != work.shape[0]:
            self.stacks = np.zeros((self.threads, work.shape[0]), work.dtype)
        assert npc * 8 % 64 == 0
        t0 = time.perf_counter()
        try:
            self.map(self._one_pool, [(k, bundles, stt, locks, pst, doms, pc, tctl, window)
                                      for k in range(self.threads)], signals=True)
        finally:
            self.wall_s += time.perf_counter() - t0
        return int(self.ctrl[STATUS])

    def _one_pool(self, k, bundles, stt, locks, pst, doms, pc, tctl, window):
        from .pool import hold_until_abort, pool_worker

        try:
            if self.fault == k:
                raise RuntimeError(f"injected fault in worker thread {k}")
            if self.fault == ("stall", k):  # takes domain 0 and never lets go
                return hold_until_abort(pc, self.ctrl)
            parts, step, tree, nbrs, evq, jour, cfg = bundles
            step = step[:3] + (self.stacks[k],)
            return pool_worker(k, self.threads, parts, step, tree, nbrs, evq, jour, cfg, stt[k],
                               locks, pst, doms, self.ctrl, pc, tctl, window, self.stall_cycles)
        except BaseException:
            self.ctrl[ABORT] = 1
            raise

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
