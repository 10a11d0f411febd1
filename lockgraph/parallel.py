"""Threaded event processing under spatial locks.

T Python threads each call ``worker`` once per step; the kernel runs without
the GIL and processes events until the step is done (whole runs of events per
call).  Shared words live in ``ctrl`` (int64, one cache line apart):

* ``QLOCK`` — spinlock guarding the event queue and the region lock states;
* ``INFLIGHT`` — events claimed and not yet committed;
* ``ABORT`` / ``STATUS`` — stop request and the first error status;
* ``PROGRESS`` — committed events (for stall detection);
* ``HIGH`` — the latest event time claimed so far (float bits).

Claim (under QLOCK): take the earliest event whose lock regions (those of its
two particles) are clear of every event in flight — the paper's rule: not the
same region nor adjacent (lock-graph distance >= 2) — skipping blocked events
(at most ``maxskip``, put back afterwards).  Under the exact policy "clear"
means distance >= 3: the neighbourhoods do not touch, so not even the event an
in-flight one creates next can reach what the claimed one reads or writes.
The slot is hidden from the queue while in flight.  Process (no lock): the same
``process_event`` as the sequential engine.  Commit (under QLOCK): queue
updates, regions released.

Causality.  Two events can only interact if their lock regions are within
distance one (the writer's regions touch the reader's neighbourhood).  Each
region keeps ``ts``: the latest time of an event that had it as its own.  An
event claimed in time order (not earlier than every event claimed before it)
cannot conflict with anything processed already; an event claimed out of order
(an earlier event created after later ones ran — a chain of follow-ups that
outran the distance rule) is checked: a later time on its regions or their
neighbours is a causality violation.  Under the exact policy the step then
stops and is redone sequentially (a repair); under the paper policy it is
counted.  A widened reach joining non-adjacent regions is a violation too.
Without violations every event reads and writes what it would sequentially,
so the state is bitwise the sequential one.
"""
import functools
import time

import numpy as np

from ._jit import kernel
from .atomics import cpu_relax, cycles, fetch_add, fetch_max, float_bits, load, sched_yield
from .atomics import spin_lock, spin_unlock, store, cas
from .events import update_queue
from .kernels import (I_PAPER, NEED_JOURNAL, NEED_LOG, OK, P_DT, S_BLOCKED, S_CLAIMS, S_CONC,
                      S_VIOL, S_WAIT, STALL, VIOLATION, process_event)
from .neighbors import JCOUNT, LCOUNT

QLOCK, INFLIGHT, ABORT, STATUS, PROGRESS, HIGH = 0, 8, 16, 24, 32, 40
NCTRL = 56


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


@kernel(inline=True)
def _clear(held, near, loff, ladj, a, far):
    """Region a at lock-graph distance >= 2 (far: >= 3) from every busy region?

    ``held[x]`` counts busy events owning region x, ``near[x]`` busy events
    with x in the closed neighbourhood of one of their regions: distance >= 2
    means no held region in a's closed neighbourhood, distance >= 3 no near one.
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
    """Add (d = 1) or remove (d = -1) region a as busy."""
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


@kernel
def worker(tid, parts, step, tree, nbrs, evq, jour, cfg, st, locks, lstate, ctrl, batch, skipped,
           stall_cycles):
    """One thread's share of a step's events.  Returns its final status.

    ``lstate = (ts, held, near)`` per region (see the module docstring; the
    counters are used under QLOCK only).  ``batch`` (B, 6) int64, this thread's
    own: slot, partner written, late flag, claim time's bits and the two
    regions of each event of its batch.  ``skipped`` (maxskip, 3): scratch for
    the events passed over in a scan.
    """
    ids = parts[7]
    ctr = nbrs[5]
    evt, evp, evc, tour_t, tour_s, hidden = evq
    jslot = jour[0]
    logt = jour[3]
    par = cfg[0]
    ipar = cfg[1]
    dt = par[P_DT]
    paper = ipar[I_PAPER] != 0
    far = not paper
    lock_of, loff, ladj = locks
    ts, held, near = lstate
    nb_max = batch.shape[0]
    maxskip = skipped.shape[0]
    waiting = False
    wait_from = 0
    seen_progress = -1
    while True:
        if load(ctrl, ABORT) != 0:
            return OK
        spin_lock(ctrl, QLOCK)
        inflight = ctrl[INFLIGHT]
        # room for every event in flight: at most two journal and one log entry each
        room = ctr[JCOUNT] + 2 * (inflight + nb_max) <= jslot.shape[0]
        if logt.shape[0] > 0 and ctr[LCOUNT] + inflight + nb_max > logt.shape[0]:
            room = False
        nb = 0
        nskip = 0
        empty = False
        while room and nb < nb_max:
            i = tour_s[1]
            if i < 0 or not tour_t[1] < dt:
                empty = True
                break
            p = evp[i]
            a1 = lock_of[i]
            a2 = lock_of[p >> 5] if p >= 0 else a1
            # clear of every claimed event (all threads, this batch so far) and,
            # under the exact policy, of the events passed over in this scan
            if _clear(held, near, loff, ladj, a1, far) and _clear(held, near, loff, ladj, a2, far):
                _busy_pair(held, near, loff, ladj, a1, a2, 1)
                batch[nb, 4] = a1
                batch[nb, 5] = a2
                tb = float_bits(tour_t[1])
                batch[nb, 0] = i
                batch[nb, 2] = 1 if tb < ctrl[HIGH] else 0
                batch[nb, 3] = tb
                if tb > ctrl[HIGH]:
                    ctrl[HIGH] = tb
                nb += 1
            else:
                st[S_BLOCKED] += 1
                if nskip >= maxskip:
                    break
                skipped[nskip, 0] = a1
                skipped[nskip, 1] = a2
                skipped[nskip, 2] = i
                nskip += 1
                if far:  # what is passed over must stay clear of what is taken
                    _busy_pair(held, near, loff, ladj, a1, a2, 1)
            hidden[i] = 1  # out of the queue: in flight, or passed over for now
            update_queue(tour_t, tour_s, evt, ids, hidden, i)
        for q in range(nskip):  # put back what was passed over
            s_ = skipped[q, 2]
            hidden[s_] = 0
            update_queue(tour_t, tour_s, evt, ids, hidden, s_)
            if far:
                _busy_pair(held, near, loff, ladj, skipped[q, 0], skipped[q, 1], -1)
        if nb == 0:
            if inflight == 0 and (empty or not room):
                spin_unlock(ctrl, QLOCK)
                if not room:
                    _fail(ctrl, NEED_LOG if logt.shape[0] > 0 and
                          ctr[LCOUNT] + 1 > logt.shape[0] else NEED_JOURNAL)
                return OK  # nothing left: the step's events are done
            spin_unlock(ctrl, QLOCK)
            now = cycles()
            prog = load(ctrl, PROGRESS)
            if not waiting or prog != seen_progress:
                waiting = True
                wait_from = now
                seen_progress = prog
            elif now - wait_from > stall_cycles:
                _fail(ctrl, STALL)
                return STALL
            cpu_relax()
            sched_yield()
            st[S_WAIT] += cycles() - now
            continue
        waiting = False
        ctrl[INFLIGHT] = inflight + nb
        st[S_CONC] += nb * (inflight + nb)
        st[S_CLAIMS] += nb
        spin_unlock(ctrl, QLOCK)

        status = OK
        for k in range(nb):
            batch[k, 1] = -1
            if status != OK:
                continue  # after an error the rest only go back to the queue
            i = batch[k, 0]
            tb = batch[k, 3]
            t = evt[i]
            a1 = batch[k, 4]
            a2 = batch[k, 5]
            # causality: only an event claimed out of time order can conflict with
            # one processed already, and only if their regions are within distance one
            if batch[k, 2] != 0 and (_touched_later(ts, loff, ladj, a1, tb)
                                     or _touched_later(ts, loff, ladj, a2, tb)):
                st[S_VIOL] += 1
                if not paper:
                    status = VIOLATION
                    continue
            status, j = process_event(i, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks)
            batch[k, 1] = j
            # the regions are this thread's own while in flight: plain writes
            if ts[a1] < tb:
                ts[a1] = tb
            if ts[a2] < tb:
                ts[a2] = tb

        spin_lock(ctrl, QLOCK)
        for k in range(nb):
            i = batch[k, 0]
            hidden[i] = 0
            update_queue(tour_t, tour_s, evt, ids, hidden, i)
            j = batch[k, 1]
            if j >= 0:
                update_queue(tour_t, tour_s, evt, ids, hidden, j)
            _busy_pair(held, near, loff, ladj, batch[k, 4], batch[k, 5], -1)
        ctrl[INFLIGHT] -= nb
        ctrl[PROGRESS] += nb
        spin_unlock(ctrl, QLOCK)
        if status != OK:
            _fail(ctrl, status)
            return status


class Workers:
    """A persistent pool of T Python threads that run ``worker`` for each step.

    The calling thread only waits (joins): it never competes for the GIL while
    the workers run.  An exception in a worker stops the others at their next
    event (through ``ABORT``) and is re-raised in the caller with its traceback.
    """

    def __init__(self, threads, maxskip=8, stall_seconds=60.0, batch=8):
        from concurrent.futures import ThreadPoolExecutor

        self.threads = threads
        self.maxskip = maxskip
        self.stall_cycles = int(stall_seconds * cycles_per_second())
        self.pool = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="lockgraph")
        self.ctrl = np.zeros(NCTRL, np.int64)
        self.batch = np.zeros((threads, batch, 6), np.int64)
        self.skipped = np.zeros((threads, max(maxskip, 0), 3), np.int64)
        self.fault = None  # tests: a thread index that raises instead of working

    def close(self):
        self.pool.shutdown(wait=True)

    def run(self, bundles, stt, locks, lstate):
        """Run the workers until the step's events are done or one stops with a
        status; returns that status (OK when all is done)."""
        from concurrent.futures import wait

        self.ctrl[:] = 0
        futures = [self.pool.submit(self._one, tid, bundles, stt, locks, lstate)
                   for tid in range(self.threads)]
        wait(futures)
        for f in futures:
            exc = f.exception()
            if exc is not None:
                raise exc
        return int(self.ctrl[STATUS])

    def _one(self, tid, bundles, stt, locks, lstate):
        try:
            if self.fault == tid:
                raise RuntimeError(f"injected fault in worker thread {tid}")
            parts, step, tree, nbrs, evq, jour, cfg = bundles
            return worker(tid, parts, step, tree, nbrs, evq, jour, cfg, stt[tid], locks, lstate,
                          self.ctrl, self.batch[tid], self.skipped[tid], self.stall_cycles)
        except BaseException:
            self.ctrl[ABORT] = 1  # the others stop at their next event
            raise
