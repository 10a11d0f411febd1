"""Smooth forces: uniform gravity and Hill's equations.

Splitting (one step of length dt)::

    kick_hill(dt/2) ; drift-with-collisions(dt) ; kick_hill(dt/2)

* ``Hill(omega)``: the shearing sheet's tidal and Coriolis terms,
  ``a = (2 omega v_y + 3 omega^2 x, -2 omega v_x, -omega^2 z)``.  The kick is the
  exact flow of these terms with positions frozen: (v_x, v_y + 1.5 omega x)
  rotates by the angle 2 omega h and v_z changes by -omega^2 z h.  The shear
  flow v = (0, -1.5 omega x, 0) is a fixed point of the kick and moves exactly
  in the drift, so a cold sheet is not heated by the splitting.  Strang
  composition of two exact sub-flows: second order in omega dt.
* ``Gravity(g)``: uniform, along -z.  It is integrated exactly, not split:
  the drift runs in the free-falling frame ``X = x - g t^2/2`` (t since the step
  start), where every particle moves on a straight line, pairs keep their
  linear relative motion, and the floor rises as g t^2 / 2 (see ``predict``).
"""
import math
from dataclasses import dataclass

from ._jit import kernel

from .errors import InputError


def _finite_positive(field, value):
    value = float(value)
    if not (value > 0 and math.isfinite(value)):
        raise InputError(field, f"must be a finite number > 0 (got {value!r})")
    return value


@dataclass(frozen=True)
class Gravity:
    """Uniform gravity of magnitude g (m/s^2) pointing along -z."""
    g: float = 9.81

    def __post_init__(self):
        object.__setattr__(self, "g", _finite_positive("gravity.g", self.g))


@dataclass(frozen=True)
class Hill:
    """Hill's (Clohessy-Wiltshire) equations for a sheet orbiting at rate omega (1/s)."""
    omega: float

    def __post_init__(self):
        object.__setattr__(self, "omega", _finite_positive("hill.omega", self.omega))


@kernel(inline=True)
def hill_coefficients(omega, h):
    """(cos 2 omega h, sin 2 omega h, 3 omega / 2, omega^2 h): ``hill_kicked``'s."""
    return (math.cos(2.0 * omega * h), math.sin(2.0 * omega * h), 1.5 * omega,
            omega * omega * h)


@kernel(inline=True)
def hill_kicked(pos, vel, i, coef):
    """Particle i's velocity after Hill's accelerations for time h with its
    position frozen, as (vx, vy, vz); ``coef = hill_coefficients(omega, h)``.
    ``kick_hill`` applies it to every particle, so whatever else needs a
    kicked velocity gets the same bits."""
    c, s, shear, zk = coef
    vx = vel[i, 0]
    w = vel[i, 1] + shear * pos[i, 0]
    return vx * c + w * s, (w * c - vx * s) - shear * pos[i, 0], vel[i, 2] - zk * pos[i, 2]


@kernel
def kick_hill(pos, vel, omega, h):
    """Apply Hill's accelerations for time h with positions frozen (in place)."""
    coef = hill_coefficients(omega, h)
    for i in range(pos.shape[0]):
        vel[i, 0], vel[i, 1], vel[i, 2] = hill_kicked(pos, vel, i, coef)
