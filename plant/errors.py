"""The plant package's exceptions: :class:`PlantError` and its kinds.  The plant imports
nothing of the FMUs' sources, so its errors have their own root; the scenarios' command
line reports both roots (``scenarios.errors.USER_ERRORS``)."""


class PlantError(Exception):
    """Root of the plant's errors."""


class ModelError(PlantError):
    """The Cassie model cannot be loaded or lacks a joint, actuator or body by name."""


class PerturbationError(PlantError, ValueError):
    """A plant perturbation (mass, COM offset, damping, push, terrain) is invalid."""


class GaitLibraryError(PlantError):
    """The gait library file is missing, unreadable or malformed (the message names the file)."""
