"""``Simulation``: a state, its physics and a step length; ``run(steps)``; ``state``; ``stats``."""
import os
import subprocess
import sys
import time as _time

import numpy as np

from . import kernels as K
from .engine import Engine
from .parallel import cycles_per_second
from .errors import InputError
from .overlaps import OVERLAP_TOLERANCE
from .physics import Physics
from .state import State



def _tiny():
    """The tiny systems whose steps compile every kernel: a state and three
    physics (a periodic cube, a dish with gravity and the collapse guard, a
    shearing sheet with Bridges' law)."""
    from .domains import Dish, PeriodicCube, ShearingSheet
    from .forces import Gravity, Hill
    from .restitution import Bridges, CollapseGuard, Constant

    pos = np.array([[-0.3, 0.0, 0.6], [0.3, 0.01, 0.6]])
    vel = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    st = State(pos, vel, np.full(2, 0.1), np.ones(2))
    return st, [
        Physics(PeriodicCube(4.0), (), Constant(1.0)),
        Physics(Dish(2.0), (Gravity(9.81),), Constant(0.8), CollapseGuard(1e-4)),
        Physics(ShearingSheet(4.0, 4.0, 1e-3), (Hill(1e-3),), Bridges()),
    ]


def _compile_sequential():
    """The sequential engine's kernels (the event loop), in every domain."""
    st, systems = _tiny()
    for ph in systems:
        Engine(st, ph, 0.05).step()


def _compile_threaded(steps=2):
    """The threaded engine's kernels (the worker, the lock structures: its first
    step) and schedule auto's steps whose events run on one thread (its
    second: the event loop of ``_compile_sequential``)."""
    st, systems = _tiny()
    eng = Engine(st, systems[0], 0.05, threads=2, lock="graph", schedule="auto")
    for _ in range(steps):
        eng.step()
    eng.close()


def _compile_pool():
    """Schedule "pool"'s kernels (``pool.pool_worker``, the step's first
    events and masks), in every domain."""
    st, systems = _tiny()
    for ph in systems:
        eng = Engine(st, ph, 0.05, threads=2, schedule="pool")
        try:
            for _ in range(2):
                eng.step()
        finally:
            eng.close()


def _on_disk(dispatcher):
    """Has numba's on-disk cache a compiled version of this kernel's current source?"""
    try:  # numba internals: any surprise means "no", which costs only time
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:
        return False


# what this process has compiled or loaded already: part ("base", "pool") ->
# the seconds it took (compile_kernels)
_COMPILED = {}


def compile_kernels(processes=2, pool=False):
    """Compile (or load from numba's on-disk cache) every kernel by running
    tiny systems in each domain, sequential and threaded, and with ``pool``
    also schedule "pool"'s.  Returns the seconds it took; a part this process
    has already compiled or loaded is not done again (its first seconds
    count), so a pool ``Simulation`` after a default one loads only the
    pool's kernels.

    Measured cold on the AMD machine of 2026-12-07, one after another in one
    process: the sequential kernels 47 s, then the threaded ones (the
    worker, the lock structures) 48 s, then the pool's 52 s.  With
    ``processes=2`` the threaded kernels, and with ``pool`` the pool's, are
    each compiled into numba's cache by a helper process of their own when
    their biggest kernel (``parallel.worker``, ``pool.pool_worker``) is not
    on disk, while this process compiles the sequential kernels; this
    process then loads them (or compiles what a helper did not leave,
    should it fail).
    """
    from .parallel import worker
    from .pool import pool_worker

    if "base" not in _COMPILED:
        t0 = _time.perf_counter()
        helpers = []
        if processes > 1 and (os.cpu_count() or 1) > 1:
            # this package, wherever it was imported from
            root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
            env = dict(os.environ)
            env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in [env.get("PYTHONPATH")] if p])
            for fn, args, dispatcher, wanted in (("_compile_threaded", "1", worker, True),
                                                 ("_compile_pool", "", pool_worker, pool)):
                if wanted and not _on_disk(dispatcher):
                    helpers.append(subprocess.Popen(
                        [sys.executable, "-c", f"from {__name__} import {fn}; {fn}({args})"],
                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        try:
            _compile_sequential()
        finally:
            for helper in helpers:
                helper.wait()
        _compile_threaded()
        _COMPILED["base"] = _time.perf_counter() - t0
    if pool and "pool" not in _COMPILED:
        t0 = _time.perf_counter()
        _compile_pool()
        _COMPILED["pool"] = _time.perf_counter() - t0
    return _COMPILED["base"] + (_COMPILED["pool"] if pool else 0.0)


class Simulation:
    """Run a hard-sphere system with the collision engine.

    Parameters
    ----------
    state : State — initial particles (validated: inside the domain, no overlaps).
    physics : Physics — domain, forces, restitution law, collapse guard.
    dt : float, s — step length.
    threads : int — worker threads (1: sequential engine).
    lock : "none" | "grid" | "grid3d" | "graph" — spatial locks of the parallel
        engine (grid: 2-D x-y cells, 8 neighbours; grid3d: 26 neighbours).
    scale : float — SCALE of the lock graph (lock-node size in units of the
        largest radius plus search radius below it).
    policy : "exact" | "paper" — exact (default): causality violations are
        detected and repaired, so any thread count gives the sequential result
        bit for bit; paper: the paper's rule, violations only counted.
    schedule : "parallel" | "auto" | "pool" — threads > 1: a step's events always
        on the worker threads, or (exact policy) on them or on one thread,
        whichever measured faster lately, or (exact policy) on more domains
        than threads that any free thread takes, waiting by particle
        (``lockgraph/pool.py``; ``lock`` and ``scale`` are then not used); same
        result bit for bit (see ``Engine``).
    window_events : float or None — how far ahead of the other threads an
        interior event may run (see ``Engine``; None: the schedule's default).
    skin, leaf_size, collapse_limit — engine tuning (see ``Engine``).
    copy : bool — with False the simulation takes over the state's arrays
        instead of copying them (for systems near the memory limit); the State
        passed in must not be used afterwards.
    """

    def __init__(self, state, physics, dt, *, threads=1, lock="graph", scale=4.0,
                 policy="exact", skin=0.5, leaf_size=16, collapse_limit=10000, copy=True,
                 window_events=None, schedule="parallel"):
        if not isinstance(state, State):
            raise InputError("state", f"must be a lockgraph.State, got {type(state).__name__}")
        if not isinstance(physics, Physics):
            raise InputError("physics", f"must be a lockgraph.Physics, got {type(physics).__name__}")
        self.physics = physics
        physics.domain.check_inside(state.pos, state.radius)
        self.compile_s = compile_kernels(pool=schedule == "pool")
        self._engine = Engine(state, physics, dt, skin=skin, leaf_size=leaf_size,
                              collapse_limit=collapse_limit, copy=copy, threads=threads,
                              lock=lock, scale=scale, policy=policy,
                              window_events=window_events, schedule=schedule)
        self.threads = self._engine.threads
        self.lock = self._engine.lock
        self.scale = self._engine.scale
        self.policy = self._engine.policy
        self.schedule = self._engine.schedule
        worst, a, b, count = self._engine.initial_overlap(OVERLAP_TOLERANCE)
        if worst > OVERLAP_TOLERANCE:
            raise InputError("state.pos", f"particles {a} and {b} overlap by {worst:.3g} of their "
                             f"contact distance ({count} overlapping pairs; tolerance "
                             f"{OVERLAP_TOLERANCE:g})")
        self.initial_overlap = worst
        self.dt = self._engine.dt
        self.wall_s = 0.0
        self.steps = 0
        self.history = []  # one dict of statistics per step

    def run(self, steps, progress=None):
        """Advance ``steps`` steps.  ``progress(done, steps)`` is called after each step.

        On an error the state is left at the last completed step.
        """
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise InputError("steps", f"must be an integer >= 0, got {steps!r}")
        eng = self._engine
        for k in range(int(steps)):
            t0 = _time.perf_counter()
            st = eng.step(check_end=k == steps - 1)
            w = _time.perf_counter() - t0
            self.wall_s += w
            self.steps += 1
            self.history.append(self._step_record(st, w))
            if progress is not None:
                progress(k + 1, int(steps))
        return self

    def _step_record(self, st, wall):
        eng = self._engine
        return {
            "step": self.steps, "wall_s": wall, "events": int(st[K.S_POPS]),
            "collisions": int(st[K.S_PAIR] + st[K.S_WALL]),
            "mean_concurrency": float(st[K.S_CONC] / st[K.S_ECYC]) if st[K.S_ECYC] else 1.0,
            "blocked_picks": int(st[K.S_BLOCKED]),
            "violations": int(st[K.S_VIOL] + st[K.S_REACHOUT]),
            "repairs": eng.repairs,
            "wait_s": float(st[K.S_WAIT]) / cycles_per_second() if st[K.S_WAIT] else 0.0,
        }

    def _threaded_event_steps(self):
        eng = self._engine
        if eng.threads == 1:
            return 0
        if eng.scheduler is None:
            return self.steps
        return eng.scheduler.count[0]

    def close(self):
        """Stop the worker threads (threads > 1); the simulation cannot run after."""
        self._engine.close()

    @property
    def state(self):
        """The current state, ordered by particle id (a copy)."""
        return self._engine.state()

    @property
    def time(self):
        return self._engine.time

    @property
    def stats(self):
        """Totals over all steps run so far (dict)."""
        t = self._engine.totals
        pairs = int(t[K.S_PAIR])
        walls = int(t[K.S_WALL])
        out = {
            "steps": self.steps,
            "time": self._engine.time,
            "duration": self.steps * self.dt,
            "collisions": pairs + walls,
            "pair_collisions": pairs,
            "wall_collisions": walls,
            # pair impacts the collapse guard made elastic (within tc of a body's last)
            "guarded_impacts": int(t[K.S_GUARDED]),
            # sleepers woken by an impact faster than v_sleep (sleeping grains only)
            "woken": int(t[K.S_WOKEN]),
            "asleep": (int(np.count_nonzero(self._engine.tlast == K.ASLEEP))
                       if self._engine.sleeping else 0),
            "stale_events": int(t[K.S_STALE]),
            "grazing_events": int(t[K.S_GRAZE]),
            "search_growths": int(t[K.S_GROW]),
            "late_candidates": int(t[K.S_ADDED]),
            "max_overlap": max(float(t[K.S_MAXOV]), self.initial_overlap),
            "max_collisions_per_step": int(t[K.S_MAXCIS]),
            "virial": float(t[K.S_VIRIAL]),
            # sum over pair collisions of (x_i - x_j) * (y-momentum given to i), kg m^2/s
            "momentum_flux_xy": float(t[K.S_XFLUX]),
            "floor_impulse": float(t[K.S_FLOORIMP]),
            "cylinder_impulse": float(t[K.S_CYLIMP]),
            "wall_s": self.wall_s,
            # wall seconds by phase: search (tree, pair search), events (first
            # predictions, queues, events), other, step (Engine.phase_seconds)
            "phase_s": self._engine.phase_seconds,
            "compile_s": self.compile_s,
            "events_per_s": (pairs + walls) / self.wall_s if self.wall_s > 0 else 0.0,
            "threads": self.threads,
            "lock": self.lock,
            "scale": self.scale,
            "policy": self.policy,
            "events": int(t[K.S_POPS]),
            # time-averaged number of threads busy with events while they ran
            "mean_concurrency": (float(t[K.S_CONC] / t[K.S_ECYC]) if t[K.S_ECYC] else 1.0),
            "blocked_picks": int(t[K.S_BLOCKED]),
            # pool: domains a thread switched to because another thread asked
            # (a pick of that one held back by it: ``pool._ask``)
            "asked_switches": int(t[K.S_ASKED]),
            "violations": int(t[K.S_VIOL] + t[K.S_REACHOUT]),
            "repairs": self._engine.repairs,
            # of those, pool steps redone on the threads (``Engine.pool_redo``)
            "repairs_on_threads": self._engine.repairs_on_threads,
            "wait_s": float(t[K.S_WAIT]) / cycles_per_second() if t[K.S_WAIT] else 0.0,
            "locks": self._engine.lock_stats,
            "schedule": self.schedule,
            # steps whose events ran on the worker threads (the rest: on one thread)
            "threaded_event_steps": self._threaded_event_steps(),
        }
        return out
