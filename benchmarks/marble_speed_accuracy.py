"""Speed against accuracy for stopping the marble: lockgraph (1 and 2 threads,
several collapse-guard times, the velocity guards, sleeping grains) against LAMMPS (1 rank,
2 MPI ranks) and LIGGGHTS at several stiffnesses, from the same settled bed.

    python benchmarks/marble_speed_accuracy.py [--seeds 2] [--height 0.08] [--quick] [--out DIR]

(about 15 minutes; ``--quick``: no E = 1e9 reference, the stiffest LAMMPS run
present is the reference)

Bed: the dish block of 1,000 grains in a 5 mm dish settled by LAMMPS at
E = 1e7 Pa (``lockgraph.marble_drop.settled_bed``, one bed per seed, shared by
every method); the marble (radius 1.5 mm, glass) drops from ``--height``
and is followed for 0.15 s.  Error: the seed-mean penetration depth's
difference from the reference's, in grain diameters, and the time to rest's.
Reference: LAMMPS at E = 1e9 Pa, dt = t_c/50.  Wall time: the drops only (the
bed is settled once, before, and cached), summed over seeds.  Writes
DIR/marble_speed_accuracy.csv and .png.
"""
import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from benchmarks.common import chart, write_csv  # noqa: E402
from benchmarks.dem_speed_accuracy import guard, methods, say  # noqa: E402
from lockgraph import dem  # noqa: E402
from lockgraph import marble_drop as M  # noqa: E402
from lockgraph.physics import Physics  # noqa: E402
from lockgraph.simulation import compile_kernels  # noqa: E402

PARAMS = {"cylinder_radius": 0.005}
N = 1000
MARBLE = (0.0015, 2500.0)  # radius m, density kg/m^3
DURATION = 0.15


def drop(bed, sc, settings, height):
    ph = sc.physics
    if "code" in settings:
        contact = dem.Contact("hertz", settings["E"], settings.get("frac", 20.0))
        return M.penetration(bed, ph, sc.dt, *MARBLE, height, DURATION, settings["code"],
                             contact, ranks=settings.get("ranks", 1))
    ph = Physics(ph.domain, ph.forces, ph.restitution, guard(settings))
    return M.penetration(bed, ph, sc.dt, *MARBLE, height, DURATION, "lockgraph",
                         threads=settings["threads"],
                         schedule=settings.get("schedule", "parallel"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--height", type=float, default=0.08)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default="out")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    compile_kernels()
    beds = []
    for seed in range(1, args.seeds + 1):
        say(f"bed {seed}: settling with LAMMPS (cached after the first time)")
        bed, sc, _ = M.settled_bed(N, seed, PARAMS, "lammps", 1e7)
        beds.append((bed, sc))
    results = {}
    for label, family, settings in methods(args.quick):
        runs = []
        for k, (bed, sc) in enumerate(beds):
            say(f"{label}, bed {k + 1}")
            runs.append(drop(bed, sc, settings, args.height))
        results[label] = {"family": family, "wall_s": sum(r["wall_s"] for r in runs),
                          "depth": float(np.mean([r["depth"] for r in runs])),
                          "rest": float(np.nanmean([r["rest_time"] for r in runs]))}
        say(f"{label}: {results[label]['wall_s']:.1f} s")
    ref_label = ([k for k in results if "reference" in k]
                 or [k for k in results if k.startswith("LAMMPS E=1e+08")])[0]
    ref = results[ref_label]
    d = 2 * float(beds[0][0].radius.max())
    rows = [{"method": k, "family": r["family"], "wall_s": r["wall_s"], "depth_m": r["depth"],
             "depth_error_d": abs(r["depth"] - ref["depth"]) / d, "rest_s": r["rest"],
             "rest_error_s": abs(r["rest"] - ref["rest"]), "reference": k == ref_label}
            for k, r in results.items()]
    path = os.path.join(args.out, "marble_speed_accuracy.csv")
    write_csv(rows, path)
    print(f"marble r = {MARBLE[0]} m from {args.height} m into {N} grains, {args.seeds} beds; "
          f"reference {ref_label}")
    print(f"{'method':34s} {'wall s':>8s} {'depth mm':>9s} {'err d':>7s} {'rest s':>7s} "
          f"{'err s':>7s}")
    for r in rows:
        print(f"{r['method']:34s} {r['wall_s']:8.1f} {r['depth_m'] * 1e3:9.3f} "
              f"{r['depth_error_d']:7.3f} {r['rest_s']:7.3f} {r['rest_error_s']:7.3f}")
    png = os.path.join(args.out, "marble_speed_accuracy.png")
    if chart(rows, "depth_error_d", "penetration depth error (grain diameters)",
             f"marble from {args.height:g} m, {N} grains", png, smallest=1e-3):
        print(f"wrote {path} and {png}")


if __name__ == "__main__":
    main()
