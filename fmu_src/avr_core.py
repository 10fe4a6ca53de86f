"""Numpy-only core of the adaptive velocity regulator (AVR).

Implements the regulator of Castillo, Weng, Stewart, Zhang and Hereid, "Velocity
Regulation of 3D Bipedal Walking Robots with Uncertain Dynamics Through Adaptive
Neural Network Controller" (IROS 2020): three decoupled regulators, each a classic PD
term plus the output ``Psi`` of a one-hidden-layer rate network whose output weights
learn online with the PES rule.

Everything here is pure (``step`` returns a new state and never mutates its inputs),
float64, seeded and free of any import besides numpy and the standard library, because
this module is copied flat into the FMU's ``resources/`` folder.

Regulators and outputs (all offsets in rad, added by the plant to its nominal gait)::

    PD_x     = Kp_x (vx[k] - vx_des) + Kd_x (vx[k] - vx[k-1])      held per step_index
    PD_y     = Kp_y (vy[k] - vy_des) + Kd_y (vy[k] - vy[k-1])      held per step_index
    PD_pitch = Kp_pitch (pitch - pitch_des) + Kd_pitch pitch_rate   every call
    PD_roll  = Kp_roll  (roll  - roll_des)  + Kd_roll  roll_rate    every call

    delta_swing_hip_pitch  = PD_x     + g_shp * Psi_x[0]
    delta_swing_knee       =            g_sk  * Psi_x[1]
    delta_swing_hip_roll   = PD_y     + g_shr * Psi_y[0]
    delta_stance_hip_roll  = PD_roll  + g_thr * Psi_y[1] + g_thr * Psi_torso[2]
    delta_stance_hip_pitch = PD_pitch + g_thp * Psi_torso[0]
    delta_stance_knee      =            g_tk  * Psi_torso[1]

each then clipped to ``[-delta_limit_rad, delta_limit_rad]`` (a safety bound that the
default 1 rad keeps out of normal operation; inputs are also refused outside their
declared physical ranges, ``INPUT_SPECS``), where ``g_*`` are the ``psi_gain_<joint>``
parameters, applied at output time only
(learning does not depend on them, so a gain of 0 switches an output off while its
network keeps learning).  ``vx[k-1]`` is vx at the previous change of the integer input
``step_index`` (any change, also a decrease); PD_x and PD_y are recomputed only when
``step_index`` changes and held in between; on the very first call ``vx[k-1] = vx[k]``
(no derivative kick).

Networks.  Each regulator has ``n_neurons`` LIFRate neurons (tau_rc = 0.02 s,
tau_ref = 0.002 s) with unit-vector encoders drawn uniformly on the sphere, maximum
rates ~ U(200, 400) Hz and intercepts ~ U(-1, 0.9) (nengo 4's Ensemble defaults; the
upper end stays below 1 because the gain ``(J_max - 1) / (1 - intercept)`` diverges as
an intercept approaches 1, giving neurons that switch on only in a sliver of the input
space with a huge slope).  Gains and biases follow from the analytic LIF rate curve
exactly as nengo builds an Ensemble with radius 1.  The random numbers come from one
small documented generator, SplitMix64 counter streams keyed by (seed, network, field),
with encoders by rejection from the cube (:class:`SplitMix64`, :func:`sphere_encoders`):
the C implementation (``native/``) builds the same networks from the same seed.

Network inputs:

* longitudinal: ``[vx, vx_des] / velocity_scale_mps``
* lateral:      ``[vy, vy_des] / velocity_scale_mps``
* torso:        ``[pitch / angle_scale_rad, roll / angle_scale_rad,
  pitch_rate / rate_scale_radps, roll_rate / rate_scale_radps]``

each then mapped into the unit ball by *radial projection*: a vector of norm <= 1 is
used unchanged, a longer one is divided by its norm (direction kept, no per-component
distortion and no loss of resolution inside the ball, unlike clip-then-divide by
sqrt(d)).

Learning (PES, as nengo 4 scales it).  Output weights ``W`` (rows = outputs, columns =
neurons) start at zero; at every call, with ``h`` the rates (Hz) for this call's input::

    Psi_raw = W h ;   Psi = clip(Psi_raw, -psi_limit, +psi_limit)
    W      <- W - learning_rate * dt / n_neurons * outer(E, h)

with ``E = desired - actual``: ``E_x = vx_des - vx`` (both longitudinal outputs),
``E_y = vy_des - vy_stride`` (both lateral outputs), ``E_pitch = pitch_des - pitch``
(torso outputs 0 and 1) and ``E_roll = roll_des - roll_stride`` (torso output 2).  So
a persistent ``vx > vx_des`` drives ``Psi_x`` positive, the same sign as its PD term.
Outputs that share an error signal keep identical weight rows forever, so the state
stores 4 rows (x, y, pitch, roll), not 7 (see :class:`RegulatorState`).  The output of
a call uses the weights from before that call's update (exactly nengo's ordering, in
which the delta computed in step k is applied at the start of step k+1).

Stride-averaged lateral and roll errors.  A biped's lateral velocity and torso roll
swing with the stance side every step: a sway of alternating sign that no offset can
remove.  The lateral and torso networks see ``vy`` and ``roll`` in their inputs, so
their presynaptic rates alternate in phase with the instantaneous errors
``vy_des - vy`` and ``roll_des - roll``, and PES integrates that correlation every
stride without bound (on the MuJoCo Cassie with a 20 kg torso the step-to-step
alternation of psi_roll grew linearly to 0.005 rad in 10 min).  The y and roll rows
therefore learn from the *stride* error: the core averages ``vy`` and ``roll`` over
the calls of each walking step (from one change of ``step_index`` to the next; the
call at which step_index changes belongs to the new step), and uses::

    vy_stride   = (mean_vy[k-1]   + mean_vy[k])   / 2     (last two completed steps)
    roll_stride = (mean_roll[k-1] + mean_roll[k]) / 2

A left and a right step average out the sway, so the stride error is what the
outputs can correct.  A step counts only if it was seen from its start (the segment
before the first change of step_index is not one), and the y and roll rows do not
learn until two steps are complete; the x and pitch rows, the PD terms and the
``error_*`` outputs are unchanged (instantaneous).  The accumulators advance at every
call, also while learning waits or adaptation is disabled.

Anti-windup (conditional integration): when ``|Psi_raw[j]| >= psi_limit`` and the
update would push ``Psi_raw[j]`` further out (``sign(-E_j) == sign(Psi_raw[j])``), the
update of row ``j`` is skipped for this call.  The weights therefore never wind up far
beyond what the limit lets through, and the output leaves saturation as soon as the
error reverses.  Rows that are not saturated learn exactly as plain PES.

``adaptation_enabled = False``: the networks are not evaluated, the weights are not
updated and Psi contributes exactly 0 (the diagnostic ``psi_*`` outputs are 0 too), so
the outputs are exactly the classic PD regulator.  The weights are kept in the state
and learning resumes from them when adaptation is re-enabled.

Performance.  One call evaluates 3 n neurons; it is a handful of numpy calls on whole
arrays: one product ``[x, 1] @ stacked`` for all currents (bias folded in), 6 passes
for the rates (computed as ``tau_rc * rate``, the factor folded into 4 scalars), one
(4, n) @ (n, 3) product for the readout and one (4, 3) @ (3, n) product for the update,
which allocates the new read-only weight array (the old one stays valid: states are
snapshots that share nothing mutable).
"""
from __future__ import annotations

import logging
import math
import struct
import zlib
from dataclasses import dataclass, field, fields
from numbers import Integral, Real

import numpy as np

try:
    from .avr_errors import InputError, ParameterError, StateError
except ImportError:  # inside the FMU the modules are top-level
    from avr_errors import InputError, ParameterError, StateError

__all__ = [
    "OUTPUT_JOINTS", "VarSpec", "PARAM_SPECS", "INPUT_SPECS", "OUTPUT_SPECS",
    "VELOCITY_LIMIT_MPS", "ANGLE_LIMIT_RAD", "RATE_LIMIT_RADPS",
    "FIXED_PARAMS", "TAU_RC", "TAU_REF", "MAX_RATE_RANGE_HZ", "INTERCEPT_RANGE",
    "RegulatorParams", "validate_params", "RegulatorInputs", "validate_inputs",
    "NetworkSpec", "Networks", "SplitMix64", "sphere_encoders", "build_networks",
    "lif_gain_bias", "neuron_rates",
    "network_inputs", "WEIGHT_ROWS", "RegulatorState", "initial_state", "step",
    "state_to_bytes", "state_from_bytes", "Regulator",
]

logger = logging.getLogger(__name__)

OUTPUT_JOINTS = (
    "swing_hip_pitch", "swing_knee", "swing_hip_roll",
    "stance_hip_roll", "stance_hip_pitch", "stance_knee",
)

#: LIFRate membrane time constant (s) and refractory period (s).
TAU_RC = 0.02
TAU_REF = 0.002
#: Distributions of the neurons' maximum rates (Hz, uniform) and intercepts (uniform,
#: in units of the unit-ball input), both nengo 4's Ensemble defaults.
MAX_RATE_RANGE_HZ = (200.0, 400.0)
INTERCEPT_RANGE = (-1.0, 0.9)

_INT32_MAX = 2**31 - 1


# --------------------------------------------------------------------------------------
# Variable declarations
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class VarSpec:
    """One declaration of an FMU variable (parameter, input or output).

    ``min``/``max`` are inclusive bounds (``None`` = unbounded); ``default`` is the FMI
    start value; ``unit`` is a plain unit string ("m/s", "rad", "rad/s", "s", "1", ...).
    """

    name: str
    type: str  # "Real" | "Integer" | "Boolean"
    default: float | int | bool | None
    min: float | None
    max: float | None
    unit: str
    causality: str  # "parameter" | "input" | "output"
    variability: str  # "tunable" | "fixed" | "continuous" | "discrete"
    description: str


def _p(name, default, lo, hi, unit, description, type="Real", variability="tunable"):
    return VarSpec(name, type, default, lo, hi, unit, "parameter", variability, description)


_GAIN = (-5.0, 5.0)
_SIGN_NOTE = ("; negative values flip the sign for plants whose joint convention is the "
              "opposite one")

PARAM_SPECS: tuple[VarSpec, ...] = (
    _p("Kp_x", 0.1, *_GAIN, "rad.s/m",
       "Longitudinal P gain: swing hip pitch offset per m/s of (vx - vx_des), "
       "rad/(m/s), in [-5, 5]; 0.1 is tuned on the MuJoCo Cassie (0.25 oscillates step to "
       "step)" + _SIGN_NOTE),
    _p("Kd_x", 0.0, *_GAIN, "rad.s/m",
       "Longitudinal D gain: swing hip pitch offset per m/s change of vx between two "
       "walking steps, rad/(m/s), in [-5, 5]" + _SIGN_NOTE),
    _p("Kp_y", 0.1, *_GAIN, "rad.s/m",
       "Lateral P gain: swing hip roll offset per m/s of (vy - vy_des), rad/(m/s), "
       "in [-5, 5]" + _SIGN_NOTE),
    _p("Kd_y", 0.0, *_GAIN, "rad.s/m",
       "Lateral D gain: swing hip roll offset per m/s change of vy between two walking "
       "steps, rad/(m/s), in [-5, 5]" + _SIGN_NOTE),
    _p("Kp_pitch", 0.0, *_GAIN, "1",
       "Torso pitch P gain: stance hip pitch offset per rad of (pitch - pitch_des), "
       "rad/rad, in [-5, 5]; 0 by default (the plant's stance controller stabilises "
       "the torso)"),
    _p("Kd_pitch", 0.0, *_GAIN, "s",
       "Torso pitch D gain: stance hip pitch offset per rad/s of pitch_rate, "
       "rad/(rad/s), in [-5, 5]; 0 by default"),
    _p("Kp_roll", 0.0, *_GAIN, "1",
       "Torso roll P gain: stance hip roll offset per rad of (roll - roll_des), "
       "rad/rad, in [-5, 5]; 0 by default"),
    _p("Kd_roll", 0.0, *_GAIN, "s",
       "Torso roll D gain: stance hip roll offset per rad/s of roll_rate, "
       "rad/(rad/s), in [-5, 5]; 0 by default"),
    _p("pitch_des", 0.0, -0.5, 0.5, "rad", "Desired torso pitch, rad, in [-0.5, 0.5]"),
    _p("roll_des", 0.0, -0.5, 0.5, "rad", "Desired torso roll, rad, in [-0.5, 0.5]"),
    _p("learning_rate", 1e-6, 0.0, 1e-3, "1",
       "PES learning rate kappa (nengo 4 convention: W -= kappa dt/n outer(E, h), "
       "h in Hz), in [0, 1e-3]; the default 1e-6 moves Psi by ~0.05 rad in ~10 s of "
       "a constant 0.3 m/s velocity error; 0 freezes the weights"),
    _p("psi_limit", 0.3, 0.0, 1.0, "rad",
       "Saturation of every network output Psi (before psi_gain), rad, in [0, 1]; "
       "saturated outputs stop integrating outward (anti-windup)"),
    _p("learn_from_step", 1, 0, _INT32_MAX, "1",
       "The networks learn only while step_index >= learn_from_step, in [0, 2147483647]; "
       "the default 1 waits for the first completed walking step (before it there is no "
       "step-averaged velocity vx[k] to learn from); 0 learns from the first call. Psi "
       "is still applied while learning waits", type="Integer"),
    _p("psi_gain_swing_hip_pitch", 1.0, *_GAIN, "1",
       "Gain of Psi_x[0] on delta_swing_hip_pitch, in [-5, 5]; 0 switches it off"),
    _p("psi_gain_swing_knee", 1.0, *_GAIN, "1",
       "Gain of Psi_x[1] on delta_swing_knee, in [-5, 5]; 0 switches it off"),
    _p("psi_gain_swing_hip_roll", 1.0, *_GAIN, "1",
       "Gain of Psi_y[0] on delta_swing_hip_roll, in [-5, 5]; 0 switches it off"),
    _p("psi_gain_stance_hip_roll", 1.0, *_GAIN, "1",
       "Gain of Psi_y[1] and Psi_torso[2] on delta_stance_hip_roll, in [-5, 5]; "
       "0 switches them off"),
    _p("psi_gain_stance_hip_pitch", 1.0, *_GAIN, "1",
       "Gain of Psi_torso[0] on delta_stance_hip_pitch, in [-5, 5]; 0 switches it off"),
    _p("psi_gain_stance_knee", 1.0, *_GAIN, "1",
       "Gain of Psi_torso[1] on delta_stance_knee, in [-5, 5]; 0 switches it off"),
    _p("adaptation_enabled", True, None, None, "1",
       "If false: no learning and Psi contributes 0 (exactly the classic PD "
       "regulator); the learned weights are kept and used again when re-enabled",
       type="Boolean"),
    _p("velocity_scale_mps", 1.5, 0.05, 10.0, "m/s",
       "Velocities are divided by this before entering the longitudinal/lateral "
       "networks (then radially projected into the unit ball), m/s, in [0.05, 10]",
       variability="fixed"),
    _p("angle_scale_rad", 0.3, 0.01, 3.2, "rad",
       "Torso pitch/roll are divided by this before entering the torso network, rad, "
       "in [0.01, 3.2]", variability="fixed"),
    _p("rate_scale_radps", 2.0, 0.01, 50.0, "rad/s",
       "Torso pitch/roll rates are divided by this before entering the torso network, "
       "rad/s, in [0.01, 50]", variability="fixed"),
    _p("n_neurons", 1000, 1, 10000, "1",
       "Neurons per network (three networks), in [1, 10000]", type="Integer",
       variability="fixed"),
    _p("seed", 0, 0, _INT32_MAX, "1",
       "Seed of the random encoders, max rates and intercepts, in [0, 2147483647]; "
       "same seed -> identical networks", type="Integer", variability="fixed"),
    _p("delta_limit_rad", 1.0, 0.0, math.pi, "rad",
       "Bound on each of the six joint offsets delta_*, rad, in [0, 3.14159]: an offset "
       "beyond +-delta_limit_rad is clipped to it (a safety net against a runaway "
       "regulator, not part of the method). The default 1 rad never engages in the "
       "paper's suite (largest |delta| there 0.152 rad) nor with default gains inside "
       "the declared input ranges of a walking robot (the networks add at most "
       "2 psi_limit = 0.6 rad); 0 makes every offset 0"),
)


def _i(name, unit, description, type="Real", variability="continuous", default=0.0,
       lo=None, hi=None):
    return VarSpec(name, type, default, lo, hi, unit, "input", variability, description)


#: Declared physical ranges of the inputs (the FMU refuses values outside them, naming the
#: range).  Generous on purpose: Cassie's record speed is about 4 m/s and the walking
#: envelope is below 1.5 m/s, so +-10 m/s only excludes nonsense (a master bug, a sensor
#: fault, 1e308); +-pi rad is the range of the plant's Euler angles; +-100 rad/s is
#: about three times a typical IMU gyro's full scale (2000 deg/s).
VELOCITY_LIMIT_MPS = 10.0
ANGLE_LIMIT_RAD = math.pi
RATE_LIMIT_RADPS = 100.0
_V, _A, _W = (-VELOCITY_LIMIT_MPS, VELOCITY_LIMIT_MPS), (-ANGLE_LIMIT_RAD, ANGLE_LIMIT_RAD), \
    (-RATE_LIMIT_RADPS, RATE_LIMIT_RADPS)

INPUT_SPECS: tuple[VarSpec, ...] = (
    _i("vx", "m/s", "Measured forward (longitudinal) velocity of the pelvis, m/s, in [-10, 10]",
       lo=_V[0], hi=_V[1]),
    _i("vy", "m/s", "Measured lateral velocity of the pelvis, m/s, in [-10, 10]", lo=_V[0], hi=_V[1]),
    _i("vx_des", "m/s", "Desired forward velocity, m/s, in [-10, 10]", lo=_V[0], hi=_V[1]),
    _i("vy_des", "m/s", "Desired lateral velocity, m/s, in [-10, 10]", lo=_V[0], hi=_V[1]),
    _i("pitch", "rad", "Measured torso pitch, rad, in [-pi, pi]", lo=_A[0], hi=_A[1]),
    _i("roll", "rad", "Measured torso roll, rad, in [-pi, pi]", lo=_A[0], hi=_A[1]),
    _i("pitch_rate", "rad/s", "Measured torso pitch rate, rad/s, in [-100, 100]", lo=_W[0], hi=_W[1]),
    _i("roll_rate", "rad/s", "Measured torso roll rate, rad/s, in [-100, 100]", lo=_W[0], hi=_W[1]),
    _i("step_index", "1",
       "Walking step counter from the plant, >= 0; the longitudinal and lateral PD "
       "terms are recomputed whenever it changes and held otherwise",
       type="Integer", variability="discrete", default=0, lo=0, hi=_INT32_MAX),
)


def _o(name, unit, description, lo=None, hi=None):
    return VarSpec(name, "Real", 0.0, lo, hi, unit, "output", "continuous", description)


_DELTA = " clipped to +-delta_limit_rad, rad"
OUTPUT_SPECS: tuple[VarSpec, ...] = (
    _o("delta_swing_hip_pitch", "rad", "Swing hip pitch offset: PD_x + g Psi_x[0]," + _DELTA, *_A),
    _o("delta_swing_knee", "rad", "Swing knee offset: g Psi_x[1]," + _DELTA, *_A),
    _o("delta_swing_hip_roll", "rad", "Swing hip roll offset: PD_y + g Psi_y[0]," + _DELTA, *_A),
    _o("delta_stance_hip_roll", "rad",
       "Stance hip roll offset: PD_roll + g Psi_y[1] + g Psi_torso[2]," + _DELTA, *_A),
    _o("delta_stance_hip_pitch", "rad",
       "Stance hip pitch offset: PD_pitch + g Psi_torso[0]," + _DELTA, *_A),
    _o("delta_stance_knee", "rad", "Stance knee offset: g Psi_torso[1]," + _DELTA, *_A),
    _o("psi_x", "rad", "Diagnostic: saturated network output Psi_x[0] (before gain), rad"),
    _o("psi_y", "rad", "Diagnostic: saturated network output Psi_y[0] (before gain), rad"),
    _o("psi_pitch", "rad",
       "Diagnostic: saturated network output Psi_torso[0] (before gain), rad"),
    _o("psi_roll", "rad",
       "Diagnostic: saturated network output Psi_torso[2] (before gain), rad"),
    _o("error_vx", "m/s", "vx - vx_des, m/s"),
    _o("error_vy", "m/s", "vy - vy_des, m/s"),
    _o("error_pitch", "rad", "pitch - pitch_des, rad"),
    _o("error_roll", "rad", "roll - roll_des, rad"),
)

_PARAM_BY_NAME = {s.name: s for s in PARAM_SPECS}
#: Parameters that define the networks and cannot change once a regulator exists.
FIXED_PARAMS = tuple(s.name for s in PARAM_SPECS if s.variability == "fixed")
_OUTPUT_NAMES = tuple(s.name for s in OUTPUT_SPECS)
_REAL_INPUT_SPECS = tuple(s for s in INPUT_SPECS if s.type == "Real")


def _fmt_range(spec: VarSpec) -> str:
    def f(v):
        return repr(int(v)) if spec.type == "Integer" else f"{v:g}"
    return f"[{f(spec.min)}, {f(spec.max)}]"


def _check_param(spec: VarSpec, value) -> tuple[object, str | None]:
    """Return ``(normalised value, problem or None)`` for one parameter value."""
    if spec.type == "Boolean":
        if isinstance(value, (bool, np.bool_)):
            return bool(value), None
        return value, f"{spec.name} = {value!r}: must be a bool (true/false)"
    if spec.type == "Integer":
        ok = isinstance(value, Integral) and not isinstance(value, (bool, np.bool_))
        if ok and spec.min <= value <= spec.max:
            return int(value), None
        return value, f"{spec.name} = {value!r}: must be an integer in {_fmt_range(spec)}"
    ok = isinstance(value, Real) and not isinstance(value, (bool, np.bool_))
    if ok:
        v = float(value)
        if math.isfinite(v) and spec.min <= v <= spec.max:
            return v, None
    return value, f"{spec.name} = {value!r}: must be a finite number in {_fmt_range(spec)}"


# --------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------
def _d(name):
    return _PARAM_BY_NAME[name].default


@dataclass(frozen=True)
class RegulatorParams:
    """All regulator parameters (names, units, ranges and defaults: ``PARAM_SPECS``).

    Construction validates every field (raising :class:`ParameterError` that lists every
    problem at once) and normalises numbers: Real fields become ``float``, Integer
    fields ``int``, Boolean fields ``bool``.  Use :meth:`replace` for a modified copy.
    """

    Kp_x: float = _d("Kp_x")  # rad/(m/s)
    Kd_x: float = _d("Kd_x")  # rad/(m/s)
    Kp_y: float = _d("Kp_y")  # rad/(m/s)
    Kd_y: float = _d("Kd_y")  # rad/(m/s)
    Kp_pitch: float = _d("Kp_pitch")  # rad/rad
    Kd_pitch: float = _d("Kd_pitch")  # rad/(rad/s)
    Kp_roll: float = _d("Kp_roll")  # rad/rad
    Kd_roll: float = _d("Kd_roll")  # rad/(rad/s)
    pitch_des: float = _d("pitch_des")  # rad
    roll_des: float = _d("roll_des")  # rad
    learning_rate: float = _d("learning_rate")  # PES kappa (nengo convention)
    psi_limit: float = _d("psi_limit")  # rad
    learn_from_step: int = _d("learn_from_step")  # walking steps
    psi_gain_swing_hip_pitch: float = _d("psi_gain_swing_hip_pitch")
    psi_gain_swing_knee: float = _d("psi_gain_swing_knee")
    psi_gain_swing_hip_roll: float = _d("psi_gain_swing_hip_roll")
    psi_gain_stance_hip_roll: float = _d("psi_gain_stance_hip_roll")
    psi_gain_stance_hip_pitch: float = _d("psi_gain_stance_hip_pitch")
    psi_gain_stance_knee: float = _d("psi_gain_stance_knee")
    adaptation_enabled: bool = _d("adaptation_enabled")
    velocity_scale_mps: float = _d("velocity_scale_mps")  # m/s
    angle_scale_rad: float = _d("angle_scale_rad")  # rad
    rate_scale_radps: float = _d("rate_scale_radps")  # rad/s
    n_neurons: int = _d("n_neurons")
    seed: int = _d("seed")
    delta_limit_rad: float = _d("delta_limit_rad")  # rad

    def __post_init__(self):
        problems = []
        for spec in PARAM_SPECS:
            value, problem = _check_param(spec, getattr(self, spec.name))
            if problem is None:
                object.__setattr__(self, spec.name, value)
            else:
                problems.append(problem)
        if problems:
            raise ParameterError(problems)

    def replace(self, **changes) -> "RegulatorParams":
        """Return a validated copy with ``changes`` applied (ParameterError if invalid)."""
        unknown = sorted(set(changes) - set(_PARAM_BY_NAME))
        values = {s.name: getattr(self, s.name) for s in PARAM_SPECS}
        values.update({k: v for k, v in changes.items() if k in _PARAM_BY_NAME})
        problems = [f"{k}: unknown parameter (known: {', '.join(_PARAM_BY_NAME)})"
                    for k in unknown]
        try:
            new = RegulatorParams(**values)
        except ParameterError as exc:
            raise ParameterError(problems + exc.problems) from None
        if problems:
            raise ParameterError(problems)
        return new

    def as_dict(self) -> dict[str, float | int | bool]:
        """Field name -> value, in ``PARAM_SPECS`` order."""
        return {s.name: getattr(self, s.name) for s in PARAM_SPECS}


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
    problems = [p for s in PARAM_SPECS
                for p in [_check_param(s, getattr(params, s.name, None))[1]] if p]
    if problems:
        raise ParameterError(problems)


# --------------------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------------------
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
    for spec in _REAL_INPUT_SPECS:
        v = getattr(inputs, spec.name)
        if (isinstance(v, Real) and not isinstance(v, (bool, np.bool_))
                and spec.min <= v <= spec.max):  # false for nan
            continue
        raise InputError(f"{spec.name} = {v!r}: must be a finite number in {_fmt_range(spec)} "
                         f"({spec.unit})")
    s = inputs.step_index
    if not (isinstance(s, Integral) and not isinstance(s, (bool, np.bool_))
            and 0 <= s <= _INT32_MAX):
        raise InputError(f"step_index = {s!r}: must be an integer in [0, {_INT32_MAX}]")


# --------------------------------------------------------------------------------------
# Networks
# --------------------------------------------------------------------------------------
def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def lif_gain_bias(max_rates, intercepts, tau_rc: float = TAU_RC,
                  tau_ref: float = TAU_REF) -> tuple[np.ndarray, np.ndarray]:
    """Gain and bias (per neuron, unit input current) of LIFRate neurons.

    The LIF rate for input current J > 1 is ``1 / (tau_ref + tau_rc ln(1 + 1/(J-1)))``.
    A neuron with intercept c (rate 0 at ``e.x = c``, i.e. ``J = 1``) and maximum rate
    m (Hz, reached at ``e.x = 1``) needs ``J_max - 1 = 1 / expm1((1/m - tau_ref) /
    tau_rc)``, hence ``gain = (J_max - 1) / (1 - c)`` and ``bias = 1 - gain c``.
    Requires ``m < 1/tau_ref`` and ``c < 1``.
    """
    max_rates = np.asarray(max_rates, dtype=np.float64)
    intercepts = np.asarray(intercepts, dtype=np.float64)
    if np.any(max_rates >= 1.0 / tau_ref) or np.any(max_rates <= 0):
        raise ValueError("max_rates must be in (0, 1/tau_ref) Hz")
    if np.any(intercepts >= 1.0):
        raise ValueError("intercepts must be < 1")
    j_max_minus_1 = 1.0 / np.expm1((1.0 / max_rates - tau_ref) / tau_rc)
    gain = j_max_minus_1 / (1.0 - intercepts)
    bias = 1.0 - gain * intercepts
    return gain, bias


@dataclass(frozen=True, eq=False)
class NetworkSpec:
    """One fixed hidden layer: ``n`` LIFRate neurons on a ``d``-dimensional input.

    ``encoders`` (n, d) unit vectors, ``max_rates`` (n,) Hz, ``intercepts`` (n,),
    ``gain`` (n,) and ``bias`` (n,) in units of the neuron's threshold current, and
    ``scaled_encoders = encoders * gain[:, None]`` (radius 1).  Input current for a
    unit-ball input x: ``J = scaled_encoders @ x + bias``.  Arrays are read-only.
    """

    name: str
    encoders: np.ndarray
    max_rates: np.ndarray
    intercepts: np.ndarray
    gain: np.ndarray
    bias: np.ndarray
    scaled_encoders: np.ndarray

    @property
    def n_neurons(self) -> int:
        return self.encoders.shape[0]

    @property
    def dimensions(self) -> int:
        return self.encoders.shape[1]


class SplitMix64:
    """The networks' random numbers: SplitMix64 streams, one per (seed, network, field).

    SplitMix64 (Steele, Lea and Flood, OOPSLA 2014; the generator Vigna recommends for
    seeding xoshiro) is a counter passed through a 64-bit finaliser, so the C core
    (``native/avr_model.c``) computes exactly the same integers.  All arithmetic is on
    unsigned 64-bit integers modulo 2**64::

        mix(z) = z3 ^ (z3 >> 31),  z3 = (z2 ^ (z2 >> 27)) * 0x94D049BB133111EB,
                                   z2 = (z  ^ (z  >> 30)) * 0xBF58476D1CE4E5B9
        key(seed, net, field) = mix(16 seed + 4 net + field)
        draw i (i = 0, 1, ...) = mix(key + (i + 1) * 0x9E3779B97F4A7C15)
        uniform_i = (draw_i >> 11) * 2**-53                     in [0, 1), exact

    ``net`` is 0 (longitudinal), 1 (lateral), 2 (torso); ``field`` is 0 (encoders),
    1 (max rates), 2 (intercepts).  Distinct (seed, net, field) give distinct keys
    (``mix`` is a bijection), so the nine streams of a seed never overlap in practice.
    """

    GAMMA = 0x9E3779B97F4A7C15
    _M1 = np.uint64(0xBF58476D1CE4E5B9)
    _M2 = np.uint64(0x94D049BB133111EB)

    def __init__(self, seed: int, net: int, field: int):
        z = np.array([16 * seed + 4 * net + field], dtype=np.uint64)
        self.key = int(self.mix(z)[0])
        self.next_index = 0

    @classmethod
    def mix(cls, z: np.ndarray) -> np.ndarray:
        """The SplitMix64 finaliser on a uint64 array (wrapping arithmetic)."""
        z = (z ^ (z >> np.uint64(30))) * cls._M1
        z = (z ^ (z >> np.uint64(27))) * cls._M2
        return z ^ (z >> np.uint64(31))

    def uniform(self, count: int) -> np.ndarray:
        """The next ``count`` doubles in [0, 1) of this stream."""
        i = np.arange(self.next_index + 1, self.next_index + count + 1, dtype=np.uint64)
        self.next_index += count
        z = np.uint64(self.key) + i * np.uint64(self.GAMMA)
        return (self.mix(z) >> np.uint64(11)).astype(np.float64) * 2.0**-53


def sphere_encoders(stream: SplitMix64, n: int, d: int) -> np.ndarray:
    """``n`` unit vectors uniform on the sphere in R^d, by rejection from the cube.

    Candidate j takes the next d uniforms u of ``stream``, ``v = 2 u - 1`` (exact);
    ``r2 = (((v0 v0 + v1 v1) + v2 v2) + ...)`` in that order; it is accepted iff
    ``0 < r2 <= 1`` and becomes ``v / sqrt(r2)``.  Only correctly rounded IEEE
    operations, in a fixed order, so the C core gets the same bits.
    """
    accepted, have = [], 0
    while have < n:  # acceptance 79% (d = 2) or 31% (d = 4): one batch, rarely two
        # The field-0 stream serves the encoders only, so candidates drawn past the
        # last accepted one are simply never used: the accepted sequence is the one a
        # candidate-by-candidate loop (the C core's) finds.
        v = 2.0 * stream.uniform(((n - have) * 4 + 16) * d).reshape(-1, d) - 1.0
        r2 = v[:, 0] * v[:, 0]
        for j in range(1, d):
            r2 = r2 + v[:, j] * v[:, j]
        take = np.flatnonzero((r2 > 0.0) & (r2 <= 1.0))[:n - have]
        accepted.append(v[take] / np.sqrt(r2[take])[:, None])
        have += len(take)
    return np.concatenate(accepted) if accepted else np.zeros((0, d))


def _make_network(name: str, n: int, d: int, seed: int, net: int) -> NetworkSpec:
    enc = sphere_encoders(SplitMix64(seed, net, 0), n, d)
    lo, hi = MAX_RATE_RANGE_HZ
    max_rates = lo + (hi - lo) * SplitMix64(seed, net, 1).uniform(n)
    lo, hi = INTERCEPT_RANGE
    intercepts = lo + (hi - lo) * SplitMix64(seed, net, 2).uniform(n)
    gain, bias = lif_gain_bias(max_rates, intercepts)
    scaled = enc * gain[:, None]
    return NetworkSpec(name, _readonly(enc), _readonly(max_rates), _readonly(intercepts),
                       _readonly(gain), _readonly(bias), _readonly(scaled))


#: Rows of the stored weight matrix, one per error signal (see RegulatorState); they
#: read the rates of the longitudinal, lateral, torso and torso network respectively.
WEIGHT_ROWS = ("x", "y", "pitch", "roll")
_N_ROWS = 4
_DIMS = (2, 2, 4)


@dataclass(frozen=True, eq=False)
class Networks:
    """The three fixed hidden layers, built from ``(n_neurons, seed)`` only.

    ``longitudinal`` (input [vx, vx_des]), ``lateral`` ([vy, vy_des]) and ``torso``
    ([pitch, roll, pitch_rate, roll_rate]), all scaled into the unit ball.

    ``stacked`` ((9, 3n), read-only) lets :func:`step` get all 3n neurons' ``J - 1`` in
    one product ``[x_long, x_lat, x_torso, 1] @ stacked``: rows 0-7 hold the transposed
    scaled encoders block-diagonally, row 8 holds ``bias - 1``.
    """

    n_neurons: int
    seed: int
    longitudinal: NetworkSpec
    lateral: NetworkSpec
    torso: NetworkSpec
    stacked: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        n = self.n_neurons
        nets = (self.longitudinal, self.lateral, self.torso)
        enc_t = np.zeros((sum(_DIMS) + 1, 3 * n))
        col = 0
        for k, net in enumerate(nets):
            if net.encoders.shape != (n, _DIMS[k]):
                raise ValueError(f"{net.name}: encoders must have shape {(n, _DIMS[k])}")
            enc_t[col:col + _DIMS[k], k * n:(k + 1) * n] = net.scaled_encoders.T
            col += _DIMS[k]
        enc_t[-1] = np.concatenate([net.bias for net in nets]) - 1.0
        object.__setattr__(self, "stacked", _readonly(enc_t))

    def __iter__(self):
        return iter((self.longitudinal, self.lateral, self.torso))


def build_networks(params: RegulatorParams) -> Networks:
    """Build the three networks from ``params.n_neurons`` and ``params.seed`` only.

    Network k (0 longitudinal, 1 lateral, 2 torso) takes its encoders, maximum rates
    and intercepts from its own :class:`SplitMix64` streams (encoders uniform on the
    sphere by :func:`sphere_encoders`; ``max_rate = 200 + 200 u``, ``intercept = -1 +
    1.9 u``), so the networks are independent of each other, identical for identical
    seeds, and the same in the C core (bit for bit on glibc, whose ``expm1`` the gains
    go through; another libm may differ in the last bit of a gain).
    """
    n, seed = int(params.n_neurons), int(params.seed)
    nets = [_make_network(name, n, d, seed, k)
            for k, (name, d) in enumerate(zip(("longitudinal", "lateral", "torso"), _DIMS))]
    logger.debug("built 3 networks of %d LIFRate neurons (seed %d)", n, seed)
    return Networks(n, seed, *nets)


def _lif_rates(j: np.ndarray) -> np.ndarray:
    """LIFRate rates (Hz) for ``j = J - 1`` (J: input current); 0 where j <= 0.

    Works in place on ``j`` (pass a temporary).  Inactive neurons get a harmless
    positive j (avoids inf, whose special-value path in log1p is slow) and are zeroed
    by the numerator of the last division; active ones are evaluated operation by
    operation as nengo does, ``1 / (tau_ref + tau_rc * log1p(1 / j))``.
    """
    active = j > 0.0
    np.maximum(j, 1e-300, out=j)
    np.divide(1.0, j, out=j)
    np.log1p(j, out=j)
    j *= TAU_RC
    j += TAU_REF
    np.divide(active, j, out=j)  # True -> 1.0, False -> 0.0 (exactly 0 Hz)
    return j


def _lif_rates_times_tau_rc(j: np.ndarray) -> np.ndarray:
    """``tau_rc *`` LIFRate rate (dimensionless) for ``j = J - 1``, in place.

    ``tau_rc r = 1 / (tau_ref / tau_rc + log1p(1 / j))``: one pass fewer than
    :func:`_lif_rates`; :func:`step` folds the factor ``1 / tau_rc`` into four scalars.
    Equal to ``tau_rc * _lif_rates(j)`` to ~1e-16 relative.
    """
    active = j > 0.0
    np.maximum(j, 1e-300, out=j)
    np.divide(1.0, j, out=j)
    np.log1p(j, out=j)
    j += _TAU_RATIO
    np.divide(active, j, out=j)
    return j


_TAU_RATIO = TAU_REF / TAU_RC
_INV_TAU_RC = 1.0 / TAU_RC


def neuron_rates(net: NetworkSpec, x) -> np.ndarray:
    """LIFRate rates (Hz, shape (n,)) of ``net`` for a scaled input ``x`` (shape (d,)).

    ``x`` is used as given (callers map it into the unit ball, see
    :func:`network_inputs`); the current is ``scaled_encoders @ x + bias``.
    """
    x = np.asarray(x, dtype=np.float64).reshape(net.dimensions)
    return _lif_rates((net.scaled_encoders @ x + net.bias) - 1.0)


def _ball2(a: float, b: float) -> tuple[float, float]:
    r = math.hypot(a, b)
    if r > 1.0:
        return a / r, b / r
    return a, b


def _scaled_values(vx, vx_des, vy, vy_des, pitch, roll, pitch_rate, roll_rate,
                   params: RegulatorParams) -> list[float]:
    """The 8 network inputs (see :func:`network_inputs`) followed by a 1.0."""
    vs, sa, sr = params.velocity_scale_mps, params.angle_scale_rad, params.rate_scale_radps
    a, b = _ball2(vx / vs, vx_des / vs)
    c, d = _ball2(vy / vs, vy_des / vs)
    p, r = pitch / sa, roll / sa
    pr, rr = pitch_rate / sr, roll_rate / sr
    n = math.hypot(p, r, pr, rr)
    if n > 1.0:
        p, r, pr, rr = p / n, r / n, pr / n, rr / n
    return [a, b, c, d, p, r, pr, rr, 1.0]  # the trailing 1 multiplies the bias row


def network_inputs(inputs: RegulatorInputs,
                   params: RegulatorParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three networks' inputs for ``inputs``: scaled and radially projected into
    the unit ball (longitudinal (2,), lateral (2,), torso (4,), dimensionless)."""
    validate_inputs(inputs)
    x = np.array(_scaled_values(
        float(inputs.vx), float(inputs.vx_des), float(inputs.vy), float(inputs.vy_des),
        float(inputs.pitch), float(inputs.roll), float(inputs.pitch_rate),
        float(inputs.roll_rate), params)[:8])
    return x[0:2], x[2:4], x[4:8]


# --------------------------------------------------------------------------------------
# State
# --------------------------------------------------------------------------------------
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
    * Stride accumulators (the y and roll learning signal, see the module docstring):
      ``stride_boundaries`` step_index changes seen, the first call counting as one
      (saturates at 4; a completed step needs 2, learning needs 4, i.e. two completed
      steps); ``stride_calls``, ``stride_sum_vy`` (m/s) and ``stride_sum_roll`` (rad):
      number of calls and sums of vy and roll in the current step;
      ``vy_mean_prev``/``vy_mean_last`` (m/s) and ``roll_mean_prev``/``roll_mean_last``
      (rad): the means over the last two completed steps.
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

    def __post_init__(self):
        w = self.weights
        if not (type(w) is np.ndarray and not w.flags.writeable and w.flags.owndata
                and w.dtype == np.float64 and w.flags.c_contiguous):
            w = np.array(w, dtype=np.float64, copy=True, order="C")
            w.flags.writeable = False
            object.__setattr__(self, "weights", w)
        if w.ndim != 2 or w.shape[0] != _N_ROWS:
            raise StateError(f"weights must have shape (4, n_neurons), got {w.shape}")

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
        return all(np.array_equal(getattr(self, f.name), getattr(other, f.name))
                   for f in fields(self))

    __hash__ = None


def initial_state(params: RegulatorParams, networks: Networks) -> RegulatorState:
    """State before the first call: zero weights, no step seen yet."""
    if networks.n_neurons != params.n_neurons:
        raise ParameterError(f"n_neurons = {params.n_neurons!r}: networks were built "
                             f"with {networks.n_neurons}")
    return RegulatorState(weights=_readonly(np.zeros((_N_ROWS, params.n_neurons))),
                          network_key=_network_key(params))


def _network_key(params: RegulatorParams) -> tuple[int, float, float, float]:
    return (params.seed, params.velocity_scale_mps, params.angle_scale_rad,
            params.rate_scale_radps)


# --------------------------------------------------------------------------------------
# Step
# --------------------------------------------------------------------------------------
def step(state: RegulatorState, inputs: RegulatorInputs, dt: float,
         params: RegulatorParams, networks: Networks) -> tuple[RegulatorState, dict]:
    """Advance the regulator by one call of length ``dt`` (s, finite, > 0).

    Pure: ``state`` is not modified.  Returns ``(new_state, outputs)`` with ``outputs``
    a dict of python floats keyed by the ``OUTPUT_SPECS`` names.  Raises
    :class:`InputError` naming the bad input (or ``dt``).  ``params`` must be the ones
    the ``networks`` were built from (fixed fields); tunable fields may change between
    calls.
    """
    if type(dt) is not float:
        if isinstance(dt, (bool, np.bool_)) or not isinstance(dt, Real):
            raise InputError(f"dt = {dt!r}: must be a finite number > 0 (s)")
        dt = float(dt)
    if not 0.0 < dt < math.inf:  # also rejects nan
        raise InputError(f"dt = {dt!r}: must be a finite number > 0 (s)")
    vx, vy, vx_des, vy_des = inputs.vx, inputs.vy, inputs.vx_des, inputs.vy_des
    pitch, roll, pitch_rate, roll_rate = (inputs.pitch, inputs.roll, inputs.pitch_rate,
                                          inputs.roll_rate)
    si = inputs.step_index
    # Fast path for the usual all-python-float inputs inside their declared ranges (the
    # comparisons are false for nan); anything else goes through the full check (which
    # raises naming the input and its range) and is converted to float.
    V, A, W = VELOCITY_LIMIT_MPS, ANGLE_LIMIT_RAD, RATE_LIMIT_RADPS
    if not (type(vx) is float and type(vy) is float and type(vx_des) is float
            and type(vy_des) is float and type(pitch) is float and type(roll) is float
            and type(pitch_rate) is float and type(roll_rate) is float
            and type(si) is int and 0 <= si <= _INT32_MAX
            and -V <= vx <= V and -V <= vy <= V and -V <= vx_des <= V and -V <= vy_des <= V
            and -A <= pitch <= A and -A <= roll <= A
            and -W <= pitch_rate <= W and -W <= roll_rate <= W):
        validate_inputs(inputs)
        vx, vy, vx_des, vy_des = float(vx), float(vy), float(vx_des), float(vy_des)
        pitch, roll = float(pitch), float(roll)
        pitch_rate, roll_rate = float(pitch_rate), float(roll_rate)
        si = int(si)
    P = params
    weights = state.weights
    n = networks.n_neurons
    if weights.shape[1] != n:
        raise StateError(f"state has n_neurons = {weights.shape[1]}, networks have {n}")

    # --- PD terms ---------------------------------------------------------------------
    if si != state.last_step_index:
        first = state.last_step_index < 0
        vx_prev = vx if first else state.vx_at_step
        vy_prev = vy if first else state.vy_at_step
        pd_x = P.Kp_x * (vx - vx_des) + P.Kd_x * (vx - vx_prev)
        pd_y = P.Kp_y * (vy - vy_des) + P.Kd_y * (vy - vy_prev)
        vx_at, vy_at = vx, vy
    else:
        pd_x, pd_y = state.pd_x, state.pd_y
        vx_at, vy_at = state.vx_at_step, state.vy_at_step
    stride = _advance_stride(state, si, vy, roll)
    pd_pitch = P.Kp_pitch * (pitch - P.pitch_des) + P.Kd_pitch * pitch_rate
    pd_roll = P.Kp_roll * (roll - P.roll_des) + P.Kd_roll * roll_rate

    # --- adaptive networks ------------------------------------------------------------
    if P.adaptation_enabled:
        x9 = np.array(_scaled_values(vx, vx_des, vy, vy_des, pitch, roll, pitch_rate,
                                     roll_rate, P))
        # s3 = tau_rc * rates (3, n): the factor 1/tau_rc goes into scalars below
        s3 = _lif_rates_times_tau_rc(x9 @ networks.stacked).reshape(3, n)
        # Psi_raw[j] = weights[j] . rates[net(j)]: the needed entries of the (4, 3)
        # product (one BLAS call beats gathering a (4, n) copy of the rates).
        prod = (weights @ s3.T).ravel().tolist()
        k = _INV_TAU_RC
        raw = [prod[0] * k, prod[4] * k, prod[8] * k, prod[11] * k]  # x, y, pitch, roll
        lim = P.psi_limit
        psi = [lim if r > lim else (-lim if r < -lim else r) for r in raw]  # rad
        if P.learning_rate != 0.0 and si >= P.learn_from_step:
            alpha = -P.learning_rate * dt / n * _INV_TAU_RC  # per unit of s3
            err = _learning_errors(stride, vx, vx_des, vy_des, pitch, P)
            # The update moves raw[j] by -learning_rate dt/n E_j |rates|^2, i.e. in the
            # direction of -E_j.  Anti-windup: skip rows at or beyond the limit that it
            # would push further out (raw[j] and -E_j of the same sign).
            coef = [0.0 if (r >= lim or r <= -lim) and r * e < 0.0 else alpha * e
                    for r, e in zip(raw, err)]
            if any(coef):  # else nothing to learn: keep (share) the read-only array
                # (4, 3) @ (3, n) = each row's coefficient times its network's rates,
                # exactly (the zero terms add exact zeros); one BLAS call.  Setting 4
                # scalars is much cheaper than np.array of a nested list.
                sel = np.zeros((4, 3))
                sel[0, 0], sel[1, 1], sel[2, 2], sel[3, 2] = coef
                new_w = sel @ s3
                new_w += weights
                new_w.flags.writeable = False
                weights = new_w
        px, py, pp, pr = psi
        g_roll = P.psi_gain_stance_hip_roll
        out = {
            "delta_swing_hip_pitch": pd_x + P.psi_gain_swing_hip_pitch * px,
            "delta_swing_knee": P.psi_gain_swing_knee * px + 0.0,  # -0.0 -> 0.0
            "delta_swing_hip_roll": pd_y + P.psi_gain_swing_hip_roll * py,
            "delta_stance_hip_roll": pd_roll + g_roll * py + g_roll * pr,
            "delta_stance_hip_pitch": pd_pitch + P.psi_gain_stance_hip_pitch * pp,
            "delta_stance_knee": P.psi_gain_stance_knee * pp + 0.0,
            "psi_x": px, "psi_y": py, "psi_pitch": pp, "psi_roll": pr,
        }
    else:
        out = {
            "delta_swing_hip_pitch": pd_x,
            "delta_swing_knee": 0.0,
            "delta_swing_hip_roll": pd_y,
            "delta_stance_hip_roll": pd_roll,
            "delta_stance_hip_pitch": pd_pitch,
            "delta_stance_knee": 0.0,
            "psi_x": 0.0, "psi_y": 0.0, "psi_pitch": 0.0, "psi_roll": 0.0,
        }
    hi = P.delta_limit_rad
    lo = 0.0 - hi  # (not -hi: a limit of 0 gives +0.0, never -0.0)
    for name in _DELTA_NAMES:  # the safety bound; values inside it pass unchanged, bit for bit
        v = out[name]
        if v > hi:
            out[name] = hi
        elif v < lo:
            out[name] = lo
    out["error_vx"] = vx - vx_des
    out["error_vy"] = vy - vy_des
    out["error_pitch"] = pitch - P.pitch_des
    out["error_roll"] = roll - P.roll_des
    # All operands are python floats here (validated params are floats, inputs were
    # converted), so every output is a python float.
    new_state = _new_state(RegulatorState)
    new_state.__dict__.update(  # skips __post_init__: weights are owned and read-only
        weights=weights, last_step_index=si, vx_at_step=vx_at, vy_at_step=vy_at,
        pd_x=pd_x, pd_y=pd_y, n_calls=state.n_calls + 1, time_s=state.time_s + dt,
        network_key=state.network_key, **stride)
    return new_state, out


def _advance_stride(state: RegulatorState, si: int, vy: float, roll: float) -> dict:
    """The stride accumulators after a call with ``step_index = si``: at a change of
    step_index the step that ends is closed (its means shifted in) if it was seen from
    its start, and this call starts the new step's sums."""
    if si == state.last_step_index:
        return dict(
            stride_boundaries=state.stride_boundaries, stride_calls=state.stride_calls + 1,
            stride_sum_vy=state.stride_sum_vy + vy, stride_sum_roll=state.stride_sum_roll + roll,
            vy_mean_prev=state.vy_mean_prev, vy_mean_last=state.vy_mean_last,
            roll_mean_prev=state.roll_mean_prev, roll_mean_last=state.roll_mean_last)
    nb = state.stride_boundaries
    vy_means = (state.vy_mean_prev, state.vy_mean_last)
    roll_means = (state.roll_mean_prev, state.roll_mean_last)
    if nb >= 2:  # the step that ends now began at a change of step_index: complete
        c = float(state.stride_calls)
        vy_means = (state.vy_mean_last, state.stride_sum_vy / c)
        roll_means = (state.roll_mean_last, state.stride_sum_roll / c)
    return dict(
        stride_boundaries=min(nb + 1, _STRIDE_READY), stride_calls=1,
        stride_sum_vy=vy, stride_sum_roll=roll,
        vy_mean_prev=vy_means[0], vy_mean_last=vy_means[1],
        roll_mean_prev=roll_means[0], roll_mean_last=roll_means[1])


def _learning_errors(stride: dict, vx: float, vx_des: float, vy_des: float, pitch: float,
                     P: RegulatorParams) -> tuple[float, float, float, float]:
    """PES errors (x, y, pitch, roll): instantaneous for x and pitch, stride-averaged
    for y and roll (0, i.e. no learning, until two steps are complete)."""
    if stride["stride_boundaries"] >= _STRIDE_READY:
        e_y = vy_des - 0.5 * (stride["vy_mean_prev"] + stride["vy_mean_last"])
        e_roll = P.roll_des - 0.5 * (stride["roll_mean_prev"] + stride["roll_mean_last"])
    else:
        e_y = e_roll = 0.0
    return (vx_des - vx, e_y, P.pitch_des - pitch, e_roll)


#: stride_boundaries at which two steps are complete (the first call, then 3 changes)
_STRIDE_READY = 4


_new_state = object.__new__
_DELTA_NAMES = tuple(f"delta_{joint}" for joint in OUTPUT_JOINTS)


# --------------------------------------------------------------------------------------
# Serialisation
# --------------------------------------------------------------------------------------
_MAGIC = b"AVRSTATE"
_VERSION = 2  # 2: the stride accumulators (version 1 had none)
# magic, version, n_rows, n_neurons, seed, velocity/angle/rate scales,
# last_step_index, n_calls, vx_at_step, vy_at_step, pd_x, pd_y, time_s,
# stride_boundaries, stride_calls, stride_sum_vy, stride_sum_roll,
# vy_mean_prev, vy_mean_last, roll_mean_prev, roll_mean_last
_HEADER = struct.Struct("<8sHHII3dqq5dqq6d")
_STRIDE_FLOATS = ("stride_sum_vy", "stride_sum_roll", "vy_mean_prev", "vy_mean_last",
                  "roll_mean_prev", "roll_mean_last")
_CRC = struct.Struct("<I")


def state_to_bytes(state: RegulatorState) -> bytes:
    """Serialise ``state`` deterministically (no pickle).

    Layout (little-endian): header ``_HEADER`` (magic ``b"AVRSTATE"``, format version
    uint16, number of weight rows (4) uint16, n_neurons uint32, then ``network_key``:
    seed uint32 and the three input scales float64 (NaN = unknown), then
    last_step_index int64, n_calls int64, vx_at_step, vy_at_step, pd_x, pd_y, time_s
    float64, stride_boundaries int64, stride_calls int64, stride_sum_vy,
    stride_sum_roll, vy_mean_prev, vy_mean_last, roll_mean_prev, roll_mean_last
    float64), the weights as 4*n float64 in C order, then a CRC-32 (uint32) of
    everything before it.  Identical states give identical bytes.
    """
    if state.network_key is not None:
        seed, *scales = state.network_key
    else:
        seed, scales = 0, (math.nan,) * 3
    head = _HEADER.pack(_MAGIC, _VERSION, _N_ROWS, state.n_neurons, seed, *scales,
                        state.last_step_index, state.n_calls, state.vx_at_step,
                        state.vy_at_step, state.pd_x, state.pd_y, state.time_s,
                        state.stride_boundaries, state.stride_calls,
                        *(getattr(state, name) for name in _STRIDE_FLOATS))
    body = head + state.weights.astype("<f8", copy=False).tobytes(order="C")
    return body + _CRC.pack(zlib.crc32(body))


def state_from_bytes(blob: bytes, params: RegulatorParams) -> RegulatorState:
    """Inverse of :func:`state_to_bytes` for a regulator with ``params``.

    Raises :class:`StateError` on a non-bytes blob, bad magic, unknown version, wrong
    size or checksum, an n_neurons (or, when recorded, seed or input scale) different
    from ``params``, or invalid contents (non-finite values, step index < -1).
    """
    if not isinstance(blob, (bytes, bytearray, memoryview)):
        raise StateError(f"state blob must be bytes, got {type(blob).__name__}")
    blob = bytes(blob)
    if len(blob) < 10 + _CRC.size:
        raise StateError(f"state blob too short ({len(blob)} bytes)")
    magic, version = struct.unpack_from("<8sH", blob, 0)
    if magic != _MAGIC:
        raise StateError(f"not a regulator state (magic {magic!r}, expected {_MAGIC!r})")
    if version != _VERSION:
        raise StateError(f"unsupported state format version {version} (this build reads "
                         f"{_VERSION}; version 1 states predate the stride-averaged "
                         f"lateral/roll learning and cannot be continued)")
    if len(blob) < _HEADER.size + _CRC.size:
        raise StateError(f"state blob too short ({len(blob)} bytes)")
    (magic, version, n_rows, n, seed, vs, sa, sr, last, n_calls, vx_at, vy_at, pd_x,
     pd_y, time_s, boundaries, stride_calls, *stride) = _HEADER.unpack_from(blob, 0)
    if n_rows != _N_ROWS:
        raise StateError(f"state has {n_rows} weight rows, expected {_N_ROWS}")
    expected = _HEADER.size + 8 * _N_ROWS * n + _CRC.size
    if len(blob) != expected:
        raise StateError(f"state blob has {len(blob)} bytes, expected {expected} "
                         f"for n_neurons = {n}")
    (crc,) = _CRC.unpack_from(blob, len(blob) - _CRC.size)
    if zlib.crc32(blob[:-_CRC.size]) != crc:
        raise StateError("state blob checksum mismatch (corrupted)")
    if n != params.n_neurons:
        raise StateError(f"state has n_neurons = {n}, regulator has {params.n_neurons}")
    key = None
    if not (math.isnan(vs) and math.isnan(sa) and math.isnan(sr)):
        key = (seed, vs, sa, sr)
        if seed != params.seed:
            raise StateError(f"state was saved with seed = {seed}, regulator has "
                             f"{params.seed}")
        here = _network_key(params)[1:]
        if (vs, sa, sr) != here:
            raise StateError(f"state was saved with input scales {(vs, sa, sr)}, "
                             f"regulator has {here}")
    w = np.frombuffer(blob, dtype="<f8", count=_N_ROWS * n, offset=_HEADER.size)
    w = w.astype(np.float64).reshape(_N_ROWS, n)  # owned, native-endian copy
    scalars = (vx_at, vy_at, pd_x, pd_y, time_s, *stride)
    if not (np.all(np.isfinite(w)) and all(math.isfinite(v) for v in scalars)):
        raise StateError("state contains non-finite values")
    if last < -1 or n_calls < 0:
        raise StateError(f"state has invalid counters (last_step_index = {last}, "
                         f"n_calls = {n_calls})")
    if not (0 <= boundaries <= _STRIDE_READY and stride_calls >= 0
            and (boundaries == 0) == (stride_calls == 0)):
        raise StateError(f"state has invalid stride counters (stride_boundaries = "
                         f"{boundaries}, stride_calls = {stride_calls})")
    w.flags.writeable = False
    return RegulatorState(w, last, vx_at, vy_at, pd_x, pd_y, n_calls, time_s, key,
                          boundaries, stride_calls, *stride)


# --------------------------------------------------------------------------------------
# Convenience wrapper
# --------------------------------------------------------------------------------------
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
        fixed = [f"{k} = {v!r}: fixed parameter, cannot change after instantiation"
                 for k, v in changes.items()
                 if k in FIXED_PARAMS and v != getattr(self.params, k)]
        if fixed:
            raise ParameterError(fixed)
        self.params = self.params.replace(**changes)

    def reset(self) -> None:
        """Back to the initial state (zero weights, no step seen)."""
        self.state = initial_state(self.params, self.networks)

    def save_state(self) -> bytes:
        return state_to_bytes(self.state)

    def load_state(self, blob: bytes) -> None:
        self.state = state_from_bytes(blob, self.params)
