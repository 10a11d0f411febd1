"""Contact-time functions: pair, floor and cylinder wall.

Inside a step every particle moves on a straight line in the step's frame
(see ``engine``): at step time t it is at ``pos[i] + vel[i] * t``, so ``pos``
holds its position extrapolated back to the step start along its current
velocity (a "false position", set again whenever the velocity changes) and
``vel[i]`` its frame velocity.  Periodic image ``img`` of a particle is
displaced by ``img_pos[img] + img_vel[img] * t``.

Every function returns the step time of the first contact that is not earlier
than ``t_now``, or ``inf`` if there is none before ``t_end``.  A pair that
overlaps at ``t_now`` while approaching collides at ``t_now``.  The pair
algebra is antisymmetric to the bit: swapping the two particles gives the same
time, whoever asks and whenever.
"""
import math

from ._jit import kernel

INF = math.inf


# the entering root c / (sqrt(b^2 - a c) - b) is at least c / (-2 b); rounding
# moves the computed root by a few units in the last place, far inside this factor
CUT_MARGIN = 1.0 + 1e-9


@kernel(inline=True)
def pair_time(pos, vel, i, j, img, img_pos, img_vel, contact, t_now, t_end):
    """First contact of i with image ``img`` of j (``contact`` = r_i + r_j)."""
    return pair_time_by(pos, vel, i, j, img, img_pos, img_vel, contact, t_now, t_end, t_end)


@kernel(inline=True)
def pair_time_by(pos, vel, i, j, img, img_pos, img_vel, contact, t_now, t_end, t_cut):
    """``pair_time``, except that a contact surely later than ``t_cut``
    (t_now <= t_cut <= t_end, or inf) may be returned as inf: a caller that
    keeps only the earliest contact skips the square root of a pair that
    cannot beat the best so far.  Every time it returns <= t_cut is
    bitwise ``pair_time``'s."""
    dx = pos[i, 0] - pos[j, 0] - img_pos[img, 0]
    dy = pos[i, 1] - pos[j, 1] - img_pos[img, 1]
    dz = pos[i, 2] - pos[j, 2] - img_pos[img, 2]
    ux = vel[i, 0] - vel[j, 0] - img_vel[img, 0]
    uy = vel[i, 1] - vel[j, 1] - img_vel[img, 1]
    uz = vel[i, 2] - vel[j, 2] - img_vel[img, 2]
    b = dx * ux + dy * uy + dz * uz
    if b >= 0.0:
        return INF  # closest approach at or before the step start: never again
    a = ux * ux + uy * uy + uz * uz
    c = dx * dx + dy * dy + dz * dz - contact * contact
    if c > 0.0:
        if c > (-2.0 * b) * t_cut * CUT_MARGIN:
            return INF  # the root is past t_cut: c / (-2 b) > t_cut
        disc = b * b - a * c
        if disc < 0.0:
            return INF  # the paths miss
        t = c / (math.sqrt(disc) - b)  # entering root, in the form that does not cancel
        if t >= t_now:
            return t if t < t_end else INF
    # entered before t_now: overlapping now if still approaching (t_now < -b / a)
    if t_now * a < -b and t_now < t_end:
        return t_now
    return INF


# a wall test's window is widened by this fraction of the step: its contact
# time is t0 + tau, rounded at the scale of the step, not of the window
WALL_SLACK = 1e-12
# the sign test of a quadratic at the window's end must clear its rounding
# (a few units in the last place of its largest term)
SIGN_MARGIN = 1e-9


@kernel
def floor_time(pos, vel, tl, i, radius, g0, t_now, t_end):
    """``floor_time_by`` without a cut (t_cut = t_end)."""
    return floor_time_by(pos, vel, tl, i, radius, g0, t_now, t_end, t_end)


@kernel(inline=True)
def floor_time_by(pos, vel, tl, i, radius, g0, t_now, t_end, t_cut):
    """First contact of i with the floor z = 0 under gravity g0 (m/s^2, downward).

    The frame is the free-falling one: real height z = pos_z + vel_z t - g0 t^2 / 2
    and real vertical velocity w = vel_z - g0 t.  The contact solves
    ``h + w tau - g0 tau^2 / 2 = 0`` from the time ``tl[i]`` the particle's
    current path began (so the result does not depend on when it is asked),
    with h the gap there; the root is taken in the form that does not cancel.
    A contact surely later than ``t_cut`` (t_now <= t_cut <= t_end) may be
    returned as inf; every time <= t_cut is the one without the cut.
    """
    t0 = tl[i]
    w = vel[i, 2] - g0 * t0
    h = (pos[i, 2] + vel[i, 2] * t0) - 0.5 * g0 * t0 * t0 - radius
    if h < 0.0:
        h = 0.0  # rounding below contact: treat as touching
    # the gap h + w tau - g0 tau^2 / 2 is concave in tau and h at tau = 0: still
    # open at the end of the (slightly widened) window, it is open all along it,
    # and the square root below need not be taken
    lw = t_cut - t0 + WALL_SLACK * t_end
    ft = w * lw - 0.5 * g0 * lw * lw
    if h + ft > SIGN_MARGIN * (h + abs(w) * lw + 0.5 * g0 * lw * lw):
        return INF
    if g0 == 0.0:
        if w >= 0.0:
            return INF
        tau = h / (-w)
    else:
        sq = math.sqrt(w * w + 2.0 * g0 * h)
        if w >= 0.0:
            tau = (w + sq) / g0
        else:
            tau = 2.0 * h / (sq - w)
    t = t0 + tau
    if t < t_now:
        t = t_now
    if t >= t_end:
        return INF
    return t


@kernel
def cylinder_time(pos, vel, tl, i, radius, rcyl, t_now, t_end):
    """``cylinder_time_by`` without a cut (t_cut = t_end)."""
    return cylinder_time_by(pos, vel, tl, i, radius, rcyl, t_now, t_end, t_end)


@kernel(inline=True)
def cylinder_time_by(pos, vel, tl, i, radius, rcyl, t_now, t_end, t_cut):
    """First contact of i with the inside of the vertical cylinder of radius rcyl
    (solved from ``tl[i]``, and cut at ``t_cut``, as ``floor_time_by``)."""
    t0 = tl[i]
    ux = vel[i, 0]
    uy = vel[i, 1]
    a = ux * ux + uy * uy
    if a == 0.0:
        return INF
    px = pos[i, 0] + ux * t0
    py = pos[i, 1] + uy * t0
    b = px * ux + py * uy
    reach = rcyl - radius
    c = px * px + py * py - reach * reach
    if c >= 0.0:
        if b > 0.0:
            tau = 0.0  # at the wall and moving out: collide now
        else:
            return INF
    else:
        # inside: a tau^2 + 2 b tau + c is convex and c < 0 at tau = 0; still
        # negative at the end of the (widened) window, it is negative all along it
        lw = t_cut - t0 + WALL_SLACK * t_end
        q2 = a * lw * lw
        q1 = 2.0 * b * lw
        if q2 + q1 + c < -SIGN_MARGIN * (q2 + abs(q1) - c):
            return INF
        sq = math.sqrt(b * b - a * c)
        if b > 0.0:
            tau = -c / (b + sq)
        else:
            tau = (sq - b) / a
    t = t0 + tau
    if t < t_now:
        t = t_now
    if t >= t_end:
        return INF
    return t
