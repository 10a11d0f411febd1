"""REBOUND on a lockgraph shearing-sheet scene: the same particles, Omega and
restitution law, run side by side with a collision log.

REBOUND (5.2.2) set-up, after its ``examples/shearing_sheet``: ``integrator =
"sei"`` (symplectic epicycle integrator: the exact Hill flow between kicks),
``boundary = "shear"``, ``gravity = "none"`` (the ring scenes have no
self-gravity), ``collision = "tree"`` (or "direct", "line", "linetree"), two
ghost boxes in x and y, the root box lx by ly by lx (particles leaving it in z
are removed: counted as ``lost``), ``sim.t`` set to the state's time so that
both codes' shear offsets agree, and REBOUND's ``hardsphere`` resolver with
the scene's restitution law as ``coefficient_of_restitution`` (REBOUND passes
the signed normal velocity: its absolute value is used).

How REBOUND resolves collisions (``src/collision.c``): once per step, at its
end, it lists the pairs that overlap and approach, shuffles them and resolves
them one by one — not in time order — and never separates overlapping pairs.
The resolver is wrapped here to log, per detected pair: whether it changed
the velocities (the resolver rejects pairs that no longer overlap or that
recede), the relative overlap (r1 + r2 - d) / (r1 + r2) at resolution, and the
y momentum moved across x (for the collisional viscosity).
"""
import ctypes
import math
import time

import numpy as np

from .domains import ShearingSheet
from .errors import InputError
from .reference_codes import rebound as _load_rebound
from .restitution import Bridges, Constant
from .state import State

COLLISIONS = ("tree", "direct", "line", "linetree")


RAND_SEED = 1


class ReboundRing:
    """A REBOUND simulation built from a lockgraph ring state.

    ``state``: a ``State`` in a ``ShearingSheet`` domain; ``physics``: its
    ``Physics`` (Hill forces, Bridges or constant restitution, no gravity);
    ``dt``: REBOUND's step (s); ``collision``: REBOUND's collision search.
    """

    def __init__(self, state, physics, dt, collision="tree"):
        rb = _load_rebound()
        dom = physics.domain
        if not isinstance(dom, ShearingSheet):
            raise InputError("physics.domain", f"REBOUND comparison needs a shearing sheet, "
                                               f"got {type(dom).__name__}")
        if physics.g:
            raise InputError("physics.forces", "the ring comparison has no uniform gravity")
        if collision not in COLLISIONS:
            raise InputError("collision", f"unknown value {collision!r}; one of "
                                          f"{', '.join(COLLISIONS)}")
        dt = float(dt)
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError("dt", f"must be a finite number > 0 (got {dt!r})")
        ny = int(round(dom.ly / dom.lx))
        if ny < 1 or abs(ny * dom.lx - dom.ly) > 1e-9 * dom.ly:
            raise InputError("domain.ly", "REBOUND's root boxes are cubes: ly must be a "
                                          f"whole multiple of lx (lx={dom.lx}, ly={dom.ly})")
        zmax = float(np.max(np.abs(state.pos[:, 2]) + state.radius))
        if zmax >= 0.5 * dom.lx:
            raise InputError("state.pos", f"particles reach |z| = {zmax:.3g} m, outside "
                                          f"REBOUND's root box (|z| < {0.5 * dom.lx:.3g} m)")
        self.rb = rb
        self.domain = dom
        self.n0 = state.n
        self.ids = np.arange(state.n)
        sim = rb.Simulation()
        # REBOUND resolves each step's collisions in a random order drawn from
        # rand_seed, which it seeds from the clock and pid: a fixed seed makes
        # a run reproducible
        sim.rand_seed = RAND_SEED
        sim.integrator = "sei"
        sim.OMEGA = dom.omega
        sim.OMEGAZ = dom.omega
        sim.gravity = "none"
        sim.boundary = "shear"
        sim.collision = collision
        sim.root_size = dom.lx
        sim.N_root_x, sim.N_root_y, sim.N_root_z = 1, ny, 1
        sim.N_ghost_x, sim.N_ghost_y, sim.N_ghost_z = 2, 2, 0
        sim.dt = dt
        sim.t = float(state.time)
        for p, v, r, m in zip(state.pos, state.vel, state.radius, state.mass):
            sim.add(m=float(m), r=float(r), x=float(p[0]), y=float(p[1]), z=float(p[2]),
                    vx=float(v[0]), vy=float(v[1]), vz=float(v[2]))
        self._restitution(sim, physics.restitution)
        self._log = {"detected": 0, "resolved": 0, "rejected": 0, "overlapping": 0,
                     "max_overlap": 0.0, "momentum_flux_xy": 0.0,
                     "largest_overlapping": 0, "largest_max_overlap": 0.0}
        self.largest = int(np.argmax(state.radius))  # the moonlet, if there is one
        self._wrap_resolver(sim)
        self.sim = sim
        self.wall_s = 0.0
        self.steps = 0

    def _restitution(self, sim, law):
        if isinstance(law, Bridges):
            vc, ex = law.v_c, law.exponent

            def eps(_sim, v):
                v = abs(v)  # REBOUND passes the signed normal velocity
                return 1.0 if v <= vc else (v / vc) ** -ex
        elif isinstance(law, Constant):
            e = law.e

            def eps(_sim, v):
                return e
        else:
            raise InputError("physics.restitution", f"{type(law).__name__} is not supported "
                                                    "in the REBOUND comparison")
        sim.coefficient_of_restitution = eps

    def _wrap_resolver(self, sim):
        rb = self.rb
        hard = rb.clibrebound.reb_collision_resolve_hardsphere
        hard.restype = ctypes.c_int
        log = self._log
        big = self.largest

        def resolve(sim_ptr, c):
            ps = sim_ptr.contents._particles
            p1 = ps[c.p1]
            p2 = ps[c.p2]
            x21 = p1.x + c.gb.x - p2.x
            y21 = p1.y + c.gb.y - p2.y
            z21 = p1.z + c.gb.z - p2.z
            rp = p1.r + p2.r
            ov = (rp - math.sqrt(x21 * x21 + y21 * y21 + z21 * z21)) / rp
            vy0 = p1.vy
            vx0 = p1.vx
            out = hard(sim_ptr, c)
            q1 = ps[c.p1]
            log["detected"] += 1
            if q1.vy != vy0 or q1.vx != vx0:
                log["resolved"] += 1
                log["momentum_flux_xy"] += x21 * q1.m * (q1.vy - vy0)
                if ov > 0:
                    log["overlapping"] += 1
                    log["max_overlap"] = max(log["max_overlap"], ov)
                    if c.p1 == big or c.p2 == big:
                        log["largest_overlapping"] += 1
                        log["largest_max_overlap"] = max(log["largest_max_overlap"], ov)
            else:
                log["rejected"] += 1
            return out

        sim.collision_resolve = resolve

    def step(self, k):
        """Advance k steps of dt."""
        t0 = time.perf_counter()
        self.sim.steps(int(k))
        self.wall_s += time.perf_counter() - t0
        self.steps += int(k)

    @property
    def lost(self):
        """Particles REBOUND removed (they left the root box)."""
        return self.n0 - self.sim.N

    @property
    def log(self):
        """Collision statistics so far: pairs detected, resolved (velocities
        changed), rejected (no longer overlapping or receding), overlapping when
        resolved, the largest relative overlap, sum of (x1 - x2) dp_y,1, and
        the overlapping count and largest overlap of the collisions involving
        the largest body (the moonlet, if any)."""
        return dict(self._log)

    def arrays(self):
        """(pos, vel, radius, mass) of the particles left, in the order added."""
        n = self.sim.N
        a = np.zeros((n, 6))
        self.sim.serialize_particle_data(xyzvxvyvz=a)
        r = np.zeros(n)
        m = np.zeros(n)
        self.sim.serialize_particle_data(r=r, m=m)
        return a[:, :3].copy(), a[:, 3:].copy(), r, m

    def state(self):
        """The current particles as a ``State`` (raises if REBOUND lost some)."""
        if self.lost:
            raise RuntimeError(f"REBOUND removed {self.lost} particles (left its box)")
        pos, vel, r, m = self.arrays()
        return State(pos, vel, r, m, time=float(self.sim.t))
