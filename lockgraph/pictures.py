"""Pictures of a scene: a snapshot of the particles and its lock graph drawn
over them (like Figure 3 of Lewis & Swords).  PNG files written atomically;
matplotlib is imported only when a picture is drawn.

Rings are seen from above (x, y); dishes from the side (x, z).  Lengths in m.
"""
import numpy as np

from .domains import Dish
from .report_charts import pyplot, save


def _view(domain):
    """(drawn axes, depth axis, axis labels): x-z with depth y for a dish, x-y
    with depth z for a ring patch."""
    if isinstance(domain, Dish):
        return (0, 2), 1, ("x (m)", "z (m)")
    return (0, 1), 2, ("x (m)", "y (m)")


def _big(radius):
    """Mask of the largest body if it is a body of its own (a marble or a
    moonlet): over 3 times the next largest radius.  The median is no test: a
    ring's power-law radii put its largest particle ~7 medians up."""
    if radius.size < 2:
        return np.zeros(radius.size, bool)
    second, top = np.partition(radius, -2)[-2:]
    return (radius == top) & (top > 3.0 * second)


def _frame(ax, domain, pos, radius, names, title):
    """Walls and floor of a dish or the box of a ring patch; equal aspect, labels."""
    from matplotlib.ticker import MaxNLocator

    if isinstance(domain, Dish):
        r = domain.radius
        top = float(np.max(pos[:, 2] + radius))
        ax.plot([-r, -r, r, r], [top, 0.0, 0.0, top], color="k", lw=1.5)
    else:
        hx, hy = domain.lx / 2, domain.ly / 2
        ax.plot([-hx, hx, hx, -hx, -hx], [-hy, -hy, hy, hy, -hy], color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.xaxis.set_major_locator(MaxNLocator(5))  # a dish's mm-sized ticks collide otherwise
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_title(title, fontsize=10)


def _circles(ax, pos, radius, axes, colours, alpha=1.0):
    """Each particle a disc of its true radius (data units), in the given order."""
    from matplotlib.collections import EllipseCollection

    d = 2.0 * radius
    ax.add_collection(EllipseCollection(d, d, np.zeros_like(d), units="xy",
                                        offsets=pos[:, list(axes)], transOffset=ax.transData,
                                        facecolors=colours, edgecolors="none", alpha=alpha))


def _depth_colours(near):
    """RGBA per particle from its nearness to the viewer in [0, 1]: near is lighter."""
    return np.column_stack([0.2 + 0.5 * near, 0.35 + 0.45 * near, 0.65 + 0.2 * near,
                            np.ones_like(near)])


def scene_snapshot(sc, path, title=None):
    """Draw ``sc``'s particles as discs of their true radii (m), the big body
    (marble or moonlet) in red, with the dish walls and floor or the ring
    patch's box; returns ``path``."""
    plt = pyplot()
    st, dom = sc.state, sc.physics.domain
    axes, depth, names = _view(dom)
    # nearer particles drawn last so they cover farther ones: the viewer is
    # above a ring (+z) and in front of a dish (-y, so that x runs to the right)
    toward = st.pos[:, depth] * (1.0 if depth == 2 else -1.0)
    order = np.argsort(toward, kind="stable")
    near = (toward[order] - toward.min()) / max(np.ptp(toward), 1e-300)
    colours = _depth_colours(near)
    colours[_big(st.radius)[order]] = (0.85, 0.15, 0.15, 1.0)
    fig, ax = plt.subplots(figsize=(6.0, 4.8))
    _circles(ax, st.pos[order], st.radius[order], axes, colours)
    _frame(ax, dom, st.pos, st.radius, names, title or f"N = {st.n}")
    return save(fig, path)


def lock_regions(sc, scale=4.0):
    """(region of each particle id (N,), loff (R+1,), ladj) of the lock graph at
    ``scale`` for ``sc``'s state: the regions the first step of a sequential
    engine builds, from the positions at the step's start, i.e. ``sc.state.pos``
    (CSR adjacency: the neighbours of region a are ladj[loff[a]:loff[a+1]])."""
    from .engine import Engine

    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=[("graph", scale)])
    eng.step()
    return eng.trace()["steps"][0]["locks"][("graph", float(scale))]


def _centroids(by_id, nreg, pos, radius):
    """(centre (R, 3) m, particle count (R,)) of each region; empty regions at 0.
    The centre weights each particle by its cross-section r**2, so a region
    holding a moonlet or marble sits on it, as in the paper's Figure 3 (a plain
    mean lands among the hundreds of small particles sharing its region)."""
    count = np.bincount(by_id, minlength=nreg)
    w = radius ** 2
    total = np.bincount(by_id, weights=w, minlength=nreg)
    centre = np.column_stack([np.bincount(by_id, weights=w * pos[:, k], minlength=nreg)
                              for k in range(3)])
    used = count > 0
    centre[used] /= total[used, None]
    return centre, count


def _edge_segments(dom, time, a, b):
    """Segments (S, 2, 3) drawing the edges between centroids a[k] and b[k]: a
    straight line, or, when the nearest periodic image of b is not b itself
    (a ring's adjacency across its box side), one stub from each end towards
    the other's image, to be clipped at the box."""
    if isinstance(dom, Dish):
        return np.stack([a, b], axis=1)
    delta = dom.offset(time)
    shifts = np.array([(kx * dom.lx, kx * delta + ky * dom.ly, 0.0)
                       for kx in (-1, 0, 1) for ky in (-1, 0, 1)])
    # only x-y distance: z is not drawn and not periodic
    d2 = (((b[:, None, :2] + shifts[None, :, :2]) - a[:, None, :2]) ** 2).sum(axis=2)
    s = shifts[np.argmin(d2, axis=1)]
    across = np.any(s != 0.0, axis=1)
    return np.concatenate([np.stack([a, b + s], axis=1),
                           np.stack([b[across], a[across] - s[across]], axis=1)])


def lock_graph_figure(sc, path, scale=4.0, title=None):
    """Draw the lock graph at ``scale`` over ``sc``'s particles (small, grey):
    each occupied region a node at its particles' area-weighted centroid (m,
    see ``_centroids``), its marker area growing with their number; each
    adjacent pair of occupied regions an edge (on a ring, a pair adjacent
    across the periodic box side is drawn as two stubs to the box edge).
    Returns {"regions", "edges", "particles", "scale"}: the occupied regions
    and adjacent pairs of them drawn (for the lock graph, every region is
    occupied: regions = R, edges = len(ladj) // 2)."""
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

    plt = pyplot()
    st, dom = sc.state, sc.physics.domain
    axes, _, names = _view(dom)
    by_id, loff, ladj = lock_regions(sc, scale)
    nreg = loff.shape[0] - 1
    centre, count = _centroids(by_id, nreg, st.pos, st.radius)
    used = count > 0
    owner = np.repeat(np.arange(nreg), np.diff(loff))
    keep = (owner < ladj) & used[owner] & used[ladj]  # each undirected pair once
    seg = _edge_segments(dom, st.time, centre[owner[keep]], centre[ladj[keep]])
    fig, ax = plt.subplots(figsize=(6.0, 4.8))
    _circles(ax, st.pos, st.radius, axes, np.array([[0.6, 0.6, 0.6, 1.0]]), alpha=0.35)
    lines = LineCollection(seg[:, :, list(axes)], colors="C0", linewidths=0.7, alpha=0.7)
    # the stubs' far ends lie outside a ring's box: keep them out of the axis limits
    ax.add_collection(lines, autolim=False)
    if not isinstance(dom, Dish):
        lines.set_clip_path(Rectangle((-dom.lx / 2, -dom.ly / 2), dom.lx, dom.ly,
                                      transform=ax.transData))
    a, b = axes
    ax.scatter(centre[used, a], centre[used, b], s=4 + 60 * count[used] / count.max(),
               color="C3", zorder=3)
    _frame(ax, dom, st.pos, st.radius, names, title or f"lock graph, SCALE {scale:g}")
    save(fig, path)
    return {"regions": int(used.sum()), "edges": int(keep.sum()), "particles": int(st.n),
            "scale": float(scale)}
