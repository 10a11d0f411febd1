"""The speed benchmark's host ceiling (``benchmarks/host_ceiling.py``): two
sequential engines on two parts of a state, one after the other and at
once.  What it times must be the same work both ways, and its halves must be
the state cut in two."""
import numpy as np
import pytest

from lockgraph import scenarios


@pytest.fixture(scope="module")
def hc(load_benchmark):
    return load_benchmark("host_ceiling")


@pytest.fixture(scope="module")
def ring():
    return scenarios.load("ring", "early", n=1000)


class TestHalves:
    def test_the_halves_are_the_state_cut_at_the_median(self, hc, ring):
        st = ring.state
        a, b = hc.halves(st, axis=0)
        assert (a.n, b.n) == (st.n // 2, st.n - st.n // 2)
        # every particle in exactly one half, with all its values
        rows = np.concatenate([np.hstack([h.pos, h.vel, h.radius[:, None]]) for h in (a, b)])
        whole = np.hstack([st.pos, st.vel, st.radius[:, None]])
        assert np.array_equal(np.unique(rows, axis=0), np.unique(whole, axis=0))
        assert a.pos[:, 0].max() <= b.pos[:, 0].min()  # cut across x


class TestCeiling:
    @pytest.mark.parametrize("split", ["halves", "copies"])
    def test_both_pairs_time_the_same_steps(self, hc, ring, split):
        # deterministic engines from the same parts: step i is the same work
        # alone and at once, and their states stay bitwise equal
        c = hc.HostCeiling(ring.state, ring.physics, ring.dt, split)
        n = ring.state.n
        assert c.counts == ([n // 2, n - n // 2] if split == "halves" else [n, n])
        try:
            c.warm()
            assert c.phases_alone == [] and c.phases_at_once == []
            for _ in range(3):
                each, wall = c.alone()
                assert len(each) == 2 and wall >= sum(each) > 0.0
                both, wall = c.at_once()
                assert len(both) == 2 and wall >= max(both) > 0.0
            assert c.identical()
            # and each step's phases, by part: parts of the step's own time
            for rec, times in ((c.phases_alone, each), (c.phases_at_once, both)):
                assert len(rec) == 3
                assert set(rec[-1]) == {"search", "events", "other", "step"}
                for k in ("search", "events"):
                    assert all(0.0 < x <= t for x, t in zip(rec[-1][k], times))
        finally:
            c.close()

    def test_an_unknown_split_is_refused(self, hc, ring):
        with pytest.raises(ValueError, match="split"):
            hc.HostCeiling(ring.state, ring.physics, ring.dt, "thirds")


def test_a_failing_step_on_the_partner_thread_raises_in_the_caller(hc, ring):
    c = hc.HostCeiling(ring.state, ring.physics, ring.dt)
    try:
        step = c._once[1].step
        c._once[1].step = lambda: 1 / 0
        with pytest.raises(ZeroDivisionError):
            c.at_once()
        c._once[1].step = step  # and the thread goes on serving
        both, wall = c.at_once()
        assert len(both) == 2 and wall >= max(both) > 0.0
    finally:
        c.close()
