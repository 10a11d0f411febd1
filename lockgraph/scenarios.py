"""Scenes: TOML files in ``scenarios/`` that declare exactly the physics they use.

A scene file has the top-level keys ``name``, ``description``, ``generator``
(how the early state is built), ``late`` (how the late state is made) and the
tables ``[physics]`` and ``[params]``.  Every parameter is used by the
generator, the physics, the step or the late recipe; a key that nothing uses,
or a missing one, is an error naming it.  Any parameter can be overridden::

    load("gas", n=4000, params={"eta": 0.40})

Late states are evolved by the engine from the early state, reproducibly, and
cached on disk keyed by every parameter and the engine version
(``$LOCKGRAPH_CACHE``, default ``~/.cache/lockgraph``).
"""
import hashlib
import json
import math
import os
import sys
import time as _time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .domains import Dish, PeriodicCube, ShearingSheet
from .errors import ScenarioError
from .forces import Gravity, Hill
from .generators import GENERATORS, add_marble
from .physics import Physics
from .restitution import Bridges, CollapseGuard, Constant, VelocityGuard
from .state import State

ENGINE_VERSION = "1"  # bump when a change alters trajectories: invalidates cached late states

TOP_KEYS = {"name", "description", "generator", "late", "physics", "params"}
PHYSICS_KEYS = {"domain", "forces", "restitution", "collapse_guard"}
DOMAINS = {"shearing_sheet": {"omega"}, "dish": {"cylinder_radius"}, "periodic_cube": set()}
FORCES = {"hill": {"omega"}, "gravity": {"g"}}
LAWS = {"constant": {"e"}, "bridges": {"v_c", "exponent"}}
# physics.collapse_guard: false, true (= "tc"), "tc" or "velocity", and the
# parameters each needs
GUARDS = {"tc": {"tc"}, "velocity": {"v_guard"}}
# and the parameters each may take (default: the hard velocity guard, exponent 0)
GUARD_OPTIONS = {"tc": set(), "velocity": {"v_guard_exponent", "v_sleep", "t_sleep"}}
LATE = {"orbits": {"late_orbits"}, "settle": {"settle_speed", "settle_time_max"},
        "time": {"late_time"}}
STEP_KEYS = {"dt"}
INT_KEYS = {"n", "seed"}


def scenario_dirs():
    """Where scene files are looked for: $LOCKGRAPH_SCENARIOS, the repository, the package."""
    dirs = []
    if os.environ.get("LOCKGRAPH_SCENARIOS"):
        dirs.append(Path(os.environ["LOCKGRAPH_SCENARIOS"]))
    here = Path(__file__).resolve().parent
    dirs += [here.parent / "scenarios", here / "_scenarios"]
    return [d for d in dirs if d.is_dir()]


def available():
    """Names of the scenes that can be loaded."""
    names = set()
    for d in scenario_dirs():
        names.update(p.stem for p in d.glob("*.toml"))
    return sorted(names)


def cache_dir():
    return Path(os.environ.get("LOCKGRAPH_CACHE", Path.home() / ".cache" / "lockgraph"))


@dataclass
class SceneFile:
    """A parsed and checked scene file."""
    name: str
    description: str
    generator: str
    late: str
    physics: dict
    params: dict
    path: Path

    def required(self):
        """Parameters this scene's physics, generator, step and late recipe use."""
        gen_req, gen_opt = GENERATORS[self.generator][1:]
        need = set(gen_req) | STEP_KEYS | LATE[self.late]
        opt = set(gen_opt)
        need |= DOMAINS[self.physics["domain"]]
        for f in self.physics["forces"]:
            need |= FORCES[f]
        need |= LAWS[self.physics["restitution"]]
        guard = guard_kind(self.physics)
        if guard is not None:
            need |= GUARDS[guard]
            opt |= GUARD_OPTIONS[guard]
        return need, opt


def find(name):
    """Path of the scene file for a scene name (or a path to a .toml file)."""
    p = Path(name)
    if p.suffix == ".toml" and p.is_file():
        return p
    for d in scenario_dirs():
        q = d / f"{name}.toml"
        if q.is_file():
            return q
    raise ScenarioError("scene", f"unknown scene {name!r}; available: {', '.join(available())}")


def read(name):
    """Parse and check a scene file.  Errors name the offending key."""
    path = find(name)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(str(path), f"not valid TOML: {exc}") from None
    where = path.name
    for k in doc:
        if k not in TOP_KEYS:
            raise ScenarioError(f"{where}: {k}", f"unknown scenario key; known: {sorted(TOP_KEYS)}")
    for k in ("name", "generator", "late", "physics", "params"):
        if k not in doc:
            raise ScenarioError(f"{where}: {k}", "missing")
    phys = dict(doc["physics"])
    for k in phys:
        if k not in PHYSICS_KEYS:
            raise ScenarioError(f"{where}: physics.{k}",
                                f"unknown scenario key; known: {sorted(PHYSICS_KEYS)}")
    phys.setdefault("forces", [])
    phys.setdefault("collapse_guard", False)
    _choice(where, "physics.domain", phys.get("domain"), DOMAINS)
    if not isinstance(phys["forces"], list):
        raise ScenarioError(f"{where}: physics.forces", "must be a list")
    for f in phys["forces"]:
        _choice(where, "physics.forces", f, FORCES)
    _choice(where, "physics.restitution", phys.get("restitution"), LAWS)
    if not isinstance(phys["collapse_guard"], bool) and phys["collapse_guard"] not in GUARDS:
        raise ScenarioError(f"{where}: physics.collapse_guard",
                            f"unknown value {phys['collapse_guard']!r}; true, false or one "
                            f"of {sorted(GUARDS)}")
    _choice(where, "generator", doc["generator"], GENERATORS)
    _choice(where, "late", doc["late"], LATE)
    scene = SceneFile(doc["name"], doc.get("description", ""), doc["generator"], doc["late"],
                      phys, dict(doc["params"]), path)
    need, opt = scene.required()
    for k in scene.params:
        if k not in need and k not in opt:
            raise ScenarioError(f"{where}: params.{k}", "unknown scenario key: nothing in this "
                                f"scene uses it (used: {sorted(need | opt)})")
    for k in sorted(need):
        if k not in scene.params:
            raise ScenarioError(f"{where}: params.{k}", "missing (the scene's physics needs it)")
    for k, v in scene.params.items():
        scene.params[k] = _check_value(f"{where}: params.{k}", k, v)
    return scene


def guard_kind(physics):
    """The collapse guard a scene's [physics] table declares: None, "tc" or "velocity"."""
    g = physics.get("collapse_guard", False)
    if g is False:
        return None
    return "tc" if g is True else g


def _choice(where, key, value, options):
    if value not in options:
        raise ScenarioError(f"{where}: {key}", f"unknown value {value!r}; one of {sorted(options)}")


def _check_value(field_name, key, value):
    if key in INT_KEYS:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ScenarioError(field_name, f"must be an integer, got {value!r}")
        if key == "n" and value < 1:
            raise ScenarioError(field_name, f"must be >= 1, got {value}")
        if key == "seed" and value < 0:
            raise ScenarioError(field_name, f"must be >= 0, got {value}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScenarioError(field_name, f"must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ScenarioError(field_name, f"must be finite, got {value!r}")
    if key != "size_slope" and value < 0:
        raise ScenarioError(field_name, f"must be >= 0, got {value!r}")
    if key in STEP_KEYS and value <= 0:
        raise ScenarioError(field_name, f"must be > 0, got {value!r}")
    return value


def parse_overrides(items):
    """``["eta=0.4", "n=100"]`` -> ``{"eta": 0.4, "n": 100}`` (values parsed as TOML)."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ScenarioError("--param", f"expected KEY=VALUE, got {item!r}")
        key, text = item.split("=", 1)
        key = key.strip()
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            raise ScenarioError(f"--param {key}", f"cannot parse value {text!r}") from None
        out[key] = value
    return out


def resolve_params(scene, n=None, seed=None, dt=None, params=None):
    """The scene's parameters with overrides applied and checked."""
    p = dict(scene.params)
    over = dict(params or {})
    for key, value in (("n", n), ("seed", seed), ("dt", dt)):
        if value is not None:
            over[key] = value
    need, opt = scene.required()
    for k, v in over.items():
        if k not in p:
            raise ScenarioError(f"params.{k}", f"unknown scenario key for scene {scene.name!r}; "
                                f"its keys: {sorted(p)}")
        p[k] = _check_value(f"params.{k}", k, v)
    return p


def build_physics(scene, p, geometry):
    ph = scene.physics
    dom = ph["domain"]
    if dom == "shearing_sheet":
        domain = ShearingSheet(geometry["lx"], geometry["ly"], p["omega"])
    elif dom == "dish":
        domain = Dish(p["cylinder_radius"])
    else:
        domain = PeriodicCube(geometry["length"])
    forces = []
    for f in ph["forces"]:
        forces.append(Hill(p["omega"]) if f == "hill" else Gravity(p["g"]))
    if ph["restitution"] == "constant":
        law = Constant(p["e"])
    else:
        law = Bridges(p["v_c"], p["exponent"])
    kind = guard_kind(ph)
    guard = (None if kind is None else CollapseGuard(p["tc"]) if kind == "tc"
             else VelocityGuard(p["v_guard"], p.get("v_guard_exponent", 0.0),
                           p.get("v_sleep", 0.0), p.get("t_sleep", 0.0)))
    return Physics(domain, tuple(forces), law, guard)


@dataclass
class Scenario:
    """A loaded scene: its state, the physics acting on it and the step length.

    name : scene name; which : "early" or "late"; params : every parameter
    (overrides applied); physics : Physics; state : State; dt : step (s).
    """
    name: str
    which: str
    params: dict
    physics: Physics
    state: State
    dt: float
    path: Path
    info: dict = field(default_factory=dict)

    def simulation(self, **options):
        from .simulation import Simulation
        return Simulation(self.state, self.physics, dt=self.dt, **options)


def load(name, state="early", n=None, seed=None, params=None, dt=None, progress=None,
         use_cache=True):
    """Load scene ``name`` in its ``early`` or ``late`` state.

    ``params`` overrides scene parameters; ``n``, ``seed`` and ``dt`` are
    shorthands for the parameters of those names.  ``progress`` (callable
    taking a message string) reports late-state generation.
    """
    if state not in ("early", "late"):
        raise ScenarioError("state", f"must be 'early' or 'late', got {state!r}")
    scene = read(name)
    p = resolve_params(scene, n, seed, dt, params)
    if state == "early":
        st, geometry = GENERATORS[scene.generator][0](p)
        physics = build_physics(scene, p, geometry)
        return Scenario(scene.name, "early", p, physics, st, p["dt"], scene.path,
                        {"geometry": geometry})
    return _late(scene, p, progress, use_cache)


# ---- late states -------------------------------------------------------------

def _cache_key(scene, p, which):
    blob = json.dumps({"physics": scene.physics, "generator": scene.generator, "late": scene.late,
                       "params": p, "which": which, "engine": ENGINE_VERSION}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def _late(scene, p, progress, use_cache):
    gen_opt = GENERATORS[scene.generator][2]
    marble = scene.late == "settle" and "marble_radius" in p
    base_p = {k: v for k, v in p.items() if not (marble and k in gen_opt)}
    if marble:
        base_p["n"] = p["n"] - 1  # the bed alone: the same key as the dish scene's
    st, geometry = GENERATORS[scene.generator][0](base_p)
    physics = build_physics(scene, base_p, geometry)
    key = _cache_key(scene, base_p, "late")
    path = cache_dir() / f"{scene.generator}-late-{key}.npz"
    state = None
    if use_cache and path.is_file():
        try:
            state = State.load(path)
        except Exception:  # a damaged cache entry is regenerated, never trusted
            state = None
    if state is None:
        state = _evolve(scene, base_p, st, physics, progress)
        if use_cache:
            state.save(path)  # atomic: an interrupted run leaves no partial file
    if marble:
        state = add_marble(state, p)
    info = {"geometry": geometry, "cache": str(path)}
    return Scenario(scene.name, "late", p, physics, state, p["dt"], scene.path, info)


def _say(progress, msg):
    if progress is not None:
        progress(msg)


def _evolve(scene, p, state, physics, progress):
    from .simulation import Simulation

    dt = p["dt"]
    sim = Simulation(state, physics, dt=dt)
    t0 = _time.perf_counter()
    if scene.late in ("orbits", "time"):
        if scene.late == "orbits":
            total = p["late_orbits"] * 2.0 * math.pi / p["omega"]
        else:
            total = p["late_time"]
        steps = max(1, int(round(total / dt)))
        _say(progress, f"{scene.name}: evolving the late state, {steps} steps")
        done = 0
        while done < steps:
            k = min(steps - done, max(1, steps // 20))
            sim.run(k)
            done += k
            _say(progress, f"{scene.name}: late state {done}/{steps} steps, "
                           f"{sim.stats['collisions']} collisions, "
                           f"{_time.perf_counter() - t0:.1f} s")
        return sim.state
    # settle: until every particle is slower than settle_speed
    limit = p["settle_time_max"]
    check = max(1, int(round(0.01 / dt)))  # look every 10 ms of simulated time
    _say(progress, f"{scene.name}: settling the bed (until every grain is slower than "
                   f"{p['settle_speed']} m/s, at most {limit} s)")
    while True:
        sim.run(check)
        s = sim.state
        vmax = float(np.sqrt(np.max(np.sum(s.vel ** 2, axis=1))))
        _say(progress, f"{scene.name}: t = {s.time:.3f} s, fastest grain {vmax:.3g} m/s, "
                       f"{sim.stats['collisions']} collisions, {_time.perf_counter() - t0:.1f} s")
        if vmax < p["settle_speed"]:
            return s
        if s.time >= limit:
            raise ScenarioError("params.settle_time_max",
                                f"the bed had not settled after {s.time:.3f} s (fastest grain "
                                f"{vmax:.3g} m/s > settle_speed {p['settle_speed']} m/s)")


def stderr_progress(msg):
    print(msg, file=sys.stderr, flush=True)
