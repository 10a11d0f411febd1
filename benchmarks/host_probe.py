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

A third probe, ``alu`` (eight independent multiply chains: throughput-bound,
as a core shared with another guest's thread would show), was added on
2026-12-04 evening, when runs of the ring showed steps whose 2-thread
speedup fell to 1.55-1.65x while the sequential engine kept its pace.
Over 1,200 steps of 20 benchmark runs (the ring, N = 200,000, pool engines)
the median paired speedup was 1.64x in the steps whose memory probe read
1.2-1.5 against 1.82-1.83x in those at 1.7 and above, and 1.62-1.68x in
the steps whose ``alu`` probe read 1.5-1.85 against 1.83x at 1.85 and above:
the host takes memory bandwidth or a share of a core, for seconds at a time.
``volley`` times a cache line handed back and forth between the two
threads: 675 ns a round trip through one minute that evening, 130-170 ns a
few minutes later (the host had moved the virtual CPUs); the pool's events
hand lines across at every boundary event.  Later that night the round trip
switched between two levels, 130-200 ns and 340-550 ns, every few minutes.
Over 270 steps of the 50,000-grain bed (pool engines, nine benchmark runs),
31 of the 34 steps slower than 1.3x came after a round trip of 300 ns or
more; in an instrumented run (50 steps, 33 of them after a round trip of 250
ns or more) the sequential engine's events cost the same in both levels
(2,404 and 2,415 cycles each) while the 2-thread pool's rose from 3,127 to
5,074 cycles in every part, its own domain's queue updates included (472 to
754): data the other thread touched last comes from far away.  The register,
throughput and memory probes do not see this; ``near(probes)`` does.

``TwoCoreProbe().measure()``: one thread runs a probe, then two threads run
it at once, for each of ``chain`` (a dependent multiply chain, about 4 ms, no
memory traffic), ``gather`` and ``alu`` (about 4 ms); returns 2 x (one
thread's time) / (two threads' time) of each, as (chain, gather, alu): about
2 when the host gives two threads twice the work, about 1 when it gives them
one thread's worth; and ``handoff_ns``, a cache line's round trip between
the threads (ns).  ``clear(probes)``: did the host leave two full cores at
that probe (each of the three rates at least ``TWO_CORES``)?  ``near(probes)``:
was the round trip below ``FAR_NS``?  ``far(probes)``: was it at least
``FAR_NS`` and below ``LATE_NS`` (the threads' cores far apart)?  Longer is
*late*: a thread the host paused during the exchanges (until 2026-12-05 also
the partner thread's wake-up, which the timing then included), no distance.
"""
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from lockgraph.atomics import load, store
from lockgraph.parallel import cache_aligned

CHAIN = 3_000_000  # multiply-xorshift steps: about 4 ms on this machine
GATHER_MB = 64  # per thread: twice the 32 MB L3 of this machine's EPYC
GATHER_READS = 300_000  # about 5 ms on one thread
ALU = 1_000_000  # steps of the eight chains: about 4 ms
VOLLEYS = 2000  # exchanges of a cache line between the two threads: about 1.5 ms
WARM = 50  # exchanges before the timing: the partner thread is running by then
# two cores, or not: the probe's values fall in two groups, 1.8-2.0 and
# 0.95-1.3 (174 probes, 60 s, idle machine); 1.6 splits them
TWO_CORES = 1.6
# between the two levels the round trip took on 2026-12-04 (130-200 ns and
# 340-550 ns; a partner thread the host did not run at all took 4-8 us), and
# on 2026-12-05 with the partner's wake-up left out (62-126 and 325-395 ns)
FAR_NS = 250.0
# a round trip this long is not the distance between the cores: the partner
# thread (woken by the pool for the exchanges) started late.  On 2026-12-05
# (EPYC; 3,030 bed steps of 101 benchmark runs, pool 8 and 16), the paired
# median was 1.76x after a round trip below 250 ns (2,046 steps), 1.34x at
# 250-400 ns (56), 1.09x at 400-700 ns (440), 1.69x at 700-2,000 ns (64) and
# 1.72x at 2 us or more (424): above 700 ns the steps ran like the near ones.
# Since then the exchanges are timed from the end of ``WARM`` first ones: over
# 360 probes of eight bed runs none was late, the round trip took 62-126 ns
# or 325-395 ns, and the paired median was 1.75x after the short one (199
# steps) and 1.09x after the long one (41)
LATE_NS = 700.0


@njit(cache=True, nogil=True)
def chain(n, seed):
    """n steps of a 64-bit LCG with an xorshift: each step waits on the last."""
    x = seed
    for _ in range(n):
        x = x * 6364136223846793005 + 1442695040888963407
        x ^= x >> 13
    return x


@njit(cache=True, nogil=True)
def alu(n, seed):
    """n steps of eight independent LCGs with an xorshift: no step waits on
    another, so the core's multipliers, not latency, set the pace."""
    a = seed
    b = seed + 1
    c = seed + 2
    d = seed + 3
    e = seed + 4
    f = seed + 5
    g = seed + 6
    h = seed + 7
    for _ in range(n):
        a = a * 6364136223846793005 + 1442695040888963407
        b = b * 6364136223846793005 + 1442695040888963407
        c = c * 6364136223846793005 + 1442695040888963407
        d = d * 6364136223846793005 + 1442695040888963407
        e = e * 6364136223846793005 + 1442695040888963407
        f = f * 6364136223846793005 + 1442695040888963407
        g = g * 6364136223846793005 + 1442695040888963407
        h = h * 6364136223846793005 + 1442695040888963407
        a ^= a >> 13
        b ^= b >> 13
        c ^= c >> 13
        d ^= d >> 13
        e ^= e >> 13
        f ^= f >> 13
        g ^= g >> 13
        h ^= h >> 13
    return a ^ b ^ c ^ d ^ e ^ f ^ g ^ h


@njit(cache=True, nogil=True)
def volley(word, me, n, start):
    """Player ``me`` (0 or 1) of exchanges ``start`` .. ``start + n - 1`` of
    one cache line: each waits for its turn's value in ``word[0]`` and writes
    the next (atomic load and store: a plain load would be hoisted out of the
    loop)."""
    for k in range(start, start + n):
        want = 2 * k + me
        while load(word, 0) != want:
            pass
        store(word, 0, want + 1)
    return 0


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
        alu(10, 1)
        self._word = cache_aligned((8,), np.int64)
        volley(self._word, 0, 1, 0)  # compile both players' calls: 0 -> 1
        volley(self._word, 1, 1, 0)  # 1 -> 2
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

    def handoff_ns(self, n=VOLLEYS):
        """Nanoseconds for one cache line to go from one thread to the other and
        back: the mean of n exchanges, timed from the end of ``WARM`` first
        ones, so that the partner thread's wake-up is not in it (it was until
        2026-12-05: "late" round trips of 0.7-8 us, ``LATE_NS``).  A pause of
        either thread by the host within the exchanges still shows as an
        outlier of microseconds."""
        self._word[0] = 0
        other = self._ex.submit(volley, self._word, 1, WARM + n, 0)
        volley(self._word, 0, WARM, 0)  # returns once the partner is exchanging
        t0 = time.perf_counter()
        volley(self._word, 0, n, WARM)
        dt = time.perf_counter() - t0
        other.result()
        return dt / n * 1e9

    def measure(self):
        """(chain, gather, alu, handoff): 2 x (one thread's time) / (two threads'
        time) of each of the first three, and ``handoff_ns``."""
        return (self._scale(chain, [(self.n, 2), (self.n, 3)]),
                self._scale(gather, [(a, GATHER_READS, s) for s, a in enumerate(self._mem)]),
                self._scale(alu, [(ALU, 2), (ALU, 3)]), self.handoff_ns())

    def close(self):
        self._ex.shutdown()


def clear(probes):
    """Did the host leave this machine two full cores at a probe (``measure``'s
    tuple): each of its three rates at least ``TWO_CORES``?"""
    return min(probes[:3]) >= TWO_CORES


def near(probes):
    """Were the two threads near each other at a probe (``measure``'s tuple): a
    cache line's round trip between them below ``FAR_NS``?"""
    return probes[3] < FAR_NS


def far(probes):
    """Were the two threads far apart at a probe: a round trip of at least
    ``FAR_NS`` but below ``LATE_NS`` (longer: a thread paused by the host,
    which says nothing of the distance)?"""
    return FAR_NS <= probes[3] < LATE_NS
