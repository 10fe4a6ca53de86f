"""Both plants the master drives (the in-process walker and the plant FMU adapter) implement
:class:`plant.interface.Plant` in full: every member, with a signature the master's calls fit.

Checked structurally on real instances (a real compiled model, the real built CassiePlant FMU
through fmpy): ``isinstance`` against a ``runtime_checkable`` protocol would only look for the
names."""
from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from plant.interface import REGULATOR_INPUT_NAMES, TELEMETRY_NAMES, Plant
from support.plant_fmu_support import built_plant_fmu

#: The members of the protocol (its own, not object's).
MEMBERS = sorted(n for n in vars(Plant) if not n.startswith("_")) + ["SIM_DT_S"]


def protocol_problems(obj) -> list[str]:
    """Why ``obj`` does not implement :class:`Plant`: a missing member, a method where a
    property is due (or the reverse), or a method whose parameters differ (names, order,
    defaults: the master calls them positionally and by keyword)."""
    problems = []
    for name in MEMBERS:
        if not hasattr(obj, name):
            problems.append(f"{type(obj).__name__} has no {name}")
            continue
        want = inspect.getattr_static(Plant, name, None)
        got = inspect.getattr_static(type(obj), name, None)
        if name == "SIM_DT_S":
            if not isinstance(getattr(obj, name), float) or not getattr(obj, name) > 0:
                problems.append(f"{name} = {getattr(obj, name)!r}: must be a float > 0")
        elif isinstance(want, property):
            if not isinstance(got, property):
                problems.append(f"{name} must be a property")
            else:
                getattr(obj, name)  # readable
        else:
            if not callable(getattr(obj, name)):
                problems.append(f"{name} must be a method")
                continue
            w = list(inspect.signature(want).parameters.values())[1:]
            g = list(inspect.signature(getattr(obj, name)).parameters.values())
            if [(p.name, p.kind, p.default) for p in w] != [(p.name, p.kind, p.default) for p in g]:
                problems.append(f"{name}{inspect.signature(getattr(obj, name))}: must be {name}({', '.join(map(str, w))})")
    return problems


def test_the_check_catches_a_plant_that_is_not_one():
    class Half:
        SIM_DT_S = 0.0005

        def set_command(self, vx_des_mps, vy_des_mps):  # other names, no yaw rate
            pass

        def fall_reason(self):  # a method where a property is due
            return None

    found = protocol_problems(Half())
    assert any(p.startswith("set_command") for p in found)
    assert "fall_reason must be a property" in found
    assert "Half has no close" in found and "Half has no advance" in found


def _drive(plant) -> list[str]:
    """What the master does to a plant in one communication step, and the close; the
    telemetry's keys."""
    plant.set_command(0.3, 0.0, 0.0)
    plant.set_pelvis_force(np.zeros(3))
    plant.set_offsets({"delta_swing_hip_pitch": 0.0})
    inputs = plant.regulator_inputs()
    assert set(inputs) == {"vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index"}
    assert isinstance(inputs["step_index"], int)
    before = list(plant.telemetry())
    plant.advance(10)
    assert list(plant.telemetry()) == before
    _signals_are_inputs_then_telemetry(plant)
    plant.set_offset_values([0.01, -0.02, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError):
        plant.set_offset_values([0.0] * 5)  # all six or none
    with pytest.raises((TypeError, ValueError)):
        plant.set_offset_values([0.0, "x", 0.0, 0.0, 0.0, 0.0])
    plant.advance(10)
    _signals_are_inputs_then_telemetry(plant)
    assert plant.fell() is False and plant.fall_reason is None
    plant.close()
    plant.close()
    return before


def _signals_are_inputs_then_telemetry(plant) -> None:
    """``signals()`` is the regulator inputs' values then the telemetry's, the same numbers."""
    signals = plant.signals()
    assert signals == (*plant.regulator_inputs().values(), *plant.telemetry().values())
    assert len(signals) == len(REGULATOR_INPUT_NAMES) + len(TELEMETRY_NAMES)
    assert list(plant.regulator_inputs()) == list(REGULATOR_INPUT_NAMES)
    assert list(plant.telemetry()) == list(TELEMETRY_NAMES)


@pytest.mark.parametrize("controller", ["python", "native"])
def test_the_walker_takes_six_finite_offsets_in_order(controller):
    from plant.constants import OFFSET_NAMES
    from plant.model import load_model
    from plant.sim import CassieWalker

    walker = CassieWalker(load_model("menagerie"), controller=controller)

    def held():
        if controller == "python":
            return [walker.controller.offsets[n] for n in OFFSET_NAMES]
        return list(walker.controller._mem.offsets)  # the C controller's memory

    values = [0.01 * (i + 1) for i in range(len(OFFSET_NAMES))]
    walker.set_offset_values(values)
    assert held() == values
    with pytest.raises(ValueError, match="delta_swing_knee must be finite"):
        walker.set_offset_values([0.0, math.nan, 0.0, 0.0, 0.0, 0.0])
    assert held() == values  # none set
    with pytest.raises(ValueError):
        walker.set_offset_values(values[:5])
    assert held() == values


@pytest.mark.parametrize("controller", ["python", "native"])
def test_the_in_process_walker_is_a_plant(controller):
    from plant.model import load_model
    from plant.sim import CassieWalker

    walker = CassieWalker(load_model("menagerie"), controller=controller)
    assert protocol_problems(walker) == []
    _drive(walker)


def test_the_plant_fmu_adapter_is_a_plant(tmp_path_factory, build_module, tmp_path):
    from scenarios.cosim.plant_fmu import FmuPlant

    fmu = built_plant_fmu(tmp_path_factory, build_module)
    plant = FmuPlant(fmu, {}, unpack_dir=tmp_path)
    try:
        assert protocol_problems(plant) == []
        keys = _drive(plant)
    finally:
        plant.close()
    assert list(tmp_path.iterdir()) == []  # close removed the extracted FMU
    from plant.model import load_model
    from plant.sim import CassieWalker

    # the master's tel_ columns come from the first telemetry: the same keys, in the same order
    assert keys == list(CassieWalker(load_model("menagerie")).telemetry())


def test_the_command_and_the_gait_speed_have_their_own_names():
    """``vx_des``/``vy_des``/``yaw_rate_des`` are the command everywhere (the FMUs' inputs, the
    walker, the controller); the controller's rate-limited gait speed is ``vx_ref``/``vy_ref``/
    ``yaw_rate_ref``."""
    from plant.model import load_model
    from plant.sim import CassieWalker

    walker = CassieWalker(load_model("menagerie"))
    walker.set_command(1.0, 0.2, 0.3)
    walk_s = walker.params.stand_time_s + walker.params.shift_time_s + 0.2  # 0.2 s into walking
    walker.advance(int(round(walk_s / walker.SIM_DT_S)))
    c = walker.controller
    assert (walker.vx_des, walker.vy_des, walker.yaw_rate_des) == (1.0, 0.2, 0.3)
    assert (c.vx_des, c.vy_des, c.yaw_rate_des) == (1.0, 0.2, 0.3)
    assert 0.0 < c.vx_ref < 1.0 and 0.0 < c.vy_ref < 0.2 and 0.0 < c.yaw_rate_ref < 0.3  # on their way
    state = walker.get_state()
    assert {"vx_des", "vy_des", "yaw_rate_des"} <= set(state["walker"])
    assert {"vx_des", "vx_ref", "vy_des", "vy_ref", "yaw_rate_des", "yaw_rate_ref"} <= set(state["controller"])
