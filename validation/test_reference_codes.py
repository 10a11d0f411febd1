"""The external reference codes are present and have what the comparisons need.

REBOUND (shearing sheet), LAMMPS with GRANULAR and OPENMP, LIGGGHTS 3.8.
In CI a missing code fails here with the install command in the message.
"""


def test_rebound_has_the_shearing_sheet(rebound):
    sim = rebound.Simulation()
    sim.OMEGA = 1.0
    sim.root_size = 10.0
    sim.N_ghost_x = 1
    sim.N_ghost_y = 1
    sim.integrator = "sei"
    sim.boundary = "shear"
    sim.collision = "tree"
    sim.collision_resolve = "hardsphere"
    sim.dt = 1e-3
    sim.add(m=1.0, r=0.1, x=0.5, vy=-0.75)
    sim.integrate(0.1)
    assert sim.N == 1
    # moving with the shear flow: x stays, y drifts at -1.5 omega x
    assert abs(sim.particles[0].x - 0.5) < 1e-12


def test_lammps_has_granular_and_openmp(lammps):
    lmp = lammps.lammps(cmdargs=["-log", "none", "-screen", "none", "-nocite"])
    try:
        pkgs = lmp.installed_packages
        assert "GRANULAR" in pkgs and "OPENMP" in pkgs, pkgs
    finally:
        lmp.close()


def test_liggghts_runs(liggghts):
    from .references import liggghts_version
    assert "LIGGGHTS" in liggghts_version(liggghts)
