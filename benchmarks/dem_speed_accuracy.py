"""Speed against accuracy on the settling dish: lockgraph (1 and 2 threads, four
collapse-guard times, the hard and the soft velocity guard at three speeds each, the soft one
also at a 1 ms step, and sleeping grains at three speeds) against LAMMPS
(1 rank, 2 MPI ranks) and LIGGGHTS at several contact stiffnesses, all from
the same falling block.

    python benchmarks/dem_speed_accuracy.py [--n 1000] [--time 0.35] [--seeds 2]
                                            [--dish-radius 0.005] [--quick]
                                            [--only TEXT ...] [--reference-cache DIR]
                                            [--out DIR]

(about 35 minutes at the defaults; ``--quick``: no E = 1e9 reference run, the
stiffest LAMMPS run present is the reference, about 8 minutes)

Scene: the dish block of N grains in a 5 mm dish (an 11-diameter bed at
N = 1000; ``--dish-radius 0.015 --n 2000``: the dish scene's own dish and
grains, a bed three grains deep), run for ``--time`` s: the fall, the
impact and the settling.

Error: the largest difference, over the sampled times (every 10 ms), of the
seed-averaged kinetic energy from the reference's, divided by the
reference's largest kinetic energy; and the settling time (rms speed below
3 mm/s) against the reference's.  Reference: LAMMPS at E = 1e9 Pa with
dt = t_c/50 — a soft-sphere code converges to hard spheres as its contacts
stiffen, and the two-body tests show it does so at 0.4 per decade of E.
Noise floor: how far two methods' means over the k seeds differ without any
method error (the fall is chaotic): sqrt(2 / k) times the standard deviation
of the reference's own seeds, the largest over the sampled times (k = 2: the
two seeds' difference over sqrt(2)).

Wall time: the whole run of each method, summed over seeds, measured in this
process one after another, seed by seed with every method in turn (DEM codes
as subprocesses, their startup included); and the wall time to settle: up to the sample from which the bed
stays settled (lockgraph's clock at that sample; the DEM code's start-up plus
its own elapsed-time column there), summed over seeds, compared at matched
settling time and kinetic energy (noise floor of the settling time: as the
kinetic energy's).  ``--only TEXT`` runs the methods whose label contains
TEXT, and the reference.  ``--reference-cache DIR`` keeps each seed's
reference run in DIR (keyed by N, time, dish radius and seed; written whole)
and reuses it: the reference is the accuracy yardstick only, its wall time
enters no ratio, so it may be computed once, or beforehand on the other core
(``reference_run``).  Writes DIR/dem_speed_accuracy.csv and .png and prints, per
method, wall time, errors, and lockgraph's time as a fraction of LAMMPS's at
matched accuracy (target <= 1/5).
"""
import argparse
import dataclasses
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from benchmarks.common import cached_npz, chart, noise_floor, write_csv  # noqa: E402
from lockgraph import dem, scenarios  # noqa: E402
from lockgraph import dish_observables as DO  # noqa: E402
from lockgraph.compare_dish import run_dem, run_lockgraph  # noqa: E402
from lockgraph.restitution import CollapseGuard, VelocityGuard  # noqa: E402
from lockgraph.simulation import compile_kernels  # noqa: E402

PARAMS = {"cylinder_radius": 0.005}
REFERENCE = ("LAMMPS E=1e+09 (reference)", "LAMMPS", {"code": "lammps", "E": 1e9, "frac": 50})


def say(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


# (v_sleep m/s, t_sleep s, step s or None: the scene's) of the sleeping-grain
# runs.  Measured 2026-12-02 and left out: v_sleep 2 cm/s without the wait,
# t_sleep = 5 ms (costlier, no closer), 2 cm/s with 2 ms (the bed 0.27 d too
# tall); steps of 0.3 and 0.5 ms (an asleep grain rises at g dt / 2 in the
# falling frame, 1.5-2.5 mm/s: fewer grains sleep, and at 0.5 ms the bed
# never settles)
SLEEPS = ((5e-3, 0.0, None), (1e-2, 0.0, None), (1e-2, 2e-3, None), (1e-2, 2e-3, 2e-4),
          (1.5e-2, 2e-3, 2e-4))


def sleep_label(v_sleep, t_sleep, dt=None):
    return (f"lockgraph v_min=0.02 soft, v_sleep={v_sleep:g}"
            + (f", t_sleep={t_sleep:g}" if t_sleep else "")
            + (f", dt={dt * 1e3:g}ms" if dt else ""))


def methods(quick):
    """(label, family, settings) of every method run."""
    # lockgraph's accuracy knob is the collapse guard's tc (impacts within tc
    # of a grain's last one are elastic: less dissipation than the real e);
    # the scene's tc is 1e-4 s
    out = [(f"lockgraph tc={tc:g}", "lockgraph", {"threads": 1, "tc": tc})
           for tc in (3e-4, 1e-4, 3e-5, 1e-5)]
    # 2 threads, schedule auto: each step's events on the threads or on one
    # thread, whichever measured cheaper (on these beds: mostly one thread;
    # always on the threads took 3x the 1-thread time on 2026-11-22)
    out += [(f"lockgraph tc={tc:g}, 2 threads auto", "lockgraph 2 threads",
             {"threads": 2, "tc": tc, "schedule": "auto"}) for tc in (1e-4, 1e-5)]
    # the velocity guard instead (impacts slower than v_min elastic): it keeps
    # dissipating in the dense bed, where the TC model makes ~all impacts elastic
    out += [(f"lockgraph v_min={v:g}", "lockgraph velocity guard", {"threads": 1, "v_guard": v})
            for v in (2e-2, 1e-2, 5e-3)]
    # the soft velocity guard (below v_min, e rises to 1 as (v / v_min)^2): the
    # bed settles, which it never does below the hard guard's v_min
    out += [(f"lockgraph v_min={v:g} soft", "lockgraph soft velocity guard",
             {"threads": 1, "v_guard": v, "v_exponent": 2.0}) for v in (3e-2, 2e-2, 1.5e-2)]
    # the step is lockgraph's cost knob only (collisions are resolved at their
    # exact times whatever the step; the velocity guards do not depend on it):
    # a 1 ms step spreads each step's tree, search and first predictions over
    # ten times the collisions of the scene's 0.1 ms
    out += [(f"lockgraph v_min={v:g} soft, dt=1ms", "lockgraph soft velocity guard",
             {"threads": 1, "v_guard": v, "v_exponent": 2.0, "dt": 1e-3}) for v in (3e-2, 2e-2)]
    # sleeping grains (the soft guard, and a grain slower than v_sleep after
    # an impact on the floor or a sleeper sleeps): a hard-sphere bed carries
    # its weight by collisions, at a rate growing with its depth; asleep, a
    # grain carries it without any.  At the scene's step: an asleep grain
    # rises and comes back by g dt^2 / 8 a step, at up to g dt / 2 (5 mm/s
    # at a 1 ms step, where it then wakes its neighbours).  Asleep at the end
    # of the step of its first slow impact on a support, a grain has had no
    # time to slide into a pocket and the bed ends looser; waiting t_sleep of
    # slow impacts first (with any partner; faster than v_sleep at a step end
    # it wakes) it has, and the bed's structure agrees with LAMMPS's
    # (validation/test_dem_dish.py)
    out += [(sleep_label(v, t, dt), "lockgraph sleeping grains",
             {"threads": 1, "v_guard": 2e-2, "v_exponent": 2.0, "v_sleep": v, "t_sleep": t,
              **({"dt": dt} if dt else {})})
            for v, t, dt in SLEEPS]
    out.append((sleep_label(1e-2, 2e-3, 2e-4) + ", 2 threads auto",
                "lockgraph 2 threads", {"threads": 2, "v_guard": 2e-2, "v_exponent": 2.0,
                                        "v_sleep": 1e-2, "t_sleep": 2e-3, "dt": 2e-4,
                                        "schedule": "auto"}))
    # 3e7 between: the matched LAMMPS run is measured, not interpolated
    for e_mod in (1e7, 3e7, 1e8):
        out.append((f"LAMMPS E={e_mod:g}", "LAMMPS", {"code": "lammps", "E": e_mod}))
    out.append(("LAMMPS E=1e+08, 2 ranks", "LAMMPS 2 ranks",
                {"code": "lammps", "E": 1e8, "ranks": 2}))
    for e_mod in (1e7, 1e8):
        out.append((f"LIGGGHTS E={e_mod:g}", "LIGGGHTS", {"code": "liggghts", "E": e_mod}))
    if not quick:
        out.append(REFERENCE)
    return out


# the 1-thread lockgraph families, each set against LAMMPS at matched accuracy
ONE_THREAD = ("lockgraph", "lockgraph velocity guard", "lockgraph soft velocity guard",
              "lockgraph sleeping grains")


def guard(settings):
    """lockgraph's collapse guard for a method's settings."""
    if "v_guard" in settings:
        return VelocityGuard(settings["v_guard"], settings.get("v_exponent", 0.0),
                             settings.get("v_sleep", 0.0), settings.get("t_sleep", 0.0))
    return CollapseGuard(settings["tc"])


def run_one(settings, n, seed, duration, params=PARAMS):
    sc = scenarios.load("dish", "early", n=n, seed=seed, params=params)
    if "threads" in settings:
        sc.physics = dataclasses.replace(sc.physics, guard=guard(settings))
        sc.dt = settings.get("dt", sc.dt)
    if "code" in settings:
        contact = dem.Contact("hertz", settings["E"], settings.get("frac", 20.0))
        t, p, v, _, info = run_dem(sc, settings["code"], duration, contact,
                                   ranks=settings.get("ranks", 1))
    else:
        t, p, v, _, info = run_lockgraph(sc, duration, threads=settings["threads"],
                                         schedule=settings.get("schedule", "parallel"))
    ke = 0.5 * np.nansum(sc.state.mass[None, :] * np.sum(v ** 2, axis=2), axis=1)
    settle = DO.settle_time(t, v)
    # the wall time until the bed is settled (measured at every sample: lockgraph's
    # clock, the DEM code's own elapsed-time column plus its start-up)
    walls = np.asarray(info["sample_wall"], float)
    settle_wall = (float(walls[int(np.flatnonzero(t == settle)[0])]) if settle == settle
                   else math.nan)
    return {"times": t, "ke": ke, "settle": settle, "wall_s": info["wall_s"],
            "settle_wall": settle_wall}


def reference_run(cache, n, seed, duration, params):
    """One seed's reference run, from ``cache`` (a directory) when it holds it,
    else run and stored there (written whole: an interrupted run leaves none).
    ``python -c "from benchmarks.dem_speed_accuracy import reference_run;
    reference_run('out/ref', 2000, 3, 0.6, {'cylinder_radius': 0.015})"`` fills it beforehand."""
    key = f"reference-n{n}-t{duration:g}-r{params['cylinder_radius']:g}-s{seed}"
    path = os.path.join(cache, key + ".npz")
    res, kept = cached_npz(path, lambda: run_one(REFERENCE[2], n, seed, duration, params))
    if kept:
        say(f"reference, seed {seed}: from {path}")
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000)
    ap.add_argument("--time", type=float, default=0.35)
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="out")
    ap.add_argument("--dish-radius", type=float, default=PARAMS["cylinder_radius"],
                    help="cylinder radius, m (0.005; the dish scene's own: 0.015)")
    ap.add_argument("--reference-cache", metavar="DIR",
                    help="keep and reuse the reference's runs in DIR")
    ap.add_argument("--only", action="append", default=None, metavar="TEXT",
                    help="run only the methods whose label contains TEXT (repeatable; "
                         "the reference always runs)")
    args = ap.parse_args()
    if args.seeds < 2:
        ap.error("--seeds must be at least 2 (the noise floors come from the seeds' spread)")
    os.makedirs(args.out, exist_ok=True)
    compile_kernels()
    chosen = [m for m in methods(args.quick)
              if not args.only or "reference" in m[0] or any(t in m[0] for t in args.only)]
    # seed by seed, every method in turn: a machine whose speed drifts over the
    # run (measured: 10-30 % between runs half an hour apart) then slows every
    # method alike instead of the ones that happened to run late
    params = {"cylinder_radius": args.dish_radius}
    by_label = {label: [] for label, _, _ in chosen}
    for seed in range(1, args.seeds + 1):
        for label, family, settings in chosen:
            say(f"{label}, seed {seed}")
            if label == REFERENCE[0] and args.reference_cache:
                by_label[label].append(reference_run(args.reference_cache, args.n, seed,
                                                     args.time, params))
            else:
                by_label[label].append(run_one(settings, args.n, seed, args.time, params))
    results = {}
    for label, family, settings in chosen:
        runs = by_label[label]
        results[label] = {"family": family, "runs": runs,
                          "wall_s": sum(r["wall_s"] for r in runs),
                          "ke": np.mean([r["ke"] for r in runs], axis=0),
                          "settle": float(np.nanmean([r["settle"] for r in runs])),
                          # NaN unless every seed settles
                          "settle_wall": sum(r["settle_wall"] for r in runs)}
        say(f"{label}: {results[label]['wall_s']:.1f} s")
    ref_label = [k for k in results if "reference" in k] or \
        [k for k in results if k.startswith("LAMMPS E=1e+08")]
    ref = results[ref_label[0]]
    scale = float(ref["ke"].max())
    # noise floors, from the reference's seeds (k = 2: their difference over sqrt(2))
    floor = noise_floor([r["ke"] for r in ref["runs"]]) / scale
    sfloor = noise_floor([r["settle"] for r in ref["runs"]])
    rows = []
    for label, r in results.items():
        err = float(np.max(np.abs(r["ke"] - ref["ke"]))) / scale
        rows.append({"method": label, "family": r["family"], "wall_s": r["wall_s"],
                     "ke_error": err, "settle_time": r["settle"],
                     "settle_error": abs(r["settle"] - ref["settle"]),
                     "settle_wall_s": r["settle_wall"],
                     "reference": label == ref_label[0]})
    path = os.path.join(args.out, "dem_speed_accuracy.csv")
    write_csv(rows, path)
    print(f"N = {args.n}, dish radius {args.dish_radius * 1e3:g} mm, {args.time:g} s of "
          f"settling, {args.seeds} seeds; reference "
          f"{ref_label[0]}; noise floors: kinetic energy {floor:.3f}, settling time "
          f"{sfloor:.3f} s")
    print(f"{'method':38s} {'wall s':>8s} {'KE error':>9s} {'settle s':>9s} {'settle err':>10s} "
          f"{'wall to settle s':>16s}")
    for r in rows:
        print(f"{r['method']:38s} {r['wall_s']:8.1f} {r['ke_error']:9.3f} "
              f"{r['settle_time']:9.3f} {r['settle_error']:10.3f} {r['settle_wall_s']:16.1f}")
    la = [r for r in rows if r["family"] == "LAMMPS" and not r["reference"]]
    # matched accuracy: for each 1-thread lockgraph run, the cheapest LAMMPS run
    # (1 rank, reference aside) at least as accurate (errors under the noise
    # floor count as equal to it)
    for lg in (r for r in rows if r["family"] in ONE_THREAD):
        eps = max(lg["ke_error"], floor)
        match = [r for r in la if r["ke_error"] <= eps]
        worse = lg["ke_error"] > 2 * max(r["ke_error"] for r in la)
        best = (min(la, key=lambda r: r["wall_s"]) if worse
                else min(match, key=lambda r: r["wall_s"]) if match
                else min(la, key=lambda r: r["ke_error"]))
        verdict = ("less accurate than every LAMMPS run: not a match (a softer LAMMPS run "
                   "would be cheaper still)" if worse
                   else "cheapest LAMMPS run as accurate (target <= 0.2)" if match
                   else "no LAMMPS run as accurate: LAMMPS's best, at lockgraph's better accuracy")
        print(f"{lg['method']} (KE error {lg['ke_error']:.3f}, {lg['wall_s']:.1f} s) vs "
              f"{best['method']} ({best['ke_error']:.3f}, {best['wall_s']:.1f} s): ratio "
              f"{lg['wall_s'] / best['wall_s']:.2f}; {verdict}")
    # matched accuracy of the settled bed: the wall time until each run's bed
    # settled, against the cheapest LAMMPS run whose settling time and kinetic
    # energy are both at least as accurate (under the noise floors: equal)
    print("time to settle, at matched settling time and kinetic energy:")
    for lg in (r for r in rows if r["family"] in ONE_THREAD):
        if lg["settle_wall_s"] != lg["settle_wall_s"]:
            print(f"{lg['method']}: a seed's bed never settles (rms above "
                  f"{DO.SETTLE_RMS * 1e3:g} mm/s at {args.time:g} s): no time to settle")
            continue
        s_eps = max(lg["settle_error"], sfloor)
        k_eps = max(lg["ke_error"], floor)
        match = [r for r in la if r["settle_error"] <= s_eps and r["ke_error"] <= k_eps]
        if not match:
            print(f"{lg['method']} (settling error {lg['settle_error']:.3f} s, KE error "
                  f"{lg['ke_error']:.3f}): no LAMMPS run as accurate on both")
            continue
        best = min(match, key=lambda r: r["settle_wall_s"])
        print(f"{lg['method']} (settling error {lg['settle_error']:.3f} s, KE error "
              f"{lg['ke_error']:.3f}, settled after {lg['settle_wall_s']:.1f} s) vs "
              f"{best['method']} ({best['settle_error']:.3f} s, {best['ke_error']:.3f}, "
              f"{best['settle_wall_s']:.1f} s): ratio "
              f"{lg['settle_wall_s'] / best['settle_wall_s']:.2f} (target <= 0.2)")
    png = os.path.join(args.out, "dem_speed_accuracy.png")
    png2 = os.path.join(args.out, "dem_time_to_settle.png")
    if chart(rows, "ke_error", "kinetic-energy error (fraction of the peak)",
             f"dish settling, N = {args.n}, {args.time:g} s", png, floor=floor) and \
            chart(rows, "settle_error", "settling-time error (s)",
                  f"dish settling, N = {args.n}: time to settle", png2, floor=sfloor,
                  smallest=1e-3, wall_key="settle_wall_s", ylabel="wall time to settle (s)"):
        print(f"wrote {path}, {png} and {png2}")


if __name__ == "__main__":
    main()
