"""Dish observables against exact geometry (no external code needed)."""
import math

import numpy as np
import pytest

from lockgraph import dish_observables as DO
from lockgraph.marble_drop import stop, uehara_exponent, uehara_depth

R = 5e-4


def test_cylinder_volume_whole_cut_and_outside():
    pos = np.array([[0.0, 0.0, 0.01],      # wholly inside
                    [0.0, 0.0, 0.0],        # half below lo = 0
                    [0.02, 0.0, 0.01],      # wholly outside the radius
                    [0.005, 0.0, 0.01]])    # centre on the cylinder surface
    rad = np.full(4, R)
    v = DO.cylinder_volume(pos, rad, 0.005, 0.0, 0.02)
    full = 4 / 3 * math.pi * R ** 3
    assert v[0] == pytest.approx(full, rel=1e-12)
    assert v[1] == pytest.approx(full / 2, rel=1e-12)
    assert v[2] == 0.0
    # a small sphere centred on a large circle: just under half inside (the
    # circle curves away); 24-point quadrature of a kinked integrand: 1e-3
    assert v[3] == pytest.approx(full / 2, rel=2e-2) and v[3] < full / 2


def test_lens_area_limits_and_symmetry():
    big = 1.0
    assert DO._lens(np.array(0.1), np.array(0.0), big) == pytest.approx(math.pi * 0.01)
    assert DO._lens(np.array(0.1), np.array(2.0), big) == 0.0
    assert DO._lens(np.array(3.0), np.array(0.5), big) == pytest.approx(math.pi)
    # two unit circles a distance 1 apart: 2 pi/3 - sqrt(3)/2
    assert DO._lens(np.array(1.0), np.array(1.0), 1.0) == pytest.approx(
        2 * math.pi / 3 - math.sqrt(3) / 2, rel=1e-12)


def cubic_bed(layers=16, side=40, pitch=2 * R):
    g = (np.arange(side) - (side - 1) / 2) * pitch
    x, y, z = np.meshgrid(g, g, R + np.arange(layers) * pitch, indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    return pos, np.full(len(pos), R)


def test_simple_cubic_packing_fraction_is_pi_over_six():
    """A simple cubic lattice of touching spheres fills pi/6 of space; sampled
    away from its edges by exact volumes the bulk fraction is that within the
    lattice's own in-plane discreteness (the circle cuts whole columns)."""
    pos, rad = cubic_bed()
    rc = 0.018  # the lattice spans +-0.0195: the cylinder lies inside it
    phi = DO.packing_fraction(pos, rad, rc)
    assert phi == pytest.approx(math.pi / 6, rel=0.01)


def test_bed_height_of_a_flat_lattice():
    """16 layers of touching spheres: the cross-section fraction falls to half
    the bulk value within a radius of the top layer's top (16 d)."""
    pos, rad = cubic_bed()
    h = DO.bed_height(pos, rad, 0.018)
    assert abs(h - 16 * 2 * R) < R


def test_floor_and_wall_coverage_of_a_layer():
    pos, rad = cubic_bed(layers=1, side=20)
    rc = 0.05
    n = len(pos)
    assert DO.floor_coverage(pos, rad, rc) == pytest.approx(n * math.pi * R ** 2 /
                                                            (math.pi * rc ** 2))
    lifted = pos + [0, 0, 0.2 * R]
    assert DO.floor_coverage(lifted, rad, rc) == 0.0


def test_settle_time_uses_rms_speed():
    t = np.arange(5) * 0.01
    vel = np.zeros((5, 3, 3))
    vel[:3, :, 2] = 0.1  # moving until the third sample
    assert DO.settle_time(t, vel) == pytest.approx(0.03)
    vel[-1, 0, 2] = 1.0  # moving again at the end: never settled
    assert math.isnan(DO.settle_time(t, vel))


def test_marble_stop_depth_and_rest():
    t = np.linspace(0, 0.1, 101)
    z = np.where(t < 0.04, 0.02 - 0.1 * t, 0.016)
    d, rest = stop(t, z, surface=0.015, marble_radius=0.002, grain_diameter=1e-3)
    assert d == pytest.approx(0.015 - 0.014)
    assert rest == pytest.approx(0.04, abs=0.0011)
    moving = 0.02 - 0.1 * t
    assert math.isnan(stop(t, moving, 0.015, 0.002, 1e-3)[1])


def test_marble_rest_by_the_hold_rule():
    """hold: at rest from the first sample whose band (0.05 d) is then kept for
    the hold; depth where the hold ends.  A slow creep (0.5 mm/s < 0.05 d /
    0.04 s) is rest; a creep that leaves the band before the hold is not."""
    t = np.linspace(0, 0.2, 201)
    z = np.where(t < 0.04, 0.02 - 0.1 * t, 0.016)
    d, rest = stop(t, z, 0.015, 0.002, 1e-3, hold=0.03)
    assert rest == pytest.approx(0.04, abs=0.0011)
    assert d == pytest.approx(0.015 - 0.014)
    creep = np.where(t < 0.04, 0.02 - 0.1 * t, 0.016 - 5e-4 * (t - 0.04))
    d, rest = stop(t, creep, 0.015, 0.002, 1e-3, hold=0.04)
    assert rest == pytest.approx(0.04, abs=0.0011)
    assert d == pytest.approx(0.001 + 5e-4 * 0.08, rel=0.02)  # at t = 0.08 s
    # the end-of-run rule dates rest to where the creep comes within 0.05 d of
    # the height at 0.2 s: 0.1 s later
    assert stop(t, creep, 0.015, 0.002, 1e-3)[1] == pytest.approx(0.1, abs=0.0011)
    fast = np.where(t < 0.04, 0.02 - 0.1 * t, 0.016 - 2e-3 * (t - 0.04))
    d, rest = stop(t, fast, 0.015, 0.002, 1e-3, hold=0.04)
    assert math.isnan(rest) and d == pytest.approx(0.015 - (fast[-1] - 0.002))


def test_a_marble_drop_ends_at_rest_by_the_hold_rule():
    """drop_lockgraph with rest=(band, hold) stops at the first sample where
    ``stop``'s hold rule is met, and ``stop`` finds its rest there."""
    from lockgraph import marble_drop as M
    from lockgraph import scenarios

    sc = scenarios.load("dish", "early", n=60, params={"cylinder_radius": 0.003})
    state = M.with_marble(sc.state, sc.physics, 0.001, 2500.0, 0.01)
    band = 1e-3  # wide: the marble is "at rest" as soon as it has moved < 1 mm for 3 ms
    t, z, vz, info = M.drop_lockgraph(state, sc.physics, sc.dt, 0.05, rest=(band, 0.003))
    assert info["stopped_at_rest"] and t[-1] - t[0] < 0.05
    assert t[-1] - t[M.held_since(t, z, band)] >= 0.003
    for m in range(len(t) - 1):  # not met before
        assert t[m] - t[M.held_since(t[:m + 1], z[:m + 1], band)] < 0.003
    d, rest = M.stop(t, z, 0.0, 0.001, band / M.REST_BAND, hold=0.003)
    assert rest == pytest.approx(t[M.held_since(t, z, band)] - t[0])


def test_uehara_exponent_recovers_one_third():
    H = np.array([0.02, 0.08, 0.32])
    d = np.array([uehara_depth(2500, 2330, 0.006, h, 0.5) for h in H])
    assert uehara_exponent(H, d) == pytest.approx(1 / 3, rel=1e-12)


def test_a_run_shorter_than_the_load_window_averages_over_all_of_it():
    """compare_dish.run_lockgraph over 30 ms (< the 100 ms load window): the
    floor load is the mean over the whole run, finite, not an index error."""
    from lockgraph import scenarios
    from lockgraph.compare_dish import LOAD_WINDOW, run_lockgraph

    sc = scenarios.load("dish", "early", n=60, params={"cylinder_radius": 0.003})
    times, pos, vel, load, info = run_lockgraph(sc, 0.03)
    assert times[-1] < LOAD_WINDOW and len(times) == 4
    assert math.isfinite(load) and load >= 0.0  # the block is still falling: little load


def test_a_long_marble_drop_reports_progress(monkeypatch):
    """drop_lockgraph says how far a long run has got (here: every sample)."""
    from lockgraph import marble_drop as M
    from lockgraph import scenarios

    sc = scenarios.load("dish", "early", n=60, params={"cylinder_radius": 0.003})
    state = M.with_marble(sc.state, sc.physics, 0.001, 2500.0, 0.01)
    monkeypatch.setattr(M, "PROGRESS_EVERY", 0.0)
    heard = []
    t, z, vz, info = M.drop_lockgraph(state, sc.physics, sc.dt, 0.003, progress=heard.append)
    assert len(heard) == len(t) - 1 == 3
    assert heard[-1].startswith("lockgraph: 0.0030 of 0.003 s simulated")


@pytest.mark.parametrize("hold", [0.0, -0.01, float("nan")])
def test_a_bad_rest_hold_is_refused_by_name(hold):
    from lockgraph.errors import InputError
    from lockgraph.marble_drop import compare_marble

    with pytest.raises(InputError, match="rest_hold"):
        compare_marble(against="lammps", n=101, rest_hold=hold)
