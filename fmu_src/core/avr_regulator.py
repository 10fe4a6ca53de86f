"""The regulator: its state and one pure call, :func:`step`.

Three decoupled regulators (longitudinal, lateral, torso), each a PD term plus the
output ``Psi`` of a fixed LIFRate network (``avr_network``) whose output weights learn
online with the PES rule.  One call, in order: PD terms (:func:`_held_pd_terms`,
:func:`_torso_pd_terms`), stride accumulators (:func:`_advance_stride`), network
output and learning with anti-windup (:func:`_adapt`), output composition and the
safety clip (:func:`_compose_outputs`).  Units: velocities m/s, angles and offsets
rad, rates rad/s, time s, weights rad/Hz.  Everything is float64, pure (``step``
returns a new state and never mutates its arguments) and seeded.  The method, with
its equations: ``docs/method.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from numbers import Real

import numpy as np

from fmu_src.core.avr_errors import InputError, ParameterError, StateError
from fmu_src.core.avr_network import (INV_TAU_RC, input_currents, lif_rates_times_tau_rc,
                           readonly, scaled_inputs)
from fmu_src.core.avr_params import network_key, validate_inputs
from fmu_src.core.avr_specs import (ANGLE_LIMIT_RAD, OFFSET_NAMES, INT32_MAX, RATE_LIMIT_RADPS,
                        SETTLED_STEPS_MAX, VELOCITY_LIMIT_MPS)

__all__ = ["WEIGHT_ROWS", "N_WEIGHT_ROWS", "STRIDE_READY", "RegulatorState",
           "initial_state", "step"]

#: Rows of the stored weight matrix, one per error signal (see RegulatorState); they
#: read the rates of the longitudinal, lateral, torso and torso network respectively.
WEIGHT_ROWS = ("x", "y", "pitch", "roll")
N_WEIGHT_ROWS = len(WEIGHT_ROWS)
#: stride_boundaries at which two steps are complete (the first call, then 3 changes)
STRIDE_READY = 4
#: The largest n_calls and stride_calls (2**53: the largest count a float64 holds exactly, and the
#: stride means divide by it).  A run never gets there (285 years at a microsecond per call); the
#: counters stop at it instead of overflowing the state's int64 fields, and a state beyond it is refused.
MAX_CALLS = 2**53
#: stride_boundaries from which the step in progress began at a change of step_index
#: (it is complete at the next change)
_STEP_SEEN_FROM_START = 2


@dataclass(frozen=True, eq=False)
class RegulatorState:
    """Immutable snapshot of everything the regulator remembers.

    * ``weights`` (4, n) learned output weights, rad/Hz (read-only; a writeable or
      non-owning array passed in is copied), one row per error signal
      (``WEIGHT_ROWS``): x (longitudinal net), y (lateral net), pitch and roll (torso
      net).  The two outputs of a network that share an error signal (Psi_x[0] and
      Psi_x[1]; Psi_y[0] and Psi_y[1]; Psi_torso[0] and Psi_torso[1]) have identical
      weight rows at all times (same zero start, same error, same presynaptic rates,
      same saturation and anti-windup decision), so each pair is stored once; they
      differ only through their psi_gain.  ``weights_x`` (2, n), ``weights_y`` (2, n)
      and ``weights_torso`` (3, n) are read-only views in the per-output layout.
    * ``last_step_index``: step_index seen at the previous call, -1 before the first.
    * ``vx_at_step``/``vy_at_step``: vx, vy (m/s) at the last step_index change.
    * ``pd_x``/``pd_y``: held longitudinal/lateral PD terms (rad).
    * ``n_calls``: number of ``step`` calls so far; ``time_s``: sum of their dt (s).
    * ``network_key``: ``(seed, velocity_scale_mps, angle_scale_rad,
      rate_scale_radps)`` of the regulator the weights belong to (``None`` = unknown);
      :func:`state_from_bytes` refuses a state learned on other networks.
    * Stride accumulators (the y and roll learning signal, see ``docs/method.md``):
      ``stride_boundaries`` step_index changes seen, the first call counting as one
      (saturates at ``STRIDE_READY`` = 4; a completed step needs 2, learning needs 4, i.e. two completed
      steps); ``stride_calls``, ``stride_sum_vy`` (m/s) and ``stride_sum_roll`` (rad):
      number of calls and sums of vy and roll in the current step;
      ``vy_mean_prev``/``vy_mean_last`` (m/s) and ``roll_mean_prev``/``roll_mean_last``
      (rad): the means over the last two completed steps.
    * The command reference (``command_accel_limit_mps2``, see :func:`_advance_reference`):
      ``ref_vx``/``ref_vy`` (m/s) after the last call, ``ref_sum_vx`` the sum of ``ref_vx``
      over the calls of the current step, ``ref_vx_step`` its mean over the step before
      (held, as ``vx`` is).
    * ``settled_steps``: step_index changes seen since the command reference last moved
      (:func:`_advance_settled`; stops at ``SETTLED_STEPS_MAX``): the velocity networks wait
      for ``learn_settled_steps`` of them.
    """

    weights: np.ndarray
    last_step_index: int = -1
    vx_at_step: float = 0.0
    vy_at_step: float = 0.0
    pd_x: float = 0.0
    pd_y: float = 0.0
    n_calls: int = 0
    time_s: float = 0.0
    network_key: tuple[int, float, float, float] | None = None
    stride_boundaries: int = 0
    stride_calls: int = 0
    stride_sum_vy: float = 0.0
    stride_sum_roll: float = 0.0
    vy_mean_prev: float = 0.0
    vy_mean_last: float = 0.0
    roll_mean_prev: float = 0.0
    roll_mean_last: float = 0.0
    ref_vx: float = 0.0
    ref_vy: float = 0.0
    ref_sum_vx: float = 0.0
    ref_vx_step: float = 0.0
    settled_steps: int = 0

    def __post_init__(self):
        weights = self.weights
        if not (type(weights) is np.ndarray and not weights.flags.writeable
                and weights.flags.owndata and weights.dtype == np.float64
                and weights.flags.c_contiguous):
            weights = readonly(np.array(weights, dtype=np.float64, copy=True, order="C"))
            object.__setattr__(self, "weights", weights)
        if weights.ndim != 2 or weights.shape[0] != N_WEIGHT_ROWS:
            raise StateError(f"weights must have shape (4, n_neurons), got {weights.shape}")

    @property
    def n_neurons(self) -> int:
        return self.weights.shape[1]

    @property
    def weights_x(self) -> np.ndarray:
        """(2, n) weights of Psi_x (swing hip pitch, swing knee), rad/Hz."""
        return self.weights[[0, 0]]  # (fancy indexing returns a copy)

    @property
    def weights_y(self) -> np.ndarray:
        """(2, n) weights of Psi_y (swing hip roll, stance hip roll), rad/Hz."""
        return self.weights[[1, 1]]

    @property
    def weights_torso(self) -> np.ndarray:
        """(3, n) weights of Psi_torso (stance hip pitch, stance knee, stance hip
        roll), rad/Hz."""
        return self.weights[[2, 2, 3]]

    def __eq__(self, other):
        if not isinstance(other, RegulatorState):
            return NotImplemented
        return all(np.array_equal(getattr(self, item.name), getattr(other, item.name))
                   for item in fields(self))

    __hash__ = None


def initial_state(params: RegulatorParams, networks: Networks) -> RegulatorState:
    """State before the first call: zero weights, no step seen yet."""
    if networks.n_neurons != params.n_neurons:
        raise ParameterError(f"n_neurons = {params.n_neurons!r}: networks were built "
                             f"with {networks.n_neurons}")
    return RegulatorState(weights=readonly(np.zeros((N_WEIGHT_ROWS, params.n_neurons))),
                          network_key=network_key(params))



def step(state: RegulatorState, inputs, dt: float, params, networks) -> tuple[RegulatorState, dict]:
    """Advance the regulator by one call of length ``dt`` (s, finite, > 0).

    Pure: ``state`` is not modified.  Returns ``(new_state, outputs)`` with ``outputs``
    a dict of python floats keyed by the ``OUTPUT_SPECS`` names.  Raises
    :class:`InputError` naming the bad input (or ``dt``).  ``params`` must be the ones
    the ``networks`` were built from (fixed fields); tunable fields may change between
    calls.
    """
    dt = _checked_dt(dt)
    values = _input_values(inputs)
    vx, vy, vx_des, vy_des, pitch, roll, pitch_rate, roll_rate, step_index = values
    if state.weights.shape[1] != networks.n_neurons:
        raise StateError(f"state has n_neurons = {state.weights.shape[1]}, networks have "
                         f"{networks.n_neurons}")
    reference = _advance_reference(state, params, vx, vy, vx_des, vy_des, step_index, dt)
    if params.command_accel_limit_mps2 != 0.0:
        ref_x, ref_y = reference["ref_vx_step"], reference["ref_vy"]
        values = (vx, vy, ref_x, ref_y, pitch, roll, pitch_rate, roll_rate, step_index)
    else:
        ref_x, ref_y = vx_des, vy_des
    settled_steps = _advance_settled(state, reference, vx_des, vy_des, step_index,
                                     params.learn_ramp_max_mps2 * dt)
    pd_x, pd_y, vx_at, vy_at = _held_pd_terms(state, params, vx, vy, ref_x, ref_y, step_index)
    stride = _advance_stride(state, step_index, vy, roll)
    pd_pitch, pd_roll = _torso_pd_terms(params, pitch, roll, pitch_rate, roll_rate)
    weights, psi = state.weights, None
    if params.adaptation_enabled:
        velocity_learns = settled_steps >= params.learn_settled_steps
        weights, psi = _adapt(weights, values, stride, dt, params, networks, velocity_learns)
    out = _compose_outputs((pd_x, pd_y, pd_pitch, pd_roll), psi, params)
    out["error_vx"] = vx - vx_des
    out["error_vy"] = vy - vy_des
    out["error_pitch"] = pitch - params.pitch_des
    out["error_roll"] = roll - params.roll_des
    # All operands are python floats here (validated params are floats, inputs were
    # converted), so every output is a python float.
    new_state = _new_state(RegulatorState)
    new_state.__dict__.update(  # skips __post_init__: weights are owned and read-only
        weights=weights, last_step_index=step_index, vx_at_step=vx_at, vy_at_step=vy_at,
        pd_x=pd_x, pd_y=pd_y, n_calls=state.n_calls + 1 if state.n_calls < MAX_CALLS else MAX_CALLS,
        time_s=state.time_s + dt,
        network_key=state.network_key, settled_steps=settled_steps, **stride, **reference)
    return new_state, out


_new_state = object.__new__


def _checked_dt(dt) -> float:
    if type(dt) is not float:
        if isinstance(dt, (bool, np.bool_)) or not isinstance(dt, Real):
            raise InputError(f"dt = {dt!r}: must be a finite number > 0 (s)")
        dt = float(dt)
    if not 0.0 < dt < math.inf:  # also rejects nan
        raise InputError(f"dt = {dt!r}: must be a finite number > 0 (s)")
    return dt


def _input_values(inputs) -> tuple:
    """``(vx, vy, vx_des, vy_des, pitch, roll, pitch_rate, roll_rate, step_index)``, checked:
    python floats and an int.

    Fast path for the usual all-python-float inputs inside their declared ranges (the
    comparisons are false for nan); anything else goes through :func:`validate_inputs`
    (which raises naming the input and its range) and is converted.
    """
    values = (inputs.vx, inputs.vy, inputs.vx_des, inputs.vy_des, inputs.pitch, inputs.roll,
              inputs.pitch_rate, inputs.roll_rate, inputs.step_index)
    vx, vy, vx_des, vy_des, pitch, roll, pitch_rate, roll_rate, step_index = values
    speed, angle, rate = VELOCITY_LIMIT_MPS, ANGLE_LIMIT_RAD, RATE_LIMIT_RADPS
    if (type(vx) is float and type(vy) is float and type(vx_des) is float
            and type(vy_des) is float and type(pitch) is float and type(roll) is float
            and type(pitch_rate) is float and type(roll_rate) is float
            and type(step_index) is int and 0 <= step_index <= INT32_MAX
            and -speed <= vx <= speed and -speed <= vy <= speed
            and -speed <= vx_des <= speed and -speed <= vy_des <= speed
            and -angle <= pitch <= angle and -angle <= roll <= angle
            and -rate <= pitch_rate <= rate and -rate <= roll_rate <= rate):
        return values
    validate_inputs(inputs)
    return (*(float(value) for value in values[:-1]), int(step_index))


def _held_pd_terms(state: RegulatorState, params, vx, vy, vx_des, vy_des, step_index):
    """``(pd_x, pd_y, vx_at_step, vy_at_step)``: the longitudinal and lateral PD terms (rad),
    recomputed when ``step_index`` changes (no derivative kick on the first call) and
    held otherwise."""
    if step_index == state.last_step_index:
        return state.pd_x, state.pd_y, state.vx_at_step, state.vy_at_step
    first = state.last_step_index < 0
    vx_prev = vx if first else state.vx_at_step
    vy_prev = vy if first else state.vy_at_step
    pd_x = params.Kp_x * (vx - vx_des) + params.Kd_x * (vx - vx_prev)
    pd_y = params.Kp_y * (vy - vy_des) + params.Kd_y * (vy - vy_prev)
    return pd_x, pd_y, vx, vy


def _toward(value: float, target: float, amount: float) -> float:
    """``value`` moved toward ``target`` by at most ``amount`` (>= 0)."""
    change = target - value
    if change > amount:
        change = amount
    elif change < -amount:
        change = -amount
    return value + change


def _advance_reference(state: RegulatorState, params, vx: float, vy: float, vx_des: float,
                       vy_des: float, step_index: int, dt: float) -> dict:
    """The command reference after this call (``RegulatorState``'s ``ref_*`` fields).

    With ``command_accel_limit_mps2`` = a > 0 the reference moves toward (vx_des, vy_des)
    by at most a dt per call, from the measured (vx, vy) at the first call: it follows a
    command step as the walking controller's gait does, so the regulator's error is the
    robot's lag behind the gait, not the distance to where the gait is still ramping to.
    With a = 0 the reference is the command itself (kept up to date, so that switching
    the limit on mid-run starts from the command in force).  ``ref_vx_step`` is the mean
    of ``ref_vx`` over the calls of the step before the current one: the longitudinal
    error compares it with ``vx``, the robot's mean velocity over that same step."""
    limit = params.command_accel_limit_mps2
    first = state.last_step_index < 0
    if limit == 0.0:
        ref_vx, ref_vy = vx_des, vy_des
    else:
        amount = limit * dt
        ref_vx = _toward(vx if first else state.ref_vx, vx_des, amount)
        ref_vy = _toward(vy if first else state.ref_vy, vy_des, amount)
    if step_index == state.last_step_index:
        ref_sum_vx, ref_vx_step = state.ref_sum_vx + ref_vx, state.ref_vx_step
    elif first:
        ref_sum_vx, ref_vx_step = ref_vx, ref_vx
    else:  # the step that ends now had stride_calls calls
        ref_sum_vx, ref_vx_step = ref_vx, state.ref_sum_vx / float(state.stride_calls)
    return dict(ref_vx=ref_vx, ref_vy=ref_vy, ref_sum_vx=ref_sum_vx, ref_vx_step=ref_vx_step)


#: How close (m/s) the command reference must be to the command to count as settled: the step
#: mean of a constant reference (a sum of equal terms divided by their count) can differ from
#: it in the last bits.
SETTLED_TOLERANCE_MPS = 1e-9


def _advance_settled(state: RegulatorState, reference: dict, vx_des: float, vy_des: float,
                     step_index: int, ramp_per_call: float) -> int:
    """``settled_steps`` after this call: 0 while the reference (after this call) is not
    settled, else one more at each change of step_index (the first call counts as one), up
    to ``SETTLED_STEPS_MAX``.  With ``ramp_per_call`` = 0 (``learn_ramp_max_mps2`` 0) settled
    means ``ref_vx``, ``ref_vy`` and the step mean ``ref_vx_step`` are each within
    ``SETTLED_TOLERANCE_MPS`` of the command; with r > 0, that ``ref_vx`` and ``ref_vy`` are
    within it and that each moved by at most r (+ the tolerance) since the last call (not
    checked at the first call, where the reference starts): a slow ramp counts as settled."""
    tolerance = SETTLED_TOLERANCE_MPS
    if abs(reference["ref_vx"] - vx_des) > tolerance or abs(reference["ref_vy"] - vy_des) > tolerance:
        return 0
    if ramp_per_call == 0.0:
        if abs(reference["ref_vx_step"] - vx_des) > tolerance:
            return 0
    elif state.last_step_index >= 0 and (
            abs(reference["ref_vx"] - state.ref_vx) > ramp_per_call + tolerance
            or abs(reference["ref_vy"] - state.ref_vy) > ramp_per_call + tolerance):
        return 0
    if step_index != state.last_step_index and state.settled_steps < SETTLED_STEPS_MAX:
        return state.settled_steps + 1
    return state.settled_steps


def _torso_pd_terms(params, pitch, roll, pitch_rate, roll_rate) -> tuple[float, float]:
    """``(pd_pitch, pd_roll)`` (rad), every call."""
    pd_pitch = params.Kp_pitch * (pitch - params.pitch_des) + params.Kd_pitch * pitch_rate
    pd_roll = params.Kp_roll * (roll - params.roll_des) + params.Kd_roll * roll_rate
    return pd_pitch, pd_roll


def _advance_stride(state: RegulatorState, step_index: int, vy: float, roll: float) -> dict:
    """The stride accumulators after a call with ``step_index``: at a change of
    step_index the step that ends is closed (its means shifted in) if it was seen from
    its start, and this call starts the new step's sums."""
    if step_index == state.last_step_index:
        return dict(
            stride_boundaries=state.stride_boundaries,
            stride_calls=state.stride_calls + 1 if state.stride_calls < MAX_CALLS else MAX_CALLS,
            stride_sum_vy=state.stride_sum_vy + vy, stride_sum_roll=state.stride_sum_roll + roll,
            vy_mean_prev=state.vy_mean_prev, vy_mean_last=state.vy_mean_last,
            roll_mean_prev=state.roll_mean_prev, roll_mean_last=state.roll_mean_last)
    boundaries = state.stride_boundaries
    vy_means = (state.vy_mean_prev, state.vy_mean_last)
    roll_means = (state.roll_mean_prev, state.roll_mean_last)
    if boundaries >= _STEP_SEEN_FROM_START:  # the step that ends now is complete
        calls = float(state.stride_calls)
        vy_means = (state.vy_mean_last, state.stride_sum_vy / calls)
        roll_means = (state.roll_mean_last, state.stride_sum_roll / calls)
    return dict(
        stride_boundaries=min(boundaries + 1, STRIDE_READY), stride_calls=1,
        stride_sum_vy=vy, stride_sum_roll=roll,
        vy_mean_prev=vy_means[0], vy_mean_last=vy_means[1],
        roll_mean_prev=roll_means[0], roll_mean_last=roll_means[1])


def _adapt(weights: np.ndarray, values: tuple, stride: dict, dt: float, params, networks,
           velocity_learns: bool = True):
    """The networks' saturated outputs ``psi`` (x, y, pitch, roll; rad) with the weights
    from before this call, and the weights after this call's PES update (with 0 as the x and
    y errors unless ``velocity_learns``)."""
    vx, vy, vx_des, vy_des, pitch, roll, pitch_rate, roll_rate, step_index = values
    scaled = scaled_inputs(vx, vx_des, vy, vy_des, pitch, roll, pitch_rate, roll_rate, params)
    # tau_rc * rates, (3, n): the factor 1 / tau_rc goes into scalars below
    rates_tau = lif_rates_times_tau_rc(input_currents(scaled, networks))
    row_rates = rates_tau[_ROW_NETWORK]  # (4, n): each weight row's presynaptic rates
    # Psi_raw[j] = weights[j] . rates[net(j)], summed in neuron order (a cumulative sum:
    # sequential by definition, unlike BLAS or np.sum), then + 0.0 (no -0.0), as the C
    # core's loop over the active neurons (the silent ones add exact zeros).
    sums = np.cumsum(np.multiply(weights, row_rates), axis=1)[:, -1].tolist()
    raw = [(0.0 + value) * INV_TAU_RC for value in sums]
    limit = params.psi_limit
    psi = [limit if value > limit else (-limit if value < -limit else value) for value in raw]
    if params.learning_rate != 0.0 and step_index >= params.learn_from_step:
        errors = _learning_errors(stride, vx, vx_des, vy_des, pitch, params, velocity_learns)
        weights = _pes_update(weights, row_rates, raw, sums, errors, dt, params)
    return weights, psi


#: The network each weight row reads: x longitudinal, y lateral, pitch and roll torso.
_ROW_NETWORK = [0, 1, 2, 2]


def _learning_errors(stride: dict, vx: float, vx_des: float, vy_des: float, pitch: float,
                     params, velocity_learns: bool) -> tuple[float, float, float, float]:
    """PES errors ``desired - actual`` (x, y, pitch, roll): instantaneous for x and pitch,
    stride-averaged for y and roll (0, i.e. no learning, until two steps are complete):
    vy and roll sway with the stance side every step, which no offset can remove and
    which PES would otherwise integrate without bound; the mean of the last two
    completed steps (a left and a right one) cancels the sway.  x and y are 0 while the
    velocity networks wait for a settled command (not ``velocity_learns``)."""
    if stride["stride_boundaries"] >= STRIDE_READY:
        e_y = vy_des - 0.5 * (stride["vy_mean_prev"] + stride["vy_mean_last"])
        e_roll = params.roll_des - 0.5 * (stride["roll_mean_prev"] + stride["roll_mean_last"])
    else:
        e_y = e_roll = 0.0
    e_x = vx_des - vx
    if not velocity_learns:
        e_x = e_y = 0.0
    return (e_x, e_y, params.pitch_des - pitch, e_roll)


def _leak_factor(leakage_per_s: float, dt: float) -> float:
    """What every weight is multiplied by before a call's PES step: ``1 - leakage dt``
    (0 once ``leakage dt`` reaches 1: a leak never flips a weight's sign)."""
    if leakage_per_s == 0.0:
        return 1.0
    amount = leakage_per_s * dt
    return 1.0 - amount if amount < 1.0 else 0.0


def _pes_update(weights, row_rates, raw, sums, errors, dt, params) -> np.ndarray:
    """The weights after one PES step with conditional-integration anti-windup and the
    leakage before it (off at 0).

    The update moves raw[j] by ``-learning_rate dt/n E_j |rates|^2``, i.e. in the
    direction of -E_j; rows at or beyond the limit that it would push further out
    (raw[j] and -E_j of the same sign) are skipped for this call.  Each weight becomes
    ``coefficient * rate + weight`` (one rounding each, as the C core).  ``row_rates``
    ((4, n), :func:`_adapt`'s own copy) is overwritten: it becomes the new weights.
    """
    limit = params.psi_limit
    alpha = -params.learning_rate * dt / row_rates.shape[1] * INV_TAU_RC  # per unit of tau_rc * rate
    coefficients = [0.0 if (value >= limit or value <= -limit) and value * error < 0.0
                    else alpha * error for value, error in zip(raw, errors)]
    keep = _leak_factor(params.leakage_per_s, dt)
    if keep != 1.0 and params.leakage_mode == 1:
        coefficients = _keep_current_output(coefficients, row_rates, [0.0 + v for v in sums], 1.0 - keep)
    if not any(coefficients) and keep == 1.0:
        return weights  # nothing changes: keep (share) the read-only array
    new_weights = np.multiply(row_rates, np.array(coefficients)[:, None], out=row_rates)
    if keep == 1.0:
        new_weights += weights
    else:  # leak first (+ 0.0: an underflow gives +0.0, never -0.0), then the PES step
        new_weights += weights * keep + 0.0
    return readonly(new_weights)


def _keep_current_output(coefficients: list, row_rates: np.ndarray, sums: list,
                         amount: float) -> list:
    """The PES coefficients plus, for each row j, ``amount (w_j . h_j) / |h_j|^2``: after
    the leak ``w_j -> (1 - amount) w_j``, adding that multiple of ``h_j`` gives back the
    part of ``w_j`` along ``h_j``, so only the part orthogonal to the current rates decays
    and the row's output at this call is kept.  ``sums[j]`` is ``w_j . h_j`` (the output's
    sum before this call), ``|h_j|^2`` is summed in neuron order (a cumulative sum, as the
    C core's loop); a row whose rates are all 0 gets nothing added."""
    squares = np.cumsum(row_rates * row_rates, axis=1)[:, -1].tolist()
    return [c if sq == 0.0 else c + (amount * s) / sq
            for c, s, sq in zip(coefficients, sums, squares)]


def _compose_outputs(pd_terms: tuple, psi: list | None, params) -> dict:
    """The six offsets (PD terms plus gained Psi, then the safety clip) and the four
    ``psi_*`` diagnostics; ``psi`` None when adaptation is off (Psi contributes exactly 0)."""
    pd_x, pd_y, pd_pitch, pd_roll = pd_terms
    if psi is None:
        out = {
            "delta_swing_hip_pitch": pd_x,
            "delta_swing_knee": 0.0,
            "delta_swing_hip_roll": pd_y,
            "delta_stance_hip_roll": pd_roll,
            "delta_stance_hip_pitch": pd_pitch,
            "delta_stance_knee": 0.0,
            "psi_x": 0.0, "psi_y": 0.0, "psi_pitch": 0.0, "psi_roll": 0.0,
        }
    else:
        psi_x, psi_y, psi_pitch, psi_roll = psi
        gain_roll = params.psi_gain_stance_hip_roll
        out = {
            "delta_swing_hip_pitch": pd_x + params.psi_gain_swing_hip_pitch * psi_x,
            "delta_swing_knee": params.psi_gain_swing_knee * psi_x + 0.0,  # -0.0 -> 0.0
            "delta_swing_hip_roll": pd_y + params.psi_gain_swing_hip_roll * psi_y,
            "delta_stance_hip_roll": pd_roll + gain_roll * psi_y + gain_roll * psi_roll,
            "delta_stance_hip_pitch": pd_pitch + params.psi_gain_stance_hip_pitch * psi_pitch,
            "delta_stance_knee": params.psi_gain_stance_knee * psi_pitch + 0.0,
            "psi_x": psi_x, "psi_y": psi_y, "psi_pitch": psi_pitch, "psi_roll": psi_roll,
        }
    high = params.delta_limit_rad
    low = 0.0 - high  # (not -high: a limit of 0 gives +0.0, never -0.0)
    for name in OFFSET_NAMES:  # the safety bound; values inside it pass unchanged, bit for bit
        value = out[name]
        if value > high:
            out[name] = high
        elif value < low:
            out[name] = low
    return out
