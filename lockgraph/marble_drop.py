"""A marble dropped into a settled dish bed: penetration depth and time to rest,
for lockgraph and the DEM codes, from the same bed.

The bed is settled once by a DEM code (a hard-sphere bed at rest costs
lockgraph about N / t_c collisions per second of simulated time, the DEM code
a fixed cost per step) and turned into a hard-sphere state: every radius is
shrunk by the largest overlap the soft contacts left (of order 0.3 % at
E = 1e7 Pa; masses are kept), velocities are set to zero.  Every code then
starts from that state plus the marble.

Uehara et al. (2003), Phys. Rev. Lett. 90, 194301: a ball of density rho_b and
diameter D_b dropped from height h into a granular bed stops at depth
d = 0.14 / mu (rho_b / rho_g)^(1/2) D_b^(2/3) H^(1/3), H = h + d the total drop
distance (mu: the grains' friction angle's tangent).  Frictionless grains
have no mu of their own; what is checked is the exponent of H.
"""
import hashlib
import json
import math
import time as _time

import numpy as np

from . import dem
from . import dish_observables as DO
from . import scenarios
from .errors import InputError, ScenarioError
from .simulation import Simulation
from .state import State

# The marble is at rest from the first sample after which its height stays
# within REST_BAND grain diameters of its final height.  A speed threshold
# would not do: in a hard-sphere bed held by the collapse guard the marble
# keeps receiving elastic kicks of a few mm/s that move it by microns.
REST_BAND = 0.05
SAMPLE_EVERY = 1e-3  # s between samples of the marble's height: 1 ms resolves the stop


def _key(**kw):
    return hashlib.sha256(json.dumps(kw, sort_keys=True, default=str).encode()).hexdigest()[:20]


def settled_bed(n, seed=1, params=None, code="lammps", stiffness=1e7, time=None,
                progress=None, use_cache=True, ranks=1):
    """A settled dish bed of ``n`` grains made by ``code`` on ``ranks`` MPI
    ranks from the dish scene's falling block, as a hard-sphere state.
    Returns (State, Scenario of the block, info dict with the shrink factor and
    the DEM wall time).  Cached on disk (``LOCKGRAPH_CACHE``) by its
    parameters, the ranks included: another domain decomposition sums the
    contact forces in another order and settles another bed (N = 50,000, 100
    steps after the marble was added: one rank's bed, settled within the
    first run, 33,000-44,000 events a step on 2026-11-30; two ranks', which
    needed 0.2 s more, 339,000 on 2026-12-05).  Raises ScenarioError if the bed
    has not settled (rms speed under 3 mm/s) by the end of the run."""
    if isinstance(ranks, bool) or not isinstance(ranks, (int, np.integer)) or ranks < 1:
        raise InputError("ranks", f"must be an integer >= 1 (got {ranks!r})")
    sc = scenarios.load("dish", "early", n=n, seed=seed, params=params)
    if time is None:  # the fall of the block's top plus the settling seen at N = 1000
        top = float(np.max(sc.state.pos[:, 2]))
        time = round(math.sqrt(2.0 * top / sc.physics.g) + 0.3, 2)
    # the key holds what the DEM run depends on (not lockgraph's tc, dt, ...)
    dem_params = {k: v for k, v in sc.params.items()
                  if k not in ("tc", "dt", "settle_speed", "settle_time_max")}
    extra = {"ranks": int(ranks)} if ranks != 1 else {}  # one rank: the keys made before ranks
    key = _key(n=n, seed=seed, params=dem_params, code=code, stiffness=stiffness, time=time,
               version=dem.code_version(code), **extra)
    path = scenarios.cache_dir() / f"dem-bed-{key}.npz"
    if use_cache and path.is_file():
        try:
            st = State.load(path)
            return st, sc, {"cache": str(path), "dem_wall_s": 0.0, "shrink": None}
        except Exception:  # a damaged cache entry is regenerated, never trusted
            pass
    contact = dem.Contact("hertz", stiffness, 20)
    state, total, wall = sc.state, 0.0, 0.0
    limit = sc.params["settle_time_max"]
    chunk = time
    while True:  # run on in chunks of 0.2 s until the bed has settled
        res = dem.run(state, sc.physics, code, chunk, contact,
                      samples=max(2, int(round(chunk / 0.01))), ranks=ranks, progress=progress)
        wall += res.wall_s
        total += chunk
        if res.failures:
            raise ScenarioError("bed", f"{code} failed while settling the bed: {res.failures}")
        if math.isfinite(DO.settle_time(res.times, res.vel)):
            break
        if total >= limit:
            raise ScenarioError("params.settle_time_max", f"the {code} bed had not settled "
                                f"after {total:g} s (rms speed still above "
                                f"{DO.SETTLE_RMS * 1e3:g} mm/s)")
        if progress is not None:
            progress(f"{code}: not settled after {total:g} s; running on")
        state = State(res.pos[-1], res.vel[-1], sc.state.radius, sc.state.mass, time=res.times[-1])
        chunk = 0.2
    t_set = total
    pos = res.pos[-1]
    rad = sc.state.radius
    worst = _worst_overlap(pos, rad, sc.physics.domain)
    shrink = 1.0 - 1.01 * worst - 1e-9
    st = State(pos, np.zeros_like(pos), rad * shrink, sc.state.mass.copy())
    if use_cache:
        path.parent.mkdir(parents=True, exist_ok=True)
        st.save(path)
    return st, sc, {"cache": str(path), "dem_wall_s": wall, "shrink": shrink,
                    "settled_by": t_set}


def _worst_overlap(pos, rad, dish):
    """Largest overlap as a fraction of the radius (pairs: of the contact
    distance) with another grain, the floor or the cylinder."""
    pair = dem.overlap_of(pos, rad, dish)
    floor = float(np.max((rad - pos[:, 2]) / rad))
    wall = float(np.max((np.hypot(pos[:, 0], pos[:, 1]) + rad - dish.radius) / rad))
    return max(pair, floor, wall, 0.0)


def with_marble(bed, physics, marble_radius, marble_density, height, gap=None):
    """The bed plus a marble on the axis whose bottom starts ``gap`` (default one
    grain radius) above the highest grain, moving down as if dropped from
    ``height`` (m) above that grain.  Returns the State (marble last)."""
    r = float(bed.radius.min())
    gap = r if gap is None else gap
    top = float(np.max(bed.pos[:, 2] + bed.radius))
    fall = max(height - gap, 0.0)
    v = math.sqrt(2.0 * physics.g * fall)
    mass = marble_density * 4.0 / 3.0 * math.pi * marble_radius ** 3
    pos = np.vstack([bed.pos, [0.0, 0.0, top + gap + marble_radius]])
    vel = np.vstack([bed.vel, [0.0, 0.0, -v]])
    return State(pos, vel, np.concatenate([bed.radius, [marble_radius]]),
                 np.concatenate([bed.mass, [mass]]))


def stop(times, z, surface, marble_radius, grain_diameter, hold=None):
    """(penetration depth d (m) of the marble's bottom below the surface, time
    to rest (s after the drop; NaN if not at rest)).

    ``hold`` None: the marble is at rest from the first sample after which its
    height stays within REST_BAND grain diameters of its height at the end of
    the run (NaN if that is only in the run's last tenth); d at the end.
    ``hold`` (s): at rest from the first sample whose band the marble has kept
    for ``hold`` s — the earliest sample m for which the samples since some
    k, t_m - t_k >= hold, all lie within the band around z_m; d at sample m
    (the same rule ``drop_lockgraph`` stops on).  NaN (and d at the end) if
    that never happens."""
    band = REST_BAND * grain_diameter
    if hold is not None:
        for m in range(len(times)):
            k = held_since(times[:m + 1], z[:m + 1], band)
            if times[m] - times[k] >= hold:
                return float(surface - (z[m] - marble_radius)), float(times[k] - times[0])
        return float(surface - (z[-1] - marble_radius)), math.nan
    d = surface - (z[-1] - marble_radius)
    k = held_since(times, z, band)
    if k >= len(times) - max(1, len(times) // 10):
        return float(d), math.nan
    return float(d), float(times[k] - times[0])


def held_since(times, z, band):
    """Index of the first sample from which every later one lies within ``band``
    (m) of the last sample's height."""
    z = np.asarray(z)
    moving = np.flatnonzero(~(np.abs(z - z[-1]) <= band))
    return int(moving[-1]) + 1 if moving.size else 0


PROGRESS_EVERY = 30.0  # s of wall time between progress lines of a long drop


def drop_lockgraph(state, physics, dt, duration, threads=1, lock="graph", scale=4.0,
                   progress=None, rest=None, schedule="parallel"):
    """The marble (last particle) through a lockgraph run: (times, z, vz, info).
    ``progress(msg)``, if given, hears about a long run every PROGRESS_EVERY s.
    ``rest = (band, hold)``: stop before ``duration`` once the marble's height
    has stayed within ``band`` (m) of its current value for ``hold`` s (see
    ``stop``); info["stopped_at_rest"] says whether it did."""
    sim = Simulation(state, physics, dt=dt, threads=threads, lock=lock, scale=scale,
                     schedule=schedule)
    every = max(1, int(round(SAMPLE_EVERY / dt)))
    times, z, vz = [state.time], [state.pos[-1, 2]], [state.vel[-1, 2]]
    walls = [0.0]
    t_start = state.time
    last = _time.perf_counter()
    at_rest = False
    for _ in range(max(1, int(round(duration / (every * dt))))):
        sim.run(every)
        st = sim.state
        times.append(st.time)
        z.append(st.pos[-1, 2])
        vz.append(st.vel[-1, 2])
        walls.append(sim.wall_s)
        if rest is not None and times[-1] - times[held_since(times, z, rest[0])] >= rest[1]:
            at_rest = True  # the run's only use was the stop: the rest costs collisions
            break
        if progress is not None and _time.perf_counter() - last >= PROGRESS_EVERY:
            last = _time.perf_counter()
            progress(f"lockgraph: {st.time - t_start:.4f} of {duration:g} s simulated, "
                     f"{sim.stats['collisions']:.3g} collisions, {sim.wall_s:.0f} s wall, "
                     f"marble at z = {st.pos[-1, 2] * 1e3:.2f} mm")
    stats = sim.stats
    final = sim.state
    info = {"wall_s": sim.wall_s, "collisions": stats["collisions"],
            "max_overlap": stats["max_overlap"], "threads": stats["threads"],
            "violations": stats["violations"], "repairs": stats["repairs"],
            "stopped_at_rest": at_rest, "simulated_s": final.time - t_start,
            "sample_wall": walls,
            # every particle's final state: a threaded run must reproduce it bit for bit
            "state_hash": final.sha256()}
    sim.close()
    return np.array(times), np.array(z), np.array(vz), info


def drop_dem(state, physics, code, duration, contact, ranks=1, progress=None):
    """The marble (last particle) through a DEM run: (times, z, vz, info)."""
    samples = max(1, int(round(duration / SAMPLE_EVERY)))
    res = dem.run(state, physics, code, duration, contact, samples=samples, ranks=ranks,
                  track=[state.n - 1], progress=progress)
    info = {"wall_s": res.wall_s, "steps": res.steps, "dt": res.dt, "failures": res.failures,
            "version": res.version,
            "sample_wall": (res.sample_wall.tolist() if res.sample_wall is not None
                            else [math.nan] * len(res.times))}
    return res.times, res.pos[:, -1, 2], res.vel[:, -1, 2], info


def penetration(bed, physics, dt, marble_radius, marble_density, height, duration,
                code="lockgraph", contact=None, threads=1, ranks=1, progress=None,
                lock="graph", scale=4.0, hold=None, schedule="parallel"):
    """Drop the marble from ``height`` into ``bed`` with ``code`` ("lockgraph",
    "lammps" or "liggghts"); returns a dict: depth (m), rest_time (s), H = height
    + depth (m), impact_speed (m/s), wall_s, info.  ``hold`` (s): the rest rule
    of ``stop``; lockgraph then stops as soon as it is met (the DEM code runs
    ``duration``, and the same rule is read off its trajectory)."""
    surface = DO.bed_height(bed.pos, bed.radius, physics.domain.radius)
    state = with_marble(bed, physics, marble_radius, marble_density, height)
    grain_d = 2.0 * float(np.median(bed.radius))
    if code == "lockgraph":
        rest_rule = None if hold is None else (REST_BAND * grain_d, hold)
        t, z, vz, info = drop_lockgraph(state, physics, dt, duration, threads, lock, scale,
                                        progress, rest_rule, schedule)
    else:
        t, z, vz, info = drop_dem(state, physics, code, duration,
                                  contact or dem.Contact("hertz", 1e7, 20), ranks, progress)
    depth, rest = stop(t, z, surface, marble_radius, grain_d, hold)
    walls = np.asarray(info["sample_wall"], float)
    rest_wall = (float(walls[int(np.argmin(np.abs(t - t[0] - rest)))]) if rest == rest
                 else math.nan)
    return {"code": code, "height": height, "depth": depth, "rest_time": rest,
            "rest_wall_s": rest_wall,
            "H": height + depth, "impact_speed": math.sqrt(2 * physics.g * height),
            "surface": surface, "wall_s": info["wall_s"], "info": info,
            "trajectory": {"t": t.tolist(), "z": z.tolist()}}


def uehara_exponent(heights_total, depths):
    """Least-squares slope of log d against log H (Uehara: 1/3)."""
    x = np.log(np.asarray(heights_total, float))
    y = np.log(np.asarray(depths, float))
    return float(np.polyfit(x, y, 1)[0])


def uehara_depth(rho_ball, rho_grain, diameter, H, mu):
    """Uehara et al. (2003) eq. (1): d = 0.14/mu (rho_b/rho_g)^(1/2) D_b^(2/3) H^(1/3)."""
    return 0.14 / mu * math.sqrt(rho_ball / rho_grain) * diameter ** (2 / 3) * H ** (1 / 3)


MARBLE_KEYS = ("marble_radius", "marble_density", "marble_speed", "marble_gap")
# The deep bed (validation's --paper-scale case, benchmarks/deep_marble.py and
# the parallel benchmark's deep_bed): 8,700 grains, 40 diameters deep in a 7.5 mm
# dish, a 6 mm marble, lockgraph at tc = 3e-5 s
DEEP_BED = {"n": 8701, "cylinder_radius": 0.0075, "marble_radius": 0.003, "tc": 3e-5}
# Its drops end at rest by the ``hold`` rule of ``stop``: 0.04 s within 0.05 d,
# i.e. a marble creeping slower than 1.25 mm/s counts as at rest.  A drop's
# cost to lockgraph grows with its length (the bed under the marble compacts:
# ~8e9 collisions per simulated second over the first 0.1 s, ~3e10 by 0.15 s,
# measured 2026-11-30), and with 0.1 s drops it came to rest after 0.04-0.064 s
# (2, 8, 32 cm), so the rule ends its drops near 0.1 s instead of 0.2 s.
DEEP_REST_HOLD = 0.04


def deep_bed(code="lammps", seed=1, progress=None):
    """The DEEP_BED bed settled by ``code`` (cached): (bed State, Scenario of
    the block, resolved dish_marble parameters, settled_bed's info)."""
    params = {k: v for k, v in DEEP_BED.items() if k != "n"}
    p = scenarios.resolve_params(scenarios.read("dish_marble"), DEEP_BED["n"], seed, None,
                                 params)
    bed_params = {k: v for k, v in params.items() if k not in MARBLE_KEYS}
    bed, sc, info = settled_bed(DEEP_BED["n"] - 1, seed, bed_params, code, progress=progress)
    return bed, sc, p, info


def compare_marble(scene="dish_marble", against="lammps", n=None, seeds=(1, 2), heights=None,
                   time=0.15, stiffness=1e7, dt_fraction=20.0, params=None, threads=1, ranks=1,
                   depth_tol=0.5, rest_tol=0.08, progress=None, rest_hold=None):
    """Drop the scene's marble into a settled bed with lockgraph and ``against``
    for each seed (one bed each, settled by ``against``) and drop height.

    ``heights`` (m) default to the one the scene's ``marble_speed`` implies,
    v^2 / 2g.  Agreement: per height, the seed-mean depths within ``depth_tol``
    grain diameters and the mean times to rest within ``rest_tol`` s (see
    validation/test_dem_marble.py for the measured spreads behind the defaults).
    ``rest_hold`` (s): the rest rule of ``stop`` for both codes; lockgraph's
    drops end as soon as it is met (``time`` is then the longest drop).
    Returns the report dict (the shape of the other comparisons)."""
    if scene != "dish_marble":
        raise InputError("scene", f"the marble comparison runs on dish_marble, got {scene!r}")
    if against not in dem.CODES:
        raise InputError("against", f"unknown DEM code {against!r}; one of {', '.join(dem.CODES)}")
    if rest_hold is not None and not (math.isfinite(rest_hold) and rest_hold > 0):
        raise InputError("rest_hold", f"must be a positive time in s or None, got {rest_hold!r}")
    seeds = [int(s) for s in seeds]
    say = progress or (lambda msg: None)
    p = scenarios.resolve_params(scenarios.read(scene), n, seeds[0], None, params)
    bed_params = {k: v for k, v in (params or {}).items() if k not in MARBLE_KEYS}
    if heights is None:
        heights = (p["marble_speed"] ** 2 / (2.0 * p["g"]),)
    contact = dem.Contact("hertz", stiffness, dt_fraction)
    d = 2.0 * p["grain_radius"]
    runs = []
    for seed in seeds:
        say(f"seed {seed}: settling the bed ({p['n'] - 1} grains) with {against}")
        bed, sc, info = settled_bed(p["n"] - 1, seed, bed_params, against, stiffness,
                                    progress=say)
        for h in heights:
            row = {"seed": seed, "height": h}
            for code in ("lockgraph", against):
                say(f"seed {seed}: marble from {h:g} m, {code}")
                r = row[code] = penetration(bed, sc.physics, sc.dt, p["marble_radius"],
                                            p["marble_density"], h, time, code, contact,
                                            threads, ranks, say, hold=rest_hold)
                say(f"seed {seed}: marble from {h:g} m, {code}: depth {r['depth'] * 1e3:.3f} mm, "
                    f"at rest after {r['rest_time']:.3f} s (nan: still moving), "
                    f"{r['info'].get('simulated_s', time):.3f} s simulated, "
                    f"{r['wall_s']:.0f} s wall")
            runs.append(row)
    per_height = []
    for h in heights:
        rows = [r for r in runs if r["height"] == h]
        out = {"height": h}
        for code in ("lockgraph", against):
            side = "lockgraph" if code == "lockgraph" else "reference"
            out[side] = {"depth": float(np.mean([r[code]["depth"] for r in rows])),
                         "rest_time": float(np.mean([r[code]["rest_time"] for r in rows])),
                         "wall_s": float(np.mean([r[code]["wall_s"] for r in rows])),
                         "rest_wall_s": float(np.mean([r[code]["rest_wall_s"] for r in rows]))}
        dd = abs(out["lockgraph"]["depth"] - out["reference"]["depth"])
        dt_rest = abs(out["lockgraph"]["rest_time"] - out["reference"]["rest_time"])
        out["depth_agree"] = bool(dd <= depth_tol * d)
        out["rest_agree"] = bool(dt_rest <= rest_tol)
        per_height.append(out)
    exps = {}
    if len(heights) >= 2:
        for code, side in (("lockgraph", "lockgraph"), (against, "reference")):
            exps[side] = uehara_exponent([o["height"] + o[side]["depth"] for o in per_height],
                                         [o[side]["depth"] for o in per_height])
    return {
        "scene": scene, "against": against, "n": int(p["n"]), "seeds": seeds,
        "heights": list(heights), "time": time, "params": dict(params or {}),
        "marble": {k: p[k] for k in ("marble_radius", "marble_density")},
        "reference_settings": {"code": dem.code_version(against), "model": "hertz",
                               "stiffness": stiffness, "dt_fraction": dt_fraction},
        "tolerances": {"depth_grain_diameters": depth_tol, "rest_time_s": rest_tol},
        "rest_rule": {"band_grain_diameters": REST_BAND, "hold_s": rest_hold},
        "per_height": per_height,
        "uehara_exponent": exps,
        "agree": all(o["depth_agree"] and o["rest_agree"] for o in per_height),
        "wall_s": {"lockgraph": float(sum(r["lockgraph"]["wall_s"] for r in runs)),
                   "reference": float(sum(r[against]["wall_s"] for r in runs))},
        "reference_failures": {k: v for r in runs for k, v in
                               (r[against]["info"].get("failures") or {}).items()},
        "runs": runs,
    }
