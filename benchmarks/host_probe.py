"""Does the host give this machine two cores right now?

This machine is a virtual one.  Measured here (2026-12-04, a probe script
run for 60 s, no other process in the machine): a register-only loop ran on two
threads at once at ~1.9 times one thread's rate in some stretches and at
~1.0 in others, switching within a second, while /proc/stat's ``steal``
hardly moved and both threads had the full CPU time the guest kernel could
see.  A 2-thread speedup measured in such a stretch says nothing about the
code.  So the speedup benchmark runs this probe beside the engines' steps and
reports what the host gave two threads while the steps ran.

The host also contends for the memory side (caches, memory bandwidth), which
a register-only loop does not see: random reads over 128 MB per thread
ran two threads at 0.7-2.7 times one thread's rate in the same minute
(median 1.50), and in benchmark runs whose register probes found two cores
in 83-92 % of the probes, the data-parallel search phase still fell to
1.6x.  ``gather`` reads 64 MB per thread.

``TwoCoreProbe().measure()``: one thread runs a probe, then two threads run
it at once, for each of ``chain`` (a dependent multiply chain, about 4 ms, no
memory traffic) and ``gather``; returns 2 x (one thread's time) / (two
threads' time) of each, as (chain, gather): about 2 when the host gives two
threads twice the work, about 1 when it gives them one thread's worth.
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

CHAIN = 3_000_000  # multiply-xorshift steps: about 4 ms on this machine
GATHER_MB = 64  # per thread: twice the 32 MB L3 of this machine's EPYC
GATHER_READS = 300_000  # about 5 ms on one thread
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


@njit(cache=True, nogil=True)
def gather(a, n, seed):
    """n reads of a at indices from an LCG (independent of the data read)."""
    x = seed
    s = 0.0
    m = a.shape[0]
    for _ in range(n):
        x = (x * 6364136223846793005 + 1442695040888963407) & 0x7FFFFFFFFFFFFFFF
        s += a[x % m]
    return s


class TwoCoreProbe:
    """Two probe threads (asleep between probes) and the measurement."""

    def __init__(self, n=CHAIN):
        self.n = int(n)
        self._ex = ThreadPoolExecutor(2, thread_name_prefix="host-probe")
        m = GATHER_MB * 2**20 // 8
        self._mem = [np.random.default_rng(s).random(m) for s in (1, 2)]
        chain(10, 1)  # compile (or load) before any timing
        gather(self._mem[0], 10, 1)
        self.measure()  # start both threads

    def _scale(self, fn, args):
        t0 = time.perf_counter()
        fn(*args[0])
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        jobs = [self._ex.submit(fn, *a) for a in args]
        for j in jobs:
            j.result()
        return 2.0 * one / (time.perf_counter() - t0)

    def measure(self):
        """(chain, gather): 2 x (one thread's time) / (two threads' time) of each."""
        return (self._scale(chain, [(self.n, 2), (self.n, 3)]),
                self._scale(gather, [(a, GATHER_READS, s) for s, a in enumerate(self._mem)]))

    def close(self):
        self._ex.shutdown()
