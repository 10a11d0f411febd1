"""What the host gives two threads of this very work, step by step.

``HostCeiling(state, physics, dt, split)`` runs two parts of the state, each
with its own sequential engine (``threads=1``), twice over: one pair steps
one part after the other on the calling thread (*alone*), the other pair
steps both parts at once, one on the calling thread and one on a second
thread (*at once*).  The pairs start from the same parts and the engines are
deterministic, so step i is the same work in both.  Nothing is shared
between the parts: no tree, no queue, no lock, no word either thread writes
for the other.  The ratio

    ceiling = (alone_1 + alone_2) / max(at_once_1, at_once_2)

is therefore what two cores of this host gave a 2-thread program doing the
engine's own work (tree, pair search, events) with no coordination cost at
all, at that moment: about 2 on two full cores, less when the host takes a
share of a core or of the memory side.  It is the reference a threaded
engine's speedup can be held to in a run on a shared machine.
``balanced``, printed beside, sums each part's rate at once over its rate
alone (alone_k / at_once_k): what a program that balanced its threads' work
perfectly could get, the parts' unequal work and a core the host slowed
left to the balancing.

The parts (``split``):

* ``"halves"``: the state cut at the median x into two halves of equal
  count, the threads' work and memory together the whole's.  Not the
  system (nothing crosses the cut: a free face there; a half keeps the
  whole's box), but where nothing pulls the particles across the face the
  halves keep the whole's work per particle: on the ring (N = 2e5, 30
  steps) the two halves alone took 50-60 ms a step, the whole 51-70 ms.
* ``"copies"``: two copies of the whole state, each thread the sequential
  engine's own work (twice the memory in all).  For scenes under gravity:
  a half of the 50,000-grain bed flows out through its face, and its step
  fell from 150-175 ms to 16-17 ms within 30 steps (2026-12-07).

``benchmarks/event_ceiling.py`` asks the same of the events phase alone,
over whole runs.
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from lockgraph.engine import Engine
from lockgraph.state import State


def half(state, sel):
    """The particles ``sel`` of ``state``, collision counts and guard clocks kept."""
    return State(state.pos[sel], state.vel[sel], state.radius[sel], state.mass[sel],
                 ncoll=state.ncoll[sel], t_last=state.t_last[sel], time=state.time)


def halves(state, axis=0):
    """The two halves of ``state`` cut at the median of ``axis`` (count-equal)."""
    order = np.argsort(state.pos[:, axis], kind="stable")
    cut = state.n // 2
    return [half(state, np.sort(order[:cut])), half(state, np.sort(order[cut:]))]


def _timed_step(eng):
    t0 = time.perf_counter()
    eng.step()
    return time.perf_counter() - t0


SPLITS = ("halves", "copies")


class HostCeiling:
    """Four sequential engines on two parts of a state (``split``: "halves"
    or "copies"): ``alone()`` steps one pair one part after the other,
    ``at_once()`` the other pair both parts at once on two threads; each
    returns the two parts' step times (s) and the wall time of the call (s),
    and appends the parts' ``Engine.phase_seconds`` of that step (a dict of
    two-item lists, s) to ``phases_alone`` or ``phases_at_once``."""

    def __init__(self, state, physics, dt, split="halves", axis=0):
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        self.split = split
        parts = halves(state, axis) if split == "halves" else [state, state]
        self.counts = [p.n for p in parts]
        self._alone = [Engine(p, physics, dt) for p in parts]
        self._once = [Engine(p, physics, dt) for p in parts]
        # one long-lived second thread (one started per step would add its
        # start-up to every timing), as host_probe's
        self._partner = ThreadPoolExecutor(1, thread_name_prefix="host-ceiling")
        self.phases_alone, self.phases_at_once = [], []

    def warm(self):
        """One untimed step of every engine (pools and lists grown to size),
        left out of the phase records."""
        self.alone()
        self.at_once()
        self.phases_alone.clear()
        self.phases_at_once.clear()

    @staticmethod
    def _phases(engs, before):
        after = [e.phase_seconds for e in engs]
        return {k: [a[k] - b[k] for a, b in zip(after, before)] for k in after[0]}

    def alone(self):
        before = [e.phase_seconds for e in self._alone]
        t0 = time.perf_counter()
        times = [_timed_step(e) for e in self._alone]
        wall = time.perf_counter() - t0
        self.phases_alone.append(self._phases(self._alone, before))
        return times, wall

    def at_once(self):
        before = [e.phase_seconds for e in self._once]
        t0 = time.perf_counter()
        other = self._partner.submit(_timed_step, self._once[1])
        mine = _timed_step(self._once[0])
        other = other.result()  # a failure there is raised here
        wall = time.perf_counter() - t0
        self.phases_at_once.append(self._phases(self._once, before))
        return [mine, other], wall

    def identical(self):
        """Did both pairs reach the same states (the same work was timed)?"""
        return all(a.state().sha256() == b.state().sha256()
                   for a, b in zip(self._alone, self._once))

    def close(self):
        self._partner.shutdown()
        for e in self._alone + self._once:
            e.close()
