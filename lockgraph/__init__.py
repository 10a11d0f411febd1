"""lockgraph: a hard-sphere collision engine processing collisions in time order,
sequentially or in parallel threads under lock-graph spatial locks.

    from lockgraph import scenarios, Simulation
    sc = scenarios.load("ring", n=2000)
    sim = Simulation(sc.state, sc.physics, dt=sc.dt).run(10)
"""
__version__ = "0.1.0"

from . import domains, forces, restitution, scenarios  # noqa: E402
from .errors import (InelasticCollapseError, InputError, LockgraphError,  # noqa: E402
                     ScenarioError, SimulationError, StepTooLargeError)
from .physics import Physics  # noqa: E402
from .simulation import Simulation  # noqa: E402
from .state import State  # noqa: E402

__all__ = ["Simulation", "State", "Physics", "scenarios", "domains", "forces", "restitution",
           "LockgraphError", "InputError", "ScenarioError", "SimulationError",
           "InelasticCollapseError", "StepTooLargeError"]
