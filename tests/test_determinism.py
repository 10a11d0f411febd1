"""Results depend only on the physics and the ids: not on engine tuning or storage order."""
import pytest

from lockgraph import scenarios
from lockgraph.simulation import Simulation


def final_hash(name, n, params, steps, **opts):
    sc = scenarios.load(name, n=n, params=params)
    sim = Simulation(sc.state, sc.physics, dt=sc.dt, **opts)
    sim.run(steps)
    return sim.state.sha256(), sim.stats


@pytest.mark.parametrize("name,n,params,steps", [
    ("gas", 400, {"eta": 0.45}, 30),
    ("dish", 200, {"cylinder_radius": 0.005}, 700),
    ("ring_moonlet", 600, {"dispersion": 0.002, "dt": 60.0, "moonlet_radius": 5.0}, 60),
])
def test_independent_of_skin_and_leaf_size(name, n, params, steps):
    ref, st = final_hash(name, n, params, steps)
    assert st["collisions"] > 100
    for opts in ({"skin": 0.0}, {"skin": 3.0}, {"leaf_size": 1}, {"leaf_size": 40}):
        assert final_hash(name, n, params, steps, **opts)[0] == ref, opts


def test_repeatable():
    a = final_hash("gas", 256, {}, 20)[0]
    b = final_hash("gas", 256, {}, 20)[0]
    assert a == b
