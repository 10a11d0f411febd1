"""The ideal band schedule (``lockgraph.band_replay``): particle levels against
a breadth-first search, makespans against hand-worked schedules and bounds."""
from collections import deque

import numpy as np
import pytest

from lockgraph.band_replay import (band_schedule, creators, domain_masks, event_domains,
                                   event_waits, order_conflicts, particle_levels, pool_schedule,
                                   region_waits)

from .helpers import symmetric_csr


def random_lists(rng, n, m):
    """Symmetric candidate lists (CSR) of m random pairs among n particles,
    and each particle's candidates as a set."""
    a = rng.integers(0, n, m)
    b = rng.integers(0, n, m)
    keep = a != b
    noff, nent = symmetric_csr(n, zip(a[keep], b[keep]), np.int64)
    adj = [set(nent[noff[i]:noff[i + 1]].tolist()) for i in range(n)]
    return adj, noff, nent


def bfs_levels(adj, domain, levels):
    """Oracle: 1 + hops to the nearest particle with a candidate in another
    domain, capped at levels + 1."""
    n = len(adj)
    dist = [None] * n
    q = deque()
    for i in range(n):
        if any(domain[j] != domain[i] for j in adj[i]):
            dist[i] = 0
            q.append(i)
    while q:
        i = q.popleft()
        for j in adj[i]:
            if dist[j] is None:
                dist[j] = dist[i] + 1
                q.append(j)
    return np.array([levels + 1 if d is None else min(d + 1, levels + 1) for d in dist])


class TestParticleLevels:
    @pytest.mark.parametrize("seed", range(6))
    @pytest.mark.parametrize("levels", [1, 2, 3])
    def test_against_bfs(self, seed, levels):
        rng = np.random.default_rng(seed)
        n = 60
        adj, noff, nent = random_lists(rng, n, 70)
        domain = (np.arange(n) >= rng.integers(10, 50)).astype(np.int64)
        got = particle_levels(noff, nent, domain, levels)
        np.testing.assert_array_equal(got, bfs_levels(adj, domain, levels))

    def test_one_domain_all_free(self):
        rng = np.random.default_rng(1)
        _, noff, nent = random_lists(rng, 20, 30)
        assert (particle_levels(noff, nent, np.zeros(20, np.int64), 2) == 3).all()

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="levels"):
            particle_levels(np.zeros(3, np.int64), np.zeros(0, np.int64), np.zeros(2), 0)
        with pytest.raises(ValueError, match="noff"):
            particle_levels(np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros(2), 1)

    def test_event_domains(self):
        lvl = np.array([3, 1, 3, 2])
        dom, band = event_domains([0, 2, 3, 0], [2, -1, 0, 1], np.array([0, 0, 1, 1]), lvl, 2)
        np.testing.assert_array_equal(dom, [0, 1, 1, 0])
        np.testing.assert_array_equal(band, [False, False, True, True])


class TestBandSchedule:
    def test_no_band_is_the_larger_half(self):
        cost = np.array([1.0, 2.0, 3.0, 4.0])
        span, busy = band_schedule([0, 1, 0, 1], np.zeros(4, bool), cost)
        assert span == 6.0
        np.testing.assert_array_equal(busy, [4.0, 6.0])

    def test_alternating_band_is_sequential(self):
        # every event waits for the other domain's previous one
        cost = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
        for runahead in (False, True):
            span, _ = band_schedule([0, 1, 0, 1, 0], np.ones(5, bool), cost, runahead)
            assert span == cost.sum()

    def test_hand_worked(self):
        # e0 d0 free 1; e1 d1 band 1 (waits for e0); e2 d0 band 1 (waits for
        # e1); e3 d1 free 5 after e1: d0 0-1, 2-3; d1 1-2, 2-7
        dom, band, cost = [0, 1, 0, 1], [False, True, True, False], [1.0, 1.0, 1.0, 5.0]
        assert band_schedule(dom, band, cost)[0] == 7.0
        # band events cost 1.5: e1 1-2.5, e2 2.5-4, e3 2.5-7.5
        assert band_schedule(dom, band, cost, sync=0.5)[0] == 7.5
        assert band_schedule(dom, band, cost, runahead=True)[0] == 7.0

    def test_runahead_fills_the_wait(self):
        # e0 d1 free 3; e1 d0 band 1 waits for e0; e2 d0 free 2: without
        # runahead d0 runs 3-4 and 4-6; with it 0-2 then 3-4
        dom, band, cost = [1, 0, 0], [False, True, False], [3.0, 1.0, 2.0]
        assert band_schedule(dom, band, cost)[0] == 6.0
        assert band_schedule(dom, band, cost, runahead=True)[0] == 4.0

    @pytest.mark.parametrize("seed", range(5))
    def test_bounds(self, seed):
        """max busy <= makespan <= sequential sum, on random traces (running
        ahead is greedy: it need not be shorter)."""
        rng = np.random.default_rng(seed)
        e = 400
        dom = rng.integers(0, 3, e)
        band = rng.random(e) < 0.2
        cost = rng.exponential(1.0, e)
        plain, busy = band_schedule(dom, band, cost)
        ahead, _ = band_schedule(dom, band, cost, runahead=True)
        for span in (plain, ahead):
            assert busy.max() - 1e-12 <= span <= cost.sum() + 1e-12


def tick_schedule(dom, band, cost, runahead, ahead):
    """Oracle for integer costs: every time unit each idle thread starts what
    the band rule allows, knowing every finish so far."""
    e_all = len(cost)
    ndom = max(dom) + 1
    fin = [None] * e_all
    busy_until = [0] * ndom
    todo = [[e for e in range(e_all) if dom[e] == d] for d in range(ndom)]
    tau = 0
    while any(todo):
        for d in range(ndom):
            if busy_until[d] > tau or not todo[d]:
                continue

            def clear(e):
                return all(fin[x] is not None and fin[x] <= tau
                           for x in range(e) if dom[x] != dom[e])
            pick = None
            front = todo[d][0]
            if not band[front] or clear(front):
                pick = front
            elif runahead:
                frees = [e for e in todo[d] if not band[e] and ahead[e]]
                if frees:
                    pick = frees[0]
            if pick is not None:
                fin[pick] = tau + cost[pick]
                busy_until[d] = fin[pick]
                todo[d].remove(pick)
        tau += 1
    return max(fin)


@pytest.mark.parametrize("seed", range(40))
@pytest.mark.parametrize("runahead", [False, True])
def test_against_tick_oracle(seed, runahead):
    """The event-driven schedule equals a unit-time oracle's on random
    integer traces (2-3 domains, 0-60 % band events)."""
    rng = np.random.default_rng(seed)
    e = int(rng.integers(1, 40))
    dom = rng.integers(0, int(rng.integers(2, 4)), e)
    band = rng.random(e) < rng.random() * 0.6
    cost = rng.integers(1, 6, e)
    span, _ = band_schedule(dom, band, cost.astype(float), runahead)
    assert span == tick_schedule(list(dom), list(band), list(cost), runahead, [True] * e)
    if runahead:  # only some free events may run ahead
        ahead = rng.random(e) < 0.5
        span, _ = band_schedule(dom, band, cost.astype(float), True, ahead=ahead)
        assert span == tick_schedule(list(dom), list(band), list(cost), True, list(ahead))


class TestOrderConflicts:
    # particles 0..3; candidate lists: 1 has 0, 0 has 1, 2 and 3 none
    noff = np.array([0, 1, 2, 2, 2])
    nent = np.array([1, 0])

    def count(self, ev_i, ev_j, kind, start, cost=1.0):
        start = np.asarray(start, float)
        return order_conflicts(ev_i, ev_j, kind, self.noff, self.nent, start, start + cost)

    def test_in_order_is_clean(self):
        assert self.count([0, 0, 2], [-1, 1, -1], [1, 0, 1], [0, 1, 2]) == 0

    def test_disjoint_overlap_is_clean(self):
        # walls of 2 and 3 at once: nothing shared
        assert self.count([2, 3], [-1, -1], [1, 1], [0, 0]) == 0

    def test_two_writes_swapped(self):
        # both write 2; the later one in key order started first
        assert self.count([2, 2], [-1, -1], [1, 1], [1, 0]) == 2

    def test_candidate_read_swapped(self):
        # event 0 writes 0 (and reads its candidate 1), event 1 writes 1 (and
        # reads 0) first: each wrote what the other read out of order
        assert self.count([0, 1], [-1, -1], [1, 1], [1, 0]) == 2
        assert self.count([0, 1], [-1, -1], [1, 1], [0, 0.5]) == 2  # overlapping
        assert self.count([0, 1], [-1, -1], [1, 1], [0, 1.0]) == 0

    def test_stale_partner_read(self):
        # a stale event of 2 reads its partner 3, written by an earlier wall
        # event still running
        assert self.count([3, 2], [-1, 3], [1, 2], [0, 0.5]) == 1
        assert self.count([3, 2], [-1, 3], [1, 2], [0, 1.0]) == 0

    def test_schedule_overlap(self):
        # the plain band rule on a trace: cross events wait, so a pair
        # event after a wall event of the same particle starts after it ends
        dom, band, cost = np.array([0, 1]), np.array([True, True]), np.array([1.0, 1.0])
        _, _, fin, start = band_schedule(dom, band, cost, finish=True)
        np.testing.assert_array_equal(start, [0.0, 1.0])
        assert order_conflicts([0, 1], [1, 0], [0, 0], self.noff, self.nent, start, fin) == 0


def bfs_masks(adj, domain, levels):
    """Oracle: the domains of the particles within `levels` hops, as bits."""
    out = []
    for p in range(len(adj)):
        seen, front = {p}, {p}
        for _ in range(levels):
            front = {y for x in front for y in adj[x]} - seen
            seen |= front
        out.append(sum(1 << int(d) for d in {domain[x] for x in seen}))
    return np.array(out, np.uint64)


def random_trace(rng, adj, e_all):
    """Events of random particles: a pair collision (kind 0) or a stale event
    (2) with a random candidate, or a wall event (1)."""
    ev_i, ev_j, kind = [], [], []
    for _ in range(e_all):
        i = int(rng.integers(0, len(adj)))
        k = int(rng.integers(0, 3)) if adj[i] else 1
        ev_i.append(i)
        kind.append(k)
        ev_j.append(int(rng.choice(sorted(adj[i]))) if k != 1 else -1)
    return np.array(ev_i), np.array(ev_j), np.array(kind)


def tick_pool(dom, wait, cost, threads, cr, fixed=False):
    """Oracle for integer costs: every time unit the free threads take, one
    at a time, the least-key event that the pool rule lets start, with
    everything re-derived from the finish times so far (fixed: domain d only
    on thread d mod T)."""
    e_all = len(cost)
    fin = [None] * e_all
    tau = 0

    def exists(x):
        return cr[x] < 0 or (fin[cr[x]] is not None and fin[cr[x]] <= tau)

    def unfinished(x):
        return (fin[x] is None and exists(x)) or (fin[x] is not None and fin[x] > tau)

    while None in fin:
        while sum(f is not None and f > tau for f in fin) < threads:
            busy = {dom[x] for x in range(e_all) if fin[x] is not None and fin[x] > tau}
            if fixed:  # a busy thread's other domains wait too
                busy = {d for d in set(dom) if any(d % threads == b % threads for b in busy)}
            picks = []
            for d in set(dom) - busy:
                pend = [x for x in range(e_all) if dom[x] == d and fin[x] is None and exists(x)]
                if pend and not any(dom[x] != d and (int(wait[pend[0]]) >> int(dom[x])) & 1
                                    and unfinished(x) for x in range(pend[0])):
                    picks.append(pend[0])
            if not picks:
                break
            e = min(picks)
            fin[e] = tau + cost[e]
        tau += 1
    return max(fin), [f - c for f, c in zip(fin, cost)]


class TestPoolSchedule:
    @pytest.mark.parametrize("seed", range(6))
    @pytest.mark.parametrize("levels", [0, 1, 2])
    def test_masks_against_bfs(self, seed, levels):
        rng = np.random.default_rng(seed)
        n = 50
        adj, noff, nent = random_lists(rng, n, 60)
        domain = rng.integers(0, 5, n)
        np.testing.assert_array_equal(domain_masks(noff, nent, domain, levels),
                                      bfs_masks(adj, domain, levels))

    @pytest.mark.parametrize("seed", range(4))
    def test_region_waits_against_bfs(self, seed):
        """The domains with a particle in a region within two region hops of
        either particle's region; particles as their own regions give the
        particle waits."""
        rng = np.random.default_rng(seed)
        n, r = 60, 12
        domain = rng.integers(0, 4, n)
        region = rng.integers(0, r, n)
        radj, loff, ladj = random_lists(rng, r, 15)
        ev_i = rng.integers(0, n, 30)
        ev_j = np.where(rng.random(30) < 0.7, rng.integers(0, n, 30), -1)
        edom, wait = region_waits(ev_i, ev_j, domain, region, loff, ladj)
        near = bfs_masks(radj, list(range(r)), 2)  # bit x: region x within two hops
        for e in range(30):
            regs = {int(region[ev_i[e]])} | ({int(region[ev_j[e]])} if ev_j[e] >= 0 else set())
            want = 0
            for p in range(n):
                if any((int(near[x]) >> int(region[p])) & 1 for x in regs) and \
                        domain[p] != domain[ev_i[e]]:
                    want |= 1 << int(domain[p])
            assert edom[e] == domain[ev_i[e]] and int(wait[e]) == want
        _, noff, nent = random_lists(rng, n, 70)
        np.testing.assert_array_equal(
            region_waits(ev_i, ev_j, domain, np.arange(n), noff, nent)[1],
            event_waits(ev_i, ev_j, domain, domain_masks(noff, nent, domain, 2))[1])
        with pytest.raises(ValueError, match="region"):
            region_waits(ev_i, ev_j, domain, np.full(n, r), loff, ladj)

    def test_event_waits_and_creators(self):
        masks = np.array([0b01, 0b11, 0b110, 0b100], np.uint64)
        edom, wait = event_waits([0, 1, 2, 3], [1, -1, 0, -1], np.array([0, 0, 1, 2]), masks)
        np.testing.assert_array_equal(edom, [0, 0, 1, 2])
        np.testing.assert_array_equal(wait, [0b10, 0b10, 0b101, 0])
        # e1 is created by e0 (wrote 1), e2 by e1 (wrote 2), e3 by e0 (a pair
        # collision wrote 1); the stale e2 wrote only 2, so e4 (0 and 3) is new
        np.testing.assert_array_equal(creators([0, 1, 2, 1, 0], [1, -1, 1, -1, 3], [0, 1, 2, 1, 0]),
                                      [-1, 0, 1, 1, 0])

    def test_bad_arguments(self):
        with pytest.raises(ValueError, match="threads"):
            pool_schedule([0], np.zeros(1, np.uint64), [1.0], 0)
        with pytest.raises(ValueError, match="creator"):
            pool_schedule([0, 0], np.zeros(2, np.uint64), [1.0, 1.0], 1, creator=[-1, 1])
        with pytest.raises(ValueError, match="domains"):
            domain_masks(np.zeros(2, np.int64), np.zeros(0, np.int64), np.array([64]), 1)
        with pytest.raises(ValueError, match="levels"):
            domain_masks(np.zeros(2, np.int64), np.zeros(0, np.int64), np.array([0]), -1)

    def test_hand_worked(self):
        # one event in each of four domains; e2 waits for domain 1, e3 for
        # domain 2; e0 costs 3, the others 1: on two threads e0 runs 0-3
        # beside e1 0-1, e2 1-2 (e1 is done), e3 2-3 (e2 is done)
        dom = [0, 1, 2, 3]
        wait = np.array([0, 0, 0b10, 0b100], np.uint64)
        span, start, fin = pool_schedule(dom, wait, [3.0, 1.0, 1.0, 1.0], 2)
        np.testing.assert_array_equal(start, [0, 0, 1, 2])
        assert span == 3.0
        # one thread is the sequential sum; waits for everyone serialise
        assert pool_schedule(dom, wait, [3.0, 1.0, 1.0, 1.0], 1)[0] == 6.0
        everyone = np.array([0b1110, 0b1101, 0b1011, 0b0111], np.uint64)
        np.testing.assert_array_equal(pool_schedule(dom, everyone, [3.0, 1.0, 1.0, 1.0], 2)[1],
                                      [0, 3, 4, 5])
        # fixed threads: e2 (domain 2) must wait for thread 0, busy with e0
        # until 3; then e3 (thread 1) runs 4-5
        np.testing.assert_array_equal(
            pool_schedule(dom, wait, [3.0, 1.0, 1.0, 1.0], 2, fixed=True)[1], [0, 0, 3, 4])

    def test_created_late_is_not_waited_for(self):
        # e2 (domain 0) waits for domain 1, whose only event e1 is created by
        # e0 (domain 2, 0-2): known in advance, e1 runs 0-1 and e2 1-2; not
        # yet there, e2 starts at once (and e1 at 2)
        dom, wait, cost = [2, 1, 0], np.array([0, 0, 0b10], np.uint64), [2.0, 1.0, 1.0]
        np.testing.assert_array_equal(pool_schedule(dom, wait, cost, 2)[1], [0, 0, 1])
        np.testing.assert_array_equal(pool_schedule(dom, wait, cost, 2, creator=[-1, 0, -1])[1],
                                      [0, 2, 0])

    @pytest.mark.parametrize("seed", range(30))
    def test_against_tick_oracle(self, seed):
        rng = np.random.default_rng(seed)
        n = 30
        adj, noff, nent = random_lists(rng, n, 40)
        domain = rng.integers(0, int(rng.integers(2, 6)), n)
        ev_i, ev_j, kind = random_trace(rng, adj, int(rng.integers(1, 30)))
        edom, wait = event_waits(ev_i, ev_j, domain,
                                 domain_masks(noff, nent, domain, int(rng.integers(0, 3))))
        cost = rng.integers(1, 5, len(ev_i))
        threads = int(rng.integers(1, 4))
        for cr in (np.full(len(ev_i), -1), creators(ev_i, ev_j, kind)):
            for fixed in (False, True):
                span, start, _ = pool_schedule(edom, wait, cost.astype(float), threads,
                                               creator=cr, fixed=fixed)
                want_span, want_start = tick_pool(list(edom), wait, list(cost), threads,
                                                  list(cr), fixed)
                assert span == want_span
                np.testing.assert_array_equal(start, want_start)

    def test_two_hops_keep_the_order(self):
        """With every event known in advance, waits for the domains within two
        hops let no event run against the sequential order, on 20 random
        traces of 200 events; waits within one hop, or none, let some through."""
        clashes = {0: 0, 1: 0, 2: 0}
        for seed in range(20):
            rng = np.random.default_rng(seed)
            n = 40
            adj, noff, nent = random_lists(rng, n, 50)
            domain = rng.integers(0, 4, n)
            ev_i, ev_j, kind = random_trace(rng, adj, 200)
            cost = rng.exponential(1.0, len(ev_i))
            for levels in clashes:
                masks = domain_masks(noff, nent, domain, levels)
                edom, wait = event_waits(ev_i, ev_j, domain, masks)
                _, start, fin = pool_schedule(edom, wait, cost, 3)
                clashes[levels] += order_conflicts(ev_i, ev_j, kind, noff, nent, start, fin)
        assert clashes[2] == 0
        assert clashes[1] > 0 and clashes[0] > 0, clashes
