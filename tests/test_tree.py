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
from lockgraph.tree import build, count_nodes, node_bounds, pair_search, search_tasks


def tree_pairs(pos, rad, sig, domain, time=0.0, fr=1.0, leaf=8):
    """Candidate pairs from the tree, as a set of (lower id, higher id, image from lower)."""
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
    while True:
        out_a = np.zeros(cap, np.int32)
        out_e = np.zeros(cap, np.int32)
        m = pair_search(anc, reach, ntop, nbox, nreach, search_tasks(ntop, half, 1)[0], img_pos,
                        out_a, out_e, np.zeros((4096, 3), np.int64), np.zeros(2))
        if m <= cap:
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


class PairSearchChecks:
    """Reused for every variant: subclasses define ``system(seed)``."""
    seeds = range(6)
    fr = 1.0
    time = 0.0

    def system(self, seed):
        raise NotImplementedError

    @pytest.fixture(params=seeds)
    def case(self, request):
        pos, rad, sig, domain = self.system(request.param)
        found = tree_pairs(pos, rad, sig, domain, self.time, self.fr)
        truth = brute_pairs(pos, rad, sig, domain, self.time, self.fr)
        return found, truth

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
                  np.zeros(256, np.int64), nsplit, 0.0, np.zeros(n)) == 0
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
                  np.zeros(256, np.int64), nsplit, band, np.zeros(len(pos))) == 0


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
