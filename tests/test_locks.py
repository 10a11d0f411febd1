"""Lock regions (lock graph and grid) against brute force.

Coverage: any two particles that may meet within the step — brute force over
all pairs and periodic images with the engine's step-start anchors and reaches
— lie in the same lock region or in adjacent ones.  Every particle has exactly
one region (regions without neighbours included).  One class of checks, run
for every scene and lock structure.
"""
import numpy as np
import pytest

from lockgraph import locks as L
from lockgraph import scenarios
from lockgraph.engine import Engine
from lockgraph.parallel import INTERIOR, classify_ranges, classify_regions

SCENES = {
    "ring": dict(n=800, params={"dispersion": 0.003, "dt": 60.0}),
    "ring_moonlet": dict(n=900, params={"dispersion": 0.003, "dt": 60.0, "moonlet_radius": 8.0}),
    "dish": dict(n=600, params={"cylinder_radius": 0.006, "dt": 0.0005, "spacing": 1.1}),
    "dish_marble": dict(n=601, params={"cylinder_radius": 0.006, "marble_radius": 0.003,
                                       "dt": 0.0005, "spacing": 1.1, "marble_gap": 0.0002}),
    "gas": dict(n=864, params={"eta": 0.35}),
}
LOCKS = [("graph", 1.2), ("graph", 2.0), ("graph", 4.0), ("graph", 6.0), ("graph", 8.0),
         ("grid", None), ("grid3d", None)]
# the lock graph with the regions far from the other domains merged, as the
# threaded exact policy builds it: 2 and 4 domains, the engine's own margin
# ("auto") and margins of 0 and 1 largest reach, which merge much more (every
# node of one domain whose box stays clear of the others' boxes)
MERGED = [("graph", 4.0, (2, "auto")), ("graph", 1.2, (2, 0.0)), ("graph", 4.0, (2, 1.0)),
          ("graph", 2.0, (4, 0.0))]


def step_structures(name, lock, scale, merge=None, steps=3):
    cfg = SCENES[name]
    sc = scenarios.load(name, n=cfg["n"], params=cfg["params"])
    eng = Engine(sc.state, sc.physics, sc.dt, lock=lock, scale=scale or 4.0, leaf_size=4)
    for _ in range(steps):
        eng.step()
    img_pos, img_vel, half, full = sc.physics.domain.images(eng.time)
    eng._setup(img_pos, img_vel, half)
    if merge is None:
        return eng, eng.build_locks(img_pos, half), sc.physics.domain
    ndom, margin = merge
    dlo, dhi = eng._domains(ndom)
    assert eng._far_domains(scale, img_pos, dlo, dhi, full) is None  # no hop measured yet
    plain = eng.build_locks(img_pos, half, domains=(dlo, dhi, full))
    eng._fine_hop = plain.info["fine_hop"]  # as a threaded step's _events_parallel does
    far = eng._far_domains(scale, img_pos, dlo, dhi, full)
    if margin != "auto":
        far = far[:4] + (margin * float(eng.nreach[0]),)
    regions = L.lock_graph(eng.ntop, eng.nbox, eng.nreach, eng.nnodes, half, img_pos, scale,
                           eng.n, domains=far)
    regions.merged_from = (dlo, dhi, far, plain)
    return eng, regions, sc.physics.domain


def brute_pairs(eng, domain):
    img_pos, img_vel, half, full = domain.images(eng.time)
    a_all, b_all = [], []
    for img in full:
        d = eng.anc[:, None, :] - eng.anc[None, :, :] - img_pos[img]
        ok = (d ** 2).sum(-1) <= (eng.reach[:, None] + eng.reach[None, :]) ** 2
        if img == 13:
            np.fill_diagonal(ok, False)
        a, b = np.nonzero(ok)
        a_all.append(a)
        b_all.append(b)
    return np.concatenate(a_all), np.concatenate(b_all)


def _case_id(p):
    merged = "" if p[3] is None else f"-merged{p[3][0]}d-{p[3][1]}"
    return f"{p[0]}-{p[1]}-{p[2]}{merged}"


@pytest.fixture(scope="module", params=[(s, lk, sc, None) for s in SCENES for lk, sc in LOCKS]
                + [(s, lk, sc, m) for s in SCENES for lk, sc, m in MERGED], ids=_case_id)
def case(request):
    name, lock, scale, merge = request.param
    eng, regions, domain = step_structures(name, lock, scale, merge)
    return name, lock, scale, eng, regions, domain


class TestLockRegions:
    def test_every_particle_has_one_region(self, case):
        name, lock, scale, eng, regions, domain = case
        assert regions.lock_of.shape == (eng.n,)
        assert regions.lock_of.min() >= 0 and regions.lock_of.max() < regions.count

    def test_adjacency_is_symmetric_without_self_loops(self, case):
        *_, regions, domain = case
        edges = set()
        for r in range(regions.count):
            for x in regions.ladj[regions.loff[r]:regions.loff[r + 1]]:
                assert x != r
                edges.add((r, int(x)))
        assert all((b, a) in edges for a, b in edges)

    def test_each_adjacency_list_lists_a_region_once(self, case):
        *_, regions, domain = case
        for r in range(regions.count):
            lst = regions.ladj[regions.loff[r]:regions.loff[r + 1]]
            assert len(np.unique(lst)) == len(lst)

    def test_pairs_that_may_meet_are_covered(self, case):
        name, lock, scale, eng, regions, domain = case
        a, b = brute_pairs(eng, domain)
        assert len(a) > 0
        la, lb = regions.lock_of[a], regions.lock_of[b]
        adjacent = np.array([regions.adjacent(x, y) for x, y in zip(la, lb)])
        assert adjacent.all(), f"{(~adjacent).sum()} pairs in non-adjacent regions"

    def test_stats(self, case):
        *_, regions, domain = case
        st = regions.stats()
        assert st["regions"] == regions.count
        assert 0 <= st["mean_degree"] <= st["max_degree"]

    @pytest.mark.parametrize("ndom", [2, 3, 4])
    def test_distance_to_other_domains(self, case, ndom):
        """classify_regions against brute force: each region's domain (-1 when
        its particles span domains) and its hop distance to the nearest region
        of another domain (BFS from every region over the adjacency; empty
        regions belong to no domain), capped at INTERIOR; the particles at the
        cap are counted."""
        *_, eng, regions, domain = case
        n, r = eng.n, regions.count
        cuts = [n * k // ndom for k in range(ndom + 1)]
        dlo, dhi = np.array(cuts[:-1], np.int64), np.array(cuts[1:], np.int64)
        owner = np.searchsorted(dhi, np.arange(n), side="right")
        doms = [set(owner[regions.lock_of == x].tolist()) for x in range(r)]
        want_dom = np.array([-2 if not d else next(iter(d)) if len(d) == 1 else -1
                             for d in doms])
        nbrs = [regions.ladj[regions.loff[x]:regions.loff[x + 1]] for x in range(r)]
        want_bd = np.full(r, INTERIOR)
        for x in range(r):
            if want_dom[x] == -1:
                want_bd[x] = 0
                continue
            if want_dom[x] == -2:
                continue  # empty regions: no events; only passed through
            seen, front, hops = {x}, [x], 0
            while front and hops < INTERIOR:
                if any(want_dom[y] not in (-2, want_dom[x]) for y in front):
                    want_bd[x] = hops
                    break
                front = [int(z) for y in front for z in nbrs[y] if z not in seen]
                seen.update(front)
                hops += 1
        dom, bd = np.zeros(r, np.int64), np.zeros(r, np.int64)
        far = classify_regions(regions.lock_of, regions.loff, regions.ladj, dlo, dhi, dom, bd,
                               np.zeros(r, np.int64), INTERIOR)
        np.testing.assert_array_equal(dom, want_dom)
        full = want_dom != -2
        np.testing.assert_array_equal(bd[full], want_bd[full])
        assert far == int((want_bd[regions.lock_of] >= INTERIOR).sum())
        if regions.kind == "graph":  # the engine's O(regions) version for tree nodes
            nodes = regions.info["lock_nodes"]
            dom2, bd2 = np.zeros(r, np.int64), np.zeros(r, np.int64)
            far2 = classify_ranges(eng.ntop[nodes, 2], eng.ntop[nodes, 3], regions.loff,
                                   regions.ladj, dlo, dhi, dom2, bd2, np.zeros(r, np.int64),
                                   INTERIOR)
            np.testing.assert_array_equal(dom2, dom)
            np.testing.assert_array_equal(bd2, bd)
            assert far2 == far


def test_lock_graph_regions_are_tree_nodes_partitioning_the_slots():
    eng, regions, domain = step_structures("gas", "graph", 4.0)
    nodes = regions.info["lock_nodes"]
    spans = sorted((int(eng.ntop[nd, 2]), int(eng.ntop[nd, 3])) for nd in nodes)
    assert spans[0][0] == 0 and spans[-1][1] == eng.n
    assert all(spans[k][1] == spans[k + 1][0] for k in range(len(spans) - 1))


def test_larger_scale_gives_fewer_larger_regions():
    counts = [step_structures("gas", "graph", s)[1].count for s in (1.2, 4.0, 8.0)]
    assert counts[0] >= counts[1] >= counts[2]
    assert counts[0] > counts[2]


def test_big_body_makes_one_big_well_connected_region():
    """The paper's Figure 3: the moonlet's lock node is large and has many edges."""
    eng, regions, domain = step_structures("ring_moonlet", "graph", 2.0)
    moon = int(np.argmax(eng.rad))
    r = regions.lock_of[moon]
    deg = regions.degrees()
    assert deg[r] >= np.percentile(deg, 90)


def test_a_region_without_neighbours_is_still_a_region():
    """With SCALE large enough the whole moonlet patch is one lock node."""
    eng, regions, domain = step_structures("ring_moonlet", "graph", 1000.0)
    assert regions.count == 1 and regions.degrees()[0] == 0
    assert (regions.lock_of == 0).all()


def test_grid_neighbours():
    eng, regions, domain = step_structures("gas", "grid", None)
    assert set(regions.degrees()) == {8}
    eng, regions, domain = step_structures("gas", "grid3d", None)
    assert set(regions.degrees()) == {26}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_csr_from_edges_with_duplicates(seed):
    """locks._csr against a set of edges: every edge in both lists, each once,
    nothing else; regions without edges get empty lists."""
    from lockgraph.locks import _csr

    rng = np.random.default_rng(seed)
    nreg = 50
    u = rng.integers(0, nreg, 400)
    v = rng.integers(0, nreg, 400)
    keep = u != v
    u, v = u[keep], v[keep]
    u = np.concatenate([u, v[:50]])  # duplicates, some reversed
    v = np.concatenate([v, u[:50]])
    loff, ladj = _csr(nreg, u, v)
    want = {r: set() for r in range(nreg)}
    for a, b in zip(u, v):
        want[int(a)].add(int(b))
        want[int(b)].add(int(a))
    for r in range(nreg):
        got = ladj[loff[r]:loff[r + 1]].tolist()
        assert len(got) == len(set(got)) and set(got) == want[r]
    assert loff[-1] == len(ladj) == sum(len(s) for s in want.values())


@pytest.fixture(scope="module", params=[(s, lk, sc, m) for s in SCENES for lk, sc, m in MERGED],
                ids=_case_id)
def merged_case(request):
    name, lock, scale, merge = request.param
    eng, regions, domain = step_structures(name, lock, scale, merge)
    return name, merge, eng, regions


def _node_of_region(eng, regions):
    """Each region's tree node (regions are tree nodes: the node whose slot range
    is exactly the region's slots)."""
    out = []
    for r in range(regions.count):
        slots = np.flatnonzero(regions.lock_of == r)
        nd = np.flatnonzero((eng.ntop[:eng.nnodes, 2] == slots.min())
                            & (eng.ntop[:eng.nnodes, 3] == slots.max() + 1))
        assert len(slots) == slots.max() + 1 - slots.min() and len(nd) >= 1
        out.append(nd[0])
    return out


class TestMergedFarRegions:
    def test_a_coarsening_of_the_lock_graph(self, merged_case):
        """Every region of the paper's lock graph lies within one merged region,
        and merged regions are tree nodes too."""
        name, merge, eng, regions = merged_case
        dlo, dhi, far, plain = regions.merged_from
        for r in range(plain.count):
            assert len(np.unique(regions.lock_of[plain.lock_of == r])) == 1
        _node_of_region(eng, regions)

    def test_only_far_nodes_of_one_domain_are_merged(self, merged_case):
        """A region that is not a lock node of the paper's graph holds the
        particles of one domain and its box is farther than the margin from
        every other domain's box and their periodic images."""
        name, merge, eng, regions = merged_case
        dlo, dhi, far, plain = regions.merged_from
        _, _, dbox, imgs, margin = far
        plain_nodes = set(_node_of_region(eng, plain))
        owner = np.searchsorted(dhi, np.arange(eng.n), side="right")
        for r, nd in enumerate(_node_of_region(eng, regions)):
            if nd in plain_nodes:
                continue
            doms = np.unique(owner[regions.lock_of == r])
            assert len(doms) == 1
            box = eng.nbox[nd]
            for e in range(len(dlo)):
                if e == doms[0]:
                    continue
                for o in imgs:
                    lo, hi = dbox[e, :3] + o, dbox[e, 3:] + o
                    gap = np.maximum(0.0, np.maximum(lo - box[3:], box[:3] - hi))
                    assert np.sqrt((gap ** 2).sum()) > margin

    def test_small_margins_merge(self, merged_case):
        """Not vacuous: a margin of 0 leaves fewer regions than the paper's graph."""
        name, merge, eng, regions = merged_case
        if merge[1] == 0.0:
            assert regions.count < regions.merged_from[3].count


def _interior_particles(regions, dlo, dhi):
    r = regions.count
    dom, bd = np.zeros(r, np.int64), np.zeros(r, np.int64)
    classify_regions(regions.lock_of, regions.loff, regions.ladj, dlo, dhi, dom, bd,
                     np.zeros(r, np.int64), INTERIOR)
    return bd[regions.lock_of] >= INTERIOR


def test_merging_keeps_interior_particles_interior(merged_case):
    """With the engine's margin (from the fine regions' hop) merged regions lie
    beyond the boundary band: every particle interior under the paper's graph
    is interior under the merged one (merging only shortens paths, so the
    reverse always holds)."""
    name, merge, eng, regions = merged_case
    dlo, dhi, far, plain = regions.merged_from
    merged_in = _interior_particles(regions, dlo, dhi)
    plain_in = _interior_particles(plain, dlo, dhi)
    assert not (merged_in & ~plain_in).any()
    if merge[1] == "auto":
        assert (merged_in == plain_in).all(), f"{(plain_in & ~merged_in).sum()} particles lost"


@pytest.mark.parametrize("name, n, params", [("ring", 20000, {}),
                                             ("dish", 4000, {"spacing": 1.1})])
def test_engine_margin_merges_without_losing_interior(name, n, params):
    """Scenes big enough for the engine's own margin to matter.  The ring: it
    merges (fewer regions) and every interior particle stays interior.  The
    dense block: regions are as wide as the boundary band is deep, so a margin
    of a fixed 8 R (the one first tried, tuned on the ring) would merge regions
    inside the band and lose most interior particles; the margin from the
    measured hop keeps them all."""
    sc = scenarios.load(name, n=n, params=params)
    eng = Engine(sc.state, sc.physics, sc.dt, scale=4.0)
    for _ in range(2):
        eng.step()
    img_pos, img_vel, half, full = sc.physics.domain.images(eng.time)
    eng._setup(img_pos, img_vel, half)
    dlo, dhi = eng._domains(2)
    plain = eng.build_locks(img_pos, half, domains=(dlo, dhi, full))
    eng._fine_hop = plain.info["fine_hop"]  # as a threaded step's _events_parallel does
    merged = eng.build_locks(img_pos, half, domains=(dlo, dhi, full))
    fixed = L.lock_graph(eng.ntop, eng.nbox, eng.nreach, eng.nnodes, half, img_pos, 4.0, eng.n,
                         domains=eng._far_domains(4.0, img_pos, dlo, dhi, full)[:4]
                         + (8.0 * float(eng.nreach[0]),))
    want = _interior_particles(plain, dlo, dhi)
    assert want.sum() > 0.1 * eng.n
    assert (_interior_particles(merged, dlo, dhi) == want).all()
    if name == "ring":
        assert merged.count < 0.8 * plain.count
    else:
        assert _interior_particles(fixed, dlo, dhi).sum() < 0.5 * want.sum()
