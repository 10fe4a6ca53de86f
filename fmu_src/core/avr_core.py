"""The adaptive velocity regulator (AVR) as one object: :class:`Regulator` holds the
parameters, the networks and the state of the pure numpy core and steps it.

Implements the regulator of Castillo, Weng, Stewart, Zhang and Hereid, "Velocity
Regulation of 3D Bipedal Walking Robots with Uncertain Dynamics Through Adaptive
Neural Network Controller" (IROS 2020); the method, its equations and design choices
are described once, in ``docs/method.md``.

Data flow of one call (``step``): inputs vx, vy, vx_des, vy_des (m/s), pitch, roll
(rad), pitch_rate, roll_rate (rad/s) and the plant's integer ``step_index`` -> PD
terms + the saturated outputs Psi (rad) of three LIFRate networks whose output
weights learn online (PES, anti-windup) -> six joint offsets ``delta_*`` (rad, added
by the plant to its nominal gait, clipped to +-delta_limit_rad) and diagnostics.

The modules of the core, one concept each: ``avr_specs`` (the variable table and the one
value check), ``avr_params`` (parameters and inputs), ``avr_network`` (the LIFRate networks
and their seeded SplitMix64 random numbers), ``avr_regulator`` (the state and the pure
``step``), ``avr_statebytes`` (the state as bytes), ``avr_errors``.  Everything is float64,
seeded and imports nothing besides numpy and the standard library, because these modules
travel inside the FMU (see ``fmu_src/packing/pack.py``).
"""
from __future__ import annotations

from fmu_src.core.avr_errors import ParameterError
from fmu_src.core.avr_network import build_networks
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams, validate_params
from fmu_src.core.avr_regulator import initial_state, step
from fmu_src.core.avr_specs import FIXED_PARAMS
from fmu_src.core.avr_statebytes import state_from_bytes


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
