"""Restitution laws, the collapse guard, and inelastic collapse without it."""
import dataclasses

import numpy as np
import pytest

from lockgraph import kernels as K
from lockgraph import scenarios
from lockgraph.engine import Engine
from lockgraph.errors import InelasticCollapseError, InputError
from lockgraph.physics import Physics
from lockgraph.restitution import Bridges, CollapseGuard, Constant, VelocityGuard, coefficient
from lockgraph.simulation import Simulation
from lockgraph.state import State

from .helpers import cube


def test_bridges_formula():
    law, e, vc, p = Bridges().encode()
    assert coefficient(law, e, vc, p, 7.7e-5) == 1.0
    assert coefficient(law, e, vc, p, 1e-6) == 1.0
    assert coefficient(law, e, vc, p, 7.7e-3) == pytest.approx(100 ** -0.234, rel=1e-14)


@pytest.mark.parametrize("tc,want", [
    # guard on: impacts 2 and 3 come within tc of impact 1 and are elastic
    (1.0, [0.0, 0.25, 0.75]),
    # guard off in effect (tc tiny): every impact has e = 0.5
    (1e-9, [0.0625 * 0 + 0.25 * 0.25 / 1.0 * 0 + 0.15625, 0.1328125 - 0.0390625 + 0.0390625 * 0,
            0.5625]),
])
def test_guard_makes_quick_repeats_elastic(tc, want):
    """Three spheres in a row (gap 0.05 between 1 and 2); sphere 0 hits 1 at
    speed 1.  With the guard, the follow-up impacts are elastic."""
    pos = np.array([[-2.0, 0, 0], [0.0, 0, 0], [1.05, 0, 0]])
    vel = np.array([[1.0, 0, 0], [0, 0, 0], [0, 0, 0]])
    st = State(pos, vel, np.full(3, 0.5), np.ones(3))
    eng = Engine(st, cube(e=0.5, guard=CollapseGuard(tc)), 3.0, record_events=True)
    eng.step()
    ev = eng.events()
    out = eng.state()
    guarded = int(eng.totals[K.S_GUARDED])
    if tc == 1.0:
        assert len(ev) == 3
        assert guarded == 2  # impacts 2 and 3, counted
        assert np.allclose(out.vel[:, 0], want, atol=1e-12)
    else:
        assert guarded == 0
        # e = 0.5 throughout: momentum 1 is conserved, kinetic energy is lost
        assert out.momentum()[0] == pytest.approx(1.0, rel=1e-12)
        assert out.vel[2, 0] == pytest.approx(0.5625, rel=1e-12)  # 0.75 * (1 + e) / 2


def test_collapse_without_guard_stops_with_diagnosis():
    """A grain dropped on the floor with e < 1 and no guard bounces infinitely
    often in finite time: the step is refused, the state stays at the last step."""
    from lockgraph.domains import Dish
    from lockgraph.forces import Gravity

    ph = Physics(Dish(0.01), (Gravity(9.81),), Constant(0.5), None)
    st = State([[0.0, 0.0, 0.0012]], [[0, 0, 0]], [0.001], [1.0])
    sim = Simulation(st, ph, dt=0.005, collapse_limit=2000)
    with pytest.raises(InelasticCollapseError, match=r"inelastic collapse.*particle 0.*collapse guard"):
        sim.run(100)
    before = sim.state
    assert before.time > 0  # some steps completed
    # the failed step left no trace: running it again fails identically
    with pytest.raises(InelasticCollapseError):
        sim.run(1)
    after = sim.state
    assert np.array_equal(before.pos, after.pos) and np.array_equal(before.vel, after.vel)
    assert before.time == after.time and np.array_equal(before.ncoll, after.ncoll)


def test_guard_prevents_collapse():
    from lockgraph.domains import Dish
    from lockgraph.forces import Gravity

    ph = Physics(Dish(0.01), (Gravity(9.81),), Constant(0.5), CollapseGuard(1e-4))
    st = State([[0.0, 0.0, 0.0012]], [[0, 0, 0]], [0.001], [1.0])
    sim = Simulation(st, ph, dt=0.005)
    sim.run(100)
    s = sim.state
    assert s.pos[0, 2] >= 0.001 - 1e-15
    # resting: hops of at most ~ (g tc / 2)^2 / (2 g) above contact
    assert s.pos[0, 2] - 0.001 < 1e-6


def test_dish_late_state_is_at_rest():
    sc = scenarios.load("dish", "late", n=300, params={"cylinder_radius": 0.005})
    speed = np.sqrt((sc.state.vel ** 2).sum(1))
    assert speed.max() < sc.params["settle_speed"]
    assert np.all(sc.state.pos[:, 2] >= sc.state.radius * (1 - 1e-12))


def test_guard_makes_a_resting_bed_elastic_at_a_cost_growing_as_tc_shrinks():
    """Where the collapse guard breaks down (README, "Where methods fail").  In a
    settled bed each grain is always within tc of its last impact, so the guard
    makes (nearly) every impact elastic: the bed sheds energy only at the walls,
    and its grains keep colliding some 20 times per tc window, so a resting bed
    costs more the smaller (more accurate) tc is.  This is why the settling
    dish's last tenth of a second takes most of lockgraph's time against DEM
    codes, whose cost per step does not depend on how long contacts last."""
    sc = scenarios.load("dish", "late", n=400, params={
        "cylinder_radius": 0.005, "dt": 0.0005, "spacing": 1.2, "drop_height": 0.0003})
    steps = 4
    rate = {}
    for tc in (1e-4, 1e-5):
        sim = Simulation(sc.state, dataclasses.replace(sc.physics, guard=CollapseGuard(tc)),
                         dt=sc.dt)
        sim.run(steps)
        s = sim.stats
        # measured 0.9997-1.0000 (10 steps, tc 1e-4 to 1e-5): a bed where even 1 %
        # of impacts dissipated would not show this breakdown
        assert s["guarded_impacts"] > 0.99 * s["pair_collisions"]
        rate[tc] = s["pair_collisions"] / (400 * steps * sc.dt)  # per grain per second
    # measured 7.4x for the 10x smaller tc (22 -> 16 impacts per grain per tc
    # window); more than 4x: the cost grows at least as tc^-0.6
    assert rate[1e-5] > 4 * rate[1e-4]


@pytest.mark.parametrize("speed,elastic", [(0.009, True), (0.011, False)])
def test_velocity_guard_makes_slow_impacts_elastic(speed, elastic):
    """Head-on, equal masses: an impact slower than v_min = 0.01 m/s is elastic
    (the spheres swap velocities) and counted as guarded; a faster one has e."""
    st = State([[-1.0, 0, 0], [0.5, 0, 0]], [[speed, 0, 0], [0, 0, 0]], np.full(2, 0.5),
               np.ones(2))
    eng = Engine(st, cube(e=0.5, guard=VelocityGuard(0.01)), 500.0)
    eng.step()
    v = eng.state().vel[:, 0]
    e = 1.0 if elastic else 0.5
    assert v == pytest.approx([0.5 * speed * (1 - e), 0.5 * speed * (1 + e)], rel=1e-12)
    assert int(eng.totals[K.S_GUARDED]) == (1 if elastic else 0)
    assert int(eng.totals[K.S_PAIR]) == 1


@pytest.mark.parametrize("speed,e", [
    # below v_min = 0.01: e = 1 - (1 - 0.5) (0.005 / 0.01)^2 = 0.875
    (0.005, 0.875),
    # above v_min the law's e
    (0.011, 0.5)])
def test_soft_velocity_guard_softens_slow_impacts(speed, e):
    """Head-on, equal masses, the soft guard (exponent 2): restitution rises
    from the law's e at v_min to 1 as the impact speed goes to zero."""
    st = State([[-1.0, 0, 0], [0.5, 0, 0]], [[speed, 0, 0], [0, 0, 0]], np.full(2, 0.5),
               np.ones(2))
    eng = Engine(st, cube(e=0.5, guard=VelocityGuard(0.01, exponent=2.0)), 500.0)
    eng.step()
    v = eng.state().vel[:, 0]
    assert v == pytest.approx([0.5 * speed * (1 - e), 0.5 * speed * (1 + e)], rel=1e-12)
    assert int(eng.totals[K.S_GUARDED]) == (1 if speed < 0.01 else 0)


def test_soft_velocity_guard_damps_a_floor_bounce_without_collapse():
    """A grain dropped on the floor, e = 0.5, soft guard (v_min = 1 cm/s,
    exponent 2): below v_min each bounce keeps 1 - 0.5 (v / v_min)^2 of its
    speed, so v falls as ~1/t — the hop is damped (unlike the hard guard's) —
    while the bounces' durations 2 v / g sum to a divergent series: no Zeno
    sequence, the bounce count grows as ~t^2.  The engine's bounce count and
    last hop speed equal this recursion's."""
    from lockgraph.domains import Dish
    from lockgraph.forces import Gravity

    v_min, e, g, rad, h0 = 0.01, 0.5, 9.81, 0.001, 0.0012
    ph = Physics(Dish(0.01), (Gravity(g),), Constant(e), VelocityGuard(v_min, exponent=2.0))
    sim = Simulation(State([[0.0, 0.0, h0]], [[0, 0, 0]], [rad], [1.0]), ph, dt=0.005,
                     collapse_limit=5000)
    steps = 60
    sim.run(steps)
    t_end = steps * 0.005
    # the recursion: impact speeds v_k at times t_k
    v = np.sqrt(2 * g * (h0 - rad))
    t = np.sqrt(2 * (h0 - rad) / g)
    bounces = 0
    while t < t_end:
        bounces += 1
        v *= e if v >= v_min else 1 - (1 - e) * (v / v_min) ** 2
        t += 2 * v / g
    assert abs(sim.stats["wall_collisions"] - bounces) <= 1  # the last may straddle t_end
    s = sim.state
    energy = 0.5 * s.vel[0, 2] ** 2 + g * (s.pos[0, 2] - rad)  # = v^2 / 2 of the hop
    assert np.sqrt(2 * energy) == pytest.approx(v, rel=1e-3)
    # damped ~ as 1/t: 2 v_min^2 / ((1 - e) g t) = 1.4e-4 m/s at t = 0.3 s (the hard
    # guard leaves a hop of at least e v_min = 5e-3 m/s)
    assert v < 0.02 * v_min
    assert bounces > 1000  # ... at a cost: ~ (1 - e) g^2 t^2 / (8 v_min^2) bounces


def test_velocity_guard_prevents_collapse_on_the_floor():
    """A grain dropped on the floor with e = 0.5: its bounces lose speed until
    they are slower than v_min, then stay elastic — no Zeno sequence, and it
    keeps hopping at most v_min^2 / (2 g) high, at least e v_min fast."""
    from lockgraph.domains import Dish
    from lockgraph.forces import Gravity

    v_min = 0.01
    ph = Physics(Dish(0.01), (Gravity(9.81),), Constant(0.5), VelocityGuard(v_min))
    st = State([[0.0, 0.0, 0.0012]], [[0, 0, 0]], [0.001], [1.0])
    sim = Simulation(st, ph, dt=0.005, collapse_limit=2000)
    sim.run(100)
    s = sim.state
    assert s.pos[0, 2] >= 0.001 - 1e-15
    # mechanical energy above contact: a hop below v_min, at least e * v_min
    energy = 0.5 * s.vel[0, 2] ** 2 + 9.81 * (s.pos[0, 2] - 0.001)
    assert 0.5 * (0.5 * v_min) ** 2 * (1 - 1e-9) <= energy < 0.5 * v_min ** 2
    assert sim.stats["max_collisions_per_step"] < 100  # hops of >= 2 e v_min / g = 1 ms


def test_scene_declares_the_velocity_guard(tmp_path):
    from lockgraph.errors import ScenarioError

    text = open(scenarios.find("dish")).read()
    assert "collapse_guard = true" in text
    path = tmp_path / "dish_v.toml"
    path.write_text(text.replace("collapse_guard = true", 'collapse_guard = "velocity"')
                    .replace("tc = 1.0e-4", "v_guard = 0.01"))
    sc = scenarios.load(str(path), "early", n=50)
    assert sc.physics.guard == VelocityGuard(0.01)
    # the soft guard: an optional exponent
    soft = text.replace("collapse_guard = true", 'collapse_guard = "velocity"').replace(
        "tc = 1.0e-4", "v_guard = 0.01\nv_guard_exponent = 2")
    path.write_text(soft)
    assert scenarios.load(str(path), "early", n=50).physics.guard == VelocityGuard(0.01, 2.0)
    path.write_text(soft.replace("v_guard_exponent = 2", "v_guard_exponent = -2"))
    with pytest.raises(ScenarioError, match="v_guard_exponent"):
        scenarios.load(str(path), "early", n=50)
    path.write_text(text.replace("tc = 1.0e-4", "tc = 1.0e-4\nv_guard_exponent = 2"))
    with pytest.raises(ScenarioError, match="v_guard_exponent"):  # not the TC model's
        scenarios.load(str(path), "early", n=50)
    for bad in (float("nan"), 0.5, -1.0):  # below 1 the floor's bounces would collapse
        with pytest.raises(InputError, match="collapse_guard.exponent"):
            VelocityGuard(0.01, bad)
    path.write_text(text.replace("collapse_guard = true", 'collapse_guard = "speed"'))
    with pytest.raises(ScenarioError, match="physics.collapse_guard"):
        scenarios.load(str(path), "early", n=50)
    # the velocity guard's parameter without it is an unknown key
    path.write_text(text.replace("tc = 1.0e-4", "tc = 1.0e-4\nv_guard = 0.01"))
    with pytest.raises(ScenarioError, match="v_guard"):
        scenarios.load(str(path), "early", n=50)
