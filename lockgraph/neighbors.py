"""Per-particle candidate lists for one step.

A candidate entry is packed into one int32: ``(j << 5) | img`` — partner slot j
in periodic image img (0..26, 13 = no shift).  The lists are symmetric: if i
lists (j, img) then j lists (i, 26 - img).

* The bulk comes from the tree's pair search and is stored as CSR:
  ``noff`` (N+1,) int64 offsets into ``nent`` (2*pairs,) int32.
* Pairs discovered later in the step (a particle's search radius grew after a
  collision) go to a pool of singly linked extras: ``xhead`` (N,) int32 first
  entry or -1, ``xent`` / ``xnext`` (X,) int32, and ``ctr[XCOUNT]`` entries used.
"""

from ._jit import kernel
from .atomics import cas, fetch_add, load

XCOUNT = 0  # ctr slot: extras used
JCOUNT = 1  # ctr slot: journal entries used
# ctr slot 2 is the engine's CTR_BAD
LCOUNT = 3  # ctr slot: event-log entries used
TCOUNT = 4  # ctr slot: trace entries used
NCTR = 8


@kernel
def build_csr(n, seg, nseg, out_a, out_e, noff, nent):
    """Symmetric CSR lists from the pair search's output, read in segments:
    segment q is ``out_a[p, f:f + c]``, ``out_e[p, f:f + c]`` with ``(p, f,
    c) = seg[q]``, q = 0..nseg-1 (``tree.pair_search_claimed``'s tasks).
    Each list holds its entries in segment order.  A slot's offset serves
    as its cursor while its list is filled (the counts in ``noff[i + 1]``,
    turned into starts, each left at its list's end: the next one's start),
    so no pass shifts them back.  (Built on both threads, each the lists of
    its half of the slots after a barrier in the pair search's call, it
    measured no faster: README, Benchmarks.)"""
    noff[0] = 0
    for i in range(n):
        noff[i + 1] = 0
    for q in range(nseg):
        p = seg[q, 0]
        for k in range(seg[q, 1], seg[q, 1] + seg[q, 2]):
            noff[out_a[p, k] + 1] += 1
            noff[(out_e[p, k] >> 5) + 1] += 1
    run = 0
    for i in range(n):
        c = noff[i + 1]
        noff[i + 1] = run
        run += c
    for q in range(nseg):
        p = seg[q, 0]
        for k in range(seg[q, 1], seg[q, 1] + seg[q, 2]):
            a = out_a[p, k]
            e = out_e[p, k]
            b = e >> 5
            nent[noff[a + 1]] = e
            noff[a + 1] += 1
            nent[noff[b + 1]] = (a << 5) | (26 - (e & 31))
            noff[b + 1] += 1


@kernel
def has_entry(noff, nent, xhead, xent, xnext, i, packed):
    for k in range(noff[i], noff[i + 1]):
        if nent[k] == packed:
            return True
    x = xhead[i]
    while x >= 0:
        if xent[x] == packed:
            return True
        x = xnext[x]
    return False


@kernel(inline=True)
def _push(xhead, xent, xnext, owner, x, packed):
    """Prepend entry x to owner's list (lock-free: other threads may push too)."""
    xent[x] = packed
    while True:
        old = load(xhead, owner)
        xnext[x] = old
        if cas(xhead, owner, old, x) == old:
            return


@kernel
def add_pair(noff, nent, xhead, xent, xnext, ctr, a, b, img):
    """Add the symmetric candidate pair (a, b in image img) unless present.

    Returns 1 if added, 0 if it was already there, -1 if the pool is full.
    Safe against other threads adding to the pool at the same time.
    """
    packed = (b << 5) | img
    if has_entry(noff, nent, xhead, xent, xnext, a, packed):
        return 0
    x = fetch_add(ctr, XCOUNT, 2)
    if x + 2 > xent.shape[0]:
        return -1
    _push(xhead, xent, xnext, a, x, packed)
    _push(xhead, xent, xnext, b, x + 1, (a << 5) | (26 - img))
    return 1
