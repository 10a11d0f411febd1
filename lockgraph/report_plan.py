"""What a report campaign runs: the ``Run`` list of each mode and scene.

Modes: ``smoke`` (the test suite's: every table and chart, tiny systems, about
a minute), ``quick`` (the default: under 10 minutes on 2 cores) and ``full``
(paper scale, ~200,000 particles in the tables: hours).  Each scene gets

- ``SCENE/speed``: the methods of the speed-accuracy chart — lockgraph
  sequential, the lock graph at each SCALE and the grid on 2 threads, the
  lock graph on 2 threads with ``schedule="auto"``, and the reference codes
  at each time step or stiffness;
- ``SCENE/reference``: the converged reference its errors are measured from;
- ``tables/SCENE``: the paper's table for the scene, early and late;
- ``failures``: the runs that show where methods break down.
"""
from .campaign import Run
from .errors import InputError

SCENES = ("ring", "ring_moonlet", "dish", "dish_marble")
MODES = ("smoke", "quick", "full")
SCALES = {"smoke": (1.2, 8.0), "quick": (1.2, 2.0, 4.0, 6.0, 8.0),
          "full": (1.2, 2.0, 4.0, 6.0, 8.0)}
# ring scenes: particles, orbits, REBOUND steps (fractions of an orbit)
RING = {"smoke": (1500, 0.1, (1e-2, 3e-3)), "quick": (2000, 1.0, (1e-2, 3e-3, 1e-3)),
        "full": (20000, 1.0, (1e-2, 3e-3, 1e-3, 3e-4))}
# the ring's late state is compared; the moonlet's late ring is thicker than REBOUND's
# root box (lx) at these sizes, so the moonlet runs from the early state
RING_STATE = {"ring": "late", "ring_moonlet": "early"}
# dish (settling): grains, simulated time (s), seeds, collapse-guard times (s),
# DEM stiffnesses (Pa), reference stiffness and dt fraction
DISH = {"smoke": (150, 0.1, (1,), (3e-4, 1e-4), (1e7,), (1e8, 20.0)),
        "quick": (500, 0.25, (1,), (3e-4, 1e-4, 3e-5), (1e7,), (1e8, 20.0)),
        "full": (1000, 0.35, (1, 2), (3e-4, 1e-4, 3e-5, 1e-5), (1e7, 1e8), (1e9, 50.0))}
DISH_RADIUS = 0.005  # m: a 5 mm dish, so that a few hundred grains make a bed
# dish_marble: bed grains, drop height (m), marble radius (m) and density, guard times
MARBLE = {"smoke": (300, 0.02, 0.0015, 2500.0, (1e-4,)),
          "quick": (1000, 0.08, 0.0015, 2500.0, (1e-4, 3e-5)),
          "full": (1000, 0.08, 0.0015, 2500.0, (1e-4, 3e-5, 1e-5))}
# the paper's tables: particles per scene and steps traced
TABLES = {"smoke": ({"ring": 1500, "ring_moonlet": 1500, "dish": 1000, "dish_marble": 1001}, 1),
          "quick": ({"ring": 5000, "ring_moonlet": 5000, "dish": 1000, "dish_marble": 1001}, 2),
          "full": ({"ring": 200000, "ring_moonlet": 200000, "dish": 200000,
                    "dish_marble": 200001}, 3)}


AUTO = ("graph SCALE 4 auto, 2 threads",
        {"threads": 2, "lock": "graph", "scale": 4.0, "schedule": "auto"})


def _threads_series(scales):
    """(label suffix, settings) of the 2-thread lockgraph variants: events
    always on the threads at each SCALE and with the grid, and schedule auto
    (events on one thread when that measured cheaper)."""
    return ([(f"graph SCALE {s:g}, 2 threads", {"threads": 2, "lock": "graph", "scale": s})
             for s in scales] + [("grid, 2 threads", {"threads": 2, "lock": "grid"}), AUTO])


def ring_runs(scene, mode):
    n, orbits, dts = RING[mode]
    base = {"scene": scene, "n": n, "seed": 1, "orbits": orbits, "state": RING_STATE[scene]}
    runs = [Run("ring_lockgraph", {**base, "dt_factor": f}, f"lockgraph dt/{int(1 / f)}",
                f"{scene}/reference") for f in (0.5, 0.25, 0.125)]
    runs.append(Run("ring_lockgraph", base, "lockgraph sequential", f"{scene}/speed"))
    for suffix, s in _threads_series(SCALES[mode]):
        runs.append(Run("ring_lockgraph", {**base, **s}, f"lockgraph {suffix}",
                        f"{scene}/speed"))
    for d in dts:
        runs.append(Run("ring_rebound", {**base, "dt_orbits": d}, f"REBOUND dt={d:g} orbit",
                        f"{scene}/speed"))
    return runs


def dish_runs(mode):
    n, time, seeds, tcs, stiff, (ref_e, ref_frac) = DISH[mode]
    runs = []
    for seed in seeds:
        base = {"n": n, "seed": seed, "time": time, "cylinder_radius": DISH_RADIUS}
        for tc in tcs:
            runs.append(Run("dish_lockgraph", {**base, "tc": tc}, f"lockgraph tc={tc:g}",
                            "dish/speed"))
        # quick: SCALE 1.2 and 2 and the grid (each 2-thread settling costs ~10 s)
        for suffix, s in _threads_series(SCALES[mode][:2] if mode != "full" else SCALES[mode]):
            runs.append(Run("dish_lockgraph", {**base, "tc": tcs[1], **s},
                            f"lockgraph tc={tcs[1]:g} {suffix}", "dish/speed"))
        for code in ("lammps", "liggghts"):
            for e in stiff:
                runs.append(Run("dish_dem", {**base, "code": code, "stiffness": e},
                                f"{_code(code)} E={e:g}", "dish/speed"))
        runs.append(Run("dish_dem", {**base, "code": "lammps", "stiffness": stiff[0],
                                     "ranks": 2}, f"LAMMPS E={stiff[0]:g}, 2 ranks",
                        "dish/speed"))
        runs.append(Run("dish_dem", {**base, "code": "lammps", "stiffness": ref_e,
                                     "dt_fraction": ref_frac},
                        f"LAMMPS E={ref_e:g} (reference)", "dish/reference"))
    return runs


def marble_runs(mode):
    n, height, radius, density, tcs = MARBLE[mode]
    _, _, _, _, stiff, (ref_e, ref_frac) = DISH[mode]
    base = {"n": n, "seed": 1, "height": height, "cylinder_radius": DISH_RADIUS,
            "marble_radius": radius, "marble_density": density}
    runs = [Run("marble_drop", {**base, "code": "lockgraph", "tc": tc}, f"lockgraph tc={tc:g}",
                "dish_marble/speed") for tc in tcs]
    # 2 threads: SCALE 4 (a 2-thread drop costs as much as a DEM run); full: every variant
    variants = (_threads_series(SCALES[mode]) if mode == "full"
                else [("graph SCALE 4, 2 threads", {"threads": 2, "lock": "graph", "scale": 4.0}),
                      AUTO])
    for suffix, s in variants:
        runs.append(Run("marble_drop", {**base, "code": "lockgraph", "tc": tcs[-1], **s},
                        f"lockgraph tc={tcs[-1]:g} {suffix}", "dish_marble/speed"))
    for code in ("lammps", "liggghts"):
        for e in stiff:
            runs.append(Run("marble_drop", {**base, "code": code, "stiffness": e},
                            f"{_code(code)} E={e:g}", "dish_marble/speed"))
    runs.append(Run("marble_drop", {**base, "code": "lammps", "stiffness": ref_e,
                                    "dt_fraction": ref_frac},
                    f"LAMMPS E={ref_e:g} (reference)", "dish_marble/reference"))
    return runs


def table_runs(scene, mode):
    sizes, steps = TABLES[mode]
    return [Run("paper_table", {"scene": scene, "state": state, "n": sizes[scene],
                                "steps": steps}, f"table {scene} {state}", f"tables/{scene}")
            for state in ("early", "late")]


def failure_runs(mode):
    n, time, seeds, *_ = DISH[mode]
    base = {"n": n, "seed": 1, "cylinder_radius": DISH_RADIUS}
    runs = [Run("collapse", {**base, "time": time, "guard": g},
                f"dish {'with' if g else 'without'} the collapse guard", "failures")
            for g in (True, False)]
    runs += [Run("dish_dem", {**base, "time": min(time, 0.1), "code": code, "stiffness": 1e7,
                              "dt_fraction": 0.5}, f"{_code(code)} dt = 2 t_c", "failures")
             for code in ("lammps", "liggghts")]
    sizes = TABLES[mode][0]
    runs += [Run("policy_check", {"scene": scene, "state": "late", "n": min(sizes[scene], 20001),
                                  "steps": 3}, f"policies on {scene}", "failures")
             for scene in ("ring_moonlet", "dish_marble")]
    return runs


def _code(code):
    return {"lammps": "LAMMPS", "liggghts": "LIGGGHTS"}[code]


def plan(mode="quick", scenes=SCENES):
    """Every run of a report in ``mode`` over ``scenes``."""
    if mode not in MODES:
        raise InputError("mode", f"one of {', '.join(MODES)}; got {mode!r}")
    scenes = list(scenes)
    for s in scenes:
        if s not in SCENES:
            raise InputError("scenes", f"unknown scene {s!r}; one of {', '.join(SCENES)}")
    runs = []
    for s in scenes:
        if s in ("ring", "ring_moonlet"):
            runs += ring_runs(s, mode)
        elif s == "dish":
            runs += dish_runs(mode)
        else:
            runs += marble_runs(mode)
        runs += table_runs(s, mode)
    runs += failure_runs(mode)
    return runs
