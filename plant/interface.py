"""What the co-simulation master needs of a plant: :class:`Plant`.

Two classes implement it: :class:`plant.sim.CassieWalker` (MuJoCo in this process) and
:class:`scenarios.cosim.plant_fmu.FmuPlant` (the CassiePlant FMU through fmpy), so the
master (:func:`scenarios.cosim.master.run_arm`) drives either through these members and
nothing else. It lives in the plant layer because it says what a plant is: the master
(above) and the FMU adapter (above) import it, the plant imports nothing from them.

Units: SI; speeds in the heading frame (x forward, y left), angles in rad.
"""
from __future__ import annotations

from typing import Any, Mapping, Protocol


class Plant(Protocol):
    """A walking Cassie the master closes its loop around (see the module docstring)."""

    #: Plant step, s; the master advances whole numbers of these per communication step.
    SIM_DT_S: float

    def set_command(self, vx_des: float, vy_des: float, yaw_rate_des: float = 0.0) -> None:
        """The commanded forward and lateral speed (m/s) and turning rate (rad/s, positive
        turns left), held until changed."""

    def set_pelvis_force(self, force_n: Any) -> None:
        """A constant world-frame force on the pelvis (N, 3 numbers), held until changed."""

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        """The regulator's joint offsets (rad), keys from ``plant.constants.OFFSET_NAMES``;
        an unknown key raises KeyError."""

    def regulator_inputs(self) -> dict:
        """The sensed regulator inputs: ``vx``, ``vy``, ``pitch``, ``roll``, ``pitch_rate``,
        ``roll_rate`` (floats) and ``step_index`` (int)."""

    def telemetry(self) -> dict:
        """Named values for logging, always the same keys in the same order."""

    def advance(self, n_steps: int) -> None:
        """Advance ``n_steps`` plant steps of :attr:`SIM_DT_S` with the nominal controller."""

    def fell(self) -> bool:
        """True once a fall has been detected (latched)."""

    @property
    def fall_reason(self) -> str | None:
        """Why the plant fell, or None while it has not."""

    def close(self) -> None:
        """Free what the plant holds (an FMU instance); calling it again does nothing."""


__all__ = ["Plant"]
