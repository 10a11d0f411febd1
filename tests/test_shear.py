"""Shearing sheet: Hill's equations, boundary crossings, collisions across the boundary."""
import math

import numpy as np
import pytest

from lockgraph.engine import Engine
from lockgraph.restitution import Constant
from lockgraph.state import State

from .helpers import sheet

OMEGA = 1e-3


def hill_exact(x0, y0, vx0, vy0, t, w=OMEGA):
    """Closed-form solution of x'' = 2w y' + 3w^2 x, y'' = -2w x'."""
    s, c = math.sin(w * t), math.cos(w * t)
    x = 4 * x0 + 2 * vy0 / w + vx0 / w * s - (3 * x0 + 2 * vy0 / w) * c
    y = y0 - 2 * vx0 / w + 2 * vx0 / w * c + (6 * x0 + 4 * vy0 / w) * s - (6 * w * x0 + 3 * vy0) * t
    return x, y


@pytest.mark.parametrize("steps_per_orbit", [200, 400])
def test_hill_splitting_second_order(steps_per_orbit):
    """One free particle over one orbit: KDK with exact sub-flows is second order."""
    period = 2 * math.pi / OMEGA
    dt = period / steps_per_orbit
    x0, vx0, vy0 = 2.0, 0.001, -1.5 * OMEGA * 2.0 + 0.0005
    st = State([[x0, 0.0, 0.0]], [[vx0, vy0, 0.0]], [0.1], [1.0])
    eng = Engine(st, sheet(lx=200.0, ly=1e4, omega=OMEGA), dt)
    for _ in range(steps_per_orbit):
        eng.step()
    x, y = hill_exact(x0, 0.0, vx0, vy0, period)
    got = eng.state().pos[0]
    err = math.hypot(got[0] - x, got[1] - y)
    # amplitude of the epicycle ~ vx0 / omega = 1 m; splitting error ~ (omega dt)^2
    # times that, with a constant measured at 200 steps/orbit: 0.2 m -> allow 2x
    assert err < 0.4 * (200 / steps_per_orbit) ** 2


def test_hill_error_ratio():
    """Halving dt cuts the error by about 4 (between 3 and 5: second order)."""
    errs = []
    period = 2 * math.pi / OMEGA
    for spo in (100, 200):
        x0, vx0, vy0 = 2.0, 0.001, -1.5 * OMEGA * 2.0 + 0.0005
        st = State([[x0, 0.0, 0.0]], [[vx0, vy0, 0.0]], [0.1], [1.0])
        eng = Engine(st, sheet(lx=200.0, ly=1e4, omega=OMEGA), period / spo)
        for _ in range(spo):
            eng.step()
        x, y = hill_exact(x0, 0.0, vx0, vy0, period)
        p = eng.state().pos[0]
        errs.append(math.hypot(p[0] - x, p[1] - y))
    assert 3.0 < errs[0] / errs[1] < 5.0


def test_shear_flow_is_a_fixed_point():
    """Particles moving with the shear flow keep x and v_y, across both boundaries."""
    xs = np.array([-40.0, -10.0, 0.0, 25.0, 49.0])
    st = State(np.column_stack([xs, np.zeros(5), np.zeros(5)]),
               np.column_stack([np.zeros(5), -1.5 * OMEGA * xs, np.zeros(5)]),
               np.full(5, 0.5), np.ones(5))
    eng = Engine(st, sheet(lx=100.0, ly=100.0, omega=OMEGA), 50.0)
    for _ in range(200):  # 10^4 s: y wraps many times for the outer particles
        eng.step()
    out = eng.state()
    assert np.allclose(out.pos[:, 0], xs, atol=1e-12)
    assert np.allclose(out.vel[:, 1], -1.5 * OMEGA * xs, rtol=1e-12, atol=1e-15)
    assert np.all(np.abs(out.pos[:, 1]) <= 50.0)


def test_radial_crossing_shifts_y_and_vy():
    """A particle leaving through x = +lx/2 re-enters at -lx/2, shifted in y by
    -delta(T) and in v_y by +1.5 omega lx (sliding-brick boundaries)."""
    lx, ly = 100.0, 80.0
    ph = sheet(lx=lx, ly=ly, omega=OMEGA, law=Constant(1.0))
    x0, vx = 49.9, 0.01
    vy = -1.5 * OMEGA * x0
    st = State([[x0, 0.0, 0.0]], [[vx, vy, 0.0]], [0.1], [1.0])
    dt = 20.0
    eng = Engine(st, ph, dt)
    hill = ph.hill
    eng.step()  # crosses within this step: 49.9 + ~0.05
    out = eng.state()
    # the same motion without wrapping: run a copy in a huge box
    big = Engine(st, sheet(lx=1e4, ly=1e4, omega=OMEGA, law=Constant(1.0)), dt)
    big.step()
    free = big.state()
    assert free.pos[0, 0] > lx / 2  # it did cross
    delta = ph.domain.offset(out.time)
    want_y = free.pos[0, 1] - delta
    want_y -= ly * math.floor(want_y / ly + 0.5)
    assert out.pos[0, 0] == pytest.approx(free.pos[0, 0] - lx, abs=1e-12)
    assert out.pos[0, 1] == pytest.approx(want_y, abs=1e-9)
    assert out.vel[0, 1] == pytest.approx(free.vel[0, 1] + 1.5 * OMEGA * lx, rel=1e-12)


def test_collision_across_radial_boundary_matches_interior():
    """Two particles meeting across x = lx/2 collide as their interior twins do:
    the same time and the same relative velocities after impact."""
    lx, ly = 100.0, 100.0
    ph = sheet(lx=lx, ly=ly, omega=OMEGA, law=Constant(0.5))

    # interior: a at x = -0.6, b at x = +0.6 (unwrapped distance 1.2 > contact 1.0)
    pos_i = np.array([[-0.6, 0.0, 0.0], [0.6, 0.1, 0.0]])
    vel_i = np.array([[0.002, -1.5 * OMEGA * -0.6, 0.0], [-0.002, -1.5 * OMEGA * 0.6, 0.0]])
    # across the boundary: shift the pair by +lx/2, then wrap b (x > lx/2) to the left
    # edge; at T = 0 the shear offset is zero, so y is unchanged and v_y gains 1.5 omega lx
    pos_b = pos_i + [lx / 2, 0, 0]
    vel_b = vel_i + [0, -1.5 * OMEGA * lx / 2, 0]
    pos_b[1, 0] -= lx
    vel_b[1, 1] += 1.5 * OMEGA * lx
    out = []
    for pos, vel in ((pos_i, vel_i), (pos_b, vel_b)):
        eng = Engine(State(pos, vel, np.full(2, 0.5), np.ones(2)), ph, 150.0, record_events=True)
        eng.step()
        ev = eng.events()
        out.append((ev, eng.state()))
    (ev_i, s_i), (ev_b, s_b) = out
    assert len(ev_i) == 1 and len(ev_b) == 1
    assert ev_b["img"][0] != 13  # met through a periodic image
    assert ev_b["t"][0] == pytest.approx(ev_i["t"][0], rel=1e-9)
    # relative velocity in the frame of the shear flow: invariant under the boundary map
    def rel_peculiar(s):
        u = s.vel + np.column_stack([np.zeros(2), 1.5 * OMEGA * s.pos[:, 0], np.zeros(2)])
        return u[0] - u[1]
    assert np.allclose(rel_peculiar(s_b), rel_peculiar(s_i), rtol=1e-7, atol=1e-12)
