"""The regulator's parameters and one call's inputs, each checked by ``avr_specs.check_param``.

:class:`RegulatorParams` holds every parameter (names, units, ranges and defaults come
from ``PARAM_SPECS``); :func:`params_from_overrides` is the one place that turns
overrides (a scenario's, a master's, a slave's) into parameters.
:class:`RegulatorInputs` holds one call's inputs (``INPUT_SPECS``), checked by
:func:`validate_inputs`.
"""
from __future__ import annotations

from dataclasses import dataclass

from fmu_src.core.avr_errors import InputError, ParameterError
from fmu_src.core.avr_specs import INPUT_SPECS, PARAM_BY_NAME, PARAM_SPECS, check_param, requires_problems

__all__ = ["RegulatorParams", "params_from_overrides", "validate_params", "network_key",
           "RegulatorInputs", "validate_inputs"]


def _default(name):
    return PARAM_BY_NAME[name].default


@dataclass(frozen=True)
class RegulatorParams:
    """All regulator parameters (names, units, ranges and defaults: ``PARAM_SPECS``).

    Construction validates every field (raising :class:`ParameterError` that lists every
    problem at once) and normalises numbers: Real fields become ``float``, Integer
    fields ``int``, Boolean fields ``bool``.  Use :meth:`replace` for a modified copy.
    """

    Kp_x: float = _default("Kp_x")  # rad/(m/s)
    Kd_x: float = _default("Kd_x")  # rad/(m/s)
    Kp_y: float = _default("Kp_y")  # rad/(m/s)
    Kd_y: float = _default("Kd_y")  # rad/(m/s)
    Kp_pitch: float = _default("Kp_pitch")  # rad/rad
    Kd_pitch: float = _default("Kd_pitch")  # rad/(rad/s)
    Kp_roll: float = _default("Kp_roll")  # rad/rad
    Kd_roll: float = _default("Kd_roll")  # rad/(rad/s)
    pitch_des: float = _default("pitch_des")  # rad
    roll_des: float = _default("roll_des")  # rad
    learning_rate: float = _default("learning_rate")  # PES kappa (nengo convention)
    psi_limit: float = _default("psi_limit")  # rad
    learn_from_step: int = _default("learn_from_step")  # walking steps
    psi_gain_swing_hip_pitch: float = _default("psi_gain_swing_hip_pitch")
    psi_gain_swing_knee: float = _default("psi_gain_swing_knee")
    psi_gain_swing_hip_roll: float = _default("psi_gain_swing_hip_roll")
    psi_gain_stance_hip_roll: float = _default("psi_gain_stance_hip_roll")
    psi_gain_stance_hip_pitch: float = _default("psi_gain_stance_hip_pitch")
    psi_gain_stance_knee: float = _default("psi_gain_stance_knee")
    adaptation_enabled: bool = _default("adaptation_enabled")
    velocity_scale_mps: float = _default("velocity_scale_mps")  # m/s
    angle_scale_rad: float = _default("angle_scale_rad")  # rad
    rate_scale_radps: float = _default("rate_scale_radps")  # rad/s
    n_neurons: int = _default("n_neurons")
    seed: int = _default("seed")
    delta_limit_rad: float = _default("delta_limit_rad")  # rad
    leakage_per_s: float = _default("leakage_per_s")  # 1/s
    leakage_mode: int = _default("leakage_mode")
    command_accel_limit_mps2: float = _default("command_accel_limit_mps2")  # m/s^2
    learn_settled_steps: int = _default("learn_settled_steps")
    learn_ramp_max_mps2: float = _default("learn_ramp_max_mps2")  # m/s^2

    def __post_init__(self):
        values, problems = _checked(self)
        if problems:
            raise ParameterError(problems)
        for name, value in values.items():
            object.__setattr__(self, name, value)

    def replace(self, **changes) -> "RegulatorParams":
        """Return a validated copy with ``changes`` applied (ParameterError if invalid)."""
        unknown = sorted(set(changes) - set(PARAM_BY_NAME))
        values = {spec.name: getattr(self, spec.name) for spec in PARAM_SPECS}
        values.update({name: value for name, value in changes.items() if name in PARAM_BY_NAME})
        problems = [f"{name}: unknown parameter (known: {', '.join(PARAM_BY_NAME)})"
                    for name in unknown]
        try:
            new = RegulatorParams(**values)
        except ParameterError as exc:
            raise ParameterError(problems + exc.problems) from None
        if problems:
            raise ParameterError(problems)
        return new


def params_from_overrides(overrides) -> RegulatorParams:
    """The default parameters with ``overrides`` (name -> value) applied: the one place
    that turns a scenario's, a master's or a slave's overrides into parameters.

    Raises :class:`ParameterError` listing every unknown name and every bad value.
    """
    return RegulatorParams().replace(**dict(overrides))


def validate_params(params: RegulatorParams) -> None:
    """Raise :class:`ParameterError` listing every invalid field of ``params``.

    Each problem names the field, its value and the allowed range, e.g.
    ``"Kp_x = nan: must be a finite number in [-5, 5]"``.
    """
    if not isinstance(params, RegulatorParams):
        raise ParameterError(f"params = {params!r}: must be a RegulatorParams")
    _, problems = _checked(params)
    if problems:
        raise ParameterError(problems)


def _checked(params) -> tuple[dict, list[str]]:
    """Every field of ``params`` normalised by ``check_param``, and every problem found: each
    bad value, then (if every value is legal) each broken ``PARAM_REQUIRES`` rule."""
    values, problems = {}, []
    for spec in PARAM_SPECS:
        value, problem = check_param(spec, getattr(params, spec.name, None))
        values[spec.name] = value
        if problem is not None:
            problems.append(problem)
    return values, problems or requires_problems(values)


def network_key(params: RegulatorParams) -> tuple[int, float, float, float]:
    """``(seed, velocity_scale_mps, angle_scale_rad, rate_scale_radps)``: what a state's
    learned weights are tied to besides ``n_neurons``."""
    return (params.seed, params.velocity_scale_mps, params.angle_scale_rad,
            params.rate_scale_radps)


@dataclass(frozen=True)
class RegulatorInputs:
    """One call's inputs (names and units: ``INPUT_SPECS``); not validated on
    construction (``step`` calls :func:`validate_inputs`)."""

    vx: float = 0.0  # m/s
    vy: float = 0.0  # m/s
    vx_des: float = 0.0  # m/s
    vy_des: float = 0.0  # m/s
    pitch: float = 0.0  # rad
    roll: float = 0.0  # rad
    pitch_rate: float = 0.0  # rad/s
    roll_rate: float = 0.0  # rad/s
    step_index: int = 0  # walking step counter, >= 0



def validate_inputs(inputs: RegulatorInputs) -> None:
    """Raise :class:`InputError` naming the first bad input and its allowed range.

    Real inputs must be finite numbers in their declared range (``INPUT_SPECS``);
    ``step_index`` an integer in [0, 2**31-1].
    """
    for spec in INPUT_SPECS:
        _, problem = check_param(spec, getattr(inputs, spec.name))
        if problem is not None:
            raise InputError(problem + (f" ({spec.unit})" if spec.type == "Real" else ""))
