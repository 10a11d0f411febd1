"""The --paper-scale marble test's drops, with each drop's outcome as it comes.

    python benchmarks/deep_marble.py [--against lammps|liggghts] [--time 0.2]
                                     [--hold 0.04] [--heights 0.02,0.08,0.32]
                                     [--out results.json]

The bed and marble of ``validation/test_dem_marble.py::test_deep_bed_...``
(``marble_drop.DEEP_BED``: 8,700 grains settled by the DEM code, 7.5 mm dish,
6 mm glass marble, lockgraph at tc = 3e-5 s), through ``compare_marble``: each
drop's depth, time to rest and wall time are printed when it ends, then the
per-height agreement and the exponent of d against H for each code.  As in the
test, drops are at most ``--time`` s and both codes' marbles are at rest by the
hold rule (``--hold`` s within 0.05 grain diameters; ``--hold 0``: at rest
relative to the height at the end of the drop, and lockgraph runs it all);
lockgraph's drops end there.
"""
import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from lockgraph import dem  # noqa: E402
from lockgraph.marble_drop import DEEP_BED, DEEP_REST_HOLD, compare_marble  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", default="lammps", choices=dem.CODES)
    ap.add_argument("--time", type=float, default=0.2, help="longest drop, s (0.2)")
    ap.add_argument("--hold", type=float, default=DEEP_REST_HOLD,
                    help=f"rest rule's hold, s ({DEEP_REST_HOLD:g}; 0: the end-of-drop rule)")
    ap.add_argument("--heights", default="0.02,0.08,0.32", help="drop heights, m")
    ap.add_argument("--out", help="write the report as JSON")
    args = ap.parse_args()
    heights = tuple(float(h) for h in args.heights.split(","))
    res = compare_marble(against=args.against, n=DEEP_BED["n"], seeds=(1,), heights=heights,
                         time=args.time, params={k: v for k, v in DEEP_BED.items() if k != "n"},
                         progress=lambda msg: print(msg, flush=True),
                         rest_hold=args.hold if args.hold > 0 else None)
    for o in res["per_height"]:
        print(f"{o['height']:g} m: depth lockgraph {o['lockgraph']['depth'] * 1e3:.2f} mm, "
              f"{args.against} {o['reference']['depth'] * 1e3:.2f} mm "
              f"(agree: {o['depth_agree']}); at rest after "
              f"{o['lockgraph']['rest_time']:.3f} / {o['reference']['rest_time']:.3f} s "
              f"(agree: {o['rest_agree']})")
    print("exponents of d against H:", res["uehara_exponent"])
    print("wall s:", res["wall_s"])
    if args.out:
        res.pop("runs")
        with open(args.out, "w") as fh:
            json.dump(res, fh, indent=1)


if __name__ == "__main__":
    main()
