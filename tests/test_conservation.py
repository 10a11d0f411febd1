"""Conservation laws over many collisions.

Tolerances: each collision changes the kinetic energy by rounding only, of
relative size ~1e-16; over ~10^4 collisions with random signs the drift grows
like sqrt(count) * 1e-16 ~ 1e-14.  We allow 1e-11: three orders of margin,
while a wrong impulse (an error of order one in one collision) changes the
energy by ~1/N ~ 1e-3.
"""
import numpy as np
import pytest

from lockgraph import scenarios
from lockgraph.simulation import Simulation

ENERGY_TOL = 1e-11


def test_elastic_gas_conserves_energy_and_momentum():
    sc = scenarios.load("gas", n=500, params={"eta": 0.4})
    sim = sc.simulation()
    e0 = sc.state.kinetic_energy()
    p0 = sc.state.momentum()
    sim.run(60)
    assert sim.stats["pair_collisions"] > 10_000
    st = sim.state
    assert st.kinetic_energy() / e0 - 1 == pytest.approx(0, abs=ENERGY_TOL)
    # momentum: zero to rounding (scale: one particle's momentum ~ 1)
    assert np.abs(st.momentum() - p0).max() < 1e-10


def test_elastic_dish_conserves_total_energy():
    """e = 1, no guard: kinetic + potential energy is conserved through floor,
    wall and pair impacts, under exactly integrated gravity."""
    from lockgraph.physics import Physics
    from lockgraph.restitution import Constant

    sc = scenarios.load("dish", n=120, params={"cylinder_radius": 0.005})
    ph = Physics(sc.physics.domain, sc.physics.forces, Constant(1.0), None)
    sim = Simulation(sc.state, ph, dt=1e-4)

    def energy(s):
        return s.kinetic_energy() + float(np.sum(s.mass * 9.81 * s.pos[:, 2]))

    e0 = energy(sc.state)
    sim.run(800)
    assert sim.stats["wall_collisions"] > 100 and sim.stats["pair_collisions"] > 100
    assert energy(sim.state) / e0 - 1 == pytest.approx(0, abs=ENERGY_TOL)


def test_inelastic_dish_loses_energy_monotonically():
    sc = scenarios.load("dish", n=120, params={"cylinder_radius": 0.005})
    sim = sc.simulation()

    def energy(s):
        return s.kinetic_energy() + float(np.sum(s.mass * 9.81 * s.pos[:, 2]))

    last = energy(sim.state)
    for _ in range(10):
        sim.run(100)
        now = energy(sim.state)
        # the floor's minimum rebound g tc / 2 may add at most m (g tc / 2)^2 / 2 per impact
        slack = sim.stats["wall_collisions"] * 0.5 * sim.state.mass[0] * (0.5 * 9.81 * 1e-4) ** 2
        assert now <= last + slack
        last = now
