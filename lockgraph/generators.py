"""Initial conditions ("early" states) of the scenes.

Each generator takes the scene's parameters and returns the state and the
geometry it decided (box sizes), reproducibly from ``seed``.
"""
import math

import numpy as np

from ._jit import kernel
from .errors import ScenarioError
from .state import State

ORBIT = 2.0 * math.pi


def power_law_radii(rng, n, rmin, rmax, slope):
    """n radii from dN/dr ~ r^slope on [rmin, rmax] (inverse transform sampling)."""
    u = rng.random(n)
    if abs(slope + 1.0) < 1e-12:
        return rmin * (rmax / rmin) ** u
    k = slope + 1.0
    return (rmin ** k + u * (rmax ** k - rmin ** k)) ** (1.0 / k)


@kernel
def _place(radius, cand, lx, ly, cell, head, nxt, pos, start, obstacle):
    """Random sequential placement without overlap in an x-y periodic box.

    Particles ``start..`` are tried in order with candidate positions taken
    from ``cand`` (K,3); ``obstacle = (x, y, z, r)`` is a fixed sphere to avoid
    (r = 0 for none).  Returns (next particle to place, candidates used).
    """
    n = radius.shape[0]
    ncx = head.shape[0]
    ncy = head.shape[1]
    k = 0
    i = start
    while i < n and k < cand.shape[0]:
        x = cand[k, 0]
        y = cand[k, 1]
        z = cand[k, 2]
        k += 1
        r = radius[i]
        ok = True
        if obstacle[3] > 0.0:
            dx = x - obstacle[0]
            dy = y - obstacle[1]
            dz = z - obstacle[2]
            if dx * dx + dy * dy + dz * dz < (r + obstacle[3]) ** 2:
                ok = False
        cx = int((x + 0.5 * lx) / cell) % ncx
        cy = int((y + 0.5 * ly) / cell) % ncy
        for ax in range(-1, 2):
            if not ok:
                break
            for ay in range(-1, 2):
                if not ok:
                    break
                q = head[(cx + ax) % ncx, (cy + ay) % ncy]
                while q >= 0:
                    dx = x - pos[q, 0]
                    dy = y - pos[q, 1]
                    dz = z - pos[q, 2]
                    dx -= lx * math.floor(dx / lx + 0.5)
                    dy -= ly * math.floor(dy / ly + 0.5)
                    if dx * dx + dy * dy + dz * dz < (r + radius[q]) ** 2:
                        ok = False
                        break
                    q = nxt[q]
        if ok:
            pos[i, 0] = x
            pos[i, 1] = y
            pos[i, 2] = z
            nxt[i] = head[cx, cy]
            head[cx, cy] = i
            i += 1
    return i, k


def ring_layer(p):
    """A dynamically cold, uniform layer in a shearing-sheet box.

    Radii from a differential power law; the box is square with area
    sum(pi r^2) / tau; heights are Gaussian with rms ``thickness``; velocities
    are the shear flow plus an isotropic Gaussian of rms ``dispersion`` per
    axis.  With ``moonlet_radius`` a body of that radius rests at the origin.
    """
    rng = np.random.default_rng(p["seed"])
    n_bg = p["n"] - (1 if "moonlet_radius" in p else 0)
    if n_bg < 2:
        raise ScenarioError("params.n", f"too few particles ({p['n']})")
    radii = power_law_radii(rng, n_bg, p["radius_min"], p["radius_max"], p["size_slope"])
    area = float(np.sum(np.pi * radii ** 2)) / p["tau"]
    lx = ly = math.sqrt(area)
    moon = p.get("moonlet_radius")
    # the periodic box must keep the moonlet clear of its own images' reach
    if moon is not None and lx < 2.5 * (moon + p["radius_max"]):
        need = 2.5 * (moon + p["radius_max"])
        nmin = int(math.ceil(p["n"] * (need / lx) ** 2))
        raise ScenarioError("params.n", f"n = {p['n']} gives a {lx:.1f} m box, too small for a "
                            f"moonlet of radius {moon} m (needs >= {need:.1f} m: n >= {nmin})")
    order = np.argsort(-radii, kind="stable")  # largest first: they are hardest to fit
    radii = radii[order]
    pos = np.zeros((n_bg, 3))
    cell = 2.0 * p["radius_max"]
    ncx = max(1, int(lx / cell))
    ncy = max(1, int(ly / cell))
    head = np.full((ncx, ncy), -1, np.int64)
    nxt = np.full(n_bg, -1, np.int64)
    obstacle = np.array([0.0, 0.0, 0.0, moon or 0.0])
    placed = 0
    tries = 0
    while placed < n_bg:
        m = 4 * (n_bg - placed) + 1024
        cand = np.empty((m, 3))
        cand[:, 0] = (rng.random(m) - 0.5) * lx
        cand[:, 1] = (rng.random(m) - 0.5) * ly
        cand[:, 2] = rng.normal(0.0, p["thickness"], m)
        placed, used = _place(radii, cand, lx, ly, lx / ncx, head, nxt, pos, placed, obstacle)
        tries += used
        if tries > 200 * n_bg + 10000:
            raise ScenarioError("params.thickness", "could not place the particles without "
                                "overlap: make the layer thicker or tau smaller")
    omega = p["omega"]
    vel = rng.normal(0.0, p["dispersion"], (n_bg, 3))
    vel[:, 1] += -1.5 * omega * pos[:, 0]
    mass = p["density"] * 4.0 / 3.0 * np.pi * radii ** 3
    if moon is not None:
        pos = np.vstack([[0.0, 0.0, 0.0], pos])
        vel = np.vstack([[0.0, 0.0, 0.0], vel])
        radii = np.concatenate([[moon], radii])
        mass = np.concatenate([[p["density"] * 4.0 / 3.0 * np.pi * moon ** 3], mass])
    return State(pos, vel, radii, mass), {"lx": lx, "ly": ly}


def grain_block(p):
    """A block of well-spaced grains wholly inside the dish, at rest, about to fall.

    Grains sit on a square lattice of pitch ``spacing`` grain diameters, jittered
    by up to ``jitter`` of the free gap, with random velocities of rms
    ``velocity_jitter``; the block is a cube when the grains fit in one and
    grows upward otherwise.  Its bottom is ``drop_height`` above the floor.
    With ``marble_radius`` a marble hangs ``marble_gap`` above the block moving
    down at ``marble_speed``.
    """
    rng = np.random.default_rng(p["seed"])
    n = p["n"] - (1 if "marble_radius" in p else 0)
    r = p["grain_radius"]
    rc = p["cylinder_radius"]
    pitch = p["spacing"] * 2.0 * r
    gap = pitch - 2.0 * r
    if gap <= 0:
        raise ScenarioError("params.spacing", "must exceed 1 (grains would touch)")
    jit = p["jitter"] * 0.5 * gap
    # widest square cross-section whose corner grains (jittered by up to jit in x
    # and y) stay inside the wall: sqrt(2) ((m - 1) pitch / 2 + jit) + r < rc
    mmax = int(math.floor(((rc - r) / math.sqrt(2.0) - jit) / (0.5 * pitch))) + 1
    while mmax > 1 and math.sqrt(2.0) * (0.5 * (mmax - 1) * pitch + jit) + r >= rc:
        mmax -= 1
    if mmax < 1 or math.sqrt(2.0) * jit + r >= rc:
        raise ScenarioError("params.cylinder_radius", "the dish is too narrow for one grain")
    side = max(1, min(mmax, int(math.ceil(n ** (1.0 / 3.0)))))
    layers = int(math.ceil(n / side ** 2))
    g = (np.arange(side) - 0.5 * (side - 1)) * pitch
    gx, gy = np.meshgrid(g, g, indexing="ij")
    sites = []
    for layer in range(layers):
        z = p["drop_height"] + r + jit + layer * pitch
        sites.append(np.column_stack([gx.ravel(), gy.ravel(), np.full(side * side, z)]))
    sites = np.vstack(sites)
    full = (n // (side * side)) * side * side
    keep = np.arange(full)
    if n > full:  # the top layer is partial: a random subset of its sites
        top = full + rng.permutation(sites.shape[0] - full)[: n - full]
        keep = np.concatenate([keep, np.sort(top)])
    pos = sites[keep] + rng.uniform(-jit, jit, (n, 3))
    vel = rng.normal(0.0, p["velocity_jitter"], (n, 3))
    radii = np.full(n, r)
    mass = np.full(n, p["grain_density"] * 4.0 / 3.0 * np.pi * r ** 3)
    state = State(pos, vel, radii, mass)
    if "marble_radius" in p:
        state = add_marble(state, p)
    return state, {}


def add_marble(state, p):
    """The state plus the marble: on the axis, ``marble_gap`` above the highest grain."""
    rm = p["marble_radius"]
    top = float(np.max(state.pos[:, 2] + state.radius)) if state.n else 0.0
    pos = np.vstack([state.pos, [0.0, 0.0, top + p["marble_gap"] + rm]])
    vel = np.vstack([state.vel, [0.0, 0.0, -p["marble_speed"]]])
    radius = np.concatenate([state.radius, [rm]])
    mass = np.concatenate([state.mass, [p["marble_density"] * 4.0 / 3.0 * np.pi * rm ** 3]])
    ncoll = np.concatenate([state.ncoll, [0]])
    t_last = np.concatenate([state.t_last, [-np.inf]])
    return State(pos, vel, radius, mass, None, ncoll, t_last, state.time)


def fcc_gas(p):
    """Monodisperse spheres on an FCC lattice (random vacancies if n is not 4 m^3)
    in a periodic cube at packing fraction ``eta``, with Maxwell velocities at
    temperature ``temperature`` (energy units, k_B = 1), zero total momentum."""
    rng = np.random.default_rng(p["seed"])
    n = p["n"]
    d = p["diameter"]
    eta = p["eta"]
    if not 0.0 < eta < 0.7:
        raise ScenarioError("params.eta", f"must be in (0, 0.7), got {eta}")
    m = int(math.ceil((n / 4.0) ** (1.0 / 3.0) - 1e-9))
    length = (n * math.pi * d ** 3 / (6.0 * eta)) ** (1.0 / 3.0)
    a = length / m
    if a / math.sqrt(2.0) <= d:
        good = ", ".join(str(4 * k ** 3) for k in range(3, 9))
        raise ScenarioError("params.eta", f"eta = {eta} is too dense for an FCC start with "
                            f"n = {n} (lattice spacing {a / math.sqrt(2.0):.4g} < diameter {d}); "
                            f"choose n = 4 m^3 ({good}, ...) or slightly less")
    base = np.array([[0, 0, 0], [0.5, 0.5, 0], [0.5, 0, 0.5], [0, 0.5, 0.5]])
    cells = np.stack(np.meshgrid(*(np.arange(m),) * 3, indexing="ij"), -1).reshape(-1, 3)
    sites = ((cells[:, None, :] + base[None]) * a).reshape(-1, 3) - 0.5 * length + 0.25 * a
    if sites.shape[0] > n:
        sites = sites[np.sort(rng.permutation(sites.shape[0])[:n])]
    mass = p["mass"]
    vel = rng.normal(0.0, math.sqrt(p["temperature"] / mass), (n, 3))
    vel -= vel.mean(axis=0)
    vel *= math.sqrt(3.0 * (n - 1) * p["temperature"] / (mass * float(np.sum(vel * vel))))
    return State(sites, vel, np.full(n, 0.5 * d), np.full(n, mass)), {"length": length}


GENERATORS = {
    "ring_layer": (ring_layer, {"n", "seed", "radius_min", "radius_max", "size_slope", "density",
                                "tau", "dispersion", "thickness", "omega"}, {"moonlet_radius"}),
    "grain_block": (grain_block, {"n", "seed", "grain_radius", "grain_density", "cylinder_radius",
                                  "spacing", "jitter", "drop_height", "velocity_jitter"},
                    {"marble_radius", "marble_density", "marble_speed", "marble_gap"}),
    "fcc_gas": (fcc_gas, {"n", "seed", "eta", "diameter", "mass", "temperature"}, set()),
}
