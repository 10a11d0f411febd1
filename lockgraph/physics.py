"""The physics a system uses: one domain, its smooth forces, a restitution law
and optionally the collapse guard — nothing else is modelled."""
from dataclasses import dataclass

from .domains import Dish, PeriodicCube, ShearingSheet
from .errors import InputError
from .forces import Gravity, Hill
from .restitution import Bridges, CollapseGuard, Constant, VelocityGuard


@dataclass(frozen=True)
class Physics:
    """What acts on the particles.

    domain : ShearingSheet | Dish | PeriodicCube
    forces : tuple of Gravity / Hill (each at most once)
    restitution : Constant | Bridges
    guard : CollapseGuard | VelocityGuard | None
    """
    domain: object
    forces: tuple = ()
    restitution: object = Constant(1.0)
    guard: object = None

    def __post_init__(self):
        if not isinstance(self.domain, (ShearingSheet, Dish, PeriodicCube)):
            raise InputError("physics.domain", f"unknown domain {self.domain!r}")
        forces = tuple(self.forces)
        object.__setattr__(self, "forces", forces)
        kinds = [type(f) for f in forces]
        for f in forces:
            if not isinstance(f, (Gravity, Hill)):
                raise InputError("physics.forces", f"unknown force {f!r}")
        if len(set(kinds)) != len(kinds):
            raise InputError("physics.forces", "each force may appear once")
        if not isinstance(self.restitution, (Constant, Bridges)):
            raise InputError("physics.restitution", f"unknown law {self.restitution!r}")
        if self.guard is not None and not isinstance(self.guard, (CollapseGuard, VelocityGuard)):
            raise InputError("physics.guard", f"must be a CollapseGuard, a VelocityGuard or "
                             f"None, got {self.guard!r}")
        hill = self.hill
        if isinstance(self.domain, ShearingSheet):
            if hill is None:
                raise InputError("physics.forces", "a shearing sheet needs Hill's equations")
            if hill.omega != self.domain.omega:
                raise InputError("physics.forces", f"Hill omega {hill.omega} differs from the "
                                 f"sheet's omega {self.domain.omega}")
        elif hill is not None:
            raise InputError("physics.forces", "Hill's equations need a ShearingSheet domain")
        if getattr(self.guard, "v_sleep", 0.0) > 0.0 and (
                self.gravity is None or not isinstance(self.domain, Dish)):
            raise InputError("collapse_guard.v_sleep", "sleeping grains rest on a floor "
                             "under gravity: they need a Dish domain and Gravity")
        if self.gravity is not None and not isinstance(self.domain, Dish):
            raise InputError("physics.forces", "uniform gravity is only modelled with a Dish "
                             "(it needs a floor)")

    def _find(self, kind):
        for f in self.forces:
            if isinstance(f, kind):
                return f
        return None

    @property
    def hill(self):
        return self._find(Hill)

    @property
    def gravity(self):
        return self._find(Gravity)

    @property
    def g(self):
        grav = self.gravity
        return grav.g if grav is not None else 0.0

    def describe(self):
        return {
            "domain": self.domain.describe(),
            "forces": [type(f).__name__.lower() for f in self.forces],
            "restitution": {"law": type(self.restitution).__name__.lower(),
                            **self.restitution.__dict__},
            "collapse_guard": None if self.guard is None else self.guard.__dict__,
        }
