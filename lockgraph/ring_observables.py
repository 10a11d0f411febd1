"""Planetary-ring observables of a shearing-sheet patch, the same for every code.

Conventions (Wisdom & Tremaine 1988; Salo 1991): x radial, y azimuthal, z
vertical; the shear flow is v_y = -1.5 Omega x.  Velocities are taken relative
to it (v_y' = v_y + 1.5 Omega x), averages are mass-weighted, A = lx * ly.

Instantaneous (``snapshot``), from positions and velocities:

* ``sigma_x``, ``sigma_y``, ``sigma_z`` (m/s): rms velocity relative to the
  shear flow (after removing the mean).
* ``thickness`` (m): rms height about the mean height.
* ``tau`` (-): dynamical optical depth sum(pi r^2) / A (changes only if a code
  loses particles).
* ``filling_midplane`` (-): volume filling factor in the plane z = mean height,
  sum(pi (r^2 - dz^2)) / A over the particles that cut it.
* ``nu_trans`` (m^2/s): translational viscosity <v_x v_y'> / (1.5 Omega).

Over a run (``rates``), from collision statistics:

* ``collision_rate`` (-): pair collisions per particle per orbit (each
  collision counts for both particles).
* ``nu_coll`` (m^2/s): collisional viscosity
  sum((x_i - x_j) dp_y,i) / (M 1.5 Omega T), dp_y,i the y momentum given to
  particle i, x_i - x_j their radial separation at contact, M the total mass
  and T the duration.
"""
import math

import numpy as np

SNAPSHOT = ("sigma_x", "sigma_y", "sigma_z", "thickness", "tau", "filling_midplane",
            "nu_trans")
RATES = ("collision_rate", "nu_coll")
UNITS = {"sigma_x": "m/s", "sigma_y": "m/s", "sigma_z": "m/s", "thickness": "m", "tau": "-",
         "filling_midplane": "-", "nu_trans": "m^2/s", "collision_rate": "1/orbit",
         "nu_coll": "m^2/s"}


def snapshot(pos, vel, radius, mass, omega, lx, ly):
    """Instantaneous observables (dict) of N particles: pos, vel (N,3) in m and
    m/s (full velocities, shear flow included), radius, mass (N,) in m and kg."""
    pos = np.asarray(pos, float)
    vel = np.asarray(vel, float)
    radius = np.asarray(radius, float)
    w = np.asarray(mass, float)
    m = w.sum()
    u = vel.copy()
    u[:, 1] += 1.5 * omega * pos[:, 0]
    u -= (w[:, None] * u).sum(axis=0) / m
    sig = np.sqrt((w[:, None] * u * u).sum(axis=0) / m)
    z = pos[:, 2] - (w * pos[:, 2]).sum() / m
    area = lx * ly
    cut = np.clip(radius ** 2 - z ** 2, 0.0, None)
    return {"sigma_x": float(sig[0]), "sigma_y": float(sig[1]), "sigma_z": float(sig[2]),
            "thickness": float(math.sqrt((w * z * z).sum() / m)),
            "tau": float(np.pi * (radius ** 2).sum() / area),
            "filling_midplane": float(np.pi * cut.sum() / area),
            "nu_trans": float((w * u[:, 0] * u[:, 1]).sum() / m / (1.5 * omega))}


def rates(pair_collisions, momentum_flux_xy, n, total_mass, omega, duration):
    """Observables over a run of ``duration`` s: see the module docstring."""
    orbits = duration * omega / (2.0 * math.pi)
    return {"collision_rate": 2.0 * pair_collisions / (n * orbits),
            "nu_coll": momentum_flux_xy / (total_mass * 1.5 * omega * duration)}


def mean_snapshots(samples):
    """Average a list of ``snapshot`` dicts key by key."""
    return {k: float(np.mean([s[k] for s in samples])) for k in samples[0]}
