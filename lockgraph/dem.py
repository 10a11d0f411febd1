"""Soft-sphere (DEM) runs of a lockgraph scene in LAMMPS or LIGGGHTS.

The two granular codes the comparison trusts resolve a collision as a contact
of finite duration t_c.  This module writes one input deck per code from a
lockgraph state and its physics — the same grains, positions, velocities,
walls, gravity and restitution — runs the code as a subprocess (a crash or a
hang cannot take the caller down; a timeout is an error, never a hang), and
reads the dumped states back to numpy.

Contact model, both codes: Hertz (``hertz/material`` in LAMMPS, ``model hertz``
in LIGGGHTS) with Young's modulus E and Poisson ratio 0.3, restitution e from
the scene, zero friction (lockgraph's spheres are smooth), no rolling
resistance.  LAMMPS also offers linear ``hooke`` (stiffness k_n in N/m).  The
step is dt = t_c / dt_fraction with t_c the contact time of the fastest
expected grain-grain impact (Hertz t_c falls as v^-1/5).
"""
import math
import os
import re
import shutil
import subprocess
import tempfile
import time as _time
from dataclasses import dataclass, field

import numpy as np

from .domains import Dish, PeriodicCube
from .errors import InputError, SimulationError
from .reference_codes import lammps_binary, liggghts_binary, mpirun
from .restitution import Constant

CODES = ("lammps", "liggghts")
NAMES = {"lammps": "LAMMPS", "liggghts": "LIGGGHTS"}  # for people
MODELS = {"lammps": ("hertz", "hooke"), "liggghts": ("hertz",)}
POISSON = 0.3
# LIGGGHTS refuses E > 1e9 Pa unless told its particles are hard
LIGGGHTS_HARD = 1e9


class DemFailure(SimulationError):
    """A DEM code exited with an error or did not finish in time."""


@dataclass(frozen=True)
class Contact:
    """The soft-sphere contact standing in for lockgraph's instantaneous collision.

    model : "hertz" (stiffness = Young's modulus E, Pa) or "hooke" (stiffness =
    k_n, N/m; LAMMPS only); dt_fraction : steps per contact time; skin :
    neighbour skin as a fraction of the smallest radius.
    """
    model: str = "hertz"
    stiffness: float = 1e8
    dt_fraction: float = 50.0
    skin: float = 0.5

    def __post_init__(self):
        if self.model not in ("hertz", "hooke"):
            raise InputError("contact.model", f"unknown value {self.model!r}; one of hertz, hooke")
        for name in ("stiffness", "dt_fraction", "skin"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"contact.{name}", f"must be a finite number > 0, got {v!r}")


def contact_time(contact, r1, r2, m1, m2, e, speed):
    """Duration (s) of a binary contact at normal approach speed ``speed`` (m/s).

    hooke: the damped oscillator's half period, exact.  hertz: the elastic
    Hertz time 2.868 (m*/(E* sqrt(R*)))^(2/5) v^(-1/5) with
    E* = E / (2 (1 - nu^2)) (damping lengthens it slightly).
    """
    meff = m1 * m2 / (m1 + m2) if math.isfinite(m2) else m1
    if contact.model == "hooke":
        return math.sqrt(meff / contact.stiffness) * math.sqrt(math.pi ** 2 + math.log(e) ** 2)
    estar = contact.stiffness / (2.0 * (1.0 - POISSON ** 2))
    rstar = r1 * r2 / (r1 + r2) if math.isfinite(r2) else r1
    return 2.868 * (meff / (estar * math.sqrt(rstar))) ** 0.4 * max(speed, 1e-12) ** -0.2


def impact_speed(state, physics):
    """Largest normal speed (m/s) a grain can reach: current speeds plus a fall
    from the highest grain to the floor."""
    v = float(np.sqrt(np.max(np.sum(state.vel ** 2, axis=1)))) if state.n else 0.0
    g = physics.g
    if g > 0:
        zmax = float(np.max(state.pos[:, 2]))
        v = math.sqrt(v * v + 2.0 * g * max(zmax, 0.0))
    return 2.0 * v  # two grains approaching head-on


def time_step(state, physics, contact):
    """(dt, t_c): t_c of the shortest contact among the particle sizes present."""
    e = physics.restitution.e
    speed = impact_speed(state, physics)
    tc = math.inf
    sizes = np.unique(np.column_stack([state.radius, state.mass]), axis=0)
    for i in range(len(sizes)):
        for j in range(i, len(sizes)):
            tc = min(tc, contact_time(contact, sizes[i, 0], sizes[j, 0], sizes[i, 1],
                                      sizes[j, 1], e, speed))
    return tc / contact.dt_fraction, tc


@dataclass
class DemResult:
    """States dumped by a DEM run.

    code, version : which program; times : (k,) s; pos, vel : (k, n, 3) m, m/s,
    rows in lockgraph's particle order (a lost particle's rows are NaN);
    dt : step (s); contact_time : t_c (s); steps : steps run; wall_s : wall time
    of the whole subprocess (s); loop_s : the code's own timing of its run loop
    (s); failures : what went wrong (dict, empty when nothing did); deck : the
    input deck; log : the code's last output lines; sample_wall : (k,) s, the
    wall time from the subprocess's start to each snapshot (its start-up plus
    the code's own elapsed-time column ``cpu`` of the thermo output; NaN if
    the output could not be read).
    """
    code: str
    version: str
    times: np.ndarray
    pos: np.ndarray
    vel: np.ndarray
    dt: float
    contact_time: float
    steps: int
    wall_s: float
    loop_s: float
    failures: dict = field(default_factory=dict)
    deck: str = ""
    log: str = ""
    max_overlap: float = math.nan
    sample_wall: np.ndarray = None


def _f(x):
    """A float for an input deck: full precision, never numpy's repr."""
    return repr(float(x))


def _check(state, physics, code, contact):
    if code not in CODES:
        raise InputError("against", f"unknown DEM code {code!r}; one of {', '.join(CODES)}")
    if contact.model not in MODELS[code]:
        raise InputError("contact.model", f"{code} runs {', '.join(MODELS[code])}, "
                         f"not {contact.model!r}")
    if not isinstance(physics.restitution, Constant):
        raise InputError("physics.restitution", "the DEM comparison models a constant "
                         f"restitution only, not {type(physics.restitution).__name__}")
    if not isinstance(physics.domain, (Dish, PeriodicCube)):
        raise InputError("physics.domain", "DEM runs model the dish (or a periodic cube "
                         f"without gravity), not {type(physics.domain).__name__}")
    if physics.hill is not None:
        raise InputError("physics.forces", "DEM runs do not model Hill's equations")


def _types(state):
    """Atom type per particle (1-based) and (radius, density) per type: one type
    per distinct size, so a marble can have its own neighbour treatment."""
    dens = state.mass / (4.0 / 3.0 * np.pi * state.radius ** 3)
    keys, inv = np.unique(np.round(np.column_stack([state.radius, dens]), 12), axis=0,
                          return_inverse=True)
    return inv.ravel() + 1, keys, dens


def _box(state, physics):
    dom = physics.domain
    if isinstance(dom, PeriodicCube):  # centred on the origin, as in lockgraph
        h = 0.5 * dom.length
        return (-h, h), (-h, h), (-h, h), "p p p"
    rmax = float(state.radius.max())
    lo = -dom.radius - rmax
    top = float(np.max(state.pos[:, 2] + state.radius)) + 2.0 * rmax
    # z shrink-wraps with a minimum: grains may rise above the initial top
    return (lo, -lo), (lo, -lo), (-rmax, top), "f f m"


def _data_file(state, physics, path):
    typ, keys, dens = _types(state)
    (xl, xh), (yl, yh), (zl, zh), _ = _box(state, physics)
    pos = state.pos
    if isinstance(physics.domain, PeriodicCube):
        h = 0.5 * physics.domain.length
        pos = np.mod(pos + h, physics.domain.length) - h
    lines = ["lockgraph state", "", f"{state.n} atoms", f"{len(keys)} atom types", "",
             f"{_f(xl)} {_f(xh)} xlo xhi", f"{_f(yl)} {_f(yh)} ylo yhi",
             f"{_f(zl)} {_f(zh)} zlo zhi", "", "Atoms", ""]
    for i in range(state.n):
        lines.append(f"{i + 1} {typ[i]} {_f(2 * state.radius[i])} {_f(dens[i])} "
                     f"{_f(pos[i, 0])} {_f(pos[i, 1])} {_f(pos[i, 2])}")
    lines += ["", "Velocities", ""]
    for i in range(state.n):
        v = state.vel[i]
        lines.append(f"{i + 1} {_f(v[0])} {_f(v[1])} {_f(v[2])} 0.0 0.0 0.0")
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    return len(keys)


def _lammps_deck(state, physics, contact, dt, steps, every, ntypes, ranks, track):
    e = physics.restitution.e
    if contact.model == "hertz":
        normal = f"hertz/material {_f(contact.stiffness)} {_f(e)} {_f(POISSON)}"
    else:
        normal = f"hooke {_f(contact.stiffness)} {_f(e)}"
    # smooth spheres: a tangential model is required, with zero stiffness and friction
    model = f"{normal} tangential linear_nohistory 0.0 0.0 damping coeff_restitution"
    skin = contact.skin * float(state.radius.min())
    _, _, _, boundary = _box(state, physics)
    lines = ["units si", "atom_style sphere", "atom_modify map array", f"boundary {boundary}",
             "comm_modify vel yes"]
    if ranks > 1:
        lines.append("processors * * 1")  # split the dish across x-y only
    lines += ["read_data data.in",
              # several sizes: the marble's type gets its own bins
              f"neighbor {_f(skin)} {'multi' if ntypes > 1 else 'bin'}",
              "neigh_modify delay 0 every 1 check yes",
              "pair_style granular", f"pair_coeff * * {model}"]
    lines += _lammps_walls(physics, model)
    # LAMMPS: 'format float'; LIGGGHTS 3.8 knows only a whole-line format
    return _run_lines(lines, dt, steps, every, "float %.17g", track)


def _lammps_walls(physics, model):
    dom = physics.domain
    if not isinstance(dom, Dish):
        return []
    return [f"fix gravity all gravity {_f(physics.g)} vector 0.0 0.0 -1.0",
            f"fix floor all wall/gran granular {model} zplane 0.0 NULL",
            f"fix cylinder all wall/gran granular {model} zcylinder {_f(dom.radius)}"]


def _liggghts_deck(state, physics, contact, dt, steps, every, ntypes, ranks, track):
    e = physics.restitution.e
    skin = contact.skin * float(state.radius.min())
    _, _, _, boundary = _box(state, physics)
    t = ntypes
    lines = ["atom_style granular", "atom_modify map array", f"boundary {boundary}",
             "newton off", "communicate single vel yes", "units si"]
    if ranks > 1:
        lines.append("processors * * 1")
    lines += ["read_data data.in",
              # 'multi' silently builds empty granular lists in 3.8: always 'bin'
              f"neighbor {_f(skin)} bin", "neigh_modify delay 0 every 1 check yes"]
    if contact.stiffness > LIGGGHTS_HARD:
        lines.append("hard_particles yes")
    lines += ["fix m1 all property/global youngsModulus peratomtype "
              + " ".join([_f(contact.stiffness)] * t),
              "fix m2 all property/global poissonsRatio peratomtype "
              + " ".join([_f(POISSON)] * t),
              f"fix m3 all property/global coefficientRestitution peratomtypepair {t} "
              + " ".join([_f(e)] * (t * t)),
              f"fix m4 all property/global coefficientFriction peratomtypepair {t} "
              + " ".join(["0.0"] * (t * t)),
              "pair_style gran model hertz tangential no_history", "pair_coeff * *"]
    dom = physics.domain
    if isinstance(dom, Dish):
        wall = "wall/gran model hertz tangential no_history primitive type 1"
        lines += [f"fix gravity all gravity {_f(physics.g)} vector 0.0 0.0 -1.0",
                  f"fix floor all {wall} zplane 0.0",
                  f"fix cylinder all {wall} zcylinder {_f(dom.radius)} 0.0 0.0"]
    return _run_lines(lines, dt, steps, every,
                      "\"%d %.17g %.17g %.17g %.17g %.17g %.17g\"", track)


def _run_lines(lines, dt, steps, every, dump_format, track):
    """The deck's tail, the same for both codes: integrate, report lost atoms
    without stopping (the harness counts them), dump every ``every`` steps —
    all particles, or only ``track`` (then all of them at the start and end)."""
    lines = lines + ["fix integrate all nve/sphere", f"timestep {_f(dt)}",
                     "thermo_style custom step atoms ke cpu", f"thermo {max(1, every)}",
                     "thermo_modify lost warn norm no"]
    group = "all"
    if track is not None:
        group = "tracked"
        lines += ["group tracked id " + " ".join(str(int(i) + 1) for i in track),
                  f"dump final all custom {steps} final.dump id x y z vx vy vz",
                  f"dump_modify final sort id format {dump_format}"]
    lines += [f"dump out {group} custom {every} out.dump id x y z vx vy vz",
              f"dump_modify out sort id format {dump_format}",
              f"run {steps}"]
    return "\n".join(lines) + "\n"


def thermo_elapsed(out):
    """The ``cpu`` column of a run's thermo table (s since the run began: both
    codes time it with MPI_Wtime), one value per thermo line; other lines
    (warnings) inside the table are skipped."""
    vals, col, width = [], None, 0
    for line in out.splitlines():
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "Step":
            col, width = (tok.index("CPU"), len(tok)) if "CPU" in tok else (None, 0)
        elif tok[0] == "Loop":
            col = None
        elif col is not None and len(tok) == width:
            try:
                vals.append(float(tok[col]))
            except ValueError:
                pass
    return np.array(vals)


def read_dump(path, n):
    """Snapshots of a LAMMPS-style custom dump ``id x y z vx vy vz``: (steps (k,),
    pos (k, n, 3), vel (k, n, 3)); atoms missing from a snapshot are NaN."""
    steps, pos, vel = [], [], []
    with open(path) as fh:
        lines = fh.read().splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("ITEM: TIMESTEP"):
            step = int(lines[i + 1])
            count = int(lines[i + 3])
            j = i + 4
            while not lines[j].startswith("ITEM: ATOMS"):
                j += 1
            rows = np.array([ln.split() for ln in lines[j + 1:j + 1 + count]], float)
            rows = rows.reshape(count, 7)
            p = np.full((n, 3), np.nan)
            v = np.full((n, 3), np.nan)
            ids = rows[:, 0].astype(np.int64) - 1
            p[ids] = rows[:, 1:4]
            v[ids] = rows[:, 4:7]
            steps.append(step)
            pos.append(p)
            vel.append(v)
            i = j + 1 + count
        else:
            i += 1
    return np.array(steps, np.int64), np.array(pos), np.array(vel)


_LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs")


def command(code, ranks=1, threads=1):
    """The command line (list) running ``code`` on ``ranks`` MPI ranks."""
    if code == "lammps":
        exe = [lammps_binary()]
        if threads > 1:
            exe += ["-sf", "omp", "-pk", "omp", str(threads)]
    else:
        exe = [liggghts_binary()]
    if ranks > 1:
        launcher = [mpirun(code), "-np", str(ranks)]
        if code == "liggghts" and hasattr(os, "geteuid") and os.geteuid() == 0:
            launcher.append("--allow-run-as-root")  # Open MPI refuses root otherwise
        exe = launcher + exe
    return exe + ["-in", "in.deck", "-log", "log.out", "-echo", "none"]


def run(state, physics, code, duration, contact=Contact(), samples=1, ranks=1, threads=1,
        timeout=3600.0, dt=None, progress=None, track=None):
    """Run ``code`` ("lammps" or "liggghts") from ``state`` for ``duration`` s and
    return a DemResult with ``samples`` + 1 snapshots (the start included).
    With ``track`` (particle indices) the snapshots between the first and the
    last hold only those particles (the others are NaN): a marble followed
    through a large bed.

    ``dt`` overrides the step chosen from the contact time (to probe a step that
    is too large).  Raises DemFailure when the code exits with an error or
    runs longer than ``timeout`` s; physical failures of a finished run (lost
    particles, energy gained, deep overlaps) are in ``result.failures``.
    """
    _check(state, physics, code, contact)
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError("duration", f"must be a finite time > 0 s, got {duration!r}")
    if not (isinstance(samples, int) and samples >= 1):
        raise InputError("samples", f"must be an integer >= 1, got {samples!r}")
    step, tc = time_step(state, physics, contact)
    if dt is not None:
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError("dt", f"must be a finite time > 0 s, got {dt!r}")
        step = float(dt)
    every = max(1, int(math.ceil(duration / step / samples)))
    steps = every * samples
    step = duration / steps  # land exactly on the sample times
    exe = command(code, ranks, threads)
    version = code_version(code)
    work = tempfile.mkdtemp(prefix=f"lockgraph-{code}-")
    try:
        ntypes = _data_file(state, physics, os.path.join(work, "data.in"))
        writer = _lammps_deck if code == "lammps" else _liggghts_deck
        if track is not None:
            track = np.unique(np.asarray(track, np.int64))
            if track.size == 0 or track.min() < 0 or track.max() >= state.n:
                raise InputError("track", f"particle indices must lie in 0..{state.n - 1}")
        deck = writer(state, physics, contact, step, steps, every, ntypes, ranks, track)
        with open(os.path.join(work, "in.deck"), "w") as fh:
            fh.write(deck)
        env = dict(os.environ, OMP_NUM_THREADS=str(threads), OMP_WAIT_POLICY="passive")
        if progress is not None:
            progress(f"{code}: {state.n} particles, {steps} steps of {step:.3g} s "
                     f"(t_c {tc:.3g} s / {contact.dt_fraction:g}), {ranks} rank(s)")
        t0 = _time.perf_counter()
        try:
            proc = subprocess.run(exe, cwd=work, env=env, capture_output=True, text=True,
                                  timeout=timeout)
        except subprocess.TimeoutExpired:
            raise DemFailure(f"{code} did not finish {steps} steps within {timeout:g} s") from None
        wall = _time.perf_counter() - t0
        out = proc.stdout + proc.stderr
        log = "\n".join(out.strip().splitlines()[-15:])
        dump = os.path.join(work, "out.dump")
        if proc.returncode != 0 or not os.path.exists(dump):
            err = [ln for ln in out.splitlines() if "ERROR" in ln]
            raise DemFailure(f"{code} exited with code {proc.returncode}: "
                             f"{err[0] if err else log}")
        dsteps, pos, vel = read_dump(dump, state.n)
        if track is not None:
            fsteps, fpos, fvel = read_dump(os.path.join(work, "final.dump"), state.n)
            for k, st in enumerate(fsteps):  # the start and the end, complete
                hit = np.flatnonzero(dsteps == st)
                if hit.size:
                    pos[hit[0]], vel[hit[0]] = fpos[k], fvel[k]
        loop = sum(float(m.group(1)) for m in _LOOP.finditer(out))
        elapsed = thermo_elapsed(out)
        sample_wall = (wall - loop + elapsed if elapsed.shape[0] == dsteps.shape[0]
                       else np.full(dsteps.shape[0], np.nan))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    if isinstance(physics.domain, PeriodicCube):
        pos = _unwrap(pos, state.pos, physics.domain.length)
    res = DemResult(code, version, state.time + dsteps * step, pos, vel, step, tc, steps,
                    wall, loop, {}, deck, log, sample_wall=sample_wall)
    res.failures = failures(res, state, physics, complete=track is None)
    return res


def _unwrap(pos, start, length):
    """Periodic positions moved to the image nearest the start (two-body runs
    are far shorter than a box crossing)."""
    return pos - length * np.round((pos - start[None]) / length)


# Overlap (fraction of the contact distance) above which a DEM state is
# reported as deeply overlapping: ten times the ~1 % a Hertz contact reaches
# in the dish at E = 1e7 Pa, so only a collapsing contact model crosses it.
DEEP_OVERLAP = 0.1
# Energy gain (fraction of the initial mechanical energy above the final
# resting level) reported as a blow-up: a dissipative run can only lose it.
ENERGY_GAIN = 0.01


def mechanical_energy(pos, vel, mass, g):
    """Kinetic plus gravitational energy (J) of each snapshot (k,)."""
    ke = 0.5 * np.nansum(mass[None, :] * np.sum(vel ** 2, axis=2), axis=1)
    pe = g * np.nansum(mass[None, :] * pos[:, :, 2], axis=1)
    return ke + pe


def overlap_of(pos, radius, domain):
    """Largest pair overlap (fraction of the contact distance) among the
    particles with finite positions (NaN with fewer than two)."""
    from .overlaps import max_overlap
    from .state import State

    ok = np.isfinite(pos).all(axis=1)
    m = int(ok.sum())
    if m < 2:
        return math.nan
    return float(max_overlap(State(pos[ok], np.zeros((m, 3)), radius[ok], np.ones(m)),
                             domain)[0])


def failures(res, state, physics, complete=True):
    """What went physically wrong in a finished DEM run (dict; empty if nothing).
    ``complete``: every snapshot holds every particle (else only the first and
    the last are used for the energy balance).  Sets ``res.max_overlap``."""
    out = {}
    lost = int(np.sum(~np.isfinite(res.pos[-1]).all(axis=1)))
    if lost:
        out["lost_particles"] = lost
    pick = slice(None) if complete else [0, -1]
    energy = mechanical_energy(res.pos[pick], res.vel[pick], state.mass, physics.g)
    floor = float(physics.g * np.sum(state.mass * state.radius))  # all grains on the floor
    scale = max(energy[0] - floor, 1e-300)
    gain = float(np.nanmax(energy - energy[0]) / scale) if np.isfinite(energy).any() else math.inf
    if not (gain <= ENERGY_GAIN):
        out["energy_gain"] = gain
    last = res.pos[-1]
    ok = np.isfinite(last).all(axis=1)
    res.max_overlap = overlap_of(last, state.radius, physics.domain)
    if res.max_overlap > DEEP_OVERLAP:
        out["deep_overlap"] = res.max_overlap
    if isinstance(physics.domain, Dish) and ok.any():
        rho = np.hypot(last[ok, 0], last[ok, 1]) + state.radius[ok]
        escaped = int(np.sum((rho > physics.domain.radius + state.radius[ok])
                             | (last[ok, 2] < 0.0)))
        if escaped:
            out["escaped_walls"] = escaped
    return out


_VERSIONS = {}


def code_version(code):
    """The code's version banner (cached), e.g. 'LAMMPS (22 Jul 2025 - Update 4)'."""
    if code not in _VERSIONS:
        exe = lammps_binary() if code == "lammps" else liggghts_binary()
        try:
            with tempfile.TemporaryDirectory() as work:  # no log file left in the caller's cwd
                p = subprocess.run([exe, "-h"] if code == "lammps" else [exe], input="",
                                   capture_output=True, text=True, timeout=120, cwd=work)
            text = [ln.strip() for ln in (p.stdout + p.stderr).splitlines() if ln.strip()]
            hit = [ln for ln in text if ln.startswith(("LAMMPS", "LIGGGHTS"))]
            # lmp -h opens with "Large-scale Atomic/... Simulator - 22 Jul 2025 - Update 4"
            big = [ln.split(" - ", 1)[1] for ln in text
                   if ln.startswith("Large-scale") and " - " in ln]
            _VERSIONS[code] = (hit[0] if hit else f"LAMMPS ({big[0]})" if big
                               else text[0] if text else code)
        except (OSError, subprocess.TimeoutExpired):
            _VERSIONS[code] = code
    return _VERSIONS[code]
