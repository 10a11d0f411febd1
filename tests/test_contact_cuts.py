"""Contact-time cuts: ``pair_time_by``, ``floor_time_by`` and
``cylinder_time_by`` skip the square root of a contact that cannot beat the
best event so far, and must never change a time the caller keeps.

Whenever the uncut function returns a time <= the cut, the cut one must return
the same bits; otherwise inf or that same later time.  Drawn: pairs
approaching, receding, grazing (paths nearly tangent: the root's rounding is
worst) and overlapping; grains on, just above and far above the floor, moving
up or down, at, near and far inside the cylinder; paths begun at the step
start or late in it (the wall times are solved from the path's start); cuts at,
one unit in the last place above and just below the true contact time, where a
too-tight bound would show.
"""
import math

import numpy as np

from lockgraph.predict import (CUT_MARGIN, cylinder_time, cylinder_time_by, floor_time,
                               floor_time_by, pair_time, pair_time_by)

IMG_POS = np.zeros((1, 3))
IMG_VEL = np.zeros((1, 3))
T_END = 1e-3  # s, the step
G = 9.81
R = 5e-4  # grain radius (m)
RCYL = 5e-3  # cylinder radius (m)


def _cuts(t, t_now):
    cuts = [t_now, T_END, math.inf]
    if t < math.inf:
        cuts += [t, math.nextafter(t, math.inf), t * (1 + 1e-12), max(t_now, t * (1 - 1e-12))]
    return [c for c in cuts if c <= T_END or c == math.inf]


def _check(uncut, cut_fn, cases):
    """Every kept time is bitwise the uncut one; returns how many were kept."""
    kept = 0
    for args in cases:
        for t_now in args[-1]:
            t = uncut(*args[:-1], t_now, T_END)
            for cut in _cuts(t, t_now):
                tb = cut_fn(*args[:-1], t_now, T_END, min(cut, T_END))
                if t <= cut:
                    assert tb == t, (args, t_now, t, tb, cut)
                    kept += 1
                else:
                    assert tb == t or tb == math.inf, (args, t_now, t, tb, cut)
    return kept


def _pairs(rng, n):
    for k in range(n):
        kind = k % 4
        d = rng.normal(size=3)
        d *= (1e-3 + rng.exponential(2e-5)) / np.linalg.norm(d)  # 1 mm contact, small gaps
        u = rng.normal(size=3) * 10 ** rng.uniform(-4, 0)
        if kind == 1:  # grazing: relative velocity almost perpendicular to the offset
            u -= (u @ d) / (d @ d) * d * (1 - 10 ** rng.uniform(-12, -2))
        if kind == 2:  # overlapping by a little
            d *= 1 - 10 ** rng.uniform(-12, -4)
        pos = np.array([d, [0.0, 0.0, 0.0]])
        vel = np.array([u, [0.0, 0.0, 0.0]])
        yield pos, vel, 0, 1, 0, IMG_POS, IMG_VEL, 1e-3, (0.0, 1e-5)


def _grains(rng, n):
    """One grain (slot 0) with a path begun at tl[0], as the engine stores it:
    the false position pos = x(tl) - vel tl in the free-falling frame."""
    for k in range(n):
        t0 = (0.0, 3e-4, 9.99e-4)[k % 3]
        gap = (0.0, 1e-12, 1e-7, 1e-5, 1e-3)[k % 5] * rng.uniform(0.5, 1.5)
        rho = RCYL - R - (0.0, 1e-12, 1e-7, 1e-5, 3e-3)[(k // 5) % 5] * rng.uniform(0.5, 1.5)
        phi = rng.uniform(0, 2 * math.pi)
        x = np.array([rho * math.cos(phi), rho * math.sin(phi), R + gap])
        v = rng.normal(size=3) * 10 ** rng.uniform(-5, 0)  # real velocity at t0
        vel = v.copy()
        vel[2] += G * t0  # frame velocity
        pos = x - vel * t0
        pos[2] += 0.5 * G * t0 * t0
        tl = np.array([t0])
        yield (pos[None, :], vel[None, :], tl, 0, R, t0,
               tuple(t for t in (t0, min(T_END * 0.999, t0 + 1e-5)) if t < T_END))


def test_pair_cut_never_changes_a_kept_time():
    assert _check(pair_time, pair_time_by, _pairs(np.random.default_rng(5), 4000)) > 4000


def test_floor_cut_never_changes_a_kept_time():
    cases = [(p, v, tl, i, r, G, tn) for p, v, tl, i, r, _, tn in
             _grains(np.random.default_rng(6), 3000)]
    assert _check(floor_time, floor_time_by, cases) > 1000


def test_cylinder_cut_never_changes_a_kept_time():
    cases = [(p, v, tl, i, r, RCYL, tn) for p, v, tl, i, r, _, tn in
             _grains(np.random.default_rng(7), 3000)]
    assert _check(cylinder_time, cylinder_time_by, cases) > 1000


def test_cuts_skip_contacts_that_come_late():
    """The bounds are useful: a contact that surely comes after the cut is not solved."""
    pos = np.array([[2e-3, 0.0, 0.0], [0.0, 0.0, 0.0]])  # gap 1 mm
    vel = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])  # meets at 1 ms
    assert pair_time(pos, vel, 0, 1, 0, IMG_POS, IMG_VEL, 1e-3, 0.0, 1.0) == 1e-3
    assert pair_time_by(pos, vel, 0, 1, 0, IMG_POS, IMG_VEL, 1e-3, 0.0, 1.0, 0.4e-3) == math.inf
    assert CUT_MARGIN - 1 < 1e-6
    # a grain 1 mm above the floor, falling at 1 m/s, lands after about 1 ms
    g = (np.array([[0.0, 0.0, R + 1e-3]]), np.array([[0.0, 0.0, -1.0]]), np.zeros(1), 0, R)
    assert 0.9e-3 < floor_time(*g, G, 0.0, 1.0) < 1e-3
    assert floor_time_by(*g, G, 0.0, 1.0, 0.5e-3) == math.inf
    # a grain 1 mm from the cylinder, moving out at 1 m/s
    c = (np.array([[RCYL - R - 1e-3, 0.0, R]]), np.array([[1.0, 0.0, 0.0]]), np.zeros(1), 0, R)
    assert math.isclose(cylinder_time(*c, RCYL, 0.0, 1.0), 1e-3)
    assert cylinder_time_by(*c, RCYL, 0.0, 1.0, 0.5e-3) == math.inf
