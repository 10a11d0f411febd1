"""The replay benchmark's domain cuts and traced costs
(``benchmarks/band_bound.py``: ``cut_domains``, ``in_slots``)."""
import numpy as np
import pytest


@pytest.fixture(scope="module")
def bb(load_benchmark):
    return load_benchmark("band_bound")


def random_events(rng, n, e):
    si = rng.integers(0, n, e)
    sj = np.where(rng.random(e) < 0.8, rng.integers(0, n, e), -1)
    cost = rng.exponential(1e-6, e)
    return si, sj, cost


@pytest.mark.parametrize("k", [2, 4, 16])
def test_height_cut_is_the_cost_cut_of_the_slots_sorted_by_height(bb, k):
    # the oracle: with the slots already in height order, the slabs are the
    # cost cut's runs of slots; shuffling the heights moves each slot's
    # domain with its height
    rng = np.random.default_rng(k)
    n = 500
    si, sj, cost = random_events(rng, n, 4000)
    pos = rng.random((n, 3)) * [1.0, 1.0, 3.0]  # z the longest axis
    order = np.argsort(pos[:, 2], kind="stable")
    sorted_pos = pos[order]
    inv = np.empty(n, np.int64)
    inv[order] = np.arange(n)
    # the same events on slots renumbered in height order
    sj_s = np.where(sj >= 0, inv[np.maximum(sj, 0)], -1)
    by_cost = bb.cut_domains(n, inv[si], sj_s, cost, "cost", k)
    by_height = bb.cut_domains(n, inv[si], sj_s, cost, "height", k, sorted_pos)
    assert np.array_equal(by_cost, by_height)
    shuffled = bb.cut_domains(n, si, sj, cost, "height", k, pos)
    assert np.array_equal(shuffled, by_height[inv])


def test_height_cut_takes_the_longest_axis_and_orders_the_slabs(bb):
    rng = np.random.default_rng(7)
    n = 400
    si, sj, cost = random_events(rng, n, 3000)
    pos = rng.random((n, 3)) * [5.0, 1.0, 1.0]  # x the longest axis
    dom = bb.cut_domains(n, si, sj, cost, "height", 8, pos)
    assert set(dom.tolist()) == set(range(8))
    # the slabs follow x: a slot's domain never falls as x grows
    assert np.all(np.diff(dom[np.argsort(pos[:, 0], kind="stable")]) >= 0)


def test_count_cut_is_equal_runs_of_slots(bb):
    dom = bb.cut_domains(16, np.zeros(1, np.int64), np.full(1, -1), np.ones(1), "count", 4)
    assert dom.tolist() == [0] * 4 + [1] * 4 + [2] * 4 + [3] * 4


def test_traced_costs_far_above_the_median_count_as_the_median(bb):
    cycles = np.full(11, 1000.0)
    cycles[3] = 1000.0 * bb.OUTLIER * 2  # the host's pause
    cycles[5] = 1000.0 * bb.OUTLIER * 0.5  # a long event, kept
    ev = np.zeros(11, dtype=[("cycles", "f8"), ("i", "i8"), ("j", "i8")])
    ev["cycles"] = cycles
    ev["i"] = np.arange(11)
    ev["j"] = -1
    si, sj, cost = bb.in_slots(ev, np.arange(11), 1e9)
    assert cost[3] == pytest.approx(1e-6)
    assert cost[5] == pytest.approx(1e-6 * bb.OUTLIER * 0.5)
    assert np.all(sj == -1) and np.array_equal(si, np.arange(11))
