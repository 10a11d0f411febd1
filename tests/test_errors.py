"""Every kind of bad input is refused with an error that names the field."""
import math

import numpy as np
import pytest

from lockgraph import scenarios
from lockgraph.errors import InputError, ScenarioError
from lockgraph.simulation import Simulation
from lockgraph.state import State

from .helpers import cube, dish, sheet


def good():
    return dict(pos=[[0.0, 0, 0], [2.0, 0, 0]], vel=[[0.0, 0, 0], [0, 0, 0]],
                radius=[0.5, 0.5], mass=[1.0, 1.0])


@pytest.mark.parametrize("field,value", [
    ("pos", [[np.nan, 0, 0], [2.0, 0, 0]]),
    ("pos", [[np.inf, 0, 0], [2.0, 0, 0]]),
    ("vel", [[0.0, -np.inf, 0], [0, 0, 0]]),
    ("vel", [[0.0, 0, 0], [0, 0, np.nan]]),
    ("radius", [0.5, np.nan]),
    ("mass", [np.inf, 1.0]),
])
def test_non_finite(field, value):
    kw = good()
    kw[field] = value
    with pytest.raises(InputError, match=rf"state\.{field}.*non-finite"):
        State(**kw)


@pytest.mark.parametrize("value", [0.0, -0.1])
def test_radius_not_positive(value):
    kw = good()
    kw["radius"] = [0.5, value]
    with pytest.raises(InputError, match=r"state\.radius: particle 1"):
        State(**kw)


@pytest.mark.parametrize("value", [0.0, -2.0])
def test_mass_not_positive(value):
    kw = good()
    kw["mass"] = [value, 1.0]
    with pytest.raises(InputError, match=r"state\.mass: particle 0"):
        State(**kw)


def test_shapes():
    kw = good()
    kw["vel"] = [[0.0, 0, 0]]
    with pytest.raises(InputError, match=r"state\.vel.*shape"):
        State(**kw)


def test_overlapping_particles():
    kw = good()
    kw["pos"] = [[0.0, 0, 0], [0.9, 0, 0]]
    with pytest.raises(InputError, match=r"state\.pos: particles 0 and 1 overlap"):
        Simulation(State(**kw), cube(), dt=0.1)


def test_overlap_through_periodic_image():
    kw = good()
    kw["pos"] = [[-29.8, 0, 0], [29.8, 0, 0]]  # 0.4 apart across the boundary of a 60 box
    with pytest.raises(InputError, match=r"overlap"):
        Simulation(State(**kw), cube(60.0), dt=0.1)


@pytest.mark.parametrize("physics,pos", [
    (cube(10.0), [[5.0, 0, 0], [0, 0, 0]]),          # x = L/2 is outside [-L/2, L/2)
    (sheet(20.0, 20.0), [[0.0, 11.0, 0], [0, 0, 0]]),  # |y| > ly / 2
    (dish(0.01), [[0.0095, 0, 0.01], [0, 0, 0.01]]),  # through the cylinder wall
    (dish(0.01), [[0.0, 0, 0.0003], [0, 0, 0.01]]),   # through the floor
])
def test_outside_domain(physics, pos):
    r = 0.001 if physics.domain.describe()["type"] == "dish" else 0.5
    st = State(pos, [[0, 0, 0], [0, 0, 0]], [r, r], [1.0, 1.0])
    with pytest.raises(InputError, match=r"state\.pos: particle 0"):
        Simulation(st, physics, dt=0.1)


@pytest.mark.parametrize("dt", [0.0, -1.0, math.nan, math.inf])
def test_bad_dt(dt):
    with pytest.raises(InputError, match=r"^dt: "):
        Simulation(State(**good()), cube(), dt=dt)


def test_bad_options():
    st = State(**good())
    with pytest.raises(InputError, match=r"^lock: unknown value 'tree'"):
        Simulation(st, cube(), dt=0.1, lock="tree")
    with pytest.raises(InputError, match=r"^policy: "):
        Simulation(st, cube(), dt=0.1, policy="fast")
    with pytest.raises(InputError, match=r"^threads: "):
        Simulation(st, cube(), dt=0.1, threads=0)
    with pytest.raises(InputError, match=r"^scale: "):
        Simulation(st, cube(), dt=0.1, scale=-1)
    with pytest.raises(InputError, match=r"^steps: "):
        Simulation(st, cube(), dt=0.1).run(-1)


def test_unknown_scene():
    with pytest.raises(ScenarioError, match=r"unknown scene 'galaxy'"):
        scenarios.load("galaxy")


def test_unknown_param_override():
    with pytest.raises(ScenarioError, match=r"params\.etta: unknown scenario key"):
        scenarios.load("gas", params={"etta": 0.3})
    with pytest.raises(ScenarioError, match=r"params\.moonlet_radius: unknown scenario key"):
        scenarios.load("ring", params={"moonlet_radius": 20.0})


def test_bad_param_values():
    with pytest.raises(ScenarioError, match=r"params\.dt: must be > 0"):
        scenarios.load("gas", dt=0.0)
    with pytest.raises(ScenarioError, match=r"params\.n: must be >= 1"):
        scenarios.load("gas", n=0)
    with pytest.raises(ScenarioError, match=r"params\.eta: must be a number"):
        scenarios.load("gas", params={"eta": "dense"})
    with pytest.raises(ScenarioError, match=r"params\.tau: must be finite"):
        scenarios.load("ring", params={"tau": math.nan})


SCENE = """
name = "tiny"
generator = "fcc_gas"
late = "time"
{extra_top}
[physics]
domain = "periodic_cube"
restitution = "constant"
{extra_physics}
[params]
n = 32
seed = 1
eta = 0.3
diameter = 1.0
mass = 1.0
temperature = 1.0
e = 1.0
dt = 0.05
late_time = 1.0
{extra_params}
"""


@pytest.mark.parametrize("extra,match", [
    (dict(extra_top='colour = "red"'), r"tiny\.toml: colour: unknown scenario key"),
    (dict(extra_physics='gravity = 9.81'), r"physics\.gravity: unknown scenario key"),
    (dict(extra_params='g = 9.81'), r"params\.g: unknown scenario key: nothing in this scene uses it"),
    (dict(extra_params='v_c = 1e-4'), r"params\.v_c: unknown scenario key"),
])
def test_unknown_keys_in_scene_file(tmp_path, extra, match):
    fill = dict(extra_top="", extra_physics="", extra_params="")
    fill.update(extra)
    path = tmp_path / "tiny.toml"
    path.write_text(SCENE.format(**fill))
    with pytest.raises(ScenarioError, match=match):
        scenarios.load(str(path))


def test_missing_key_in_scene_file(tmp_path):
    text = SCENE.format(extra_top="", extra_physics="", extra_params="").replace("\ne = 1.0\n", "\n")
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"params\.e: missing"):
        scenarios.load(str(path))


def test_physics_needs_its_parameters(tmp_path):
    text = SCENE.format(extra_top="", extra_physics="", extra_params="")
    text = text.replace('restitution = "constant"', 'restitution = "bridges"')
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"params\.e: unknown scenario key"):
        scenarios.load(str(path))


@pytest.mark.parametrize("threads", [1, 2])
def test_step_too_large_leaves_the_state(threads):
    """Two reaches that could span half the periodic box: the step is refused
    (naming dt), the state is the step start's bit for bit, and the storage
    order the particles' own (the tree's re-sort runs in the same phase as
    the reaches, before they are checked)."""
    from lockgraph.engine import Engine
    from lockgraph.errors import StepTooLargeError
    g = (np.arange(4) - 1.5) * 2.5
    pos = np.array([[x, y, z] for x in g for y in g for z in g])
    vel = np.random.default_rng(0).normal(0.0, 0.1, pos.shape)
    vel[[5, 40]] = [[20.0, 0, 0], [0, -20.0, 0]]
    st = State(pos, vel, np.full(len(pos), 0.5), np.ones(len(pos)))
    e = Engine(st.copy(), cube(10.0), 1.0, threads=threads)
    for _ in range(2):
        with pytest.raises(StepTooLargeError, match=r"dt=1\.0: two particles' reaches"):
            e.step()
        after = e.state()
        assert np.array_equal(after.pos, st.pos) and np.array_equal(after.vel, st.vel)
        assert np.array_equal(e.perm, np.arange(len(pos)))
    e.close()
