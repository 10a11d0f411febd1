"""Threaded events over more domains than threads, waiting by particle.

``Engine(..., threads=T, schedule="pool")``: each step's particles are cut
into K = ``Engine.pool_domains`` domains (runs of tree slots: spatial blocks),
each with its own time-ordered queue, and any free thread takes any domain
(claimed with a CAS) and runs its events in key order (time, id) for as long
as they may run.  The replay (``band_replay.pool_schedule``) put the ceiling
of this schedule on the 50,000-grain bed at 1.94x with 4 domains on 2 threads,
against 1.56x with one domain per thread.

**Who waits for whom** (by particle, from the step's candidate lists, not
lock regions).  An event at key k of slots i (and partner j) writes i and j
and reads their candidates.  ``h1[s]``: the domains of s and its candidates;
``h2[s]``: the union of ``h1`` over s and its candidates (two hops); each
worked out at the step start for a dense scene, at its first use in the
step for a sparse one (``Engine.pool_masks``; ``kernels.hop1``, ``hop2``).  The
event waits until every other domain in ``h2[i] | h2[j]`` has no event with
a smaller key in its queue (its *clock*, the queue's root, is later) and
no event in flight at the same time or earlier (published apart from the
clock: another thread's commit that rescans a bucket of this queue may
already see an event's new predictions while it runs).  An event
whose ``h2`` is its own domain alone is *interior*: nothing another domain
does can reach what it reads or writes, and it runs without looking at the
others (except for ``window``, how far it may run ahead of them).

**Causality, checked.**  Waiting covers the events in the queues; an event
created later (a partner's new event put into its domain's queue by another
thread) may still come before one that already ran.  So every event records
its key time on its two particles (``wt``), and an event that is not interior,
or is *late* (earlier than an event its domain already ran), checks at its
commit that no particle it wrote or read (i, j and their candidates, the
pairs found during the event included) carries a later time: any event that
read or wrote what this one writes, or wrote what it read, wrote one of those
particles.  A later time is a violation: the step is redone (a repair, from
the step-start values the pool saved: ``pool_start``; not from the undo
journal, which two threads writing one particle at once can leave wrong), on
the threads with the narrow interior window ``REDO_WINDOW`` and, if that
attempt finds a violation too, on one thread (``Engine.pool_redo``), so the
result is always the sequential one bit for bit.  A pick
whose particle's event changed before its look passed (the same pair event
held by both particles, run from the other side) is *stale*: it is withdrawn,
not repaired.  The
ordering of the two checks across threads is by full fences: an event that
is not interior publishes its ``wt`` with an atomic maximum before it reads any
particle, and the checking commit runs under its domain's lock.

**Candidates found mid-step.**  A widened reach that adds a pair (k, m)
leaves the masks true when m's domain is already in ``h1[k]`` and k's in
``h1[m]`` (so neither one-hop set grows), and ``h1[m]`` is within ``h2[k]``,
``h1[k]`` within ``h2[m]`` (so no two-hop set grows): ``kernels.grow`` is
given the masks (``locks = (sdom, -, -, (h1, h2, checked, exposed))``) and
tests that rule.  Any other new pair (a few dozen a step on a dense bed,
most of them between particles several hops apart at the step start, so
wider masks do not help) is let in but *exposes* k and m
(``kernels.expose_pair``): events ordered by no mask may now write them.
From then on every event on k, m or a particle that reads them (their
candidates, and any found later) is *checked*: it waits for its masks and
for the domains its mark names (the one-hop masks of k and m, and of the
pairs exposed before them that share an end: the two-hop set the new pair
makes, ``test_pool.py`` against breadth-first search), publishes its
particle times with a fence and checks at its commit.  (Until 2026-12-06 it
waited for every domain: on the bed, 5 % of the events, and 0.18-0.19
blocked picks an event against 0.13-0.14 now; README, Benchmarks: "Checked
events wait for their marks".)  The event that found the pair then waits
until every event already in flight elsewhere has committed (``_settle``:
each of those reads the marks again at its commit, and has published its
times before this one checks).

**Which domain, cut how.**  The domains are the tree's nodes of one depth
(slabs stacked along a long scene's longest axis: ``Engine._slab_levels``);
a free thread claims the free domain with the earliest clock among those
its two masks let it (``claim_masks``, by ``Engine.pool_claim``): the
domains it claims first and those it may claim at all.  ``"band"`` (the
default): its own run of domains (cut at equal shares of the cycles the
last step spent inside each domain's events, one event in ``TIME_EVERY``
timed and counted that many times) first, then only the domains
next to that run (``domain_adjacency``, worked out with the first events),
so that the particles inside a run, away from its edge, are written by one
thread only.  ``"earliest"``: any.  ``"home"``: its share of the domains in slot
order first, then any.  ``Engine.pool_split = "work"`` cuts the slots into
runs of about equal work by the last step's collisions (``work_split``).
Measured on the 50,000-grain bed against ``"earliest"`` (README,
Benchmarks: "Band claims" and "Own domains"): "band" 19-32 % faster in the
minutes the two threads' cores are far apart (separate caches) and 0.90-1.05
times as fast when they are near (the ring, N = 2e5: 1 % slower, the cost of
the adjacency); "home" 0-16 % faster far and 1-6 % slower near.

**Own runs, no claims** (``"runs"``, the default since 2026-12-06).  Each
thread holds its run of domains (cut as for ``"band"``) for the whole step
and never takes another's: no claims, no releases, no asking.  After each
event it looks at the earliest of its own domains (``_pick_own``); an
event that waits for none but its own domains is ordered by their clocks
alone (only this thread runs them; another writes them only to hand one
an event, under the lock) and runs as an interior one; only an event that
also waits for another thread's domains publishes its times, looks twice
and checks at its commit (below: "Checks by the other threads'
domains").  When every own domain waits, the thread spins a little
(``RUNS_SPINS``) before it yields.  Measured on the bed, paired, against
``"band"`` in the same processes: 1-3 % faster, and no repairs in 96 steps
where "band" had 5 (README, Benchmarks: "Own runs, no claims").

Three refinements of the runs (2026-12-06, README, Benchmarks: "Held picks,
own checks, a cut by cost"):

* *Held picks.*  A domain whose root event was held back remembers by what
  (``_still_blocked``): until its root changes, later picks read only that
  domain's clock line, not the masks and the looks again (blocked picks on
  the bed: 0.18 an event, from 1.07).
* *Checks by the other threads' domains.*  An event's commit checks only
  when its masks hold another thread's domain (or it is late, or strict):
  an event of another thread that writes or reads what this one reads or
  writes has a particle within one candidate hop of this event's, so that
  thread's domain is in this event's two-hop masks.
* *A cut by cost.*  The runs end where the last step's cost (each domain's
  cycles shared over its slots by their collisions: ``cost_points``)
  reaches equal shares, inside a domain if need be, which is then split in
  two (``cost_cut``; the domains are then one more than
  ``Engine.pool_domains``).  At the nearest domain edge the two threads'
  cycles differed by up to 20 % on the bed.

**Asking.**  A pick held back by a domain of another thread's own run
(``_blocker`` names it) asks that thread to run it (``_ask``), and that
thread, after its event in flight, takes it when it is free (``_answer``;
counted: ``S_ASKED``).  Without the ask the thread whose front lags at the
edge between two runs gets there only when its own earliest clock says so,
while the other thread's picks at that edge fail.  Measured on the bed
(paired, 16-20 steps, five runs): 2-5 % faster steps, blocked picks 0.62
an event against 0.72-0.77.  Taking the blocker at once instead (the
asker claims it) was 6-7 % slower: the domain's particles move to the
other core.

Shared words: ``dctl`` per domain (its lock; on a second line its clock; on a
third its owner; on a fourth its latest event time and progress), then the
step's row and a row per thread (its claim masks, read only), and ``tctl``
per thread (in flight; on a second line, the domain another thread asks it to
run).
"""
import numpy as np

from ._jit import kernel
from .atomics import (bits_float, cas, claim_from_ends, cpu_relax, cycles, fetch_max, float_bits,
                      load, sched_yield, spin_lock, spin_unlock, store)
from .events import update_queue, update_queue_pair
from .kernels import (NEED_JOURNAL, NEED_LOG, OK, P_DT, S_ASKED, S_BLOCKED, S_CLAIMS, S_CONC,
                      S_REACHOUT, S_VIOL, S_WAIT, STALL, VIOLATION, hop2, init_range,
                      journal_room, process_event)
from .neighbors import LCOUNT
from .parallel import (ABORT, JITTER, NOWAIT, TIME_EVERY, _fail, _pause, _progress,
                       cache_aligned, say_started, wait_blocked)
from .predict import INF

MAX_DOMAINS = 63  # bits of an int64 mask
# under ``pool_claim = "runs"`` a thread whose own domains all wait for another
# thread's first spins RUNS_SPINS times RUNS_PAUSES pauses (a few hundred ns
# each; about 0.1 ms in all), looking again after each, before the waits of
# ``parallel.wait_blocked`` (a yield, a system call, each).  Measured on the
# bed against "band" in the same processes (16 steps each, paired with the
# sequential engine): 3.0 and 3.1 % faster with the spin, 0.5-2.1 % with the
# yields alone (README, Benchmarks: "Own runs, no claims")
RUNS_SPINS = 256
RUNS_PAUSES = 8
# the interior window (in a domain's mean times between events) of a step redone
# on the threads after a violation (``Engine.pool_redo``).  Measured on the bed,
# 16 domains: the window of 8 events (the default until 2026-12-07) repaired the
# sixth step of every run then (an interior event run ahead of an earlier one
# three candidate hops away); windows of 1 and 2 events had no repair in 50
# steps and ran at 1.64 and 1.67x against 1.74x near (README, Benchmarks: "What
# the far cost is not")
REDO_WINDOW = 2.0
# per-domain row of dctl (four cache lines): its lock and its queue's version
# (bumped under the lock at every change of the queue); its clock and the time of
# its event in flight (INF when none), read together; its owner (read by every
# claim, written only by claims and releases); the latest event time it ran, the
# settling flag, the progress count, the cycles spent inside its events (the
# next step's band cut: ``claim_masks``) and its events so far (which of them
# are timed: ``TIME_EVERY``), written by the owner at every commit and
# kept off the owner's line, which the other threads' claims read (measured on the
# bed, 100 steps: 1-2 % faster than with the progress beside the owner)
PLOCK, PVER, PCLOCK, PINFL, POWNER, PHIGH, PSETTLE, PPROG, PCYC, PNEV = \
    0, 1, 8, 9, 16, 24, 25, 26, 27, 28
NPCTL = 32
# one row more after the domains' rows: nonzero once a pair found mid-step broke
# the masks (counted by the engine: ``Engine.pool_checked_steps``)
PCHECKED = 0
# then a row per thread: the domains it claims first and those it may claim
# (``claim_masks``), and 1 when it runs its own domains only, never claiming
# ("runs"), read once by its worker
POWN, PALLOW, PRUNS = 0, 1, 2
# per-thread row of tctl (two cache lines): in flight; on the second line, the
# domain another thread asks it to run, plus one (0: none; ``_ask``), written
# by the asker, so the thread's own stores to its first line never miss
TFLIGHT, TASK = 0, 8
NTCTL = 16


@kernel
def clear_words(d, sdom, wt, hops, lo, hi):
    """The pool's words of domain d's slots lo..hi-1 at the step start: the
    domain, no event time, masks not yet worked out (``kernels.hop1``,
    ``hop2``), unchecked, unexposed.  Array by array, as slices: one loop over
    the slots writing all six took 3.4 times as long (N = 2e5: 0.34 against
    0.10 ms)."""
    sdom[lo:hi] = d
    wt[lo:hi] = -1
    for r in range(4):
        hops[r, lo:hi] = 0


@kernel
def init_domain(d, sdom, wt, hops, parts, nbrs, evq, cfg, st, lo, hi, tour_t, tour_s):
    """Domain d at the step start: its slots' pool words (``clear_words``),
    then their first events and the domain's queue (``kernels.init_range``).
    (Its step-start values are already saved: the permutation gathers them,
    ``pool_start``.)
    The masks are filled here (``init_domains``, ``two_hop_masks``) or at
    first use (``Engine.pool_masks``): most slots of a sparse scene never
    need them (ring N = 2e5: 2,226 events a step; masks for every slot,
    worked out before the events, cost 1.0-2.0 ms of a 42 ms step), and
    every slot of a dense one does."""
    clear_words(d, sdom, wt, hops, lo, hi)
    init_range(parts, nbrs, evq, cfg, st, lo, hi, tour_t, tour_s)


@kernel(inline=True)
def domain_of(dhi, s):
    """The domain holding slot s: the first whose run ends after s."""
    lo = 0
    hi = dhi.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        if dhi[mid] > s:
            hi = mid
        else:
            lo = mid + 1
    return lo


@kernel
def domain_adjacency(noff, nent, dhi, d, lo, hi, h1):
    """The mask of the domains holding domain d (slots lo..hi-1) and the
    step-start candidates of its slots; unless ``h1`` is empty, each slot's
    own such mask (its one-hop mask, ``kernels.hop1``) into ``h1``."""
    md = np.int64(1) << d
    m = md
    keep = h1.shape[0] > 0
    for s in range(lo, hi):
        ms = md
        for k in range(noff[s], noff[s + 1]):
            c = nent[k] >> 5
            if c < lo or c >= hi:  # most candidates are in d: no search
                ms |= np.int64(1) << domain_of(dhi, c)
        if keep:
            h1[s] = ms
        m |= ms
    return m


@kernel
def two_hop_masks(me, nthr, claim, hops, sdom, noff, nent, dlo, dhi):
    """Thread ``me`` of ``nthr``'s share (a domain a task) of every slot's
    two-hop mask (``kernels.hop2``, from the one-hop masks that
    ``init_domains`` filled for every slot)."""
    nd = dlo.shape[0]
    r = 0
    while True:
        d = claim_from_ends(claim, me, nthr, r, nd)
        r += 1
        if d >= nd:
            return 0
        for s in range(dlo[d], dhi[d]):
            hop2(hops, sdom, noff, nent, s)


@kernel
def init_domains(me, nthr, claim, sdom, wt, hops, parts, nbrs, evq, cfg, rows, dlo, dhi, dtour_t,
                 dtour_s, adj, masks, ctrl):
    """Thread ``me`` of ``nthr``'s share of ``init_domain`` over every domain
    (``rows``, ``dtour_t``, ``dtour_s``: a row each), a domain a task
    (``atomics.claim_from_ends``: on two threads the first from the front,
    the second from the back), and of the domains' ``domain_adjacency`` when
    ``adj`` has a row for them; with ``masks``, also every slot's one-hop
    mask (then ``two_hop_masks``).  One call a thread, not one a domain: each
    call from Python takes the GIL, and two threads taking it in turn wait
    for each other's wake-up."""
    say_started(ctrl, me, nthr)
    nd = dlo.shape[0]
    r = 0
    while True:
        d = claim_from_ends(claim, me, nthr, r, nd)
        r += 1
        if d >= nd:
            return 0
        init_domain(d, sdom, wt, hops, parts, nbrs, evq, cfg, rows[d], dlo[d], dhi[d],
                    dtour_t[d], dtour_s[d])
        if masks or adj.shape[0] > 0:
            m = domain_adjacency(nbrs[0], nbrs[1], dhi, d, dlo[d], dhi[d],
                                 hops[0] if masks else hops[0][:0])
            if adj.shape[0] > 0:
                adj[d] = m


@kernel(inline=True)
def _later_near(wt, noff, nent, xhead, xent, xnext, s, tb):
    """Does s or a candidate of s (the extras found mid-step included) carry
    an event time later than tb?"""
    if load(wt, s) > tb:
        return True
    for k in range(noff[s], noff[s + 1]):
        if load(wt, nent[k] >> 5) > tb:
            return True
    x = load(xhead, s)
    while x >= 0:
        if load(wt, xent[x] >> 5) > tb:
            return True
        x = xnext[x]
    return False


@kernel(inline=True)
def _blocker(dctl, dtour_t, dtour_s, ids, w, tb, t, idi):
    """The first domain in mask w with an event of key smaller than (t, idi)
    or an event in flight not later than t; -1 if none (the event is
    ordered).  (An event in flight holds its domain back even when the queue
    no longer shows it: a bucket rescan by another thread's commit may
    already see its new predictions.)"""
    e = 0
    while w != 0:
        if w & 1:
            if load(dctl, e * NPCTL + PINFL) <= tb:
                return e
            c = load(dctl, e * NPCTL + PCLOCK)
            if c < tb:
                return e
            if c == tb:  # a tie in time: the ids decide, read under the lock
                spin_lock(dctl, e * NPCTL + PLOCK)
                r = dtour_s[e][1]
                before = r >= 0 and (dtour_t[e][1] < t or (dtour_t[e][1] == t and ids[r] < idi))
                spin_unlock(dctl, e * NPCTL + PLOCK)
                if before:
                    return e
        w >>= 1
        e += 1
    return -1


@kernel(inline=True)
def _ask(dctl, tctl, ndom, nthr, me, x):
    """Ask the other thread whose own domains (``claim_masks``) hold domain x
    to run x next (``_answer``); its word is written only when it changes."""
    for k in range(nthr):
        if k != me and (load(dctl, (ndom + 1 + k) * NPCTL + POWN) >> x) & 1:
            if load(tctl, k * NTCTL + TASK) != x + 1:
                store(tctl, k * NTCTL + TASK, x + 1)
            return


@kernel(inline=True)
def _answer(dctl, tctl, me, cur, st):
    """After an event: the domain this thread runs next, cur or the one
    another thread asked for (``_ask``) if that one is free and now claimed."""
    a = load(tctl, me * NTCTL + TASK)
    if a == 0:
        return cur
    store(tctl, me * NTCTL + TASK, 0)
    x = a - 1
    if x != cur and load(dctl, x * NPCTL + POWNER) == -1 and cas(dctl, x * NPCTL + POWNER, -1,
                                                                  me) == -1:
        store(dctl, cur * NPCTL + POWNER, -1)
        st[S_ASKED] += 1
        return x
    return cur


@kernel(inline=True)
def _others_clock(dctl, d, ndom):
    m = float_bits(INF)
    for e in range(ndom):
        if e != d:
            c = load(dctl, e * NPCTL + PCLOCK)
            if c < m:
                m = c
    return m


@kernel(inline=True)
def _claim_in(dctl, lo, hi, me, dtb, tried):
    """Claim the free domain of lo..hi-1 with the earliest clock before the
    step end that is not in the mask ``tried``; -1 if there is none or
    another thread took it first."""
    best = -1
    bc = dtb
    for e in range(lo, hi):
        if (tried >> e) & 1 == 0 and load(dctl, e * NPCTL + POWNER) == -1:
            c = load(dctl, e * NPCTL + PCLOCK)
            if c < bc:
                bc = c
                best = e
    if best >= 0 and cas(dctl, best * NPCTL + POWNER, -1, me) == -1:
        return best
    return -1


@kernel(inline=True)
def _still_blocked(dctl, e, bx, bt, bv):
    """Is domain e's root event still held back by the domain that held it
    back when last picked (``bx[e]``, -1: none)?  Only while e's queue
    version is ``bv[e]`` (the same root) and that domain still has an event
    in flight not later than the root's time ``bt[e]`` or a clock before it
    (one line of the blocker read, not the pick's masks and looks)."""
    x = bx[e]
    if x < 0 or load(dctl, e * NPCTL + PVER) != bv[e]:
        return False
    tb = bt[e]
    return load(dctl, x * NPCTL + PINFL) <= tb or load(dctl, x * NPCTL + PCLOCK) < tb


@kernel(inline=True)
def _pick_own(dctl, own, tried, dtb, bx, bt, bv):
    """Under ``pool_claim = "runs"``: the thread's own domain (mask ``own``,
    never claimed by another) with the earliest clock before the step end
    that is not in ``tried`` and not still held back (``_still_blocked``);
    -1 if none.  Also returns whether a domain was passed over as held back."""
    best = -1
    bc = dtb
    held = False
    m = own & ~tried
    e = 0
    while m != 0:
        if m & 1:
            c = load(dctl, e * NPCTL + PCLOCK)
            if c < bc:
                if _still_blocked(dctl, e, bx, bt, bv):
                    held = True
                else:
                    bc = c
                    best = e
        m >>= 1
        e += 1
    return best, held


@kernel(inline=True)
def _claim(dctl, ndom, me, dtb, tried, own, allowed):
    """Claim a domain (``_claim_in``): among the thread's own domains (mask
    ``own``) first, then among those it may take (``allowed``, which holds
    ``own``; see ``claim_masks``)."""
    if own != allowed:
        c = _claim_in(dctl, 0, ndom, me, dtb, tried | ~own)
        if c >= 0:
            return c
    return _claim_in(dctl, 0, ndom, me, dtb, tried | ~allowed)


@kernel(inline=True)
def home_range(me, nthr, ndom):
    """Thread ``me`` of ``nthr``'s own domains: lo..hi-1, its share of the
    domains in slot order (a spatial block; with ``work_split``'s domains,
    about 1/nthr of the last step's collisions)."""
    return me * ndom // nthr, (me + 1) * ndom // nthr


@kernel
def work_split(cis, dlo, dhi):
    """Cut the slots 0..N-1 into len(dlo) runs of about equal work, a slot's
    work being its collisions in the step just run (``cis``) plus one: run q
    ends at the first slot whose running sum reaches q/len(dlo) of the total
    (integer sums, so exact).  A slot heavier than a run leaves runs empty."""
    n = cis.shape[0]
    nd = dlo.shape[0]
    total = np.int64(0)
    for s in range(n):
        total += cis[s] + 1
    acc = np.int64(0)
    q = 1
    dlo[0] = 0
    for s in range(n):
        if q >= nd:
            break
        acc += cis[s] + 1
        while q < nd and acc * nd >= total * q:
            dhi[q - 1] = s + 1
            dlo[q] = s + 1
            q += 1
    while q < nd:  # only without slots (n = 0)
        dhi[q - 1] = n
        dlo[q] = n
        q += 1
    dhi[nd - 1] = n


@kernel(inline=True)
def _idle(tctl, nthr):
    for k in range(nthr):
        if load(tctl, k * NTCTL + TFLIGHT) != 0:
            return False
    return True


@kernel(inline=True)
def _done(dctl, tctl, ndom, nthr, dtb):
    """No event before the step end in any queue and none in flight (the
    progress count read on both sides of the look, so a commit that moved an
    event into a domain already looked at is seen)."""
    p0 = _progress(dctl, ndom, NPCTL, PPROG)
    for e in range(ndom):
        if load(dctl, e * NPCTL + PCLOCK) < dtb or load(dctl, e * NPCTL + PINFL) < dtb:
            return False
    if not _idle(tctl, nthr):
        return False
    return _progress(dctl, ndom, NPCTL, PPROG) == p0


@kernel(inline=True)
def _settle(dctl, ctrl, d, ndom, stall_cycles):
    """After a pair that broke the masks: note it on the step's row, then wait
    until every other domain's event in flight has committed (its progress
    moved), or none is, or it is settling too.  STALL if that takes longer
    than the stall limit; ABORT ends it."""
    store(dctl, ndom * NPCTL + PCHECKED, 1)
    store(dctl, d * NPCTL + PSETTLE, 1)
    inf = float_bits(INF)
    for e in range(ndom):
        if e == d:
            continue
        p0 = load(dctl, e * NPCTL + PPROG)
        t0 = cycles()
        while load(dctl, e * NPCTL + PINFL) != inf and load(dctl, e * NPCTL + PPROG) == p0 \
                and load(dctl, e * NPCTL + PSETTLE) == 0:
            if load(ctrl, ABORT) != 0:
                return OK
            if cycles() - t0 > stall_cycles:
                return STALL
            cpu_relax()
    return OK


@kernel(inline=True)
def _publish_pool(dctl, d, tour_t, tour_s, seen_v, seen_i, seen_t):
    """Under d's lock, after its queue changed: its clock, a new version, and
    the root as this thread now sees it."""
    r = tour_s[1]
    t = tour_t[1] if r >= 0 else INF
    store(dctl, d * NPCTL + PCLOCK, float_bits(t))
    v = dctl[d * NPCTL + PVER] + 1
    store(dctl, d * NPCTL + PVER, v)
    seen_v[d] = v
    seen_i[d] = r
    seen_t[d] = t


@kernel
def pool_worker(me, nthr, parts, step, tree, nbrs, evq, jour, cfg, st, locks, pst, doms, ctrl,
                dctl, tctl, window, stall_cycles):
    """Thread ``me`` of ``nthr``: claims domains and runs their events until the
    step is done.  ``pst = (hops, wt, sdom, seen)``: per slot, the domain
    masks and the checked and exposed marks (``kernels.hop2``,
    ``expose_pair``), the latest event time on it (float bits, -1 before
    any) and its domain; ``seen``:
    per thread and domain, a queue version and the root then (slot, time);
    ``doms = (dlo, dhi, dtour_t, dtour_s)``.  Returns its final status."""
    say_started(ctrl, me, nthr)
    ids = parts[7]
    noff, nent, xhead, xent, xnext, ctr = nbrs
    evt, evp, evc, tour_t_, tour_s_, hidden = evq
    jslot = jour[0]
    logt = jour[3]
    dt = cfg[0][P_DT]
    dtb = float_bits(dt)
    hops, wt, sdom, seen = pst
    marked = hops[2]
    dlo, dhi, dtour_t, dtour_s = doms
    ndom = dlo.shape[0]
    cur = -1
    # each domain's root as this thread last saw it under the domain's lock, and
    # the queue's version then: while the version holds, the root holds
    seen_v = seen[0][me]
    seen_i = seen[1][me]
    seen_t = seen[2][me]
    seen_v[:] = -1
    # under "runs", per own domain: the domain that held back its root event
    # (-1: none), that event's time (float bits) and the queue's version then
    bx = seen[3][me]
    bt = seen[4][me]
    bv = seen[5][me]
    bx[:] = -1
    tried = np.int64(0)  # domains whose next event was blocked since the last event or wait
    oclock = -INF
    waiting = False
    nblk = 0
    wait_from = 0
    checked = 0
    strict = False
    seen = -1
    rng = load(ctrl, JITTER) * (2 * me + 1)
    nowait = load(ctrl, NOWAIT) != 0
    own = load(dctl, (ndom + 1 + me) * NPCTL + POWN)
    allowed = load(dctl, (ndom + 1 + me) * NPCTL + PALLOW)
    runs = load(dctl, (ndom + 1 + me) * NPCTL + PRUNS) != 0
    d = 0
    i = 0
    p = -1
    j = -1
    t = 0.0
    tb = float_bits(t)
    w = np.int64(0)
    wall = np.int64(0)
    late = False
    while True:
        if load(ctrl, ABORT) != 0:
            if cur >= 0:
                store(dctl, cur * NPCTL + POWNER, -1)
            return OK
        blocked = False
        x = -1  # the domain that held the pick back, if one did
        jroom = journal_room(st, ctr, jslot.shape[0], nthr)
        if not jroom or (logt.shape[0] > 0 and ctr[LCOUNT] + nthr + 1 > logt.shape[0]):
            if cur >= 0:
                store(dctl, cur * NPCTL + POWNER, -1)
                cur = -1
            if _idle(tctl, nthr):
                _fail(ctrl, NEED_LOG if jroom else NEED_JOURNAL)
                return OK
            blocked = True
        if not blocked and cur < 0:
            held = False
            if runs:
                cur, held = _pick_own(dctl, own, tried, dtb, bx, bt, bv)
            else:
                cur = _claim(dctl, ndom, me, dtb, tried, own, allowed)
            if cur < 0:
                if held:
                    tried = 0  # own domains held back: wait, then look again
                elif tried != 0:
                    # every free domain was tried since the last event or wait:
                    # wait once, then try them all again
                    tried = 0
                elif _done(dctl, tctl, ndom, nthr, dtb):
                    return OK
                blocked = True
        if not blocked:
            d = cur
            if load(dctl, d * NPCTL + PVER) == seen_v[d]:
                # the queue has not changed since this thread last read its root
                # (a change that begins now comes after this read, as if the lock
                # had been taken just before it): no lock round trip
                i = seen_i[d]
                t = seen_t[d]
            else:
                spin_lock(dctl, d * NPCTL + PLOCK)
                i = dtour_s[d][1]
                t = dtour_t[d][1] if i >= 0 else INF
                seen_v[d] = dctl[d * NPCTL + PVER]
                spin_unlock(dctl, d * NPCTL + PLOCK)
                seen_i[d] = i
                seen_t[d] = t
            if rng != 0:  # fault injection: widens the gap a stale pick comes through
                rng = _pause(rng)
            if i < 0 or not t < dt:
                if runs:  # its clock was behind the root: the others first
                    tried |= np.int64(1) << d
                else:
                    store(dctl, d * NPCTL + POWNER, -1)
                cur = -1
                continue
            tb = float_bits(t)
            p = evp[i]
            j = p >> 5 if p >= 0 else -1
            w = hop2(hops, sdom, noff, nent, i)
            if j >= 0:
                w |= hop2(hops, sdom, noff, nent, j)
            # near a pair the masks do not know (marked, ``kernels.expose_pair``):
            # wait also for the domains the marks name, not for every domain
            mark = load(marked, i)
            if j >= 0:
                mark |= load(marked, j)
            strict = mark != 0
            w |= mark
            w &= ~(np.int64(1) << d)
            # late: not after an event this domain already ran (equal times
            # included: the check then also sees the order of equal keys)
            late = tb <= dctl[d * NPCTL + PHIGH]
            # every other domain the event waits for: its commit checks them (under
            # "runs", the other threads' domains only: this thread's own are
            # ordered by its picks alone, and an event of another thread that
            # writes or reads what this one does puts that thread's domain in
            # these masks)
            wall = w & ~own if runs else w
            if runs and not strict and w & own != 0:
                # "runs": this thread alone runs its own domains, so they are
                # ordered by their clocks alone (lines no other thread writes but
                # to hand one an event), and the event is interior unless it also
                # waits for another thread's domains: no published times, no
                # second look, no check at its commit (``wall``)
                x = _blocker(dctl, dtour_t, dtour_s, ids, w & own, tb, t, ids[i])
                blocked = x >= 0
                w &= ~own
            if blocked:
                pass  # held back by one of its own domains
            elif w == 0 and not strict:
                if t > oclock + window:
                    oclock = bits_float(_others_clock(dctl, d, ndom))
                    blocked = t > oclock + window
                if not blocked:
                    store(dctl, d * NPCTL + PINFL, tb)
                    if wt[i] < tb:
                        wt[i] = tb
                    if j >= 0 and wt[j] < tb:
                        wt[j] = tb
            else:
                if not nowait:
                    x = _blocker(dctl, dtour_t, dtour_s, ids, w, tb, t, ids[i])
                    blocked = x >= 0
                if not blocked:
                    # in flight, and the event's time on what it writes, each with a
                    # full fence; then look again: a thread that passed its own look
                    # before these stores is seen now, or sees them (and if its
                    # event comes first, its check finds this one's time)
                    store(dctl, d * NPCTL + PINFL, tb)
                    fetch_max(wt, i, tb)
                    if j >= 0:
                        fetch_max(wt, j, tb)
                    if not nowait and _blocker(dctl, dtour_t, dtour_s, ids, w, tb, t,
                                               ids[i]) >= 0:
                        store(dctl, d * NPCTL + PINFL, float_bits(INF))
                        blocked = True
                    elif not nowait and (evt[i] != t or evp[i] != p):
                        # a stale pick: since the root was read, another thread's event
                        # with i as its partner has committed (the look just passed), so
                        # i has a new event.  Running the old one would be wrong, skipping
                        # it is not: withdraw and read the root again (the writer's own
                        # commit checks its order); counted as a blocked pick.  The times
                        # published on i and j stay: a time too late can make a check
                        # fail, never pass (README, Threads).
                        store(dctl, d * NPCTL + PINFL, float_bits(INF))
                        st[S_BLOCKED] += 1
                        continue
            if blocked:
                st[S_BLOCKED] += 1
                if runs and x >= 0:
                    bx[d] = x
                    bt[d] = tb
                    bv[d] = seen_v[d]
                if not runs:
                    store(dctl, d * NPCTL + POWNER, -1)
                cur = -1
                # try the other free domains before any wait: a yield after every
                # blocked pick cost more than the waits themselves (README, Benchmarks)
                tried |= np.int64(1) << d
                if x >= 0 and (own >> x) & 1 == 0 and not runs:
                    # held back by another thread's domain: ask that thread to
                    # run it (measured on the bed: README, Benchmarks "Asking")
                    _ask(dctl, tctl, ndom, nthr, me, x)
                continue
        if blocked and runs and nblk < RUNS_SPINS:
            # every own domain waits: spin a little before any yield (a system
            # call); the thread that holds them back is at work
            c0 = cycles()
            for _ in range(RUNS_PAUSES):
                cpu_relax()
            nblk += 1
            st[S_WAIT] += cycles() - c0
            continue
        if blocked:
            wait_from, checked, seen, nblk, stalled = wait_blocked(
                dctl, ndom, NPCTL, PPROG, st, waiting, wait_from, checked, seen, nblk,
                stall_cycles)
            waiting = True
            if stalled:
                _fail(ctrl, STALL)
                return STALL
            continue
        waiting = False
        nblk = 0
        tried = np.int64(0)
        store(tctl, me * NTCTL + TFLIGHT, 1)
        if rng != 0:
            rng = _pause(rng)
        # one event in TIME_EVERY of each domain is timed (its first among them)
        nev = dctl[d * NPCTL + PNEV]
        dctl[d * NPCTL + PNEV] = nev + 1  # d is this thread's: a plain write
        timed = nev % TIME_EVERY == 0
        c0 = cycles() if timed else 0
        check = wall != 0 or late or strict
        r0 = st[S_REACHOUT]
        if evt[i] != t or evp[i] != p:
            # i's event changed since it was read, and after the last look: another
            # thread wrote i out of order (only without waiting: ``NOWAIT``)
            st[S_VIOL] += 1
            status = VIOLATION
            jw = -1
        else:
            status, jw = process_event(i, t, parts, step, tree, nbrs, evq, jour, cfg, st,
                                       locks)
        if timed:  # it stands for TIME_EVERY events
            spent = (cycles() - c0) * TIME_EVERY
            st[S_CONC] += spent
            dctl[d * NPCTL + PCYC] += spent
        if status == OK and st[S_REACHOUT] > r0:
            # a pair found by this event broke the masks (``expose_pair``): this
            # event commits once every event that began before that could see
            # the marks has committed (or is settling too), so each of those
            # checks by the marks at its commit, or has published its times
            check = True
            st[S_REACHOUT] = r0  # not a violation here (the engine counts checked steps)
            status = _settle(dctl, ctrl, d, ndom, stall_cycles)
        st[S_CLAIMS] += 1
        if rng != 0:
            rng = _pause(rng)
        # commit: the two domains' locks in a fixed order (the first is a fence
        # before the check)
        e = sdom[jw] if jw >= 0 else d
        a = min(d, e)
        b = max(d, e)
        spin_lock(dctl, a * NPCTL + PLOCK)
        if b != a:
            spin_lock(dctl, b * NPCTL + PLOCK)
        if status == OK and (check or load(marked, i) != 0 or (j >= 0 and load(marked, j) != 0)):
            if _later_near(wt, noff, nent, xhead, xent, xnext, i, tb) or (
                    j >= 0 and _later_near(wt, noff, nent, xhead, xent, xnext, j, tb)):
                st[S_VIOL] += 1
                status = VIOLATION
        lo = dlo[d]
        hi = dhi[d]
        if e == d and jw >= 0:
            update_queue_pair(dtour_t[d], dtour_s[d], evt, ids, hidden, lo, hi, i, jw)
        else:
            update_queue(dtour_t[d], dtour_s[d], evt, ids, hidden, lo, hi, i)
            if jw >= 0:
                update_queue(dtour_t[e], dtour_s[e], evt, ids, hidden, dlo[e], dhi[e], jw)
        # progress first: a look that sees the new clocks then sees it too (_done)
        store(dctl, d * NPCTL + PPROG, load(dctl, d * NPCTL + PPROG) + 1)
        if e != d:
            _publish_pool(dctl, e, dtour_t[e], dtour_s[e], seen_v, seen_i, seen_t)
        _publish_pool(dctl, d, dtour_t[d], dtour_s[d], seen_v, seen_i, seen_t)
        store(dctl, d * NPCTL + PINFL, float_bits(INF))
        store(dctl, d * NPCTL + PSETTLE, 0)
        if tb > dctl[d * NPCTL + PHIGH]:
            dctl[d * NPCTL + PHIGH] = tb
        if b != a:
            spin_unlock(dctl, b * NPCTL + PLOCK)
        spin_unlock(dctl, a * NPCTL + PLOCK)
        if status != OK:
            # posted while still in flight: a thread that waits for every thread
            # to be idle (a full journal or log: ``_idle``) must not post its
            # status first, or a violation would be lost and the step resumed,
            # not redone
            _fail(ctrl, status)
            store(tctl, me * NTCTL + TFLIGHT, 0)
            return status
        store(tctl, me * NTCTL + TFLIGHT, 0)
        if runs:
            cur = -1  # the earliest of its own domains next
        else:
            cur = _answer(dctl, tctl, me, cur, st)


@kernel
def pool_rows(pctl, nd, dtour_t, dtour_s, own, allowed, runs, ctrl, jitter, nowait):
    """The pool's shared words at the start of a ``Workers.run_pool`` call:
    the workers' control words (``ctrl``: all 0 but the fault injection's
    ``JITTER`` seed and ``NOWAIT``); each domain's clock (its queue's root,
    INF when empty), nothing in flight, no owner, no progress, lock and
    version 0 (its latest event time and its counts, ``PHIGH`` on, are
    kept: a call after a grown journal resumes the step); each thread's
    masks (``claim_masks``) and ``runs``.  A kernel: as array operations
    these took 0.085 ms of a ring pool step, with the pool thread idle."""
    for c in range(ctrl.shape[0]):
        ctrl[c] = 0
    ctrl[JITTER] = jitter
    ctrl[NOWAIT] = nowait
    inf = float_bits(INF)
    for d in range(nd):
        for c in range(PHIGH):
            pctl[d, c] = 0
        i = dtour_s[d, 1]
        pctl[d, PCLOCK] = float_bits(dtour_t[d, 1]) if i >= 0 else inf
        pctl[d, PINFL] = inf
        pctl[d, POWNER] = -1
        pctl[d, PSETTLE] = 0
        pctl[d, PPROG] = 0
    for k in range(own.shape[0]):
        pctl[nd + 1 + k, POWN] = own[k]
        pctl[nd + 1 + k, PALLOW] = allowed[k]
        pctl[nd + 1 + k, PRUNS] = runs


@kernel
def hold_until_abort(dctl, ctrl):
    """Tests: the thread holding domain 0 (taken for it before the workers
    start: ``Workers.run_pool``) never runs or releases it (under "runs":
    never runs its own domains), so the others can only stall — and must
    say so."""
    while load(ctrl, ABORT) == 0:
        sched_yield()
    store(dctl, POWNER, -1)
    return OK


def pool_start(n, keep, tracked=0):
    """The step-start values of a pool step, ``(vel (n, 3), ncoll (n,),
    tlast (tracked,))``, what ``restore_start`` puts back when the step is
    redone: filled by the storage permutation (``engine._permute_share``),
    which gathers those arrays through them.  They and the per-slot arrays
    of ``pool_state`` live in the dict ``keep`` from one step to the next
    (fresh ones each step cost page faults: ring N = 2e5, 1.96-2.34 ms a
    step with its 10 MB new)."""
    if keep.get("n") != n or len(keep["start"][2]) != tracked:
        # sdom int32: also ``grow``'s lock_of, so one array serves both
        keep.update(n=n, sdom=np.empty(n, np.int32), hops=np.empty((4, n), np.int64),
                    wt=np.empty(n, np.int64),
                    start=(np.empty((n, 3)), np.empty(n, np.int64), np.empty(tracked)))
    return keep["start"]


def pool_state(n, nd, threads, keep, tracked=0):
    """The per-slot arrays of a pool step, ``(hops, wt, sdom)`` (filled by
    ``init_domain``), with the threads' rows of seen queue roots, and
    ``grow``'s view ``(sdom, -, -, hops)``, kept in ``keep`` (``pool_start``;
    the rows of seen roots are zeroed here)."""
    pool_start(n, keep, tracked)
    sdom, wt, hops = keep["sdom"], keep["wt"], keep["hops"]
    locks = (sdom, np.zeros(1, np.int64), np.zeros(0, np.int32), hops)
    width = -(-nd // 8) * 8  # whole cache lines: a row is one thread's
    if keep.get("seen_shape") != (threads, width):
        keep.update(seen_shape=(threads, width), seen=tuple(
            cache_aligned((threads, width), np.float64 if k == 2 else np.int64)
            for k in range(6)))
    seen = keep["seen"]
    for a in seen:
        a.fill(0)
    return (hops, wt, sdom, seen), locks


def restore_start(vel, ncoll, tlast, start):
    """Put back the step-start values ``pool_start`` kept (a pool step that is
    redone).  Not the undo journal (``kernels.journal``): in a pool step with
    events out of order two threads may write one particle at once, and then
    a particle's journal entry may hold the other thread's half-done write, or
    an increment of its collision count may be lost (measured: 26 of 300
    no-wait runs of the marble dish, 20 steps each, rolled back to a wrong
    state; 23 ended away from the sequential result)."""
    vel0, ncoll0, tlast0 = start
    vel[...] = vel0
    ncoll[...] = ncoll0
    if tlast.shape[0] > 0:
        tlast[...] = tlast0


def claim_masks(claim, nd, nthr, adj=None, work=None):
    """Which of nd domains each of nthr pool threads claims first, and which
    it may claim at all (``Engine.pool_claim``): ``(own, allowed)``, two
    (nthr,) int64 arrays of domain masks, ``own`` within ``allowed``.

    * ``"earliest"``: any domain (own = allowed = all).
    * ``"home"``: its share of the domains in slot order (``home_range``)
      first, then any.
    * ``"runs"``: its run as for ``"band"``, and no other domain (a thread
      whose run is empty runs none); the engine then tells the workers
      never to claim (``Workers.run_pool``'s ``runs``).
    * ``"band"``: its run of the domains in slot order, cut at equal shares
      of ``work`` (nd,) (the engine passes each domain's cycles inside its
      events in the last step, ``PCYC``, sampled: ``TIME_EVERY``; equal
      shares without), and then only the domains next to that run: those
      holding a step-start candidate of one of its slots (``adj`` (nd,):
      each domain's ``domain_adjacency``).  A thread whose run is empty may
      claim any.
      The particles inside a run away from its edge are then written by one
      thread only.

    The runs are cut in a kernel (``_run_masks``): in Python they took 0.11
    ms of a ring pool step, with the pool thread idle.
    """
    own = np.empty(nthr, np.int64)
    allowed = np.empty(nthr, np.int64)
    if claim in ("band", "runs"):
        w = np.zeros(nd, np.int64) if work is None else np.asarray(work, np.int64)
        band = claim == "band"
        _run_masks(w, nthr, np.asarray(adj, np.int64) if band else w[:0], band, own, allowed,
                   np.empty(nd + 1, np.int64))
        return own, allowed
    full = (1 << nd) - 1
    if claim == "home":
        own[:] = [sum(1 << d for d in range(*home_range(k, nthr, nd))) for k in range(nthr)]
    elif claim == "earliest":
        own[:] = full
    else:
        raise ValueError(f"unknown claim {claim!r}")
    allowed[:] = full
    return own, allowed


@kernel
def _run_masks(work, nthr, adj, band, own, allowed, cum):
    """``claim_masks``' runs: run k of nthr ends at the domain edge nearest
    k/nthr of the total of ``work`` + 1 (the first such, in whole numbers),
    no earlier than run k - 1; ``adj`` (band only): each domain's
    neighbours; ``cum`` (nd + 1,): scratch."""
    nd = work.shape[0]
    cum[0] = 0
    for d in range(nd):
        cum[d + 1] = cum[d] + work[d] + 1
    full = (np.int64(1) << nd) - 1 if nd < 64 else np.int64(-1)
    prev = 0
    for k in range(nthr):
        end = nd
        if k < nthr - 1:
            best = 0
            bd = abs(cum[0] * nthr - cum[nd] * (k + 1))
            for q in range(1, nd + 1):
                dq = abs(cum[q] * nthr - cum[nd] * (k + 1))
                if dq < bd:
                    bd = dq
                    best = q
            end = max(best, prev)
        m = np.int64(0)
        near = np.int64(0)
        for d in range(prev, end):
            m |= np.int64(1) << d
            if band:
                near |= adj[d]
        own[k] = m
        allowed[k] = (m | near) if m != 0 or not band else full
        prev = end


def cost_points(work, dlo, dhi, cis, nthr):
    """Where a step's runs should end: the cost of slots 0..s-1 (float) at
    every domain edge s and at the slot nearest k/nthr of the total cost
    (k = 1..nthr-1), each domain's cycles ``work`` (nd,) shared over its
    slots by their collisions in the step (``cis``) plus one.  Returns
    ``(slots, costs, cuts)``: the slots (int64) and their costs (float64),
    each slot once (the edges in order, then any cut that is not an edge),
    and the cut slots (int64, one per k whose share falls in a domain with
    work).  Only the domains holding a cut are summed slot by slot (the
    ring, N = 2e5: a pass over every slot took 1-2 ms of a 25 ms step), all
    of it in a kernel (``_cost_points``; in Python 0.13 ms of a ring pool
    step, with the pool thread idle)."""
    nd = len(dlo)
    slots = np.empty(nd + nthr, np.int64)
    costs = np.empty(nd + nthr, np.float64)
    cuts = np.empty(max(nthr - 1, 0), np.int64)
    npt, ncut = _cost_points(np.asarray(work, np.float64), dlo, dhi, cis, nthr, slots, costs,
                             cuts, np.empty(nd + 1))
    return slots[:npt], costs[:npt], cuts[:ncut]


@kernel
def _cost_points(work, dlo, dhi, cis, nthr, slots, costs, cuts, cumd):
    """``cost_points`` into slots, costs, cuts; their counts.  ``cumd``
    (nd + 1,): scratch."""
    nd = work.shape[0]
    cumd[0] = 0.0
    for d in range(nd):
        cumd[d + 1] = cumd[d] + work[d]
    npt = 0
    for d in range(nd + 1):
        s = dlo[d] if d < nd else dhi[nd - 1]
        if npt > 0 and slots[npt - 1] == s:  # an empty domain: its edge once, the last cost
            costs[npt - 1] = cumd[d]
        else:
            slots[npt] = s
            costs[npt] = cumd[d]
            npt += 1
    ncut = 0
    for k in range(1, nthr):
        target = cumd[nd] * k / nthr
        q = np.searchsorted(cumd, target, side="right") - 1
        if q < 0 or q >= nd or not work[q] > 0:
            continue
        s, c = _nearest_cost(cis, dlo[q], dhi[q], cumd[q], work[q], target)
        if _find(slots, npt, s) < 0:
            slots[npt] = s
            costs[npt] = c
            npt += 1
        cuts[ncut] = s
        ncut += 1
    return npt, ncut


@kernel(inline=True)
def _find(a, n, x):
    """The first k < n with a[k] == x; -1 if none."""
    for k in range(n):
        if a[k] == x:
            return k
    return -1


@kernel
def _nearest_cost(cis, lo, hi, base, work, target):
    """The slot s in lo..hi (its edge included) whose cost ``base`` plus
    ``work`` shared over slots lo..hi-1 by ``cis`` plus one, summed over
    slots lo..s-1, is nearest ``target`` (the first such), and that cost.
    One pass to sum, one to look: the numpy of it (a float copy, a cumulative
    sum, an argmin over a domain's ~12,500 slots) took 0.17 ms a step on the
    ring.  The sums are of whole numbers below 2**53: exact in any order."""
    total = 0.0
    for s in range(lo, hi):
        total += cis[s] + 1.0
    scale = work / total
    best = lo
    cbest = base
    acc = 0.0
    for s in range(lo, hi + 1):
        c = base + acc * scale
        if abs(c - target) < abs(cbest - target):
            best = s
            cbest = c
        if s < hi:
            acc += cis[s] + 1.0
    return best, cbest


def cost_cut(dlo, dhi, cost):
    """Domains (dlo, dhi) with one more edge at each cut slot of ``cost =
    (slots, costs, cuts)`` (``cost_points``) inside a domain, that domain
    split in two, and each domain's cost (int64, rounded); (dlo, dhi, None)
    unchanged if an edge has no cost in ``slots`` (another cut of the slots
    than the last step's).  In a kernel (``_cost_cut``): in Python 0.07 ms
    of a ring pool step."""
    slots, costs, cuts = cost
    out = np.empty((4, len(dlo) + len(cuts)), np.int64)
    m = _cost_cut(dlo, dhi, slots, costs, cuts, out[0], out[1], out[2], out[3])
    if m < 0:
        return dlo, dhi, None
    return out[0, :m], out[1, :m], out[2, :m]


@kernel
def _cost_cut(dlo, dhi, slots, costs, given, lo, hi, work, cuts):
    """``cost_cut`` into lo, hi, work; the domains' count, or -1 when an
    edge has no cost.  The cuts ``given`` are taken in slot order, each
    once, sorted into ``cuts`` (scratch; ``cost_points`` gives them in
    order already)."""
    for k in range(given.shape[0]):
        x = given[k]
        r = k
        while r > 0 and cuts[r - 1] > x:
            cuts[r] = cuts[r - 1]
            r -= 1
        cuts[r] = x
    m = dlo.shape[0]
    for q in range(m):
        lo[q] = dlo[q]
        hi[q] = dhi[q]
    for k in range(given.shape[0]):
        s = cuts[k]
        if k > 0 and s == cuts[k - 1]:
            continue
        if m >= MAX_DOMAINS:
            break
        for q in range(m):
            if lo[q] < s < hi[q]:  # domain q becomes q (lo..s) and q + 1 (s..hi)
                for r in range(m, q + 1, -1):
                    lo[r] = lo[r - 1]
                    hi[r] = hi[r - 1]
                hi[q + 1] = hi[q]
                lo[q + 1] = s
                hi[q] = s
                m += 1
                break
    npt = slots.shape[0]
    for q in range(m):
        a = _find(slots, npt, lo[q])
        b = _find(slots, npt, hi[q])
        if a < 0 or b < 0:
            return -1
        work[q] = np.int64(np.rint(costs[b] - costs[a]))  # half to even, as round()
    return m
