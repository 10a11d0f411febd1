"""The ideal band schedule (``lockgraph.band_replay``): particle levels against
a breadth-first search, makespans against hand-worked schedules and bounds."""
from collections import deque

import numpy as np
import pytest

from lockgraph.band_replay import band_schedule, event_domains, order_conflicts, particle_levels

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
        _, _, fin = band_schedule(dom, band, cost, finish=True)
        assert order_conflicts([0, 1], [1, 0], [0, 0], self.noff, self.nent, fin - cost, fin) == 0
