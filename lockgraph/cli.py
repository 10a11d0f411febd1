"""The ``lockgraph`` command line.

    lockgraph scenes
    lockgraph run SCENE [--state early|late] [--n N] [--steps K] [--dt DT] [--seed S]
                        [--threads T] [--lock none|grid|graph] [--scale X]
                        [--policy exact|paper] [--schedule parallel|auto|pool]
                        [--param KEY=VALUE ...]
                        [--save FILE.npz] [--json] [--quiet]

    lockgraph compare SCENE --against rebound [--state early|late] [--n N] [--orbits X]
                        [--seed S] [--seeds K] [--k K] [--dt-orbits X] [--json]
                        [--out FILE.json]
    lockgraph compare dish|dish_marble --against lammps|liggghts [--n N] [--time T]
                        [--seed S] [--seeds K] [--k K] [--heights H1,H2,..]
                        [--stiffness E] [--dt-fraction F] [--ranks R] [--json]
                        [--out FILE.json]
    lockgraph report [--scenes ring,ring_moonlet,dish,dish_marble] [--quick | --full | --smoke]
                     [--out DIR] [--cache DIR] [--scheduler ADDRESS] [--no-pictures]

Exit codes: 0 success, 1 some runs of a report failed (listed in it), 2 bad input
(the message names the field), 3 the run could not continue (the state is left at
the last completed step; nothing is saved), 4 a reference code is not installed (the message says how to install it).
"""
import argparse
import json
import resource
import sys
import time

from . import __version__
from .errors import InputError, SimulationError
from .reference_codes import MissingReference


def _peak_rss_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


class Progress:
    """At most one line a second on stderr: steps done, collisions, rate."""

    def __init__(self, enabled, label):
        self.enabled = enabled
        self.label = label
        self.t0 = time.perf_counter()
        self.last = 0.0

    def message(self, msg):
        if self.enabled:
            print(msg, file=sys.stderr, flush=True)

    def steps(self, sim, done, total):
        if not self.enabled:
            return
        now = time.perf_counter()
        if done < total and now - self.last < 1.0:
            return
        self.last = now
        s = sim.stats
        rate = s["events_per_s"]
        print(f"{self.label}: step {done}/{total}, {s['collisions']} collisions, "
              f"{rate:.3g} collisions/s, {now - self.t0:.1f} s", file=sys.stderr, flush=True)


def cmd_scenes(args):
    from . import scenarios

    for name in scenarios.available():
        scene = scenarios.read(name)
        print(f"{name:14s} {scene.description}")
    return 0


def cmd_run(args):
    from . import scenarios
    from .observables import reduced_pressure
    from .simulation import Simulation

    progress = Progress(not args.quiet, args.scene)
    params = scenarios.parse_overrides(args.param)
    sc = scenarios.load(args.scene, state=args.state, n=args.n, seed=args.seed, dt=args.dt,
                        params=params, progress=progress.message)
    sim = Simulation(sc.state, sc.physics, dt=sc.dt, threads=args.threads, lock=args.lock,
                     scale=args.scale, policy=args.policy, schedule=args.schedule)
    sim.run(args.steps, progress=lambda d, t: progress.steps(sim, d, t))
    final = sim.state
    stats = sim.stats
    out = {
        "scene": sc.name,
        "state": sc.which,
        "n": final.n,
        "steps": args.steps,
        "dt": sc.dt,
        "seed": sc.params["seed"],
        "threads": args.threads,
        "lock": args.lock,
        "scale": args.scale,
        "policy": args.policy,
        "schedule": args.schedule,
        "threaded_event_steps": stats["threaded_event_steps"],
        "events": stats["events"],
        "mean_concurrency": stats["mean_concurrency"],
        "blocked_picks": stats["blocked_picks"],
        "asked_switches": stats["asked_switches"],
        "wait_s": stats["wait_s"],
        "collisions": stats["collisions"],
        "pair_collisions": stats["pair_collisions"],
        "wall_collisions": stats["wall_collisions"],
        "guarded_impacts": stats["guarded_impacts"],
        "wall_s": stats["wall_s"],
        "phase_s": stats["phase_s"],
        "compile_s": stats["compile_s"],
        "events_per_s": stats["events_per_s"],
        "max_overlap": stats["max_overlap"],
        "violations": stats["violations"],
        "repairs": stats["repairs"],
        "repairs_on_threads": stats["repairs_on_threads"],
        "time": final.time,
        "state_sha256": final.sha256(),
        "peak_rss_mb": _peak_rss_mb(),
        "params": sc.params,
        "stats": stats,
    }
    if sc.name == "gas" or sc.physics.domain.describe()["type"] == "periodic_cube":
        out["pressure_reduced"] = reduced_pressure(final, stats)
        eta = sc.params.get("eta")
        if eta is not None:
            out["pressure_carnahan_starling"] = (1 + eta + eta ** 2 - eta ** 3) / (1 - eta) ** 3
    if args.save:
        final.save(args.save)  # only after a successful run, atomically
    if args.json:
        print(json.dumps(out, default=_jsonable))
    else:
        for k, v in out.items():
            if k not in ("params", "stats"):
                print(f"{k:18s} {v}")
        if args.save:
            print(f"{'saved':18s} {args.save}")
    return 0


def cmd_compare(args):
    from . import scenarios
    from .compare import AGAINST, compare_ring
    from .compare_dish import AGAINST as DEM

    if args.against not in AGAINST + DEM:
        raise InputError("against", f"unknown value {args.against!r}; one of "
                                    f"{', '.join(AGAINST + DEM)}")
    least = 1 if args.scene == "dish_marble" else 2  # the others use the replicate scatter
    if args.seeds < least:
        raise InputError("seeds", f"need at least {least} replicate seeds, got {args.seeds}")
    progress = Progress(not args.quiet, f"compare {args.scene}")
    seeds = [args.seed + k for k in range(args.seeds)]
    params = scenarios.parse_overrides(args.param)
    if args.against in DEM:
        return _compare_dem(args, seeds, params, progress)
    res = compare_ring(args.scene, state=args.state, n=args.n or 2000, orbits=args.orbits,
                       seeds=seeds, k=args.k, rebound_dt_orbits=args.dt_orbits,
                       params=params, progress=progress.message)
    _write_report(args, res)
    if args.json:
        print(json.dumps(res, default=_jsonable))
        return 0
    print(f"{args.scene} ({args.state}), N = {res['n']}, {res['orbits']:g} orbits, seeds "
          f"{res['seeds']}; agreement within k = {res['k']:g} sigma of the replicate scatter")
    _observable_table(res, "REBOUND")
    f = res["reference_failures"]
    print(f"agree: {res['agree']}; wall: lockgraph {res['wall_s']['lockgraph']:.1f} s, REBOUND "
          f"{res['wall_s']['reference']:.1f} s")
    nl = sum(r["lockgraph"]["collisions"] for r in res["runs"])
    nr = sum(r["reference"]["collisions"] for r in res["runs"])
    print(f"collisions: lockgraph {nl}, REBOUND {nr} ({100 * f['missed_fraction']:+.1f} % "
          f"missed by REBOUND; negative: it resolved more)")
    print(f"REBOUND: {f['overlaps']} collisions resolved while overlapping (largest "
          f"{f['max_overlap']:.3g} of the contact distance), {f['lost_particles']} particles "
          f"lost; with the largest particle {f['largest_body_overlaps']} overlapping (largest "
          f"{f['largest_body_max_overlap']:.3g}); lockgraph largest overlap "
          f"{res['lockgraph_failures']['max_overlap']:.2g}")
    return 0


def _observable_table(res, name):
    import math

    print(f"{'observable':18s} {'lockgraph':>12s} {name:>12s} {'uncertainty':>12s} "
          f"{'z':>7s}  agree")
    for key, o in res["observables"].items():
        z = o["z"]
        zs = f"{z:7.2f}" if math.isfinite(z) else f"{z:>7}"
        print(f"{key:18s} {o['lockgraph']:12.4g} {o['reference']:12.4g} "
              f"{o['uncertainty']:12.3g} {zs}  {'yes' if o['agree'] else 'NO'}")


def _compare_marble(args, seeds, params, progress):
    from . import dem
    from .marble_drop import compare_marble

    heights = None
    if args.heights:
        try:
            heights = tuple(float(x) for x in args.heights.split(","))
        except ValueError:
            raise InputError("heights", f"comma-separated drop heights in m, got "
                                        f"{args.heights!r}") from None
        if not all(h > 0 for h in heights):
            raise InputError("heights", f"drop heights must be > 0 m, got {args.heights!r}")
    res = compare_marble(args.scene, against=args.against, n=args.n, seeds=seeds,
                         heights=heights, time=args.time or 0.15, stiffness=args.stiffness,
                         dt_fraction=args.dt_fraction, params=params, ranks=args.ranks,
                         progress=progress.message)
    _write_report(args, res)
    if args.json:
        print(json.dumps(res, default=_jsonable))
        return 0
    name = dem.NAMES[args.against]
    print(f"{args.scene}: marble radius {res['marble']['marble_radius']:g} m into a bed of "
          f"{res['n'] - 1} grains, seeds {res['seeds']}; {res['reference_settings']['code']}")
    print(f"{'height m':>9s} {'depth lockgraph':>16s} {'depth ' + name:>16s} "
          f"{'rest lockgraph':>15s} {'rest ' + name:>15s}  agree")
    for o in res["per_height"]:
        a, b = o["lockgraph"], o["reference"]
        print(f"{o['height']:9.3g} {a['depth']:16.4g} {b['depth']:16.4g} {a['rest_time']:15.3g} "
              f"{b['rest_time']:15.3g}  {'yes' if o['depth_agree'] and o['rest_agree'] else 'NO'}")
    if res["uehara_exponent"]:
        print(f"Uehara exponent of H (1/3): {res['uehara_exponent']}")
    print(f"agree: {res['agree']}; wall: lockgraph {res['wall_s']['lockgraph']:.1f} s, {name} "
          f"{res['wall_s']['reference']:.1f} s; {name} failures: {res['reference_failures']}")
    return 0


def _compare_dem(args, seeds, params, progress):
    from . import dem
    from .compare_dish import compare_dish

    if args.scene == "dish_marble":
        return _compare_marble(args, seeds, params, progress)
    res = compare_dish(args.scene, against=args.against, n=args.n, time=args.time or 0.5,
                       seeds=seeds,
                       k=args.k, stiffness=args.stiffness, dt_fraction=args.dt_fraction,
                       params=params, ranks=args.ranks, progress=progress.message)
    _write_report(args, res)
    if args.json:
        print(json.dumps(res, default=_jsonable))
        return 0
    name = dem.NAMES[args.against]
    rs = res["reference_settings"]
    print(f"{args.scene}, N = {res['n']}, {res['time']:g} s from the falling block, seeds "
          f"{res['seeds']}; {rs['code']}: Hertz E = {rs['stiffness']:g} Pa, dt = "
          f"{rs['dt']:.3g} s (t_c / {rs['dt_fraction']:g}); agreement within k = "
          f"{res['k']:g} sigma plus the stated allowance")
    _observable_table(res, name)
    fl = res["checks"]["floor_load"]
    print(f"floor load / weight: lockgraph {fl['values']['lockgraph']}, {name} "
          f"{fl['values']['reference']} (within {fl['tolerance']:g}: "
          f"{'yes' if fl['pass'] else 'NO'})")
    st = res["settle_time"]
    print(f"settling time (rms speed < {st['rms_speed'] * 1e3:g} mm/s): lockgraph "
          f"{st['lockgraph']} s, {name} {st['reference']} s")
    print(f"agree: {res['agree']}; wall: lockgraph {res['wall_s']['lockgraph']:.1f} s, {name} "
          f"{res['wall_s']['reference']:.1f} s; {name} failures: {res['reference_failures']}")
    return 0


def _write_report(args, res):
    if args.out:
        import os

        tmp = args.out + ".tmp"
        with open(tmp, "w") as fh:  # never a half-written report
            json.dump(res, fh, default=_jsonable, indent=1)
        os.replace(tmp, args.out)


def _jsonable(v):
    import numpy as np

    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return float(v)
    raise TypeError(f"not JSON serialisable: {v!r}")


SCENE_NAMES = ("ring", "ring_moonlet", "dish", "dish_marble")


def cmd_report(args):
    from .report import build

    scenes = [x for x in args.scenes.split(",") if x]
    t0 = time.perf_counter()
    print(f"lockgraph report: {args.mode} campaign over {', '.join(scenes)} into {args.out}/",
          file=sys.stderr, flush=True)
    out = build(args.out, args.mode, scenes, args.scheduler, args.cache,
                pictures=not args.no_pictures)
    print(f"lockgraph report: wrote {out['index']} ({out['runs']} runs, {out['cached']} from "
          f"the cache, {out['failed']} failed) in {time.perf_counter() - t0:.0f} s",
          file=sys.stderr)
    return 1 if out["failed"] else 0


def parser():
    p = argparse.ArgumentParser(prog="lockgraph", description="Hard-sphere collisions in time "
                                "order, sequential or in parallel threads under lock-graph locks.")
    p.add_argument("--version", action="version", version=f"lockgraph {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("scenes", help="list the scenes")
    s.set_defaults(func=cmd_scenes)
    r = sub.add_parser("run", help="run a scene")
    r.add_argument("scene", help="scene name (see 'lockgraph scenes') or a .toml file")
    r.add_argument("--state", choices=("early", "late"), default="early")
    r.add_argument("--n", type=int, help="number of particles (scene parameter n)")
    r.add_argument("--steps", type=int, default=10)
    r.add_argument("--dt", type=float, help="step length in s (scene parameter dt)")
    r.add_argument("--seed", type=int, help="random seed (scene parameter seed)")
    r.add_argument("--threads", type=int, default=1)
    r.add_argument("--lock", default="graph", help="none | grid | grid3d | graph (threads > 1)")
    r.add_argument("--scale", type=float, default=4.0, help="lock-graph SCALE")
    r.add_argument("--policy", default="exact", help="exact | paper")
    r.add_argument("--schedule", default="parallel",
                   help="parallel | auto | pool: threads > 1, a step's events on the worker "
                        "threads always, or (exact policy) on one thread when that measured "
                        "faster, or (exact policy) on 4 domains a thread that any free thread "
                        "takes, waiting by particle")
    r.add_argument("--param", action="append", metavar="KEY=VALUE",
                   help="override a scene parameter (repeatable)")
    r.add_argument("--save", metavar="FILE.npz", help="write the final state (pos, vel, radius, "
                   "mass, ordered by particle id)")
    r.add_argument("--json", action="store_true", help="print one JSON object")
    r.add_argument("--quiet", action="store_true", help="no progress on stderr")
    r.set_defaults(func=cmd_run)
    c = sub.add_parser("compare", help="compare a scene against a reference code")
    c.add_argument("scene", help="ring or ring_moonlet (REBOUND); dish or dish_marble "
                                 "(LAMMPS, LIGGGHTS)")
    c.add_argument("--against", required=True, help="rebound | lammps | liggghts")
    c.add_argument("--state", choices=("early", "late"), default="late",
                   help="ring state (late); the dish always starts from the falling block")
    c.add_argument("--n", type=int, help="particles (ring: 2000; dish: the scene's)")
    c.add_argument("--time", type=float,
                   help="dish: seconds to run from the falling block (0.5); dish_marble: "
                        "seconds after the drop (0.15)")
    c.add_argument("--heights", help="dish_marble: drop heights in m, comma-separated "
                                     "(default: from the scene's marble_speed)")
    c.add_argument("--stiffness", type=float, default=1e7,
                   help="dish: DEM Young's modulus in Pa (1e7)")
    c.add_argument("--dt-fraction", type=float, default=20.0,
                   help="dish: DEM steps per contact time (20)")
    c.add_argument("--ranks", type=int, default=1, help="dish: MPI ranks of the DEM code (1)")
    c.add_argument("--orbits", type=float, default=2.0, help="run length in orbits (2)")
    c.add_argument("--seed", type=int, default=1, help="first seed (1)")
    c.add_argument("--seeds", type=int, default=3, help="replicates: seeds seed.. (3)")
    c.add_argument("--k", type=float, default=3.0, help="agreement within k sigma (3)")
    c.add_argument("--dt-orbits", type=float, default=1e-3,
                   help="REBOUND's step in orbits (1e-3)")
    c.add_argument("--param", action="append", metavar="KEY=VALUE",
                   help="override a scene parameter (repeatable)")
    c.add_argument("--json", action="store_true", help="print one JSON object")
    c.add_argument("--out", metavar="FILE.json", help="also write the JSON report to FILE")
    c.add_argument("--quiet", action="store_true", help="no progress on stderr")
    c.set_defaults(func=cmd_compare)
    rp = sub.add_parser("report", help="run a campaign and write the HTML comparison report")
    rp.add_argument("--scenes", default=",".join(SCENE_NAMES),
                    help=f"comma-separated subset of {','.join(SCENE_NAMES)} (all)")
    mode = rp.add_mutually_exclusive_group()
    mode.add_argument("--quick", dest="mode", action="store_const", const="quick",
                      help="small systems, under 10 minutes on 2 cores (the default)")
    mode.add_argument("--full", dest="mode", action="store_const", const="full",
                      help="paper scale (~200,000 particles in the tables): hours")
    mode.add_argument("--smoke", dest="mode", action="store_const", const="smoke",
                      help="tiny systems, every table and chart (about a minute; for tests)")
    rp.add_argument("--out", default="report", help="output directory (report)")
    rp.add_argument("--cache", help="cache of finished runs (OUT/cache)")
    rp.add_argument("--scheduler", metavar="ADDRESS",
                    help="run on a Dask distributed cluster: 'local' starts one here, else "
                         "the scheduler's address (tcp://host:8786); default: one after "
                         "another in this process")
    rp.add_argument("--no-pictures", action="store_true", help="leave out the scene pictures")
    rp.set_defaults(func=cmd_report, mode="quick")
    return p


def main(argv=None):
    args = parser().parse_args(argv)
    try:
        return args.func(args)
    except InputError as exc:
        print(f"lockgraph: error: {exc}", file=sys.stderr)
        return 2
    except SimulationError as exc:
        print(f"lockgraph: run stopped: {exc}", file=sys.stderr)
        return 3
    except MissingReference as exc:
        print(f"lockgraph: reference code missing: {exc}", file=sys.stderr)
        return 4
    except KeyboardInterrupt:
        print("lockgraph: interrupted; nothing saved", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
