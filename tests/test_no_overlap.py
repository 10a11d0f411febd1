"""No overlap is ever created: every scene, many steps, checked by brute force.

Tolerance 1e-12 relative: contacts are resolved where the centres are exactly
one contact distance apart, up to rounding of positions (~1e-16 relative to
the box size); 1e-12 allows for boxes 10^4 contact distances across.
"""
import pytest

from lockgraph import scenarios

from .helpers import SMALL, brute_max_overlap

STEPS = {"gas": 100, "ring": 200, "ring_moonlet": 200, "dish": 300, "dish_marble": 300}


@pytest.mark.parametrize("name", sorted(SMALL))
def test_no_overlap_after_many_steps(name):
    cfg = dict(SMALL[name])
    n = cfg["n"] * 4
    params = dict(cfg["params"])
    if name == "ring_moonlet":
        n = 150
    sc = scenarios.load(name, n=n, params=params)
    sim = sc.simulation()
    worst = 0.0
    for _ in range(4):
        sim.run(STEPS[name] // 4)
        worst = max(worst, brute_max_overlap(sim.state, sc.physics.domain))
    assert sim.stats["collisions"] > 50
    assert worst < 1e-12
    assert sim.stats["max_overlap"] < 1e-12
