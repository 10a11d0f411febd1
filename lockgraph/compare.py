"""Side-by-side comparison of lockgraph with a reference code on a scene.

``compare_ring`` runs lockgraph and REBOUND on the same ring particles for
several seeds (replicates: each seed is an independent realization of the
scene) and compares every observable of ``ring_observables`` by its
replicate scatter:

    z = (mean_lockgraph - mean_reference) / sqrt(se_lockgraph^2 + se_reference^2)

with se the standard error of a code's mean over the seeds.  An observable
agrees when |z| <= k.  ``k = 3`` by default: with about ten observables and
Gaussian scatter, the chance that some |z| exceeds 3 by luck alone is about
3 %, while a systematic difference of a few standard errors shows.  (With
only a few seeds the standard errors are themselves uncertain: use >= 3.)

Snapshot observables are averaged over ``samples`` equally spaced times of
each run (after the start); rates are taken over the whole run.
"""
import math

import numpy as np

from . import ring_observables as RO
from . import scenarios
from .errors import InputError
from .rebound_ring import ReboundRing
from .simulation import Simulation

AGAINST = ("rebound",)
RING_SCENES = ("ring", "ring_moonlet")


def _zscore(a, sa, b, sb):
    u = math.hypot(sa, sb)
    d = a - b
    if u == 0.0:
        return (0.0 if d == 0.0 else math.copysign(math.inf, d)), 0.0
    return d / u, u


def summarize(values_a, values_b, k, units=None):
    """Per observable: both means, their standard errors, the combined
    uncertainty, z and agreement; ``values_*`` map name -> list over seeds."""
    out = {}
    for name in values_a:
        a = np.asarray(values_a[name], float)
        b = np.asarray(values_b[name], float)
        sa = float(a.std(ddof=1) / math.sqrt(a.size)) if a.size > 1 else 0.0
        sb = float(b.std(ddof=1) / math.sqrt(b.size)) if b.size > 1 else 0.0
        z, u = _zscore(float(a.mean()), sa, float(b.mean()), sb)
        out[name] = {"lockgraph": float(a.mean()), "reference": float(b.mean()),
                     "se_lockgraph": sa, "se_reference": sb, "uncertainty": u, "z": z,
                     "agree": bool(abs(z) <= k), "unit": (units or {}).get(name, "")}
    return out


def sampled(advance, arrays, domain, steps, samples):
    """Advance ``steps`` steps in ``samples`` equal chunks (``advance(k)``) and take
    a ``ring_observables.snapshot`` of ``arrays()`` = (pos, vel, radius, mass)
    after each; returns the list of snapshots."""
    d = domain
    snaps = []
    done = 0
    for s in range(1, samples + 1):
        target = int(round(steps * s / samples))
        advance(target - done)
        done = target
        snaps.append(RO.snapshot(*arrays(), d.omega, d.lx, d.ly))
    return snaps


def state_arrays(sim):
    """(pos, vel, radius, mass) of a lockgraph ``Simulation``, by particle id."""
    st = sim.state
    return st.pos, st.vel, st.radius, st.mass


def _run_lockgraph(sc, steps, samples, threads):
    d = sc.physics.domain
    sim = Simulation(sc.state, sc.physics, dt=sc.dt, threads=threads)
    snaps = sampled(sim.run, lambda: state_arrays(sim), d, steps, samples)
    stats = sim.stats
    obs = RO.mean_snapshots(snaps)
    obs.update(RO.rates(stats["pair_collisions"], stats["momentum_flux_xy"], sc.state.n,
                        float(sc.state.mass.sum()), d.omega, stats["duration"]))
    info = {"wall_s": sim.wall_s, "collisions": stats["pair_collisions"],
            "max_overlap": stats["max_overlap"], "steps": steps}
    sim.close()
    return obs, info


def _run_rebound(sc, duration, dt, samples, collision):
    d = sc.physics.domain
    ref = ReboundRing(sc.state, sc.physics, dt, collision=collision)
    steps = int(round(duration / dt))
    snaps = sampled(ref.step, ref.arrays, d, steps, samples)
    log = ref.log
    obs = RO.mean_snapshots(snaps)
    obs.update(RO.rates(log["resolved"], log["momentum_flux_xy"], sc.state.n,
                        float(sc.state.mass.sum()), d.omega, steps * dt))
    info = {"wall_s": ref.wall_s, "collisions": log["resolved"], "steps": steps,
            "overlapping": log["overlapping"], "max_overlap": log["max_overlap"],
            "rejected": log["rejected"], "lost": ref.lost,
            "largest_overlapping": log["largest_overlapping"],
            "largest_max_overlap": log["largest_max_overlap"]}
    return obs, info


def compare_ring(scene="ring", state="late", n=2000, orbits=2.0, seeds=(1, 2, 3), k=3.0,
                 rebound_dt_orbits=1e-3, collision="tree", samples=10, threads=1,
                 params=None, progress=None):
    """Run lockgraph and REBOUND on ``scene`` for each seed; returns the report dict
    (see ``lockgraph compare --help``)."""
    if scene not in RING_SCENES:
        raise InputError("scene", f"the REBOUND comparison runs on {', '.join(RING_SCENES)}; "
                                  f"got {scene!r}")
    for name, v in (("orbits", orbits), ("k", k), ("rebound_dt_orbits", rebound_dt_orbits)):
        if not (v > 0 and math.isfinite(v)):
            raise InputError(name, f"must be a finite number > 0 (got {v!r})")
    seeds = [int(s) for s in seeds]
    if len(seeds) < 2:
        raise InputError("seeds", "need at least 2 seeds for a replicate scatter")
    say = progress or (lambda msg: None)
    per_a, per_b, runs = {}, {}, []
    for seed in seeds:
        sc = scenarios.load(scene, state, n=n, seed=seed, params=params, progress=say)
        omega = sc.physics.domain.omega
        orbit = 2.0 * math.pi / omega
        steps = max(1, int(round(orbits * orbit / sc.dt)))
        duration = steps * sc.dt
        say(f"seed {seed}: lockgraph, {steps} steps of {sc.dt:g} s")
        a, ia = _run_lockgraph(sc, steps, samples, threads)
        say(f"seed {seed}: REBOUND, dt = {rebound_dt_orbits:g} orbit "
            f"({int(round(duration / (rebound_dt_orbits * orbit)))} steps)")
        b, ib = _run_rebound(sc, duration, rebound_dt_orbits * orbit, samples, collision)
        say(f"seed {seed}: lockgraph {ia['wall_s']:.1f} s, {ia['collisions']} collisions; "
            f"REBOUND {ib['wall_s']:.1f} s, {ib['collisions']} collisions")
        for key in a:
            per_a.setdefault(key, []).append(a[key])
            per_b.setdefault(key, []).append(b[key])
        runs.append({"seed": seed, "lockgraph": ia, "reference": ib})
    obs = summarize(per_a, per_b, k, RO.UNITS)
    la = [r["lockgraph"] for r in runs]
    lb = [r["reference"] for r in runs]
    deficit = [1.0 - y["collisions"] / x["collisions"] for x, y in zip(la, lb)
               if x["collisions"] > 0]
    return {
        "scene": scene, "state": state, "against": "rebound", "n": n, "orbits": orbits,
        "seeds": seeds, "k": k, "samples": samples,
        "reference_settings": {"code": "REBOUND", "dt_orbits": rebound_dt_orbits,
                               "collision": collision, "integrator": "sei",
                               "boundary": "shear", "resolver": "hardsphere"},
        "observables": obs,
        "agree": all(o["agree"] for o in obs.values()),
        "wall_s": {"lockgraph": float(sum(r["wall_s"] for r in la)),
                   "reference": float(sum(r["wall_s"] for r in lb))},
        "lockgraph_failures": {"max_overlap": max(r["max_overlap"] for r in la)},
        "reference_failures": {
            "overlaps": int(sum(r["overlapping"] for r in lb)),
            "max_overlap": max(r["max_overlap"] for r in lb),
            "lost_particles": int(sum(r["lost"] for r in lb)),
            # collisions with the largest body (the moonlet) resolved while overlapping
            "largest_body_overlaps": int(sum(r["largest_overlapping"] for r in lb)),
            "largest_body_max_overlap": max(r["largest_max_overlap"] for r in lb),
            # collisions REBOUND resolved fewer than lockgraph (missed or merged)
            "missed_collisions": int(sum(x["collisions"] - y["collisions"]
                                         for x, y in zip(la, lb))),
            "missed_fraction": float(np.mean(deficit)) if deficit else 0.0},
        "runs": runs,
    }
