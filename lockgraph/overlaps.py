"""Checks of a state against its domain: inside the boundaries, no overlapping pair."""
import math

import numpy as np

from ._jit import kernel
from .errors import InputError
from .tree import build, count_nodes, node_bounds, pair_search

# Relative overlap (contact - distance)/contact accepted in an input state.  The
# engine's own states carry overlaps of order 1e-15 (rounding at contact), so
# 1e-9 separates rounding from genuinely overlapping input by six orders.
OVERLAP_TOLERANCE = 1e-9


@kernel
def _pair_overlaps(pos, rad, out_a, out_e, npairs, img_pos, res_ov, res_a, res_b):
    """Largest relative overlap among candidate pairs and how many exceed tol."""
    worst = 0.0
    count = 0
    for k in range(npairs):
        a = out_a[k]
        b = out_e[k] >> 5
        img = out_e[k] & 31
        dx = pos[a, 0] - pos[b, 0] - img_pos[img, 0]
        dy = pos[a, 1] - pos[b, 1] - img_pos[img, 1]
        dz = pos[a, 2] - pos[b, 2] - img_pos[img, 2]
        c = rad[a] + rad[b]
        ov = (c - math.sqrt(dx * dx + dy * dy + dz * dz)) / c
        if ov > res_ov[1]:
            count += 1
        if ov > worst:
            worst = ov
            res_a[0] = a
            res_b[0] = b
    res_ov[0] = worst
    return count


def max_overlap(state, domain):
    """(largest relative overlap, id a, id b, pairs above tolerance) of a state."""
    n = state.n
    if n < 2:
        return 0.0, -1, -1, 0
    pos = state.pos.copy()
    perm = np.arange(n, dtype=np.int32)
    leaf = 8
    ntop = np.zeros((count_nodes(n, leaf), 6), np.int32)
    nn = build(pos, leaf, perm, ntop, np.zeros(256, np.int64))
    anc = pos[perm]
    rad = state.radius[perm]
    nbox = np.zeros((nn, 6))
    nreach = np.zeros(nn)
    node_bounds(anc, rad, ntop, nn, nbox, nreach)
    img_pos, img_vel, half, full = domain.images(state.time)
    cap = 4 * n + 1024
    stack = np.zeros((4096, 2), np.int64)
    while True:
        out_a = np.zeros(cap, np.int32)
        out_e = np.zeros(cap, np.int32)
        m = pair_search(anc, rad, ntop, nbox, nreach, half, img_pos, out_a, out_e, stack,
                        np.zeros(2))
        if m <= cap:
            break
        cap = m + 1024
    res_ov = np.array([0.0, OVERLAP_TOLERANCE])
    res_a = np.array([-1], np.int64)
    res_b = np.array([-1], np.int64)
    count = _pair_overlaps(anc, rad, out_a, out_e, m, img_pos, res_ov, res_a, res_b)
    a = int(perm[res_a[0]]) if res_a[0] >= 0 else -1
    b = int(perm[res_b[0]]) if res_b[0] >= 0 else -1
    return float(res_ov[0]), a, b, int(count)


def check_state(state, domain):
    """Raise InputError unless every particle is inside the domain and none overlap."""
    domain.check_inside(state.pos, state.radius)
    worst, a, b, count = max_overlap(state, domain)
    if worst > OVERLAP_TOLERANCE:
        raise InputError("state.pos", f"particles {a} and {b} overlap by {worst:.3g} of their "
                         f"contact distance ({count} overlapping pairs; tolerance "
                         f"{OVERLAP_TOLERANCE:g})")
    return worst
