"""Unit and property tests of the numpy-only regulator core (fmu_src/core/avr_core.py).

Most tests use small networks (n_neurons 40..200) to stay fast; what they check does
not depend on the size.  Exact (==) comparisons are used wherever the core promises
bit-exact behaviour (PD path, determinism, purity, serialisation); tolerances elsewhere
are justified where they appear.
"""
import dataclasses
import math
import re
import struct
import zlib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fmu_src.core import avr_statebytes
from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_JOINTS, OUTPUT_SPECS, PARAM_SPECS
from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams, validate_inputs, validate_params
from fmu_src.core.avr_regulator import RegulatorState, initial_state, step
from fmu_src.core.avr_network import build_networks, lif_gain_bias
from fmu_src.core.avr_statebytes import state_from_bytes, state_to_bytes
from fmu_src.core.avr_errors import InputError, ParameterError, StateError
from fmu_src.core.reference.rates import network_inputs, neuron_rates
from fmu_src.core.avr_network import TAU_RC, TAU_REF
from fmu_src.core.avr_params import network_key
from fmu_src.core.avr_regulator import MAX_CALLS

DT = 0.005
HYP = settings(derandomize=True, deadline=None, max_examples=40,
               suppress_health_check=[HealthCheck.too_slow])


#: The paper's plain rule: the remedy against drift (leakage) off.
PLAIN = dict(leakage_per_s=0.0)


def small(**changes) -> RegulatorParams:
    """A small network that learns from the first call (learn_from_step=0) with the paper's
    plain rule (remedies off unless given): the learning tests drive step_index freely; the
    gate and each remedy have tests of their own."""
    changes.setdefault("learn_from_step", 0)
    for name, value in PLAIN.items():
        changes.setdefault(name, value)
    return RegulatorParams(n_neurons=changes.pop("n_neurons", 60), **changes)


def clip(v, limit):
    """The offsets' safety bound, written out: +-delta_limit_rad."""
    return min(max(v, -limit), limit)


def classic_pd(params, seq):
    """The classic PD regulator, written out independently of the core (offsets clipped to
    +-delta_limit_rad)."""
    outs, last, vxp, vyp, pdx, pdy = [], None, None, None, None, None
    for u in seq:
        if u.step_index != last:
            vxp = u.vx if last is None else vxp
            vyp = u.vy if last is None else vyp
            pdx = params.Kp_x * (u.vx - u.vx_des) + params.Kd_x * (u.vx - vxp)
            pdy = params.Kp_y * (u.vy - u.vy_des) + params.Kd_y * (u.vy - vyp)
            vxp, vyp, last = u.vx, u.vy, u.step_index
        lim = params.delta_limit_rad
        outs.append({
            "delta_swing_hip_pitch": clip(pdx, lim),
            "delta_swing_knee": 0.0,
            "delta_swing_hip_roll": clip(pdy, lim),
            "delta_stance_hip_roll": clip(params.Kp_roll * (u.roll - params.roll_des)
                                          + params.Kd_roll * u.roll_rate, lim),
            "delta_stance_hip_pitch": clip(params.Kp_pitch * (u.pitch - params.pitch_des)
                                           + params.Kd_pitch * u.pitch_rate, lim),
            "delta_stance_knee": 0.0,
        })
    return outs


#: The Real inputs' declared ranges, in RegulatorInputs order: random walks stay inside them.
INPUT_LO = np.array([s.min for s in INPUT_SPECS if s.type == "Real"])
INPUT_HI = np.array([s.max for s in INPUT_SPECS if s.type == "Real"])


def random_inputs(rng, n, steps_every=7, scale=1.0):
    seq, walk = [], np.zeros(8)
    for k in range(n):
        walk = np.clip(walk + rng.normal(0.0, 0.05 * scale, 8), INPUT_LO, INPUT_HI)
        seq.append(RegulatorInputs(*map(float, walk), step_index=k // steps_every))
    return seq


def run(reg_or_state, seq, params=None, nets=None, dt=DT):
    if isinstance(reg_or_state, Regulator):
        return [reg_or_state.step(u, dt) for u in seq]
    state, outs = reg_or_state, []
    for u in seq:
        state, out = step(state, u, dt, params, nets)
        outs.append(out)
    return state, outs


# ------------------------------------------------------------------------------ specs
def test_specs_match_dataclasses_and_api_order():
    assert [s.name for s in PARAM_SPECS] == [
        "Kp_x", "Kd_x", "Kp_y", "Kd_y", "Kp_pitch", "Kd_pitch", "Kp_roll", "Kd_roll",
        "pitch_des", "roll_des", "learning_rate", "psi_limit", "learn_from_step",
        "psi_gain_swing_hip_pitch", "psi_gain_swing_knee", "psi_gain_swing_hip_roll",
        "psi_gain_stance_hip_roll", "psi_gain_stance_hip_pitch", "psi_gain_stance_knee",
        "adaptation_enabled", "velocity_scale_mps", "angle_scale_rad",
        "rate_scale_radps", "n_neurons", "seed", "delta_limit_rad",
        "leakage_per_s", "leakage_mode", "command_accel_limit_mps2", "learn_settled_steps",
        "learn_ramp_max_mps2"]
    assert [f.name for f in dataclasses.fields(RegulatorParams)] == [s.name for s in PARAM_SPECS]
    p = RegulatorParams()
    for s in PARAM_SPECS:
        assert getattr(p, s.name) == s.default and s.causality == "parameter"
        assert s.variability in ("tunable", "fixed") and s.description
        if s.type != "Boolean":
            assert s.min <= s.default <= s.max
            assert f"{s.min:g}" in s.description or s.name == "seed"
    assert [f.name for f in dataclasses.fields(RegulatorInputs)] == [s.name for s in INPUT_SPECS]
    assert [s.name for s in INPUT_SPECS] == ["vx", "vy", "vx_des", "vy_des", "pitch",
                                             "roll", "pitch_rate", "roll_rate", "step_index"]
    names = [s.name for s in OUTPUT_SPECS]
    assert names == [f"delta_{j}" for j in OUTPUT_JOINTS] + [
        "psi_x", "psi_y", "psi_pitch", "psi_roll",
        "error_vx", "error_vy", "error_pitch", "error_roll"]
    # start values are what step outputs for all-zero inputs at the start
    reg = Regulator(small())
    out = reg.step(RegulatorInputs(), DT)
    assert list(out) == names
    assert all(out[s.name] == s.default == 0.0 for s in OUTPUT_SPECS)
    assert all(type(v) is float for v in out.values())


# ------------------------------------------------------------------------- params
def test_params_report_every_problem_with_field_and_range():
    with pytest.raises(ParameterError) as exc:
        RegulatorParams(Kp_x=math.nan, Kd_y=7.0, learning_rate=-1.0, psi_limit="x",
                        adaptation_enabled=1, n_neurons=0, seed=2**31, angle_scale_rad=0.0,
                        psi_gain_swing_knee=math.inf)
    problems = exc.value.problems
    assert problems == [
        "Kp_x = nan: must be a finite number in [-5, 5]",
        "Kd_y = 7.0: must be a finite number in [-5, 5]",
        "learning_rate = -1.0: must be a finite number in [0, 0.001]",
        "psi_limit = 'x': must be a finite number in [0, 1]",
        "psi_gain_swing_knee = inf: must be a finite number in [-5, 5]",
        "adaptation_enabled = 1: must be a bool (true/false)",
        "angle_scale_rad = 0.0: must be a finite number in [0.01, 3.2]",
        "n_neurons = 0: must be an integer in [1, 10000]",
        "seed = 2147483648: must be an integer in [0, 2147483647]",
    ]
    assert str(exc.value) == "; ".join(problems)


def test_params_types_are_normalised_and_bools_are_not_numbers():
    p = RegulatorParams(Kp_x=1, n_neurons=np.int64(10), adaptation_enabled=np.bool_(False))
    assert type(p.Kp_x) is float and type(p.n_neurons) is int
    assert p.adaptation_enabled is False
    with pytest.raises(ParameterError, match=r"Kp_x = True: must be a finite number"):
        RegulatorParams(Kp_x=True)
    with pytest.raises(ParameterError, match=r"n_neurons = 10.0: must be an integer"):
        RegulatorParams(n_neurons=10.0)


def test_an_integer_beyond_float_range_is_a_parameter_problem_not_a_crash():
    """float(10**400) overflows: the check once let that OverflowError escape."""
    with pytest.raises(ParameterError) as exc:
        RegulatorParams(Kp_x=10**400, psi_limit=-(10**400))
    assert [p.split(": ", 1)[1] for p in exc.value.problems] == [
        "must be a finite number in [-5, 5]", "must be a finite number in [0, 1]"]
    with pytest.raises(InputError, match=r"vx = 1000.*: must be a finite number in \[-10, 10\] \(m/s\)"):
        validate_inputs(RegulatorInputs(vx=10**400))


def test_replace_validates_and_names_unknown_fields():
    p = RegulatorParams()
    q = p.replace(Kp_x=0.5)
    assert q.Kp_x == 0.5 and p.Kp_x == 0.1 and q.Kd_x == p.Kd_x
    with pytest.raises(ParameterError) as exc:
        p.replace(Kp_y=99, bogus=1)
    assert len(exc.value.problems) == 2
    assert exc.value.problems[0].startswith("bogus: unknown parameter")
    assert exc.value.problems[1] == "Kp_y = 99: must be a finite number in [-5, 5]"
    validate_params(q)
    # validate_params also catches an object corrupted behind the dataclass' back
    object.__setattr__(q, "psi_limit", -1.0)
    with pytest.raises(ParameterError, match=r"psi_limit = -1.0: .* \[0, 1\]"):
        validate_params(q)
    with pytest.raises(ParameterError):
        validate_params({"Kp_x": 1.0})


@HYP
@given(data=st.data())
def test_property_in_range_accepted_out_of_range_rejected(data):
    specs = [s for s in PARAM_SPECS if s.type == "Real"]
    spec = data.draw(st.sampled_from(specs))
    ok = data.draw(st.floats(spec.min, spec.max))
    # the one rule between parameters holds (learn_ramp_max_mps2 needs learn_settled_steps)
    assert getattr(RegulatorParams(**{spec.name: ok, "learn_settled_steps": 1}), spec.name) == ok
    bad = data.draw(st.one_of(
        st.floats(max_value=spec.min, exclude_max=True),
        st.floats(min_value=spec.max, exclude_min=True),
        st.just(math.nan)))
    with pytest.raises(ParameterError) as exc:
        RegulatorParams(**{spec.name: bad})
    (msg,) = exc.value.problems
    assert msg.startswith(f"{spec.name} = ") and "must be a finite number in [" in msg


# ------------------------------------------------------------------------- inputs
@pytest.mark.parametrize("name", [s.name for s in INPUT_SPECS if s.type == "Real"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "1.0", None, True])
def test_non_finite_inputs_are_rejected_by_name(name, bad):
    u = dataclasses.replace(RegulatorInputs(), **{name: bad})
    with pytest.raises(InputError, match=rf"^{name} = "):
        validate_inputs(u)
    reg = Regulator(small())
    before = reg.state
    with pytest.raises(InputError, match=rf"^{name} = "):
        reg.step(u, DT)
    assert reg.state is before


@pytest.mark.parametrize("spec", [s for s in INPUT_SPECS if s.type == "Real"], ids=lambda s: s.name)
def test_inputs_outside_their_declared_range_are_rejected_naming_it(spec):
    """Every Real input has a physical range; vx = 1e308 used to give a 1e307 rad offset."""
    assert spec.min is not None and spec.max is not None and spec.min < 0.0 < spec.max
    reg = Regulator(small())
    before = reg.state
    expected = re.escape(f"must be a finite number in [{spec.min:g}, {spec.max:g}]")
    for bad in (1e308, -1e308, math.nextafter(spec.max, math.inf), math.nextafter(spec.min, -math.inf)):
        u = dataclasses.replace(RegulatorInputs(), **{spec.name: bad})
        with pytest.raises(InputError, match=rf"^{spec.name} = .*{expected}"):
            reg.step(u, DT)
    assert reg.state is before  # a refused call changes nothing
    for edge in (spec.min, spec.max):  # the bounds themselves are legal
        reg.step(dataclasses.replace(RegulatorInputs(), **{spec.name: edge}), DT)


def test_joint_offsets_are_clipped_to_the_tunable_delta_limit():
    u = RegulatorInputs(vx=9.0, vx_des=-9.0, vy=-9.0, vy_des=9.0, pitch=3.0, roll=-3.0,
                        pitch_rate=90.0, roll_rate=-90.0, step_index=1)
    p = small(adaptation_enabled=False, Kp_x=5.0, Kp_y=5.0, Kp_pitch=5.0, Kp_roll=5.0)
    assert p.delta_limit_rad == 1.0  # the documented default
    signs = {"swing_hip_pitch": 1.0, "swing_hip_roll": -1.0, "stance_hip_roll": -1.0,
             "stance_hip_pitch": 1.0, "swing_knee": 0.0, "stance_knee": 0.0}
    for limit in (1.0, 0.25, math.pi):
        out = Regulator(p.replace(delta_limit_rad=limit)).step(u, DT)
        assert {j: out[f"delta_{j}"] for j in signs} == {j: s * limit for j, s in signs.items()}
    out = Regulator(p.replace(delta_limit_rad=0.0)).step(u, DT)
    assert all(math.copysign(1.0, out[f"delta_{j}"]) == 1.0 and out[f"delta_{j}"] == 0.0 for j in signs)
    # the networks' outputs are bounded too (psi saturated at 1 rad, gain 5 -> 5 rad before the clip)
    learner = Regulator(small(psi_limit=1.0, learning_rate=1e-3, psi_gain_swing_knee=5.0))
    outs = run(learner, [RegulatorInputs(vx=9.0, vx_des=-9.0, step_index=k) for k in range(400)])
    assert outs[-1]["psi_x"] == 1.0 and outs[-1]["delta_swing_knee"] == 1.0


def test_delta_limit_inside_the_bound_changes_nothing_bit_for_bit():
    seq = random_inputs(np.random.default_rng(4), 200)
    a = run(Regulator(small(learning_rate=2e-4)), seq)
    b = run(Regulator(small(learning_rate=2e-4, delta_limit_rad=math.pi)), seq)
    assert max(abs(o[f"delta_{j}"]) for o in a for j in OUTPUT_JOINTS) < 1.0  # never clipped here
    assert a == b


@pytest.mark.parametrize("bad", [-1, 1.0, True, "3", 2**31])
def test_bad_step_index_rejected(bad):
    with pytest.raises(InputError, match=r"^step_index = .*integer in \[0, 2147483647\]"):
        validate_inputs(RegulatorInputs(step_index=bad))


@pytest.mark.parametrize("bad", [0.0, -0.005, math.nan, math.inf, "0.01", None, True])
def test_bad_dt_rejected(bad):
    reg = Regulator(small())
    with pytest.raises(InputError, match=r"^dt = "):
        reg.step(RegulatorInputs(), bad)


def test_numpy_and_int_inputs_are_accepted_and_outputs_are_python_floats():
    reg = Regulator(small())
    out = reg.step(RegulatorInputs(vx=np.float64(0.5), vy=1, step_index=np.int32(3)), 1)
    assert all(type(v) is float for v in out.values())
    assert reg.state.last_step_index == 3 and type(reg.state.last_step_index) is int


# ----------------------------------------------------------------------- networks
def test_same_seed_same_networks_and_outputs_different_seed_differs():
    a, b = Regulator(small(seed=7)), Regulator(small(seed=7))
    c = Regulator(small(seed=8))
    for na, nb, nc in zip(a.networks, b.networks, c.networks):
        for f in ("encoders", "gain", "bias", "max_rates", "intercepts"):
            assert np.array_equal(getattr(na, f), getattr(nb, f))
        assert not np.allclose(na.encoders, nc.encoders)
    # each network gets its own stream (same-shaped nets are not copies)
    assert not np.allclose(a.networks.longitudinal.encoders, a.networks.lateral.encoders)
    seq = random_inputs(np.random.default_rng(0), 120)
    outs_a, outs_b, outs_c = run(a, seq), run(b, seq), run(c, seq)
    assert outs_a == outs_b  # bit-exact
    assert outs_a != outs_c
    assert a.state == b.state


def test_network_construction_follows_nef_conventions():
    nets = build_networks(small(n_neurons=500, seed=3))
    for net, d in zip(nets, (2, 2, 4)):
        assert net.encoders.shape == (500, d)
        # unit encoders; 1e-15 ~ a few ulps of the norm computation
        np.testing.assert_allclose(np.linalg.norm(net.encoders, axis=1), 1.0, atol=1e-15)
        assert np.all((net.max_rates >= 200) & (net.max_rates < 400))
        assert np.all((net.intercepts >= -1.0) & (net.intercepts < 0.9))
        assert not net.encoders.flags.writeable and not net.gain.flags.writeable
        # rate is max_rate along the encoder (x = e, e.x = 1) and 0 at the intercept;
        # rtol 1e-12 covers the rounding of gain/bias and of the LIF rate formula
        i = np.arange(20)
        along = np.array([neuron_rates(net, net.encoders[k])[k] for k in i])
        np.testing.assert_allclose(along, net.max_rates[i], rtol=1e-12)
        at_c = np.array([neuron_rates(net, net.intercepts[k] * net.encoders[k])[k] for k in i])
        # J = 1 up to rounding (j ~ 1e-15); the LIF curve leaves 0 only logarithmically,
        # 1 / (tau_rc ln(1e15)) ~ 1.5 Hz, so "about 0" here means < 2 Hz
        assert np.all(at_c < 2.0)
        below = np.array([neuron_rates(net, (net.intercepts[k] - 0.01) * net.encoders[k])[k]
                          for k in i])
        assert np.all(below == 0.0)


def test_lif_gain_bias_analytic_curve():
    m, c = np.array([200.0, 333.0, 399.9]), np.array([-0.99, 0.0, 0.89])
    gain, bias = lif_gain_bias(m, c)
    j = gain * 1.0 + bias - 1.0
    rate = 1.0 / (TAU_REF + TAU_RC * np.log1p(1.0 / j))
    np.testing.assert_allclose(rate, m, rtol=1e-12)  # a few ulps through log1p/expm1
    np.testing.assert_allclose(gain * c + bias, 1.0, rtol=1e-15, atol=1e-15)
    with pytest.raises(ValueError):
        lif_gain_bias([500.0], [0.0])  # >= 1/tau_ref
    with pytest.raises(ValueError):
        lif_gain_bias([300.0], [1.0])


def test_network_inputs_are_scaled_and_radially_projected():
    p = small(velocity_scale_mps=2.0, angle_scale_rad=0.5, rate_scale_radps=4.0)
    xl, xy, xt = network_inputs(RegulatorInputs(vx=1.0, vx_des=0.5, vy=-0.2, vy_des=0.0,
                                                pitch=0.1, roll=0.0, pitch_rate=-0.4,
                                                roll_rate=0.8), p)
    assert xl.tolist() == [0.5, 0.25] and xy.tolist() == [-0.1, 0.0]
    assert xt.tolist() == [0.2, 0.0, -0.1, 0.2]
    xl, _, xt = network_inputs(RegulatorInputs(vx=6.0, vx_des=8.0, pitch=3.0), p)
    np.testing.assert_allclose(xl, [0.6, 0.8], rtol=1e-15)  # direction kept, norm 1
    np.testing.assert_allclose(xt, [1.0, 0.0, 0.0, 0.0], rtol=1e-15)


# ---------------------------------------------------------------------- PD path
def test_adaptation_off_is_exactly_the_classic_pd():
    p = small(adaptation_enabled=False, Kp_pitch=0.3, Kd_pitch=0.02, Kp_roll=-0.4,
              Kd_roll=0.05, pitch_des=0.05, roll_des=-0.02, Kp_x=0.7, Kd_x=-0.1)
    seq = random_inputs(np.random.default_rng(11), 300)
    outs = run(Regulator(p), seq)
    for got, want in zip(outs, classic_pd(p, seq)):
        for k, v in want.items():
            assert got[k] == v, k  # exact: same arithmetic, no network term
        assert got["psi_x"] == got["psi_y"] == got["psi_pitch"] == got["psi_roll"] == 0.0


@HYP
@given(seed=st.integers(0, 2**31 - 1), steps_every=st.integers(1, 9),
       scale=st.floats(0.01, 20.0))
def test_property_adaptation_off_equals_pd(seed, steps_every, scale):
    p = small(adaptation_enabled=False, Kp_roll=0.2, Kd_pitch=0.1, n_neurons=5)
    seq = random_inputs(np.random.default_rng(seed), 40, steps_every, scale)
    outs = run(Regulator(p), seq)
    for got, want in zip(outs, classic_pd(p, seq)):
        assert all(got[k] == v for k, v in want.items())


def test_pd_held_between_steps_and_derivative_uses_previous_step_value():
    p = small(adaptation_enabled=False, Kp_x=0.5, Kd_x=0.2, Kp_y=0.3, Kd_y=0.1)
    reg = Regulator(p)
    o = reg.step(RegulatorInputs(vx=1.0, vx_des=0.5, vy=0.2, step_index=4), DT)
    # first call: no derivative kick
    assert o["delta_swing_hip_pitch"] == 0.5 * (1.0 - 0.5)
    assert o["delta_swing_hip_roll"] == 0.3 * 0.2
    # same step_index: held, whatever the velocities do
    o = reg.step(RegulatorInputs(vx=3.0, vx_des=0.0, vy=-1.0, step_index=4), DT)
    assert o["delta_swing_hip_pitch"] == 0.5 * (1.0 - 0.5)
    assert o["delta_swing_hip_roll"] == 0.3 * 0.2
    assert o["error_vx"] == 3.0  # errors are reported every call
    # new step: derivative against the value at the previous step change (1.0, 0.2)
    o = reg.step(RegulatorInputs(vx=0.7, vx_des=0.5, vy=0.1, step_index=5), DT)
    assert o["delta_swing_hip_pitch"] == 0.5 * (0.7 - 0.5) + 0.2 * (0.7 - 1.0)
    assert o["delta_swing_hip_roll"] == 0.3 * 0.1 + 0.1 * (0.1 - 0.2)
    # any change counts, also backwards (e.g. the plant restarted its counter)
    o = reg.step(RegulatorInputs(vx=0.6, vx_des=0.5, step_index=0), DT)
    assert o["delta_swing_hip_pitch"] == 0.5 * (0.6 - 0.5) + 0.2 * (0.6 - 0.7)
    # torso PD is updated every call
    reg.set_params(Kp_pitch=2.0, Kd_roll=1.0)
    o1 = reg.step(RegulatorInputs(pitch=0.1, roll_rate=0.3, step_index=0), DT)
    o2 = reg.step(RegulatorInputs(pitch=0.2, roll_rate=-0.3, step_index=0), DT)
    assert (o1["delta_stance_hip_pitch"], o2["delta_stance_hip_pitch"]) == (2.0 * 0.1, 2.0 * 0.2)
    assert (o1["delta_stance_hip_roll"], o2["delta_stance_hip_roll"]) == (0.3, -0.3)


# -------------------------------------------------------------------- adaptation
def test_first_update_is_the_pes_rule():
    p = small(learning_rate=1e-4, n_neurons=80)
    reg = Regulator(p)
    u = RegulatorInputs(vx=0.4, vx_des=0.1, vy=-0.2, vy_des=0.1, pitch=0.05, roll=-0.03,
                        pitch_rate=0.2, roll_rate=-0.1)
    out = reg.step(u, DT)
    assert out["psi_x"] == 0.0  # output uses the weights from before the update
    xl, xy, xt = network_inputs(u, p)
    hx, hy, ht = (neuron_rates(net, x) for net, x in zip(reg.networks, (xl, xy, xt)))
    a = -p.learning_rate * DT / p.n_neurons
    # y and roll learn from stride means: nothing before two steps are complete
    want = np.array([a * (0.1 - 0.4) * hx, 0.0 * hy, a * (0.0 - 0.05) * ht, 0.0 * ht])
    # The core gets J - 1 from ordered sums with bias - 1 folded in and log1p_fixed, neuron_rates
    # from scaled_encoders @ x + bias - 1 and numpy's log1p: a few ulps apart.  That is ~1e-15 relative
    # for most rates, more just above threshold where the rate rises like
    # 1/ln(1/(J-1)) but is tiny, hence an absolute floor of 1e-12 of the largest value.
    np.testing.assert_allclose(reg.state.weights, want, rtol=1e-12,
                               atol=1e-12 * np.abs(want).max())
    out = reg.step(u, DT)
    np.testing.assert_allclose(out["psi_x"], want[0] @ hx, rtol=1e-12)
    assert out["delta_swing_knee"] == out["psi_x"]  # gain 1, shared row
    np.testing.assert_allclose(out["psi_roll"], want[3] @ ht, rtol=1e-12)


@pytest.mark.parametrize("field_, err_in, psi_out, pd_out, pd_gain", [
    ("vx", dict(vx=0.8, vx_des=0.5), "psi_x", "delta_swing_hip_pitch", "Kp_x"),
    ("vy", dict(vy=-0.3, vy_des=0.0), "psi_y", "delta_swing_hip_roll", "Kp_y"),
    ("pitch", dict(pitch=0.1), "psi_pitch", "delta_stance_hip_pitch", "Kp_pitch"),
    ("roll", dict(roll=-0.08), "psi_roll", "delta_stance_hip_roll", "Kp_roll"),
])
def test_constant_error_drives_psi_with_the_sign_of_the_pd_term(field_, err_in, psi_out,
                                                               pd_out, pd_gain):
    p = small(Kp_pitch=0.5, Kp_roll=0.5, learning_rate=1e-5)
    reg = Regulator(p)
    pd_only = Regulator(p.replace(adaptation_enabled=False))
    # step_index advances every 20 calls; vy and roll learn from the means of the last
    # two complete steps: step 1 (calls 20..39) and step 2 (40..59) are complete at call
    # 60, whose update is the first one, so Psi moves from call 61 on.
    start = 61 if field_ in ("vy", "roll") else 1
    psis = [reg.step(RegulatorInputs(**err_in, step_index=k // 20), DT)[psi_out]
            for k in range(200)]
    u = RegulatorInputs(**err_in, step_index=9)
    pd = pd_only.step(u, DT)[pd_out]
    assert pd != 0.0
    assert all(x == 0.0 for x in psis[:start])
    assert np.all(np.diff(psis[start - 1:]) * np.sign(pd) > 0)  # strictly growing away from 0
    assert np.sign(psis[-1]) == np.sign(pd)
    # and the output is PD + Psi
    out = reg.step(u, DT)
    assert out[pd_out] == pytest.approx(pd + out[psi_out], rel=1e-15, abs=1e-15)


def test_default_learning_speed_matches_documentation():
    """Defaults: a constant 0.3 m/s error moves Psi by ~0.05 rad in ~10 s (dt 5 ms)."""
    reg = Regulator(RegulatorParams(n_neurons=1000, learn_from_step=0))
    for k in range(2000):
        out = reg.step(RegulatorInputs(vx=0.8, vx_des=0.5, step_index=k // 80), DT)
    assert 0.02 < out["psi_x"] < 0.15  # "of the order of 0.05 rad"


def test_saturation_and_anti_windup():
    # Torso pitch: the error E_pitch = pitch_des - pitch can be reversed through
    # pitch_des without moving the network input, so the raw output is comparable.
    lim = 0.1
    reg = Regulator(small(learning_rate=5e-4, psi_limit=lim))
    push = RegulatorInputs(pitch=0.1, pitch_rate=0.2)
    psis = np.array([reg.step(push, DT)["psi_pitch"] for _ in range(100)])
    assert psis.max() == lim and np.all(np.abs(psis) <= lim)
    k_sat = int(np.argmax(psis == lim))
    assert 5 < k_sat < 60 and np.all(np.diff(psis[:k_sat]) > 0)
    w_sat = reg.state.weights[2].copy()
    for _ in range(200):
        o = reg.step(push, DT)
        assert o["psi_pitch"] == o["delta_stance_knee"] == lim
    assert np.array_equal(reg.state.weights[2], w_sat)  # no wind-up while pushed out
    h = neuron_rates(reg.networks.torso, network_inputs(push, reg.params)[2])
    inc = float(psis[1] - psis[0])  # raw change of one update at this error size
    assert lim <= float(w_sat @ h) <= lim + inc * (1 + 1e-9)  # stopped one update past
    # reversing the error leaves saturation after at most two updates (without
    # anti-windup it would take as many calls as it was pushed, ~250)
    reg.set_params(pitch_des=0.2)
    back = [reg.step(push, DT)["psi_pitch"] for _ in range(5)]
    assert back[2] < lim and np.all(np.diff(back[1:]) < 0)
    # only the pitch row learned
    assert np.all(reg.state.weights[[0, 1, 3]] == 0.0)


def test_psi_limit_zero_switches_psi_off_without_wind_up():
    reg = Regulator(small(learning_rate=1e-3, psi_limit=0.0))
    u = RegulatorInputs(vx=1.0)
    outs = [reg.step(u, DT)]
    w1 = reg.state.weights  # raw 0 is not "pushed further out": one update happens
    assert np.any(w1[0] > 0.0)
    outs += [reg.step(u, DT) for _ in range(50)]
    assert reg.state.weights is w1  # then frozen: the row is saturated and pushed out
    assert all(o["psi_x"] == 0.0 and o["delta_swing_knee"] == 0.0 for o in outs)


@pytest.mark.parametrize("joint", OUTPUT_JOINTS)
def test_psi_gain_zero_switches_an_output_off_while_learning_goes_on(joint):
    p = small(learning_rate=1e-4, Kp_x=0, Kd_x=0, Kp_y=0, Kd_y=0,
              **{f"psi_gain_{joint}": 0.0})
    reg, ref = Regulator(p), Regulator(p.replace(**{f"psi_gain_{joint}": 1.0}))
    seq = [RegulatorInputs(vx=0.9, vx_des=0.2, vy=0.3, pitch=0.1, roll=-0.1, pitch_rate=0.5,
                           step_index=k // 10) for k in range(60)]
    for u in seq:
        o, r = reg.step(u, DT), ref.step(u, DT)
        assert o[f"delta_{joint}"] == 0.0 and str(o[f"delta_{joint}"]) == "0.0"
        for k in r:  # every other output is unaffected
            if k != f"delta_{joint}":
                assert o[k] == r[k], k
    assert reg.state == ref.state  # learning is independent of the gain
    assert r[f"delta_{joint}"] != 0.0


def test_negative_psi_gain_flips_the_contribution():
    p = small(learning_rate=1e-4, psi_gain_swing_knee=-2.0)
    reg = Regulator(p)
    for _ in range(20):
        o = reg.step(RegulatorInputs(vx=0.9), DT)
    assert o["delta_swing_knee"] == -2.0 * o["psi_x"] != 0.0


def test_toggling_adaptation_keeps_the_weights():
    p = small(learning_rate=1e-4)
    seq = random_inputs(np.random.default_rng(5), 200)
    a, b = Regulator(p), Regulator(p)
    run(a, seq[:100])
    run(b, seq[:100])
    w = a.state.weights
    a.set_params(adaptation_enabled=False)
    outs_off = run(a, seq[100:150])
    assert a.state.weights is w  # not updated (and nothing copied)
    assert all(o["psi_x"] == 0.0 for o in outs_off)
    a.set_params(adaptation_enabled=True)
    oa, ob = a.step(seq[150], DT), b.step(seq[150], DT)
    for k in ("psi_x", "psi_y", "psi_pitch", "psi_roll"):
        assert oa[k] == ob[k] != 0.0  # resumes from the very same weights
    # x and pitch learn from this call's error: the same update.  The y and roll rows
    # learn from stride means, which kept advancing in `a` while adaptation was off.
    np.testing.assert_array_equal(a.state.weights[[0, 2]], b.state.weights[[0, 2]])
    assert a.state.stride_boundaries == 4 and a.state.vy_mean_last != b.state.vy_mean_last


def test_learning_rate_zero_freezes_weights_but_keeps_psi():
    reg = Regulator(small(learning_rate=1e-4))
    run(reg, [RegulatorInputs(vx=0.5)] * 20)
    w = reg.state.weights
    reg.set_params(learning_rate=0.0)
    o = reg.step(RegulatorInputs(vx=0.5), DT)
    assert reg.state.weights is w and o["psi_x"] > 0.0


# --------------------------------------------------------------- purity and state
def test_step_is_pure():
    p = small(learning_rate=1e-4)
    nets = build_networks(p)
    s0 = initial_state(p, nets)
    s1, _ = run(s0, random_inputs(np.random.default_rng(1), 30), p, nets)
    blob = state_to_bytes(s1)
    w_copy = s1.weights.copy()
    u = RegulatorInputs(vx=0.3, vy=0.1, pitch=0.02, step_index=99)
    s2, o2 = step(s1, u, DT, p, nets)
    s2b, o2b = step(s1, u, DT, p, nets)
    assert state_to_bytes(s1) == blob and np.array_equal(s1.weights, w_copy)
    assert o2 == o2b and s2 == s2b and s2 is not s1
    assert s2.n_calls == s1.n_calls + 1 and s2.time_s == s1.time_s + DT
    with pytest.raises(ValueError):
        s1.weights[0, 0] = 1.0  # read-only
    with pytest.raises(dataclasses.FrozenInstanceError):
        s1.pd_x = 1.0
    # the state copies writeable arrays given to it
    w = np.ones((4, 60))
    s = RegulatorState(w)
    w[0, 0] = 5.0
    assert s.weights[0, 0] == 1.0
    assert s.weights_x.shape == (2, 60) and s.weights_torso.shape == (3, 60)


def test_state_round_trip_is_bit_exact_and_continues_identically():
    p = small(learning_rate=1e-4, n_neurons=100)
    nets = build_networks(p)
    seq = random_inputs(np.random.default_rng(2), 200)
    s, _ = run(initial_state(p, nets), seq[:120], p, nets)
    blob = state_to_bytes(s)
    assert state_to_bytes(s) == blob  # deterministic
    r = state_from_bytes(blob, p)
    assert r == s and state_to_bytes(r) == blob
    assert r.weights.tobytes() == s.weights.tobytes()
    end_a, outs_a = run(s, seq[120:], p, nets)
    end_b, outs_b = run(r, seq[120:], p, nets)
    assert outs_a == outs_b and end_a == end_b
    # also through a fresh Regulator built from the same params
    reg = Regulator(p)
    reg.load_state(blob)
    assert run(reg, seq[120:]) == outs_a
    # and through bytearray / memoryview
    assert state_from_bytes(bytearray(blob), p) == s
    assert state_from_bytes(memoryview(blob), p) == s


@HYP
@given(w=st.lists(st.floats(-1e3, 1e3), min_size=4 * 7, max_size=4 * 7),
       last=st.integers(0, 2**31 - 1), n_calls=st.integers(0, MAX_CALLS),
       scalars=st.lists(st.floats(-1e6, 1e6), min_size=5, max_size=5))
def test_property_any_state_round_trips(w, last, n_calls, scalars):
    """Any state a run can reach (before the first call: last_step_index -1 and time 0)."""
    p = RegulatorParams(n_neurons=7, seed=123)
    s = RegulatorState(np.array(w).reshape(4, 7), last if n_calls else -1, *scalars[:4], n_calls,
                       abs(scalars[4]) if n_calls else 0.0, network_key(p))
    r = state_from_bytes(state_to_bytes(s), p)
    assert r == s and state_to_bytes(r) == state_to_bytes(s)


def _recrc(body: bytes) -> bytes:
    return body + struct.pack("<I", zlib.crc32(body))


@pytest.mark.parametrize("case", ["magic", "version", "rows", "short", "long", "crc",
                                  "n_neurons", "seed", "scale", "nan", "counter",
                                  "type", "empty"])
def test_bad_blobs_raise_state_error(case):
    p = small(learning_rate=1e-4)
    reg = Regulator(p)
    run(reg, random_inputs(np.random.default_rng(0), 10))
    blob = state_to_bytes(reg.state)
    body = blob[:-4]
    h = avr_statebytes._HEADER
    fields_ = list(h.unpack_from(body))
    if case == "magic":
        bad = _recrc(b"NOTSTATE" + body[8:])
    elif case == "version":
        fields_[1] = 99
        bad = _recrc(h.pack(*fields_) + body[h.size:])
    elif case == "rows":
        fields_[2] = 7
        bad = _recrc(h.pack(*fields_) + body[h.size:])
    elif case == "short":
        bad = blob[:-9]
    elif case == "long":
        bad = blob + b"\0"
    elif case == "crc":
        bad = bytearray(blob)
        bad[h.size + 5] ^= 0x01
        bad = bytes(bad)
    elif case == "n_neurons":
        bad = blob
        p = p.replace(n_neurons=61)
    elif case == "seed":
        bad = blob
        p = p.replace(seed=1)
    elif case == "scale":
        bad = blob
        p = p.replace(rate_scale_radps=3.0)
    elif case == "nan":
        w = np.frombuffer(body, "<f8", offset=h.size).copy()
        w[3] = math.nan
        bad = _recrc(body[:h.size] + w.tobytes())
    elif case == "counter":
        fields_[9] = -2
        bad = _recrc(h.pack(*fields_) + body[h.size:])
    elif case == "type":
        bad = "not bytes"
    else:
        bad = b""
    with pytest.raises(StateError):
        state_from_bytes(bad, p)


def test_regulator_rejects_changing_fixed_parameters():
    reg = Regulator(small())
    with pytest.raises(ParameterError, match=r"n_neurons = 10: fixed parameter"):
        reg.set_params(n_neurons=10, Kp_x=1.0)
    assert reg.params.Kp_x == 0.1
    reg.set_params(seed=reg.params.seed, Kp_x=1.0)  # unchanged fixed values are fine
    assert reg.params.Kp_x == 1.0
    run(reg, [RegulatorInputs(vx=1.0)] * 5)
    reg.reset()
    assert reg.state == initial_state(reg.params, reg.networks)


@HYP
@given(seed=st.integers(0, 2**31 - 1), scale=st.floats(0.1, 100.0),
       lr=st.floats(0.0, 1e-3), lim=st.floats(0.0, 1.0))
def test_property_outputs_finite_and_psi_bounded(seed, scale, lr, lim):
    p = small(n_neurons=30, learning_rate=lr, psi_limit=lim, seed=seed % 1000)
    outs = run(Regulator(p), random_inputs(np.random.default_rng(seed), 60, 3, scale))
    for o in outs:
        assert all(math.isfinite(v) for v in o.values())
        assert all(abs(o[k]) <= lim for k in ("psi_x", "psi_y", "psi_pitch", "psi_roll"))


@HYP
@given(gains=st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6),
       seed=st.integers(0, 1000))
def test_property_outputs_compose_pd_and_gained_psi(gains, seed):
    """Every output is its PD term plus its psi gain times the (shared) network output.

    The PD terms come from a twin with adaptation off; rtol/atol 1e-15 absorb the single
    rounding of the final additions (values are O(1) rad)."""
    changes = {f"psi_gain_{j}": g for j, g in zip(OUTPUT_JOINTS, gains)}
    p = small(n_neurons=30, learning_rate=2e-4, Kp_pitch=0.3, Kd_roll=0.1, **changes)
    reg, pd = Regulator(p), Regulator(p.replace(adaptation_enabled=False))
    g = dict(zip(OUTPUT_JOINTS, gains))
    for u in random_inputs(np.random.default_rng(seed), 30, 4):
        o, d = reg.step(u, DT), pd.step(u, DT)
        # (the twin's PD terms stay far below delta_limit_rad for these small inputs, so d
        # is unclipped; the sum is clipped like the core's output)
        want = {
            "swing_hip_pitch": d["delta_swing_hip_pitch"] + g["swing_hip_pitch"] * o["psi_x"],
            "swing_knee": g["swing_knee"] * o["psi_x"],
            "swing_hip_roll": d["delta_swing_hip_roll"] + g["swing_hip_roll"] * o["psi_y"],
            "stance_hip_roll": d["delta_stance_hip_roll"]
            + g["stance_hip_roll"] * (o["psi_y"] + o["psi_roll"]),
            "stance_hip_pitch": d["delta_stance_hip_pitch"]
            + g["stance_hip_pitch"] * o["psi_pitch"],
            "stance_knee": g["stance_knee"] * o["psi_pitch"],
        }
        for j, v in want.items():
            assert o[f"delta_{j}"] == pytest.approx(clip(v, p.delta_limit_rad), rel=1e-15, abs=1e-15), j
        for k in ("error_vx", "error_vy", "error_pitch", "error_roll"):
            assert o[k] == d[k]


def test_learning_waits_for_learn_from_step_but_psi_keeps_acting():
    """learn_from_step = 1: no step-averaged velocity exists before the first
    completed walking step, so step_index 0 must not teach the networks anything (the
    default, 12, waits out the whole start-up: tests/scenarios/test_startup.py)."""
    p = small(learn_from_step=1, learning_rate=1e-4)
    nets = build_networks(p)
    s0 = initial_state(p, nets)
    u = RegulatorInputs(vx=0.0, vx_des=0.5, step_index=0)
    s1, out = step(s0, u, 0.005, p, nets)
    assert np.array_equal(s1.weights, s0.weights) and out["psi_x"] == 0.0  # waited
    s2, _ = step(s1, RegulatorInputs(vx=0.8, vx_des=0.5, step_index=1), 0.005, p, nets)
    assert not np.array_equal(s2.weights, s1.weights)  # learns from the first step on
    s3, out3 = step(s2, RegulatorInputs(vx=0.8, vx_des=0.5, step_index=1), 0.005,
                    p.replace(learn_from_step=5), nets)
    assert np.array_equal(s3.weights, s2.weights)  # gate closed again: frozen ...
    assert out3["psi_x"] != 0.0  # ... but what was learned still acts
    assert RegulatorParams().learn_from_step == 12


# -------------------------------------------------------------------- stride learning
def test_y_and_roll_learn_from_the_mean_of_the_last_two_steps():
    """Exactly the PES rule with E_y = vy_des - (mean_vy[k-1] + mean_vy[k]) / 2 (and
    roll likewise), the step means over the calls of each complete step."""
    p = small(learning_rate=1e-4, n_neurons=80)
    reg = Regulator(p)
    vys = {0: [0.9], 1: [0.1, 0.3, 0.2], 2: [-0.2, 0.0]}  # step 0 not seen from its start
    rolls = {0: [0.5], 1: [0.02, 0.04, 0.03], 2: [-0.05, -0.01]}
    for k in (0, 1, 2):
        for vy, roll in zip(vys[k], rolls[k]):
            reg.step(RegulatorInputs(vy=vy, roll=roll, step_index=k), DT)
    assert not reg.state.weights[[1, 3]].any()  # two steps complete only at the next change
    u = RegulatorInputs(vy=0.7, vy_des=0.1, roll=0.2, step_index=3)
    w0 = reg.state.weights
    reg.step(u, DT)
    _, xy, xt = network_inputs(u, p)
    hy, ht = neuron_rates(reg.networks.lateral, xy), neuron_rates(reg.networks.torso, xt)
    a = -p.learning_rate * DT / p.n_neurons
    e_y = 0.1 - 0.5 * (sum(vys[1]) / 3 + sum(vys[2]) / 2)
    e_roll = 0.0 - 0.5 * (sum(rolls[1]) / 3 + sum(rolls[2]) / 2)
    # tolerance: the rates differ by a few ulps between the core and neuron_rates (see
    # test_first_update_is_the_pes_rule)
    np.testing.assert_allclose(reg.state.weights[1] - w0[1], a * e_y * hy, rtol=1e-12,
                               atol=1e-12 * np.abs(a * e_y * hy).max())
    np.testing.assert_allclose(reg.state.weights[3] - w0[3], a * e_roll * ht, rtol=1e-12,
                               atol=1e-12 * np.abs(a * e_roll * ht).max())


def test_alternating_sway_leaves_the_lateral_and_roll_weights_bounded():
    """A sway that alternates with the stance side (vy and roll a half sine of
    alternating sign per step, of 40..42 calls) correlates with the lateral and torso
    networks' rates.  Learning from the instantaneous error integrates that correlation
    every stride (the weights grow linearly: the largest weight over the second half of
    the run is twice that of the first half); from the stride error, whose sway averages
    out, they stay bounded and periodic (ratio ~1; 1.5 separates the two clearly)."""
    reg = Regulator(small(learning_rate=1e-4, n_neurons=200, seed=3))
    peaks = []
    for k in range(400):
        side = 1.0 if k % 2 else -1.0
        for j in range(40 + k % 3):
            sway = side * math.sin(math.pi * (j + 0.5) / 40)
            reg.step(RegulatorInputs(vx=0.5, vx_des=0.5, vy=0.1 + 0.1 * sway, vy_des=0.1,
                                     roll=0.05 * sway, roll_rate=0.3 * sway, step_index=k), DT)
        peaks.append(np.abs(reg.state.weights[[1, 3]]).max(axis=1))
    peaks = np.array(peaks)
    first, second = peaks[:200].max(axis=0), peaks[200:].max(axis=0)
    assert np.all(second <= 1.5 * first), (first, second)


# ------------------------------------------------------- remedies against parameter drift


def _learned(**params):
    """A regulator (plain rule until ``params`` are set) that has learned for 30 calls."""
    reg = Regulator(small(learning_rate=1e-4))
    run(reg, [RegulatorInputs(vx=0.5, vx_des=0.1, pitch=0.1, step_index=k // 7) for k in range(30)])
    assert np.all(np.abs(reg.state.weights[[0, 2]]).max(axis=1) > 0.0)
    reg.set_params(**params)
    return reg


def test_leakage_scales_every_weight_before_the_pes_step():
    """leakage_mode 0: sigma-modification, every weight scaled by 1 - leakage dt."""
    reg = _learned(leakage_per_s=0.5, leakage_mode=0)
    w = reg.state.weights
    # No learning error (vx = vx_des, pitch = pitch_des, y and roll not ready): only the leak acts,
    # on every weight, silent neurons' too, by exactly one rounded product each.
    reg.step(RegulatorInputs(vx=0.3, vx_des=0.3, step_index=4), DT)
    assert np.array_equal(reg.state.weights, w * (1.0 - 0.5 * DT))
    # With an error: the plain rule's increment added to the leaked weights.
    u = RegulatorInputs(vx=0.5, vx_des=0.1, pitch=0.1, step_index=4)
    plain = _learned()
    plain.step(u, DT)
    leaky = _learned(leakage_per_s=0.5, leakage_mode=0)
    leaky.step(u, DT)
    w = _learned().state.weights
    np.testing.assert_allclose(leaky.state.weights, plain.state.weights - w * (0.5 * DT),
                               rtol=0, atol=1e-15 * np.abs(w).max())  # a few roundings of |w|


def test_leakage_never_flips_a_weight_sign():
    """leakage_per_s dt >= 1 empties the weights (a factor 1 - leakage dt < 0 would flip them)."""
    reg = _learned(leakage_per_s=1.0, leakage_mode=0)
    reg.step(RegulatorInputs(vx=0.3, vx_des=0.3, step_index=4), 1.5)
    assert np.array_equal(reg.state.weights, np.zeros_like(reg.state.weights))
    assert not np.signbit(reg.state.weights).any()


def test_leakage_mode_1_keeps_the_current_output_and_leaks_the_rest():
    """Mode 1 leaks only the part of each row orthogonal to the current rates: with no
    learning error, the outputs at the same inputs stay (to a few roundings) while the
    weights shrink and the outputs at other inputs move; mode 0 scales the outputs too."""
    # no learning error: only the leak acts; u far from where _learned learned (0.5 against 0.1)
    u = RegulatorInputs(vx=-0.4, vx_des=-0.4, step_index=4)
    other = RegulatorInputs(vx=1.0, vx_des=1.0, step_index=4)
    kept, scaled = _learned(leakage_per_s=0.5, leakage_mode=1), _learned(leakage_per_s=0.5, leakage_mode=0)
    w0 = kept.state.weights
    psi_other_before = _learned().step(other, DT)["psi_x"]
    first_kept, first_scaled = kept.step(u, DT), scaled.step(u, DT)
    for _ in range(400):
        last_kept, last_scaled = kept.step(u, DT), scaled.step(u, DT)
    for row in ("psi_x", "psi_pitch"):
        assert abs(first_kept[row]) > 1e-4
        # 400 leak steps, each exact up to a few roundings of |psi| (1e-16 relative each)
        assert last_kept[row] == pytest.approx(first_kept[row], rel=1e-12)
        assert last_scaled[row] == pytest.approx(first_scaled[row] * (1.0 - 0.5 * DT) ** 400, rel=1e-9)
    norms0, norms = np.linalg.norm(w0, axis=1), np.linalg.norm(kept.state.weights, axis=1)
    assert norms[0] < 0.9 * norms0[0] and norms[2] < norms0[2]  # what u does not use has leaked
    kept_other = kept.step(other, DT)["psi_x"]
    assert abs(kept_other - psi_other_before) > 0.05 * abs(psi_other_before)


def test_leakage_mode_is_inert_without_leakage():
    u = [RegulatorInputs(vx=0.5, vx_des=0.1, pitch=0.1, step_index=k // 7) for k in range(60)]
    a = Regulator(small(learning_rate=1e-4, leakage_per_s=0.0))
    b = Regulator(small(learning_rate=1e-4, leakage_per_s=0.0, leakage_mode=1))
    assert run(a, u) == run(b, u)
    assert np.array_equal(a.state.weights, b.state.weights)


def test_leakage_mode_range_is_named():
    with pytest.raises(ParameterError, match=r"leakage_mode = 2: must be an integer in \[0, 1\]"):
        small(leakage_mode=2)


def _pd_walk(limit, commands, vx=0.5, calls_per_step=50):
    """delta_swing_hip_pitch of a PD-only regulator (Kp_x 0.1) fed a constant vx and the
    command sequence ``commands`` (one per call), a new step every ``calls_per_step`` calls."""
    reg = Regulator(small(adaptation_enabled=False, command_accel_limit_mps2=limit))
    return [reg.step(RegulatorInputs(vx=vx, vx_des=c, step_index=k // calls_per_step), DT)["delta_swing_hip_pitch"]
            for k, c in enumerate(commands)], reg


def test_command_reference_follows_a_command_step_at_the_limit_and_averages_over_the_step():
    """With the limit a, a command step 0.5 -> 1.0 m/s is followed at a dt per call; the held
    PD term compares vx with the reference's mean over the step before, as vx is a mean."""
    commands = [0.5] * 100 + [1.0] * 300  # the step at call 100, the start of walking step 2
    plain, _ = _pd_walk(0.0, commands)
    limited, reg = _pd_walk(0.5, commands)
    assert plain[100] == pytest.approx(0.1 * (0.5 - 1.0))  # the whole step at once
    assert limited[100] == pytest.approx(0.0, abs=1e-15)  # the step before had the old command
    ref = [min(1.0, 0.5 + 0.5 * DT * (j + 1)) for j in range(50)]  # calls 100..149
    assert limited[150] == pytest.approx(0.1 * (0.5 - sum(ref) / 50), rel=1e-12)
    assert limited[149] == limited[100]  # held within a step
    assert reg.state.ref_vx == pytest.approx(1.0) and reg.state.ref_vy == 0.0  # reached after 200 calls
    # error_vx stays the distance to the command itself
    assert reg.step(RegulatorInputs(vx=0.5, vx_des=1.0, step_index=8), DT)["error_vx"] == -0.5


def test_command_reference_starts_at_the_measured_velocity_and_is_off_at_zero():
    _, reg = _pd_walk(0.5, [1.0], vx=0.2)
    assert reg.state.ref_vx == pytest.approx(0.2 + 0.5 * DT) and reg.state.ref_vx_step == reg.state.ref_vx
    out, _ = _pd_walk(0.5, [1.0], vx=0.2)
    assert out[0] == pytest.approx(0.1 * (0.2 - (0.2 + 0.5 * DT)))
    # at 0 the reference is the command, kept up to date, and nothing else changes
    u = [RegulatorInputs(vx=0.5, vx_des=0.1 + 0.01 * (k // 30), pitch=0.1, step_index=k // 7) for k in range(90)]
    a, b = Regulator(small(learning_rate=1e-4)), Regulator(small(learning_rate=1e-4, command_accel_limit_mps2=0.0))
    assert run(a, u) == run(b, u) and b.state.ref_vx == u[-1].vx_des


def test_command_reference_is_learned_against_and_saved_in_the_state():
    """The networks learn from the reference's error: with a command the reference has not
    reached yet the x row learns less than against the command; the reference survives a
    state round trip and the run continues identically."""
    u = [RegulatorInputs(vx=0.5, vx_des=0.5 if k < 20 else 1.5, step_index=k // 10) for k in range(80)]
    plain, limited = Regulator(small(learning_rate=1e-4)), Regulator(small(learning_rate=1e-4, command_accel_limit_mps2=0.5))
    run(plain, u), run(limited, u)
    # after the step the reference moves 0.0025 m/s per call: over the 60 calls its error is a
    # few percent of the command's 1 m/s; the bound leaves room for the other presynaptic
    # rates (the network reads the reference as its command input)
    assert 0.0 < np.abs(limited.state.weights[0]).max() < 0.25 * np.abs(plain.state.weights[0]).max()
    blob = state_to_bytes(limited.state)
    again = Regulator(small(learning_rate=1e-4, command_accel_limit_mps2=0.5))
    again.load_state(blob)
    assert again.state == limited.state and again.state.ref_vx == limited.state.ref_vx != 0.0
    more = [RegulatorInputs(vx=0.6, vx_des=1.5, step_index=8 + k // 10) for k in range(40)]
    assert run(again, more) == run(limited, more)


def test_velocity_learning_waits_for_a_settled_reference():
    """With learn_settled_steps = N the x and y rows do not learn (plain rule: they stay put)
    while the command reference moves and until N step changes after it settled; the torso rows
    learn as without it; the count survives a state round trip; a forged count is refused."""
    def seq(k0, k1, vx_des):  # 10 calls per step; the robot lags the command by 0.2 m/s
        return [RegulatorInputs(vx=vx_des - 0.2, vx_des=vx_des, vy=0.05, pitch=0.1, step_index=k // 10)
                for k in range(k0, k1)]
    limit = dict(learning_rate=1e-4, command_accel_limit_mps2=0.5)
    waits, plain = Regulator(small(learn_settled_steps=3, **limit)), Regulator(small(**limit))
    # from rest (the reference starts at the measured vx, 0.2 below the command: it needs
    # 0.2 / (0.5 * 0.005) = 80 calls to get there, and its step mean one step more)
    run(waits, seq(0, 80, 0.4)), run(plain, seq(0, 80, 0.4))
    assert waits.state.settled_steps == 0
    assert np.all(waits.state.weights[[0, 1]] == 0.0) and np.any(plain.state.weights[0] != 0.0)
    assert np.array_equal(waits.state.weights[2], plain.state.weights[2])
    # settled: the step mean reaches the command at the change of step 9 -> counts 1; learns from 3
    counts = []
    for u in seq(80, 140, 0.4):
        waits.step(u, DT)
        counts.append(waits.state.settled_steps)
    assert counts[::10] == [0, 1, 2, 3, 4, 5] and np.any(waits.state.weights[0] != 0.0)
    blob = state_to_bytes(waits.state)
    again = Regulator(small(learn_settled_steps=3, **limit))
    again.load_state(blob)
    assert again.state == waits.state and again.state.settled_steps == 5
    x_row = waits.state.weights[0].copy()
    run(waits, seq(140, 141, 0.9))  # a new command: the reference moves, the count restarts
    assert waits.state.settled_steps == 0 and np.array_equal(waits.state.weights[0], x_row)
    h = avr_statebytes._HEADER
    fields_ = list(h.unpack_from(blob))
    for forged in (-1, fields_[9] + 1):  # below 0, beyond n_calls
        fields_[-1] = forged
        with pytest.raises(StateError, match=rf"settled_steps = {forged}: must be in \[0, min\(n_calls"):
            state_from_bytes(_recrc(h.pack(*fields_) + blob[h.size:-4]), waits.params)


def test_learn_ramp_max_learns_on_a_slow_ramp_and_waits_after_a_step():
    """With learn_ramp_max_mps2 = a > 0 a command ramping at most a counts as settled (the
    velocity rows learn on it after learn_settled_steps step changes), a faster ramp or a
    step (which the acceleration limit turns into its catch-up) restarts the count; with 0
    no moving command counts (the rule of learn_settled_steps)."""
    def ramp(k0, k1, v0, rate):  # 10 calls per step; the command moves rate m/s^2 after v0 (k0 - 1)
        return [RegulatorInputs(vx=v0 + rate * (k + 1 - k0) * DT - 0.2, vx_des=v0 + rate * (k + 1 - k0) * DT,
                                pitch=0.1, step_index=k // 10) for k in range(k0, k1)]
    settings = dict(learning_rate=1e-4, command_accel_limit_mps2=0.5, learn_settled_steps=3)
    regs = {a: Regulator(small(learn_ramp_max_mps2=a, **settings)) for a in (0.0, 0.25)}
    for reg in regs.values():  # settled at 0.3 m/s (the reference starts 0.2 below: 80 calls)
        run(reg, ramp(0, 200, 0.3, 0.0))
    # (with a > 0 the count starts when the reference reaches the command, with 0 one step
    # later, when its step mean has too)
    assert [reg.state.settled_steps for reg in regs.values()] == [11, 12]
    # a ramp at 0.2 m/s^2 (below 0.25): the count goes on with a = 0.25, restarts with 0
    rows = {a: reg.state.weights[0].copy() for a, reg in regs.items()}
    counts = {a: [] for a in regs}
    for u in ramp(200, 400, 0.3, 0.2):
        for a, reg in regs.items():
            reg.step(u, DT)
            counts[a].append(reg.state.settled_steps)
    assert set(counts[0.0]) == {0} and np.array_equal(regs[0.0].state.weights[0], rows[0.0])
    assert min(counts[0.25]) > 3 and np.any(regs[0.25].state.weights[0] != rows[0.25])
    assert np.array_equal(regs[0.25].state.weights[2:], regs[0.0].state.weights[2:])  # torso as with 0
    # a ramp at 0.3 m/s^2 (above 0.25) restarts the count and stops the velocity learning
    row = regs[0.25].state.weights[0].copy()
    run(regs[0.25], ramp(400, 440, 0.7, 0.3))
    assert regs[0.25].state.settled_steps == 0 and np.array_equal(regs[0.25].state.weights[0], row)
    # a step: the reference catches up at 0.5 m/s^2 (above a): no count until it arrives
    fast = Regulator(small(learn_ramp_max_mps2=0.25, **settings))
    run(fast, ramp(0, 200, 0.3, 0.0))
    run(fast, ramp(200, 300, 0.8, 0.0))  # 0.5 m/s away: 200 calls to get there
    assert fast.state.settled_steps == 0
    run(fast, ramp(300, 440, 0.8, 0.0))  # arrives at call 399: counts at 400, 410, 420, 430
    assert fast.state.settled_steps == 4


def test_learn_ramp_max_range_is_named():
    with pytest.raises(ParameterError, match=r"learn_ramp_max_mps2 = 11(\.0)?: must be .*\[0(\.0)?, 10(\.0)?\]"):
        small(learn_ramp_max_mps2=11.0)


def test_learn_settled_steps_range_is_named():
    with pytest.raises(ParameterError, match=r"learn_settled_steps = -1: must be an integer in \[0, 1000\]"):
        small(learn_settled_steps=-1)


def test_command_accel_limit_range_is_named():
    with pytest.raises(ParameterError, match=r"command_accel_limit_mps2 = -0.5: must be a finite number in \[0, 10\]"):
        small(command_accel_limit_mps2=-0.5)


def test_remedies_are_in_the_parameter_table_with_ranges():
    for name, unit in (("leakage_per_s", "1/s"),):
        spec = next(s for s in PARAM_SPECS if s.name == name)
        assert (spec.unit, spec.min, spec.variability) == (unit, 0.0, "tunable")
        with pytest.raises(ParameterError, match=rf"{name} = -0.1: must be a finite number in \[0, 1\]"):
            small(**{name: -0.1})


# ---- tiers, rules between parameters, profiles (issue 43) ------------------------------------
def test_every_parameter_has_a_tier_and_the_research_switches_are_off_by_default():
    from fmu_src.core.avr_specs import EXPERIMENTAL, TIERS

    assert all(s.tier in TIERS for s in PARAM_SPECS)
    assert all(s.tier is None for s in (*INPUT_SPECS, *OUTPUT_SPECS))
    experimental = [s for s in PARAM_SPECS if s.tier == EXPERIMENTAL]
    assert {s.name for s in experimental} == {"learn_settled_steps", "learn_ramp_max_mps2"}
    assert all(s.default == 0 for s in experimental)
    # the model descriptions' text: the tier first
    assert RegulatorParams.__dataclass_fields__ and PARAM_SPECS[0].fmi_description == "[method] " + PARAM_SPECS[0].description


def test_the_retired_knobs_are_gone_and_named_as_unknown():
    for name in ("error_deadzone_mps", "weight_norm_max", "overspeed_unlearn"):
        assert name not in {s.name for s in PARAM_SPECS}
        with pytest.raises(ParameterError, match=rf"{name}: unknown parameter"):
            RegulatorParams().replace(**{name: 0})


def test_a_ramp_limit_without_settled_steps_is_refused_naming_both_with_every_other_problem():
    with pytest.raises(ParameterError) as exc:
        small(learn_ramp_max_mps2=0.25)
    assert exc.value.problems == ["learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0 (it is 0)"]
    small(learn_ramp_max_mps2=0.25, learn_settled_steps=1)  # together: legal
    reg = Regulator(small(learn_ramp_max_mps2=0.25, learn_settled_steps=1))
    with pytest.raises(ParameterError, match="learn_ramp_max_mps2 = 0.25 requires learn_settled_steps > 0"):
        reg.set_params(learn_settled_steps=0)
    # a bad value is named first; the rule is checked once every value is legal
    with pytest.raises(ParameterError) as exc:
        small(learn_ramp_max_mps2=0.25, Kp_x=9.0)
    assert exc.value.problems == ["Kp_x = 9.0: must be a finite number in [-5, 5]"]


def test_profiles_list_only_differences_and_the_robust_one_is_the_studys_design():
    from fmu_src.core.avr_profiles import PROFILES, profile_overrides

    assert list(PROFILES) == ["paper", "default", "robust"]
    assert profile_overrides("default") == {}
    assert profile_overrides("paper") == {"leakage_per_s": 0.0}
    # robustness_random_ramp's regulator settings through its extends chain (docs/results.md)
    assert profile_overrides("robust") == {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 8,
                                           "learning_rate": 2e-6, "learn_ramp_max_mps2": 0.25}
    for name in PROFILES:
        params = RegulatorParams().replace(**profile_overrides(name))
        assert all(getattr(params, key) != spec.default for spec in PARAM_SPECS
                   for key in [spec.name] if key in PROFILES[name])
    with pytest.raises(ParameterError, match=r"profile = 'fast': unknown \(allowed: paper, default, robust\)"):
        profile_overrides("fast")


def test_a_version_4_state_is_refused_naming_the_version():
    reg = Regulator(small())
    reg.step(RegulatorInputs(vx=0.2, vx_des=0.4, step_index=1), DT)
    blob = bytearray(state_to_bytes(reg.state))
    assert struct.unpack_from("<H", blob, 8) == (5,)
    struct.pack_into("<H", blob, 8, 4)
    blob[-4:] = struct.pack("<I", zlib.crc32(bytes(blob[:-4])))
    with pytest.raises(StateError, match=r"unsupported state format version 4 \(this build reads 5;.*"
                                         r"error_deadzone_mps, weight_norm_max and overspeed_unlearn \(version 4\)"):
        state_from_bytes(bytes(blob), reg.params)
