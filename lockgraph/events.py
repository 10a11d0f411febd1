"""The time-ordered event queue: one pending event per particle, in a tournament tree.

Per storage slot ``i``:

* ``evt[i]``: step time of i's earliest predicted event (s), ``inf`` if none
  before the step end;
* ``evp[i]``: the partner: ``(j << 5) | img`` for particle j in image img,
  ``FLOOR`` or ``CYLINDER`` for walls, ``NONE``;
* ``evc[i]``: the partner's collision counter (low 32 bits) when the event was
  predicted.  The event is stale when the partner has collided since.

``tour`` (2P,) int32, P a power of two >= N, is a complete binary tree whose
leaf ``P + i`` is slot i and whose inner nodes hold the winner of their two
children.  Events are ordered by (time, particle id): the order depends only on
the physics and the ids, never on storage order or thread count.
"""
import numpy as np
from ._jit import kernel

NONE = -1
FLOOR = -2
CYLINDER = -3


def tournament_size(n):
    p = 1
    while p < max(n, 1):
        p *= 2
    return p


@kernel(inline=True)
def earlier(a, b, evt, ids):
    """True if slot a's event comes before slot b's (-1 means 'no slot')."""
    if a < 0:
        return False
    if b < 0:
        return True
    ta = evt[a]
    tb = evt[b]
    if ta < tb:
        return True
    if ta > tb:
        return False
    return ids[a] < ids[b]


@kernel
def build_queue(tour, evt, ids, n):
    p = tour.shape[0] >> 1
    for k in range(p):
        tour[p + k] = k if k < n else -1
    for k in range(p - 1, 0, -1):
        a = tour[2 * k]
        b = tour[2 * k + 1]
        tour[k] = a if earlier(a, b, evt, ids) else b


@kernel(inline=True)
def update_queue(tour, evt, ids, i):
    """Restore the tournament after evt[i] changed."""
    k = (tour.shape[0] >> 1) + i
    k >>= 1
    while k >= 1:
        a = tour[2 * k]
        b = tour[2 * k + 1]
        tour[k] = a if earlier(a, b, evt, ids) else b
        k >>= 1
