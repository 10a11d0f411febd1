"""The time-ordered event queue: one pending event per particle, in a tournament tree.

Per storage slot ``i``:

* ``evt[i]``: step time of i's earliest predicted event (s), ``inf`` if none
  before the step end;
* ``evp[i]``: the partner: ``(j << 5) | img`` for particle j in image img,
  ``FLOOR`` or ``CYLINDER`` for walls, ``NONE``;
* ``evc[i]``: the partner's collision counter (low 32 bits) when the event was
  predicted.  The event is stale when the partner has collided since.

The queue is a tournament tree over *buckets* of ``BUCKET`` consecutive slots
(storage is in tree order, so a bucket is a small spatial region): leaf
``Q + b`` holds the earliest event of bucket b, each inner node the earlier of
its two children, the root the earliest of all.  Nodes store their winner's
key — ``tour_t`` (2Q,) float64 time and ``tour_s`` (2Q,) int32 slot — so a
climb compares neighbouring memory and never chases particles.  Events are
ordered by (time, particle id): the order depends only on the physics and the
ids, never on storage order or thread count.  ``hidden`` (N,) uint8 takes a
slot out of the queue without touching its event (worker threads hide events
in flight or passed over).
"""
import numpy as np
from ._jit import kernel

NONE = -1
FLOOR = -2
CYLINDER = -3


BUCKET_BITS = 3
BUCKET = 1 << BUCKET_BITS


def tournament_size(n):
    """Q: the number of leaves (a power of two >= the number of buckets of n slots)."""
    buckets = (max(n, 1) + BUCKET - 1) // BUCKET
    q = 1
    while q < buckets:
        q *= 2
    return q


@kernel(inline=True)
def key_less(t1, s1, t2, s2, ids):
    """(t1, slot s1) before (t2, slot s2)?  Slot -1 means 'none'."""
    if t1 < t2:
        return True
    if t1 > t2:
        return False
    if s2 < 0:
        return s1 >= 0
    if s1 < 0:
        return False
    return ids[s1] < ids[s2]


@kernel(inline=True)
def earlier(a, b, evt, ids):
    """True if slot a's event comes before slot b's (-1 means 'no slot')."""
    if a < 0:
        return False
    if b < 0:
        return True
    return key_less(evt[a], a, evt[b], b, ids)


@kernel(inline=True)
def _bucket_min(evt, ids, hidden, lo, hi, b):
    """Earliest event of bucket b of the slot range lo..hi-1."""
    first = lo + (b << BUCKET_BITS)
    last = min(first + BUCKET, hi)
    bt = np.inf
    bs = -1
    for k in range(first, last):
        if hidden[k] == 0 and key_less(evt[k], k, bt, bs, ids):
            bt = evt[k]
            bs = k
    return bt, bs


@kernel
def build_queue(tour_t, tour_s, evt, ids, hidden, lo, hi):
    """Build the tournament over slots lo..hi-1 (a domain; the whole system: 0..N)."""
    build_leaves(tour_t, tour_s, evt, ids, hidden, lo, hi, 0, tour_t.shape[0] >> 1)
    build_inner(tour_t, tour_s, ids)


@kernel(inline=True)
def buckets_of(n):
    """The buckets that slots 0..n-1 fill (the last one possibly in part)."""
    return (n + BUCKET - 1) >> BUCKET_BITS


@kernel(inline=True)
def build_leaves(tour_t, tour_s, evt, ids, hidden, lo, hi, b0, b1):
    """Leaves b0..b1-1 of the tournament over slots lo..hi-1: each bucket's
    earliest event (none past the last slot's bucket)."""
    q = tour_t.shape[0] >> 1
    for b in range(b0, b1):
        t, s = _bucket_min(evt, ids, hidden, lo, hi, b)
        tour_t[q + b] = t
        tour_s[q + b] = s


@kernel(inline=True)
def build_inner(tour_t, tour_s, ids):
    """The tournament's inner nodes, from its leaves."""
    q = tour_t.shape[0] >> 1
    for k in range(q - 1, 0, -1):
        a = 2 * k
        if key_less(tour_t[a + 1], tour_s[a + 1], tour_t[a], tour_s[a], ids):
            a += 1
        tour_t[k] = tour_t[a]
        tour_s[k] = tour_s[a]


@kernel(inline=True)
def _climb_node(tour_t, tour_s, ids, k):
    """Recompute node k from its children; False if it is unchanged."""
    a = 2 * k
    if key_less(tour_t[a + 1], tour_s[a + 1], tour_t[a], tour_s[a], ids):
        a += 1
    t = tour_t[a]
    s = tour_s[a]
    if tour_t[k] == t and tour_s[k] == s:
        return False
    tour_t[k] = t
    tour_s[k] = s
    return True


@kernel(inline=True)
def _set_leaf(tour_t, tour_s, evt, ids, hidden, lo, hi, i, b):
    """Recompute leaf of bucket b after evt[i] changed; False if nothing above can change."""
    q = tour_t.shape[0] >> 1
    t, s = _bucket_min(evt, ids, hidden, lo, hi, b)
    k = q + b
    if tour_t[k] == t and tour_s[k] == s and s != i:
        return False
    tour_t[k] = t
    tour_s[k] = s
    return True


@kernel(inline=True)
def update_queue(tour_t, tour_s, evt, ids, hidden, lo, hi, i):
    """Restore the tournament of slots lo..hi-1 after evt[i] (or hidden[i]) changed.

    Recomputes i's bucket, then climbs; stops at the first node whose winner
    (time and slot) is unchanged — nothing above it can change either.
    """
    q = tour_t.shape[0] >> 1
    b = (i - lo) >> BUCKET_BITS
    if not _set_leaf(tour_t, tour_s, evt, ids, hidden, lo, hi, i, b):
        return
    k = (q + b) >> 1
    while k >= 1 and _climb_node(tour_t, tour_s, ids, k):
        k >>= 1


@kernel(inline=True)
def update_queue_pair(tour_t, tour_s, evt, ids, hidden, lo, hi, i, j):
    """``update_queue`` for i and then j (both changed), sharing their bucket
    and the climb above the node where their paths meet."""
    q = tour_t.shape[0] >> 1
    bi = (i - lo) >> BUCKET_BITS
    bj = (j - lo) >> BUCKET_BITS
    if bi == bj:
        # one scan sees both; a changed winner that is neither i nor j still
        # needs the climb, as in update_queue
        t, s = _bucket_min(evt, ids, hidden, lo, hi, bi)
        k = q + bi
        if tour_t[k] == t and tour_s[k] == s and s != i and s != j:
            return
        tour_t[k] = t
        tour_s[k] = s
        k >>= 1
        while k >= 1 and _climb_node(tour_t, tour_s, ids, k):
            k >>= 1
        return
    ui = _set_leaf(tour_t, tour_s, evt, ids, hidden, lo, hi, i, bi)
    uj = _set_leaf(tour_t, tour_s, evt, ids, hidden, lo, hi, j, bj)
    ki = (q + bi) >> 1
    kj = (q + bj) >> 1
    # both paths climb level by level (every leaf is at one depth) until they meet
    while ki != kj and (ui or uj):
        if ui:
            ui = _climb_node(tour_t, tour_s, ids, ki)
        if uj:
            uj = _climb_node(tour_t, tour_s, ids, kj)
        ki >>= 1
        kj >>= 1
    if not (ui or uj):
        return
    k = ki
    while k >= 1 and _climb_node(tour_t, tour_s, ids, k):
        k >>= 1
