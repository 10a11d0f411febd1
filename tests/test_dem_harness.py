"""The DEM harness without running a DEM code: decks, dumps, contact times,
bad input."""
import math

import numpy as np
import pytest

from lockgraph import dem
from lockgraph.domains import Dish, PeriodicCube, ShearingSheet
from lockgraph.errors import InputError
from lockgraph.forces import Gravity, Hill
from lockgraph.physics import Physics
from lockgraph.restitution import Bridges, CollapseGuard, Constant
from lockgraph.state import State

R = 5e-4


def dish_state():
    pos = np.array([[0.0, 0.0, 0.002], [0.002, 0.0, 0.002], [0.0, 0.0, 0.02]])
    rad = np.array([R, R, 0.005])
    return State(pos, np.zeros((3, 3)), rad, 2330 * 4 / 3 * np.pi * rad ** 3)


DISH = Physics(Dish(0.015), (Gravity(9.81),), Constant(0.8), CollapseGuard(1e-4))


def test_hertz_contact_time_matches_integrated_contact():
    """Integrate m x'' = -k x^1.5 (undamped Hertz) and compare the duration."""
    c = dem.Contact("hertz", 1e8)
    m = 2330 * 4 / 3 * math.pi * R ** 3
    v = 0.7
    tc = dem.contact_time(c, R, R, m, m, 1.0, v)
    meff, rstar = m / 2, R / 2
    estar = 1e8 / (2 * (1 - dem.POISSON ** 2))
    k = 4 / 3 * estar * math.sqrt(rstar)
    x, u, t, h = 0.0, v, 0.0, tc / 2e5
    while True:  # velocity Verlet until the overlap closes again
        a = -k * max(x, 0) ** 1.5 / meff
        u += 0.5 * h * a
        x += h * u
        u += 0.5 * h * (-k * max(x, 0) ** 1.5 / meff)
        t += h
        if x <= 0:
            break
    assert t == pytest.approx(tc, rel=2e-3)


def test_hooke_contact_time_is_the_damped_half_period():
    c = dem.Contact("hooke", 1e3)
    m = 1e-6
    tc = dem.contact_time(c, R, R, m, m, 0.5, 1.0)
    w = math.sqrt(1e3 / (m / 2))
    assert tc == pytest.approx(math.sqrt(math.pi ** 2 + math.log(0.5) ** 2) / w)


def test_time_step_takes_the_shortest_contact():
    st = dish_state()
    dt, tc = dem.time_step(st, DISH, dem.Contact("hertz", 1e7, 20))
    assert dt == pytest.approx(tc / 20)
    speed = dem.impact_speed(st, DISH)
    m = st.mass[0]
    gg = dem.contact_time(dem.Contact("hertz", 1e7), R, R, m, m, 0.8, speed)
    assert tc <= gg * (1 + 1e-12)


@pytest.mark.parametrize("writer", [dem._lammps_deck, dem._liggghts_deck])
def test_deck_has_walls_gravity_and_zero_friction(writer, tmp_path):
    st = dish_state()
    ntypes = dem._data_file(st, DISH, tmp_path / "data.in")
    assert ntypes == 2  # the big body gets its own type
    deck = writer(st, DISH, dem.Contact("hertz", 1e7), 1e-6, 1000, 100, ntypes, 1, None)
    assert "read_data data.in" in deck and "run 1000" in deck
    assert "gravity 9.81" in deck and "zplane 0.0" in deck and "zcylinder 0.015" in deck
    assert "nve/sphere" in deck and "dump out all custom 100" in deck
    if writer is dem._lammps_deck:
        assert "linear_nohistory 0.0 0.0" in deck and "coeff_restitution" in deck
        assert "neighbor" in deck and "multi" in deck
    else:
        assert "coefficientFriction peratomtypepair 2 0.0 0.0 0.0 0.0" in deck
        assert "coefficientRestitution peratomtypepair 2 0.8 0.8 0.8 0.8" in deck
    tracked = writer(st, DISH, dem.Contact("hertz", 1e7), 1e-6, 1000, 100, ntypes, 1, [2])
    assert "group tracked id 3" in tracked and "dump final all custom 1000" in tracked
    data = (tmp_path / "data.in").read_text()
    assert "3 atoms" in data and "Velocities" in data


def test_read_dump_orders_by_id_and_marks_missing(tmp_path):
    text = ("ITEM: TIMESTEP\n0\nITEM: NUMBER OF ATOMS\n2\nITEM: BOX BOUNDS ff ff ff\n"
            "0 1\n0 1\n0 1\nITEM: ATOMS id x y z vx vy vz\n"
            "2 0.5 0.5 0.5 1 2 3\n1 0.1 0.2 0.3 0 0 -1\n"
            "ITEM: TIMESTEP\n10\nITEM: NUMBER OF ATOMS\n1\nITEM: BOX BOUNDS ff ff ff\n"
            "0 1\n0 1\n0 1\nITEM: ATOMS id x y z vx vy vz\n1 0.1 0.2 0.25 0 0 -1\n")
    path = tmp_path / "out.dump"
    path.write_text(text)
    steps, pos, vel = dem.read_dump(path, 2)
    assert steps.tolist() == [0, 10]
    assert pos[0, 0].tolist() == [0.1, 0.2, 0.3] and vel[0, 1].tolist() == [1, 2, 3]
    assert np.isnan(pos[1, 1]).all() and pos[1, 0, 2] == 0.25


def test_thermo_elapsed_reads_the_cpu_column_through_warnings():
    """The wall time at each snapshot comes from the thermo table's ``cpu``
    column (LAMMPS 2024 layout; LIGGGHTS prints the same header); a warning
    inside the table is skipped, and a second run's table is read on."""
    out = """Setting up Verlet run ...
   Step        Atoms        KinEng          CPU
         0        2   0.0001             0
        10        2   0.0002    0.51
WARNING: Lost atoms: original 2 current 2 (src/thermo.cpp:488)
        20        2   0.0003    1.25
Loop time of 1.25 on 1 procs for 20 steps with 2 atoms
Step Atoms KinEng CPU
       20        2   0.0003  0
"""
    assert dem.thermo_elapsed(out).tolist() == [0.0, 0.51, 1.25, 0.0]
    assert "cpu" in dem._run_lines([], 1e-6, 20, 10, "", None)


def test_failures_of_a_clean_and_a_broken_run():
    st = dish_state()
    pos = np.stack([st.pos, st.pos - [0, 0, 1e-4]])
    vel = np.zeros_like(pos)
    res = dem.DemResult("lammps", "", np.array([0.0, 0.1]), pos, vel, 1e-6, 1e-4, 10, 1, 1)
    assert dem.failures(res, st, DISH) == {}
    hot = vel.copy()
    hot[1, 0] = [0, 0, 5.0]  # energy from nowhere
    lost = pos.copy()
    lost[1, 1] = np.nan
    bad = dem.DemResult("lammps", "", np.array([0.0, 0.1]), lost, hot, 1e-6, 1e-4, 10, 1, 1)
    f = dem.failures(bad, st, DISH)
    assert f["lost_particles"] == 1 and f["energy_gain"] > dem.ENERGY_GAIN


def test_bad_input_names_the_field():
    st = dish_state()
    with pytest.raises(InputError, match="against"):
        dem._check(st, DISH, "yade", dem.Contact())
    with pytest.raises(InputError, match="contact.model"):
        dem._check(st, DISH, "liggghts", dem.Contact("hooke", 1e3))
    with pytest.raises(InputError, match="contact.model"):
        dem.Contact("jkr")
    with pytest.raises(InputError, match="contact.stiffness"):
        dem.Contact("hertz", -1.0)
    with pytest.raises(InputError, match="contact.dt_fraction"):
        dem.Contact("hertz", 1e7, float("nan"))
    bridges = Physics(Dish(0.015), (Gravity(9.81),), Bridges(), None)
    with pytest.raises(InputError, match="physics.restitution"):
        dem._check(st, bridges, "lammps", dem.Contact())
    sheet = Physics(ShearingSheet(0.1, 0.1, 1e-4), (Hill(1e-4),), Constant(0.5))
    with pytest.raises(InputError, match="physics.domain"):
        dem._check(st, sheet, "lammps", dem.Contact())
    cube = Physics(PeriodicCube(0.1), (), Constant(0.5))
    dem._check(st, cube, "lammps", dem.Contact())  # two-body runs: allowed
    with pytest.raises(InputError, match="duration"):
        dem.run(st, DISH, "lammps", -1.0)
    with pytest.raises(InputError, match="samples"):
        dem.run(st, DISH, "lammps", 0.1, samples=0)


def test_settled_bed_is_cached_by_its_ranks(tmp_path, monkeypatch):
    """Another MPI decomposition settles another bed (README, Benchmarks), so a
    bed settled on one rank is never served for two: each is made and cached
    under its own key.  The DEM run is stood in for by the block itself, at
    rest (the harness, not the physics, is under test)."""
    from lockgraph import marble_drop as M
    monkeypatch.setenv("LOCKGRAPH_CACHE", str(tmp_path))
    runs = []

    def at_rest(state, physics, code, duration, contact, samples=1, ranks=1, progress=None):
        runs.append(ranks)
        pos = np.stack([state.pos, state.pos])
        return dem.DemResult(code, "test", np.array([0.0, duration]), pos, np.zeros_like(pos),
                             1e-6, 2e-5, 1, 0.0, 0.0)

    monkeypatch.setattr(M.dem, "run", at_rest)
    params = {"cylinder_radius": 0.005}
    one, _, _ = M.settled_bed(60, params=params)
    two, _, _ = M.settled_bed(60, params=params, ranks=2)
    again, _, info = M.settled_bed(60, params=params, ranks=2)
    assert runs == [1, 2]  # the third call is served from the cache
    assert len(list(tmp_path.glob("dem-bed-*.npz"))) == 2
    assert info["dem_wall_s"] == 0.0 and again.sha256() == two.sha256()
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError, match="ranks"):
            M.settled_bed(60, params=params, ranks=bad)
