"""The regulator FMU's variables: one declaration each, and the one check of a value.

``PARAM_SPECS``, ``INPUT_SPECS`` and ``OUTPUT_SPECS`` declare every FMU variable once
(name, type, start value, inclusive range, unit, causality, variability, description);
the slave, the model description, the documentation page, the C headers and the
scenario files all derive from them.  :func:`check_param` is the one rule that decides
whether a value is legal for a declaration (and normalises it); :func:`format_range`
is the one way a range is written in a message.  Units are SI (m/s, rad, rad/s, s).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from numbers import Integral, Real

import numpy as np

__all__ = [
    "OUTPUT_JOINTS", "VarSpec", "PARAM_SPECS", "INPUT_SPECS", "OUTPUT_SPECS",
    "VELOCITY_LIMIT_MPS", "ANGLE_LIMIT_RAD", "RATE_LIMIT_RADPS", "INT32_MAX", "SETTLED_STEPS_MAX",
    "FIXED_PARAMS", "PARAM_BY_NAME", "OUTPUT_NAMES", "OFFSET_NAMES", "PYTHON_TYPES",
    "TIERS", "METHOD", "TUNING", "EXPERIMENTAL", "PARAM_REQUIRES",
    "format_range", "check_param", "requires_problems",
]

#: The six joints that get an offset, in the order of the ``delta_*`` outputs.
OUTPUT_JOINTS = (
    "swing_hip_pitch", "swing_knee", "swing_hip_roll",
    "stance_hip_roll", "stance_hip_pitch", "stance_knee",
)

#: Largest FMI Integer (int32): the upper bound of the integer variables.
INT32_MAX = 2**31 - 1
#: Largest learn_settled_steps; the state's count of settled step changes stops at it.
SETTLED_STEPS_MAX = 1000

#: The Python type an FMI variable's value is converted to, by FMI type name.
PYTHON_TYPES = {"Real": float, "Integer": int, "Boolean": bool}


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
    tier: str | None = None  # a parameter's tier (TIERS); None for inputs and outputs

    @property
    def fmi_description(self) -> str:
        """The description as the model descriptions write it: the tier first, if any."""
        return self.description if self.tier is None else f"[{self.tier}] {self.description}"


#: The parameter tiers, each with what it holds (the documentation pages and docs/fmus.md say it).
METHOD, TUNING, EXPERIMENTAL = "method", "tuning", "experimental"
TIERS = {
    METHOD: "the paper's method: its gains, learning rate, networks and output switches",
    TUNING: "gains, rates and limits this implementation adds, which a user may tune",
    EXPERIMENTAL: "research switches, off by default",
}


def _param(name, tier, default, lo, hi, unit, description, type="Real", variability="tunable"):
    return VarSpec(name, type, default, lo, hi, unit, "parameter", variability, description, tier)


_GAIN_RANGE = (-5.0, 5.0)
_SIGN_NOTE = ("; negative values flip the sign for plants whose joint convention is the "
              "opposite one")

PARAM_SPECS: tuple[VarSpec, ...] = (
    _param("Kp_x", METHOD, 0.1, *_GAIN_RANGE, "rad.s/m",
           "Longitudinal P gain: swing hip pitch offset per m/s of (vx - vx_des), "
           "rad/(m/s), in [-5, 5]; 0.1 is tuned on the MuJoCo Cassie (0.25 oscillates step to "
           "step)" + _SIGN_NOTE),
    _param("Kd_x", METHOD, 0.0, *_GAIN_RANGE, "rad.s/m",
           "Longitudinal D gain: swing hip pitch offset per m/s change of vx between two "
           "walking steps, rad/(m/s), in [-5, 5]" + _SIGN_NOTE),
    _param("Kp_y", METHOD, 0.1, *_GAIN_RANGE, "rad.s/m",
           "Lateral P gain: swing hip roll offset per m/s of (vy - vy_des), rad/(m/s), "
           "in [-5, 5]" + _SIGN_NOTE),
    _param("Kd_y", METHOD, 0.0, *_GAIN_RANGE, "rad.s/m",
           "Lateral D gain: swing hip roll offset per m/s change of vy between two walking "
           "steps, rad/(m/s), in [-5, 5]" + _SIGN_NOTE),
    _param("Kp_pitch", METHOD, 0.0, *_GAIN_RANGE, "1",
           "Torso pitch P gain: stance hip pitch offset per rad of (pitch - pitch_des), "
           "rad/rad, in [-5, 5]; 0 by default (the plant's stance controller stabilises "
           "the torso)"),
    _param("Kd_pitch", METHOD, 0.0, *_GAIN_RANGE, "s",
           "Torso pitch D gain: stance hip pitch offset per rad/s of pitch_rate, "
           "rad/(rad/s), in [-5, 5]; 0 by default"),
    _param("Kp_roll", METHOD, 0.0, *_GAIN_RANGE, "1",
           "Torso roll P gain: stance hip roll offset per rad of (roll - roll_des), "
           "rad/rad, in [-5, 5]; 0 by default"),
    _param("Kd_roll", METHOD, 0.0, *_GAIN_RANGE, "s",
           "Torso roll D gain: stance hip roll offset per rad/s of roll_rate, "
           "rad/(rad/s), in [-5, 5]; 0 by default"),
    _param("pitch_des", METHOD, 0.0, -0.5, 0.5, "rad", "Desired torso pitch, rad, in [-0.5, 0.5]"),
    _param("roll_des", METHOD, 0.0, -0.5, 0.5, "rad", "Desired torso roll, rad, in [-0.5, 0.5]"),
    _param("learning_rate", METHOD, 1e-6, 0.0, 1e-3, "1",
           "PES learning rate kappa (nengo 4 convention: W -= kappa dt/n outer(E, h), "
           "h in Hz), in [0, 1e-3]; the default 1e-6 moves Psi by ~0.05 rad in ~10 s of "
           "a constant 0.3 m/s velocity error; 0 freezes the weights"),
    _param("psi_limit", TUNING, 0.3, 0.0, 1.0, "rad",
           "Saturation of every network output Psi (before psi_gain), rad, in [0, 1]; "
           "saturated outputs stop integrating outward (anti-windup)"),
    _param("learn_from_step", TUNING, 12, 0, INT32_MAX, "1",
           "The networks learn only while step_index >= learn_from_step, in [0, 2147483647]; "
           "the default 12 waits out the start-up (the step-averaged vx is 0 until the first "
           "completed step and lags after it; the gait ramps to the command at 0.5 m/s^2, "
           "to 1 m/s by about step 8): until then the offsets are PD-only's; 1 learns from "
           "the first completed step, 0 from the first call. Psi is still applied while "
           "learning waits", type="Integer"),
    _param("psi_gain_swing_hip_pitch", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_x[0] on delta_swing_hip_pitch, in [-5, 5]; 0 switches it off"),
    _param("psi_gain_swing_knee", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_x[1] on delta_swing_knee, in [-5, 5]; 0 switches it off"),
    _param("psi_gain_swing_hip_roll", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_y[0] on delta_swing_hip_roll, in [-5, 5]; 0 switches it off"),
    _param("psi_gain_stance_hip_roll", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_y[1] and Psi_torso[2] on delta_stance_hip_roll, in [-5, 5]; "
           "0 switches them off"),
    _param("psi_gain_stance_hip_pitch", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_torso[0] on delta_stance_hip_pitch, in [-5, 5]; 0 switches it off"),
    _param("psi_gain_stance_knee", METHOD, 1.0, *_GAIN_RANGE, "1",
           "Gain of Psi_torso[1] on delta_stance_knee, in [-5, 5]; 0 switches it off"),
    _param("adaptation_enabled", METHOD, True, None, None, "1",
           "If false: no learning and Psi contributes 0 (exactly the classic PD "
           "regulator); the learned weights are kept and used again when re-enabled",
           type="Boolean"),
    _param("velocity_scale_mps", METHOD, 1.5, 0.05, 10.0, "m/s",
           "Velocities are divided by this before entering the longitudinal/lateral "
           "networks (then radially projected into the unit ball), m/s, in [0.05, 10]",
           variability="fixed"),
    _param("angle_scale_rad", METHOD, 0.3, 0.01, 3.2, "rad",
           "Torso pitch/roll are divided by this before entering the torso network, rad, "
           "in [0.01, 3.2]", variability="fixed"),
    _param("rate_scale_radps", METHOD, 2.0, 0.01, 50.0, "rad/s",
           "Torso pitch/roll rates are divided by this before entering the torso network, "
           "rad/s, in [0.01, 50]", variability="fixed"),
    _param("n_neurons", METHOD, 1000, 1, 10000, "1",
           "Neurons per network (three networks), in [1, 10000]", type="Integer",
           variability="fixed"),
    _param("seed", METHOD, 0, 0, INT32_MAX, "1",
           "Seed of the random encoders, max rates and intercepts, in [0, 2147483647]; "
           "same seed -> identical networks", type="Integer", variability="fixed"),
    _param("delta_limit_rad", TUNING, 1.0, 0.0, math.pi, "rad",
           "Bound on each of the six joint offsets delta_*, rad, in [0, 3.14159]: an offset "
           "beyond +-delta_limit_rad is clipped to it (a safety net against a runaway "
           "regulator, not part of the method). The default 1 rad never engages in the "
           "paper's suite (largest |delta| there 0.152 rad) nor with default gains inside "
           "the declared input ranges of a walking robot (the networks add at most "
           "2 psi_limit = 0.6 rad); 0 makes every offset 0"),
    # The remedy against parameter drift (docs/adaptation.md): acts only on calls that learn;
    # at 0 the rule is the paper's plain PES.
    _param("leakage_per_s", TUNING, 0.01, 0.0, 1.0, "1/s",
           "Leakage (sigma-modification) of the learned weights toward zero, 1/s, in [0, 1]: "
           "every call that learns first scales every weight by (1 - leakage_per_s dt) (by 0 "
           "if leakage_per_s dt >= 1); 0 switches it off (the paper's plain rule)"),
    _param("leakage_mode", TUNING, 1, 0, 1, "1",
           "Which part of the weights leaks, in [0, 1]: 0 every weight (sigma-modification: "
           "each row decays toward zero, its output with it); 1 only the part of each row "
           "orthogonal to its current presynaptic rates (the row's output at this call is "
           "kept; what the current state does not use decays at leakage_per_s)",
           type="Integer"),
    _param("command_accel_limit_mps2", TUNING, 0.0, 0.0, 10.0, "m/s2",
           "Rate limit of the regulator's own command reference, m/s^2, in [0, 10]: the "
           "reference follows (vx_des, vy_des) changing by at most command_accel_limit_mps2 dt "
           "per call (from the measured velocity at the first call), and the longitudinal PD "
           "term, error and network input use the reference averaged over the last completed "
           "step (as vx is), the lateral ones the reference now; 0.5 matches the walking "
           "controller's gait ramp, so a command step is not answered twice (once by the gait, "
           "once by an offset against an error the gait is already removing); 0 switches it "
           "off (vx_des and vy_des are used as they come, the paper's rule)"),
    _param("learn_settled_steps", EXPERIMENTAL, 0, 0, SETTLED_STEPS_MAX, "1",
           "The velocity networks (x, y) learn only once the command reference has been "
           "settled over this many step_index changes, in [0, 1000]: settled means the "
           "reference equals the command (vx_des, vy_des) and so does its mean over the last "
           "completed step (each within 1e-9 m/s); a moving reference resets the count. While "
           "they wait their learning errors are 0 (leakage still acts) and the "
           "torso networks learn as usual. Errors during a command change are mostly the "
           "gait's own transient, which a learned offset carries over to the next command; "
           "0 switches it off (the paper's rule: learn at every call)", type="Integer"),
    _param("learn_ramp_max_mps2", EXPERIMENTAL, 0.0, 0.0, 10.0, "m/s2",
           "How fast the command may ramp and still count as settled for learn_settled_steps, "
           "m/s2, in [0, 10]: with a > 0, settled means the reference equals the command (the "
           "acceleration limit is not limiting) and it moved by at most a dt on each axis since "
           "the last call, so a slow ramp (which the gait follows without a transient) is "
           "learned from while a command step, a fast ramp or the limiter's catch-up resets the "
           "count; 0 keeps the rule of learn_settled_steps (the reference and its step mean "
           "must equal the command: no learning while the command moves); a > 0 requires "
           "learn_settled_steps > 0"),
)


def _input(name, unit, description, lo=None, hi=None, type="Real", variability="continuous",
           default=0.0):
    return VarSpec(name, type, default, lo, hi, unit, "input", variability, description)


#: Declared physical ranges of the inputs (the FMU refuses values outside them, naming the
#: range).  Generous on purpose: Cassie's record speed is about 4 m/s and the walking
#: envelope is below 1.5 m/s, so +-10 m/s only excludes nonsense (a master bug, a sensor
#: fault, 1e308); +-pi rad is the range of the plant's Euler angles; +-100 rad/s is
#: about three times a typical IMU gyro's full scale (2000 deg/s).
VELOCITY_LIMIT_MPS = 10.0
ANGLE_LIMIT_RAD = math.pi
RATE_LIMIT_RADPS = 100.0
_VELOCITY_RANGE = (-VELOCITY_LIMIT_MPS, VELOCITY_LIMIT_MPS)
_ANGLE_RANGE = (-ANGLE_LIMIT_RAD, ANGLE_LIMIT_RAD)
_RATE_RANGE = (-RATE_LIMIT_RADPS, RATE_LIMIT_RADPS)

INPUT_SPECS: tuple[VarSpec, ...] = (
    _input("vx", "m/s", "Measured forward (longitudinal) velocity of the pelvis, m/s, in [-10, 10]",
           *_VELOCITY_RANGE),
    _input("vy", "m/s", "Measured lateral velocity of the pelvis, m/s, in [-10, 10]", *_VELOCITY_RANGE),
    _input("vx_des", "m/s", "Desired forward velocity, m/s, in [-10, 10]", *_VELOCITY_RANGE),
    _input("vy_des", "m/s", "Desired lateral velocity, m/s, in [-10, 10]", *_VELOCITY_RANGE),
    _input("pitch", "rad", "Measured torso pitch, rad, in [-pi, pi]", *_ANGLE_RANGE),
    _input("roll", "rad", "Measured torso roll, rad, in [-pi, pi]", *_ANGLE_RANGE),
    _input("pitch_rate", "rad/s", "Measured torso pitch rate, rad/s, in [-100, 100]", *_RATE_RANGE),
    _input("roll_rate", "rad/s", "Measured torso roll rate, rad/s, in [-100, 100]", *_RATE_RANGE),
    _input("step_index", "1",
           "Walking step counter from the plant, >= 0; the longitudinal and lateral PD "
           "terms are recomputed whenever it changes and held otherwise",
           type="Integer", variability="discrete", default=0, lo=0, hi=INT32_MAX),
)


def _output(name, unit, description, lo=None, hi=None):
    return VarSpec(name, "Real", 0.0, lo, hi, unit, "output", "continuous", description)


_CLIPPED = " clipped to +-delta_limit_rad, rad"
OUTPUT_SPECS: tuple[VarSpec, ...] = (
    _output("delta_swing_hip_pitch", "rad", "Swing hip pitch offset: PD_x + g Psi_x[0]," + _CLIPPED, *_ANGLE_RANGE),
    _output("delta_swing_knee", "rad", "Swing knee offset: g Psi_x[1]," + _CLIPPED, *_ANGLE_RANGE),
    _output("delta_swing_hip_roll", "rad", "Swing hip roll offset: PD_y + g Psi_y[0]," + _CLIPPED, *_ANGLE_RANGE),
    _output("delta_stance_hip_roll", "rad",
            "Stance hip roll offset: PD_roll + g Psi_y[1] + g Psi_torso[2]," + _CLIPPED, *_ANGLE_RANGE),
    _output("delta_stance_hip_pitch", "rad",
            "Stance hip pitch offset: PD_pitch + g Psi_torso[0]," + _CLIPPED, *_ANGLE_RANGE),
    _output("delta_stance_knee", "rad", "Stance knee offset: g Psi_torso[1]," + _CLIPPED, *_ANGLE_RANGE),
    _output("psi_x", "rad", "Diagnostic: saturated network output Psi_x[0] (before gain), rad"),
    _output("psi_y", "rad", "Diagnostic: saturated network output Psi_y[0] (before gain), rad"),
    _output("psi_pitch", "rad",
            "Diagnostic: saturated network output Psi_torso[0] (before gain), rad"),
    _output("psi_roll", "rad",
            "Diagnostic: saturated network output Psi_torso[2] (before gain), rad"),
    _output("error_vx", "m/s", "vx - vx_des, m/s"),
    _output("error_vy", "m/s", "vy - vy_des, m/s"),
    _output("error_pitch", "rad", "pitch - pitch_des, rad"),
    _output("error_roll", "rad", "roll - roll_des, rad"),
)


PARAM_BY_NAME = {spec.name: spec for spec in PARAM_SPECS}
#: Parameters that act only together: ``(a, b)``, a nonzero ``a`` requires a nonzero ``b`` (``a``
#: has no effect without it).  Checked with every parameter set (:func:`requires_problems`).
PARAM_REQUIRES = (("learn_ramp_max_mps2", "learn_settled_steps"),)
#: Parameters that define the networks and cannot change once a regulator exists.
FIXED_PARAMS = tuple(spec.name for spec in PARAM_SPECS if spec.variability == "fixed")
OUTPUT_NAMES = tuple(spec.name for spec in OUTPUT_SPECS)
#: The six joint-offset outputs, in ``OUTPUT_JOINTS`` order.
OFFSET_NAMES = tuple(f"delta_{joint}" for joint in OUTPUT_JOINTS)


def format_range(spec: VarSpec) -> str:
    """``[min, max]`` of a bounded variable as messages write it (``[-5, 5]``, ``[0, 2147483647]``)."""
    def bound(value):
        return repr(int(value)) if spec.type == "Integer" else f"{value:g}"
    return f"[{bound(spec.min)}, {bound(spec.max)}]"


def _is_bool(value) -> bool:
    return isinstance(value, (bool, np.bool_))


def check_param(spec: VarSpec, value) -> tuple[object, str | None]:
    """``(normalised value, None)`` if ``value`` is legal for ``spec``, else ``(value, problem)``.

    Boolean: a bool.  Integer: an integer (not a bool) in ``[min, max]``.  Real: a finite
    real number (not a bool) in ``[min, max]``, normalised to ``float``.  The problem
    names the variable, the value and the allowed range, e.g.
    ``"Kp_x = nan: must be a finite number in [-5, 5]"``.
    """
    if spec.type == "Boolean":
        if _is_bool(value):
            return bool(value), None
        return value, f"{spec.name} = {value!r}: must be a bool (true/false)"
    if spec.type == "Integer":
        if isinstance(value, Integral) and not _is_bool(value) and spec.min <= value <= spec.max:
            return int(value), None
        return value, f"{spec.name} = {value!r}: must be an integer in {format_range(spec)}"
    if isinstance(value, Real) and not _is_bool(value):
        try:
            number = float(value)
        except OverflowError:  # an int beyond float's range: out of range, not a crash
            number = math.inf
        if math.isfinite(number) and spec.min <= number <= spec.max:
            return number, None
    return value, f"{spec.name} = {value!r}: must be a finite number in {format_range(spec)}"


def requires_problems(values) -> list[str]:
    """Every ``PARAM_REQUIRES`` rule that the parameter values ``values`` (name -> value)
    break, each naming both fields, e.g. ``"learn_ramp_max_mps2 = 0.25 requires
    learn_settled_steps > 0 (it is 0)"``."""
    return [f"{a} = {values[a]!r} requires {b} > 0 (it is {values[b]!r})"
            for a, b in PARAM_REQUIRES if values[a] != 0 and values[b] == 0]
