"""The slow, operation-by-operation reference path of the regulator's networks (tests only; never inside an FMU).

:func:`neuron_rates` evaluates one network's LIFRate rates in Hz exactly as nengo writes
them, ``1 / (tau_ref + tau_rc log1p(1 / (J - 1)))`` per network, where the core
(``fmu_src.core.avr_network.lif_rates_times_tau_rc``) evaluates all three networks at once
with its fixed-series ``log1p`` and folds ``1 / tau_rc`` into scalars; :func:`network_inputs` gives each
network's input as an array.  The tests compare the core against these.
"""
import numpy as np

from fmu_src.core.avr_network import TAU_RC, TAU_REF, NetworkSpec, scaled_inputs
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams, validate_inputs

#: A tiny positive current for inactive neurons (keeps inf out of log1p), as in the core.
_TINY_CURRENT = 1e-300


def lif_rates(current: np.ndarray) -> np.ndarray:
    """LIFRate rates (Hz) for ``current = J - 1`` (J: input current); 0 where it is <= 0.

    Works in place on ``current`` (pass a temporary); inactive neurons are zeroed by the
    numerator of the last division.
    """
    active = current > 0.0
    np.maximum(current, _TINY_CURRENT, out=current)
    np.divide(1.0, current, out=current)
    np.log1p(current, out=current)
    current *= TAU_RC
    current += TAU_REF
    np.divide(active, current, out=current)  # True -> 1.0, False -> 0.0 (exactly 0 Hz)
    return current


def neuron_rates(net: NetworkSpec, x) -> np.ndarray:
    """LIFRate rates (Hz, shape (n,)) of ``net`` for a scaled input ``x`` (shape (d,)).

    ``x`` is used as given (see :func:`network_inputs`); the current is
    ``scaled_encoders @ x + bias``.
    """
    x = np.asarray(x, dtype=np.float64).reshape(net.dimensions)
    return lif_rates((net.scaled_encoders @ x + net.bias) - 1.0)


def network_inputs(inputs: RegulatorInputs,
                   params: RegulatorParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three networks' inputs for ``inputs``: scaled and radially projected into
    the unit ball (longitudinal (2,), lateral (2,), torso (4,), dimensionless)."""
    validate_inputs(inputs)
    x = np.array(scaled_inputs(
        float(inputs.vx), float(inputs.vx_des), float(inputs.vy), float(inputs.vy_des),
        float(inputs.pitch), float(inputs.roll), float(inputs.pitch_rate),
        float(inputs.roll_rate), params)[:8])
    return x[0:2], x[2:4], x[4:8]
