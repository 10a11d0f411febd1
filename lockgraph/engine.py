"""One step of the collision engine (sequential), driving the numba kernels.

A step of length dt:

1. half kick of Hill's equations (shearing sheet only; done in the same
   pass as the search radii, after a speed sample of the kicked velocities);
2. search radii, kD-tree over the step-start positions (the *anchors*),
   particles re-stored in tree order, candidate pairs by two-argument recursion;
3. every particle's first event predicted; events processed strictly in
   (time, particle id) order — advance the two particles, resolve, predict
   both again against their candidates and walls; a particle whose velocity
   rose past its search radius widens it and searches the tree again;
4. everyone drifts to the step end; periodic wrap; second half kick.

If a step cannot finish (an internal pool is full, inelastic collapse, a
search radius larger than the periodic box allows) the drift phase is undone
from the anchors and the undo journal, so the state is exactly what it was
after the first half kick; errors then also undo that kick (to rounding:
the inverse rotation is not exact, a few ulps of the velocities).
"""
import itertools
import math
import numbers
import time

import numpy as np

from . import kernels as K
from ._jit import kernel
from . import locks as L
from .atomics import claim_from_ends, fetch_add, load, next_task, store
from .pool import (MAX_DOMAINS, NPCTL, PCHECKED, PCYC, PHIGH, REDO_WINDOW, claim_masks,
                   cost_cut, cost_points, init_domains, pool_start, pool_state, restore_start,
                   two_hop_masks, work_split)
from .parallel import (ABORT, INTERIOR, NCTRL, AlignedScratch, Workers, cache_aligned,
                       classify_ranges, classify_regions, cycles_per_second, pause_spin,
                       say_started)
from .domains import DOMAIN_DISH, wrap
from .errors import InelasticCollapseError, InputError, SimulationError, StepTooLargeError
from .events import BUCKET_BITS, tournament_size
from .forces import kick_hill
from .neighbors import JCOUNT, NCTR, build_csr
from .restitution import CollapseGuard, VelocityGuard
from .schedule import EventSchedule
from .state import State
from .tree import (END, NLIST, NTOP, SELF_IMAGE, START, bound_node, count_nodes, identity, median_of,
                   node_bounds, pair_search_claimed, permute_mat3, permute_rows, permute_vec,
                   resort, resort_stealing, search_frontier, skeleton, subtree_bounds)

LOCKS = ("none", "grid", "grid3d", "graph")
NO_SLEEP = np.zeros(0)  # _finish's sleep states without sleeping grains (read only)
# ``_permute_share``'s step-start values when the step is not a pool step (read only)
NO_START = (np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0))
POLICIES = ("exact", "paper")
SCHEDULES = ("parallel", "auto", "pool")
# tasks per thread in the claimed phases (Engine.balance, _claimed)
BALANCE = 4
# The re-sort and the pair search are shared out while they run, not in fixed
# halves: a core of this machine is at times much slower than the other (the
# same 5 ms task took 5.07 ms median, 6.73 ms p90 on one core; 5.00 / 5.39 on
# the other), and a fixed half waits for it.  Ring N = 2e5, two threads, the
# fixed halves and these stepping in turn in one process (three runs of 15
# steps): search phase 30.6-31.6 -> 27.2-28.6 ms, step 38.6-40.0 -> 35.0-37.8.
# Re-sort: each subtree's nodes this many levels down (at most) are taken by
# whichever thread is free, but none smaller than STEAL_MIN_SLOTS slots (the
# levels above stay with the subtree's thread: ring, 2.6 of 11.3 ms).
STEAL_LEVELS = 5
STEAL_MIN_SLOTS = 1024
# Pair search: about this many tasks per thread (nodes of N / (SEARCH_TASKS T)
# slots at most, and the pairs between them), claimed in the recursion's order.
SEARCH_TASKS = 32
# How far an interior event may run ahead of the other threads' domains, in a
# domain's mean times between events (``window_events``).  Under the pool 32:
# on the bed, paired in one process against 8 (rounds of 3 steps), the step
# 0.958-0.980 the time with 8 with the threads' cores far apart (30 and 26
# rounds) and 0.931 near (4 rounds); 16: 0.983 far; 128 and unbounded: one
# repair in 90 steps each, none with 32 in 180 (README, Benchmarks: "Slab
# domains, and atomic maxima read first").  Under lock regions 8.
POOL_WINDOW = 32.0
LOCK_WINDOW = 8.0
# The pool's domains are slabs (``Engine._slab_levels``) in a scene whose
# longest side is at least this many times its second: there the tree's top
# two levels split along that side anyway, so slabs add few faces between
# domains (the bed, 2.4: step 4.6 % faster; the ring's square sheet, 1.0:
# events 3 % slower with slabs).
SLAB_ASPECT = 2.0
PH_SEARCH, PH_EVENTS, PH_STEP = range(3)  # Engine.phase_s
# the per-particle arrays the storage permutation moves, in the order of its
# tasks (``_permute_share``; then ``tlast`` when guarded)
PERMUTED = ("pos", "vel", "rad", "mass", "ncoll", "reach", "ids")
STATUS_NAMES = {K.OK: "ok", K.NEED_JOURNAL: "need journal", K.POOL_OVERFLOW: "pool overflow",
                K.COLLAPSE: "collapse", K.SIGMA_TOO_LARGE: "sigma too large", K.CHUNK: "chunk", K.NEED_LOG: "need log", K.VIOLATION: "violation",
                K.STALL: "stall"}

# chunks a thread of the per-particle passes (the first phase's, the step
# end), claimed: a thread that starts late, or does other work first (the
# top nodes' re-sort), takes fewer
CHUNKS = 16
# Each thread its own end.  On two threads every claimed per-slot phase of
# a step gives the first thread a run of slots from the front and the
# second one from the back (``atomics.claim_from_ends``): the first phase's
# chunks, the pair search's tasks, the step end and, under the pool, the
# first events and queues of the domains (``pool.init_domains``), as the
# pool's events give each thread its run of domains (``pool.claim_masks``:
# the first thread the lowest).
# So the lines of a thread's domains that the first events and the queues
# write are in its own core's caches when its events read them; taken in
# turn, half came from the other core's, at 3-4 times the cost when the
# host puts the two virtual CPUs on cores far apart
# (``benchmarks/host_probe.py``).  The storage permutation stays by arrays:
# by halves it took 1.3 ms longer on the ring.  README, Benchmarks: "Each
# thread its own end".


@kernel
def _finish(pos, vel, tl, dt, g, code, wp, omega, drift, slp, t_end, t_sleep, v_sleep):
    """Step end for a slice of particles: (with ``drift``) the rest of the way to
    the step end, real coordinates, grains falling asleep (``slp``: their sleep
    states, or empty), wrap, second half kick.  One compiled call, so a worker
    thread does not go back to Python (and the GIL) between them."""
    if drift:
        K.drift_all(pos, vel, tl, dt)
    K.leave_frame(pos, vel, tl, dt, g)
    if slp.shape[0] > 0:
        K.rest_sleepers(vel, slp, t_end, t_sleep, v_sleep)
    wrap(pos, vel, code, wp)
    if omega != 0.0:
        kick_hill(pos, vel, omega, 0.5 * dt)


@kernel
def _finish_claimed(me, nthr, ctl, pos, vel, tl, dt, g, code, wp, omega, drift, slp, t_end,
                    t_sleep, v_sleep, ctrl):
    """Thread ``me`` of ``nthr``'s share of the step end (``_finish``):
    chunks of the particles claimed with an atomic fetch-add on ``ctl[0]``
    (0 at the start) until none is left, so that the threads end together
    however late each started; on two threads from the two ends
    (``atomics.claim_from_ends``)."""
    say_started(ctrl, me, nthr)
    n = pos.shape[0]
    nchunks = CHUNKS * nthr
    r = 0
    while True:
        q = claim_from_ends(ctl[:1], me, nthr, r, nchunks)
        r += 1
        if q >= nchunks:
            return 0
        lo = n * q // nchunks
        hi = n * (q + 1) // nchunks
        _finish(pos[lo:hi], vel[lo:hi], tl[lo:hi], dt, g, code, wp, omega, drift, slp[lo:hi],
                t_end, t_sleep, v_sleep)  # slp empty (no sleeping grains): its slice too


# words of the first phase's control array (``_first_phase``): the re-sort of
# the nodes above the subtrees done (1) or failed (-1); the next chunk; on
# cache lines of their own
TOP_DONE, NEXT_CHUNK = 0, 8
NFIRST = 16


@kernel
def _first_phase(me, nthr, ctl, ctrl, pos, vel, rad, reach, par, extra, omega, h, reaches, tops,
                 tl, cis, xhead, ctr, hidden, perm, ntop, depth_split, fresh, vslots, vids,
                 stacks, nsplit, band, keys, subroots, steal_depth, below, nbelow, steal_ctl,
                 slab):
    """Thread ``me`` of ``nthr`` (the last one the calling thread) in a step's
    first phase.

    The last thread re-sorts the nodes above the threads' subtrees (``depth_split``
    levels, ``tree.resort``) while the others start on the per-particle
    passes; then every thread claims chunks of the particles (``ctl``'s
    NEXT_CHUNK; on two threads from the two ends) and clears their
    per-step arrays (``K.reset_step``) and, with ``reaches``, gives them
    Hill's kick for time h (omega and h nonzero: the step's first half
    kick) and their step-start reaches
    (``K.compute_reach``), the two largest of which go to ``tops[me]``;
    then, once the top nodes are done, re-sorts its subtrees
    (``tree.resort_stealing``: subtrees me, me + nthr, ...).  One call a
    thread and claimed chunks: the top nodes' re-sort takes 0.3-1.0 ms a
    step (ring N = 2e5), so fixed shares sized from the last step left one
    thread idle for a tenth of the phase.  Every chunk is claimed by a call
    that runs to its end, so no particle is left unkicked.  Returns 0, or -1
    if a work stack was short (or ``ctrl`` ABORT was set while waiting)."""
    say_started(ctrl, me, nthr)
    n = pos.shape[0]
    if me == nthr - 1:
        # root and depths as int64 values, never literals: numba compiles a
        # kernel again for each literal argument (~10 s each for resort)
        ok = resort(pos, perm, ntop, np.int64(0), depth_split, fresh, vslots[me], vids[me],
                    stacks[me], nsplit, band, keys, slab)
        store(ctl, TOP_DONE, 1 if ok >= 0 else -1)
    top = tops[me]  # zeros: compute_reach takes in each chunk's reaches
    nchunks = CHUNKS * nthr
    r = 0
    while True:
        q = claim_from_ends(ctl[NEXT_CHUNK:NEXT_CHUNK + 1], me, nthr, r, nchunks)
        r += 1
        if q >= nchunks:
            break
        lo = n * q // nchunks
        hi = n * (q + 1) // nchunks
        K.reset_step(tl[lo:hi], cis[lo:hi], xhead[lo:hi], ctr, hidden[lo:hi])
        if reaches:
            if omega != 0.0 and h != 0.0:
                kick_hill(pos[lo:hi], vel[lo:hi], omega, h)
            K.compute_reach(pos[lo:hi], vel[lo:hi], rad[lo:hi], reach[lo:hi], par, extra,
                            top)
    spins = 0
    while load(ctl, TOP_DONE) == 0:
        if load(ctrl, ABORT) != 0:
            return -1
        spins = pause_spin(spins)
    if load(ctl, TOP_DONE) < 0:
        return -1
    for k in range(me, subroots.shape[0], nthr):
        if resort_stealing(k, pos, perm, ntop, subroots[k], steal_depth, fresh, vslots[k],
                           vids[k], stacks[k], nsplit, band, keys, below, nbelow,
                           steal_ctl, slab) < 0:
            return -1
    return 0


@kernel
def _permute_share(me, nthr, claim, pos, vel, rad, mass, ncoll, ids, reach, tlast, perm, buf,
                   anc, start):
    """Thread ``me`` of ``nthr``'s share of the storage permutation
    (``Engine._permute``), an array a task (``PERMUTED``, and ``tlast`` if it
    is per particle; ``atomics.next_task``).  ``buf`` (N,) float64 is this
    thread's gather buffer, seen as each array's type.  The positions are
    gathered through ``anc`` (N, 3), which is left holding them: the step's
    anchors.  ``start = (vel0, ncoll0, tlast0)``, a pool step's step-start
    values (``pool.pool_start``), or empty: when full, the velocities,
    collision counts and guard clocks are gathered through them, which
    leaves the copy a repair puts back (``pool.restore_start``) without a
    pass of its own (until 2026-12-07 ``save_start`` copied them with each
    domain's first events; README, Benchmarks: "The pool's step start by
    slices")."""
    n = perm.shape[0]
    ntasks = 8 if tlast.shape[0] == n else 7
    vel0, ncoll0, tlast0 = start
    keep = ncoll0.shape[0] == n
    r = 0
    while True:
        q = next_task(claim, me, nthr, r)
        r += 1
        if q >= ntasks:
            return 0
        # the largest first and the smallest (4 bytes) last, so that the
        # threads' last tasks end close together
        if q == 0:
            permute_rows(pos, perm, anc)
        elif q == 1:
            if keep:
                permute_rows(vel, perm, vel0)
            else:
                permute_mat3(vel, perm, buf)
        elif q == 2:
            permute_vec(rad, perm, buf)
        elif q == 3:
            permute_vec(mass, perm, buf)
        elif q == 4:
            if keep:
                permute_vec(ncoll, perm, ncoll0)
            else:
                permute_vec(ncoll, perm, buf.view(np.int64))
        elif q == 5:
            permute_vec(reach, perm, buf)
        elif q == ntasks - 1:
            permute_vec(ids, perm, buf.view(np.int32)[:n])
        elif keep and tlast0.shape[0] == n:
            permute_vec(tlast, perm, tlast0)
        else:
            permute_vec(tlast, perm, buf)


@kernel
def _permute_and_anchor(me, nthr, claim, arrived, ctrl, pos, vel, rad, mass, ncoll, ids, reach,
                        tlast, perm, buf, anc, ntop, subroots, nbox, nreach, order, start):
    """Thread ``me`` of ``nthr``: its share of the storage permutation
    (``_permute_share``, which leaves the anchors, the step-start positions,
    in ``anc``); then, once every thread is done with it (``arrived``:
    one word, 0 at the start), for its subtrees (me, me + nthr, ...) the
    permutation of their slots back to the identity and the bounds of their
    nodes.  One call,
    not a phase each: a phase's hand-over to the pool thread and back costs
    0.1-0.2 ms.  Returns 0, or -1 if ``ctrl`` ABORT was set while waiting."""
    say_started(ctrl, me, nthr)
    _permute_share(me, nthr, claim, pos, vel, rad, mass, ncoll, ids, reach, tlast, perm, buf,
                   anc, start)
    fetch_add(arrived, 0, 1)
    spins = 0
    while load(arrived, 0) < nthr:
        if load(ctrl, ABORT) != 0:
            return -1
        spins = pause_spin(spins)
    for k in range(me, subroots.shape[0], nthr):
        nd = subroots[k]
        lo = ntop[nd, START]
        hi = ntop[nd, END]
        identity(perm[lo:hi], lo)
        subtree_bounds(anc, reach, ntop, nd, nbox, nreach, order[k])
    return 0


@kernel
def _search_share(me, nthr, ctrl, anc, reach, ntop, nbox, nreach, tasks, ntasks, claim, img_pos,
                  out_a, out_e, stack, work, seg):
    """Thread ``me`` of ``nthr``'s share of the pair search
    (``tree.pair_search_claimed``, into row me of ``out_a``, ``out_e``),
    saying so as it begins when it is the calling thread's (``STARTED``,
    ``Workers.map``)."""
    say_started(ctrl, me, nthr)
    return pair_search_claimed(anc, reach, ntop, nbox, nreach, tasks, ntasks, claim, img_pos,
                               out_a[me], out_e[me], stack, work, seg, me, nthr)


class _Option:
    """An engine attribute that holds one of a few strings (REBOUND-style: an
    unknown value raises an InputError naming the attribute, and the value
    is kept)."""

    def __init__(self, *options):
        self.options = options

    def __set_name__(self, owner, name):
        self.name = name
        self.slot = "_" + name

    def __get__(self, obj, objtype=None):
        return self if obj is None else getattr(obj, self.slot)

    def __set__(self, obj, value):
        if value not in self.options:
            raise InputError(self.name, "must be " + " or ".join(map(repr, self.options))
                             + f" (got {value!r})")
        setattr(obj, self.slot, value)


class Engine:
    """Sequential event-driven hard-sphere engine working on a private copy of a state.

    Parameters
    ----------
    state : State
    physics : Physics
    dt : float, s — step length (> 0).
    skin : float — extra search radius, in units of the median speed times dt.
    leaf_size : int — particles per kD-tree leaf.
    rebuild_every : int — build the tree from scratch every this many steps;
        in between, particles are re-sorted into the last tree's nodes.
    collapse_limit : int — collisions of one particle within one step that are
        taken as inelastic collapse.
    The largest overlap among candidate pairs is measured at every step start
    (free: the first predictions see every pair) and, when asked, at a step's
    end (``step(check_end=True)``; the simulation does it after its last step).
    record_events : bool — keep a log of every resolved collision (``events()``).
    copy : bool — work on a copy of the state's arrays (default).  With
        ``copy=False`` the engine takes the arrays over (no second copy in
        memory); the State object passed in must not be used afterwards.
    threads : int — worker threads for the events (1: sequential).
    lock : "none" | "grid" | "grid3d" | "graph" — lock regions for threads > 1.
    scale : float — the lock graph's SCALE.
    policy : "exact" | "paper" — exact: causality violations are detected and
        the step redone sequentially, so results equal the sequential engine's
        bit for bit; paper: the paper's rule, violations only counted.
    schedule : "parallel" | "auto" — with threads > 1, where a step's events run:
        always on the worker threads, or (exact policy only) on the worker
        threads or the calling thread alone, whichever measured faster lately
        (``schedule.EventSchedule``; the result is the same bit for bit).  The
        other phases of a step run on all threads either way.  "pool" (exact
        policy): ``pool_domains`` domains (4 a thread by default) that the
        threads take in turn, events waiting by particle (``lockgraph/pool.py``;
        how the domains are cut and claimed: ``pool_split``, ``pool_claim``);
        ``lock`` and ``scale`` are not used.
    window_events : float or None — how far an interior event may run ahead
        of the other threads' domains, in units of a domain's mean time between
        events.  None: ``POOL_WINDOW`` (32) under ``schedule="pool"``, 8 else.
    stall_seconds : float — a step in which no thread completes an event for
        this long stops with an error (never a hang).
    balance : int or None — with threads > 1, tasks per thread in the phases
        whose tasks the threads claim in turn (the first predictions of a step
        whose events run on one thread, the storage permutation): default 4;
        0 gives each thread one fixed share.  The result is the same bit for
        bit either way.
    trace_locks : list of (lock, scale) or None — record a trace for the
        scheduling replay (sequential runs only): every event's particles, time
        and cost, and each step's lock regions for each listed lock structure.
    """

    # How schedule "pool" cuts a step's slots into domains: "tree" (default)
    # into the kD-tree's nodes of one depth (equal counts of particles), or
    # "work" into runs of about equal work by each particle's collisions in
    # the last step (``pool.work_split``; the first step, and a changed
    # domain count, as "tree").  On the 50,000-grain bed the first half of
    # the tree's slots held 75-84 % of a step's collisions.
    pool_split = _Option("work", "tree")
    # Which domain a pool thread runs (``pool.claim_masks``): "runs" (default
    # since 2026-12-06) the earliest of its own run of domains (cut as for
    # "band"), never another's, with no claims at all (README, Benchmarks:
    # "Own runs, no claims"); "band" (the default from 2026-12-05) the
    # earliest free one of its own run of domains (cut
    # at equal shares of the cycles the last step spent inside its domains'
    # events) and, only when none of those can run, of the domains next to
    # that run, never others: the particles inside a run stay with one
    # thread (README, Benchmarks: "Band claims"); "earliest" the one with
    # the earliest clock; "home" the earliest of its own share of the
    # domains in slot order (``pool.home_range``) and, only when none of
    # those can run, the earliest of all (README, Benchmarks: "Own domains").
    pool_claim = _Option("runs", "band", "earliest", "home")
    # How a pool step is redone after a violation: "threads" (default since
    # 2026-12-05) first on the threads again, interior events held within
    # ``pool.REDO_WINDOW`` events of the other domains (the default window's
    # run-ahead is where the bed's violations came from), and on one thread
    # only if that attempt finds a violation too; "one" on one thread at once.
    pool_redo = _Option("threads", "one")
    # When schedule "pool" works out each slot's domain masks (``kernels.hop1``,
    # ``hop2``): "auto" (default) for every slot at the step start when the
    # last step had more events than particles, else each at its first use;
    # "start"; "first_use".  At first use a dense scene pays for them inside
    # its events, where they are computed from cold lines one slot at a time
    # (README, Benchmarks: "The pool on one thread, and its masks at the step
    # start").
    pool_masks = _Option("auto", "start", "first_use")

    def __init__(self, state, physics, dt, *, skin=0.5, leaf_size=16, collapse_limit=10000,
                 chunk_events=1 << 20, record_events=False, copy=True, rebuild_every=10,
                 threads=1, lock="graph", scale=4.0, policy="exact", schedule="parallel",
                 window_events=None, stall_seconds=60.0, trace_locks=None, balance=None):
        dt = float(dt) if not isinstance(dt, bool) else float("nan")
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError("dt", f"must be a finite number > 0 (got {dt!r})")
        if not (skin >= 0 and math.isfinite(skin)):
            raise InputError("skin", f"must be >= 0 (got {skin!r})")
        if not 1 <= int(leaf_size) <= 256:
            raise InputError("leaf_size", f"must be in 1..256 (got {leaf_size!r})")
        if int(collapse_limit) < 1:
            raise InputError("collapse_limit", f"must be >= 1 (got {collapse_limit!r})")
        self.physics = physics
        self.dt = dt
        self.skin = float(skin)
        self.leaf_size = int(leaf_size)
        self.rebuild_every = int(rebuild_every)
        self.collapse_limit = int(collapse_limit)
        self.chunk_events = int(chunk_events)
        self.record_events = bool(record_events)
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise InputError("threads", f"must be an integer >= 1, got {threads!r}")
        if balance is not None and (isinstance(balance, bool) or not isinstance(
                balance, (int, np.integer)) or balance < 0):
            raise InputError("balance", f"must be an integer >= 0 or None, got {balance!r}")
        if lock not in LOCKS:
            raise InputError("lock", f"unknown value {lock!r}; one of {', '.join(LOCKS)}")
        if policy not in POLICIES:
            raise InputError("policy", f"unknown value {policy!r}; one of {', '.join(POLICIES)}")
        scale = float(scale)
        if not (scale > 0 and math.isfinite(scale)):
            raise InputError("scale", f"must be a finite number > 0, got {scale!r}")
        if schedule not in SCHEDULES:
            raise InputError("schedule", f"unknown value {schedule!r}; one of "
                             f"{', '.join(SCHEDULES)}")
        if schedule == "auto" and policy != "exact":
            raise InputError("schedule", "'auto' runs some steps' events on one thread, which "
                             "gives the threads' result only under policy 'exact'")
        if schedule == "pool" and policy != "exact":
            raise InputError("schedule", "'pool' waits by particle and repairs what it cannot "
                             "order: it has no 'paper' policy")
        if threads > 1 and lock == "none":
            raise InputError("lock", "threads > 1 need lock regions: 'grid', 'grid3d' or 'graph'")
        self.threads = int(threads)
        self.lock = lock
        self.scale = scale
        self.policy = policy
        self.schedule = schedule
        self.scheduler = EventSchedule() if schedule == "auto" and threads > 1 else None
        # exact policy, lock graph: regions far from the other domains are merged
        # (``_far_domains``); an attribute, not an option, so benchmarks can compare
        self.merge_far = True
        # schedule "pool": domains shared by the threads (an attribute, like merge_far)
        self.pool_domains = 4 * self.threads
        self.pool_split = "tree"
        self.pool_redo = "threads"
        self.pool_claim = "runs"
        self.pool_masks = "auto"
        # the pool's last step: each domain's cycles inside its events
        # (``claim_masks``'s work), and this step's domain adjacency (filled
        # by ``init_domains``)
        self._pool_work = None
        # the cost of slots 0..s-1 in the last pool step's events at its domains'
        # edges and where the runs should end (``pool.cost_points``), and this
        # step's domains' share of it
        self._pool_cost = None
        self._pool_dwork = None
        self._pool_last = None
        self._domain_memo = {}  # _domains: t -> (dlo, dhi)
        self._slabs = None  # the tree's domain levels are slabs (``_slab_levels``)
        self._pool_adj = np.zeros(0, np.int64)
        self._pool_cuts = None  # (dlo, dhi): the last pool step's work_split
        # pool steps in which a pair found mid-step broke the masks (``kernels.expose_pair``;
        # of the attempt that completed the step on the threads)
        self.pool_checked_steps = 0
        self._fine_hop = None  # the mean hop between fine lock regions, last threaded step
        if window_events is None:
            window_events = POOL_WINDOW if schedule == "pool" else LOCK_WINDOW
        if isinstance(window_events, bool) or not isinstance(window_events, numbers.Real) \
                or not window_events > 0:
            raise InputError("window_events", f"must be a number > 0, got {window_events!r}")
        self.workers = (Workers(self.threads, window_events, stall_seconds)
                        if self.threads > 1 else None)
        # the phase kernels' control words: the workers', or words of their own on one thread
        self._ctrl = self.workers.ctrl if self.workers is not None else np.zeros(NCTRL, np.int64)
        self.last_events = 0.0
        self.repairs = 0
        self.repairs_on_threads = 0  # of those, redone on the threads (``pool_redo``)
        self._regions = None  # (last threaded step's LockRegions, interior fraction)
        self._lock_stats = None
        if trace_locks is not None and self.threads != 1:
            raise InputError("trace_locks", "traces are recorded by sequential runs (threads=1)")
        self.trace_locks = [(k, float(s) if k == "graph" else None) for k, s in (trace_locks or [])]
        for k, _ in self.trace_locks:
            if k not in LOCKS or k == "none":
                raise InputError("trace_locks", f"unknown lock structure {k!r}")
        self.trace_steps = []
        self.trf = np.zeros((4096 if self.trace_locks else 0, 2))
        self.tri = np.zeros((self.trf.shape[0], 3), np.int64)
        hill = physics.hill
        if hill is not None and 1.5 * hill.omega * dt >= 0.25:
            raise InputError("dt", f"{dt} s is too long for the shearing sheet: "
                             f"need 1.5*omega*dt < 0.25 (dt < {0.25 / (1.5 * hill.omega):.6g} s)")
        self.balance = 0 if self.threads == 1 else BALANCE if balance is None else int(balance)
        self._pool_keep = {}  # schedule="pool": its per-slot arrays, kept across steps
        self._scratch = AlignedScratch()  # the step's control words and queues
        self._pool_start = None  # a pool step's step-start values (``_rollback``)
        self._load(state, copy)
        self.totals = np.zeros(K.NSTAT)
        self.phase_s = np.zeros(3)  # wall seconds: search, events, whole steps (phase_seconds)
        self.search_visits = 0.0  # node pairs visited by the pair searches so far
        self.search_tests = 0.0   # particle pairs tested by them
        self.max_overlap = 0.0
        self.steps_done = 0
        self.step_stats = None

    # ---- state in and out ------------------------------------------------
    def _load(self, state, copy):
        n = state.n
        if np.any(state.t_local != 0):
            raise InputError("state.t_local", "must be zero between steps")
        take = (lambda a: a.copy()) if copy else (lambda a: a)
        self.n = n
        self.time = state.time
        self.pos = take(state.pos)
        self.vel = take(state.vel)
        self.rad = take(state.radius)
        self.mass = take(state.mass)
        self.tl = take(state.t_local)
        self.ncoll = take(state.ncoll)
        # last-collision times matter only to the TC guard: not kept otherwise.
        # With sleeping grains the kernels' per-particle guard word (``tlast``:
        # journaled, permuted and rolled back like the TC clock) holds the sleep
        # state instead (K.AWAKE, K.ASLEEP, or the time a drowsy grain's run of
        # slow impacts began: State.t_last, when sleeping waits t_sleep)
        guard = self.physics.guard
        self.sleeping = isinstance(guard, VelocityGuard) and guard.v_sleep > 0.0
        self.guarded = isinstance(guard, CollapseGuard) or self.sleeping
        if self.sleeping:
            since = (take(state.t_last) if guard.t_sleep > 0.0
                     else np.full(n, K.AWAKE))
            self.tlast = np.where(take(state.asleep), K.ASLEEP, since)
        else:
            self.tlast = take(state.t_last) if self.guarded else np.zeros(0)
        self.tlast_in = (None if isinstance(guard, CollapseGuard)
                         else state.t_last.copy() if copy else state.t_last)
        self.ids = np.arange(n, dtype=np.int32)
        self.perm = np.arange(n, dtype=np.int32)
        vcap = max(4096, n // 16)  # violators moved per node by a re-sort
        parts = max(self.threads, 2 ** (math.ceil(math.log2(self.threads))))
        self.vslots = np.zeros((parts, vcap), np.int64)
        self.vids = np.zeros((parts, vcap), np.int32)
        self.keys = np.zeros(n)  # selection keys by slot (resort; threads own disjoint slots)
        self.anc = np.zeros((n, 3))
        self.reach = np.zeros(n)
        self.top = np.zeros(2)
        self.search_work = np.zeros(2)
        self.speed_sample = np.zeros(min(n, 1024) if n else 1)
        self.speed_perm = np.zeros(len(self.speed_sample), np.int64)  # median_of's scratch
        self.cis = np.zeros(n, np.int32)
        self.work = np.zeros(256, np.int64)
        self.stack2 = np.zeros((self.threads, 4096, 3), np.int64)
        self.search_work2 = np.zeros((self.threads, 2))
        self.nnodes_cap = count_nodes(n, self.leaf_size)
        self.ntop = np.zeros((self.nnodes_cap, NTOP), np.int32)
        self.nnodes = skeleton(n, self.leaf_size, self.ntop, np.zeros(256, np.int64))
        self.since_build = None  # steps since the tree was last built from scratch
        t = self.threads
        # the subtrees the threads re-sort and bound (2^depth of them), and the nodes above
        self.depth_split = max(0, math.ceil(math.log2(t))) if t > 1 else 0
        self.subroots, self.top_nodes = self._split_nodes(self.depth_split)
        self.subroot_arr = np.array(self.subroots, np.int64)
        # each subtree's nodes steal_depth levels down, which the re-sort shares out
        # (``tree.resort_stealing``): as many levels as keep them at least
        # STEAL_MIN_SLOTS, at most STEAL_LEVELS
        sub = n / max(len(self.subroots), 1)
        self.steal_depth = int(min(STEAL_LEVELS, max(0, math.floor(math.log2(
            max(sub / STEAL_MIN_SLOTS, 1.0))))))
        below = [self._split_nodes(self.steal_depth, nd)[0] for nd in self.subroots]
        self.below = np.zeros((len(below), max(len(b) for b in below)), np.int64)
        self.nbelow = np.array([len(b) for b in below], np.int64)
        for k, b in enumerate(below):
            self.below[k, :len(b)] = b
        self.steal_ctl = cache_aligned((len(below) * NLIST,), np.int64)
        # the pair search's tasks (``tree.search_frontier``), claimed by the threads
        self.search_max = max(self.leaf_size, n // (SEARCH_TASKS * self.threads))
        self.stasks = np.zeros((4096, 3), np.int64)
        self.sseg = np.zeros((4096, 3), np.int64)
        self.sclaim = cache_aligned((8,), np.int64)
        parts = max(t, len(self.subroots))
        self.stacks = np.zeros((parts, 512), np.int64)
        self.order = np.zeros((parts, self.nnodes_cap), np.int64)
        self.scratches = np.zeros((t, n))  # gather buffers of the permutation (8 bytes)
        self._kick = 0.0  # s: Hill's kick pending for the step's first phase (_setup)
        self.nbox = np.zeros((self.nnodes_cap, 6))
        self.nsplit = np.full(self.nnodes_cap, np.nan)  # split keys (resort)
        self.nreach = np.zeros(self.nnodes_cap)
        self.noff = np.zeros(n + 1, np.int64)
        self.pair_cap = max(1024, 4 * n // self.threads)  # per search part
        self.out_a = np.zeros((self.threads, self.pair_cap), np.int32)
        self.out_e = np.zeros((self.threads, self.pair_cap), np.int32)
        self.npairs_part = np.zeros(self.threads, np.int64)
        self.nent = np.zeros(2 * self.pair_cap * self.threads, np.int32)
        self.xhead = np.full(n, -1, np.int32)
        self.xent = np.zeros(max(1024, n // 4), np.int32)
        self.xnext = np.zeros(self.xent.shape[0], np.int32)
        self.ctr = np.zeros(NCTR, np.int64)
        self.evt = np.full(n, np.inf)
        self.evp = np.full(n, -1, np.int32)
        self.evc = np.zeros(n, np.int32)
        self.hidden = np.zeros(n, np.uint8)
        self.tour_t = np.full(2 * tournament_size(n), np.inf)
        self.tour_s = np.full(2 * tournament_size(n), -1, np.int32)
        jcap = max(256, n // 8)
        self.jslot = np.zeros(jcap, np.int32)
        self.jvel = np.zeros((jcap, 3))
        self.jtlast = np.zeros(jcap)
        lcap = 1024 if self.record_events else 0
        self.logt = np.zeros(lcap)
        self.logi = np.zeros((lcap, 3), np.int64)
        self.log_steps = []  # (step index, first log entry) per step
        self.par = np.zeros(K.NPAR)
        self.no_locks = (np.zeros(0, np.int32), np.zeros(1, np.int64), np.zeros(0, np.int32),
                         np.zeros((4, 0), np.int64))
        self.ipar = np.zeros(K.NIPAR, np.int64)
        self._encode()

    def _encode(self):
        ph = self.physics
        par, ipar = self.par, self.ipar
        dt = self.dt
        hill = ph.hill
        shear = 1.5 * hill.omega if hill is not None else 0.0
        par[K.P_DT] = dt
        par[K.P_SHEAR] = shear
        par[K.P_FR] = 1.0 / (1.0 - shear * dt) if shear else 1.0
        par[K.P_G] = ph.g
        dish = ph.domain.code == DOMAIN_DISH
        par[K.P_RCYL] = ph.domain.radius if dish else 0.0
        law, e, vc, expo = ph.restitution.encode()
        par[K.P_E] = e
        par[K.P_VC] = vc
        par[K.P_EXP] = expo
        tc = ph.guard.tc if isinstance(ph.guard, CollapseGuard) else -1.0
        par[K.P_TC] = tc
        par[K.P_WMIN] = 0.5 * ph.g * tc if tc > 0 else 0.0
        vg = isinstance(ph.guard, VelocityGuard)
        par[K.P_VMIN] = ph.guard.v_min if vg else -1.0
        par[K.P_VEXP] = ph.guard.exponent if vg else 0.0
        par[K.P_VSLEEP] = ph.guard.v_sleep if vg else 0.0
        par[K.P_TSLEEP] = ph.guard.t_sleep if vg else 0.0
        # No pair may be in reach of two images of each other (nor a particle of its
        # own image): the two largest reaches must sum to less than half the
        # shortest period.  Radii alone must already fit.
        period = ph.domain.min_period()
        par[K.P_HALFPER] = 0.5 * period if math.isfinite(period) else math.inf
        top = np.sort(self.rad)[-2:] if self.n >= 2 else np.array([0.0, 0.0])
        r12 = float(top.sum()) if top.size == 2 else 2.0 * float(top.sum())
        if par[K.P_FR] * r12 >= par[K.P_HALFPER]:
            raise InputError("domain", f"the periodic box (shortest period {period:.6g} m) is "
                             f"too small for particles of radii {top.tolist()} m: it must be "
                             f"longer than 2 * (r1 + r2) = {2 * r12:.6g} m")
        ipar[K.I_LAW] = law
        ipar[K.I_DISH] = 1 if dish else 0
        ipar[K.I_CAP] = self.collapse_limit
        ipar[K.I_PAPER] = 1 if self.policy == "paper" else 0

    def _split_nodes(self, depth, root=0):
        """The nodes ``depth`` levels below ``root`` (or leaves above them), left
        to right, and the nodes above."""
        subroots, top = [], []
        stack = [(root, 0)]
        while stack:
            nd, dep = stack.pop()
            left = int(self.ntop[nd, 0])
            if dep == depth or left < 0:
                subroots.append(nd)
                continue
            top.append(nd)
            stack.append((int(self.ntop[nd, 1]), dep + 1))
            stack.append((left, dep + 1))
        subroots.sort(key=lambda nd: self.ntop[nd, 2])
        return subroots, top

    def _pmap(self, fn, arglist, signals=False):
        """Run fn(*args) for each args, on the worker threads when there are
        some (``signals``: fn sets ``parallel.STARTED`` as the calling thread's
        share begins, ``Workers.map``)."""
        if self.workers is None or len(arglist) <= 1:
            return [fn(*a) for a in arglist]
        return self.workers.map(fn, arglist, signals)

    def _claimed(self, fn, ntasks, args_of):
        """[fn(*args_of(i, k)) for i in range(ntasks)] on the threads, k being
        the thread that runs task i (for its own scratch buffers): with
        ``balance`` > 0 the threads claim the tasks in turn, otherwise thread
        k runs tasks k, k + T, ...

        Why claimed: a fixed share per thread waits for the slower share, and
        shares of equal size are uneven when the work is.  On the 50,000-grain
        bed the first predictions of the dense bottom half took 4.5 ms against
        the top half's 3.0 (one run); claimed in eighths the phase took
        2.0-3.2 ms against 3.3-3.6 in halves (three runs, 5.1-5.9 on one
        thread).  Results are per task, so which thread ran a task changes
        nothing."""
        if self.workers is None or ntasks <= 1:
            return [fn(*args_of(i, 0)) for i in range(ntasks)]
        t = self.threads
        claim = itertools.count()  # next() is atomic under the GIL
        out = [None] * ntasks
        stop = []

        def run(k):
            try:
                for i in (claim if self.balance > 0 else range(k, ntasks, t)):
                    if i >= ntasks or stop:
                        return
                    out[i] = fn(*args_of(i, k))
            except BaseException:
                stop.append(k)  # the others take no more; map raises this
                raise
        self.workers.map(run, [(k,) for k in range(t)])
        return out

    def _slices(self):
        t = self.threads
        return [slice(self.n * k // t, self.n * (k + 1) // t) for k in range(t)]

    def state(self):
        """The current state as a State ordered by particle id (a copy)."""
        order = np.empty(self.n, np.int64)
        order[self.ids] = np.arange(self.n)
        asleep = None
        if self.sleeping:
            word = self.tlast[order]
            asleep = word == K.ASLEEP
            t_last = np.where(asleep, -np.inf, word)  # drowsy since; -inf otherwise
        elif self.guarded:
            t_last = self.tlast[order]
        else:
            # without a guard's word collision times are not tracked: as given
            t_last = self.tlast_in.copy()
        return State(self.pos[order], self.vel[order], self.rad[order], self.mass[order],
                     self.tl[order], self.ncoll[order], t_last, self.time, asleep=asleep)

    # ---- bundles -----------------------------------------------------------
    def _bundles(self, img_pos, img_vel, img_all):
        parts = (self.pos, self.vel, self.rad, self.mass, self.tl, self.ncoll, self.tlast, self.ids)
        step = (self.anc, self.reach, self.cis, self.work)
        tree = (self.ntop, self.nbox, self.nreach, self.nreach.view(np.int64))
        nbrs = (self.noff, self.nent, self.xhead, self.xent, self.xnext, self.ctr)
        evq = (self.evt, self.evp, self.evc, self.tour_t, self.tour_s, self.hidden)
        jour = (self.jslot, self.jvel, self.jtlast, self.logt, self.logi)
        cfg = (self.par, self.ipar, img_pos, img_vel, img_all, self.par.view(np.int64))
        return parts, step, tree, nbrs, evq, jour, cfg

    # ---- the step ------------------------------------------------------------
    def step(self, check_end=False):
        """Advance one step of length dt.  Returns the step's statistics array.

        ``check_end``: also measure the largest overlap among candidate pairs at
        the step end (an O(candidates) pass).
        """
        step0 = time.perf_counter()
        try:
            return self._step(check_end)
        finally:  # a failed step's time counts too, as its phases' do
            self.phase_s[PH_STEP] += time.perf_counter() - step0

    def _step(self, check_end):
        if self.workers is not None:
            self.workers.wake()
        ph = self.physics
        hill = ph.hill
        # the first half kick: in the step's first phase (_setup), unless
        # asleep grains are held first (their velocities set before the kick)
        self._kick = 0.5 * self.dt if hill is not None and not self.sleeping else 0.0
        if hill is not None and self._kick == 0.0:
            self._pmap(kick_hill, [(self.pos[q], self.vel[q], hill.omega, 0.5 * self.dt)
                                   for q in self._slices()])
        if self.sleeping:
            # an asleep grain moves up at g dt / 2 in the free-falling frame:
            # back where it was at the step end, never below it in between
            K.hold_sleepers(self.vel, self.tlast, 0.5 * ph.g * self.dt)
        try:
            st = self._drift_phase()
        except BaseException:
            if hill is not None and self._kick == 0.0:  # kicked: undone
                kick_hill(self.pos, self.vel, hill.omega, -0.5 * self.dt)
            self._kick = 0.0
            if self.sleeping:
                K.hold_sleepers(self.vel, self.tlast, 0.0)
            raise
        if check_end:  # the overlaps at the step end, before leaving the frame
            self._pmap(K.drift_all, [(self.pos[q], self.vel[q], self.tl[q], self.dt)
                                     for q in self._slices()])
            ov = K.max_overlap(self.pos, self.rad, self.noff, self.nent, self.xhead, self.xent,
                               self.xnext, self._img_pos, self._img_vel, self.dt)
            st[K.S_MAXOV] = max(st[K.S_MAXOV], ov)
        self.time += self.dt
        wp = ph.domain.wrap_params(self.time)
        ctl = self._scratch.get("finish", (8,), np.int64)
        self._pmap(_finish_claimed, signals=True, arglist=[
            (k, self.threads, ctl, self.pos, self.vel, self.tl, self.dt, ph.g, ph.domain.code, wp,
             hill.omega if hill is not None else 0.0, not check_end,
             self.tlast if self.sleeping else NO_SLEEP, self.time, self.par[K.P_TSLEEP],
             self.par[K.P_VSLEEP], self._ctrl) for k in range(self.threads)])
        if self.workers is not None:
            self.workers.rest()
        self._accumulate(st)
        self.last_events = float(st[K.S_POPS])
        self.steps_done += 1
        return st

    @property
    def phase_seconds(self):
        """Wall seconds spent so far, by phase: ``search`` (reaches, tree, pair
        search, candidate lists), ``events`` (first predictions, queues and
        the events), ``other`` (kicks, step ends, Python) and ``step`` (all);
        a repaired step counts every attempt."""
        search, events, step = (float(x) for x in self.phase_s)
        return {"search": search, "events": events, "other": step - search - events,
                "step": step}

    def _accumulate(self, st):
        m = self.totals[K.S_MAXOV]
        c = self.totals[K.S_MAXCIS]
        self.totals += st
        self.totals[K.S_MAXOV] = max(m, st[K.S_MAXOV])
        self.totals[K.S_MAXCIS] = max(c, st[K.S_MAXCIS])
        self.step_stats = st

    def _setup(self, img_pos, img_vel, half, touching_only=False):
        """Search radii, tree, storage order, candidate lists, first events.

        ``touching_only``: search radii zero, so the lists hold the pairs that
        touch or overlap now (for checking an input state).  A pending kick
        (``self._kick``, s: the step's first half kick) is applied in the
        first phase, beside the re-sort of the top nodes rather than in a
        pass of its own, and is then no longer pending (a redo of the step
        starts from the kicked state); the speed sample sees the kicked
        velocities.
        """
        n = self.n
        # the tree: a fresh one every rebuild_every steps, else last step's re-sorted
        # (each node re-split in a band about last step's split, twice the skin
        # distance wide: rebuild_node); the nodes above the threads' subtrees
        # first, then the subtrees in parallel
        fresh = self.since_build is None or self.since_build >= self.rebuild_every
        self.since_build = 0 if fresh else self.since_build + 1
        t = self.threads
        if touching_only:
            self.reach[:] = self.rad
            band = 2.0 * float(self.par[K.P_EXTRA])
            kick = omega = extra = 0.0
        else:
            kick = self._kick if n > 0 else 0.0
            omega = self.physics.hill.omega if kick != 0.0 else 0.0
            K.sample_speeds(self.pos, self.vel, self.par, self.speed_sample, omega, kick)
            typical = median_of(self.speed_sample, self.speed_perm)
            extra = self.skin * typical * self.dt + 0.5 * self.par[K.P_G] * self.dt ** 2
            self.par[K.P_EXTRA] = extra
            band = 2.0 * extra
        # the nodes above the subtrees, then the subtrees, beside the kick, the
        # reaches and the clearing of the per-step arrays (``_first_phase``)
        ctl = self._scratch.get("first", (NFIRST,), np.int64)
        tops = np.zeros((t, 2))
        self.steal_ctl[:] = 0
        ctrl = self._ctrl
        self._kick = 0.0  # applied now: every chunk is claimed by a call that ends
        res = self._pmap(_first_phase, signals=True, arglist=[
            (k, t, ctl, ctrl, self.pos, self.vel, self.rad, self.reach, self.par, extra, omega,
             kick, not touching_only, tops, self.tl, self.cis, self.xhead, self.ctr, self.hidden,
             self.perm, self.ntop, self.depth_split, fresh, self.vslots, self.vids, self.stacks,
             self.nsplit, band, self.keys, self.subroot_arr, self.steal_depth, self.below,
             self.nbelow, self.steal_ctl, self._slab_levels(fresh)) for k in range(t)])
        if min(res) < 0:
            identity(self.perm, 0)  # the storage order is still the particles'
            self.since_build = None
            raise SimulationError("kD-tree deeper than its work stack")
        if not touching_only:
            self.top[:] = np.sort(tops.ravel())[::-1][:2]
            if self.top[0] + self.top[1] >= self.par[K.P_HALFPER]:
                # the re-sort is not applied yet: the storage order is still
                # the particles', and the next step builds a fresh tree
                identity(self.perm, 0)
                self.since_build = None
                raise StepTooLargeError(
                    f"dt={self.dt}: two particles' reaches ({self.top[0]:.4g} and "
                    f"{self.top[1]:.4g} m) could span half the periodic box "
                    f"({self.par[K.P_HALFPER]:.4g} m); use a smaller dt or a larger box")
            self.par[K.P_RMAX] = self.top[0]
        nnodes = self.nnodes
        if self.threads == 1:
            self._permute()  # and the anchors
            identity(self.perm, 0)
            node_bounds(self.anc, self.reach, self.ntop, nnodes, self.nbox, self.nreach)
        else:
            # the permutation, then each thread's subtrees: the permutation of
            # their slots back to the identity, anchors, bounds; then the nodes
            # above them
            arrived = self._scratch.get("arrived", (8,), np.int64)[:1]
            claim = self._claim_word("permute")
            tlast = self.tlast if self.guarded else NO_SLEEP
            # a pool step's start values, gathered by the permutation itself
            start = (pool_start(n, self._pool_keep, len(self.tlast))
                     if self.schedule == "pool" else NO_START)
            res = self._pmap(_permute_and_anchor, signals=True, arglist=[
                (k, t, claim, arrived, ctrl, self.pos, self.vel, self.rad, self.mass, self.ncoll,
                 self.ids, self.reach, tlast, self.perm, self.scratches[k], self.anc, self.ntop,
                 self.subroot_arr, self.nbox, self.nreach, self.order, start) for k in range(t)])
            assert min(res) == 0  # ABORT is set only by a raise, which map raises
            for nd in reversed(self.top_nodes):  # pre-order reversed: children first
                bound_node(self.anc, self.reach, self.ntop, nd, self.nbox, self.nreach)
        images = np.array([SELF_IMAGE] + [int(i) for i in half if i != SELF_IMAGE], np.int64)
        while True:
            nt = search_frontier(self.ntop, self.nbox, self.nreach, img_pos, images,
                                 self.search_max, self.stasks, self.stack2[0])
            if nt != -2:
                break
            self.stasks = np.zeros((2 * self.stasks.shape[0], 3), np.int64)
            self.sseg = np.zeros_like(self.stasks)
        if nt < 0:
            raise SimulationError("pair search deeper than its work stack")
        while True:
            self.sclaim[0] = 0
            res = self._pmap(_search_share, signals=True, arglist=[
                (k, t, ctrl, self.anc, self.reach, self.ntop, self.nbox, self.nreach,
                 self.stasks, nt, self.sclaim, img_pos, self.out_a, self.out_e, self.stack2[k],
                 self.search_work2[k], self.sseg) for k in range(t)])
            if min(res) < 0:
                raise SimulationError("pair search deeper than its work stack")
            self.npairs_part[:] = res
            if max(res) <= self.pair_cap:
                break
            self.pair_cap = int(max(res) * 1.25) + 1024
            self.out_a = np.zeros((self.threads, self.pair_cap), np.int32)
            self.out_e = np.zeros((self.threads, self.pair_cap), np.int32)
            self.nent = np.zeros(2 * self.pair_cap * self.threads, np.int32)
        self.npairs = int(self.npairs_part.sum())
        self.search_visits += self.search_work2[:, 0].sum()
        self.search_tests += self.search_work2[:, 1].sum()
        build_csr(n, self.sseg, nt, self.out_a, self.out_e, self.noff, self.nent)

    def _permute(self):
        """Apply the storage permutation ``perm`` to every per-particle array
        that keeps its values across steps (``PERMUTED``, and ``tlast`` when
        guarded), in place through a gather buffer (``_permute_share``; on
        several threads, ``_permute_and_anchor``).

        Why in place: gathering into spare arrays and swapping them in halves
        the memory traffic (ring N = 2e5, one thread, the seven arrays: 4.1
        ms in place, 3.3 ms into spares) but holds ~80 more bytes a particle,
        past the ring's 200-byte target."""
        _permute_share(0, 1, np.zeros(0, np.int64), self.pos, self.vel, self.rad, self.mass,
                       self.ncoll, self.ids, self.reach, self.tlast if self.guarded else NO_SLEEP,
                       self.perm, self.scratches[0], self.anc, NO_START)

    def _claim_word(self, name):
        """A claim counter at 0 for the kernels of the claimed phase ``name``
        (``init_domains``, ``_permute_and_anchor``): one word on a cache line
        of its own (kept from step to step: ``AlignedScratch``), or empty
        (fixed shares) when ``balance`` is 0."""
        if self.balance == 0:
            return np.zeros(0, np.int64)
        return self._scratch.get("claim " + name, (8,), np.int64)[:1]

    def _drift_phase(self):
        ph = self.physics
        img_pos, img_vel, half, full = ph.domain.images(self.time)
        self._img_pos, self._img_vel = img_pos, img_vel
        self.par[K.P_T0] = self.time
        log_start = int(self.ctr[K.LCOUNT]) if self.record_events else 0
        on_one = self.threads == 1 or (self.scheduler is not None and self.scheduler.sequential())
        sequential = on_one
        spent = 0.0  # in the events (first events on), over every attempt
        detected = np.zeros(K.NSTAT)  # the violations of attempts that were repaired
        redo_window = None  # a pool redo on the threads: its interior window (events)
        while True:
            began = time.perf_counter()
            self._setup(img_pos, img_vel, half)
            self.phase_s[PH_SEARCH] += time.perf_counter() - began
            began = time.perf_counter()
            self.ctr[K.LCOUNT] = log_start
            st = detected.copy()
            self._pool_start = None  # this attempt's step-start values, when a pool step
            parts, step, tree, nbrs, evq, jour, cfg = self._bundles(img_pos, img_vel, full)
            if sequential:
                # events on one thread (one thread in all, schedule auto or a
                # repair): the first events on all threads, then one queue
                m = self.threads * max(self.balance, 1)
                # cut at buckets' first slots: each task builds its buckets' leaves
                lo = [(self.n * k // m) >> BUCKET_BITS << BUCKET_BITS for k in range(m)] + [self.n]
                rows = self._scratch.get("rows", (m, K.NSTAT))
                self._claimed(K.first_events, m, lambda i, k: (
                    parts, nbrs, evq, cfg, rows[i], lo[i], lo[i + 1]))
                st[K.S_MAXOV] = rows[:, K.S_MAXOV].max()
                K.init_queue(parts, evq)
            else:
                # each domain's first events, then the domain's queue
                nd = self._pool_count() if self.schedule == "pool" else self.threads
                dlo, dhi = self._pool_ranges(nd) if self.schedule == "pool" else self._domains(nd)
                nd = len(dlo)
                q = tournament_size(int((dhi - dlo).max()))
                dtour_t = self._scratch.get("dtour_t", (nd, 2 * q), np.float64, np.inf)
                dtour_s = self._scratch.get("dtour_s", (nd, 2 * q), np.int32, -1)
                rows = self._scratch.get("rows", (nd, K.NSTAT))
                # claimed: the pool's domains outnumber the threads, and
                # ``_pmap`` would deal them out round robin to the pool's
                # threads beside the caller (ring N = 2e5, 16 domains:
                # 3.9 ms a step dealt, against 1.6 + 1.1 ms for the claimed
                # first events and the one queue)
                if self.schedule == "pool":  # and the pool's words of the domain's slots
                    pst, locks = pool_state(self.n, nd, self.threads, self._pool_keep,
                                            len(self.tlast))
                    hops, wt, sdom = pst[:3]
                    # a redo puts back these step-start values, not the journal's
                    start = self._pool_keep["start"]
                    claim = self._claim_word("domains")
                    # "band" claims by domain adjacency, worked out with the first events
                    self._pool_adj = adj = np.zeros(nd if self._pool_claim == "band" else 0,
                                                    np.int64)
                    masks = self._pool_masks == "start" or (
                        self._pool_masks == "auto" and self.last_events > self.n)
                    self._pmap(init_domains, signals=True, arglist=[
                        (k, self.threads, claim, sdom, wt, hops, parts, nbrs, evq, cfg, rows,
                         dlo, dhi, dtour_t, dtour_s, adj, masks, self._ctrl)
                        for k in range(self.threads)])
                    if masks:  # the two-hop masks once every one-hop mask is there
                        claim = self._claim_word("masks")
                        self._pmap(two_hop_masks, [(k, self.threads, claim, hops, sdom,
                                                    nbrs[0], nbrs[1], dlo, dhi)
                                                   for k in range(self.threads)])
                    self._pool_start = start
                else:
                    self._claimed(K.init_range, nd, lambda d, k: (
                        parts, nbrs, evq, cfg, rows[d], dlo[d], dhi[d], dtour_t[d],
                        dtour_s[d]))
                st[K.S_MAXOV] = rows[:, K.S_MAXOV].max()
            try:
                if sequential:
                    status = self._events_sequential(st, img_pos, img_vel, full, half)
                elif self.schedule == "pool":
                    status = self._events_pool(st, img_pos, img_vel, full,
                                               (dlo, dhi, dtour_t, dtour_s), pst, locks,
                                               redo_window)
                else:
                    status = self._events_parallel(st, img_pos, img_vel, half, full,
                                                   (dlo, dhi, dtour_t, dtour_s))
            except BaseException:
                self._rollback()  # interrupted or a worker failed: undo the step
                self.ctr[K.LCOUNT] = log_start
                raise
            if status == K.OK and self.schedule == "pool" and self._pool_split == "work":
                # the next step's domains, from this step's collisions per slot (the
                # storage order moves little from one step to the next)
                nd = self._pool_count()
                cuts = (np.empty(nd, np.int64), np.empty(nd, np.int64))
                work_split(self.cis, cuts[0], cuts[1])
                self._pool_cuts = cuts
            took = time.perf_counter() - began
            spent += took
            self.phase_s[PH_EVENTS] += took
            if status == K.OK:
                st[K.S_JNEXT] = st[K.S_JEND] = 0.0  # journal cursors, not statistics
                if self.record_events:
                    self.log_steps.append((self.steps_done, log_start))
                if self.scheduler is not None:  # a repair counts as the threads' cost
                    self.scheduler.record(on_one, spent / max(float(st[K.S_POPS]), 1.0))
                return st
            bad = int(self.ctr[K.CTR_BAD])
            bad_id = int(self.ids[bad]) if 0 <= bad < self.n else -1
            self._rollback()
            self.ctr[K.LCOUNT] = log_start
            if (status != K.POOL_OVERFLOW and not sequential and self.policy == "exact"
                    and st[K.S_VIOL] + st[K.S_REACHOUT] > 0):
                # a violation was seen: whatever else stopped the attempt may have
                # come from reading out of order; the repair decides
                status = K.VIOLATION
            if status == K.POOL_OVERFLOW:
                self._grow_pool()
                continue  # redo the step with a larger pool: same result
            if status == K.VIOLATION:
                self.repairs += 1
                # the repair's result is the sequential one, but what was
                # detected is counted: the statistics say why the step was redone
                for k in (K.S_VIOL, K.S_REACHOUT):
                    detected[k] = st[k]
                if (self.schedule == "pool" and self.pool_redo == "threads"
                        and redo_window is None
                        and self.workers.window_events > REDO_WINDOW):
                    # on the threads again, interior events kept near the others'
                    # clocks: without violations any pool attempt gives the
                    # sequential result, and a violation here is caught like any
                    redo_window = REDO_WINDOW
                    self.repairs_on_threads += 1
                else:
                    sequential = True  # redo the step sequentially
                continue
            if status == K.COLLAPSE:
                raise InelasticCollapseError(
                    f"inelastic collapse at t = {self.time:.9g} s: particle {bad_id} collided "
                    f"more than {self.collapse_limit} times within one step of {self.dt} s "
                    f"(collisions per step explode). Enable the collapse guard "
                    f"(restitution TC model, scenario key 'tc'), lower the restitution "
                    f"dissipation, or raise collapse_limit if this is genuine. The state is "
                    f"left at the last completed step.")
            if status == K.SIGMA_TOO_LARGE:
                raise StepTooLargeError(
                    f"at t = {self.time:.9g} s particle {bad_id} sped up so much that it could "
                    f"reach a periodic image of itself within dt = {self.dt} s; use a "
                    f"smaller dt. The state is left at the last completed step.")
            if status == K.STALL:
                raise SimulationError(
                    f"the worker threads stalled at t = {self.time:.9g} s: no event completed "
                    f"for {self.workers.stall_cycles / cycles_per_second():.0f} s. The state "
                    f"is left at the last completed step.")
            raise SimulationError(f"engine status {STATUS_NAMES.get(status, status)}")

    def _events_sequential(self, st, img_pos, img_vel, full, half):
        parts, step, tree, nbrs, evq, jour, cfg = self._bundles(img_pos, img_vel, full)
        if self.trace_locks:
            locks = {}
            for kind, scale in self.trace_locks:
                regions = self.build_locks(img_pos, half, kind, scale)
                by_id = np.empty(self.n, np.int32)
                by_id[self.ids] = regions.lock_of
                locks[(kind, scale)] = (by_id, regions.loff, regions.ladj)
            self.ctr[K.TCOUNT] = 0
        while True:
            status = K.run_events(parts, step, tree, nbrs, evq, jour, cfg, st, self.no_locks,
                                  (self.trf, self.tri), self.chunk_events)
            if status == K.CHUNK:
                continue
            if status in (K.NEED_JOURNAL, K.NEED_LOG, K.NEED_TRACE):
                if status == K.NEED_JOURNAL:
                    self._grow_journal()
                elif status == K.NEED_LOG:
                    self._grow_log()
                else:
                    self._grow_trace()
                parts, step, tree, nbrs, evq, jour, cfg = self._bundles(img_pos, img_vel, full)
                continue
            if status == K.OK and self.trace_locks:
                k = int(self.ctr[K.TCOUNT])
                ev = np.zeros(k, dtype=[("t", np.float64), ("cycles", np.float64),
                                        ("i", np.int64), ("j", np.int64), ("kind", np.int64)])
                ev["t"], ev["cycles"] = self.trf[:k, 0], self.trf[:k, 1]
                ev["i"], ev["j"], ev["kind"] = self.tri[:k, 0], self.tri[:k, 1], self.tri[:k, 2]
                self.trace_steps.append({"events": ev, "locks": locks})
            return status

    def _grow_trace(self):
        used = int(self.ctr[K.TCOUNT])
        trf = np.zeros((2 * self.trf.shape[0], 2))
        tri = np.zeros((2 * self.tri.shape[0], 3), np.int64)
        trf[:used], tri[:used] = self.trf[:used], self.tri[:used]
        self.trf, self.tri = trf, tri

    def trace(self):
        """The recorded trace: a list per step of {'events': structured array
        (t, cycles, i, j, kind) in processing order (ids; j = -1 for walls),
        'locks': {(lock, scale): (region of each particle id, loff, ladj)}},
        and the cycle counter's frequency."""
        return {"steps": self.trace_steps, "cycles_per_second": cycles_per_second(),
                "n": self.n, "dt": self.dt}

    def build_locks(self, img_pos, half, lock=None, scale=None, domains=None):
        """The lock regions of the current step (after ``_setup``); by default of the
        engine's own lock structure and SCALE.  ``domains = (dlo, dhi, images)``
        (lock graph only): merge each domain's regions far from the other
        domains (``_far_domains``)."""
        lock = lock or self.lock
        scale = scale or self.scale
        if lock == "graph":
            far = self._far_domains(scale, img_pos, *domains) if domains is not None else None
            return L.lock_graph(self.ntop, self.nbox, self.nreach, self.nnodes, half, img_pos,
                                scale, self.n, self._pmap, self.threads, far)
        dims = 3 if lock == "grid3d" else 2
        return L.grid_locks(self.anc, self.top[0] + self.top[1], self.physics.domain,
                            self.time, dims)

    def _far_domains(self, scale, img_pos, dlo, dhi, images):
        """``lock_graph``'s domains argument: each domain's box, the periodic
        image offsets and the margin beyond which a tree node of one domain is
        a lock region however large; None when there is no margin yet.

        Why: under the exact policy an interior event (its regions >= INTERIOR
        hops from every other domain's) takes no lock at all, so away from the
        cuts the regions' size does not matter, while near them fine regions
        keep the boundary band thin and cheap to build.  The margin is
        2 R + (INTERIOR - 1) h, R the largest reach and h the mean hop between
        the fine regions of the last threaded step (a region's size plus twice
        its largest reach: farther apart they are not adjacent), so that a
        merged region is about INTERIOR hops from the other domains.  The
        first threaded step merges nothing (``_fine_hop`` is set by
        ``_events_parallel``).  The breadth-first search from the
        cuts decides what is interior in the end; a margin that is too small
        merges regions inside the boundary band, which makes all their events
        boundary events (measured on the settled 10,000-grain dish at SCALE 4:
        a margin of 8 R, about the band's half width, left an interior
        fraction of 0.13 against 0.41 unmerged, 16 R and more kept 0.41)."""
        if self._fine_hop is None:
            return None
        rmax = float(self.nreach[0])
        margin = 2.0 * rmax + (INTERIOR - 1) * self._fine_hop
        dbox = np.empty((len(dlo), 6))
        dbox[:, :3] = np.inf
        dbox[:, 3:] = -np.inf
        stack = [0]
        while stack:  # the largest nodes inside one domain each: their boxes' union
            nd = stack.pop()
            a, b = int(self.ntop[nd, 2]), int(self.ntop[nd, 3])
            e = [k for k in range(len(dlo)) if dlo[k] <= a and b <= dhi[k] and a < b]
            if e:
                k = e[0]
                dbox[k, :3] = np.minimum(dbox[k, :3], self.nbox[nd, :3])
                dbox[k, 3:] = np.maximum(dbox[k, 3:], self.nbox[nd, 3:])
            elif self.ntop[nd, 0] >= 0:
                stack += [int(self.ntop[nd, 0]), int(self.ntop[nd, 1])]
        return (np.asarray(dlo, np.int64), np.asarray(dhi, np.int64), dbox,
                np.ascontiguousarray(img_pos[images]), margin)

    def _domains(self, t=None):
        """Slot ranges of the T domains (T: the engine's threads unless given):
        the tree's nodes at depth ceil(log2 T), left to right, merged down to T
        (spatial blocks of about N/T particles)."""
        t = t or self.threads
        # the nodes' slot ranges are the skeleton's (``tree.skeleton``, made
        # once for N): the same domains every step, worked out once (a walk in
        # Python took 0.1 ms of a pool step on the ring)
        if t in self._domain_memo:
            return self._domain_memo[t]
        depth = max(0, math.ceil(math.log2(t)))
        ranges = []
        stack = [(0, 0)]
        while stack:
            nd, dep = stack.pop()
            left = self.ntop[nd, 0]
            if dep == depth or left < 0:
                ranges.append((int(self.ntop[nd, 2]), int(self.ntop[nd, 3])))
                continue
            stack.append((int(self.ntop[nd, 1]), dep + 1))
            stack.append((int(left), dep + 1))
        ranges.sort()
        while len(ranges) > t:  # merge the smallest neighbouring pair
            k = min(range(len(ranges) - 1), key=lambda q: ranges[q + 1][1] - ranges[q][0])
            ranges[k:k + 2] = [(ranges[k][0], ranges[k + 1][1])]
        while len(ranges) < t:
            ranges.append((self.n, self.n))
        dlo = np.array([r[0] for r in ranges], np.int64)
        dhi = np.array([r[1] for r in ranges], np.int64)
        self._domain_memo[t] = (dlo, dhi)
        return dlo, dhi

    def _pool_ranges(self, nd):
        """The slot ranges of the pool's nd domains this step (``pool_split``)."""
        cuts = self._pool_cuts
        self._pool_dwork = None
        if self._pool_split == "work" and cuts is not None and len(cuts[0]) == nd:
            return cuts  # fresh arrays each step, read only
        dlo, dhi = self._domains(nd)
        c = self._pool_cost
        if self._pool_claim in ("band", "runs") and c is not None:
            # the threads' runs end at equal shares of the cost, inside a domain
            # if need be (that domain split in two), not at the nearest edge
            dlo, dhi, self._pool_dwork = cost_cut(dlo, dhi, c)
        return dlo, dhi

    def _pool_count(self):
        """The pool's domains: ``pool_domains`` rounded down to a power of two
        (tree nodes of one depth), at most ``pool.MAX_DOMAINS`` and N."""
        k = max(1, min(int(self.pool_domains), MAX_DOMAINS, self.n))
        return 1 << (k.bit_length() - 1)

    def _slab_levels(self, fresh):
        """The tree's top levels split along the root's axis (``tree.resort``'s
        ``slab``; it acts on a fresh tree only): under ``schedule="pool"`` on
        threads, in a scene whose longest side is at least ``SLAB_ASPECT``
        times its second, down to the pool's domains.  The domains are then
        slabs stacked along the long axis, and the threads' runs (slots in
        order, cut by cost) meet across a section of the scene, not along a
        surface that turns with the splits below it.  On the 50,000-grain
        bed (a column 29 mm wide, 69 mm tall) the collisions within two
        candidate hops of the other run fell from 16 % to 8.3 % (a plane at
        the cost median: 8.7 %) and the step took 4.6 % less; on the ring
        (N = 2e5, a square sheet) slabs made the events 3 % slower: more
        faces between domains, and a run edge no shorter (README,
        Benchmarks: "Slab domains, and atomic maxima read first").  Else 0:
        every node its own longest axis.  The result does not depend on the
        tree (``test_determinism``)."""
        if self.schedule != "pool" or self.threads < 2 or self.n == 0:
            return 0
        if fresh or self._slabs is None:
            # the root's box of the last step's anchors: a pass over the
            # positions (numpy's, along axis 0) took 5-10 ms on the ring
            box = self.nbox[0]
            ext = np.sort(box[3:] - box[:3] if self._slabs is not None else
                          np.ptp(self.pos, axis=0))
            self._slabs = bool(ext[2] >= SLAB_ASPECT * ext[1])
        return self._pool_count().bit_length() - 1 if self._slabs else 0

    def _events_pool(self, st, img_pos, img_vel, full, queues, pst, locks, window_events=None):
        """The step's events under ``schedule="pool"`` (``lockgraph/pool.py``)
        on the threads until done; ``pst``, ``locks``: ``pool.pool_state``,
        filled with the first events (``pool.init_domain``); ``window_events``:
        the interior window in a domain's mean times between events (None:
        ``Workers.window_events``)."""
        dlo, dhi, dtour_t, dtour_s = queues
        nd = len(dlo)
        self._pool_last = (dlo, dhi)  # this step's domains, for the tests
        # and the step's row (PCHECKED), and the threads' claim masks
        pctl = self._scratch.get("pctl", (nd + 1 + self.threads, NPCTL), np.int64)
        pctl[:, PHIGH] = -1
        work = self._pool_dwork if self._pool_dwork is not None and len(self._pool_dwork) == nd \
            else self._pool_work if self._pool_work is not None and len(self._pool_work) == nd \
            else None
        masks = claim_masks(self._pool_claim, nd, self.threads, self._pool_adj, work)
        per_domain = max(self.last_events / nd, 1.0)
        if window_events is None:
            window_events = self.workers.window_events
        window = window_events * self.dt / per_domain
        status = self._on_threads(st, img_pos, img_vel, full, lambda bundles, stt:
                                  self.workers.run_pool(bundles, stt, locks, pst, queues,
                                                        pctl, window, masks,
                                                        self._pool_claim == "runs"))
        if status == K.OK:
            # counted once a step, and the band cut of the next step (and of a
            # redo) from the events of a whole step, not of a stopped attempt
            self.pool_checked_steps += int(pctl[nd, PCHECKED] != 0)
            # cycles, not events: an event's cost differs from domain to domain
            # (1,450-3,800 cycles on the bed), and a cut at equal events left one
            # thread more to take from the other's run (README, Benchmarks:
            # "A band cut by cycles")
            self._pool_work = pctl[:nd, PCYC].copy()
            self._pool_cost = cost_points(self._pool_work, dlo, dhi, self.cis, self.threads)
        return status

    @staticmethod
    def _add_rows(st, stt):
        """Add the threads' statistics rows to st (maxima where they are maxima)."""
        for row in stt:
            m = max(st[K.S_MAXOV], row[K.S_MAXOV])
            c = max(st[K.S_MAXCIS], row[K.S_MAXCIS])
            st += row
            st[K.S_MAXOV] = m
            st[K.S_MAXCIS] = c

    def _events_parallel(self, st, img_pos, img_vel, half, full, queues):
        """The step's events on the worker threads.  ``queues = (dlo, dhi,
        dtour_t, dtour_s)``: the domains' slot ranges and their queues (built
        with the first events)."""
        dlo, dhi, dtour_t, dtour_s = queues
        merge = self.merge_far and self.policy == "exact" and self.lock == "graph"
        regions = self.build_locks(img_pos, half, domains=(dlo, dhi, full) if merge else None)
        if merge:  # the next step's margin
            self._fine_hop = regions.info["fine_hop"]
        locks = (regions.lock_of, regions.loff, regions.ladj, np.zeros((4, 0), np.int64))
        r = regions.count
        lstate = (np.zeros(r, np.int64), np.zeros(r, np.int64), np.zeros(r, np.int64))
        dom = np.zeros(r, np.int64)
        bd = np.zeros(r, np.int64)
        if regions.kind == "graph":  # regions are tree nodes: slot ranges
            nodes = regions.info["lock_nodes"]
            far = classify_ranges(self.ntop[nodes, START], self.ntop[nodes, END], regions.loff,
                                  regions.ladj, dlo, dhi, dom, bd, np.zeros(r, np.int64),
                                  INTERIOR)
        else:
            far = classify_regions(regions.lock_of, regions.loff, regions.ladj, dlo, dhi, dom,
                                   bd, np.zeros(r, np.int64), INTERIOR)
        # the statistics are worked out only when asked for (lock_stats): ~1 ms a step at N = 2e5
        self._regions = (regions, far / max(self.n, 1))
        self._lock_stats = None
        doms = (dom, bd, dlo, dhi, dtour_t, dtour_s)
        # how far an interior event may run ahead of the other domains: a few of
        # one domain's typical gaps between events (from the last step)
        per_domain = max(self.last_events / self.threads, 1.0)
        window = self.workers.window_events * self.dt / per_domain
        return self._on_threads(st, img_pos, img_vel, full, lambda bundles, stt:
                                self.workers.run(bundles, stt, locks, lstate, doms, window))

    def _on_threads(self, st, img_pos, img_vel, full, run):
        """Call ``run(bundles, stt)`` (the workers on the step's events) until it
        stops for a reason other than a full journal or log (grown, then the
        step resumes); the threads' statistics rows are added to st."""
        stt = self._scratch.get("stt", (self.threads, K.NSTAT))
        wall0 = self.workers.wall_s
        try:
            while True:
                status = run(self._bundles(img_pos, img_vel, full), stt)
                if status in (K.NEED_JOURNAL, K.NEED_LOG):
                    self._grow_journal() if status == K.NEED_JOURNAL else self._grow_log()
                    continue
                return status
        finally:
            self._add_rows(st, stt)
            st[K.S_ECYC] += (self.workers.wall_s - wall0) * cycles_per_second()

    @property
    def lock_stats(self):
        """The last threaded step's lock regions: count, degrees, particles per
        region, and the interior fraction (particles whose regions are at least
        INTERIOR hops from another domain's); None before such a step."""
        if self._regions is None:
            return None
        if self._lock_stats is None:
            regions, interior = self._regions
            self._lock_stats = {**regions.stats(), "interior_fraction": interior}
        return self._lock_stats

    def _rollback(self):
        K.rollback(self.pos, self.vel, self.tl, self.ncoll, self.tlast, self.anc, self.cis,
                   self.jslot, self.jvel, self.jtlast, int(self.ctr[JCOUNT]))
        self.ctr[JCOUNT] = 0
        if self._pool_start is not None:  # a pool step: its threads may have raced
            restore_start(self.vel, self.ncoll, self.tlast, self._pool_start)
            self._pool_start = None

    def _grow_journal(self):
        cap = 2 * self.jslot.shape[0]
        used = int(self.ctr[JCOUNT])
        for name in ("jslot", "jvel", "jtlast"):
            old = getattr(self, name)
            new = np.zeros((cap,) + old.shape[1:], old.dtype)
            new[:used] = old[:used]
            setattr(self, name, new)

    def _grow_log(self):
        cap = 2 * self.logt.shape[0]
        used = int(self.ctr[K.LCOUNT])
        logt = np.zeros(cap)
        logi = np.zeros((cap, 3), np.int64)
        logt[:used] = self.logt[:used]
        logi[:used] = self.logi[:used]
        self.logt, self.logi = logt, logi

    def events(self):
        """The event log: a structured array of every resolved collision, in order.

        Fields: ``step`` (index), ``t`` (s since that step's start), ``a`` and
        ``b`` (particle ids; b is FLOOR = -2 or CYLINDER = -3 for walls) and
        ``img`` (periodic image of b seen from a; 13 = none).
        """
        used = int(self.ctr[K.LCOUNT])
        out = np.zeros(used, dtype=[("step", np.int64), ("t", np.float64), ("a", np.int64),
                                    ("b", np.int64), ("img", np.int64)])
        bounds = self.log_steps + [(None, used)]
        for (step, start), (_, end) in zip(bounds[:-1], bounds[1:]):
            out["step"][start:end] = step
        out["t"] = self.logt[:used]
        out["a"] = self.logi[:used, 0]
        out["b"] = self.logi[:used, 1]
        out["img"] = self.logi[:used, 2]
        return out

    def _grow_pool(self):
        cap = 2 * self.xent.shape[0]
        self.xent = np.zeros(cap, np.int32)
        self.xnext = np.zeros(cap, np.int32)

    def close(self):
        """Stop the worker threads (if any)."""
        if self.workers is not None:
            self.workers.close()
            self.workers = None

    # ---- diagnostics ---------------------------------------------------------
    def initial_overlap(self, tol):
        """(largest relative overlap, id a, id b, pairs above tol) of the current state.

        Uses the engine's own tree and lists, so checking a large input state
        costs no memory beyond the engine's.
        """
        img_pos, img_vel, half, full = self.physics.domain.images(self.time)
        self._setup(img_pos, img_vel, half, touching_only=True)
        out = np.zeros(3, np.int64)
        worst = K.overlap_report(self.pos, self.rad, self.noff, self.nent, img_pos, tol, out)
        a = int(self.ids[out[0]]) if out[0] >= 0 else -1
        b = int(self.ids[out[1]]) if out[1] >= 0 else -1
        return float(worst), min(a, b), max(a, b), int(out[2])


    def memory_bytes(self):
        """Bytes held in the engine's arrays."""
        return sum(v.nbytes for v in vars(self).values() if isinstance(v, np.ndarray))
