"""Does the host give this machine two cores right now?

This machine is a virtual one.  Measured here (2026-12-04, ``memprobe`` runs
of 60 s, no other process in the machine): a register-only loop ran on two
threads at once at ~1.9 times one thread's rate in some stretches and at
~1.0 in others, switching within a second, while /proc/stat's ``steal``
hardly moved and both threads had the full CPU time the guest kernel could
see.  A 2-thread speedup measured in such a stretch says nothing about the
code.  So the speedup benchmark runs this probe beside the engines' steps and
reports which steps ran while two cores were there.

``TwoCoreProbe().measure()``: one thread runs a dependent multiply chain
(``chain``, about 4 ms, no memory traffic), then two threads run it at once;
returns 2 x (one thread's time) / (two threads' time): about 2 with two cores,
about 1 with one.
"""
import time
from concurrent.futures import ThreadPoolExecutor

from numba import njit

CHAIN = 3_000_000  # multiply-xorshift steps: about 4 ms on this machine
# two cores, or not: the probe's values fall in two groups, 1.8-2.0 and
# 0.95-1.3 (174 probes, 60 s, idle machine); 1.6 splits them
TWO_CORES = 1.6


@njit(cache=True, nogil=True)
def chain(n, seed):
    """n steps of a 64-bit LCG with an xorshift: each step waits on the last."""
    x = seed
    for _ in range(n):
        x = x * 6364136223846793005 + 1442695040888963407
        x ^= x >> 13
    return x


class TwoCoreProbe:
    """Two probe threads (asleep between probes) and the measurement."""

    def __init__(self, n=CHAIN):
        self.n = int(n)
        self._ex = ThreadPoolExecutor(2, thread_name_prefix="host-probe")
        chain(10, 1)  # compile (or load) before any timing
        self.measure()  # start both threads

    def measure(self):
        """2 x (one thread's time) / (two threads' time) for ``chain``."""
        t0 = time.perf_counter()
        chain(self.n, 1)
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        jobs = [self._ex.submit(chain, self.n, s) for s in (2, 3)]
        for j in jobs:
            j.result()
        two = time.perf_counter() - t0
        return 2.0 * one / two

    def close(self):
        self._ex.shutdown()
