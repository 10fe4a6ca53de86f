"""A regulator core stepped on an in-process walker, without FMI: the gait calibration,
the plant tests and the plant benchmark close the loop this way."""
from __future__ import annotations

from fmu_src.core.avr_params import RegulatorInputs
from plant.constants import OFFSET_NAMES
from plant.sim import CassieWalker


def apply_regulator(walker: CassieWalker, regulator, dt_s: float) -> dict[str, float]:
    """Step ``regulator`` once on the walker's signals and apply its six offsets.

    Args:
        walker: the plant; its :meth:`CassieWalker.regulator_inputs` (vx, vy in m/s,
            pitch, roll in rad, their rates in rad/s, step_index) and its commanded
            speeds ``vx_des``/``vy_des`` (m/s) are the regulator inputs.
        regulator: an ``fmu_src.core.avr_core.Regulator`` (e.g. with
            ``RegulatorParams(adaptation_enabled=False)``: the paper's PD only), or
            any object with the same ``step(RegulatorInputs, dt) -> dict`` whose dict
            holds at least the ``OFFSET_NAMES``.
        dt_s: length of this regulator call (s), the communication step (0.01 s
            for ``advance(20)``).

    Returns:
        The six ``delta_*`` joint offsets (rad) passed to :meth:`CassieWalker.set_offsets`
        (the core's diagnostic outputs ``psi_*``/``error_*`` are dropped).
    """
    u = walker.regulator_inputs()
    out = regulator.step(RegulatorInputs(vx_des=walker.vx_des, vy_des=walker.vy_des,
                                         **u), dt_s)
    offsets = {k: out[k] for k in OFFSET_NAMES}
    walker.set_offsets(offsets)
    return offsets
