"""A brute-force O(N^2) event-driven reference of lockgraph's physics.

No tree, no candidate lists, no search radii, no tournament: every step it
predicts every pair of particles in every periodic image (and every wall),
always processes the globally earliest event — ordered by (time, lower id,
higher id, image), walls after pairs of the same particle — and predicts the
two particles again against everybody.  It is the slow, obvious twin of the
engine: same splitting and the same contact-time formulas written out again
in numpy, so the two agree to the last bit unless the engine misses or
misorders an event.
"""
import math

import numpy as np

from lockgraph.domains import DOMAIN_DISH, wrap
from lockgraph.forces import kick_hill

FLOOR = -2
CYLINDER = -3


def _coefficient(law, vn):
    kind, e, vc, expo = law
    if kind == 0:
        return e
    if vn <= vc:
        return 1.0
    return (vn / vc) ** (-expo)


class Reference:
    """Brute-force engine over a State (in id order) with a Physics and a step dt."""

    def __init__(self, state, physics, dt):
        self.physics = physics
        self.dt = float(dt)
        self.pos = state.pos.copy()
        self.vel = state.vel.copy()
        self.rad = state.radius.copy()
        self.mass = state.mass.copy()
        self.ncoll = state.ncoll.copy()
        self.tlast = state.t_last.copy()
        self.time = state.time
        self.n = state.n
        self.law = physics.restitution.encode()
        self.tc = physics.guard.tc if physics.guard is not None else -1.0
        self.g0 = physics.g
        self.wmin = 0.5 * self.g0 * self.tc if physics.guard is not None else 0.0
        self.dish = physics.domain.code == DOMAIN_DISH
        self.events = []  # (step, t, a, b, img) with a < b for pairs
        self.steps_done = 0

    # ---- predictions ---------------------------------------------------------
    def _pair_row(self, i, t_now):
        """Contact times of i with every particle j in every image: shape (N, K).

        Positions are false positions (extrapolated to the step start along the
        current velocity), as in the engine."""
        pos, vel = self.pos, self.vel
        ip, iv = self.img_pos[self.imgs], self.img_vel[self.imgs]  # (K,3)
        d = []
        u = []
        for a in range(3):
            d.append((pos[i, a] - pos[:, a])[:, None] - ip[None, :, a])
            u.append((vel[i, a] - vel[:, a])[:, None] - iv[None, :, a])
        dx, dy, dz = d
        ux, uy, uz = u
        contact = (self.rad[i] + self.rad)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            b = dx * ux + dy * uy + dz * uz
            a2 = ux * ux + uy * uy + uz * uz
            c = dx * dx + dy * dy + dz * dz - contact * contact
            disc = b * b - a2 * c
            enter = c / (np.sqrt(np.maximum(disc, 0.0)) - b)
        t = np.full(dx.shape, np.inf)
        ahead = (b < 0.0) & (c > 0.0) & (disc >= 0.0) & (enter >= t_now)
        t[ahead] = np.where(enter[ahead] < self.dt, enter[ahead], np.inf)
        # entered before now (or overlapping at the start): collide now while approaching
        now = (b < 0.0) & ~ahead & ~((c > 0.0) & (disc < 0.0)) & (t_now * a2 < -b) \
            & (t_now < self.dt)
        t[now] = t_now
        t[i, :] = np.inf  # a particle never meets itself or its images
        return t

    def _floor(self, i, t_now):
        t0 = self.tl[i]
        w = self.vel[i, 2] - self.g0 * t0
        h = (self.pos[i, 2] + self.vel[i, 2] * t0) - 0.5 * self.g0 * t0 * t0 - self.rad[i]
        if h < 0.0:
            h = 0.0
        if self.g0 == 0.0:
            if w >= 0.0:
                return math.inf
            tau = h / (-w)
        else:
            sq = math.sqrt(w * w + 2.0 * self.g0 * h)
            tau = (w + sq) / self.g0 if w >= 0.0 else 2.0 * h / (sq - w)
        t = max(t0 + tau, t_now)
        return t if t < self.dt else math.inf

    def _cylinder(self, i, t_now):
        ux, uy = self.vel[i, 0], self.vel[i, 1]
        a = ux * ux + uy * uy
        if a == 0.0:
            return math.inf
        t0 = self.tl[i]
        px = self.pos[i, 0] + ux * t0
        py = self.pos[i, 1] + uy * t0
        b = px * ux + py * uy
        reach = self.physics.domain.radius - self.rad[i]
        c = px * px + py * py - reach * reach
        if c >= 0.0:
            if b > 0.0:
                tau = 0.0
            else:
                return math.inf
        else:
            sq = math.sqrt(b * b - a * c)
            tau = -c / (b + sq) if b > 0.0 else (sq - b) / a
        t = max(t0 + tau, t_now)
        return t if t < self.dt else math.inf

    def _predict(self, i, t_now):
        row = self._pair_row(i, t_now)
        self.T[i] = row
        self.T[:, i] = row[:, ::-1]  # image k from i is image 26-k from j: reversed order
        if self.dish:
            self.W[i, 0] = self._floor(i, t_now)
            self.W[i, 1] = self._cylinder(i, t_now)

    def _next(self):
        """The earliest event (t, kind, a, b, k): pairs by (t, lower id, higher id,
        image); a wall by (t, id) after the pairs of that particle."""
        n = self.n
        best = None
        upper = np.triu(np.ones((n, n), bool), 1)[:, :, None]
        T = np.where(upper, self.T, np.inf)
        tp = T.min() if T.size else np.inf
        if np.isfinite(tp):
            i, j, k = np.argwhere(T == tp)[0]  # lexicographic (i, j, k)
            best = (tp, 0, int(i), int(j), int(k))
        if self.dish:
            tw = self.W.min()
            if np.isfinite(tw):
                i, w = np.argwhere(self.W == tw)[0]  # lowest id, floor before cylinder
                if best is None or tw < best[0] or (tw == best[0] and i < best[2]):
                    best = (tw, 1, int(i), int(w), 0)
        return best

    # ---- the step --------------------------------------------------------------
    def step(self):
        ph = self.physics
        hill = ph.hill
        if hill is not None:
            kick_hill(self.pos, self.vel, hill.omega, 0.5 * self.dt)
        self.img_pos, self.img_vel, half, full = ph.domain.images(self.time)
        self.imgs = np.array(sorted(full))
        K = len(self.imgs)
        self.kimg = {int(img): q for q, img in enumerate(self.imgs)}
        self.tl = np.zeros(self.n)  # step time each particle's current path began
        self.T = np.full((self.n, self.n, K), np.inf)
        self.W = np.full((self.n, 2), np.inf)
        for i in range(self.n):
            self._predict(i, 0.0)
        while True:
            ev = self._next()
            if ev is None or not ev[0] < self.dt:
                break
            t, kind, a, b, k = ev
            if kind == 0:
                self._collide_pair(a, b, int(self.imgs[k]), t)
                self._predict(a, t)
                self._predict(b, t)
            else:
                self._collide_wall(a, FLOOR if b == 0 else CYLINDER, t)
                self._predict(a, t)
        self.pos += self.vel * self.dt
        if self.g0 != 0.0:
            self.pos[:, 2] -= 0.5 * self.g0 * self.dt * self.dt
            self.vel[:, 2] -= self.g0 * self.dt
        self.time += self.dt
        wrap(self.pos, self.vel, ph.domain.code, ph.domain.wrap_params(self.time))
        if hill is not None:
            kick_hill(self.pos, self.vel, hill.omega, 0.5 * self.dt)
        self.steps_done += 1

    def _at(self, i, t):
        return [self.pos[i, a] + self.vel[i, a] * t for a in range(3)]

    def _set(self, i, x, t):
        for a in range(3):
            self.pos[i, a] = x[a] - self.vel[i, a] * t
        self.tl[i] = t

    def _collide_pair(self, i, j, img, t):
        xi, xj = self._at(i, t), self._at(j, t)
        ip, iv = self.img_pos[img], self.img_vel[img]
        d = [xi[a] - xj[a] - (ip[a] + iv[a] * t) for a in range(3)]
        dist = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        nrm = [x / dist for x in d]
        vn = ((self.vel[i, 0] - self.vel[j, 0] - iv[0]) * nrm[0]
              + (self.vel[i, 1] - self.vel[j, 1] - iv[1]) * nrm[1]
              + (self.vel[i, 2] - self.vel[j, 2] - iv[2]) * nrm[2])
        if vn >= 0.0:
            return
        now = self.time + t
        if self.tc > 0.0 and (now - self.tlast[i] < self.tc or now - self.tlast[j] < self.tc):
            e = 1.0
        else:
            e = _coefficient(self.law, -vn)
        mi, mj = self.mass[i], self.mass[j]
        imp = -(1.0 + e) * vn * (mi * mj / (mi + mj))
        ai, aj = imp / mi, imp / mj
        for a in range(3):
            self.vel[i, a] += ai * nrm[a]
            self.vel[j, a] -= aj * nrm[a]
        self._set(i, xi, t)
        self._set(j, xj, t)
        self.ncoll[i] += 1
        self.ncoll[j] += 1
        self.tlast[i] = now
        self.tlast[j] = now
        self.events.append((self.steps_done, t, i, j, img))

    def _collide_wall(self, i, wall, t):
        x = self._at(i, t)
        hit = False
        if wall == FLOOR:
            w = self.vel[i, 2] - self.g0 * t
            if w <= 0.0:
                e = _coefficient(self.law, -w)
                w2 = max(-e * w, self.wmin)
                self.vel[i, 2] = w2 + self.g0 * t
                hit = True
        else:
            rho = math.sqrt(x[0] * x[0] + x[1] * x[1])
            nx, ny = x[0] / rho, x[1] / rho
            vn = self.vel[i, 0] * nx + self.vel[i, 1] * ny
            if vn > 0.0:
                e = _coefficient(self.law, vn)
                self.vel[i, 0] -= (1.0 + e) * vn * nx
                self.vel[i, 1] -= (1.0 + e) * vn * ny
                hit = True
        if hit:
            self._set(i, x, t)
            self.ncoll[i] += 1
            self.events.append((self.steps_done, t, i, wall, 13))


def canonical_events(events):
    """Engine or reference events as tuples (step, t, lower id, other, image from lower)."""
    out = []
    for step, t, a, b, img in events:
        a, b, img = int(a), int(b), int(img)
        if b >= 0 and b < a:
            a, b, img = b, a, 26 - img
        out.append((int(step), float(t), a, b, img))
    return out
