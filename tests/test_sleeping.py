"""Sleeping grains (``VelocityGuard(..., v_sleep=...)``): falling asleep on a
support, immovable against slow impacts, woken by fast ones, kept through
files, rolled back with a failed step, and bitwise the same on threads."""
import dataclasses

import numpy as np
import pytest

from lockgraph import kernels as K
from lockgraph import scenarios
from lockgraph.domains import Dish, PeriodicCube
from lockgraph.engine import Engine
from lockgraph.errors import InelasticCollapseError, InputError, ScenarioError
from lockgraph.forces import Gravity
from lockgraph.physics import Physics
from lockgraph.restitution import Constant, VelocityGuard
from lockgraph.simulation import Simulation
from lockgraph.state import State

G = 9.81
R = 2.5e-4
E = 0.5


def dish(v_sleep, e=E, v_min=0.02, t_sleep=0.0):
    return Physics(Dish(0.01), (Gravity(G),), Constant(e),
                   VelocityGuard(v_min, 2.0, v_sleep, t_sleep))


def test_a_dropped_grain_falls_asleep_on_the_floor_and_stays_put():
    """Dropped 1 mm, it bounces (soft guard) until a bounce leaves it slower
    than v_sleep, then sleeps from that step's end: at rest, exactly, on or
    just above the floor (a hop slower than v_sleep rises at most
    v_sleep^2 / 2 g), and it stays where it fell asleep to the bit."""
    v_sleep = 5e-3
    sim = Simulation(State([[0.0, 0.0, R + 1e-3]], [[0, 0, 0]], [R], [1e-7]),
                     dish(v_sleep), dt=1e-4)
    sim.run(600)
    s = sim.state
    assert s.asleep.tolist() == [True]
    assert s.vel.tolist() == [[0.0, 0.0, 0.0]]
    assert R <= s.pos[0, 2] <= R + v_sleep ** 2 / (2 * G)
    before = sim.stats["collisions"]
    sim.run(100)
    assert sim.state.pos.tobytes() == s.pos.tobytes()  # no drift, no events
    assert sim.stats["collisions"] == before
    assert sim.stats["asleep"] == 1


def test_without_sleeping_the_grain_keeps_bouncing():
    sim = Simulation(State([[0.0, 0.0, R + 1e-3]], [[0, 0, 0]], [R], [1e-7]),
                     dish(0.0), dt=1e-4)
    sim.run(700)
    assert not sim.state.asleep.any()
    assert sim.stats["asleep"] == 0
    assert np.abs(sim.state.vel).max() > 0.0


def dropped(t_sleep, steps=600):
    """The grain of the test above, with ``t_sleep``: its states step by step."""
    sim = Simulation(State([[0.0, 0.0, R + 1e-3]], [[0, 0, 0]], [R], [1e-7]),
                     dish(5e-3, t_sleep=t_sleep), dt=1e-4)
    out = []
    for _ in range(steps):
        sim.run(1)
        out.append(sim.state)
    return out


def test_a_grain_waits_t_sleep_before_it_sleeps():
    """With ``t_sleep``: a grain is drowsy from its first slow bounce on, its
    state's t_last the time of that bounce (-inf while awake), and it falls
    asleep at the first step end at least t_sleep later, not before; with
    t_sleep = 0 at the end of that bounce's step, as without it."""
    t_sleep = 2e-3
    states = dropped(t_sleep)
    first = next(k for k, s in enumerate(states) if np.isfinite(s.t_last[0]))
    since = states[first].t_last[0]
    assert states[first - 1].time < since <= states[first].time
    asleep = next(k for k, s in enumerate(states) if s.asleep[0])
    # slow bounces all the way (a bounce slower than v_sleep stays slower): no reset
    assert all(s.t_last[0] == since for s in states[first:asleep])
    assert not any(s.asleep[0] for s in states[:asleep])
    assert states[asleep].time - 1e-4 < since + t_sleep <= states[asleep].time
    assert states[asleep].vel.tolist() == [[0.0, 0.0, 0.0]]
    assert states[asleep].t_last[0] == -np.inf
    no_wait = dropped(0.0)
    assert next(k for k, s in enumerate(no_wait) if s.asleep[0]) == first
    assert all(s.t_last[0] == -np.inf for s in no_wait)


def test_a_drowsy_grain_is_kept_in_files_and_goes_on_bitwise(tmp_path):
    """A drowsy grain's time survives a file, so a run saved and resumed
    while it waits is bitwise the run that never stopped."""
    ph = dish(5e-3, t_sleep=2e-3)
    start = State([[0.0, 0.0, R + 1e-3]], [[0, 0, 0]], [R], [1e-7])
    whole = Simulation(start, ph, dt=1e-4)
    whole.run(600)
    states = dropped(2e-3, 600)
    k = next(k for k, s in enumerate(states) if np.isfinite(s.t_last[0])) + 3
    assert np.isfinite(states[k].t_last[0]) and not states[k].asleep[0]
    states[k].save(tmp_path / "drowsy.npz")
    resumed = Simulation(State.load(tmp_path / "drowsy.npz"), ph, dt=1e-4)
    resumed.run(600 - (k + 1))
    assert resumed.state.sha256() == whole.state.sha256()
    assert resumed.state.asleep.tolist() == [True]


def test_a_drowsy_grain_that_speeds_up_wakes():
    """A drowsy grain faster than v_sleep at a step end is awake again (with
    t_sleep the wait and that check stand in for the support): here a slow
    bounce in the air on a grain that then falls away from it."""
    v_sleep, t_sleep = 5e-3, 2e-3
    # two grains side by side 10 radii up, touching slowly: both drowsy, then falling
    st = State([[0.0, 0.0, 10 * R], [2 * R + 1e-9, 0.0, 10 * R]],
               [[1e-3, 0, 0], [-1e-3, 0, 0]], [R, R], [1e-7, 1e-7])
    sim = Simulation(st, dish(v_sleep, t_sleep=t_sleep), dt=1e-4)
    sim.run(1)
    assert np.isfinite(sim.state.t_last).all()  # drowsy after their slow impact
    sim.run(int(v_sleep / G / 1e-4) + 1)  # falling: faster than v_sleep
    assert (sim.state.t_last == -np.inf).all() and not sim.state.asleep.any()


DT = 1e-4
V_SLEEP = 5e-3


def oblique(normal_speed, side_speed):
    """A sleeper (where a support left it, 9 radii above the floor) and a grain
    0.1 um from touching it at 45 degrees above, approaching along the line
    of centres at ``normal_speed`` and moving sideways (y) at ``side_speed``:
    they meet early in the first step, and nothing else happens in it."""
    n0 = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)
    s0 = np.array([0.0, 0.0, 10 * R])
    p0 = s0 + (2 * R + 1e-7) * n0
    v0 = -normal_speed * n0 + np.array([0.0, side_speed, 0.0])
    st = State([s0, p0], [[0, 0, 0], v0], [R, R], [1e-7, 1e-7], asleep=[True, False])
    eng = Engine(st, dish(V_SLEEP), DT, record_events=True)
    eng.step()
    ev = eng.events()
    assert len(ev) == 1 and {int(ev[0]["a"]), int(ev[0]["b"])} == {0, 1}
    t = float(ev[0]["t"])
    # at the impact: the grain's lab path under gravity, the sleeper's rising
    # at g dt / 2 in the free-falling frame
    p = p0 + v0 * t - np.array([0, 0, 0.5 * G * t * t])
    s = s0 + np.array([0, 0, 0.5 * G * DT * t - 0.5 * G * t * t])
    v = v0 - np.array([0, 0, G * t])
    vs = np.array([0, 0, 0.5 * G * DT - G * t])
    n = (p - s) / np.linalg.norm(p - s)
    vn = float(np.dot(v - vs, n))
    return eng, st, v, vs, n, vn, t


def soft_e(vn):
    return 1 - (1 - E) * (vn / 0.02) ** 2 if vn < 0.02 else E


def test_a_slow_impact_finds_a_sleeper_immovable():
    """Normal approach 4 mm/s < v_sleep: the sleeper keeps its place to the bit
    and gets no velocity; the grain bounces off it as off a wall moving with
    the sleeper, v' = v - (1 + e) v_n n, e the soft guard's at v_n.  Moving
    sideways at 6 mm/s > v_sleep it stays awake."""
    eng, st, v, vs, n, vn, t = oblique(4e-3, 6e-3)
    assert -vn < V_SLEEP
    after = eng.state()
    assert after.pos[0].tobytes() == st.pos[0].tobytes()
    assert after.vel[0].tolist() == [0.0, 0.0, 0.0]
    assert after.asleep.tolist() == [True, False]
    want = v - (1 + soft_e(-vn)) * vn * n
    # sideways the grain keeps its post-impact velocity to the step end
    assert after.vel[1, :2] == pytest.approx(want[:2], rel=1e-9, abs=1e-15)
    assert after.vel[1, 2] == pytest.approx(want[2] - G * (DT - t), rel=1e-9)
    eng.close()


def test_a_slow_impact_puts_the_mover_to_sleep_too():
    """Straight along the line of centres at 4 mm/s: after the bounce the grain
    is slower than v_sleep relative to the sleeper, so it sleeps from the step
    end on, where it then is, at rest."""
    eng, st, v, vs, n, vn, t = oblique(4e-3, 0.0)
    after = eng.state()
    assert after.asleep.tolist() == [True, True]
    assert after.vel.tolist() == [[0.0] * 3, [0.0] * 3]
    gap = np.linalg.norm(after.pos[1] - after.pos[0]) - 2 * R
    assert 0.0 <= gap < V_SLEEP * DT
    eng.step()  # both asleep: nothing happens, nothing moves
    assert len(eng.events()) == 1
    assert eng.state().pos.tobytes() == after.pos.tobytes()
    eng.close()


def test_a_fast_impact_wakes_the_sleeper_and_is_a_two_body_impact():
    """Normal approach 5 cm/s > v_sleep: the sleeper wakes and the impact is an
    ordinary one between equal masses: each gets half of (1 + e) v_n along
    n, and the horizontal momentum is conserved."""
    eng, st, v, vs, n, vn, t = oblique(0.05, 0.0)
    assert eng.totals[K.S_WOKEN] == 1
    after = eng.state()
    assert after.asleep.tolist() == [False, False]
    want_mover = v - 0.5 * (1 + E) * vn * n
    want_sleeper = vs + 0.5 * (1 + E) * vn * n
    assert after.vel[1, :2] == pytest.approx(want_mover[:2], rel=1e-9, abs=1e-15)
    assert after.vel[0, :2] == pytest.approx(want_sleeper[:2], rel=1e-9, abs=1e-15)
    assert after.vel[0, 0] + after.vel[1, 0] == pytest.approx(v[0], rel=1e-12)
    eng.close()


@pytest.mark.parametrize("height,wakes", [(0.0, True), (4 * R, False)],
                         ids=["on-the-floor", "in-the-air"])
def test_a_slow_impact_from_below_wakes_a_sleeper_only_from_the_floor(height, wakes):
    """A grain moving straight up at 3 mm/s (< v_sleep) into a sleeper just
    above it.  From the floor the sleeper wakes: held on its straight frame
    path it comes back down by up to g dt^2 / 8 in a step and, immovable,
    would squeeze the grain against the floor without end (measured before
    this rule: an inelastic collapse in a settling dish).  In the air it
    stays put."""
    z = R + height
    st = State([[0.0, 0.0, z + 2 * R + 1e-9], [0.0, 0.0, z]], [[0, 0, 0], [0, 0, 3e-3]],
               [R, R], [1e-7, 1e-7], asleep=[True, False])
    eng = Engine(st, dish(V_SLEEP), DT, record_events=True)
    eng.step()
    assert int(eng.totals[K.S_WOKEN]) == int(wakes)
    after = eng.state()
    if not wakes:
        assert after.pos[0].tobytes() == st.pos[0].tobytes()
        assert after.asleep[0]
    else:
        assert not after.asleep[0]
    eng.close()


def test_sleeping_needs_gravity_and_a_dish_and_a_valid_speed():
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(InputError, match="collapse_guard.v_sleep"):
            VelocityGuard(0.02, 2.0, bad)
    with pytest.raises(InputError, match="collapse_guard.v_sleep"):
        Physics(PeriodicCube(1.0), (), Constant(0.5), VelocityGuard(0.02, 2.0, 1e-3))
    with pytest.raises(InputError, match="collapse_guard.v_sleep"):
        Physics(Dish(0.01), (), Constant(0.5), VelocityGuard(0.02, 2.0, 1e-3))
    for bad in (-1e-3, float("nan"), float("inf")):
        with pytest.raises(InputError, match="collapse_guard.t_sleep"):
            VelocityGuard(0.02, 2.0, 1e-3, bad)
    with pytest.raises(InputError, match="collapse_guard.t_sleep.*v_sleep"):
        VelocityGuard(0.02, 2.0, 0.0, 1e-3)


def test_an_asleep_grain_must_be_at_rest():
    with pytest.raises(InputError, match="state.asleep"):
        State([[0.0, 0.0, R]], [[0, 0, 1e-3]], [R], [1.0], asleep=[True])
    with pytest.raises(InputError, match="state.asleep"):
        State([[0.0, 0.0, R]], [[0, 0, 0]], [R], [1.0], asleep=[True, False])


def test_asleep_flags_survive_files(tmp_path):
    st = State([[0.0, 0.0, R], [0.0, 0.0, 4 * R]], [[0, 0, 0], [0, 0, -1e-3]], [R, R],
               [1.0, 1.0], asleep=[True, False])
    st.save(tmp_path / "s.npz")
    back = State.load(tmp_path / "s.npz")
    assert back.asleep.tolist() == [True, False]
    assert back.copy().asleep.tolist() == [True, False]
    assert State.from_ase(st.to_ase()).asleep.tolist() == [True, False]


def settling_dish(n=400, v_sleep=1e-2, t_sleep=0.0):
    sc = scenarios.load("dish", "early", n=n, params={"cylinder_radius": 0.005,
                                                      "dt": 0.0005, "spacing": 1.2,
                                                      "drop_height": 0.0003})
    sc.physics = dataclasses.replace(sc.physics,
                                     guard=VelocityGuard(0.02, 2.0, v_sleep, t_sleep))
    return sc


def test_a_settling_dish_goes_to_sleep_without_overlaps():
    """400 grains dropped into the dish: most fall asleep, none overlaps
    another or the floor beyond rounding (the engine's own check), and the
    bed costs far fewer collisions than without sleeping."""
    sc = settling_dish()
    sim = Simulation(sc.state, sc.physics, dt=sc.dt)
    sim.run(300)
    s = sim.state
    assert s.asleep.mean() > 0.8
    assert sim.stats["max_overlap"] < 1e-9
    assert (s.pos[:, 2] - s.radius).min() > -1e-12
    assert sim.stats["woken"] > 0
    awake = Simulation(sc.state, dataclasses.replace(
        sc.physics, guard=VelocityGuard(0.02, 2.0)), dt=sc.dt)
    awake.run(300)
    assert sim.stats["collisions"] < 0.5 * awake.stats["collisions"]


@pytest.mark.parametrize("lock,scale,t_sleep", [("graph", 1.2, 0.0), ("graph", 4.0, 0.0),
                                               ("grid", 4.0, 0.0), ("graph", 1.2, 2e-3)])
def test_sleeping_is_exact_on_threads(lock, scale, t_sleep):
    """Falling asleep, waking and immovable sleepers are events like any other:
    two threads under the exact policy give the sequential run's bits and
    sleep flags (and, waiting t_sleep, drowsy times)."""
    sc = settling_dish(t_sleep=t_sleep)
    steps = 240 if t_sleep else 120  # waiting, the first grains sleep after 0.07 s
    ref = Simulation(sc.state, sc.physics, dt=sc.dt)
    ref.run(steps)
    sim = Simulation(sc.state, sc.physics, dt=sc.dt, threads=2, lock=lock, scale=scale)
    try:
        sim.run(steps)
        assert ref.stats["woken"] > 0 and ref.stats["asleep"] > 0
        assert sim.state.sha256() == ref.state.sha256()
        assert sim.state.asleep.tolist() == ref.state.asleep.tolist()
        assert sim.state.t_last.tobytes() == ref.state.t_last.tobytes()
    finally:
        sim._engine.close()


def test_a_failed_step_leaves_sleepers_as_they_were():
    """A step that stops (here: the collision cap) is rolled back: every
    grain's position, velocity and sleep flag are the last completed step's."""
    sc = settling_dish()
    sim = Simulation(sc.state, sc.physics, dt=sc.dt)
    sim.run(150)
    before = sim.state
    assert before.asleep.any()
    sim._engine.collapse_limit = 0
    sim._engine.ipar[K.I_CAP] = 0
    with pytest.raises(InelasticCollapseError):
        sim.run(1)
    after = sim.state
    assert after.sha256() == before.sha256()
    assert after.asleep.tolist() == before.asleep.tolist()


def test_scene_declares_sleeping(tmp_path):
    text = open(scenarios.find("dish")).read()
    v = text.replace("collapse_guard = true", 'collapse_guard = "velocity"').replace(
        "tc = 1.0e-4", "v_guard = 0.02\nv_guard_exponent = 2\nv_sleep = 0.003")
    path = tmp_path / "dish_sleep.toml"
    path.write_text(v)
    sc = scenarios.load(str(path), "early", n=50)
    assert sc.physics.guard == VelocityGuard(0.02, 2.0, 0.003)
    path.write_text(v.replace("v_sleep = 0.003", "v_sleep = 0.003\nt_sleep = 0.002"))
    assert scenarios.load(str(path), "early", n=50).physics.guard == \
        VelocityGuard(0.02, 2.0, 0.003, 0.002)
    path.write_text(text.replace("tc = 1.0e-4", "tc = 1.0e-4\nv_sleep = 0.003"))
    with pytest.raises(ScenarioError, match="v_sleep"):  # not the TC model's
        scenarios.load(str(path), "early", n=50)
