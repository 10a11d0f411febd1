"""A body 10-20 times larger than the rest must not slow the small ones.

Measured with the engine's work counters, not wall time: particle pairs tested
by the tree search, candidate-list lengths and queue pops per collision, for
the same small spheres with and without one big body (the small ones that
would overlap it removed).  A uniform grid sized for the big body would test
~ (R/r)^3 = 1e3-1e4 times more pairs per small particle; the tree's per-node
reach keeps the big body's cost in its own leaf.

Bound: 1.5x for the search and 1.25x for the lists.  Removing the spheres inside
the body and adding the body's own neighbours change the small ones'
surroundings by a few percent; the bounds leave room for that and still fail
by orders of magnitude if the big body's size leaked into everyone's search.
"""
import numpy as np
import pytest

from lockgraph.domains import Dish
from lockgraph.engine import Engine
from lockgraph.physics import Physics
from lockgraph.restitution import Constant
from lockgraph.state import State

R_SMALL = 0.5


def spheres(big_radius, seed=3):
    """Small spheres on a jittered lattice in a cylinder, optionally a big one at the centre."""
    rng = np.random.default_rng(seed)
    g = np.arange(-14.0, 14.01, 1.4)
    z = np.arange(1.0, 30.0, 1.4)
    pos = np.stack(np.meshgrid(g, g, z, indexing="ij"), -1).reshape(-1, 3)
    pos = pos[np.hypot(pos[:, 0], pos[:, 1]) < 14.0]
    pos += rng.uniform(-0.15, 0.15, pos.shape)
    centre = np.array([0.0, 0.0, 15.0])
    if big_radius:
        far = np.linalg.norm(pos - centre, axis=1) > big_radius + R_SMALL + 0.05
        pos = pos[far]
    n = len(pos)
    vel = rng.normal(0, 1.0, (n, 3))
    rad = np.full(n, R_SMALL)
    mass = np.ones(n)
    if big_radius:
        pos = np.vstack([pos, centre])
        vel = np.vstack([vel, [0.0, 0.0, 0.0]])
        rad = np.append(rad, big_radius)
        mass = np.append(mass, (big_radius / R_SMALL) ** 3)
    return State(pos, vel, rad, mass), centre


def work(big_radius, steps=6):
    st, centre = spheres(big_radius)
    eng = Engine(st, Physics(Dish(15.0), (), Constant(1.0)), 0.05)
    for _ in range(steps):
        eng.step()
    small = eng.rad == R_SMALL
    away = np.linalg.norm(eng.pos - centre, axis=1) > big_radius + 3.0
    counts = np.diff(eng.noff)
    n_small = small.sum()
    return {
        "tests_per_small": eng.search_tests / (steps + 1) / n_small,
        "cands_small_away": counts[small & away].mean(),
        "pops_per_collision": eng.totals[8] / (eng.totals[0] + eng.totals[1]),
        "collisions": eng.totals[0] + eng.totals[1],
    }


@pytest.mark.parametrize("ratio", [10, 20])
def test_big_body_does_not_slow_small_ones(ratio):
    base = work(0.0)
    big = work(ratio * R_SMALL)
    assert base["collisions"] > 500 and big["collisions"] > 500
    assert big["tests_per_small"] <= 1.5 * base["tests_per_small"], (big, base)
    assert big["cands_small_away"] <= 1.25 * base["cands_small_away"], (big, base)
    assert big["pops_per_collision"] <= 1.25 * base["pops_per_collision"], (big, base)
