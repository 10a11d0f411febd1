"""Restitution laws and the inelastic-collapse guard.

* ``Constant(e)``: normal restitution e for every impact.
* ``Bridges(v_c, exponent)``: Bridges, Hatzes & Lin (1984, Nature 309, 333),
  frost-covered ice at ring temperatures: e(v_n) = min(1, (|v_n| / v_c)^-exponent),
  v_c = 7.7e-5 m/s, exponent = 0.234.
* ``CollapseGuard(tc)``: the TC model of Luding & McNamara (1998, Granular
  Matter 1, 113): a pair impact is elastic if either body had a pair impact
  less than ``tc`` seconds before.  Wall impacts neither follow nor reset this
  clock (a grain resting on the floor touches it every few tc; counting those
  touches would make all its impacts elastic and a settling bed would keep its
  horizontal motion for ever — measured: a 200-grain dish froze at 0.06 m/s rms
  for tc from 1e-4 to 1e-6 s).  Instead the floor returns a body at no less
  than ``g tc / 2``, the speed of a hop lasting tc, which ends the floor's own
  Zeno sequence of ever faster bounces.
* ``VelocityGuard(v_min)``: impacts (pair, floor and cylinder) whose normal
  approach speed is below ``v_min`` are elastic, the others follow the law.
  Collapse needs relative speeds that shrink without end, so a floor on the
  dissipating speeds prevents it, as velocity-dependent restitution does in
  McNamara & Falcon (2005, Phys. Rev. E 71, 031302), whose e reaches 1 below
  about sqrt(g d).  Unlike the TC model it keeps dissipating in a dense bed
  whose grains collide often but fast: in the settling dish 95-99.8 % of the
  impacts came within tc = 1e-4 s of a grain's last one and were made elastic
  by the TC model.  The price: motion below ``v_min`` is never damped, so a
  settled bed keeps bouncing (the settling dish at 0.35 s: rms 2-6 mm/s for
  v_min from 3 mm/s to 2 cm/s, against 1 mm/s under the TC model at 1e-4 s).
* ``VelocityGuard(v_min, exponent=p)``, p > 0, the soft form: below ``v_min``
  the restitution is 1 - (1 - e(v)) (v / v_min)^p, continuous at v_min and 1
  only in the limit v -> 0.  Slow motion is still damped: a floor bounce's
  speed v obeys dv/dn = -(1 - e) v^(p+1) / v_min^p per bounce, and a bounce
  lasts 2 v / g, so v_n ~ n^(-1/p) and the durations sum to a divergent series
  for p >= 1 (no Zeno sequence; for p < 1 it converges: refused).  For p = 2
  the speed falls as 1/t while the bounce count grows as t^2 (for p = 1
  exponentially).  The settling dish does settle under it (at v_min =
  2-3 cm/s, p = 2, close to the reference's settling time), but a settled
  bed's collision rate keeps rising as its motion dies out.
* ``VelocityGuard(v_min, exponent=p, v_sleep=s)``, s > 0, adds sleeping
  grains (as rigid-body and granular codes put bodies at rest to sleep): a grain
  whose speed relative to its support after an impact on the floor or on a
  sleeping grain is below ``v_sleep`` falls asleep at the end of the step,
  where it then is: held at rest, feeling no gravity and no walls.  An impact
  on a sleeping grain with normal approach speed below ``v_sleep`` finds it
  immovable (the mover bounces off it as off a wall); a faster one wakes it
  and is an ordinary two-body impact, as is one from below by a grain on
  the floor (the engine's asleep grain rises and comes back by g dt^2 / 8
  in a step, and would squeeze it against the floor without end).  A hard-sphere bed carries its weight
  by collisions, at a rate growing with the weight above a grain; asleep, a
  grain carries it without any.  The price: momentum is not conserved at an
  immovable sleeper, a grain asleep on a slope does not slide (it acts as if
  it had friction), and a sleeper whose support leaves stays where it is
  until it is hit; a grain falls asleep up to ``v_sleep`` dt from, and up
  to ``v_sleep^2 / 2 g`` above, where it last touched its support.
* ``VelocityGuard(v_min, exponent=p, v_sleep=s, t_sleep=w)``, w > 0: a grain
  sleeps only after waiting: it is drowsy from its first impact after which
  its speed relative to the other body (the floor, a sleeper, or now any
  grain) is below ``v_sleep``, stays drowsy while every impact is that slow,
  wakes at a faster one or if it is as fast as ``v_sleep`` at a step end,
  and falls asleep at the first step end at least ``t_sleep`` after it
  became drowsy.  Put to sleep on its first slow landing, a grain has had no
  time to slide into a pocket, and the settled bed is looser than a DEM
  code's (1,000 grains: 0.23 d taller, floor coverage 0.037 lower, against
  LAMMPS); after 2 ms of slow impacts it agrees with LAMMPS within the
  scene's tolerances, at 1.6-1.9 times the wall time (4-6 times the
  collisions).  The drowsy grains'
  times are the state's ``t_last``, so a saved run resumes bitwise.
"""
from dataclasses import dataclass

from ._jit import kernel

from .errors import InputError

LAW_CONSTANT = 0
LAW_BRIDGES = 1


def _positive(field, value):
    value = float(value)
    if not value > 0 or value != value or value == float("inf"):
        raise InputError(field, f"must be a finite number > 0 (got {value!r})")
    return value


@dataclass(frozen=True)
class Constant:
    """Constant normal coefficient of restitution, 0 <= e <= 1."""
    e: float

    def __post_init__(self):
        e = float(self.e)
        if not (0.0 <= e <= 1.0):
            raise InputError("restitution.e", f"must be in [0, 1] (got {self.e!r})")
        object.__setattr__(self, "e", e)

    def encode(self):
        return LAW_CONSTANT, self.e, 0.0, 0.0


@dataclass(frozen=True)
class Bridges:
    """Velocity-dependent restitution e = min(1, (|v_n|/v_c)^-exponent)."""
    v_c: float = 7.7e-5
    exponent: float = 0.234

    def __post_init__(self):
        object.__setattr__(self, "v_c", _positive("restitution.v_c", self.v_c))
        object.__setattr__(self, "exponent", _positive("restitution.exponent", self.exponent))

    def encode(self):
        return LAW_BRIDGES, 1.0, self.v_c, self.exponent


@dataclass(frozen=True)
class CollapseGuard:
    """TC model: impacts within ``tc`` seconds of a body's previous one are elastic."""
    tc: float

    def __post_init__(self):
        object.__setattr__(self, "tc", _positive("collapse_guard.tc", self.tc))


@dataclass(frozen=True)
class VelocityGuard:
    """Impacts whose normal approach speed v is below ``v_min`` (m/s) are elastic
    (``exponent`` 0, the hard guard) or, with ``exponent`` p > 0 (the soft
    guard), have restitution 1 - (1 - e(v)) (v / v_min)^p: continuous at
    v_min, elastic only in the limit v -> 0.  ``v_sleep`` > 0 (m/s) lets slow
    grains sleep on their supports, after ``t_sleep`` (s) of slow impacts if
    that is > 0 (see the module docstring; it needs gravity and a dish)."""
    v_min: float
    exponent: float = 0.0
    v_sleep: float = 0.0
    t_sleep: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "v_min", _positive("collapse_guard.v_min", self.v_min))
        p = float(self.exponent)
        if not (p == 0.0 or 1.0 <= p < float("inf")):
            # below 1 a floor bounce's durations v_n ~ n^(-1/p) sum to a finite
            # time: the Zeno sequence the guard is there to prevent
            raise InputError("collapse_guard.exponent",
                             f"must be 0 (hard guard) or a finite number >= 1 (got "
                             f"{self.exponent!r}; below 1 bounces would collapse)")
        object.__setattr__(self, "exponent", p)
        s = float(self.v_sleep)
        if not (0.0 <= s < float("inf")):
            raise InputError("collapse_guard.v_sleep",
                             f"must be a finite number >= 0 (0: no sleeping; got "
                             f"{self.v_sleep!r})")
        object.__setattr__(self, "v_sleep", s)
        d = float(self.t_sleep)
        if not (0.0 <= d < float("inf")):
            raise InputError("collapse_guard.t_sleep",
                             f"must be a finite number >= 0 (got {self.t_sleep!r})")
        if d > 0.0 and s == 0.0:
            raise InputError("collapse_guard.t_sleep",
                             "is how long a grain waits before it sleeps: it needs "
                             "v_sleep > 0")
        object.__setattr__(self, "t_sleep", d)


@kernel
def coefficient(law, e, v_c, exponent, vn):
    """Restitution for an impact with normal approach speed vn >= 0."""
    if law == LAW_CONSTANT:
        return e
    if vn <= v_c:
        return 1.0
    return (vn / v_c) ** (-exponent)
