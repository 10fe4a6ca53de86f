"""The regulator FMU's exceptions (``fmu_src`` is self-contained: numpy only).

:class:`AvrError` is the base of every error this project raises on purpose;
``plant.errors`` and ``scenarios.errors`` derive theirs from it, so a caller can catch
one class.  Every error that reports bad input names the field and the allowed range.
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
