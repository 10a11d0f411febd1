"""The runs a report campaign is made of: each a function of JSON-able
parameters returning a JSON-able dict, with its wall time measured inside.

Every function takes ``progress(fraction, note="")`` and reports how far it
is.  ``KINDS`` maps a run's kind (``campaign.Run.kind``) to its function.
Lockgraph's wall times are ``Simulation.wall_s`` (the steps only, not the
kernel compilation nor the sampling between chunks); REBOUND's are its
integration calls; the DEM codes' are their whole subprocess runs (start-up
included, as a user would time them).
"""
import math
import time

import numpy as np

from . import dem, scenarios
from . import dish_observables as DO
from . import marble_drop as M
from .compare import sampled, state_arrays
from .compare_dish import measure, run_dem, run_lockgraph
from .errors import InelasticCollapseError
from .paper_tables import finite
from .physics import Physics
from .restitution import CollapseGuard
from .simulation import Simulation
from .state import state_sha256

SAMPLES = 10          # snapshots over a ring run (sigma_x is their mean)
MARBLE_DURATION = 0.15  # s after release: the marble stops well within it


def _ring(scene, n, seed, state):
    return scenarios.load(scene, state, n=n, seed=seed)


def _orbit_steps(sc, orbits, dt):
    orbit = 2.0 * math.pi / sc.physics.domain.omega
    return orbit, max(1, int(round(orbits * orbit / dt)))


def _chunked(advance, steps, progress):
    """``advance`` wrapped so that each chunk reports the fraction done."""
    done = [0]

    def step(k):
        advance(k)
        done[0] += k
        progress(done[0] / steps)
    return step


def ring_lockgraph(scene, n, seed, orbits, state="late", dt_factor=1.0, threads=1, lock="graph",
                   scale=4.0, policy="exact", progress=None, schedule="parallel"):
    """Lockgraph on a ring scene's ``state`` for ``orbits`` orbits at
    dt = dt_factor x the scene's dt: collisions, mean sigma_x (m/s) over
    ``SAMPLES`` snapshots, overlaps, and the parallel engine's statistics."""
    sc = _ring(scene, n, seed, state)
    dt = sc.dt * dt_factor
    _, steps = _orbit_steps(sc, orbits, dt)
    sim = Simulation(sc.state, sc.physics, dt=dt, threads=threads, lock=lock, scale=scale,
                     policy=policy, schedule=schedule)
    try:
        snaps = sampled(_chunked(sim.run, steps, progress),
                        lambda: state_arrays(sim), sc.physics.domain, steps, SAMPLES)
        s = sim.stats
        final = sim.state
    finally:
        sim.close()
    return {"wall_s": sim.wall_s, "steps": steps, "dt": dt, "n": int(sc.state.n),
            "collisions": s["pair_collisions"], "max_overlap": s["max_overlap"],
            "sigma_x": float(np.mean([x["sigma_x"] for x in snaps])),
            "violations": s["violations"], "repairs": s["repairs"],
            "mean_concurrency": s["mean_concurrency"],
            "locks": finite(s["locks"]),
            # a fingerprint of the final state: the exact policy must reproduce it bit for bit
            "state_hash": final.sha256()}


def ring_rebound(scene, n, seed, orbits, dt_orbits, state="late", progress=None):
    """REBOUND (SEI, shearing sheet, hard-sphere resolver) on the same state for
    the same time as ``ring_lockgraph``: collisions, sigma_x and its failures
    (collisions resolved while overlapping, particles lost)."""
    from .rebound_ring import ReboundRing

    sc = _ring(scene, n, seed, state)
    orbit, lg_steps = _orbit_steps(sc, orbits, sc.dt)
    duration = lg_steps * sc.dt  # the time ring_lockgraph runs at dt_factor 1
    dt = dt_orbits * orbit
    steps = max(1, int(round(duration / dt)))
    ref = ReboundRing(sc.state, sc.physics, dt)
    snaps = sampled(_chunked(ref.step, steps, progress), ref.arrays,
                    sc.physics.domain, steps, SAMPLES)
    log = ref.log
    return {"wall_s": ref.wall_s, "steps": steps, "dt": dt, "n": int(sc.state.n),
            "collisions": log["resolved"], "max_overlap": log["max_overlap"],
            "overlapping": log["overlapping"], "lost": int(ref.lost),
            "largest_overlapping": log["largest_overlapping"],
            "largest_max_overlap": log["largest_max_overlap"],
            "sigma_x": float(np.mean([x["sigma_x"] for x in snaps]))}


def _dish(n, seed, cylinder_radius, tc=None):
    params = {"cylinder_radius": cylinder_radius}
    if tc is not None:
        params["tc"] = tc
    return scenarios.load("dish", "early", n=n, seed=seed, params=params)


def _dish_summary(sc, times, pos, vel, load, info):
    ke = 0.5 * np.nansum(sc.state.mass[None, :] * np.sum(vel ** 2, axis=2), axis=1)
    obs = None
    if not info.get("failures") and np.all(np.isfinite(pos[-1])):
        # a blown-up DEM run has no bed to measure
        obs = measure(times, pos, vel, sc.state.radius, sc.physics.domain.radius, load)[0]
    return {"wall_s": info["wall_s"], "n": int(sc.state.n), "times": times.tolist(),
            "ke": ke.tolist(), "settle_time": float(DO.settle_time(times, vel)),
            "observables": finite(obs), "floor_load": float(load),
            "max_overlap": float(info.get("max_overlap", 0.0)),
            "failures": finite(info.get("failures", {})),
            "steps": int(info["steps"]), "dt": float(info["dt"])}


def dish_lockgraph(n, seed, time, tc, cylinder_radius, threads=1, lock="graph", scale=4.0,
                   progress=None, schedule="parallel"):
    """Lockgraph on the dish from its falling block for ``time`` s with the
    collapse guard's ``tc`` (s): kinetic energy every 10 ms, settling time,
    bed observables."""
    sc = _dish(n, seed, cylinder_radius, tc)
    progress(0.0, "running")
    times, pos, vel, load, info = run_lockgraph(sc, time, threads=threads, lock=lock,
                                                scale=scale, progress=progress,
                                                schedule=schedule)
    out = _dish_summary(sc, times, pos, vel, load, info)
    out["state_hash"] = state_sha256(pos[-1], vel[-1])  # 2 threads must reproduce it bit for bit
    return out


def dish_dem(code, n, seed, time, stiffness, cylinder_radius, dt_fraction=20.0, ranks=1,
             progress=None):
    """LAMMPS or LIGGGHTS on the same falling block: Hertz contacts of Young's
    modulus ``stiffness`` (Pa), dt = t_c / dt_fraction (a fraction below 1
    probes a step that is too large)."""
    sc = _dish(n, seed, cylinder_radius)
    contact = dem.Contact("hertz", stiffness, dt_fraction)
    progress(0.0, f"{code} subprocess")
    times, pos, vel, load, info = run_dem(sc, code, time, contact, ranks=ranks)
    out = _dish_summary(sc, times, pos, vel, load, info)
    out["contact_time"] = info["contact_time"]
    out["version"] = info["version"]
    return out


def marble_drop(code, n, seed, height, cylinder_radius, marble_radius, marble_density,
                tc=None, threads=1, lock="graph", scale=4.0, stiffness=1e7, dt_fraction=20.0,
                ranks=1, progress=None, schedule="parallel"):
    """The marble dropped from ``height`` (m) into a bed settled by LAMMPS:
    penetration depth (m), time to rest (s), wall time."""
    params = {"cylinder_radius": cylinder_radius}
    progress(0.0, "bed (cached after the first run)")
    bed, sc, _ = M.settled_bed(n, seed, params, "lammps", 1e7)
    ph = sc.physics
    progress(0.3, f"{code} drop")
    if code == "lockgraph":
        ph = Physics(ph.domain, ph.forces, ph.restitution, CollapseGuard(tc))
        r = M.penetration(bed, ph, sc.dt, marble_radius, marble_density, height,
                          MARBLE_DURATION, "lockgraph", threads=threads, lock=lock, scale=scale,
                          schedule=schedule)
    else:
        r = M.penetration(bed, ph, sc.dt, marble_radius, marble_density, height,
                          MARBLE_DURATION, code, dem.Contact("hertz", stiffness, dt_fraction),
                          ranks=ranks)
    return {"wall_s": r["wall_s"], "depth": r["depth"], "rest_time": r["rest_time"],
            "grain_diameter": 2.0 * float(np.median(bed.radius)), "n": int(bed.n) + 1,
            "surface": r["surface"], "trajectory": r["trajectory"],
            "failures": finite(r["info"].get("failures", {})),
            **{k: r["info"][k] for k in ("violations", "repairs", "state_hash")
               if k in r["info"]}}


def paper_table(scene, state, n, steps, p=16, warm=1, progress=None):
    """One scene and state of the paper's tables: traced events, measured 1- and
    2-thread times per lock configuration, replays at up to 64 threads
    (``paper_tables.run_case``)."""
    from .paper_tables import run_case, thread_start_seconds

    progress(0.0, "loading the state")
    sc = scenarios.load(scene, state, n=n)
    t0 = time.perf_counter()
    ovh = thread_start_seconds()
    out = run_case(sc, steps, p, warm, ovh, progress=lambda msg: progress(0.5, msg.strip()))
    out["step_overhead_s"] = ovh
    out["wall_s"] = time.perf_counter() - t0
    return finite(out)


def collapse(n, seed, time, cylinder_radius, guard, progress=None):
    """The settling dish with (``guard``) or without the TC collapse guard:
    collisions per step until the run ends or stops, and the diagnosis."""
    sc = _dish(n, seed, cylinder_radius)
    ph = sc.physics
    if not guard:
        ph = Physics(ph.domain, ph.forces, ph.restitution, None)
    sim = Simulation(sc.state, ph, dt=sc.dt)
    steps = int(round(time / sc.dt))
    error = None
    try:
        for k in range(0, steps, 100):
            sim.run(min(100, steps - k))
            progress((k + 100) / steps)
    except InelasticCollapseError as exc:
        error = str(exc)
    per_step = [h["collisions"] for h in sim.history]
    sim.close()
    return {"wall_s": sim.wall_s, "guard": guard, "stopped": error is not None,
            "diagnosis": error, "time_reached": float(sim.state.time),
            "collisions_per_step": per_step, "dt": sc.dt}


def policy_check(scene, state, n, steps, threads=2, scale=4.0, progress=None):
    """The same steps sequentially and on ``threads`` threads under the exact
    and the paper policy: causality violations seen, repairs made, and whether
    each final state is bitwise the sequential one."""
    sc = scenarios.load(scene, state, n=n)
    out = {}
    for k, (name, th, policy) in enumerate((("sequential", 1, "exact"),
                                            ("exact", threads, "exact"),
                                            ("paper", threads, "paper"))):
        sim = Simulation(sc.state, sc.physics, dt=sc.dt, threads=th, scale=scale, policy=policy)
        try:
            sim.run(steps)
            st = sim.state
            out[name] = {"wall_s": sim.wall_s, "state_hash": st.sha256(),
                         "violations": sim.stats["violations"], "repairs": sim.stats["repairs"],
                         "violations_per_step": [h["violations"] for h in sim.history],
                         "pos": st.pos}
        finally:
            sim.close()
        progress((k + 1) / 3)
    seq = out["sequential"].pop("pos")
    for name in ("exact", "paper"):
        pos = out[name].pop("pos")
        out[name]["identical"] = out[name]["state_hash"] == out["sequential"]["state_hash"]
        out[name]["max_position_difference"] = float(np.max(np.abs(pos - seq)))
    out["wall_s"] = sum(out[k]["wall_s"] for k in ("sequential", "exact", "paper"))
    out["n"] = int(sc.state.n)
    return out


KINDS = {f.__name__: f for f in (ring_lockgraph, ring_rebound, dish_lockgraph, dish_dem,
                                 marble_drop, paper_table, collapse, policy_check)}
