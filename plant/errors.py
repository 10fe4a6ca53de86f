"""The plant package's exceptions (both derive from :class:`fmu_src.avr_errors.AvrError`)."""

from fmu_src.avr_errors import AvrError


class ModelError(AvrError):
    """The Cassie model cannot be loaded or lacks a joint, actuator or body by name."""


class PerturbationError(AvrError, ValueError):
    """A plant perturbation (mass, COM offset, damping, push, terrain) is invalid."""
