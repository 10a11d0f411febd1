"""Checks of a state against its domain: inside the boundaries, no overlapping pair."""
import numpy as np

from .errors import InputError
from .kernels import overlap_report
from .neighbors import build_csr
from .tree import build, count_nodes, node_bounds, pair_search, search_tasks

# Relative overlap (contact - distance)/contact accepted in an input state.  The
# engine's own states carry overlaps of order 1e-15 (rounding at contact), so
# 1e-9 separates rounding from genuinely overlapping input by six orders.
OVERLAP_TOLERANCE = 1e-9


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
    stack = np.zeros((4096, 3), np.int64)
    tasks = search_tasks(ntop, half, 1)[0]
    while True:
        out_a = np.zeros((1, cap), np.int32)
        out_e = np.zeros((1, cap), np.int32)
        m = pair_search(anc, rad, ntop, nbox, nreach, tasks, img_pos, out_a[0], out_e[0], stack,
                        np.zeros(2))
        if m <= cap:
            break
        cap = m + 1024
    noff = np.zeros(n + 1, np.int64)
    nent = np.zeros(2 * m, np.int32)
    build_csr(n, np.array([[0, 0, m]], np.int64), 1, out_a, out_e, noff, nent)
    out = np.zeros(3, np.int64)
    worst = overlap_report(anc, rad, noff, nent, img_pos, OVERLAP_TOLERANCE, out)
    a = int(perm[out[0]]) if out[0] >= 0 else -1
    b = int(perm[out[1]]) if out[1] >= 0 else -1
    return float(worst), min(a, b), max(a, b), int(out[2])


def check_state(state, domain):
    """Raise InputError unless every particle is inside the domain and none overlap."""
    domain.check_inside(state.pos, state.radius)
    worst, a, b, count = max_overlap(state, domain)
    if worst > OVERLAP_TOLERANCE:
        raise InputError("state.pos", f"particles {a} and {b} overlap by {worst:.3g} of their "
                         f"contact distance ({count} overlapping pairs; tolerance "
                         f"{OVERLAP_TOLERANCE:g})")
    return worst
