"""Pictures of a scene: a snapshot of the particles and its lock graph drawn
over them (like Figure 3 of Lewis & Swords).  PNG files written atomically;
matplotlib is imported only when a picture is drawn.

Rings are seen from above (x, y); dishes from the side (x, z).
"""
import numpy as np

from .domains import Dish
from .report_charts import pyplot, save


def _view(domain):
    """(the two coordinate axes drawn, their names)."""
    return ((0, 2), ("x (m)", "z (m)")) if isinstance(domain, Dish) else ((0, 1), ("x (m)", "y (m)"))


def _big(radius):
    """Mask of the largest body if it is much larger than the typical particle
    (a marble or a moonlet; a ring's size spread is not one)."""
    top = radius.max()
    return (radius == top) & (top > 5.0 * np.median(radius))


def _frame(ax, domain, pos, radius, axes):
    """Walls and floor of a dish, the box of a ring patch; equal aspect."""
    if isinstance(domain, Dish):
        r = domain.radius
        top = float(np.max(pos[:, 2] + radius))
        ax.plot([-r, -r, r, r], [top, 0.0, 0.0, top], color="k", lw=1.5)
    else:
        lx, ly = domain.lx, domain.ly
        ax.plot([-lx / 2, lx / 2, lx / 2, -lx / 2, -lx / 2],
                [-ly / 2, -ly / 2, ly / 2, ly / 2, -ly / 2], color="k", lw=0.8)
    ax.set_aspect("equal")


def _circles(ax, pos, radius, axes, colours, alpha=1.0):
    from matplotlib.collections import EllipseCollection

    a, b = axes
    d = 2.0 * radius
    ax.add_collection(EllipseCollection(d, d, np.zeros_like(d), units="xy",
                                        offsets=pos[:, [a, b]], transOffset=ax.transData,
                                        facecolors=colours, edgecolors="none", alpha=alpha))


def scene_snapshot(sc, path, title=None):
    """Draw ``sc``'s particles at their true radii (the big body in red) with
    its walls or box; returns ``path``."""
    plt = pyplot()
    st, dom = sc.state, sc.physics.domain
    axes, names = _view(dom)
    fig, ax = plt.subplots(figsize=(6.0, 4.8))
    big = _big(st.radius)
    # side view of a dish: draw back to front so nearer grains cover farther ones
    order = np.argsort(st.pos[:, 1]) if isinstance(dom, Dish) else np.arange(st.n)
    shade = (st.pos[order, 1] - st.pos[:, 1].min()) / max(np.ptp(st.pos[:, 1]), 1e-30)
    colours = np.column_stack([0.25 + 0.5 * shade, 0.45 + 0.35 * shade,
                               0.8 - 0.2 * shade, np.ones_like(shade)])
    colours[big[order]] = (0.85, 0.15, 0.15, 1.0)
    _circles(ax, st.pos[order], st.radius[order], axes, colours)
    _frame(ax, dom, st.pos, st.radius, axes)
    ax.autoscale_view()
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_title(title or f"N = {st.n}", fontsize=10)
    return save(fig, path)


def lock_regions(sc, scale=4.0):
    """(region of each particle id, loff, ladj) of the lock graph at ``scale``
    for ``sc``'s state: the regions the first step of a sequential engine
    builds (CSR adjacency: the neighbours of region a are ladj[loff[a]:loff[a+1]])."""
    from .engine import Engine

    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=[("graph", scale)])
    eng.step()
    (by_id, loff, ladj), = eng.trace()["steps"][0]["locks"].values()
    return by_id, loff, ladj


def lock_graph_figure(sc, path, scale=4.0, title=None):
    """Draw the lock graph at ``scale`` over ``sc``'s particles: each occupied
    region a node at its particles' centroid, sized by their number; an edge
    per adjacent pair of occupied regions (on a ring, pairs adjacent only
    across the periodic boundary are counted but not drawn).  Returns
    {"regions", "edges", "particles", "scale"}: occupied regions and adjacent
    pairs of them."""
    plt = pyplot()
    st, dom = sc.state, sc.physics.domain
    axes, names = _view(dom)
    by_id, loff, ladj = lock_regions(sc, scale)
    nreg = loff.shape[0] - 1
    count = np.bincount(by_id, minlength=nreg)
    centre = np.zeros((nreg, 3))
    for k in range(3):
        centre[:, k] = np.bincount(by_id, weights=st.pos[:, k], minlength=nreg)
    used = count > 0
    centre[used] /= count[used, None]
    owner = np.repeat(np.arange(nreg), np.diff(loff))
    keep = (owner < ladj) & used[owner] & used[ladj]
    u, v = owner[keep], ladj[keep]
    fig, ax = plt.subplots(figsize=(6.0, 4.8))
    _circles(ax, st.pos, st.radius, axes, np.array([[0.7, 0.7, 0.7, 1.0]]), alpha=0.5)
    a, b = axes
    if not isinstance(dom, Dish):
        # adjacency across the periodic (and sheared) boundary would cross the
        # whole box: those edges are left out of the picture (still counted)
        d = np.abs(centre[v] - centre[u])
        inside = (d[:, 0] < 0.5 * dom.lx) & (d[:, 1] < 0.5 * dom.ly)
        u, v = u[inside], v[inside]
    edges = np.stack([centre[u][:, [a, b]], centre[v][:, [a, b]]], axis=1)
    from matplotlib.collections import LineCollection

    ax.add_collection(LineCollection(edges, colors="C0", linewidths=0.6, alpha=0.6))
    ax.scatter(centre[used, a], centre[used, b], s=2 + 40 * count[used] / count.max(),
               color="C3", zorder=3)
    _frame(ax, dom, st.pos, st.radius, axes)
    ax.autoscale_view()
    ax.set_xlabel(names[0])
    ax.set_ylabel(names[1])
    ax.set_title(title or f"lock graph, SCALE {scale:g}", fontsize=10)
    save(fig, path)
    return {"regions": int(used.sum()), "edges": int(keep.sum()), "particles": int(st.n),
            "scale": float(scale)}
