"""numba kernels of one step's drift phase: predict, collide, grow, run events.

Argument bundles (tuples of plain arrays; all particle arrays in storage order,
which is the tree order of the current step):

* ``parts = (pos, vel, rad, mass, tl, ncoll, tlast, ids)`` — the state (``tlast``,
  the collapse guard's per-particle word, is empty unless the physics has the
  TC guard, whose last pair-impact times it holds, or sleeping grains, whose
  sleep states it holds: AWAKE, ASLEEP or a drowsy grain's time; ``ids`` int32); inside
  the drift phase ``pos``/``vel`` are *frame* coordinates (free-falling frame
  when there is gravity): a particle is at ``pos + vel * t`` at step time t
  (``pos`` is its position extrapolated to the step start, reset whenever its
  velocity changes) and ``tl`` is the step time of its last change.
* ``step = (anc, reach, cis, work)`` — anchors (step-start positions, (N,3)),
  reaches (N,) (search radius + fr * radius, see ``tree``), collisions of each
  particle in this step (N,) int32, and an int64 work array (a search stack
  deeper than the tree).
* ``tree = (ntop, nbox, nreach, nreach_bits)`` — see ``tree`` (the last is an
  int64 view of ``nreach`` for atomic maxima).
* ``nbrs = (noff, nent, xhead, xent, xnext, ctr)`` — see ``neighbors``.
* ``evq = (evt, evp, evc, tour_t, tour_s, hidden)`` — see ``events``.
* ``jour = (jslot, jvel, jtlast, logt, logi)`` — undo journal: the velocity
  and last collision time of each particle before its first collision in the
  step; and the optional event log (empty arrays: off): ``logt`` (L,) step
  time and ``logi`` (L,3) int64 ``(id_a, id_b or FLOOR/CYLINDER, img)`` of
  every resolved collision, seen from particle a.
* ``cfg = (par, ipar, img_pos, img_vel, img_all, parb)`` — step constants
  (``parb`` is an int64 view of ``par``, for the atomic P_RMAX).
* ``locks = (lock_of, loff, ladj, hops)`` — the step's lock regions (empty
  arrays when running sequentially); a widened reach that brings together
  particles of non-adjacent regions is a violation of the lock design.  The
  pool schedule has no regions: ``lock_of`` is each slot's domain and
  ``hops`` (4, N) int64 its one- and two-hop domain masks (0 until first
  used: ``hop1``, ``hop2``) and its checked and exposed marks (``pool``);
  the rule for a new pair is then ``pool``'s (``regions_adjacent``).  ``hops`` is (4, 0) otherwise.
* ``st`` (NSTAT,) float64 — statistics of the step (one row per thread); its
  slots ``S_JNEXT`` / ``S_JEND`` hold the calling thread's journal block (not
  statistics: the engine clears them).

Counters shared between threads (pool, journal, log) are advanced with atomic
fetch-add, tree reaches with atomic maxima; everything else a kernel writes
belongs to particles whose lock regions the calling thread holds.

Kernels return a status code; all state lives in the arrays, so a kernel that
stops for more room resumes exactly where it left off.
"""
import math

import numpy as np
from ._jit import kernel

from .forces import hill_coefficients, hill_kicked
from .events import (BUCKET_BITS, CYLINDER, FLOOR, NONE, build_inner, build_leaves,
                     build_queue, buckets_of, update_queue, update_queue_pair)
from .atomics import (cycles, fetch_add, fetch_max, fetch_or, float_bits, load, prefetch_read,
                      prefetch_write, store)
from .neighbors import JCOUNT, LCOUNT, TCOUNT, XCOUNT, add_pair
from .predict import (INF, cylinder_time, cylinder_time_by, floor_time, floor_time_by,
                      pair_time, pair_time_by)
from .restitution import coefficient
from .tree import END, LEFT, RIGHT, SELF_IMAGE, START, pair_reach_ok, point_gap2, raise_reach

# par: float parameters of the step
(P_DT, P_T0, P_SHEAR, P_FR, P_G, P_RCYL, P_E, P_VC, P_EXP, P_TC, P_WMIN, P_HALFPER,
 P_RMAX, P_EXTRA, P_VMIN, P_VEXP, P_VSLEEP, P_TSLEEP) = range(18)
NPAR = 18
# sleep states (in ``tlast`` when P_VSLEEP > 0): awake (-inf), asleep (+inf: at
# rest on its support, its velocity set by the step, not by impacts), and
# drowsy: a finite word s, the time (the run's clock) from which every impact
# was a slow one on a support (with P_TSLEEP > 0: on any body); asleep from
# the first step end at least P_TSLEEP after s (P_TSLEEP = 0: the end of the
# step of its slow impact)
AWAKE, ASLEEP = -math.inf, math.inf
# ipar: integer parameters
I_LAW, I_DISH, I_CAP, I_PAPER = range(4)
NIPAR = 4
# st: statistics
(S_PAIR, S_WALL, S_STALE, S_GRAZE, S_GROW, S_ADDED, S_MAXOV, S_VIRIAL, S_POPS,
 S_FLOORIMP, S_CYLIMP, S_MAXCIS, S_VIOL, S_BLOCKED, S_WAIT, S_CONC, S_CLAIMS, S_REACHOUT,
 S_ECYC, S_XFLUX, S_GUARDED, S_JNEXT, S_JEND, S_WOKEN, S_ASKED) = range(25)
NSTAT = 32  # 256 bytes: four cache lines, so rows of a 64-byte aligned array share none
# journal entries a thread claims at a time: one shared fetch-add per JBLOCK
# entries, not one per entry (in a dense bed nearly every event journals a
# particle, and two threads adding to one counter pass its line to and fro)
JBLOCK = 64
# status codes
(OK, NEED_JOURNAL, POOL_OVERFLOW, COLLAPSE, SIGMA_TOO_LARGE, CHUNK, NEED_LOG, VIOLATION, STALL,
 NEED_TRACE) = range(10)
# trace kinds
T_PAIR, T_WALL, T_STALE = 0, 1, 2
CTR_BAD = 2  # ctr slot: the slot that caused a COLLAPSE / SIGMA_TOO_LARGE

WALL_KEY_FLOOR = 1 << 62
WALL_KEY_CYL = (1 << 62) + 1


@kernel(inline=True)
def slow_impact(ipar, par, vn):
    """Restitution of an impact the collapse guard covers (normal speed vn >= 0):
    1 (elastic) under the TC model and the hard velocity guard; under the soft
    velocity guard (exponent p = par[P_VEXP] > 0, only below v_min)
    1 - (1 - e(vn)) (vn / v_min)^p."""
    p = par[P_VEXP]
    if p <= 0.0 or vn >= par[P_VMIN]:  # TC-guarded impacts may be fast: elastic
        return 1.0
    e = coefficient(ipar[I_LAW], par[P_E], par[P_VC], par[P_EXP], vn)
    r = vn / par[P_VMIN]
    # the scenes' exponent 2 without a call to pow (5 % of a settling bed's time)
    f = r * r if p == 2.0 else r ** p
    return 1.0 - (1.0 - e) * f


@kernel(inline=True)
def rel_speed2(vel, i, j):
    """Squared speed of i relative to j."""
    ux = vel[i, 0] - vel[j, 0]
    uy = vel[i, 1] - vel[j, 1]
    uz = vel[i, 2] - vel[j, 2]
    return ux * ux + uy * uy + uz * uz


@kernel(inline=True)
def position_at(pos, vel, i, t):
    """Frame position (x, y, z) of particle i at step time t."""
    return (pos[i, 0] + vel[i, 0] * t, pos[i, 1] + vel[i, 1] * t, pos[i, 2] + vel[i, 2] * t)


@kernel(inline=True)
def overlap_now(pos, i, j, img, img_pos, contact):
    """Relative overlap (contact - distance) / contact of i and image img of j at
    the step start; 0 if they do not touch."""
    dx = pos[i, 0] - pos[j, 0] - img_pos[img, 0]
    dy = pos[i, 1] - pos[j, 1] - img_pos[img, 1]
    dz = pos[i, 2] - pos[j, 2] - img_pos[img, 2]
    d2 = dx * dx + dy * dy + dz * dz
    if d2 < contact * contact:
        return (contact - math.sqrt(d2)) / contact
    return 0.0


@kernel(inline=True)
def predict(i, t_now, parts, nbrs, evq, cfg):
    """Set particle i's earliest event at or after t_now (ties: partner id, image)."""
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    noff, nent, xhead, xent, xnext, ctr = nbrs
    evt, evp, evc, tour_t, tour_s, hidden = evq
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    t_end = par[P_DT]
    best = INF
    cut = t_end  # the contact tests' cut: the best so far (every finite time is < t_end)
    bkey = WALL_KEY_CYL + 1
    bp = NONE
    bc = 0
    ri = rad[i]
    for k in range(noff[i], noff[i + 1]):
        e = nent[k]
        j = e >> 5
        img = e & 31
        t = pair_time_by(pos, vel, i, j, img, img_pos, img_vel, ri + rad[j], t_now, t_end, cut)
        if t <= best and t < INF:
            key = ids[j] * 32 + img
            if t < best or key < bkey:
                best = t
                cut = t
                bkey = key
                bp = e
                bc = ncoll[j]
    x = xhead[i]
    while x >= 0:
        e = xent[x]
        j = e >> 5
        img = e & 31
        t = pair_time_by(pos, vel, i, j, img, img_pos, img_vel, ri + rad[j], t_now, t_end, cut)
        if t <= best and t < INF:
            key = ids[j] * 32 + img
            if t < best or key < bkey:
                best = t
                cut = t
                bkey = key
                bp = e
                bc = ncoll[j]
        x = xnext[x]
    if ipar[I_DISH] != 0 and not (par[P_VSLEEP] > 0.0 and tlast[i] == ASLEEP):
        # (an asleep grain rises and comes back to rest: no wall can stop it)
        t = floor_time_by(pos, vel, tl, i, ri, par[P_G], t_now, t_end, cut)
        if t < best:
            best = t
            cut = t
            bp = FLOOR
        t = cylinder_time_by(pos, vel, tl, i, ri, par[P_RCYL], t_now, t_end, cut)
        if t < best:
            best = t
            bp = CYLINDER
    evt[i] = best
    evp[i] = bp
    evc[i] = np.int32(bc)


@kernel(inline=True)
def journal(i, vel, tlast, cis, jour, ctr, st):
    """Record i's velocity and last collision time before its first change this
    step, in the calling thread's block of the journal (``st[S_JNEXT]`` up to
    ``st[S_JEND]``); a new block is claimed when it is used up, its entries
    marked unused (slot -1) until written.  The caller has checked the room
    (``journal_room``)."""
    if cis[i] == 0:
        jslot = jour[0]
        jvel = jour[1]
        jtlast = jour[2]
        k = np.int64(st[S_JNEXT])
        if k >= np.int64(st[S_JEND]):
            k = fetch_add(ctr, JCOUNT, JBLOCK)
            for q in range(k, k + JBLOCK):
                jslot[q] = -1
            st[S_JEND] = k + JBLOCK
        st[S_JNEXT] = k + 1
        jslot[k] = i
        jvel[k, 0] = vel[i, 0]
        jvel[k, 1] = vel[i, 1]
        jvel[k, 2] = vel[i, 2]
        if tlast.shape[0] > 0:  # tracked only under a collapse guard
            jtlast[k] = tlast[i]


@kernel(inline=True)
def journal_room(st, ctr, cap, claims):
    """Room for the two entries of one more event of the calling thread, while
    up to ``claims`` threads (this one included) may each claim a block?"""
    return st[S_JEND] - st[S_JNEXT] >= 2 or ctr[JCOUNT] + claims * JBLOCK <= cap


@kernel(inline=True)
def log_event(jour, ctr, t, a, b, img):
    logt = jour[3]
    if logt.shape[0] > 0:
        logi = jour[4]
        k = fetch_add(ctr, LCOUNT, 1)
        logt[k] = t
        logi[k, 0] = a
        logi[k, 1] = b
        logi[k, 2] = img


@kernel(inline=True)
def hop1(hops, sdom, noff, nent, s):
    """The pool's one-hop domain mask of slot s: the domains of s and its
    step-start candidates (CSR), worked out at its first use in the step and
    kept in ``hops[0]`` (0 until then: a mask always holds s's own domain).
    Threads that race to fill it write the same value (atomic words: a
    reader sees 0 or the mask, nothing torn)."""
    h1 = hops[0]
    m = load(h1, s)
    if m == 0:
        m = np.int64(1) << sdom[s]
        for k in range(noff[s], noff[s + 1]):
            m |= np.int64(1) << sdom[nent[k] >> 5]
        store(h1, s, m)
    return m


@kernel(inline=True)
def hop2(hops, sdom, noff, nent, s):
    """The pool's two-hop domain mask of slot s: ``hop1`` over s and its
    step-start candidates, kept in ``hops[1]`` like ``hop1``."""
    h2 = hops[1]
    m = load(h2, s)
    if m == 0:
        m = hop1(hops, sdom, noff, nent, s)
        for k in range(noff[s], noff[s + 1]):
            m |= hop1(hops, sdom, noff, nent, nent[k] >> 5)
        store(h2, s, m)
    return m


@kernel(inline=True)
def regions_adjacent(locks, noff, nent, a, b):
    """Are the lock regions of slots a and b the same or adjacent?  With
    domain masks (the pool): may a and b become candidates without changing
    any mask?  Each one's domain is already one hop from the other, and each
    one's one-hop set is already within the other's two hops — so every
    event's wait set (two hops) still covers what it reads and writes."""
    lock_of, loff, ladj, hops = locks
    if hops.shape[1] > 0:
        h1a = hop1(hops, lock_of, noff, nent, a)
        h1b = hop1(hops, lock_of, noff, nent, b)
        return ((h1a >> lock_of[b]) & 1) != 0 and ((h1b >> lock_of[a]) & 1) != 0 and \
            (h1b & ~hop2(hops, lock_of, noff, nent, a)) == 0 and \
            (h1a & ~hop2(hops, lock_of, noff, nent, b)) == 0
    la = lock_of[a]
    lb = lock_of[b]
    if la == lb:
        return True
    for k in range(loff[la], loff[la + 1]):
        if ladj[k] == lb:
            return True
    return False


@kernel(inline=True)
def expose_pair(noff, nent, xhead, xent, xnext, hops, sdom, k, m):
    """The pool (``pool``): a pair (k, m) outside the masks.  k and m become
    *exposed* (``hops[3]``: written by events the masks do not order) and they
    and every particle that reads them, their candidates, *checked*
    (``hops[2]``: their events publish their times with a fence, check, and
    wait for the domains in this word besides their masks).  Both words are
    domain masks, ORed in: the one-hop masks of k and m (their domains
    included) and what k and m were already exposed to, so a checked event
    waits for the domains of the events that may now write or read what it
    reads or writes through the new pair (k's events read m, m's events and
    its partners' read k)."""
    x = hop1(hops, sdom, noff, nent, k) | hop1(hops, sdom, noff, nent, m) | \
        load(hops[3], k) | load(hops[3], m)
    fetch_or(hops[3], k, x)
    fetch_or(hops[3], m, x)
    marked = hops[2]
    for u in range(2):
        s = k if u == 0 else np.int64(m)
        fetch_or(marked, s, x)
        for q in range(noff[s], noff[s + 1]):
            fetch_or(marked, nent[q] >> 5, x)
        z = xhead[s]
        while z >= 0:
            fetch_or(marked, xent[z] >> 5, x)
            z = xnext[z]


# grow's test without square roots: a relative margin far above their rounding,
# used only where the room left inside the bound is not itself a rounding residue
GROW_MARGIN = 1.0 + 1e-9
GROW_ROOM = 1e-5


@kernel
def widen(k, new, parts, step, tree, nbrs, cfg, st, locks):
    """``grow``'s rare part: set k's search radius to ``new`` plus the step's
    skin, raise the tree's bounds and search the tree for the partners k could
    now meet.  Not inlined: it runs for one impact in 24 on the 50,000-grain
    bed (one in 4 on the ring, N = 2e5), and its tree search inlined into
    every event loop made their compile several times longer (README,
    Tests); measured in one process against the inlined one, the events
    ran as fast (bed 0.98-1.04x) or faster (ring 0.93-0.97x)."""
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    anc, reach, cis, work = step
    ntop, nbox, nreach, nreach_bits = tree
    noff, nent, xhead, xent, xnext, ctr = nbrs
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    # widen with the step's skin too: a particle that sped up once tends to again
    new += par[P_EXTRA]
    if new + par[P_RMAX] >= par[P_HALFPER]:
        ctr[CTR_BAD] = k
        return SIGMA_TOO_LARGE
    reach[k] = new
    if load(parb, P_RMAX) < float_bits(new):  # read first: every event reads par's lines
        fetch_max(parb, P_RMAX, float_bits(new))
    raise_reach(ntop, nreach_bits, k, new)
    st[S_GROW] += 1
    stack = work  # depth-first: never more entries than the tree's depth + 1
    for q in range(img_all.shape[0]):
        img = img_all[q]
        ox = img_pos[img, 0]
        oy = img_pos[img, 1]
        oz = img_pos[img, 2]
        qx = anc[k, 0] - ox
        qy = anc[k, 1] - oy
        qz = anc[k, 2] - oz
        stack[0] = 0
        sp = 1
        while sp > 0:
            sp -= 1
            nd = stack[sp]
            r = reach[k] + nreach[nd]
            if point_gap2(nbox, nd, qx, qy, qz) > r * r:
                continue
            left = ntop[nd, LEFT]
            if left >= 0:
                stack[sp] = ntop[nd, RIGHT]
                stack[sp + 1] = left
                sp += 2
                continue
            for m in range(ntop[nd, START], ntop[nd, END]):
                if m == k and img == SELF_IMAGE:
                    continue
                if pair_reach_ok(anc, reach, k, m, ox, oy, oz):
                    hops = locks[3]
                    if locks[0].shape[0] > 0 and not regions_adjacent(locks, noff, nent, k, m):
                        # beyond the lock design: regions thought independent now interact
                        st[S_REACHOUT] += 1
                        if hops.shape[1] > 0:
                            # the pool carries on: what the pair exposes is checked
                            # from now on (and its worker settles the other domains)
                            expose_pair(noff, nent, xhead, xent, xnext, hops, locks[0], k, m)
                        elif ipar[I_PAPER] == 0:
                            ctr[CTR_BAD] = k
                            return VIOLATION
                    elif hops.shape[1] > 0 and (hops[3, k] != 0 or hops[3, m] != 0):
                        # a new reader of an exposed particle: its events wait
                        # for what the exposed one's wait for
                        x = hops[3, k] | hops[3, m]
                        fetch_or(hops[2], k, x)
                        fetch_or(hops[2], m, x)
                    added = add_pair(noff, nent, xhead, xent, xnext, ctr, k, m, img)
                    if added < 0:
                        return POOL_OVERFLOW
                    st[S_ADDED] += added
    return OK


@kernel(inline=True)
def grow(k, t, parts, step, tree, nbrs, cfg, st, locks):
    """Widen k's search radius after its velocity changed at step time t.

    The new bound covers k's displacement so far plus its straight path to the
    step end; if it exceeds the old one the tree's bounds are raised and the
    tree is searched for partners k could now meet, which join both lists.
    """
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    anc, reach, cis, work = step
    ntop, nbox, nreach, nreach_bits = tree
    noff, nent, xhead, xent, xnext, ctr = nbrs
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    dt = par[P_DT]
    s = par[P_SHEAR]
    fr = par[P_FR]
    x = pos[k, 0] + vel[k, 0] * t
    dx = x - anc[k, 0]
    dy = ((pos[k, 1] + vel[k, 1] * t) + s * t * x) - anc[k, 1]  # sheared-frame coordinate
    dz = (pos[k, 2] + vel[k, 2] * t) - anc[k, 2]
    uy = vel[k, 1] + s * x  # velocity relative to the shear flow
    sp2 = vel[k, 0] * vel[k, 0] + uy * uy + vel[k, 2] * vel[k, 2]
    d2 = dx * dx + dy * dy + dz * dz
    lw = (dt - t) * (1.0 + s * dt)
    # most impacts stay well inside the bound: (|d| + lw |v|)^2 <= 2 (d^2 + lw^2 v^2)
    # shows it without the two square roots (the margins cover their rounding)
    room = reach[k] - fr * rad[k]
    if room > GROW_ROOM * reach[k] and 2.0 * (d2 + lw * lw * sp2) * GROW_MARGIN <= room * room:
        return OK
    # not lw * speed: the exact test keeps its rounding (and so its results) bit for bit
    sig = math.sqrt(d2) + (dt - t) * math.sqrt(sp2) * (1.0 + s * dt)
    new = sig + fr * rad[k]
    if new <= reach[k]:
        return OK
    return widen(k, new, parts, step, tree, nbrs, cfg, st, locks)


@kernel(inline=True)
def collide_pair(i, j, img, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks):
    """Resolve the collision of i with image img of j at step time t.  Returns
    (status, whether the velocities changed); their search radii and next
    events are then the caller's (``process_event``)."""
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    anc, reach, cis, work = step
    noff, nent, xhead, xent, xnext, ctr = nbrs
    evt, evp, evc, tour_t, tour_s, hidden = evq
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    journal(i, vel, tlast, cis, jour, ctr, st)
    journal(j, vel, tlast, cis, jour, ctr, st)
    xi0, xi1, xi2 = position_at(pos, vel, i, t)
    xj0, xj1, xj2 = position_at(pos, vel, j, t)
    dx = xi0 - xj0 - (img_pos[img, 0] + img_vel[img, 0] * t)
    dy = xi1 - xj1 - (img_pos[img, 1] + img_vel[img, 1] * t)
    dz = xi2 - xj2 - (img_pos[img, 2] + img_vel[img, 2] * t)
    dist = math.sqrt(dx * dx + dy * dy + dz * dz)
    nx = dx / dist
    ny = dy / dist
    nz = dz / dist
    vn = ((vel[i, 0] - vel[j, 0] - img_vel[img, 0]) * nx
          + (vel[i, 1] - vel[j, 1] - img_vel[img, 1]) * ny
          + (vel[i, 2] - vel[j, 2] - img_vel[img, 2]) * nz)
    if vn >= 0.0:
        # grazing: the predicted contact vanished in rounding; nothing happens
        st[S_GRAZE] += 1
    else:
        now = par[P_T0] + t
        tc = par[P_TC]
        vsleep = par[P_VSLEEP]
        fixed_i = False  # an asleep body hit slower than v_sleep: immovable
        fixed_j = False
        if vsleep > 0.0:
            # hit slowly a sleeper stays put, hit fast it wakes.  An asleep
            # grain rises and comes back by up to g dt^2 / 8 in a step (its
            # straight path in the free-falling frame), so a grain on the floor
            # under it would be squeezed by an immovable body without end: a
            # sleeper hit from below by a grain that close to the floor wakes
            if -vn < vsleep:
                near = 0.25 * par[P_G] * par[P_DT] * par[P_DT]
                # (n points from j to i)
                fixed_i = tlast[i] == ASLEEP and not (
                    nz > 0.0 and xj2 - 0.5 * par[P_G] * t * t - rad[j] < near)
                fixed_j = tlast[j] == ASLEEP and not (
                    nz < 0.0 and xi2 - 0.5 * par[P_G] * t * t - rad[i] < near)
            st[S_WOKEN] += ((tlast[i] == ASLEEP and not fixed_i)
                            + (tlast[j] == ASLEEP and not fixed_j))
        if (tc > 0.0 and (now - tlast[i] < tc or now - tlast[j] < tc)) or -vn < par[P_VMIN]:
            e = slow_impact(ipar, par, -vn)
            st[S_GUARDED] += 1  # made (more) elastic by the collapse guard
        else:
            e = coefficient(ipar[I_LAW], par[P_E], par[P_VC], par[P_EXP], -vn)
        mi = mass[i]
        mj = mass[j]
        if fixed_j:
            imp = -(1.0 + e) * vn * mi
            ai = imp / mi
            aj = 0.0
        elif fixed_i:
            imp = -(1.0 + e) * vn * mj
            ai = 0.0
            aj = imp / mj
        else:
            imp = -(1.0 + e) * vn * (mi * mj / (mi + mj))
            ai = imp / mi
            aj = imp / mj
        vel[i, 0] += ai * nx
        vel[i, 1] += ai * ny
        vel[i, 2] += ai * nz
        vel[j, 0] -= aj * nx
        vel[j, 1] -= aj * ny
        vel[j, 2] -= aj * nz
        # new false positions: through the contact point along the new velocities
        # (an immovable sleeper keeps its path to the bit)
        if not fixed_i:
            pos[i, 0] = xi0 - vel[i, 0] * t
            pos[i, 1] = xi1 - vel[i, 1] * t
            pos[i, 2] = xi2 - vel[i, 2] * t
            tl[i] = t
        if not fixed_j:
            pos[j, 0] = xj0 - vel[j, 0] * t
            pos[j, 1] = xj1 - vel[j, 1] * t
            pos[j, 2] = xj2 - vel[j, 2] * t
            tl[j] = t
        ncoll[i] += 1
        ncoll[j] += 1
        cis[i] += 1
        cis[j] += 1
        if tc > 0.0:
            tlast[i] = now
            tlast[j] = now
        elif vsleep > 0.0:
            # after a slow impact on a sleeper the mover is drowsy if its speed
            # relative to it stays below v_sleep; any other impact wakes both
            # (or keeps them awake), unless sleeping waits (below)
            if fixed_j:
                tlast[i] = drowsy(tlast[i], now, rel_speed2(vel, i, j) < vsleep * vsleep)
            elif fixed_i:
                tlast[j] = drowsy(tlast[j], now, rel_speed2(vel, j, i) < vsleep * vsleep)
            elif par[P_TSLEEP] > 0.0:
                # with a delay any slow impact keeps both drowsy: the delay and
                # the speed check at the step end stand in for the support
                slow = rel_speed2(vel, i, j) < vsleep * vsleep
                tlast[i] = drowsy(tlast[i], now, slow)
                tlast[j] = drowsy(tlast[j], now, slow)
            else:
                tlast[i] = AWAKE
                tlast[j] = AWAKE
        st[S_PAIR] += 1
        st[S_VIRIAL] += imp * dist
        # y-momentum carried across x by the impulse (collisional stress P_xy)
        st[S_XFLUX] += imp * ny * dx
        log_event(jour, ctr, t, ids[i], ids[j], img)
        contact = rad[i] + rad[j]
        ov = (contact - dist) / contact
        if ov > st[S_MAXOV]:
            st[S_MAXOV] = ov
        c = max(cis[i], cis[j])
        if c > st[S_MAXCIS]:
            st[S_MAXCIS] = c
        if c > ipar[I_CAP]:
            ctr[CTR_BAD] = i if cis[i] >= cis[j] else j
            return COLLAPSE, False
        return OK, True
    return OK, False


@kernel(inline=True)
def collide_wall(i, wall, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks):
    """Resolve particle i hitting the floor or the cylinder at step time t.
    Returns (status, whether the velocity changed), as ``collide_pair``."""
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    anc, reach, cis, work = step
    noff, nent, xhead, xent, xnext, ctr = nbrs
    evt, evp, evc, tour_t, tour_s, hidden = evq
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    journal(i, vel, tlast, cis, jour, ctr, st)
    x0, x1, x2 = position_at(pos, vel, i, t)
    # Walls neither follow nor reset the collapse guard's clock: a grain resting
    # on the floor touches it every few tc, and if those touches made its next
    # impacts elastic a bed would never lose its horizontal motion.  A wall ends
    # its own Zeno sequence instead: the floor returns at least P_WMIN.
    hit = False
    if wall == FLOOR:
        g0 = par[P_G]
        w = vel[i, 2] - g0 * t  # real vertical velocity
        if w <= 0.0:
            e = slow_impact(ipar, par, -w) if -w < par[P_VMIN] else \
                coefficient(ipar[I_LAW], par[P_E], par[P_VC], par[P_EXP], -w)
            w2 = -e * w
            if w2 < par[P_WMIN]:
                w2 = par[P_WMIN]
            vel[i, 2] = w2 + g0 * t
            st[S_FLOORIMP] += mass[i] * (w2 - w)
            hit = True
            vsleep = par[P_VSLEEP]
            if vsleep > 0.0:  # the floor is a support: asleep from the step end on if slow
                u2 = vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + w2 * w2
                tlast[i] = drowsy(tlast[i], par[P_T0] + t, u2 < vsleep * vsleep)
    else:
        rho = math.sqrt(x0 * x0 + x1 * x1)
        nx = x0 / rho
        ny = x1 / rho
        vn = vel[i, 0] * nx + vel[i, 1] * ny
        if vn > 0.0:
            e = slow_impact(ipar, par, vn) if vn < par[P_VMIN] else \
                coefficient(ipar[I_LAW], par[P_E], par[P_VC], par[P_EXP], vn)
            vel[i, 0] -= (1.0 + e) * vn * nx
            vel[i, 1] -= (1.0 + e) * vn * ny
            st[S_CYLIMP] += mass[i] * (1.0 + e) * vn
            hit = True
    if hit:
        pos[i, 0] = x0 - vel[i, 0] * t
        pos[i, 1] = x1 - vel[i, 1] * t
        pos[i, 2] = x2 - vel[i, 2] * t
        tl[i] = t
        ncoll[i] += 1
        cis[i] += 1
        st[S_WALL] += 1
        log_event(jour, ctr, t, ids[i], wall, SELF_IMAGE)
        if cis[i] > st[S_MAXCIS]:
            st[S_MAXCIS] = cis[i]
        if cis[i] > ipar[I_CAP]:
            ctr[CTR_BAD] = i
            return COLLAPSE, False
        return OK, True
    st[S_GRAZE] += 1
    return OK, False


@kernel(inline=True)
def _offer(i, t, e, key_e, evt, evp, evc, ids, ncoll):
    """Make (t, partner e) i's pending event if it comes first by (time, partner id, image)."""
    cur = evt[i]
    if t > cur:
        return
    if t == cur:
        p = evp[i]
        if p >= 0 and ids[p >> 5] * 32 + (p & 31) <= key_e:
            return
    evt[i] = t
    evp[i] = e
    evc[i] = np.int32(ncoll[e >> 5])


@kernel
def init_range(parts, nbrs, evq, cfg, st, lo, hi, tour_t, tour_s):
    """``first_events`` for the slots lo..hi-1 of one domain, and that
    domain's queue (``tour_t``, ``tour_s``)."""
    evt, evp, evc, tour_t_, tour_s_, hidden = evq
    _first_events(parts, nbrs, evq, cfg, st, lo, hi)
    build_queue(tour_t, tour_s, evt, parts[7], hidden, lo, hi)


@kernel
def first_events(parts, nbrs, evq, cfg, st, lo, hi):
    """Predict the first event of the step of every slot lo..hi-1, and measure
    the largest relative overlap among their pairs (all particles are at the
    step start) into ``st[S_MAXOV]``; then the leaves of the one queue over
    all slots (``evq``'s tournament) for the buckets of lo..hi-1, which must
    begin on a bucket's first slot (lo a multiple of ``events.BUCKET``) and
    end on a bucket's last or at N, so that each bucket is read by the call
    that wrote it.  ``init_queue`` finishes the queue.

    Each candidate pair is predicted once and offered to both particles; the
    outcome equals ``predict`` run on every particle (same minimum by (time,
    partner id, image), walls after pairs).  A pair across the range's edge
    is predicted by each side, from its lower slot, so the bits do not depend
    on how the slots are shared out among threads.  The leaves are built here,
    by the threads, not after them: the ring's (N = 2e5) one-thread queue
    build took 1.2 ms of a 31 ms two-thread step."""
    _first_events(parts, nbrs, evq, cfg, st, lo, hi)
    evt, evp, evc, tour_t, tour_s, hidden = evq
    build_leaves(tour_t, tour_s, evt, parts[7], hidden, 0, parts[0].shape[0], lo >> BUCKET_BITS,
                 buckets_of(hi))


@kernel
def init_queue(parts, evq):
    """The queue over all slots once ``first_events`` has built the leaves of
    every slot's bucket: the empty leaves past them and the inner nodes."""
    evt, evp, evc, tour_t, tour_s, hidden = evq
    n = parts[0].shape[0]
    build_leaves(tour_t, tour_s, evt, parts[7], hidden, 0, n, buckets_of(n),
                 tour_t.shape[0] >> 1)
    build_inner(tour_t, tour_s, parts[7])


@kernel(inline=True)
def _first_events(parts, nbrs, evq, cfg, st, lo, hi):
    """The first events of slots lo..hi-1 (offers reach only slots in the range)
    and the largest overlap among their pairs with higher or equal slots."""
    pos, vel, rad, mass, tl, ncoll, tlast, ids = parts
    noff, nent, xhead, xent, xnext, ctr = nbrs
    evt, evp, evc, tour_t, tour_s, hidden = evq
    par, ipar, img_pos, img_vel, img_all, parb = cfg
    t_end = par[P_DT]
    # as slices, an array at a time (as ``pool.clear_words``, where one loop
    # writing six arrays took 3.4 times as long)
    evt[lo:hi] = INF
    evp[lo:hi] = NONE
    evc[lo:hi] = 0
    for i in range(lo, hi):
        ri = rad[i]
        for k in range(noff[i], noff[i + 1]):
            e = nent[k]
            j = e >> 5
            img = e & 31
            if j < i:
                if j >= lo:
                    continue  # the pair was offered from j's list
                # j is another range's: predicted from j, as a range holding both does
                t = pair_time(pos, vel, j, i, 26 - img, img_pos, img_vel, rad[j] + ri, 0.0,
                              t_end)
                if t < INF:
                    _offer(i, t, e, ids[j] * 32 + img, evt, evp, evc, ids, ncoll)
                continue
            contact = ri + rad[j]
            ov = overlap_now(pos, i, j, img, img_pos, contact)
            if ov > st[S_MAXOV]:
                st[S_MAXOV] = ov
            t = pair_time(pos, vel, i, j, img, img_pos, img_vel, contact, 0.0, t_end)
            if t < INF:
                _offer(i, t, e, ids[j] * 32 + img, evt, evp, evc, ids, ncoll)
                if j < hi:
                    _offer(j, t, (i << 5) | (26 - img), ids[i] * 32 + 26 - img, evt, evp, evc,
                           ids, ncoll)
    if ipar[I_DISH] != 0:
        sleeping = par[P_VSLEEP] > 0.0
        for i in range(lo, hi):
            if sleeping and tlast[i] == ASLEEP:
                continue  # no wall events (as ``predict``)
            t = floor_time(pos, vel, tl, i, rad[i], par[P_G], 0.0, t_end)
            if t < evt[i]:
                evt[i] = t
                evp[i] = FLOOR
            t = cylinder_time(pos, vel, tl, i, rad[i], par[P_RCYL], 0.0, t_end)
            if t < evt[i]:
                evt[i] = t
                evp[i] = CYLINDER


@kernel(inline=True)
def prefetch_event(i, j, parts, nbrs):
    """Start fetching the cache lines an event on i (partner j, or -1) is
    about to use: the two particles' positions and velocities, to be written,
    and their candidates' positions and velocities, which ``predict`` reads.
    The fetches then overlap instead of waiting one after another inside the
    event (README, Benchmarks: "Where the far cost is, and prefetching")."""
    pos, vel = parts[0], parts[1]
    noff, nent = nbrs[0], nbrs[1]
    for q in range(2):
        s = i if q == 0 else j
        if s < 0:
            break
        prefetch_write(vel, s)
        prefetch_write(pos, s)
        for k in range(noff[s], noff[s + 1]):
            c = nent[k] >> 5
            prefetch_read(pos, c)
            prefetch_read(vel, c)


@kernel(inline=True)
def process_event(i, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks):
    """Carry out slot i's pending event at step time t (the caller owns i and its
    partner).  A stale event (the partner collided since it was predicted) only
    predicts i again.  Every slot whose pending event changed must then be
    updated in the queue by the caller: i, and the partner if the status's
    second value is >= 0.  Returns (status, partner slot or -1)."""
    ncoll = parts[5]
    evt, evp, evc, tour_t, tour_s, hidden = evq
    p = evp[i]
    st[S_POPS] += 1
    prefetch_event(i, p >> 5 if p >= 0 else -1, parts, nbrs)
    j = -1
    moved = False
    if p >= 0:
        if np.int32(ncoll[p >> 5]) != evc[i]:
            st[S_STALE] += 1  # partner collided since: predict i again
        else:
            j = p >> 5
            status, moved = collide_pair(i, j, p & 31, t, parts, step, tree, nbrs, evq, jour,
                                         cfg, st, locks)
            if status != OK:
                return status, j
    else:
        status, moved = collide_wall(i, p, t, parts, step, tree, nbrs, evq, jour, cfg, st,
                                     locks)
        if status != OK:
            return status, -1
    # i's (and j's) search radius, then next event: each kernel at one call
    # site, so inlined once (with ``predict`` inlined at four sites and
    # ``grow``'s tree search at three, run_events alone took 205 s to
    # compile; 24-28 s now: README, Tests)
    if moved:
        for q in range(2 if j >= 0 else 1):
            status = grow(i if q == 0 else j, t, parts, step, tree, nbrs, cfg, st, locks)
            if status != OK:
                return status, j
    for q in range(2 if j >= 0 else 1):
        predict(i if q == 0 else j, t, parts, nbrs, evq, cfg)
    return OK, j


@kernel
def run_events(parts, step, tree, nbrs, evq, jour, cfg, st, locks, trace, max_events):
    """Process events in (time, id) order until the step end or a status.

    Returns OK when no event is left before the step end, CHUNK after
    ``max_events`` events, NEED_JOURNAL / NEED_LOG / NEED_TRACE (nothing
    changed; grow the buffer and call again) or an error status
    (POOL_OVERFLOW, COLLAPSE, SIGMA_TOO_LARGE: the step must be rolled back).

    ``trace = (trf, tri)`` (empty: off) records every event popped, for the
    scheduling replay: ``trf[k] = (t, cycles spent)``, ``tri[k] = (id of i,
    id of the partner or -1, kind)`` with kind T_PAIR, T_WALL or T_STALE.
    """
    ids = parts[7]
    ctr = nbrs[5]
    evt, evp, evc, tour_t, tour_s, hidden = evq
    jslot = jour[0]
    logt = jour[3]
    dt = cfg[0][P_DT]
    done = 0
    while done < max_events:
        i = tour_s[1]
        if i < 0:
            return OK
        t = evt[i]
        if not t < dt:
            return OK
        if logt.shape[0] > 0 and ctr[LCOUNT] >= logt.shape[0]:
            return NEED_LOG
        if not journal_room(st, ctr, jslot.shape[0], 1):
            return NEED_JOURNAL
        trf, tri = trace
        tracing = trf.shape[0] > 0
        if tracing:
            if ctr[TCOUNT] >= trf.shape[0]:
                return NEED_TRACE
            p = evp[i]
            c0 = cycles()
        status, j = process_event(i, t, parts, step, tree, nbrs, evq, jour, cfg, st, locks)
        if status != OK:
            return status
        if tracing:
            k = ctr[TCOUNT]
            trf[k, 0] = t
            trf[k, 1] = cycles() - c0
            tri[k, 0] = ids[i]
            tri[k, 1] = ids[p >> 5] if p >= 0 else -1
            tri[k, 2] = T_WALL if p < 0 else (T_PAIR if j >= 0 else T_STALE)
            ctr[TCOUNT] = k + 1
        if j >= 0:
            update_queue_pair(tour_t, tour_s, evt, ids, hidden, 0, evt.shape[0], i, j)
        else:
            update_queue(tour_t, tour_s, evt, ids, hidden, 0, evt.shape[0], i)
        done += 1
    return CHUNK


@kernel
def sample_speeds(pos, vel, par, out, omega, h):
    """Speeds relative to the shear flow of every (N // len(out))-th particle;
    with ``omega`` and h nonzero, of its velocity after Hill's kick for time
    h (``forces.hill_kicked``: the kick not yet applied, the same values)."""
    n = pos.shape[0]
    m = out.shape[0]
    stride = max(1, n // m)
    s = par[P_SHEAR]
    coef = hill_coefficients(omega, h)
    for q in range(m):
        i = min(q * stride, n - 1)
        vx, vy, vz = vel[i, 0], vel[i, 1], vel[i, 2]
        if omega != 0.0 and h != 0.0:
            vx, vy, vz = hill_kicked(pos, vel, i, coef)
        uy = vy + s * pos[i, 0]
        out[q] = math.sqrt(vx * vx + uy * uy + vz * vz)


@kernel
def compute_reach(pos, vel, rad, reach, par, extra, top):
    """Step-start reaches: search radius plus fr times the radius.

    The search radius is sig = |u| (1 + s dt) dt + extra, with u the velocity
    relative to the shear flow: the particle's own straight path plus a skin
    ``extra`` for later speed-ups (the engine uses skin * median speed * dt
    + g dt^2 / 2: a median, so a few fast particles do not widen everyone's
    search).  Correctness does not depend on the skin (a particle that outruns
    its reach widens it and searches again); it only trades candidate-list
    length against such searches.  ``top`` (2,), the two largest reaches
    so far (zeros to begin with), takes in these particles' (so a thread can
    pass it chunk after chunk).
    """
    n = pos.shape[0]
    dt = par[P_DT]
    s = par[P_SHEAR]
    fr = par[P_FR]
    for i in range(n):
        uy = vel[i, 1] + s * pos[i, 0]
        sp = math.sqrt(vel[i, 0] * vel[i, 0] + uy * uy + vel[i, 2] * vel[i, 2])
        r = (sp * (1.0 + s * dt) * dt + extra) + fr * rad[i]
        reach[i] = r
        if r > top[0]:
            top[1] = top[0]
            top[0] = r
        elif r > top[1]:
            top[1] = r


@kernel
def reset_step(tl, cis, xhead, ctr, hidden):
    """Clear the per-step arrays (callable on slices: ctr is reset by every call)."""
    tl[:] = 0.0
    cis[:] = 0
    hidden[:] = 0
    xhead[:] = -1
    ctr[XCOUNT] = 0
    ctr[JCOUNT] = 0


@kernel
def drift_all(pos, vel, tl, t):
    """Move every particle along its frame trajectory to step time t (pos becomes
    the real position there)."""
    for i in range(pos.shape[0]):
        pos[i, 0] += vel[i, 0] * t
        pos[i, 1] += vel[i, 1] * t
        pos[i, 2] += vel[i, 2] * t
        tl[i] = t


@kernel
def hold_sleepers(vel, slp, w):
    """At the step start: every asleep grain's velocity (0, 0, w); w = g dt / 2
    brings it back to its place at the step end under gravity (0 undoes it)."""
    for i in range(vel.shape[0]):
        if slp[i] == ASLEEP:
            vel[i, 0] = 0.0
            vel[i, 1] = 0.0
            vel[i, 2] = w


@kernel(inline=True)
def drowsy(word, now, slow):
    """A grain's sleep word after an impact on a support at time ``now``:
    drowsy (since its first slow impact in a row) if ``slow``, else awake."""
    if not slow:
        return AWAKE
    return word if AWAKE < word < ASLEEP else now


@kernel
def rest_sleepers(vel, slp, t_end, t_sleep, v_sleep):
    """At the step end (time ``t_end``), in real coordinates: grains drowsy for
    at least ``t_sleep`` fall asleep (with ``t_sleep`` > 0 a drowsy grain as
    fast as ``v_sleep`` wakes instead), and every asleep grain is at rest."""
    for i in range(vel.shape[0]):
        if AWAKE < slp[i] < ASLEEP:
            u2 = vel[i, 0] * vel[i, 0] + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2]
            if t_sleep > 0.0 and u2 >= v_sleep * v_sleep:
                slp[i] = AWAKE
            elif t_end - slp[i] >= t_sleep:
                slp[i] = ASLEEP
        if slp[i] == ASLEEP:
            vel[i, 0] = 0.0
            vel[i, 1] = 0.0
            vel[i, 2] = 0.0


@kernel
def leave_frame(pos, vel, tl, dt, g0):
    """At the step end: back from the free-falling frame to real coordinates."""
    if g0 != 0.0:
        dz = 0.5 * g0 * dt * dt
        dv = g0 * dt
        for i in range(pos.shape[0]):
            pos[i, 2] -= dz
            vel[i, 2] -= dv
    tl[:] = 0.0


@kernel
def max_overlap(pos, rad, noff, nent, xhead, xent, xnext, img_pos, img_vel, t):
    """Largest relative overlap (contact - distance)/contact over candidate pairs.

    All particles must be at the same step time t (as after ``drift_all``).
    """
    worst = 0.0
    n = pos.shape[0]
    for i in range(n):
        k = noff[i]
        x = xhead[i]
        while True:
            if k < noff[i + 1]:
                e = nent[k]
                k += 1
            elif x >= 0:
                e = xent[x]
                x = xnext[x]
            else:
                break
            j = e >> 5
            if j < i:
                continue
            img = e & 31
            dx = pos[i, 0] - pos[j, 0] - (img_pos[img, 0] + img_vel[img, 0] * t)
            dy = pos[i, 1] - pos[j, 1] - (img_pos[img, 1] + img_vel[img, 1] * t)
            dz = pos[i, 2] - pos[j, 2] - (img_pos[img, 2] + img_vel[img, 2] * t)
            contact = rad[i] + rad[j]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            ov = (contact - d) / contact
            if ov > worst:
                worst = ov
    return worst


@kernel
def overlap_report(pos, rad, noff, nent, img_pos, tol, out):
    """Largest relative overlap among candidate pairs at step time 0.

    ``out`` (3,) int64 receives (slot a, slot b, pairs overlapping by more
    than ``tol``); returns the largest overlap.
    """
    worst = 0.0
    count = 0
    out[0] = -1
    out[1] = -1
    for i in range(pos.shape[0]):
        for k in range(noff[i], noff[i + 1]):
            e = nent[k]
            j = e >> 5
            if j < i:
                continue
            ov = overlap_now(pos, i, j, e & 31, img_pos, rad[i] + rad[j])
            if ov > tol:
                count += 1
            if ov > worst:
                worst = ov
                out[0] = i
                out[1] = j
    out[2] = count
    return worst


@kernel
def rollback(pos, vel, tl, ncoll, tlast, anc, cis, jslot, jvel, jtlast, jcount):
    """Undo the drift phase: positions from the anchors, velocities from the journal
    (entries with slot -1: claimed, unused)."""
    for k in range(jcount):
        s = jslot[k]
        if s < 0:
            continue
        vel[s, 0] = jvel[k, 0]
        vel[s, 1] = jvel[k, 1]
        vel[s, 2] = jvel[k, 2]
        if tlast.shape[0] > 0:
            tlast[s] = jtlast[k]
    for i in range(pos.shape[0]):
        pos[i, 0] = anc[i, 0]
        pos[i, 1] = anc[i, 1]
        pos[i, 2] = anc[i, 2]
        tl[i] = 0.0
        ncoll[i] -= cis[i]
        cis[i] = 0
