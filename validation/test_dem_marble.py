"""A marble dropped into a settled bed: lockgraph against LAMMPS and LIGGGHTS.

Each DEM code settles its own bed from the dish block (N = 1000 grains in a
5 mm dish, 11 diameters deep, Hertz E = 1e7 Pa), which becomes a hard-sphere
state (radii shrunk by the largest soft overlap, 0.4 %); the marble (radius
1.5 mm, glass) then drops from 2 and 8 cm into that same bed in lockgraph and
in the DEM code, 0.15 s each.

lockgraph runs with the collapse guard at tc = 3e-5 s, not the scene's 1e-4 s:
measured on this bed, tc = 1e-4 s dissipates too little while the marble
ploughs in (depths 2.27 and 2.97 mm against LAMMPS's 2.17 and 3.15 mm; at rest
up to 0.074 s later), tc = 3e-5 s gives 2.15 and 3.17 mm (the speed-accuracy
benchmark shows the same on the settling block's kinetic energy).

The paper-scale case (--paper-scale) is the issue's: a bed >= 40 grain
diameters deep, three drop heights, and Uehara et al.'s H^(1/3) scaling.
"""
import math

import pytest

from lockgraph.marble_drop import DEEP_BED, DEEP_REST_HOLD, compare_marble

CODES = ("lammps", "liggghts")
# Depths agree within half a grain diameter: the marble comes to rest on
# whichever grains it meets, which sets its height to a fraction of d
# (measured, one seed: 0.02-0.3 d apart at tc = 3e-5 s; 0.1-0.2 d at 1e-4 s).
DEPTH_TOL = 0.5
# Times to rest (height within 0.05 d of its final value) agree within 0.08 s:
# the stop takes 0.04-0.13 s, and a marble's last creeps among grains are
# chaotic (measured, one seed, four drops: 0.02-0.05 s apart).
REST_TOL = 0.08
CI = {"n": 1001, "cylinder_radius": 0.005, "marble_radius": 0.0015, "tc": 3e-5}


@pytest.fixture(scope="module")
def marble_reports():
    return {}


@pytest.mark.parametrize("code", CODES)
def test_marble_stops_like_in_dem(dem_code, code, marble_reports):
    dem_code(code)
    res = compare_marble(against=code, n=CI["n"], seeds=(1,), heights=(0.02, 0.08), time=0.15,
                         params={k: v for k, v in CI.items() if k != "n"},
                         depth_tol=DEPTH_TOL, rest_tol=REST_TOL, progress=print)
    marble_reports[code] = res
    for o in res["per_height"]:
        print(code, o)
        for side in ("lockgraph", "reference"):
            assert math.isfinite(o[side]["rest_time"]), (side, o)
            assert o[side]["depth"] > 0
            # the wall time until the sample the marble rests from
            assert 0 < o[side]["rest_wall_s"] <= o[side]["wall_s"], (side, o)
        assert o["depth_agree"] and o["rest_agree"], o
    # a harder drop goes deeper, in both codes
    a, b = res["per_height"]
    for side in ("lockgraph", "reference"):
        assert b[side]["depth"] > a[side]["depth"]
    assert res["reference_failures"] == {}


PAPER = DEEP_BED  # 8,700 grains in a 7.5 mm dish, a 6 mm marble, tc = 3e-5 s
HEIGHTS = (0.02, 0.08, 0.32)
# Uehara et al. (2003) measured d ~ H^(1/3) for frictional grains.  These grains
# are frictionless, and both codes find a weaker law: measured 2026-11-22 on the
# LAMMPS bed with 0.1 s drops, exponents 0.173 (lockgraph) and 0.186 (LAMMPS),
# depths 6.62 / 8.36 / 10.25 mm against 6.31 / 7.96 / 10.09 mm; 2026-11-30 on
# the LIGGGHTS bed (benchmarks/deep_marble.py), 0.167 and 0.191, depths 6.61 /
# 8.24 / 10.07 mm against 6.21 / 8.06 / 10.08 mm; this test itself (rest by the
# hold rule, lockgraph stopping there), 2026-11-30: 0.167 vs 0.190 (LIGGGHTS) and
# 0.172 vs 0.185 (LAMMPS), all depths within 0.4 d.  So the test
# asks lockgraph's exponent to match the DEM code's within EXPONENT_TOL (a 5 %
# depth error at both ends of the 12x range of H, opposite ways, moves the
# slope by 0.04), and states the distance to 1/3 without asserting on it.
EXPONENT_TOL = 0.05


@pytest.mark.paper_scale
@pytest.mark.parametrize("code", CODES)
def test_deep_bed_penetration_and_uehara_scaling(dem_code, code):
    """A bed 40 grain diameters deep (8,700 grains in a 7.5 mm dish), a 6 mm
    marble from 2, 8 and 32 cm: depths and times to rest against the DEM code,
    and the exponent of d against H = h + d (log-log fit) against the DEM
    code's.  Both codes' marbles are at rest by the hold rule (DEEP_REST_HOLD:
    0.04 s within 0.05 d); lockgraph's drops stop there, the DEM code's run
    0.2 s.  Cost, measured 2026-11-30: 35 min (LIGGGHTS) and 44 min
    (LAMMPS) with the bed's settling, the two run at once on the two cores;
    lockgraph's drops 210-930 s each (the resting bed collides 5e9-3e10 times
    per simulated second, more as it compacts under the marble).
    benchmarks/deep_marble.py runs the same drops one at a time."""
    dem_code(code)
    res = compare_marble(against=code, n=PAPER["n"], seeds=(1,), heights=HEIGHTS, time=0.2,
                         params={k: v for k, v in PAPER.items() if k != "n"},
                         depth_tol=DEPTH_TOL, rest_tol=REST_TOL, progress=print,
                         rest_hold=DEEP_REST_HOLD)
    for o in res["per_height"]:
        print(code, o)
        assert o["depth_agree"] and o["rest_agree"], o
    exps = res["uehara_exponent"]
    print(code, "Uehara exponents", exps, "(Uehara et al., frictional grains: 1/3)")
    assert 0.0 < exps["lockgraph"] and 0.0 < exps["reference"]  # deeper from higher
    assert abs(exps["lockgraph"] - exps["reference"]) <= EXPONENT_TOL, exps
