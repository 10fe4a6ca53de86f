"""What the co-simulation master needs of a plant: :class:`Plant`.

Two classes implement it: :class:`plant.sim.CassieWalker` (MuJoCo in this process) and
:class:`scenarios.cosim.plant_fmu.FmuPlant` (the CassiePlant FMU through fmpy), so the
master (:func:`scenarios.cosim.master.run_arm`) drives either through these members and
nothing else. It lives in the plant layer because it says what a plant is: the master
(above) and the FMU adapter (above) import it, the plant imports nothing from them.

Units: SI; speeds in the heading frame (x forward, y left), angles in rad.
"""
from __future__ import annotations

import operator
from typing import Any, Mapping, Protocol, Sequence

#: The regulator inputs a plant senses, in the order of :meth:`Plant.regulator_inputs` and of
#: the head of :meth:`Plant.signals`.
REGULATOR_INPUT_NAMES = ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index")
#: The last telemetry keys: the command the plant was given, with the sensed ``yaw`` and
#: ``yaw_rate`` between (the order of the results' columns).
TELEMETRY_TAIL = ("vx_des", "vy_des", "yaw", "yaw_rate", "yaw_rate_des")
#: The telemetry's keys, in the order of :meth:`Plant.telemetry` and of the tail of :meth:`Plant.signals`.
TELEMETRY_NAMES = ("t", "pelvis_x", "pelvis_y", "pelvis_z", "vx", "vy", "vx_step_avg", "vy_signal", "pitch", "roll",
                   "stance", "tau", "step_index", "left_foot_force", "right_foot_force", *TELEMETRY_TAIL)


def signal_pickers(sources: Sequence[str], regulator_from: Mapping[str, str] | None = None,
                   telemetry_from: Mapping[str, str] | None = None) -> tuple[Any, Any]:
    """How a plant picks :meth:`Plant.signals` out of its own values, named ``sources``: the
    regulator inputs and the telemetry up to :data:`TELEMETRY_TAIL` (one getter), then the tail's
    ``yaw`` and ``yaw_rate`` (the other); the plant puts its command around them. ``regulator_from``
    and ``telemetry_from``: the source of each name whose source has another name."""
    at = {n: i for i, n in enumerate(sources)}
    regulator_from, telemetry_from = regulator_from or {}, telemetry_from or {}
    reg = [at[regulator_from.get(n, n)] for n in REGULATOR_INPUT_NAMES]
    tel = [at[telemetry_from.get(n, n)] for n in TELEMETRY_NAMES[:-len(TELEMETRY_TAIL)]]
    return operator.itemgetter(*reg, *tel), operator.itemgetter(at["yaw"], at["yaw_rate"])


def inputs_of(signals: Sequence[Any]) -> dict:
    """:meth:`Plant.regulator_inputs` from :meth:`Plant.signals` (``step_index`` an int)."""
    inputs = dict(zip(REGULATOR_INPUT_NAMES, signals))
    inputs["step_index"] = int(inputs["step_index"])
    return inputs


def telemetry_of(signals: Sequence[Any]) -> dict:
    """:meth:`Plant.telemetry` from :meth:`Plant.signals` (every value a float)."""
    return dict(zip(TELEMETRY_NAMES, map(float, signals[len(REGULATOR_INPUT_NAMES):])))


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

    def set_offset_values(self, values: Sequence[float]) -> None:
        """:meth:`set_offsets` of all six offsets given as numbers in ``OFFSET_NAMES``' order
        (the master's per-step call: no names to look up)."""

    def regulator_inputs(self) -> dict:
        """The sensed regulator inputs (:data:`REGULATOR_INPUT_NAMES`): ``vx``, ``vy``, ``pitch``,
        ``roll``, ``pitch_rate``, ``roll_rate`` (floats) and ``step_index`` (int)."""

    def telemetry(self) -> dict:
        """Named floats for logging: :data:`TELEMETRY_NAMES`, in that order."""

    def signals(self) -> tuple:
        """The values of :meth:`regulator_inputs` then of :meth:`telemetry`, in one call (the
        master's per-step read; the same numbers, ``step_index`` as the plant holds it)."""

    def advance(self, n_steps: int) -> None:
        """Advance ``n_steps`` plant steps of :attr:`SIM_DT_S` with the nominal controller."""

    def fell(self) -> bool:
        """True once a fall has been detected (latched)."""

    @property
    def fall_reason(self) -> str | None:
        """Why the plant fell, or None while it has not."""

    def close(self) -> None:
        """Free what the plant holds (an FMU instance); calling it again does nothing."""


__all__ = ["Plant", "REGULATOR_INPUT_NAMES", "TELEMETRY_NAMES", "TELEMETRY_TAIL", "inputs_of", "signal_pickers",
           "telemetry_of"]
