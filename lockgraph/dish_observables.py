"""Granular observables of a dish state, the same functions for every code.

Inputs are plain arrays: pos (n, 3) m, radius (n,) m of the *grains* (a
marble is passed separately or left out), the cylinder radius (m).  Packing
fractions use the volume of each sphere inside the sampled region — exact in
z, by quadrature across a cylindrical boundary — never a count of centres:
a wall orders the grains in shells, and counting centres would make the
result jump as a shell crosses the sampling radius.
"""
import math

import numpy as np

UNITS = {
    "bed_height": "m",
    "packing_fraction": "",
    "floor_coverage": "",
    "wall_coverage": "",
    "floor_load": "",
    "settle_time": "s",
}

# How far from the floor, the surface and the wall the bulk sample stays, in
# grain diameters.  The layering a flat wall imposes has decayed to a few per
# cent by 2 d (the floor profile of a settled bed: peaks 0.74, 0.66, 0.63 at
# 0.5, 1.4, 2.3 d); measured on settled beds, margins of 2 and 3 d give the
# same bulk fraction within 0.007.
BULK_MARGIN = 2.0
# A grain is in the floor (wall) layer when its centre is within 10 % of a
# radius of touching it: closer than a second layer can get.
LAYER_SLACK = 0.1


_FIND = object()  # "find the bulk region": a region argument not given


def _region(pos, radius, cylinder_radius, region):
    return bulk_region(pos, radius, cylinder_radius) if region is _FIND else region


# Gauss-Legendre nodes for the integral over height of a sphere's horizontal
# cross-section inside a circle: 24 nodes put the volume within ~1e-4 of exact
# (the integrand has a kink where the cross-section touches the circle).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(24)


def _lens(a, rho, big):
    """Area of a disk of radius a centred rho from the axis inside the circle of
    radius big (arrays broadcast)."""
    a = np.maximum(a, 0.0)
    inside = rho + a <= big
    outside = rho >= a + big
    cover = rho + big <= a
    rr = np.maximum(rho, 1e-300)
    aa = np.maximum(a, 1e-300)
    c1 = np.clip((rr * rr + aa * aa - big * big) / (2 * rr * aa), -1.0, 1.0)
    c2 = np.clip((rr * rr + big * big - aa * aa) / (2 * rr * big), -1.0, 1.0)
    k = (-rr + aa + big) * (rr + aa - big) * (rr - aa + big) * (rr + aa + big)
    lens = aa * aa * np.arccos(c1) + big * big * np.arccos(c2) - 0.5 * np.sqrt(np.maximum(k, 0))
    return np.where(inside, np.pi * a * a,
                    np.where(outside, 0.0, np.where(cover, np.pi * big * big, lens)))


def cylinder_volume(pos, radius, big, lo, hi):
    """Volume (m^3) of each sphere inside the cylinder of radius ``big`` around
    the axis, between heights lo and hi."""
    z = pos[:, 2]
    rho = np.hypot(pos[:, 0], pos[:, 1])
    a0 = np.clip(lo - z, -radius, radius)
    b0 = np.clip(hi - z, -radius, radius)
    mid = 0.5 * (a0 + b0)
    half = 0.5 * (b0 - a0)
    u = mid[:, None] + half[:, None] * _GL_X[None, :]
    sec = np.sqrt(np.maximum(radius[:, None] ** 2 - u * u, 0.0))
    area = _lens(sec, rho[:, None], big)
    return half * (area * _GL_W[None, :]).sum(axis=1)


def profile_z(pos, radius, area, z):
    """Packing fraction on the heights ``z`` (m): grain cross-section per ``area``."""
    u = z[:, None] - pos[None, :, 2]
    sec = np.clip(radius[None, :] ** 2 - u * u, 0.0, None)
    return np.pi * sec.sum(axis=1) / area


def bed_height(pos, radius, cylinder_radius):
    """Height (m) where the cross-section packing fraction, coming down from the
    top, first reaches half the bulk value."""
    d = 2.0 * float(np.median(radius))
    top = float(np.max(pos[:, 2] + radius))
    z = np.linspace(0.0, top, max(64, int(top / d * 50)))
    phi = profile_z(pos, radius, math.pi * cylinder_radius ** 2, z)
    inner = (z > BULK_MARGIN * d) & (z < top - BULK_MARGIN * d)
    ref = float(np.median(phi[inner])) if inner.any() else float(phi.max())
    above = np.flatnonzero(phi >= 0.5 * ref)
    k = int(above[-1])
    if k + 1 >= len(z):
        return float(z[-1])
    # linear interpolation of the half-crossing between grid points k and k+1
    f0, f1 = phi[k] - 0.5 * ref, phi[k + 1] - 0.5 * ref
    return float(z[k] + (z[k + 1] - z[k]) * f0 / (f0 - f1))


def bulk_region(pos, radius, cylinder_radius, height=None):
    """(sampling radius, z low, z high) of the bulk sample, or None when the bed
    is too shallow or narrow to have one; ``height``: the bed height if known."""
    d = 2.0 * float(np.median(radius))
    h = bed_height(pos, radius, cylinder_radius) if height is None else height
    rs = cylinder_radius - BULK_MARGIN * d
    lo, hi = BULK_MARGIN * d, h - BULK_MARGIN * d
    if rs <= d or hi - lo <= d:
        return None
    return rs, lo, hi


def packing_fraction(pos, radius, cylinder_radius, region=_FIND):
    """Bulk packing fraction: grain volume inside the sampled cylinder (the
    margins away from floor, surface and wall) per its volume; NaN without a
    bulk.  ``region``: the ``bulk_region`` if already found."""
    reg = _region(pos, radius, cylinder_radius, region)
    if reg is None:
        return math.nan
    rs, lo, hi = reg
    vol = cylinder_volume(pos, radius, rs, lo, hi).sum()
    return float(vol / (math.pi * rs * rs * (hi - lo)))


def floor_coverage(pos, radius, cylinder_radius):
    """Fraction of the floor area under the cross-sections of grains touching it."""
    touch = pos[:, 2] < radius * (1.0 + LAYER_SLACK)
    return float(np.sum(np.pi * radius[touch] ** 2) / (math.pi * cylinder_radius ** 2))


def wall_coverage(pos, radius, cylinder_radius, region=_FIND):
    """Fraction of the cylinder wall, over the bulk's height range, covered by
    the cross-sections of grains touching it; NaN without a bulk.  ``region``:
    the ``bulk_region`` if already found."""
    reg = _region(pos, radius, cylinder_radius, region)
    if reg is None:
        return math.nan
    _, lo, hi = reg
    rho = np.hypot(pos[:, 0], pos[:, 1])
    touch = (rho + radius > cylinder_radius - LAYER_SLACK * radius) & \
            (pos[:, 2] > lo) & (pos[:, 2] < hi)
    return float(np.sum(np.pi * radius[touch] ** 2) / (2 * math.pi * cylinder_radius * (hi - lo)))


def layering(pos, radius, cylinder_radius, depth=4.0, bins=80, region=_FIND):
    """Packing-fraction profiles near the floor and the wall.

    Returns dict: ``z`` (bins,) m and ``phi_z`` over the whole cross-section
    for 0 < z < depth grain diameters; ``rho`` (bins,) m and ``phi_rho`` in
    annuli within ``depth`` diameters of the wall, over the bulk's heights
    (``region``: the ``bulk_region`` if already found).
    """
    d = 2.0 * float(np.median(radius))
    z = np.linspace(0.0, depth * d, bins)
    phi_z = profile_z(pos, radius, math.pi * cylinder_radius ** 2, z)
    out = {"z": z, "phi_z": phi_z}
    reg = _region(pos, radius, cylinder_radius, region)
    edges = np.linspace(cylinder_radius - depth * d, cylinder_radius, bins + 1)
    rho = np.hypot(pos[:, 0], pos[:, 1])
    if reg is None:
        out.update(rho=0.5 * (edges[1:] + edges[:-1]), phi_rho=np.full(bins, np.nan))
        return out
    _, lo, hi = reg
    near = rho + radius > edges[0]
    inner = np.array([cylinder_volume(pos[near], radius[near], e, lo, hi).sum()
                      for e in edges])
    shell = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2) * (hi - lo)
    out.update(rho=0.5 * (edges[1:] + edges[:-1]), phi_rho=np.diff(inner) / shell)
    return out


def snapshot(pos, radius, cylinder_radius):
    """The static observables of one settled state (dict)."""
    h = bed_height(pos, radius, cylinder_radius)
    reg = bulk_region(pos, radius, cylinder_radius, h)
    return {
        "bed_height": h,
        "packing_fraction": packing_fraction(pos, radius, cylinder_radius, reg),
        "floor_coverage": floor_coverage(pos, radius, cylinder_radius),
        "wall_coverage": wall_coverage(pos, radius, cylinder_radius, reg),
    }


# rms grain speed (m/s) below which a bed counts as settled.  Above the rest
# noise of both kinds of code: a resting hard-sphere bed keeps ~0.6 mm/s rms
# (the collapse guard's elastic contacts), a DEM bed at E = 1e7 Pa ~1–2 mm/s
# (contact vibrations); a falling or sliding bed is far above it.
SETTLE_RMS = 3e-3


def settle_time(times, vel, speed=SETTLE_RMS):
    """First sample time (s) from which the rms grain speed stays below
    ``speed`` (m/s); NaN if the run never settles."""
    rms = np.sqrt(np.nanmean(np.sum(vel ** 2, axis=2), axis=1))
    fast = np.flatnonzero(~(rms < speed))
    if fast.size == 0:
        return float(times[0])
    k = int(fast[-1]) + 1
    return float(times[k]) if k < len(times) else math.nan


def floor_load_from_momentum(t0, t1, pz0, pz1, weight):
    """Floor force over weight from the momentum balance of a frictionless bed
    (smooth walls carry no vertical load): F = W + dP_z/dt."""
    return float(1.0 + (pz1 - pz0) / ((t1 - t0) * weight))
