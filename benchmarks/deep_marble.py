"""The --paper-scale marble test's drops, one height at a time, with results as they come.

    python benchmarks/deep_marble.py [--against lammps|liggghts] [--time 0.1]
                                     [--heights 0.02,0.08,0.32]

The bed and marble of ``validation/test_dem_marble.py::test_deep_bed_...``
(8,700 grains settled by the DEM code, 7.5 mm dish, 6 mm glass marble,
lockgraph at tc = 3e-5 s): for each drop height lockgraph and the DEM code run
``--time`` seconds and a line ``RESULT {json}`` is printed at once (depth,
time to rest, H, wall time), then the exponent of d against H for each code.
The test runs 0.2 s drops, which cost hours per code (see README); 0.1 s
drops give the depths and the exponent in ~30 min of lockgraph per code.
"""
import argparse
import json
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from lockgraph import dem, scenarios  # noqa: E402
from lockgraph import marble_drop as M  # noqa: E402

PAPER = {"cylinder_radius": 0.0075, "marble_radius": 0.003, "tc": 3e-5}  # as the test


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--against", default="lammps", choices=dem.CODES)
    ap.add_argument("--time", type=float, default=0.1, help="seconds per drop (0.1)")
    ap.add_argument("--heights", default="0.02,0.08,0.32", help="drop heights, m")
    args = ap.parse_args()
    heights = [float(h) for h in args.heights.split(",")]
    p = scenarios.resolve_params(scenarios.read("dish_marble"), 8701, 1, None, PAPER)
    bed_params = {k: v for k, v in PAPER.items() if k not in M.MARBLE_KEYS}
    bed, sc, info = M.settled_bed(8700, 1, bed_params, args.against, 1e7, progress=print)
    print("bed", json.dumps({k: v for k, v in info.items() if k != "shrink"}), flush=True)
    contact = dem.Contact("hertz", 1e7, 20.0)
    rows = []
    for h in heights:
        for code in ("lockgraph", args.against):
            r = M.penetration(bed, sc.physics, sc.dt, p["marble_radius"], p["marble_density"],
                              h, args.time, code, contact, progress=print)
            out = {k: v for k, v in r.items() if k not in ("trajectory", "info")}
            print("RESULT", json.dumps(out), flush=True)
            rows.append(r)
    if len(heights) >= 2:
        for code in ("lockgraph", args.against):
            rs = [r for r in rows if r["code"] == code]
            print("EXPONENT", code, M.uehara_exponent([r["H"] for r in rs],
                                                      [r["depth"] for r in rs]))


if __name__ == "__main__":
    main()
