"""Observables computed from states and run statistics."""
import numpy as np


def temperature(state):
    """Kinetic temperature k_B T = m <|v - v_cm|^2> / 3 with N - 1 degrees of freedom per axis."""
    n = state.n
    vcm = state.momentum() / state.mass.sum()
    dv = state.vel - vcm
    return float(np.sum(state.mass[:, None] * dv * dv)) / (3.0 * max(n - 1, 1))


def reduced_pressure(state, stats):
    """Z = P V / (N k_B T) of an elastic hard-sphere gas from the collision virial.

    P V = N k_B T + (1 / 3 t) sum_collisions J |r_ij|, summed over the run's
    collisions (J the impulse magnitude, |r_ij| the contact distance) over the
    run's duration t = steps * dt.  Valid when the temperature is constant
    (elastic collisions), as in the ``gas`` scene.
    """
    t = stats["duration"]
    if t <= 0:
        return float("nan")
    kt = temperature(state)
    return 1.0 + stats["virial"] / (3.0 * t * state.n * kt)


def carnahan_starling(eta):
    """Carnahan-Starling compressibility factor Z(eta) of hard spheres."""
    return (1 + eta + eta ** 2 - eta ** 3) / (1 - eta) ** 3
