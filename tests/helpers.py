"""Small systems for the tests."""
import numpy as np

from lockgraph.domains import Dish, PeriodicCube, ShearingSheet
from lockgraph.forces import Gravity, Hill
from lockgraph.physics import Physics
from lockgraph.restitution import Bridges, CollapseGuard, Constant
from lockgraph.state import State

# Scene overrides that make small systems eventful enough for brute-force checks
# (a narrow dish so grains meet the wall, a hot ring so particles collide).
SMALL = {
    "gas": dict(n=32, params={"eta": 0.3}),
    "ring": dict(n=60, params={"dispersion": 0.003, "dt": 60.0}),
    "ring_moonlet": dict(n=100, params={"dispersion": 0.003, "dt": 60.0, "moonlet_radius": 3.0}),
    "dish": dict(n=30, params={"cylinder_radius": 0.003, "dt": 0.001}),
    "dish_marble": dict(n=31, params={"cylinder_radius": 0.004, "marble_radius": 0.002,
                                      "dt": 0.001}),
}


def two_spheres(x1, x2, v1, v2, r1=0.5, r2=0.5, m1=1.0, m2=1.0):
    return State(np.array([x1, x2], float), np.array([v1, v2], float),
                 np.array([r1, r2]), np.array([m1, m2]))


def cube(length=60.0, e=1.0, guard=None):
    return Physics(PeriodicCube(length), (), Constant(e), guard)


def dish(radius=0.01, e=0.8, g=9.81, tc=None):
    return Physics(Dish(radius), (Gravity(g),), Constant(e),
                   CollapseGuard(tc) if tc else None)


def sheet(lx=100.0, ly=100.0, omega=1e-3, law=None):
    return Physics(ShearingSheet(lx, ly, omega), (Hill(omega),), law or Bridges())


def brute_max_overlap(state, domain):
    """Largest relative overlap over all pairs and all periodic images (O(N^2))."""
    img_pos, img_vel, half, full = domain.images(state.time)
    worst = 0.0
    pos, rad = state.pos, state.radius
    for k in full:
        d = pos[:, None, :] - pos[None, :, :] - img_pos[k]
        dist = np.sqrt((d ** 2).sum(-1))
        contact = rad[:, None] + rad[None, :]
        ov = (contact - dist) / contact
        if k == 13:
            np.fill_diagonal(ov, -np.inf)
        worst = max(worst, float(ov.max()))
    return worst


def symmetric_csr(n, edges, dtype=np.int32):
    """Symmetric CSR adjacency (offsets (n + 1,), sorted neighbours) of n
    nodes from (u, v) edges, duplicates merged."""
    adj = [set() for _ in range(n)]
    for u, v in edges:
        adj[u].add(v)
        adj[v].add(u)
    off = np.zeros(n + 1, np.int64)
    off[1:] = np.cumsum([len(a) for a in adj])
    return off, np.array([v for a in adj for v in sorted(a)], dtype)
