"""The adaptive velocity regulator (AVR): public façade of the numpy-only core.

Implements the regulator of Castillo, Weng, Stewart, Zhang and Hereid, "Velocity
Regulation of 3D Bipedal Walking Robots with Uncertain Dynamics Through Adaptive
Neural Network Controller" (IROS 2020); the method, its equations and design choices
are described once, in ``docs/method.md``.

Data flow of one call (``step``): inputs vx, vy, vx_des, vy_des (m/s), pitch, roll
(rad), pitch_rate, roll_rate (rad/s) and the plant's integer ``step_index`` -> PD
terms + the saturated outputs Psi (rad) of three LIFRate networks whose output
weights learn online (PES, anti-windup) -> six joint offsets ``delta_*`` (rad, added
by the plant to its nominal gait, clipped to +-delta_limit_rad) and diagnostics.

This module is the façade: the :class:`Regulator` wrapper and the public names of the
modules that do the work, so ``from fmu_src.avr_core import X`` keeps working:

* ``avr_specs``: the variable declarations (``PARAM_SPECS``, ``INPUT_SPECS``,
  ``OUTPUT_SPECS``), the one value check ``check_param`` and ``PYTHON_TYPES``;
* ``avr_params``: ``RegulatorParams``, ``params_from_overrides``, ``RegulatorInputs``;
* ``avr_network``: the LIFRate networks and their seeded SplitMix64 random numbers;
* ``avr_regulator``: ``RegulatorState``, ``initial_state`` and the pure ``step``;
* ``avr_statebytes``: ``state_to_bytes`` / ``state_from_bytes`` (format version 2).

Everything is float64, seeded and imports nothing besides numpy and the standard
library (and each other, package-relative), because these modules travel inside the FMU
(``resources/avr_regulator_lib/``, see ``avr_packaging/pack.py``).
"""
from __future__ import annotations

from .avr_errors import ParameterError
from .avr_network import (INTERCEPT_RANGE, MAX_RATE_RANGE_HZ, NETWORK_NAMES, TAU_RC, TAU_REF,
                          Networks, NetworkSpec, SplitMix64, build_networks, lif_gain_bias,
                          scaled_inputs, sphere_encoders, LN2, SQRT2, log1p_fixed,
                          expm1_fixed)
from .avr_params import (RegulatorInputs, RegulatorParams, network_key, params_from_overrides,
                         validate_inputs, validate_params)
from .avr_regulator import MAX_CALLS, WEIGHT_ROWS, RegulatorState, initial_state, step
from .avr_specs import (ANGLE_LIMIT_RAD, FIXED_PARAMS, INPUT_SPECS, OUTPUT_JOINTS, OUTPUT_SPECS,
                        PARAM_SPECS, PYTHON_TYPES, RATE_LIMIT_RADPS, VELOCITY_LIMIT_MPS, VarSpec,
                        check_param, format_range)
from .avr_statebytes import state_from_bytes, state_to_bytes

__all__ = [
    "OUTPUT_JOINTS", "VarSpec", "PARAM_SPECS", "INPUT_SPECS", "OUTPUT_SPECS", "PYTHON_TYPES",
    "VELOCITY_LIMIT_MPS", "ANGLE_LIMIT_RAD", "RATE_LIMIT_RADPS", "FIXED_PARAMS",
    "check_param", "format_range",
    "TAU_RC", "TAU_REF", "MAX_RATE_RANGE_HZ", "INTERCEPT_RANGE", "NETWORK_NAMES",
    "RegulatorParams", "params_from_overrides", "validate_params", "network_key",
    "RegulatorInputs", "validate_inputs",
    "NetworkSpec", "Networks", "SplitMix64", "sphere_encoders", "build_networks",
    "lif_gain_bias", "scaled_inputs", "LN2", "SQRT2", "log1p_fixed", "expm1_fixed",
    "WEIGHT_ROWS", "MAX_CALLS", "RegulatorState", "initial_state", "step",
    "state_to_bytes", "state_from_bytes", "Regulator",
]


class Regulator:
    """Stateful wrapper: holds ``params``, ``networks`` and the current ``state``.

    Used by the in-process co-simulation path and the benchmarks; the FMU slave may
    use the pure functions directly.
    """

    def __init__(self, params: RegulatorParams | None = None):
        self.params = RegulatorParams() if params is None else params
        validate_params(self.params)
        self.networks = build_networks(self.params)
        self.state = initial_state(self.params, self.networks)

    def step(self, inputs: RegulatorInputs, dt: float) -> dict[str, float]:
        """One call of length ``dt`` (s); returns the ``OUTPUT_SPECS`` dict."""
        self.state, out = step(self.state, inputs, dt, self.params, self.networks)
        return out

    def set_params(self, **changes) -> None:
        """Change tunable parameters (ParameterError for invalid or fixed ones)."""
        fixed = [f"{name} = {value!r}: fixed parameter, cannot change after instantiation"
                 for name, value in changes.items()
                 if name in FIXED_PARAMS and value != getattr(self.params, name)]
        if fixed:
            raise ParameterError(fixed)
        self.params = self.params.replace(**changes)

    def reset(self) -> None:
        """Back to the initial state (zero weights, no step seen)."""
        self.state = initial_state(self.params, self.networks)

    def load_state(self, blob: bytes) -> None:
        self.state = state_from_bytes(blob, self.params)
