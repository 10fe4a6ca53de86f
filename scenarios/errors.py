"""The scenarios package's exceptions (both derive from :class:`fmu_src.core.avr_errors.AvrError`)
and :data:`USER_ERRORS`, the errors a command reports as a message (bad input, a failed run)."""

from fmu_src.core.avr_errors import AvrError
from plant.errors import PlantError


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
    """The co-simulation master got a non-OK status from an FMU (message has its log)."""


#: What the command line reports as a message and an exit status, not a traceback.
USER_ERRORS = (AvrError, PlantError)
