"""Exceptions raised by lockgraph.  Every input error names the offending field."""


class LockgraphError(Exception):
    """Base class of lockgraph's errors."""


class InputError(LockgraphError, ValueError):
    """Invalid user input.  ``field`` names what was wrong (e.g. ``state.radius``)."""

    def __init__(self, field, message):
        self.field = field
        super().__init__(f"{field}: {message}")


class ScenarioError(InputError):
    """A scenario file or a scenario parameter is invalid."""


class SimulationError(LockgraphError, RuntimeError):
    """A run could not continue; the state was left at the last completed step."""


class InelasticCollapseError(SimulationError):
    """Collisions per step exploded (inelastic collapse)."""


class StepTooLargeError(SimulationError):
    """The time step is too large for the periodic box."""
