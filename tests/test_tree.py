"""kD-tree pair search against brute force: soundness and completeness, per variant.

One class of checks (``PairSearchChecks``) runs on every domain and size
distribution.  A pair (a, b, image) is a candidate when

    |anc[a] - anc[b] - img_pos[image]| <= reach[a] + reach[b]

with reach = sig + fr * rad.  Soundness: every pair the tree reports satisfies it.  Completeness: every pair
brute force finds is reported.  Each unordered pair is reported once.
"""
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as hs

from lockgraph.domains import Dish, PeriodicCube, ShearingSheet
from lockgraph.tree import build, count_nodes, median_of, node_bounds, pair_search, search_tasks


def claimed_search(anc, reach, ntop, nbox, nreach, img_pos, half, max_size, cap, threads=1):
    """The engine's pair search: ``search_frontier``'s tasks claimed by
    ``threads`` threads (``pair_search_claimed``), then ``build_csr``.
    Returns (pairs found, per thread (out_a, out_e), segments, task count,
    noff, nent)."""
    import threading

    from lockgraph.neighbors import build_csr
    from lockgraph.tree import SELF_IMAGE, pair_search_claimed, search_frontier
    images = np.array([SELF_IMAGE] + [i for i in half if i != SELF_IMAGE], np.int64)
    tasks = np.zeros((4096, 3), np.int64)
    nt = search_frontier(ntop, nbox, nreach, img_pos, images, max_size, tasks,
                         np.zeros((4096, 3), np.int64))
    assert nt > 0
    seg = np.full((nt, 3), -1, np.int64)
    claim = np.zeros(8, np.int64)
    out = [(np.zeros(cap, np.int32), np.zeros(cap, np.int32)) for _ in range(threads)]
    res = [None] * threads

    def run(k):
        res[k] = pair_search_claimed(anc, reach, ntop, nbox, nreach, tasks, nt, claim, img_pos,
                                     out[k][0], out[k][1], np.zeros((4096, 3), np.int64),
                                     np.zeros(2), seg, k, threads)
    pool = [threading.Thread(target=run, args=(k,)) for k in range(threads)]
    for th in pool:
        th.start()
    for th in pool:
        th.join()
    m = sum(res)
    n = len(anc)
    noff, nent = np.zeros(n + 1, np.int64), np.zeros(2 * max(m, 1), np.int32)
    if max(res) <= cap:
        build_csr(n, seg, nt, np.array([o[0] for o in out]), np.array([o[1] for o in out]),
                  noff, nent)
    return res, out, seg, nt, noff, nent


def tree_pairs(pos, rad, sig, domain, time=0.0, fr=1.0, leaf=8, claimed=None):
    """Candidate pairs from the tree, as a set of (lower id, higher id, image
    from lower): ``pair_search`` from the root, or with ``claimed`` (a node
    size) the engine's claimed search over tasks of nodes that small."""
    n = len(pos)
    perm = np.arange(n, dtype=np.int32)
    ntop = np.zeros((count_nodes(n, leaf), 6), np.int32)
    nn = build(pos.copy(), leaf, perm, ntop, np.zeros(256, np.int64))
    assert nn == count_nodes(n, leaf)
    assert sorted(perm) == list(range(n))  # a permutation
    anc = pos[perm]
    reach = (sig + fr * rad)[perm]
    nbox, nreach = np.zeros((nn, 6)), np.zeros(nn)
    node_bounds(anc, reach, ntop, nn, nbox, nreach)
    img_pos, img_vel, half, full = domain.images(time)
    cap = 16
    while claimed is None:
        out_a = np.zeros(cap, np.int32)
        out_e = np.zeros(cap, np.int32)
        m = pair_search(anc, reach, ntop, nbox, nreach, search_tasks(ntop, half, 1)[0], img_pos,
                        out_a, out_e, np.zeros((4096, 3), np.int64), np.zeros(2))
        if m <= cap:
            break
        cap = m
    while claimed is not None:
        res, out, seg, nt, _, _ = claimed_search(anc, reach, ntop, nbox, nreach, img_pos, half,
                                                 claimed, cap)
        m = res[0]
        if m <= cap:  # the pairs in task order
            out_a = np.concatenate([out[0][0][f:f + c] for _, f, c in seg[:nt]] + [[]])
            out_e = np.concatenate([out[0][1][f:f + c] for _, f, c in seg[:nt]] + [[]])
            out_a, out_e = out_a.astype(np.int64), out_e.astype(np.int64)
            break
        cap = m
    found = []
    for k in range(m):
        a = int(perm[out_a[k]])
        b = int(perm[out_e[k] >> 5])
        img = int(out_e[k] & 31)
        if b < a:
            a, b, img = b, a, 26 - img
        found.append((a, b, img))
    return found


def brute_pairs(pos, rad, sig, domain, time=0.0, fr=1.0):
    img_pos, img_vel, half, full = domain.images(time)
    out = set()
    n = len(pos)
    for img in full:
        d = pos[:, None, :] - pos[None, :, :] - img_pos[img]
        dist2 = (d ** 2).sum(-1)
        reach = sig + fr * rad
        ok = dist2 <= (reach[:, None] + reach[None, :]) ** 2
        for a, b in zip(*np.nonzero(ok)):
            if a < b:
                out.add((int(a), int(b), int(img)))
    return out


_CASES = {}


class PairSearchChecks:
    """Reused for every variant: subclasses define ``system(seed)``.  Each
    system is searched from the root (``pair_search``) and as the engine
    does, over claimed tasks (``search_frontier``, ``pair_search_claimed``)
    of nodes of at most 8 (leaves) or 40 slots."""
    seeds = range(6)
    fr = 1.0
    time = 0.0

    def system(self, seed):
        raise NotImplementedError

    @pytest.fixture(params=[(seed, how) for seed in seeds for how in (None, 8, 40)],
                    ids=lambda p: f"{p[0]}-{'root' if p[1] is None else f'tasks{p[1]}'}")
    def case(self, request):
        seed, claimed = request.param
        key = (type(self).__name__, seed, claimed)
        if key not in _CASES:  # one search and brute force for the four checks
            pos, rad, sig, domain = self.system(seed)
            _CASES[key] = (tree_pairs(pos, rad, sig, domain, self.time, self.fr, claimed=claimed),
                           brute_pairs(pos, rad, sig, domain, self.time, self.fr))
        return _CASES[key]

    def test_sound(self, case):
        found, truth = case
        assert set(found) <= truth, f"false pairs: {sorted(set(found) - truth)[:5]}"

    def test_complete(self, case):
        found, truth = case
        assert truth <= set(found), f"missed pairs: {sorted(truth - set(found))[:5]}"

    def test_each_pair_once(self, case):
        found, truth = case
        assert len(found) == len(set(found))

    def test_nontrivial(self, case):
        found, truth = case
        assert len(truth) > 10  # the variant exercises the search


class TestPeriodicCube(PairSearchChecks):
    def system(self, seed):
        rng = np.random.default_rng(seed)
        n, L = 300, 12.0
        pos = rng.uniform(-L / 2, L / 2, (n, 3))
        rad = rng.uniform(0.2, 0.6, n)
        sig = rng.uniform(0.0, 0.3, n)
        return pos, rad, sig, PeriodicCube(L)


class TestShearingSheetWithOffset(PairSearchChecks):
    """Radial images are shifted in y by the shear offset at this time."""
    time = 1234.5
    fr = 1.05

    def system(self, seed):
        rng = np.random.default_rng(100 + seed)
        n, lx, ly = 300, 20.0, 16.0
        pos = np.column_stack([rng.uniform(-lx / 2, lx / 2, n), rng.uniform(-ly / 2, ly / 2, n),
                               rng.normal(0, 0.5, n)])
        rad = rng.uniform(0.2, 1.0, n)
        sig = rng.uniform(0.0, 0.3, n)
        return pos, rad, sig, ShearingSheet(lx, ly, 3e-3)


class TestDish(PairSearchChecks):
    def system(self, seed):
        rng = np.random.default_rng(200 + seed)
        n = 300
        rho = 9.0 * np.sqrt(rng.random(n))
        phi = rng.uniform(0, 2 * np.pi, n)
        pos = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), rng.uniform(0.5, 8.0, n)])
        rad = np.full(n, 0.5)
        sig = rng.uniform(0.0, 0.2, n)
        return pos, rad, sig, Dish(10.0)


class TestTwentyToOneSizes(PairSearchChecks):
    """A body 20x the radius of the rest (the marble): its leaf pairs with many."""

    def system(self, seed):
        rng = np.random.default_rng(300 + seed)
        n, L = 400, 30.0
        pos = rng.uniform(-L / 2, L / 2, (n, 3))
        rad = np.full(n, 0.25)
        rad[0] = 5.0
        sig = rng.uniform(0.0, 0.2, n)
        return pos, rad, sig, PeriodicCube(L)


class TestLatticeDuplicates(PairSearchChecks):
    """Many equal coordinates (a lattice): the median split must cope with ties."""

    def system(self, seed):
        rng = np.random.default_rng(400 + seed)
        g = np.arange(7) - 3.0
        pos = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3) * 1.1
        rad = np.full(len(pos), 0.5)
        sig = np.where(rng.random(len(pos)) < 0.3, 0.1, 0.0)
        return pos, rad, sig, PeriodicCube(7.7)


@pytest.mark.parametrize("leaf", [1, 2, 3, 5, 16, 64])
def test_leaf_sizes(leaf):
    rng = np.random.default_rng(7)
    pos = rng.uniform(-5, 5, (150, 3))
    rad = rng.uniform(0.2, 0.5, 150)
    sig = rng.uniform(0, 0.2, 150)
    found = tree_pairs(pos, rad, sig, PeriodicCube(10.0), leaf=leaf)
    assert set(found) == brute_pairs(pos, rad, sig, PeriodicCube(10.0))
    assert len(found) == len(set(found))


@given(hs.integers(2, 60), hs.integers(0, 2 ** 31 - 1), hs.floats(0.05, 0.8))
def test_random_point_sets(n, seed, spread):
    """Hypothesis: arbitrary small sets, including near-coincident points."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-3, 3, (n, 3)) * spread
    rad = rng.uniform(0.01, 0.3, n)
    sig = rng.uniform(0, 0.2, n)
    dom = Dish(20.0)
    assert set(tree_pairs(pos, rad, sig, dom, leaf=4)) == brute_pairs(pos, rad, sig, dom)


def test_single_particle_has_no_pairs():
    pos = np.zeros((1, 3))
    assert tree_pairs(pos, np.ones(1), np.ones(1), PeriodicCube(10.0)) == []


def _kd_ordered(pos, perm, ntop, nnodes):
    """Every node's left child's particles <= its right child's along its axis."""
    from lockgraph.tree import AXIS, END, LEFT, RIGHT, START
    key = pos
    for nd in range(nnodes):
        left, right = int(ntop[nd, LEFT]), int(ntop[nd, RIGHT])
        if left < 0:
            continue
        ax = int(ntop[nd, AXIS])
        lo = key[perm[ntop[left, START]:ntop[left, END]], ax]
        hi = key[perm[ntop[right, START]:ntop[right, END]], ax]
        if lo.max() > hi.min():
            return False
    return True


def _fresh_tree(pos, leaf=8):
    """A new tree over pos: (perm, ntop, node count, split keys)."""
    from lockgraph.tree import resort, skeleton
    n = len(pos)
    ntop = np.zeros((count_nodes(n, leaf), 6), np.int64)
    nn = skeleton(n, leaf, ntop, np.zeros(256, np.int64))
    perm = np.arange(n, dtype=np.int32)
    nsplit = np.full(nn, np.nan)
    assert resort(pos, perm, ntop, 0, -1, True, np.zeros(1, np.int64), np.zeros(1, np.int32),
                  np.zeros(256, np.int64), nsplit, 0.0, np.zeros(n), 0) == 0
    assert _kd_ordered(pos, perm, ntop, nn)
    return perm, ntop, nn, nsplit


def _step_later(seed, n=500, noise=0.05, wrapped=0):
    """A tree built over random points, and the points a step later: moved
    by ``noise``, ``wrapped`` of them by a box length (a periodic wrap)."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1, 1, (n, 3))
    perm, ntop, nn, nsplit = _fresh_tree(pos)
    later = pos + rng.normal(0, noise, pos.shape)
    for i in rng.choice(n, wrapped, replace=False):
        later[i, rng.integers(3)] += 2.0 * rng.choice([-1.0, 1.0])
    return later, perm, ntop, nn, nsplit


def _resort(pos, perm, ntop, nsplit, band, cap=4096):
    from lockgraph.tree import resort
    assert resort(pos, perm, ntop, 0, -1, False, np.zeros(cap, np.int64), np.zeros(cap, np.int32),
                  np.zeros(256, np.int64), nsplit, band, np.zeros(len(pos)), 0) == 0


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("cap", [4096, 3])
@pytest.mark.parametrize("band", [0.0, 0.01, 10.0])
@pytest.mark.parametrize("wrapped", [0, 25])
def test_resort_of_last_steps_tree_is_a_kd_order(seed, cap, band, wrapped):
    """``resort`` of last step's tree (``rebuild_node``: a band about last
    step's split key, widened, then the halves' extents) leaves a permutation
    in kD order, whether particles moved a little or wrapped across a periodic
    boundary, the band is empty, tight or holds everything, or the movers
    overflow the work buffers (cap 3); and so does the next step's."""
    from lockgraph.tree import SMALL_NODE
    # nodes above SMALL_NODE on three levels: the band; below: whole selections
    pos, perm, ntop, nn, nsplit = _step_later(seed, n=8 * SMALL_NODE + 37, wrapped=wrapped)
    assert not _kd_ordered(pos, perm, ntop, nn)  # particles crossed splits
    n = len(pos)
    for step in range(2):
        _resort(pos, perm, ntop, nsplit, band, cap)
        assert sorted(perm) == list(range(n))
        assert _kd_ordered(pos, perm, ntop, nn)
        pos = pos + np.random.default_rng(seed).normal(0, 0.05, pos.shape)


@pytest.mark.parametrize("slab", [0, 1, 3, 4])
def test_slab_levels_split_along_the_roots_axis(slab):
    """A fresh tree with ``slab`` levels (the pool's domains as slabs): the
    nodes fewer than ``slab`` levels down are split along the root's axis
    (the longest of the whole box), the rest along their own longest; the
    order is a kD order either way, and the nodes ``slab`` levels down are
    slabs: their ranges along the root's axis do not overlap."""
    from lockgraph.tree import AXIS, LEFT, PARENT, START, END, resort, skeleton
    rng = np.random.default_rng(7)
    n, leaf = 3000, 8
    pos = rng.uniform(0, 1, (n, 3)) * [0.4, 0.3, 1.0]  # a column, like the bed
    ntop = np.zeros((count_nodes(n, leaf), 6), np.int64)
    nn = skeleton(n, leaf, ntop, np.zeros(256, np.int64))
    perm = np.arange(n, dtype=np.int32)
    assert resort(pos, perm, ntop, 0, -1, True, np.zeros(1, np.int64), np.zeros(1, np.int32),
                  np.zeros(256, np.int64), np.full(nn, np.nan), 0.0, np.zeros(n), slab) == 0
    assert _kd_ordered(pos, perm, ntop, nn)
    assert ntop[0, AXIS] == 2
    depth = np.zeros(nn, np.int64)
    for nd in range(1, nn):  # parents come first in node order
        depth[nd] = depth[ntop[nd, PARENT]] + 1
    inner = ntop[:nn, LEFT] >= 0
    own = np.zeros(nn, np.int64)
    for nd in np.flatnonzero(inner):
        box = pos[perm[ntop[nd, START]:ntop[nd, END]]]
        own[nd] = np.argmax(box.max(axis=0) - box.min(axis=0))
    top = inner & (depth < slab)
    assert np.all(ntop[:nn, AXIS][top] == 2)
    assert np.array_equal(ntop[:nn, AXIS][inner & ~top & (depth > 0)],
                          own[inner & ~top & (depth > 0)])
    if slab == 4:  # the bed's 16 domains: stacked along z
        assert 0 < np.count_nonzero(own[top] != 2)  # not what the longest axis gives
        spans = sorted((pos[perm[ntop[nd, START]:ntop[nd, END]], 2].min(),
                        pos[perm[ntop[nd, START]:ntop[nd, END]], 2].max())
                       for nd in np.flatnonzero(depth == slab))
        assert len(spans) == 16
        assert all(a[1] <= b[0] for a, b in zip(spans, spans[1:]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_resort_moves_only_what_crossed(seed):
    """Nothing moved: the order is kept.  One particle wrapped across the
    box: in the nodes above SMALL_NODE only the particles that change sides
    move, swapped pairwise, so far fewer slots change than when the halves'
    extents decide (a negative band: one far particle makes every particle of
    the other half a crosser, all along its path; measured here 6,100-6,800
    slots against 1,000-2,600)."""
    from lockgraph.tree import SMALL_NODE
    n = 64 * SMALL_NODE
    pos, perm, ntop, nn, nsplit = _step_later(seed, n=n, noise=0.0)
    kept = perm.copy()
    _resort(pos, kept, ntop, nsplit.copy(), 0.01)
    assert np.array_equal(kept, perm)
    pos[perm[0], int(ntop[0, 5])] += 2.0  # the first slot's particle to the far side
    moved = {}
    for band in (0.01, -1.0):
        order = perm.copy()
        _resort(pos, order, ntop, nsplit.copy(), band)
        assert _kd_ordered(pos, order, ntop, nn)
        moved[band] = np.count_nonzero(order != perm)
    assert 0 < 2 * moved[0.01] < moved[-1.0], moved


def _searched_tree(n, seed, leaf=8):
    """A tree over n random particles in a periodic cube, bounded: (anc, reach,
    ntop, nbox, nreach, img_pos, half)."""
    rng = np.random.default_rng(seed)
    box = 20.0
    pos = rng.uniform(-box / 2, box / 2, (n, 3))
    rad = rng.uniform(0.05, 0.15, n)
    perm = np.arange(n, dtype=np.int32)
    ntop = np.zeros((count_nodes(n, leaf), 6), np.int32)
    nn = build(pos.copy(), leaf, perm, ntop, np.zeros(256, np.int64))
    anc, reach = pos[perm], (0.2 + rad)[perm]
    nbox, nreach = np.zeros((nn, 6)), np.zeros(nn)
    node_bounds(anc, reach, ntop, nn, nbox, nreach)
    img_pos, _, half, _ = PeriodicCube(box).images(0.0)
    return anc, reach, ntop, nbox, nreach, img_pos, half


@pytest.mark.parametrize("seed", [0, 1])
def test_claimed_search_lists_do_not_depend_on_the_threads(seed):
    """Two threads claiming the tasks at once (nogil kernels) run every task
    exactly once, and the candidate lists (``build_csr`` reads the tasks in
    their order) are the ones one thread builds, entry for entry."""
    tree = _searched_tree(6000, seed)
    one = claimed_search(*tree, max_size=64, cap=200000)
    two = claimed_search(*tree, max_size=64, cap=200000, threads=2)
    nt = one[3]
    assert nt == two[3] and nt > 50
    seg = two[2]
    assert set(seg[:, 0]) <= {0, 1} and (seg[:, 2] >= 0).all()  # every task run
    assert sum(two[0]) == one[0][0]
    for k in range(2):  # each thread's segments tile its output in claim order
        mine = seg[seg[:, 0] == k]
        # by where each starts (a task with no pairs first among those starting
        # where it does): the claim order, whichever end a thread claims from
        mine = mine[np.lexsort((mine[:, 2], mine[:, 1]))]
        assert (mine[:, 1] == np.concatenate([[0], np.cumsum(mine[:, 2])[:-1]])).all()
        assert mine[:, 2].sum() == two[0][k]
    assert np.array_equal(one[4], two[4]) and np.array_equal(one[5], two[5])


@pytest.mark.parametrize("seed", range(6))
def test_candidate_lists_are_the_brute_force_lists(seed):
    """``build_csr`` over arrays holding garbage gives the lists a
    brute-force build gives: each pair once from each end, the mirrored
    image at the other, in segment order (pairs of a slot with its own
    image included), and nothing written past them."""
    from lockgraph.neighbors import build_csr
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    rows, cap = 3, 40
    out_a = rng.integers(0, n, (rows, cap)).astype(np.int32)
    out_e = ((rng.integers(0, n, (rows, cap)) << 5) | rng.integers(0, 27, (rows, cap)))
    out_e = out_e.astype(np.int32)
    self_pairs = rng.random((rows, cap)) < 0.1
    out_e[self_pairs] = (out_a[self_pairs] << 5) | 13
    nseg = int(rng.integers(0, 12))
    seg = np.zeros((nseg, 3), np.int64)
    for q in range(nseg):
        f = int(rng.integers(0, cap))
        seg[q] = (rng.integers(0, rows), f, rng.integers(0, cap - f + 1))
    lists = [[] for _ in range(n)]
    for p, f, c in seg:
        for k in range(f, f + c):
            a, e = int(out_a[p, k]), int(out_e[p, k])
            lists[a].append(e)
            lists[e >> 5].append((a << 5) | (26 - (e & 31)))
    want_off = np.concatenate([[0], np.cumsum([len(x) for x in lists])])
    want_ent = np.array([e for x in lists for e in x], np.int32)
    noff = np.full(n + 1, -7, np.int64)
    nent = np.full(len(want_ent) + 3, -7, np.int32)
    build_csr(n, seg, nseg, out_a, out_e, noff, nent)
    assert np.array_equal(noff, want_off)
    assert np.array_equal(nent[:len(want_ent)], want_ent) and (nent[len(want_ent):] == -7).all()


def test_claimed_search_buffers_and_stack_short():
    """Out of room: the count is still exact (the caller retries with larger
    buffers); a stack too short says so (-1) and stops the other threads."""
    from lockgraph.tree import SELF_IMAGE, pair_search_claimed, search_frontier
    anc, reach, ntop, nbox, nreach, img_pos, half = _searched_tree(3000, 2)
    full = claimed_search(anc, reach, ntop, nbox, nreach, img_pos, half, 64, 100000)[0][0]
    assert claimed_search(anc, reach, ntop, nbox, nreach, img_pos, half, 64, 10)[0][0] == full
    images = np.array([SELF_IMAGE] + [i for i in half if i != SELF_IMAGE], np.int64)
    assert search_frontier(ntop, nbox, nreach, img_pos, images, 64, np.zeros((3, 3), np.int64),
                           np.zeros((4096, 3), np.int64)) == -2
    assert search_frontier(ntop, nbox, nreach, img_pos, images, 64, np.zeros((4096, 3), np.int64),
                           np.zeros((2, 3), np.int64)) == -1
    tasks = np.zeros((4096, 3), np.int64)
    nt = search_frontier(ntop, nbox, nreach, img_pos, images, 64, tasks,
                         np.zeros((4096, 3), np.int64))
    claim = np.zeros(8, np.int64)
    assert pair_search_claimed(anc, reach, ntop, nbox, nreach, tasks, nt, claim, img_pos,
                               np.zeros(10, np.int32), np.zeros(10, np.int32),
                               np.zeros((2, 3), np.int64), np.zeros(2),
                               np.zeros((nt, 3), np.int64), 0, 1) == -1
    assert claim[0] == nt  # nothing left for the others


def _stealing_setup(seed, depth):
    """Last step's tree over moved particles (as ``_step_later``), its two
    subtrees and their nodes ``depth`` levels down, for ``resort_stealing``."""
    from lockgraph.tree import LEFT, NLIST, RIGHT, SMALL_NODE
    pos, perm, ntop, nn, nsplit = _step_later(seed, n=16 * SMALL_NODE + 59, wrapped=5)
    subroots = [int(ntop[0, LEFT]), int(ntop[0, RIGHT])]
    below = []
    for root in subroots:
        level = [root]
        for _ in range(depth):
            level = [c for nd in level for c in ((int(ntop[nd, LEFT]), int(ntop[nd, RIGHT]))
                                                 if ntop[nd, LEFT] >= 0 else (nd,))]
        below.append(level)
    width = max(map(len, below))
    lists = np.zeros((2, width), np.int64)
    for k, b in enumerate(below):
        lists[k, :len(b)] = b
    nbelow = np.array([len(b) for b in below], np.int64)
    return pos, perm, ntop, nn, nsplit, subroots, lists, nbelow, np.zeros(2 * NLIST, np.int64)


def _steal(me, pos, perm, ntop, subroots, nsplit, lists, nbelow, ctl, stack=256):
    from lockgraph.tree import resort_stealing
    return resort_stealing(me, pos, perm, ntop, subroots[me], 2, False, np.zeros(4096, np.int64),
                           np.zeros(4096, np.int32), np.zeros(stack, np.int64), nsplit, 0.01,
                           np.zeros(len(pos)), lists, nbelow, ctl, 0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_resort_stealing_is_resort(seed):
    """``resort_stealing`` of the two subtrees (the top node re-sorted first),
    run by two threads at once or one after the other, leaves the permutation
    and split keys ``resort`` leaves, whoever took which node."""
    import threading

    from lockgraph.tree import LIST_OPEN, NLIST, resort
    pos, perm0, ntop, nn, ns0, subroots, lists, nbelow, ctl = _stealing_setup(seed, 2)
    args = (np.zeros(4096, np.int64), np.zeros(4096, np.int32), np.zeros(256, np.int64))
    want_perm, want_ns = perm0.copy(), ns0.copy()
    assert resort(pos, want_perm, ntop, 0, -1, False, *args, want_ns, 0.01, np.zeros(len(pos)),
                  0) == 0
    assert _kd_ordered(pos, want_perm, ntop, nn)
    for concurrent in (False, True):
        perm, ns = perm0.copy(), ns0.copy()
        assert resort(pos, perm, ntop, 0, 1, False, *args, ns, 0.01, np.zeros(len(pos)), 0) == 0
        ctl[:] = 0
        res = [None, None]

        def run(me):
            res[me] = _steal(me, pos, perm, ntop, subroots, ns, lists, nbelow, ctl)
        if concurrent:
            pool = [threading.Thread(target=run, args=(k,)) for k in range(2)]
            for th in pool:
                th.start()
            for th in pool:
                th.join()
        else:
            run(0)  # list 1 is not open yet: left to its owner
            assert ctl[NLIST + LIST_OPEN] == 0
            run(1)
        assert res == [0, 0]
        assert np.array_equal(perm, want_perm)
        assert np.array_equal(ns, want_ns, equal_nan=True)


def test_resort_stealing_stack_short():
    """A work stack too short: -1, and the subtree's list is marked failed
    (never opened), so no other thread takes from it."""
    from lockgraph.tree import LIST_OPEN, NLIST
    pos, perm, ntop, nn, ns, subroots, lists, nbelow, ctl = _stealing_setup(0, 2)
    assert _steal(0, pos, perm, ntop, subroots, ns, lists, nbelow, ctl, stack=2) == -1
    assert ctl[LIST_OPEN] == -1 and ctl[NLIST + LIST_OPEN] == 0


@pytest.mark.parametrize("m", [1, 2, 3, 8, 1023, 1024])
@pytest.mark.parametrize("ties", [False, True])
def test_median_of_is_numpys_median_bit_for_bit(m, ties):
    """``median_of`` (the engine's typical speed, by selection in a kernel)
    returns exactly ``np.median``: the search skin, and so every reach, is
    the same number as before it replaced the numpy call."""
    rng = np.random.default_rng(m + 7 * ties)
    for _ in range(20):
        a = rng.lognormal(0.0, 1.0, m)
        if ties:
            a = np.round(a, 1)  # many equal values
        want = np.median(a)
        got = median_of(a.copy(), np.zeros(m, np.int64))
        assert got == want
