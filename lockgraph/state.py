"""The particle state: a structure of arrays, validated once on entry.

All arrays are ordered by particle id (row k is particle k).
"""
import hashlib
import os
import tempfile
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

MAX_PARTICLES = (1 << 26) - 1  # candidate entries pack the partner index into 26 bits


def state_sha256(pos, vel):
    """sha256 of the pos then vel float64 bytes (C order): the fingerprint by which
    a threaded run is checked to reproduce the sequential one bit for bit."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(pos, np.float64).tobytes())
    h.update(np.ascontiguousarray(vel, np.float64).tobytes())
    return h.hexdigest()


@dataclass
class State:
    """Particles of a hard-sphere system.

    Attributes
    ----------
    pos : (N, 3) float64, m — positions.
    vel : (N, 3) float64, m/s — velocities.
    radius : (N,) float64, m — sphere radii, > 0.
    mass : (N,) float64, kg — masses, > 0.
    t_local : (N,) float64, s — time since the current step start at which
        ``pos`` is valid; zero between steps.
    ncoll : (N,) int64 — collisions each particle has had (pairs and walls).
    t_last : (N,) float64, s — absolute time of each particle's last collision
        (``-inf`` if none); used by the collapse guard.  With sleeping grains
        that wait (``VelocityGuard``'s ``t_sleep`` > 0) instead: the time from
        which each drowsy grain has had only slow impacts (``-inf``: awake or
        asleep).
    time : float, s — absolute simulation time.
    asleep : (N,) bool — grains asleep (at rest on their support, see
        ``restitution.VelocityGuard``'s ``v_sleep``); all False unless the
        physics lets grains sleep.  An asleep grain's velocity is zero.
    """
    pos: np.ndarray
    vel: np.ndarray
    radius: np.ndarray
    mass: np.ndarray
    t_local: np.ndarray = None
    ncoll: np.ndarray = None
    t_last: np.ndarray = None
    time: float = 0.0
    meta: dict = field(default_factory=dict)
    asleep: np.ndarray = None

    def __post_init__(self):
        self.pos = _float_array("state.pos", self.pos, (None, 3))
        n = self.pos.shape[0]
        if n > MAX_PARTICLES:
            raise InputError("state.pos", f"{n} particles; at most {MAX_PARTICLES} are supported")
        self.vel = _float_array("state.vel", self.vel, (n, 3))
        self.radius = _float_array("state.radius", self.radius, (n,))
        self.mass = _float_array("state.mass", self.mass, (n,))
        self.t_local = (np.zeros(n) if self.t_local is None
                        else _float_array("state.t_local", self.t_local, (n,)))
        if self.ncoll is None:
            self.ncoll = np.zeros(n, np.int64)
        else:
            self.ncoll = np.ascontiguousarray(self.ncoll, dtype=np.int64)
            if self.ncoll.shape != (n,):
                raise InputError("state.ncoll", f"must have shape ({n},), got {self.ncoll.shape}")
        if self.t_last is None:
            self.t_last = np.full(n, -np.inf)
        else:
            self.t_last = np.ascontiguousarray(self.t_last, dtype=np.float64)
            if self.t_last.shape != (n,) or np.isnan(self.t_last).any():
                raise InputError("state.t_last", f"must be ({n},) float without NaN")
        if self.asleep is None:
            self.asleep = np.zeros(n, bool)
        else:
            self.asleep = np.ascontiguousarray(self.asleep, dtype=bool)
            if self.asleep.shape != (n,):
                raise InputError("state.asleep", f"must have shape ({n},), got "
                                 f"{self.asleep.shape}")
            moving = np.flatnonzero(self.asleep & np.any(self.vel != 0.0, axis=1))
            if moving.size:
                raise InputError("state.asleep", f"particle {int(moving[0])} is asleep but "
                                 f"moving (velocity {self.vel[moving[0]].tolist()}); an "
                                 f"asleep grain is at rest ({moving.size} such)")
        self.time = float(self.time)
        if not np.isfinite(self.time):
            raise InputError("state.time", f"must be finite (got {self.time!r})")
        bad = np.flatnonzero(~(self.radius > 0))
        if bad.size:
            raise InputError("state.radius", f"particle {int(bad[0])} has radius "
                             f"{self.radius[bad[0]]!r}; radii must be > 0 ({bad.size} bad)")
        bad = np.flatnonzero(~(self.mass > 0))
        if bad.size:
            raise InputError("state.mass", f"particle {int(bad[0])} has mass "
                             f"{self.mass[bad[0]]!r}; masses must be > 0 ({bad.size} bad)")

    @property
    def n(self):
        return self.pos.shape[0]

    def copy(self):
        return State(self.pos.copy(), self.vel.copy(), self.radius.copy(), self.mass.copy(),
                     self.t_local.copy(), self.ncoll.copy(), self.t_last.copy(), self.time,
                     dict(self.meta), self.asleep.copy())

    def sha256(self):
        """sha256 of the pos then vel float64 bytes (C order, ordered by id)."""
        return state_sha256(self.pos, self.vel)

    def kinetic_energy(self):
        return 0.5 * float(np.sum(self.mass[:, None] * self.vel * self.vel))

    def momentum(self):
        return (self.mass[:, None] * self.vel).sum(axis=0)

    # ---- files -------------------------------------------------------------
    def save(self, path):
        """Write an .npz atomically: a failed write never leaves a partial file."""
        path = os.fspath(path)
        directory = os.path.dirname(os.path.abspath(path))
        os.makedirs(directory, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".npz", dir=directory)
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, pos=self.pos, vel=self.vel, radius=self.radius, mass=self.mass,
                         t_local=self.t_local, ncoll=self.ncoll, t_last=self.t_last,
                         time=np.float64(self.time), asleep=self.asleep)
            os.replace(tmp, path)
        except BaseException:
            if os.path.exists(tmp):
                os.unlink(tmp)
            raise

    @classmethod
    def load(cls, path):
        with np.load(path) as f:
            missing = [k for k in ("pos", "vel", "radius", "mass") if k not in f]
            if missing:
                raise InputError("state file", f"{path} lacks array(s) {', '.join(missing)}")
            return cls(f["pos"], f["vel"], f["radius"], f["mass"],
                       f["t_local"] if "t_local" in f else None,
                       f["ncoll"] if "ncoll" in f else None,
                       f["t_last"] if "t_last" in f else None,
                       float(f["time"]) if "time" in f else 0.0,
                       asleep=f["asleep"] if "asleep" in f else None)

    # ---- ASE -------------------------------------------------------------
    def to_ase(self, domain=None):
        """An ``ase.Atoms`` holding this state.

        Positions are stored as given (m, not Angstrom).  The exact velocities,
        radii, local times, counters and last-collision times are per-atom
        arrays ``velocity``, ``radius``, ``t_local``, ``ncoll``, ``t_last``,
        ``asleep``;
        masses are the atoms' masses.  ``atoms.info['time']`` holds the time.
        """
        from ase import Atoms

        atoms = Atoms(numbers=np.ones(self.n, int), positions=self.pos, masses=self.mass)
        if domain is not None:
            cell, pbc = domain.cell()
            atoms.set_cell(cell)
            atoms.set_pbc(pbc)
        atoms.new_array("velocity", self.vel.copy())
        atoms.new_array("radius", self.radius.copy())
        atoms.new_array("t_local", self.t_local.copy())
        atoms.new_array("ncoll", self.ncoll.copy())
        atoms.new_array("t_last", self.t_last.copy())
        atoms.new_array("asleep", self.asleep.copy())
        atoms.info["time"] = self.time
        return atoms

    @classmethod
    def from_ase(cls, atoms):
        if "radius" not in atoms.arrays:
            raise InputError("atoms.arrays['radius']", "an ase.Atoms needs per-atom radii")
        vel = atoms.arrays["velocity"] if "velocity" in atoms.arrays else atoms.get_velocities()
        get = atoms.arrays.get
        return cls(atoms.get_positions(), vel, atoms.arrays["radius"], atoms.get_masses(),
                   get("t_local"), get("ncoll"), get("t_last"), atoms.info.get("time", 0.0),
                   asleep=get("asleep"))


def _float_array(name, value, shape):
    try:
        arr = np.array(value, dtype=np.float64, copy=True, order="C")
    except (TypeError, ValueError) as exc:
        raise InputError(name, f"must be a float array ({exc})") from None
    want = tuple(arr.shape[i] if s is None else s for i, s in enumerate(shape)) \
        if arr.ndim == len(shape) else None
    if want is None or arr.shape != want:
        expect = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise InputError(name, f"must have shape {expect}, got {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise InputError(name, f"contains a non-finite value {arr[tuple(idx)]!r} at index "
                         f"{tuple(int(i) for i in idx)} ({int(bad.sum())} non-finite)")
    return arr
