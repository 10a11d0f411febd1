"""Binary kD-tree over step-start positions, and the searches that run on it.

The tree is rebuilt every step over the *anchors* (particle positions at the
start of the step).  Each node stores

* ``ntop[k] = (left, right, start, end, parent, axis)`` (int32): children (-1
  for a leaf), the half-open range of storage slots it covers, its parent and
  the axis it is split along;
* ``nbox[k] = (xlo, ylo, zlo, xhi, yhi, zhi)`` (float64, metres): bounding box of
  the anchors below it;
* ``nreach[k]``: the largest *reach* below it (m).

A particle's reach is ``sig + fr * radius``: ``sig`` (its search radius)
bounds how far it can move, in the frame where the step's background motion
vanishes, between the step start and the step end; ``fr >= 1`` accounts for the
shear of that frame (``fr = 1`` without shear).  Two particles ``a`` and ``b``
(``b`` in periodic image ``img``) can meet within the step only if::

    |anc[a] - anc[b] - img_pos[img]| <= reach[a] + reach[b]

Both searches here return exactly the pairs that satisfy it.  Reaches only
grow during a step (see ``raise_reach``).

Particles are stored in tree order: node ``k`` covers slots
``start..end-1``.  ``build`` returns the permutation that puts them there.
"""
import numpy as np

from ._jit import kernel
from .atomics import cas, claim_from_ends, fetch_add, fetch_max, float_bits, load, store

LEFT, RIGHT, START, END, PARENT, AXIS = 0, 1, 2, 3, 4, 5
NTOP = 6
SELF_IMAGE = 13  # image index of the box itself: (kx, ky, kz) = (0, 0, 0)


def count_nodes(n, leaf_size):
    """Number of nodes ``build`` creates for ``n`` particles."""
    memo = {}

    def count(m):
        if m <= leaf_size:
            return 1
        if m not in memo:
            memo[m] = 1 + count(m // 2) + count(m - m // 2)
        return memo[m]

    return count(max(n, 1))


@kernel(inline=True)
def _select_keyed(perm, keys, off, lo, hi, k):
    """Reorder perm[lo..hi] so that perm[k] holds the k-th smallest key, the
    key of perm[q] being keys[q + off] (moved along with it): the passes read
    contiguous keys instead of gathering positions."""
    while lo < hi:
        mid = (lo + hi) >> 1
        a = keys[lo + off]
        b = keys[mid + off]
        c = keys[hi + off]
        if a > b:
            a, b = b, a
        if b > c:
            b = c
        pivot = a if a > b else b
        i = lo
        j = hi
        while i <= j:
            while keys[i + off] < pivot:
                i += 1
            while keys[j + off] > pivot:
                j -= 1
            if i <= j:
                tmp = perm[i]
                perm[i] = perm[j]
                perm[j] = tmp
                x = keys[i + off]
                keys[i + off] = keys[j + off]
                keys[j + off] = x
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return


@kernel
def median_of(a, perm):
    """np.median(a), bit for bit, with ``a`` reordered (scratch) and ``perm``
    (int64, as long) scratch: the middle value by selection, and for an even
    count the mean of the two middle ones.  In Python, np.median of the
    engine's 1,024 sampled speeds took 0.2 ms of each ring step."""
    m = a.shape[0]
    h = m // 2
    _select_keyed(perm, a, 0, 0, m - 1, h)
    hi = a[h]
    if m % 2 == 1:
        return hi
    lo = a[0]
    for q in range(1, h):  # the largest of the lower half
        lo = max(lo, a[q])
    return (lo + hi) / 2.0


@kernel(inline=True)
def _split_keyed(pos, perm, axis, s, e, m, keys):
    """perm[s..e-1] split so that its m - s smallest keys come first; returns
    a key between the two parts."""
    for q in range(s, e):
        keys[q] = pos[perm[q], axis]
    _select_keyed(perm, keys, 0, s, e - 1, m)
    return keys[m]


@kernel(inline=True)
def _select_movers(pos, perm, slots, ids, nv, nl, axis, keys, s):
    """Of the nv particles in ``slots`` (the first nl of them left-half
    slots), the nl with the smallest keys end in left-half slots: the ones
    that change sides are swapped pairwise and all others keep their slots
    (and so their place in the children: a selection that shuffled them all
    made the children's splits move them again, all the way down).
    keys[s..s+nv-1] and ``ids`` are scratch.  Returns a key between the parts."""
    for q in range(nv):
        ids[q] = perm[slots[q]]
        keys[s + q] = pos[ids[q], axis]
    if nl == 0 or nl == nv:
        w = keys[s]
        for q in range(nv):
            w = max(w, keys[s + q]) if nl == nv else min(w, keys[s + q])
        return w
    _select_keyed(ids, keys, s, 0, nv - 1, nl)  # the nl smallest keys first
    wl = keys[s]
    for q in range(nl):
        wl = max(wl, keys[s + q])
    ties = 0  # of the nl smallest, those equal to wl
    for q in range(nl):
        if keys[s + q] == wl:
            ties += 1
    wr = keys[s + nl]
    for q in range(nl, nv):
        wr = min(wr, keys[s + q])
    # left slots whose particle goes right (ids: their indices in slots), then
    # each right slot whose particle goes left swaps with the next of them
    nleave = 0
    for q in range(nl):
        x = pos[perm[slots[q]], axis]
        if x < wl:
            continue
        if x == wl and ties > 0:
            ties -= 1
            continue
        ids[nleave] = q
        nleave += 1
    a = 0
    for q in range(nl, nv):
        x = pos[perm[slots[q]], axis]
        if x < wl or (x == wl and ties > 0):
            if x == wl:
                ties -= 1
            u = slots[ids[a]]
            t = perm[u]
            perm[u] = perm[slots[q]]
            perm[slots[q]] = t
            a += 1
    return 0.5 * (wl + wr)


@kernel
def skeleton(n, leaf_size, ntop, stack):
    """The tree's topology for n particles: node ranges, children and parents.

    It depends only on n and the leaf size (every node is split at its middle
    slot), so it is made once; ``resort`` fills in split axes and the order of
    the particles.  Returns the number of nodes, or -1 if ``stack`` was short.
    """
    ntop[0, LEFT] = -1
    ntop[0, RIGHT] = -1
    ntop[0, START] = 0
    ntop[0, END] = n
    ntop[0, PARENT] = -1
    ntop[0, AXIS] = 0
    nnodes = 1
    stack[0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        nd = stack[sp]
        s = ntop[nd, START]
        e = ntop[nd, END]
        if e - s <= leaf_size:
            continue
        m = (s + e) >> 1
        for c in range(2):
            k = nnodes + c
            ntop[k, LEFT] = -1
            ntop[k, RIGHT] = -1
            ntop[k, START] = s if c == 0 else m
            ntop[k, END] = m if c == 0 else e
            ntop[k, PARENT] = nd
            ntop[k, AXIS] = 0
        ntop[nd, LEFT] = nnodes
        ntop[nd, RIGHT] = nnodes + 1
        if sp + 2 > stack.shape[0]:
            return -1
        stack[sp] = nnodes + 1
        stack[sp + 1] = nnodes
        sp += 2
        nnodes += 2
    return nnodes


@kernel
def resort(pos, perm, ntop, root, max_depth, fresh, slots, ids, stack, nsplit, delta, keys, slab):
    """Put the particles of the subtree under ``root`` into tree order.

    Top-down over the subtree, down to ``max_depth`` levels below ``root``
    (negative: all the way).  ``fresh``: every node gets the longest axis of
    its particles' box and a median selection (a new tree); otherwise each
    node keeps last step's axis and split ``nsplit[node]`` and only the
    particles that crossed it are moved (``rebuild_node``); ``nsplit`` is
    updated.  ``slab`` (>= 0): a fresh node fewer than ``slab`` levels below
    the tree's root (node 0) is split along the root's axis, not its own
    longest, so the nodes ``slab`` levels down are slabs stacked along the
    scene's longest axis (the pool's domains: ``Engine._slab_levels``).
    Subtrees of different nodes are disjoint slot ranges: threads may re-sort
    them at the same time.  Returns -1 if ``stack`` was short.
    """
    stack[0] = root
    stack[1] = 0
    sp = 2
    while sp > 0:
        sp -= 2
        nd = stack[sp]
        depth = stack[sp + 1]
        left = ntop[nd, LEFT]
        if left < 0 or (max_depth >= 0 and depth >= max_depth):
            continue
        s = ntop[nd, START]
        e = ntop[nd, END]
        if fresh:
            lo0 = hi0 = pos[perm[s], 0]
            lo1 = hi1 = pos[perm[s], 1]
            lo2 = hi2 = pos[perm[s], 2]
            for k in range(s + 1, e):
                q = perm[k]
                x = pos[q, 0]
                y = pos[q, 1]
                z = pos[q, 2]
                lo0 = min(lo0, x)
                hi0 = max(hi0, x)
                lo1 = min(lo1, y)
                hi1 = max(hi1, y)
                lo2 = min(lo2, z)
                hi2 = max(hi2, z)
            axis = 0
            ext = hi0 - lo0
            if hi1 - lo1 > ext:
                axis = 1
                ext = hi1 - lo1
            if hi2 - lo2 > ext:
                axis = 2
            if nd != 0 and slab > 1:
                # within the top ``slab`` levels: the root's axis
                level = 1
                up = ntop[nd, PARENT]
                while up > 0 and level < slab:
                    level += 1
                    up = ntop[up, PARENT]
                if level < slab:
                    axis = ntop[0, AXIS]
            ntop[nd, AXIS] = axis
            nsplit[nd] = _split_keyed(pos, perm, axis, s, e, ntop[left, END], keys)
        else:
            rebuild_node(pos, perm, ntop, nsplit, nd, slots, ids, delta, keys)
        if sp + 4 > stack.shape[0]:
            return -1
        stack[sp] = ntop[nd, RIGHT]
        stack[sp + 1] = depth + 1
        stack[sp + 2] = left
        stack[sp + 3] = depth + 1
        sp += 4
    return 0


# a list of ``resort_stealing``: its packed word (next slot from the front in
# the low 32 bits, end from the back in the high), and on the next cache line
# its state
LIST_WORD, LIST_OPEN = 0, 8
NLIST = 16


@kernel(inline=True)
def _take(ctl, at, front):
    """Take an entry of the list whose packed word is ``ctl[at]``: its owner
    from the front, another thread from the back (one CAS, so both ends never
    take the same entry).  Returns the entry's index, -1 if none is left."""
    while True:
        w = load(ctl, at)
        h = w & 0xFFFFFFFF
        t = w >> 32
        if h >= t:
            return -1
        if front:
            k = h
            nw = (h + 1) | (t << 32)
        else:
            k = t - 1
            nw = h | (k << 32)
        if cas(ctl, at, w, nw) == w:
            return k


@kernel
def resort_stealing(me, pos, perm, ntop, root, depth, fresh, slots, ids, stack, nsplit, delta,
                    keys, below, nbelow, ctl, slab):
    """``resort`` of subtree ``me`` (node ``root``), shared out while it runs.

    The nodes of the subtree's top ``depth`` levels are re-sorted here; then
    its list ``below[me, :nbelow[me]]`` (the nodes ``depth`` levels down) is
    opened, and this call re-sorts them from the front while the calls of the
    other subtrees, done with their own, take them from the back.  A list
    not yet open when a call looks is left to its owner, so no call ever
    waits.  The nodes are disjoint slot ranges and each is re-sorted whole
    by one call, so the result is ``resort`` of the subtree, whoever took
    what.  ``ctl`` (NLIST words a list, zero at the start): the packed word
    and the state (1 open, -1 failed).  Scratch arrays as ``resort``, this
    call's own.  Returns 0, or -1 if ``stack`` was short.
    """
    at = me * NLIST
    if resort(pos, perm, ntop, root, depth, fresh, slots, ids, stack, nsplit, delta, keys,
              slab) < 0:
        store(ctl, at + LIST_OPEN, -1)
        return -1
    store(ctl, at + LIST_WORD, nbelow[me] << 32)
    store(ctl, at + LIST_OPEN, 1)  # after the levels above: a taker sees them done
    nl = below.shape[0]
    for r in range(nl):
        k = (me + r) % nl
        if r > 0 and load(ctl, k * NLIST + LIST_OPEN) != 1:
            continue
        while True:
            q = _take(ctl, k * NLIST + LIST_WORD, r == 0)
            if q < 0:
                break
            # -1 as an int64 value: a literal would compile resort once more
            if resort(pos, perm, ntop, below[k, q], np.int64(-1), fresh, slots, ids, stack,
                      nsplit, delta, keys, slab) < 0:
                return -1
    return 0


def build(pos, leaf_size, perm, ntop, stack):
    """A fresh tree over ``pos`` (N,3): ``skeleton`` then ``resort``.

    ``perm`` (N,) int32 must hold a permutation on entry; on exit slot ``k`` of
    tree order holds particle ``perm[k]``.  Returns the number of nodes, or -1
    if ``stack`` was too short.
    """
    nn = skeleton(pos.shape[0], leaf_size, ntop, stack)
    if nn < 0:
        return -1
    work = np.zeros(2 * stack.shape[0], np.int64)
    if resort(pos, perm, ntop, 0, -1, True, np.zeros(1, np.int64), np.zeros(1, perm.dtype),
              work, np.zeros(nn), 0.0, np.zeros(pos.shape[0]), 0) < 0:
        return -1
    return nn


# A node this small with any particle across its split is selected whole (on
# keys): at the ring's deep levels most nodes have crossers, and one keyed
# selection beats the band's passes (ring N = 2e5: re-sort 43 -> 23 ms; 128 to
# 512 alike, 32: 28 ms, 2048: 31 ms).
SMALL_NODE = 256


@kernel(inline=True)
def _crossed(pos, perm, axis, s, m, e, v):
    """Is a particle of slots s..m-1 above v or one of m..e-1 below it (or v NaN)?"""
    if not np.isfinite(v):
        return True
    for k in range(s, m):
        if pos[perm[k], axis] > v:
            return True
    for k in range(m, e):
        if pos[perm[k], axis] < v:
            return True
    return False


@kernel(inline=True)
def rebuild_node(pos, perm, ntop, nsplit, nd, slots, ids, delta, keys):
    """Re-split node nd along its stored axis, moving only the particles that
    crossed its split key and those next to it.

    ``v = nsplit[nd]`` is last step's split key.  If no particle is on the
    wrong side of ``v``, nothing moves; else a node of at most SMALL_NODE
    particles is selected whole.  In a larger one the particles within
    ``delta`` of ``v`` and the ones on the wrong side of it (however far: a
    particle that wrapped across a periodic boundary) are selected among
    themselves, and those that change sides swap slots pairwise
    (``_select_movers``), which is a valid split when the left slots among
    them are no fewer than the right half's crossers below the band and no
    more than all but the left half's beyond it.  Else the band is widened
    (up to 5 times, in proportion to the shortfall), and then the extents of
    the halves decide (``rebuild_split``).  The rest of the order, and so
    cache locality, is kept; ``nsplit[nd]`` gets the new split key.

    Why not the extents first: one particle that wrapped across a periodic
    boundary makes the left half's maximum (or the right's minimum) the far
    end of the box, every particle of the other half a crosser, and the node
    a full selection, all along the wrapped particle's path.
    """
    left = ntop[nd, LEFT]
    s = ntop[nd, START]
    e = ntop[nd, END]
    m = ntop[left, END]
    axis = ntop[nd, AXIS]
    v = nsplit[nd]
    cap = slots.shape[0]
    if e - s <= SMALL_NODE:
        if _crossed(pos, perm, axis, s, m, e, v):
            nsplit[nd] = _split_keyed(pos, perm, axis, s, e, m, keys)
        return
    if np.isfinite(v) and delta >= 0.0:
        for attempt in range(6):
            lo_b = v - delta
            hi_b = v + delta
            nv = 0
            wrong = 0
            far_l = 0  # left-half particles beyond the band (must go right)
            for k in range(s, m):
                x = pos[perm[k], axis]
                if x >= lo_b:
                    if x > v:
                        wrong += 1
                        if x > hi_b:
                            far_l += 1
                    if nv < cap:
                        slots[nv] = k
                    nv += 1
            nl = nv
            far_r = 0  # right-half particles below the band (must go left)
            for k in range(m, e):
                x = pos[perm[k], axis]
                if x <= hi_b:
                    if x < v:
                        wrong += 1
                        if x < lo_b:
                            far_r += 1
                    if nv < cap:
                        slots[nv] = k
                    nv += 1
            if wrong == 0:
                return  # every left particle <= v <= every right one
            if nv > cap:
                break
            if far_r <= nl and nl <= nv - far_l:
                w = _select_movers(pos, perm, slots, ids, nv, nl, axis, keys, s)
                # the fixed ones are below lo_b (left) or above hi_b (right)
                nsplit[nd] = min(max(w, lo_b), hi_b)
                return
            # too few in the band to make up for the crossers (particles that
            # wrapped go all one way): widen it in proportion, from its density
            inside = nv - far_l - far_r
            short = max(far_r - nl, far_l - (nv - nl))
            grow = max(1.5, 2.0 * (inside + short) / inside) if inside > 0 else 8.0
            delta = grow * delta if delta > 0.0 else 1e-9 * max(1.0, abs(v))
    mx = -np.inf
    for k in range(s, m):
        mx = max(mx, pos[perm[k], axis])
    mn = np.inf
    for k in range(m, e):
        mn = min(mn, pos[perm[k], axis])
    if mx <= mn:
        nsplit[nd] = 0.5 * (mx + mn)
    else:
        nsplit[nd] = rebuild_split(pos, perm, ntop, nd, slots, ids, mx, mn, keys)


@kernel(inline=True)
def rebuild_split(pos, perm, ntop, nd, slots, ids, mx, mn, keys):
    """``rebuild_node``'s last resort, given the left half's largest key
    ``mx`` and the right half's smallest ``mn`` (mx > mn): the particles beyond
    them are selected among themselves, or, if they do not fit the work
    buffers, the whole node.  Returns the new split key."""
    left = ntop[nd, LEFT]
    s = ntop[nd, START]
    e = ntop[nd, END]
    m = ntop[left, END]
    axis = ntop[nd, AXIS]
    cap = slots.shape[0]
    nv = 0
    for k in range(s, m):
        if pos[perm[k], axis] > mn:
            if nv < cap:
                slots[nv] = k
            nv += 1
    nl = nv
    for k in range(m, e):
        if pos[perm[k], axis] < mx:
            if nv < cap:
                slots[nv] = k
            nv += 1
    if nv > cap:
        return _split_keyed(pos, perm, axis, s, e, m, keys)
    w = _select_movers(pos, perm, slots, ids, nv, nl, axis, keys, s)
    return min(max(w, mn), mx)


@kernel
def subtree_bounds(anc, reach, ntop, root, nbox, nreach, order):
    """Box and max reach of every node of the subtree under ``root`` (children
    before parents); ``order`` is a work buffer as long as the subtree."""
    order[0] = root
    n = 1
    k = 0
    while k < n:  # breadth-first listing: parents before children
        nd = order[k]
        k += 1
        left = ntop[nd, LEFT]
        if left >= 0:
            order[n] = left
            order[n + 1] = ntop[nd, RIGHT]
            n += 2
    for q in range(n - 1, -1, -1):
        bound_node(anc, reach, ntop, order[q], nbox, nreach)


@kernel
def bound_node(anc, reach, ntop, nd, nbox, nreach):
    left = ntop[nd, LEFT]
    if left < 0:
        s = ntop[nd, START]
        e = ntop[nd, END]
        # in locals, not in nbox: nbox may alias anc for all numba knows, so
        # bounds kept in it were stored and loaded again for every particle
        # (node_bounds at N = 2e5: 4.6 ms that way, 0.95 ms in locals)
        x0 = y0 = z0 = np.inf
        x1 = y1 = z1 = -np.inf
        mr = 0.0
        for k in range(s, e):  # the same comparisons as before, bit for bit
            v = anc[k, 0]
            if v < x0:
                x0 = v
            if v > x1:
                x1 = v
            v = anc[k, 1]
            if v < y0:
                y0 = v
            if v > y1:
                y1 = v
            v = anc[k, 2]
            if v < z0:
                z0 = v
            if v > z1:
                z1 = v
            if reach[k] > mr:
                mr = reach[k]
        nbox[nd, 0] = x0
        nbox[nd, 1] = y0
        nbox[nd, 2] = z0
        nbox[nd, 3] = x1
        nbox[nd, 4] = y1
        nbox[nd, 5] = z1
        nreach[nd] = mr
    else:
        right = ntop[nd, RIGHT]
        for a in range(3):
            nbox[nd, a] = min(nbox[left, a], nbox[right, a])
            nbox[nd, 3 + a] = max(nbox[left, 3 + a], nbox[right, 3 + a])
        nreach[nd] = max(nreach[left], nreach[right])


@kernel
def node_bounds(anc, reach, ntop, nnodes, nbox, nreach):
    """Fill box and max reach of every node, bottom-up.

    Children always have larger indices than their parent, so one reverse
    sweep sees every child before its parent.  ``anc`` and ``reach`` are in
    tree order.
    """
    for nd in range(nnodes - 1, -1, -1):
        bound_node(anc, reach, ntop, nd, nbox, nreach)


@kernel(inline=True)
def _box_gap2(nbox, a, b, ox, oy, oz):
    """Squared distance between the box of node a and the box of node b shifted by o."""
    return box_gap2(nbox, a, nbox, b, ox, oy, oz)


@kernel(inline=True)
def box_gap2(boxa, a, boxb, b, ox, oy, oz):
    """Squared distance between the box boxa[a] and the box boxb[b] shifted by o
    (rows lo x, y, z, hi x, y, z)."""
    d2 = 0.0
    g = boxa[a, 0] - (boxb[b, 3] + ox)
    h = (boxb[b, 0] + ox) - boxa[a, 3]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    g = boxa[a, 1] - (boxb[b, 4] + oy)
    h = (boxb[b, 1] + oy) - boxa[a, 4]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    g = boxa[a, 2] - (boxb[b, 5] + oz)
    h = (boxb[b, 2] + oz) - boxa[a, 5]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    return d2


@kernel(inline=True)
def point_gap2(nbox, nd, qx, qy, qz):
    """Squared distance from point q to the box of node nd."""
    d2 = 0.0
    g = nbox[nd, 0] - qx
    h = qx - nbox[nd, 3]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    g = nbox[nd, 1] - qy
    h = qy - nbox[nd, 4]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    g = nbox[nd, 2] - qz
    h = qz - nbox[nd, 5]
    if h > g:
        g = h
    if g > 0.0:
        d2 += g * g
    return d2


@kernel(inline=True)
def pair_reach_ok(anc, reach, a, b, ox, oy, oz):
    """True if particles a and b (b shifted by o) may meet within the step."""
    dx = anc[a, 0] - anc[b, 0] - ox
    dy = anc[a, 1] - anc[b, 1] - oy
    dz = anc[a, 2] - anc[b, 2] - oz
    r = reach[a] + reach[b]
    return dx * dx + dy * dy + dz * dz <= r * r


def search_tasks(ntop, half_images, parts=1, depth=2, stop=None):
    """Starting points of the pair search: (node a, node b, image) triples.

    (root, root) for every image in ``half_images``; the self image's recursion
    is unrolled ``depth`` levels so that the work can be shared out (never
    through nodes with ``stop[node] >= 0``, e.g. lock nodes).  Returns
    ``parts`` lists of tasks with about equal numbers of particles below them.
    """
    tasks = [(0, 0, int(img)) for img in half_images if img != SELF_IMAGE]
    frontier = [(0, 0)]
    for _ in range(depth):
        nxt = []
        for a, b in frontier:
            la, ra = int(ntop[a, LEFT]), int(ntop[a, RIGHT])
            lb, rb = int(ntop[b, LEFT]), int(ntop[b, RIGHT])
            if stop is not None and (stop[a] >= 0 or stop[b] >= 0):
                nxt.append((a, b))
            elif a == b:
                if la < 0:
                    nxt.append((a, b))
                else:
                    nxt += [(la, la), (la, ra), (ra, ra)]
            elif la < 0 or lb < 0:
                nxt.append((a, b))
            else:
                nxt += [(la, lb), (la, rb), (ra, lb), (ra, rb)]
        frontier = nxt
    tasks = [(a, b, SELF_IMAGE) for a, b in frontier] + tasks
    size = lambda t: (int(ntop[t[0], END] - ntop[t[0], START])
                      + int(ntop[t[1], END] - ntop[t[1], START]))
    groups = [[] for _ in range(parts)]
    loads = [0] * parts
    for t in sorted(tasks, key=size, reverse=True):  # largest first to the least loaded
        k = loads.index(min(loads))
        groups[k].append(t)
        loads[k] += size(t)
    return [np.array(g, np.int64).reshape(-1, 3) for g in groups]


@kernel
def pair_search(anc, reach, ntop, nbox, nreach, tasks, img_pos, out_a, out_e, stack, work):
    """Two-argument (dual-tree) recursion: the candidate pairs below the tasks.

    Each task (a, b, img) runs the recursion over nodes a and b, b in periodic
    image img (see ``search_tasks``: from (root, root) for the self image and
    one of each pair of opposite images, every unordered pair of particles is
    found once).  Pairs are reported as ``out_a[k] = a`` and ``out_e[k] = (b <<
    5) | img``.  Returns the number of pairs found; if that exceeds the
    buffers' length only the first ``len(out_a)`` are stored and the caller
    retries with larger buffers.  ``stack`` is an (M, 3) int64 work array; -1 is
    returned if it was too short (about three entries per tree level).
    ``work`` (2,) float64 receives the node pairs visited and the particle pairs
    tested (the search's cost, independent of timing).
    """
    cap = out_a.shape[0]
    count = 0
    visits = 0
    tests = 0
    sp = 0
    for q in range(tasks.shape[0]):
        stack[sp, 0] = tasks[q, 0]
        stack[sp, 1] = tasks[q, 1]
        stack[sp, 2] = tasks[q, 2]
        sp += 1
    while sp > 0:
        sp -= 1
        na = stack[sp, 0]
        nb = stack[sp, 1]
        img = stack[sp, 2]
        visits += 1
        la = ntop[na, LEFT]
        lb = ntop[nb, LEFT]
        if sp + 3 > stack.shape[0]:
            return -1
        if img == SELF_IMAGE and na == nb:
            if la < 0:
                s = ntop[na, START]
                e = ntop[na, END]
                tests += (e - s) * (e - s - 1) // 2
                for a in range(s, e):
                    for b in range(a + 1, e):
                        if pair_reach_ok(anc, reach, a, b, 0.0, 0.0, 0.0):
                            if count < cap:
                                out_a[count] = a
                                out_e[count] = (b << 5) | img
                            count += 1
            else:
                sp = _push_children(ntop, nbox, stack, sp, na, nb, img)
            continue
        ox = img_pos[img, 0]
        oy = img_pos[img, 1]
        oz = img_pos[img, 2]
        r = nreach[na] + nreach[nb]
        if _box_gap2(nbox, na, nb, ox, oy, oz) > r * r:
            continue
        if la < 0 and lb < 0:
            for a in range(ntop[na, START], ntop[na, END]):
                # skip a at once if it is out of reach of the whole leaf nb
                ra = reach[a] + nreach[nb]
                if point_gap2(nbox, nb, anc[a, 0] - ox, anc[a, 1] - oy,
                              anc[a, 2] - oz) > ra * ra:
                    continue
                tests += ntop[nb, END] - ntop[nb, START]
                for b in range(ntop[nb, START], ntop[nb, END]):
                    if a == b:
                        continue  # a particle never meets its own image
                    if pair_reach_ok(anc, reach, a, b, ox, oy, oz):
                        if count < cap:
                            out_a[count] = a
                            out_e[count] = (b << 5) | img
                        count += 1
            continue
        sp = _push_children(ntop, nbox, stack, sp, na, nb, img)
    work[0] = visits
    work[1] = tests
    return count


@kernel(inline=True)
def _push_children(ntop, nbox, stack, sp, na, nb, img):
    """The pair search's step down from the node pair (na, nb) in image img
    (not two leaves): the same node's two halves and the pair between them,
    else the larger box's halves (the inner one's if the other is a leaf),
    pushed at ``stack[sp:]``; returns the new stack size."""
    la = ntop[na, LEFT]
    lb = ntop[nb, LEFT]
    if img == SELF_IMAGE and na == nb:
        ra = ntop[na, RIGHT]
        for c in range(3):
            stack[sp + c, 2] = img
        stack[sp, 0] = la
        stack[sp, 1] = la
        stack[sp + 1, 0] = la
        stack[sp + 1, 1] = ra
        stack[sp + 2, 0] = ra
        stack[sp + 2, 1] = ra
        return sp + 3
    split_a = lb < 0
    if la >= 0 and lb >= 0:
        ea = max(nbox[na, 3] - nbox[na, 0], nbox[na, 4] - nbox[na, 1],
                 nbox[na, 5] - nbox[na, 2])
        eb = max(nbox[nb, 3] - nbox[nb, 0], nbox[nb, 4] - nbox[nb, 1],
                 nbox[nb, 5] - nbox[nb, 2])
        split_a = ea >= eb
    stack[sp, 2] = img
    stack[sp + 1, 2] = img
    if split_a:
        stack[sp, 0] = la
        stack[sp, 1] = nb
        stack[sp + 1, 0] = ntop[na, RIGHT]
        stack[sp + 1, 1] = nb
    else:
        stack[sp, 0] = na
        stack[sp, 1] = lb
        stack[sp + 1, 0] = na
        stack[sp + 1, 1] = ntop[nb, RIGHT]
    return sp + 2


@kernel
def search_frontier(ntop, nbox, nreach, img_pos, images, max_size, tasks, stack):
    """Tasks of the claimed pair search: the two-argument recursion of
    ``pair_search`` from (root, root, img) for each image in ``images`` (the
    self image and one of each pair of opposite images, as ``search_tasks``),
    stepped down until both nodes of a pair hold at most ``max_size`` slots
    (or are leaves); pairs of nodes out of each other's reach are dropped.
    The searches below the tasks, together, find each candidate pair once, in
    the orientation ``pair_search`` from the root gives it.

    ``tasks`` (M, 3) int64 receives (node a, node b, image) in the
    recursion's order (neighbouring tasks cover neighbouring space);
    ``stack`` is an (M', 3) int64 work array.  Returns the number of tasks,
    -1 if ``stack`` was short, -2 if ``tasks`` was.
    """
    if images.shape[0] + 3 > stack.shape[0]:
        return -1
    sp = 0
    for q in range(images.shape[0]):
        stack[sp, 0] = 0
        stack[sp, 1] = 0
        stack[sp, 2] = images[q]
        sp += 1
    nt = 0
    while sp > 0:
        sp -= 1
        na = stack[sp, 0]
        nb = stack[sp, 1]
        img = stack[sp, 2]
        if sp + 3 > stack.shape[0]:
            return -1
        diag = img == SELF_IMAGE and na == nb
        if not diag:
            r = nreach[na] + nreach[nb]
            if _box_gap2(nbox, na, nb, img_pos[img, 0], img_pos[img, 1], img_pos[img, 2]) > r * r:
                continue
        la = ntop[na, LEFT]
        lb = ntop[nb, LEFT]
        small = (ntop[na, END] - ntop[na, START] <= max_size
                 and ntop[nb, END] - ntop[nb, START] <= max_size)
        if small or (la < 0 and lb < 0) or (diag and la < 0):
            if nt >= tasks.shape[0]:
                return -2
            tasks[nt, 0] = na
            tasks[nt, 1] = nb
            tasks[nt, 2] = img
            nt += 1
        else:
            sp = _push_children(ntop, nbox, stack, sp, na, nb, img)
    return nt


@kernel
def pair_search_claimed(anc, reach, ntop, nbox, nreach, tasks, ntasks, claim, img_pos, out_a,
                        out_e, stack, work, seg, me, nthr):
    """One thread's share of a pair search over ``tasks[:ntasks]`` (from
    ``search_frontier``): thread ``me`` of ``nthr`` claims the next task with
    an atomic fetch-add on ``claim[0]`` (start at 0) until none is left, so a
    thread slowed down (another guest on its core) takes fewer; on two
    threads the first from the front, the second from the back
    (``atomics.claim_from_ends``).  Task q's pairs go to this
    thread's ``out_a``, ``out_e`` (as ``pair_search``), and ``seg[q] = (me,
    first, count)`` says where: ``build_csr`` reads them in task order, so
    the lists do not depend on which thread ran which task.  Returns this
    thread's pair count (stored or not, as ``pair_search``), or -1 if
    ``stack`` was short (the other threads then stop too).  ``work`` as
    ``pair_search``, summed over the thread's tasks."""
    cap = out_a.shape[0]
    count = 0
    visits = 0.0
    tests = 0.0
    r = 0
    while True:
        q = claim_from_ends(claim, me, nthr, r, ntasks)
        r += 1
        if q >= ntasks:
            break
        first = min(count, cap)
        m = pair_search(anc, reach, ntop, nbox, nreach, tasks[q:q + 1], img_pos, out_a[first:],
                        out_e[first:], stack, work)
        if m < 0:
            store(claim, 0, ntasks)
            return -1
        visits += work[0]
        tests += work[1]
        seg[q, 0] = me
        seg[q, 1] = count
        seg[q, 2] = m
        count += m
    work[0] = visits
    work[1] = tests
    return count


@kernel
def find_leaf(ntop, slot):
    """Index of the leaf whose slot range contains ``slot``."""
    nd = 0
    while ntop[nd, LEFT] >= 0:
        left = ntop[nd, LEFT]
        if slot < ntop[left, END]:
            nd = left
        else:
            nd = ntop[nd, RIGHT]
    return nd


@kernel
def raise_reach(ntop, nreach_bits, slot, value):
    """Raise the max reach of every node above ``slot`` to at least ``value``.

    ``nreach_bits`` is the int64 view of ``nreach``: reaches are non-negative,
    so an atomic integer maximum of the bit patterns is a maximum of the values
    (safe with other threads raising at the same time).
    """
    nd = find_leaf(ntop, slot)
    bits = float_bits(value)
    # all the way up, even past a node already as high: another thread may have
    # raised that node and not yet its ancestors, and this thread's search must
    # not start before its own raise is complete.  A node already as high is
    # only read: an atomic maximum takes its line from the other thread's
    # cache even when it changes nothing, and the bed's widenings (one impact
    # in 24) all pass through the root's line (README, Benchmarks: "Slab
    # domains, and atomic maxima read first": the bed's step 2.7 % faster
    # with the threads' cores far apart)
    while nd >= 0:
        if load(nreach_bits, nd) < bits:
            fetch_max(nreach_bits, nd, bits)
        nd = ntop[nd, PARENT]


@kernel
def identity(perm, first):
    """perm[k] = first + k: a slice of the storage permutation back to the
    identity once it has been applied."""
    for k in range(perm.shape[0]):
        perm[k] = first + k


@kernel
def permute_vec(a, perm, buf):
    """In place a[k] = a_old[perm[k]] for a 1-D array, through ``buf`` (at least
    N entries of a's type): a gather, whose loads are independent of each other
    (following the permutation's cycles in place chains every load on the last
    and measured 7x slower at N = 2e5)."""
    n = perm.shape[0]
    for k in range(n):
        buf[k] = a[perm[k]]
    for k in range(n):
        a[k] = buf[k]


@kernel
def permute_rows(a, perm, buf):
    """In place a[k, :] = a_old[perm[k], :] for an (N, 3) array through ``buf``
    (N, 3), which then holds the permuted rows too (the anchors, or a pool
    step's start velocities: a copy the caller needs anyway).  One gather
    over whole rows: ``permute_mat3`` reads each row three times."""
    n = perm.shape[0]
    for k in range(n):
        p = perm[k]
        buf[k, 0] = a[p, 0]
        buf[k, 1] = a[p, 1]
        buf[k, 2] = a[p, 2]
    for k in range(n):
        a[k, 0] = buf[k, 0]
        a[k, 1] = buf[k, 1]
        a[k, 2] = buf[k, 2]


@kernel
def permute_mat3(a, perm, buf):
    """In place a[k, :] = a_old[perm[k], :] for an (N,3) array, a column at a
    time through ``buf`` (N entries): a third of the memory a row buffer needs."""
    n = perm.shape[0]
    for c in range(3):
        for k in range(n):
            buf[k] = a[perm[k], c]
        for k in range(n):
            a[k, c] = buf[k]
