"""Simulation domains: boundaries and periodic images.

* ``ShearingSheet(lx, ly, omega)``: sliding-brick boundaries.  x (radial) is
  periodic with a shear offset, y (azimuthal) is periodic, z is open.  The
  background flow is v_y = -1.5 omega x; the image across +x of a particle at
  (x, y) sits at (x + lx, y + delta(T)) and moves 1.5 omega lx slower in y, with
  delta(T) = -1.5 omega lx T wrapped into [-ly/2, ly/2).  Box: |x| < lx/2, |y| < ly/2.
* ``Dish(radius)``: a static vertical cylinder wall of that radius around the z
  axis and a flat floor at z = 0; open above.
* ``PeriodicCube(length)``: periodic in x, y and z, |x|, |y|, |z| < length/2.

Periodic images are numbered ``(kx+1)*9 + (ky+1)*3 + (kz+1)``, so 13 is the box
itself and 26 - k is the opposite of k.  At step time t image k is displaced by
``img_pos[k] + img_vel[k] * t``.
"""
import math
from dataclasses import dataclass

import numpy as np
from ._jit import kernel

from .errors import InputError

DOMAIN_SHEET = 1
DOMAIN_DISH = 2
DOMAIN_CUBE = 3


def _length(field, value):
    value = float(value)
    if not (value > 0 and math.isfinite(value)):
        raise InputError(field, f"must be a finite length > 0 (got {value!r})")
    return value


def _image_index(kx, ky, kz):
    return (kx + 1) * 9 + (ky + 1) * 3 + (kz + 1)


def _image_tables(shifts):
    """img_pos/img_vel (27,3) from {(kx,ky,kz): (offset, velocity)}; exact negation."""
    img_pos = np.zeros((27, 3))
    img_vel = np.zeros((27, 3))
    for (kx, ky, kz), (off, vel) in shifts.items():
        k = _image_index(kx, ky, kz)
        img_pos[k] = off
        img_vel[k] = vel
    return img_pos, img_vel


def _split_images(keys):
    idx = sorted(_image_index(*k) for k in keys)
    half = [k for k in idx if k >= 13]  # 13 itself, and one of each opposite pair
    return np.array(half, np.int64), np.array(idx, np.int64)


@dataclass(frozen=True)
class ShearingSheet:
    """Shearing-sheet box of lx (radial) by ly (azimuthal) metres at orbital rate omega."""
    lx: float
    ly: float
    omega: float

    code = DOMAIN_SHEET
    periodic = (True, True, False)

    def __post_init__(self):
        object.__setattr__(self, "lx", _length("domain.lx", self.lx))
        object.__setattr__(self, "ly", _length("domain.ly", self.ly))
        object.__setattr__(self, "omega", _length("domain.omega", self.omega))

    @property
    def shear(self):
        """Shear rate 1.5 omega (1/s): v_y(x) = -shear * x."""
        return 1.5 * self.omega

    def offset(self, time):
        """delta(T): y shift of the image across +x at absolute time T (s)."""
        d = math.fmod(-self.shear * self.lx * time, self.ly)
        if d >= 0.5 * self.ly:
            d -= self.ly
        elif d < -0.5 * self.ly:
            d += self.ly
        return d

    def images(self, time):
        delta = self.offset(time)
        shifts = {}
        for kx in (-1, 0, 1):
            for ky in (-1, 0, 1):
                off = (kx * self.lx, kx * delta + ky * self.ly, 0.0)
                vel = (0.0, -kx * self.shear * self.lx, 0.0)
                shifts[(kx, ky, 0)] = (off, vel)
        img_pos, img_vel = _image_tables(shifts)
        half, full = _split_images(shifts)
        return img_pos, img_vel, half, full

    def min_period(self):
        return min(self.lx, self.ly)

    def wrap_params(self, time):
        return np.array([self.lx, self.ly, 0.0, self.shear, self.offset(time)])

    def check_inside(self, pos, radius):
        hx, hy = 0.5 * self.lx, 0.5 * self.ly
        bad = np.flatnonzero((pos[:, 0] < -hx) | (pos[:, 0] >= hx))
        if bad.size:
            i = int(bad[0])
            raise InputError("state.pos", f"particle {i} has x = {pos[i, 0]!r} outside the "
                             f"shearing-sheet box [-{hx}, {hx}) ({bad.size} particles outside)")
        bad = np.flatnonzero((pos[:, 1] < -hy) | (pos[:, 1] >= hy))
        if bad.size:
            i = int(bad[0])
            raise InputError("state.pos", f"particle {i} has y = {pos[i, 1]!r} outside the "
                             f"shearing-sheet box [-{hy}, {hy}) ({bad.size} particles outside)")

    def cell(self):
        return np.diag([self.lx, self.ly, 0.0]), [True, True, False]

    def describe(self):
        return {"type": "shearing_sheet", "lx": self.lx, "ly": self.ly, "omega": self.omega}


@dataclass(frozen=True)
class Dish:
    """Vertical cylinder of the given radius (m) around the z axis, floor at z = 0."""
    radius: float

    code = DOMAIN_DISH
    periodic = (False, False, False)

    def __post_init__(self):
        object.__setattr__(self, "radius", _length("domain.radius", self.radius))

    def images(self, time):
        img_pos, img_vel = _image_tables({(0, 0, 0): ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))})
        half = np.array([13], np.int64)
        return img_pos, img_vel, half, half.copy()

    def min_period(self):
        return math.inf

    def wrap_params(self, time):
        return np.zeros(5)

    def check_inside(self, pos, radius):
        rho = np.hypot(pos[:, 0], pos[:, 1])
        # relative tolerance: a grain resting on a wall may sit one rounding inside it
        tol = 1e-9 * radius
        bad = np.flatnonzero(rho + radius > self.radius + tol)
        if bad.size:
            i = int(bad[0])
            raise InputError("state.pos", f"particle {i} (radius {radius[i]!r}) at distance "
                             f"{rho[i]!r} from the axis crosses the dish wall of radius "
                             f"{self.radius} ({bad.size} particles outside)")
        bad = np.flatnonzero(pos[:, 2] - radius < -tol)
        if bad.size:
            i = int(bad[0])
            raise InputError("state.pos", f"particle {i} (radius {radius[i]!r}) at z = "
                             f"{pos[i, 2]!r} is below the dish floor z = 0 "
                             f"({bad.size} particles outside)")

    def cell(self):
        d = 2 * self.radius
        return np.diag([d, d, 0.0]), [False, False, False]

    def describe(self):
        return {"type": "dish", "radius": self.radius}


@dataclass(frozen=True)
class PeriodicCube:
    """Cube of the given edge length (m), periodic in x, y and z."""
    length: float

    code = DOMAIN_CUBE
    periodic = (True, True, True)

    def __post_init__(self):
        object.__setattr__(self, "length", _length("domain.length", self.length))

    def images(self, time):
        L = self.length
        shifts = {}
        for kx in (-1, 0, 1):
            for ky in (-1, 0, 1):
                for kz in (-1, 0, 1):
                    shifts[(kx, ky, kz)] = ((kx * L, ky * L, kz * L), (0.0, 0.0, 0.0))
        img_pos, img_vel = _image_tables(shifts)
        half, full = _split_images(shifts)
        return img_pos, img_vel, half, full

    def min_period(self):
        return self.length

    def wrap_params(self, time):
        return np.array([self.length, self.length, self.length, 0.0, 0.0])

    def check_inside(self, pos, radius):
        h = 0.5 * self.length
        bad = np.flatnonzero(np.any((pos < -h) | (pos >= h), axis=1))
        if bad.size:
            i = int(bad[0])
            raise InputError("state.pos", f"particle {i} at {pos[i].tolist()} is outside the "
                             f"periodic cube [-{h}, {h})^3 ({bad.size} particles outside)")

    def cell(self):
        return np.eye(3) * self.length, [True, True, True]

    def describe(self):
        return {"type": "periodic_cube", "length": self.length}


@kernel
def wrap(pos, vel, code, wp):
    """Map positions back into the periodic box (shear: shift y and v_y too).

    ``wp = (lx, ly, lz, shear, delta)`` with delta the shear offset at the time
    of the positions.
    """
    if code == DOMAIN_SHEET:
        lx = wp[0]
        ly = wp[1]
        shear = wp[3]
        delta = wp[4]
        hx = 0.5 * lx
        for i in range(pos.shape[0]):
            if pos[i, 0] >= hx:
                pos[i, 0] -= lx
                pos[i, 1] -= delta
                vel[i, 1] += shear * lx
            elif pos[i, 0] < -hx:
                pos[i, 0] += lx
                pos[i, 1] += delta
                vel[i, 1] -= shear * lx
                if pos[i, 0] >= hx:  # x + lx rounded up onto the far edge
                    pos[i, 0] = hx * (1.0 - 2.2e-16)
            pos[i, 1] = _wrap1(pos[i, 1], ly)
    elif code == DOMAIN_CUBE:
        L = wp[0]
        for i in range(pos.shape[0]):
            for a in range(3):
                pos[i, a] = _wrap1(pos[i, a], L)


@kernel
def _wrap1(x, L):
    """x mapped into [-L/2, L/2)."""
    h = 0.5 * L
    if x >= h or x < -h:
        x -= L * math.floor(x / L + 0.5)
        if x >= h:
            x -= L
        if x < -h:  # only by rounding
            x = -h
    return x
