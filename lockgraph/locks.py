"""Spatial lock regions for the parallel engine: the lock graph and grid locks.

Both give the same structure, rebuilt every step:

* ``lock_of`` (N,) int32 — the lock region of each storage slot (every
  particle has exactly one, including regions without neighbours);
* ``loff`` (R+1,) int64, ``ladj`` (E,) int32 — symmetric adjacency in CSR form,
  without self-loops or duplicates (lists in no particular order);
* ``boxes`` (R, 6) float64 — each region's box (for pictures and tests).

Coverage: any two particles that may meet within the step (anchors within
``reach[a] + reach[b]``, see ``tree``) lie in the same region or in adjacent
regions.  An event may run only if its particles' regions and all regions
adjacent to them are free.

**Lock graph** (Lewis & Swords): a node of the kD-tree is a lock node if it is a
leaf or if its size (largest box side) is below ``scale`` times the largest
reach under it; recursion stops at the first lock node on every root-to-leaf
path.  Edges come from the paper's two-argument recursion from (root, root)
(and root against each periodic image of root): two lock nodes whose boxes are
within their reaches are joined.  Larger ``scale`` moves lock nodes up the
tree: fewer, larger regions with fewer edges.

**Grid locks** (the earlier method): a uniform grid whose cell is at least the
largest pair reach (two largest reaches: "2 x max radius + search radius"),
over x-y (2-D, 8 neighbours) or x-y-z (3-D, 26 neighbours); periodic and
sheared boundaries get the neighbours their images bring.
"""
import math

import numpy as np

from ._jit import kernel
from .tree import END, LEFT, RIGHT, SELF_IMAGE, START, _box_gap2, box_gap2, search_tasks

KINDS = ("graph", "grid", "grid3d")


@kernel(inline=True)
def _far_from_others(nbox, nd, start, end, dlo, dhi, dbox, imgs, margin):
    """Does node nd lie in one domain, more than ``margin`` from the box of every
    other domain and of each of their periodic images?"""
    ndom = dlo.shape[0]
    own = -1
    for e in range(ndom):
        if dlo[e] <= start and end <= dhi[e]:
            own = e
    if own < 0:
        return False
    m2 = margin * margin
    for e in range(ndom):
        if e == own or dhi[e] <= dlo[e]:
            continue
        for k in range(imgs.shape[0]):
            if box_gap2(nbox, nd, dbox, e, imgs[k, 0], imgs[k, 1], imgs[k, 2]) <= m2:
                return False
    return True


@kernel
def _mark_lock_nodes(ntop, nbox, nreach, scale, lockid, stack, dlo, dhi, dbox, imgs, margin,
                     fine):
    """Top-down: lockid[nd] = region index for lock nodes, -1 above them.

    With domains (``dlo``/``dhi`` slot ranges, ``dbox`` their boxes, ``imgs``
    the periodic image offsets; empty arrays for none), a node of one domain
    farther than ``margin`` from every other domain is a lock node too.
    ``fine`` (3,) gets the sums of the size and the largest reach of the lock
    nodes that are not such merged ones, and their count.
    Returns the number of lock nodes (regions) or -1 if the stack was short.
    """
    nl = 0
    stack[0] = 0
    sp = 1
    fine[:] = 0.0
    while sp > 0:
        sp -= 1
        nd = stack[sp]
        size = max(nbox[nd, 3] - nbox[nd, 0], nbox[nd, 4] - nbox[nd, 1], nbox[nd, 5] - nbox[nd, 2])
        if ntop[nd, LEFT] < 0 or size < scale * nreach[nd]:
            fine[0] += size
            fine[1] += nreach[nd]
            fine[2] += 1.0
            lockid[nd] = nl
            nl += 1
            continue
        if dlo.shape[0] > 1 and _far_from_others(nbox, nd, ntop[nd, START], ntop[nd, END],
                                                 dlo, dhi, dbox, imgs, margin):
            lockid[nd] = nl
            nl += 1
            continue
        lockid[nd] = -1
        if sp + 2 > stack.shape[0]:
            return -1
        stack[sp] = ntop[nd, RIGHT]
        stack[sp + 1] = ntop[nd, LEFT]
        sp += 2
    return nl


@kernel
def _fill_lock_of(ntop, lockid, nnodes, lock_of, lnode):
    for nd in range(nnodes):
        k = lockid[nd]
        if k >= 0:
            lnode[k] = nd
            for s in range(ntop[nd, START], ntop[nd, END]):
                lock_of[s] = k


@kernel
def _lock_edges(ntop, nbox, nreach, lockid, tasks, img_pos, out_u, out_v, stack):
    """Two-argument recursion over lock nodes from the task pairs (see
    ``tree.search_tasks``).  Returns the number of edges found (entries beyond
    len(out_u) are counted, not stored), or -1 for a short stack."""
    cap = out_u.shape[0]
    count = 0
    for q in range(tasks.shape[0]):
        img = tasks[q, 2]
        ox = img_pos[img, 0]
        oy = img_pos[img, 1]
        oz = img_pos[img, 2]
        selfimg = img == SELF_IMAGE
        stack[0, 0] = tasks[q, 0]
        stack[0, 1] = tasks[q, 1]
        sp = 1
        while sp > 0:
            sp -= 1
            na = stack[sp, 0]
            nb = stack[sp, 1]
            if sp + 3 > stack.shape[0]:
                return -1
            ka = lockid[na]
            kb = lockid[nb]
            if selfimg and na == nb:
                if ka >= 0:
                    continue
                la = ntop[na, LEFT]
                ra = ntop[na, RIGHT]
                stack[sp, 0] = la
                stack[sp, 1] = la
                stack[sp + 1, 0] = la
                stack[sp + 1, 1] = ra
                stack[sp + 2, 0] = ra
                stack[sp + 2, 1] = ra
                sp += 3
                continue
            r = nreach[na] + nreach[nb]
            if _box_gap2(nbox, na, nb, ox, oy, oz) > r * r:
                continue
            if ka >= 0 and kb >= 0:
                if ka != kb:
                    if count < cap:
                        out_u[count] = min(ka, kb)
                        out_v[count] = max(ka, kb)
                    count += 1
                continue
            if ka >= 0 or (kb < 0 and (nbox[nb, 3] - nbox[nb, 0]) + (nbox[nb, 4] - nbox[nb, 1])
                           + (nbox[nb, 5] - nbox[nb, 2]) > (nbox[na, 3] - nbox[na, 0])
                           + (nbox[na, 4] - nbox[na, 1]) + (nbox[na, 5] - nbox[na, 2])):
                stack[sp, 0] = na
                stack[sp, 1] = ntop[nb, LEFT]
                stack[sp + 1, 0] = na
                stack[sp + 1, 1] = ntop[nb, RIGHT]
            else:
                stack[sp, 0] = ntop[na, LEFT]
                stack[sp, 1] = nb
                stack[sp + 1, 0] = ntop[na, RIGHT]
                stack[sp + 1, 1] = nb
            sp += 2
    return count


@kernel
def _edges_csr(nreg, u, v, m, loff, ladj, tmp, mark):
    """Symmetric CSR adjacency, duplicates removed.

    ``u[:m]``, ``v[:m]``: edges (either order, duplicates allowed); ``loff``
    (nreg+1,) and ``ladj`` (2m,) receive the result, ``tmp`` (2m,) and
    ``mark`` (nreg,) are work space.  Each list keeps the edges' order (the
    first of duplicates): deterministic for a given edge list.  Returns the
    number of adjacency entries.
    """
    for r in range(nreg + 1):
        loff[r] = 0
    for k in range(m):
        loff[u[k] + 1] += 1
        loff[v[k] + 1] += 1
    for r in range(nreg):
        loff[r + 1] += loff[r]
    for k in range(m):  # fill, with loff[r] as r's cursor
        tmp[loff[u[k]]] = v[k]
        loff[u[k]] += 1
        tmp[loff[v[k]]] = u[k]
        loff[v[k]] += 1
    for r in range(nreg, 0, -1):
        loff[r] = loff[r - 1]
    loff[0] = 0
    for r in range(nreg):
        mark[r] = -1
    # duplicates by marking, not sorting: an insertion sort of every short list
    # cost 0.8 of 1.3 ms at 16,000 regions (N = 2e5), its branches unpredictable
    out = 0
    for r in range(nreg):
        s = loff[r]
        e = loff[r + 1]
        loff[r] = out
        for a in range(s, e):
            x = tmp[a]
            if mark[x] != r:
                mark[x] = r
                ladj[out] = x
                out += 1
    loff[nreg] = out
    return out


def _csr(nregions, u, v):
    """Symmetric CSR adjacency from an edge list (duplicates removed)."""
    m = len(u)
    loff = np.zeros(nregions + 1, np.int64)
    ladj = np.zeros(2 * m, np.int32)
    k = _edges_csr(nregions, u.astype(np.int32), v.astype(np.int32), m, loff, ladj,
                   np.zeros(2 * m, np.int32), np.zeros(nregions, np.int32))
    return loff, ladj[:k].copy()


class LockRegions:
    """Lock regions of one step.  See the module docstring for the arrays."""

    def __init__(self, kind, lock_of, loff, ladj, boxes, info):
        self.kind = kind
        self.lock_of = lock_of
        self.loff = loff
        self.ladj = ladj
        self.boxes = boxes
        self.info = info

    @property
    def count(self):
        return self.loff.shape[0] - 1

    def degrees(self):
        return np.diff(self.loff)

    def stats(self):
        d = self.degrees()
        occupied = np.bincount(self.lock_of, minlength=self.count)
        return {"kind": self.kind, "regions": int(self.count),
                "occupied": int(np.count_nonzero(occupied)),
                "mean_degree": float(d.mean()) if d.size else 0.0,
                "max_degree": int(d.max()) if d.size else 0,
                "mean_particles": float(occupied[occupied > 0].mean()) if occupied.any() else 0.0,
                **{k: v for k, v in self.info.items() if not isinstance(v, np.ndarray)}}

    def adjacent(self, a, b):
        """True if regions a and b are the same or adjacent."""
        if a == b:
            return True
        return b in self.ladj[self.loff[a]:self.loff[a + 1]]


def lock_graph(ntop, nbox, nreach, nnodes, half_images, img_pos, scale, n, pmap=None,
               parts=1, domains=None):
    """The lock graph of a built tree (node bounds and reaches filled in).

    ``pmap(fn, arglists)``, if given, runs the edge search in ``parts`` pieces
    on worker threads.  ``domains = (dlo, dhi, dbox, images, margin)``, if
    given, also makes a lock node of every node that lies in one domain farther
    than ``margin`` from all the others (see ``Engine._far_domains``)."""
    lockid = np.full(nnodes, -1, np.int32)
    stack = np.zeros(256, np.int64)
    if domains is None:
        no = np.zeros(0, np.int64)
        domains = (no, no, np.zeros((0, 6)), np.zeros((0, 3)), 0.0)
    dlo, dhi, dbox, imgs, margin = domains
    fine = np.zeros(3)
    nl = _mark_lock_nodes(ntop, nbox, nreach, float(scale), lockid, stack, dlo, dhi, dbox, imgs,
                          float(margin), fine)
    if nl < 0:
        raise RuntimeError("lock-node search deeper than its stack")
    lock_of = np.zeros(n, np.int32)
    lnode = np.zeros(nl, np.int32)
    _fill_lock_of(ntop, lockid, nnodes, lock_of, lnode)
    pmap = pmap or (lambda fn, args: [fn(*a) for a in args])
    tasks = search_tasks(ntop, half_images, parts, stop=lockid)
    cap = 8 * nl // parts + 64
    while True:
        u = np.zeros((parts, cap), np.int32)
        v = np.zeros((parts, cap), np.int32)
        ms = pmap(_lock_edges, [(ntop, nbox, nreach, lockid, tasks[k], img_pos, u[k], v[k],
                                 np.zeros((4096, 2), np.int64)) for k in range(parts)])
        if min(ms) < 0:
            raise RuntimeError("lock-graph recursion deeper than its stack")
        if max(ms) <= cap:
            break
        cap = max(ms) + 64
    u = np.concatenate([u[k, :ms[k]] for k in range(parts)])
    v = np.concatenate([v[k, :ms[k]] for k in range(parts)])
    loff, ladj = _csr(nl, u, v)
    # np.take: fancy indexing of the (R, 6) rows took 0.24 ms here at N = 2e5, take 0.06
    # the mean hop between fine regions: a size plus twice a reach (regions
    # farther apart than their reaches are not adjacent)
    hop = (fine[0] + 2.0 * fine[1]) / fine[2] if fine[2] > 0 else 0.0
    return LockRegions("graph", lock_of, loff, ladj, np.take(nbox, lnode, axis=0),
                       {"scale": float(scale), "lock_nodes": lnode, "fine_hop": hop})


def grid_locks(anc, reach_pair_max, domain, time, dims=2):
    """Grid lock regions over x-y (dims=2) or x-y-z (dims=3) for step-start anchors."""
    n = anc.shape[0]
    c = max(float(reach_pair_max), 1e-300)
    periodic = list(domain.periodic)
    lo = np.zeros(3)
    size = np.zeros(3)
    ncell = np.ones(3, np.int64)
    box_len = [getattr(domain, "lx", None), getattr(domain, "ly", None), None]
    if domain.describe()["type"] == "periodic_cube":
        box_len = [domain.length] * 3
    for a in range(dims):
        if periodic[a]:
            L = box_len[a]
            ncell[a] = max(1, int(math.floor(L / c)))
            lo[a] = -0.5 * L
            size[a] = L / ncell[a]
        else:
            amin, amax = float(anc[:, a].min()), float(anc[:, a].max())
            ncell[a] = max(1, int(math.ceil((amax - amin) / c)))
            lo[a] = amin
            size[a] = max((amax - amin) / ncell[a], c)
    for a in range(dims, 3):
        lo[a] = float(anc[:, a].min())
        size[a] = max(float(anc[:, a].max()) - lo[a], 1e-300) * (1 + 1e-12) + 1e-300
    idx = np.zeros((n, 3), np.int64)
    for a in range(3):
        if a < dims:
            idx[:, a] = np.clip(np.floor((anc[:, a] - lo[a]) / size[a]).astype(np.int64), 0,
                                ncell[a] - 1)
    nx, ny, nz = ncell
    lock_of = ((idx[:, 0] * ny + idx[:, 1]) * nz + idx[:, 2]).astype(np.int32)
    nregions = int(nx * ny * nz)
    # neighbours: for every cell and periodic image, the cells whose boxes lie within c
    img_pos, img_vel, half, full = domain.images(time)
    ii, jj, kk = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    cells = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], 1)
    cell_lo = lo + cells * size
    cell_hi = cell_lo + size
    glo = lo
    ghi = lo + ncell * size
    us, vs = [], []
    stencil = [np.array(d) for d in np.ndindex(*([4] * dims))]
    for img in full:
        off = img_pos[img].copy()
        if dims == 2:
            off[2] = 0.0
        # cells whose box, moved by -off, still comes within c of the grid
        slo = cell_lo - off
        shi = cell_hi - off
        sel = np.ones(len(cells), bool)
        for a in range(dims):
            sel &= (shi[:, a] >= glo[a] - c) & (slo[:, a] <= ghi[a] + c)
        if not sel.any():
            continue
        a_all = np.flatnonzero(sel)
        base = np.floor((slo[sel] - lo) / size).astype(np.int64)
        for d in stencil:
            other = base.copy()
            other[:, :dims] += d - 1  # offsets -1 .. 2 around where the moved box starts
            if dims == 2:
                other[:, 2] = 0
            ok = np.ones(len(a_all), bool)
            for a in range(3):
                ok &= (other[:, a] >= 0) & (other[:, a] < ncell[a])
            if not ok.any():
                continue
            o = other[ok]
            a_id = a_all[ok]
            olo = lo + o * size + off
            ohi = olo + size
            gap = np.maximum(0.0, np.maximum(cell_lo[a_id] - ohi, olo - cell_hi[a_id]))
            if dims == 2:
                gap[:, 2] = 0.0
            near = (gap ** 2).sum(1) <= c * c
            a_id = a_id[near]
            b = o[near]
            b_id = (b[:, 0] * ny + b[:, 1]) * nz + b[:, 2]
            keep = a_id != b_id
            us.append(np.minimum(a_id[keep], b_id[keep]))
            vs.append(np.maximum(a_id[keep], b_id[keep]))
    u = np.concatenate(us) if us else np.zeros(0, np.int64)
    v = np.concatenate(vs) if vs else np.zeros(0, np.int64)
    loff, ladj = _csr(nregions, u, v)
    boxes = np.concatenate([cell_lo, cell_hi], 1)
    kind = "grid" if dims == 2 else "grid3d"
    return LockRegions(kind, lock_of, loff, ladj, boxes,
                       {"cell": size[:dims].tolist(), "cells": ncell[:dims].tolist()})
