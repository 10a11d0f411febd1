"""Analytic two-body collisions and wall impacts.

Tolerance: 1e-12 relative.  Each result passes through a handful of
floating-point operations (a square root, a division, a few products), each
exact to half an ulp (1.1e-16); 1e-12 leaves four orders of margin and still
catches any wrong formula, which errs at order 1.
"""
import math

import numpy as np
import pytest

from lockgraph.engine import Engine
from lockgraph.restitution import Bridges
from lockgraph.physics import Physics
from lockgraph.domains import PeriodicCube

from .helpers import cube, dish, two_spheres

TOL = 1e-12


def one_step(state, physics, dt):
    eng = Engine(state, physics, dt, record_events=True)
    eng.step()
    return eng.state(), eng.events()


def expected_1d(v1, v2, m1, m2, e):
    """Post-collision velocities along the line of centres."""
    p = m1 * v1 + m2 * v2
    u1 = (p + m2 * e * (v2 - v1)) / (m1 + m2)
    u2 = (p + m1 * e * (v1 - v2)) / (m1 + m2)
    return u1, u2


@pytest.mark.parametrize("e", [1.0, 0.8, 0.3, 0.0])
@pytest.mark.parametrize("m2", [1.0, 3.0, 0.01])
def test_head_on(e, m2):
    # centres 3 apart, radii 0.5 + 0.5: contact after closing 2 at speed 1 + 0.5
    st = two_spheres([-1.5, 0, 0], [1.5, 0, 0], [1.0, 0, 0], [-0.5, 0, 0], m2=m2)
    out, ev = one_step(st, cube(e=e), 4.0)
    assert len(ev) == 1
    assert ev["t"][0] == pytest.approx(2.0 / 1.5, rel=TOL)
    u1, u2 = expected_1d(1.0, -0.5, 1.0, m2, e)
    assert out.vel[0, 0] == pytest.approx(u1, rel=TOL, abs=TOL)
    assert out.vel[1, 0] == pytest.approx(u2, rel=TOL, abs=TOL)
    assert np.all(out.vel[:, 1:] == 0)
    # momentum exact to rounding
    assert out.momentum()[0] == pytest.approx(1.0 - 0.5 * m2, rel=TOL, abs=TOL)
    # positions: both drifted to the step end after the collision
    t = ev["t"][0]
    assert out.pos[0, 0] == pytest.approx(-1.5 + 1.0 * t + u1 * (4.0 - t), rel=TOL, abs=TOL)


@pytest.mark.parametrize("impact", [0.0, 0.3, 0.7, 0.99])
def test_oblique(impact):
    """Impact parameter b (in units of the contact distance 1): the normal
    component follows the 1-D law, the tangential one is unchanged."""
    r = 0.5
    st = two_spheres([-2.0, impact, 0], [0.0, 0, 0], [1.0, 0, 0], [0, 0, 0], r1=r, r2=r,
                     m1=2.0, m2=1.0)
    out, ev = one_step(st, cube(e=0.6), 4.0)
    assert len(ev) == 1
    # contact when the centres are 1 apart: x = -sqrt(1 - b^2)
    xc = -math.sqrt(1 - impact ** 2)
    assert ev["t"][0] == pytest.approx(2.0 + xc, rel=TOL)
    n = np.array([xc, impact, 0.0])  # from 2 to 1 at contact, unit length
    v1 = np.array([1.0, 0, 0])
    vn = v1 @ n  # approach speed along -n ... signed normal component of the relative velocity
    u1n, u2n = expected_1d(vn, 0.0, 2.0, 1.0, 0.6)
    want1 = v1 + (u1n - vn) * n
    want2 = u2n * n
    assert np.allclose(out.vel[0], want1, rtol=TOL, atol=TOL)
    assert np.allclose(out.vel[1], want2, rtol=TOL, atol=TOL)


def test_grazing_miss():
    st = two_spheres([-2.0, 1.0001, 0], [0.0, 0, 0], [1.0, 0, 0], [0, 0, 0])
    out, ev = one_step(st, cube(), 4.0)
    assert len(ev) == 0
    assert np.array_equal(out.vel, st.vel)


def test_unequal_radii():
    st = two_spheres([-3.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0], [0, 0, 0], r1=0.1, r2=2.0,
                     m1=1.0, m2=8000.0)
    out, ev = one_step(st, cube(), 4.0)
    assert ev["t"][0] == pytest.approx(0.9, rel=TOL)
    u1, u2 = expected_1d(1.0, 0.0, 1.0, 8000.0, 1.0)
    assert out.vel[0, 0] == pytest.approx(u1, rel=TOL)
    assert out.vel[1, 0] == pytest.approx(u2, rel=TOL)


def test_bridges_restitution():
    """e(v) = (v / v_c)^-0.234 above v_c, elastic below."""
    law = Bridges(v_c=0.01, exponent=0.234)
    for v, want in [(0.1, (0.1 / 0.01) ** -0.234), (0.005, 1.0)]:
        st = two_spheres([-1.5, 0, 0], [1.5, 0, 0], [v / 2, 0, 0], [-v / 2, 0, 0])
        out, ev = one_step(st, Physics(PeriodicCube(60.0), (), law), 3.0 / v)
        assert len(ev) == 1
        assert out.vel[0, 0] == pytest.approx(-want * v / 2, rel=TOL)


def test_multiple_collisions_in_one_step():
    """Newton's cradle: three spheres in a row, two collisions in one step."""
    from lockgraph.state import State
    st = State(np.array([[-3.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0]]),
               np.array([[1.0, 0, 0], [0, 0, 0], [0, 0, 0]]), np.full(3, 0.5), np.ones(3))
    out, ev = one_step(st, cube(), 5.0)
    assert [(a, b) for a, b in zip(ev["a"], ev["b"])] in ([(0, 1), (1, 2)], [(1, 0), (1, 2)],
                                                          [(0, 1), (2, 1)], [(1, 0), (2, 1)])
    assert np.allclose(out.vel[:, 0], [0.0, 0.0, 1.0], atol=TOL)


class TestWalls:
    def test_drop_on_floor_exact_time(self):
        """Released at rest from height h: lands after sqrt(2 (h - r) / g), rebounds at e v."""
        g, r, h, e = 9.81, 0.001, 0.05, 0.7
        from lockgraph.state import State
        st = State([[0.0, 0.0, h]], [[0.0, 0.0, 0.0]], [r], [1.0])
        out, ev = one_step(st, dish(radius=0.01, e=e, g=g), 0.2)
        t_hit = math.sqrt(2 * (h - r) / g)
        assert ev["b"][0] == -2  # floor
        assert ev["t"][0] == pytest.approx(t_hit, rel=TOL)
        v_hit = g * t_hit
        # after the bounce: up at e v_hit, decelerating for 0.2 - t_hit
        assert out.vel[0, 2] == pytest.approx(e * v_hit - g * (0.2 - t_hit), rel=1e-11)
        tau = 0.2 - t_hit
        assert out.pos[0, 2] == pytest.approx(r + e * v_hit * tau - 0.5 * g * tau * tau, rel=1e-11)

    def test_free_fall_is_exact(self):
        from lockgraph.state import State
        st = State([[0.0, 0.0, 10.0]], [[0.0, 0.0, 3.0]], [0.001], [1.0])
        eng = Engine(st, dish(radius=1.0), 0.01)
        for _ in range(50):
            eng.step()
        t = 0.5
        out = eng.state()
        assert out.pos[0, 2] == pytest.approx(10.0 + 3.0 * t - 0.5 * 9.81 * t * t, rel=1e-12)
        assert out.vel[0, 2] == pytest.approx(3.0 - 9.81 * t, rel=1e-12)

    def test_cylinder_wall(self):
        from lockgraph.state import State
        R, r = 0.01, 0.001
        st = State([[0.002, 0.0, 0.005]], [[1.0, 0.5, 0.0]], [r], [1.0])
        out, ev = one_step(st, dish(radius=R, e=0.5, g=9.81), 0.02)
        walls = ev[ev["b"] == -3]
        assert len(walls) >= 1
        t = walls["t"][0]
        # contact when |p + v t| = R - r in the horizontal plane
        p = np.array([0.002, 0.0]) + np.array([1.0, 0.5]) * t
        assert np.hypot(*p) == pytest.approx(R - r, rel=TOL)
