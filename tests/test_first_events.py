"""The threaded engine's first events (``kernels.init_range``, one call per
domain) against ``first_events`` over all slots and ``init_queue`` (the
sequential engine's): bit for bit the same pending
event for every particle, the same largest overlap, and each domain's queue
the tournament ``build_queue`` makes over that domain's slots.  Domains are
cut at arbitrary slots, so pairs across a cut are exercised in both orders."""
import numpy as np
import pytest

from lockgraph import kernels as K
from lockgraph import scenarios
from lockgraph.engine import Engine
from lockgraph.events import BUCKET_BITS, build_queue, tournament_size

SCENES = {
    "ring": dict(n=800, params={"dispersion": 0.003, "dt": 60.0}),
    "dish_marble": dict(n=601, params={"cylinder_radius": 0.006, "marble_radius": 0.003,
                                       "dt": 0.0005, "spacing": 1.1, "marble_gap": 0.0002}),
    "gas": dict(n=864, params={"eta": 0.35}),
}


def set_up(name, steps):
    """An engine on scene ``name`` after ``steps`` steps, with the next step's
    candidate lists found: (engine, parts, nbrs, evq, cfg) for the kernels."""
    cfg = SCENES[name]
    sc = scenarios.load(name, n=cfg["n"], params=cfg["params"])
    eng = Engine(sc.state, sc.physics, sc.dt, leaf_size=4)
    for _ in range(steps):
        eng.step()
    img_pos, img_vel, half, full = sc.physics.domain.images(eng.time)
    eng._setup(img_pos, img_vel, half)
    parts, step, tree, nbrs, evq, jour, cfg_ = eng._bundles(img_pos, img_vel, full)
    return eng, parts, nbrs, evq, cfg_


@pytest.mark.parametrize("name", sorted(SCENES))
@pytest.mark.parametrize("cuts", [(0.5,), (0.13, 0.61), (0.25, 0.5, 0.75)])
def test_domain_first_events_equal_the_sequential_ones(name, cuts):
    eng, parts, nbrs, evq, cfg_ = set_up(name, 3)
    st = np.zeros(K.NSTAT)
    K.first_events(parts, nbrs, evq, cfg_, st, 0, eng.n)
    K.init_queue(parts, evq)
    want = (eng.evt.copy(), eng.evp.copy(), eng.evc.copy())
    assert np.isfinite(want[0]).any()  # some particle has an event this step
    n = eng.n
    bounds = [0] + [int(c * n) for c in cuts] + [n]
    rows = np.zeros((len(bounds) - 1, K.NSTAT))
    eng.evt[:] = -1.0  # every slot must be written
    for d, (lo, hi) in enumerate(zip(bounds[:-1], bounds[1:])):
        q = tournament_size(hi - lo)
        tt, ts = np.full(2 * q, np.inf), np.full(2 * q, -1, np.int32)
        K.init_range(parts, nbrs, evq, cfg_, rows[d], lo, hi, tt, ts)
        tt2, ts2 = np.full(2 * q, np.inf), np.full(2 * q, -1, np.int32)
        build_queue(tt2, ts2, eng.evt, eng.ids, eng.hidden, lo, hi)
        assert np.array_equal(tt[1:], tt2[1:]) and np.array_equal(ts[1:], ts2[1:])
    got = (eng.evt, eng.evp, eng.evc)
    for a, b in zip(want, got):
        assert np.array_equal(a, b)  # bit for bit (times compared exactly)
    assert rows[:, K.S_MAXOV].max() == st[K.S_MAXOV]


@pytest.mark.parametrize("name", sorted(SCENES))
@pytest.mark.parametrize("tasks", [1, 3, 7])
def test_first_events_by_buckets_build_the_one_queue(name, tasks):
    """The engine's one queue from first events in slices cut at buckets'
    first slots (each slice builds its buckets' leaves, ``init_queue`` the
    rest): node for node the tournament ``build_queue`` makes from scratch,
    whatever the slices, after every slot's leaf was set to garbage."""
    eng, parts, nbrs, evq, cfg_ = set_up(name, 2)
    tour_t, tour_s = evq[3], evq[4]
    tour_t[:] = -7.0
    tour_s[:] = 12345
    n = eng.n
    lo = [(n * k // tasks) >> BUCKET_BITS << BUCKET_BITS for k in range(tasks)] + [n]
    st = np.zeros(K.NSTAT)
    for k in reversed(range(tasks)):  # any order
        K.first_events(parts, nbrs, evq, cfg_, st, lo[k], lo[k + 1])
    K.init_queue(parts, evq)
    tt, ts = np.full_like(tour_t, np.inf), np.full_like(tour_s, -1)
    build_queue(tt, ts, eng.evt, eng.ids, eng.hidden, 0, n)
    assert np.array_equal(tour_t[1:], tt[1:]) and np.array_equal(tour_s[1:], ts[1:])
    assert tour_s[1] >= 0  # some event to run
