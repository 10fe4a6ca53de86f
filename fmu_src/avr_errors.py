"""The project's one exceptions module.

It lives in ``fmu_src`` because the FMU must be self-contained (numpy only) and
the regulator core raises these; ``plant`` and ``scenarios`` import from here too.
Every error that reports bad input names the field and the allowed range.
"""


class AvrError(Exception):
    """Base class of every error this project raises on purpose."""


class ParameterError(AvrError, ValueError):
    """A regulator parameter is missing, of the wrong type or out of range.

    ``problems`` lists every problem found (one string each), not just the first.
    """

    def __init__(self, problems):
        if isinstance(problems, str):
            problems = [problems]
        self.problems = list(problems)
        super().__init__("; ".join(self.problems))


class InputError(AvrError, ValueError):
    """A regulator input is NaN, infinite or out of range (message names it)."""


class StateError(AvrError):
    """An FMU state blob cannot be restored (wrong format, size or version)."""


class ModelError(AvrError):
    """The Cassie model cannot be loaded or lacks a joint, actuator or body by name."""


class PerturbationError(AvrError, ValueError):
    """A plant perturbation (mass, COM offset, damping, push, terrain) is invalid."""


class ScenarioError(AvrError, ValueError):
    """A scenario file is invalid; ``problems`` lists every problem at once."""

    def __init__(self, problems, source=None):
        if isinstance(problems, str):
            problems = [problems]
        self.problems = list(problems)
        self.source = source
        head = f"{source}: " if source else ""
        super().__init__(head + f"{len(self.problems)} problem(s):\n  - " + "\n  - ".join(self.problems))


class CosimError(AvrError):
    """The co-simulation master got a non-OK status from the FMU (message has its log)."""
