"""Contact-time functions: pair, floor and cylinder wall.

Inside a step every particle moves on a straight line in the step's frame
(see ``engine``): ``pos[i]`` is its frame position at its local time
``tl[i]`` (seconds since the step start) and ``vel[i]`` its frame velocity.
Periodic image ``img`` of a particle is displaced by
``img_pos[img] + img_vel[img] * t`` at step time ``t``.

Every function returns the step time of the first contact that is not earlier
than ``t_now``, or ``inf`` if there is none before ``t_end``.  A pair that
already overlaps while approaching collides at ``t_now``.  The algebra is
written so that swapping the two particles gives bitwise the same time.
"""
import math

from ._jit import kernel

INF = math.inf


@kernel(inline=True)
def pair_time(pos, vel, tl, i, j, img, img_pos, img_vel, contact, t_now, t_end):
    """First contact of i with image ``img`` of j (``contact`` = r_i + r_j)."""
    if i > j:  # canonical order: the same bits whichever particle asks
        i, j = j, i
        img = 26 - img
    ti = tl[i]
    tj = tl[j]
    tr = ti if ti > tj else tj
    di = tr - ti
    dj = tr - tj
    dx = (pos[i, 0] + vel[i, 0] * di) - (pos[j, 0] + vel[j, 0] * dj) - (img_pos[img, 0] + img_vel[img, 0] * tr)
    dy = (pos[i, 1] + vel[i, 1] * di) - (pos[j, 1] + vel[j, 1] * dj) - (img_pos[img, 1] + img_vel[img, 1] * tr)
    dz = (pos[i, 2] + vel[i, 2] * di) - (pos[j, 2] + vel[j, 2] * dj) - (img_pos[img, 2] + img_vel[img, 2] * tr)
    ux = vel[i, 0] - vel[j, 0] - img_vel[img, 0]
    uy = vel[i, 1] - vel[j, 1] - img_vel[img, 1]
    uz = vel[i, 2] - vel[j, 2] - img_vel[img, 2]
    b = dx * ux + dy * uy + dz * uz
    if b >= 0.0:
        return INF  # not approaching
    a = ux * ux + uy * uy + uz * uz
    c = dx * dx + dy * dy + dz * dz - contact * contact
    if c <= 0.0:
        tau = 0.0  # touching or overlapping while approaching: collide now
    else:
        disc = b * b - a * c
        if disc < 0.0:
            return INF  # closest approach misses
        tau = c / (math.sqrt(disc) - b)  # stable root: no cancellation
    t = tr + tau
    if t < t_now:
        t = t_now
    if t >= t_end:
        return INF
    return t


@kernel
def floor_time(pos, vel, tl, i, radius, g0, t_now, t_end):
    """First contact of i with the floor z = 0 under gravity g0 (m/s^2, downward).

    The frame is the free-falling one: real height z = pos_z - g0 t^2 / 2 and
    real vertical velocity w = vel_z - g0 t.  The contact solves
    ``h + w tau - g0 tau^2 / 2 = 0`` with h the gap; the root is taken in the
    form that does not cancel.
    """
    ti = tl[i]
    w = vel[i, 2] - g0 * ti
    h = pos[i, 2] - 0.5 * g0 * ti * ti - radius
    if h < 0.0:
        h = 0.0  # rounding below contact: treat as touching
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
    t = ti + tau
    if t < t_now:
        t = t_now
    if t >= t_end:
        return INF
    return t


@kernel
def cylinder_time(pos, vel, tl, i, radius, rcyl, t_now, t_end):
    """First contact of i with the inside of the vertical cylinder of radius rcyl."""
    ti = tl[i]
    px = pos[i, 0]
    py = pos[i, 1]
    ux = vel[i, 0]
    uy = vel[i, 1]
    a = ux * ux + uy * uy
    if a == 0.0:
        return INF
    b = px * ux + py * uy
    reach = rcyl - radius
    c = px * px + py * py - reach * reach
    if c >= 0.0:
        if b > 0.0:
            tau = 0.0  # at the wall and moving out: collide now
        else:
            return INF
    else:
        sq = math.sqrt(b * b - a * c)
        if b > 0.0:
            tau = -c / (b + sq)
        else:
            tau = (sq - b) / a
    t = ti + tau
    if t < t_now:
        t = t_now
    if t >= t_end:
        return INF
    return t
