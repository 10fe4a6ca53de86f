"""The regulator slave's set_real, in process: the fast path for in-range Real inputs stores
exactly what the generic path stores, and every other call takes the generic path, which
checks value by value (the C guard checks first inside the FMU; this is the slave's own
line of defence)."""
import math

import pytest

from fmu_src.regulator_fmu.avr_slave import AdaptiveVelocityRegulator, FmiCallError
from fmu_src.core.avr_specs import INPUT_SPECS

H = 0.005
REAL_INPUTS = [spec for spec in INPUT_SPECS if spec.type == "Real"]


def _slave():
    s = AdaptiveVelocityRegulator(instance_name="unit")
    s.setup_experiment(0.0)
    s.enter_initialization_mode()
    s.exit_initialization_mode()
    return s


def _vr(slave, name):
    return next(vr for vr, (var, _) in enumerate(slave._by_vr) if var == name)


def test_fast_path_stores_what_the_generic_path_stores():
    fast, generic = _slave(), _slave()
    vrs = [_vr(fast, spec.name) for spec in REAL_INPUTS]
    for values in ([spec.min for spec in REAL_INPUTS], [spec.max for spec in REAL_INPUTS],
                   [0.1 * (k + 1) for k in range(len(REAL_INPUTS))], [-0.0] * len(REAL_INPUTS)):
        fast.set_real(vrs, values)
        generic._set_many(vrs, values, "Real")
        assert fast._values == generic._values
        assert all(math.copysign(1.0, fast._values[s.name]) == math.copysign(1.0, v)
                   for s, v in zip(REAL_INPUTS, values))


@pytest.mark.parametrize("bad", [math.nan, math.inf, 1e6])
def test_an_illegal_value_is_refused_by_the_generic_path(bad):
    s = _slave()
    vx, vy = _vr(s, "vx"), _vr(s, "vy")
    with pytest.raises(FmiCallError, match="vy"):
        s.set_real([vx, vy], [0.2, bad])


def test_ints_outputs_and_parameters_take_the_generic_path():
    s = _slave()
    s.set_real([_vr(s, "vx")], [1])  # an int: legal, stored as a float
    assert s._values["vx"] == 1.0 and type(s._values["vx"]) is float
    s.set_real([_vr(s, "vx"), _vr(s, "Kp_x")], [0.3, 0.25])  # a tunable parameter in the batch
    assert s._values["Kp_x"] == 0.25 and s._params.Kp_x == 0.25  # _store refreshed the params
    with pytest.raises(FmiCallError, match="output"):
        s.set_real([_vr(s, "vx"), _vr(s, "psi_x")], [0.3, 0.0])


def test_nothing_is_set_after_terminate():
    s = _slave()
    assert s.do_step(0.0, H)
    s.terminate()
    with pytest.raises(FmiCallError, match="fmi2Terminate"):
        s.set_real([_vr(s, "vx")], [0.2])
    assert s._values["vx"] == 0.0


def test_a_subclass_with_rules_of_its_own_has_every_value_checked():
    class Stricter(AdaptiveVelocityRegulator):
        def _value_problem(self, spec, value):
            return "vx above 1" if spec.name == "vx" and value > 1.0 else super()._value_problem(spec, value)

    plain, strict = AdaptiveVelocityRegulator(instance_name="plain"), Stricter(instance_name="strict")
    assert plain._real_inputs and not strict._real_inputs
    # the fast path's bounds are finite: inf and nan can never pass them
    assert all(map(math.isfinite, [b for _, lo, hi in plain._real_inputs.values() for b in (lo, hi)]))
    with pytest.raises(FmiCallError, match="vx above 1"):
        strict.set_real([_vr(strict, "vx")], [2.0])
