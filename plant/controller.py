"""Nominal HZD-style walking controller for the MuJoCo Cassie plant.

Structure (Castillo et al., IROS 2020, nominal controller with our own gait)
---------------------------------------------------------------------------
Joint-level virtual constraints ``y = q - (y_d(tau, alpha) + delta_y)`` on the ten
motor joints are driven to zero by joint PD evaluated by MuJoCo at every plant
step (2 kHz, the model's 0.5 ms step): :meth:`CassiePhysics.configure_pd_servos`
makes each motor a servo ``tau = kp (q_d - q) + kd (qd_d - qd) + tau_ff`` clipped
to ``gear * ctrlrange`` (112.5/112.5/195.2/195.2/45 N m for hip roll/yaw/pitch,
knee, foot).  The Python layer (:meth:`NominalController.update`) refreshes the
targets ``q_d``, ``qd_d``, ``tau_ff`` every ``ControllerParams.control_substeps``
plant steps (default 4 = every 2 ms, 500 Hz); between refreshes the servo keeps
tracking at plant rate with fresh joint measurements.

* Phase ``tau = (t - t_step_start) / T`` with ``T`` the gait's step time; the step
  ends (stance switches, step index ``k`` += 1) once ``tau > switch_min_tau`` and
  the swing foot's normal force exceeds ``touchdown_force_n``, or at
  ``tau = switch_max_tau``.
* ``y_d`` are Bezier polynomials in ``tau``: the swing leg's absolute (world
  heading-frame) leg angle and lateral angle go from their lift-off values to the
  gait's landing values with the shape ``GaitParams.swing_shape``; the swing
  foot height above the ground follows ``GaitParams.swing_height``, the ground
  taken under the foot's target (the hip plus the leg's reach at the target
  angles), not under the hip, so on slopes the foot lands where the ground is; both are
  turned into hip-pitch/knee/hip-roll targets by the rigid-spring leg kinematics
  (:class:`LegKinematics`), subtracting the measured pelvis pitch/roll.  The
  swing foot is held level.  The stance hip pitch and hip roll hold the torso
  at ``torso_pitch_des``/0 (their constraint is on the torso angle), the stance
  knee holds the leg length ``stance_leg_length_m`` with a gravity feedforward,
  the stance foot is passive.
* Landing leg angle = ``asin(v T / 2L) + leg_angle_offset(v_des) + delta_swing_hip_pitch``
  with ``v`` the low-pass filtered measured forward speed (neutral point,
  ``neutral_point_blend = 1``): the nominal gait is speed-neutral and the
  per-speed offset from the gait library makes it settle at ``v_des``.  There is
  no integral action anywhere in the nominal controller, so a model change
  (torso mass, COM) leaves a steady-state speed error for the regulator.
* Heading and turning: the reference heading starts at the yaw at start and
  turns at the commanded yaw rate ``yaw_rate_des`` (rad/s, positive to the left)
  through the rate limit ``yaw_accel_limit_radps2``, and only while walking: at
  ``yaw_rate_ref``.  The
  stance hip yaw is a PD on the pelvis yaw about that reference (rate reference
  ``yaw_rate_ref``); the swing hip yaw lands the foot along the reference heading
  advanced by half a step, ``yaw_rate_ref * T / 2``, so that the stance hip yaw
  swings symmetrically about zero while the pelvis turns over it.  Speeds stay in
  the pelvis heading frame, so ``vx``/``vy`` mean the same when turning.
* The gait speed ``vx_ref``/``vy_ref`` follows the command ``vx_des``/``vy_des``
  through a rate limit (``accel_limit_mps2``).
* Start from rest: ``stand_time_s`` standing on both feet (COM fed back through
  the foot torques), ``shift_time_s`` shifting the pelvis over the first stance
  foot, then walking.  No velocity kick.

Regulator interface: six joint offsets (rad) and their sign conventions
-----------------------------------------------------------------------
Pitch > 0 is nose down, roll > 0 is left side up (see ``plant/cassie.py``).
``delta_*`` are mapped onto the joint of the leg currently in that role:

=========================  ===============================================================
``delta_swing_hip_pitch``  + moves the swing foot's landing point forward (decelerates the
                           next step).  Added to the swing leg's landing angle, blended
                           in with the swing Bezier so the landing hip pitch carries it.
``delta_swing_knee``       + extends the swing knee (foot lands further forward and
                           lower / earlier).  Added to the swing knee target, blended in.
``delta_swing_hip_roll``   + moves the swing foot toward +y (left, heading frame) for
                           either leg (both hip-roll axes point forward).  Blended in.
``delta_stance_hip_roll``  + rolls the torso toward negative roll: added to the stance
                           hip-roll target.
``delta_stance_hip_pitch`` + pitches the torso toward negative pitch (nose up):
                           subtracted from the stance hip-pitch target.
``delta_stance_knee``      + extends the stance knee (raises the pelvis): added to the
                           stance knee target.
=========================  ===============================================================

Regulator inputs (``CassieWalker.regulator_inputs``): ``vx`` is the
step-averaged forward velocity of the last *completed* step, ``vx[k]`` = pelvis
displacement along the heading over the whole step divided by its duration,
held constant during a step (0 until the first step completes);
``step_index = k``; ``vy`` is the heading-frame lateral pelvis velocity through a
first-order low-pass filter with time constant ``vy_filter_tau_s`` = 0.1 s (a
continuously filtered signal: the paper's mid-step average mixes the periodic
sway with the drift and made the lateral loop unstable); pitch/roll and their
rates as above.  Because ``fmu_src.core.avr_core`` samples and holds its lateral PD
once per step (like the longitudinal one), a held lateral term alone was unstable
here too (falls within 8-17 s at Kp_y = 0.3); the nominal controller therefore
closes the lateral sway loop itself, continuously, with the same filtered ``vy``:
landing lateral angle ``+= lateral_speed_gain * (vy - vy_ref)`` (0.3 rad per m/s,
proportional only), and the regulator's held lateral PD trims the drift.

All offsets are applied on top of the calibrated gait, so zero offsets at the
commanded speed give (on the nominal model) the commanded speed.

Recommended regulator defaults (measured with this plant and
``fmu_src.core.avr_core`` with adaptation off): ``Kp_x = 0.10`` rad/(m/s) (0.15 works
too; 0.25 oscillates step to step and falls within 4-12 s), ``Kd_x = 0`` (0.05 is
fine), ``Kp_y = 0.1`` rad/(m/s), ``Kd_y = 0``, torso gains 0 (the stance hip PD
already holds the torso).  These are ``fmu_src.core.avr_core.RegulatorParams``'
defaults; the gait calibration, the walking tests and the plant benchmark run
that core in-process with ``adaptation_enabled=False`` through
:func:`plant.sim.apply_regulator`.

Layout: the parameters are :class:`plant.controller_params.ControllerParams`, the leg
geometry and the Bezier curves :mod:`plant.kinematics`, the gaits :mod:`plant.gaits`.
This module is longer than 400 lines because this docstring is the controller's
reference (method, offset signs, regulator inputs); :meth:`NominalController.update`
is made of small steps: sense, phase, standing / stance / swing targets, servo writes.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Mapping, NamedTuple

import numpy as np

from plant.cassie import CassiePhysics
from plant.constants import MOTOR_JOINTS, OFFSET_NAMES, SIDES
from plant.controller_params import ControllerParams
from plant.gaits import GaitLibrary, GaitParams
from plant.kinematics import LegKinematics, bezier

log = logging.getLogger(__name__)


#: The neutral-point landing angle asin(v T / 2L) takes its argument clipped to +-this:
#: at most 30 degrees from vertical, beyond any speed the gait library covers.
MAX_STEP_SINE = 0.5
#: The swing leg length is the vertical hip-to-ankle drop over cos(pitch) cos(roll) of the
#: leg, that product floored here (leg angles beyond 60 degrees would stretch the leg).
MIN_LEG_COS = 0.5
#: The weight shift reaches its full distance after this fraction of ``shift_time_s``
#: (a smoothstep), then holds it until the first step.
SHIFT_RAMP_FRACTION = 0.7
#: Shortest weight-shift ramp, s (keeps the ramp finite for ``shift_time_s = 0``).
MIN_SHIFT_RAMP_S = 1e-3
#: Shortest step (s) counted for the step-averaged speed ``vx_step_avg``.
MIN_STEP_DURATION_S = 1e-6

#: Share of the torso PD and of the feedforwards each leg carries: both legs in double
#: support (standing, weight shift), the stance leg alone in single support.
DOUBLE_SUPPORT_SHARE = 0.5
SINGLE_SUPPORT_SHARE = 1.0


@dataclass
class _Targets:
    """Servo targets keyed by (side, motor joint): position (rad), velocity (rad/s),
    feedforward torque (N m) and gains (N m/rad, N m s/rad)."""

    q: dict = field(default_factory=dict)
    qd: dict = field(default_factory=dict)
    ff: dict = field(default_factory=dict)
    kp: dict = field(default_factory=dict)
    kd: dict = field(default_factory=dict)


class _Sensed(NamedTuple):
    """What one update measures: time (s), pelvis angles (rad) and rates (rad/s) in the
    heading frame, the heading error (rad), joint positions and velocities per side."""

    t: float
    pitch: float
    roll: float
    roll_rate: float
    pitch_rate: float
    yaw_rate: float
    yaw_err: float
    q: dict
    qd: dict


_Q_NAMES = MOTOR_JOINTS + ("tarsus",)


def _low_pass(filtered: float, value: float, dt: float, tau_s: float) -> float:
    """One step of a first-order low-pass filter with time constant ``tau_s`` over ``dt``."""
    a = dt / (tau_s + dt) if dt > 0 else 0.0
    return filtered + a * (value - filtered)


def _neutral_angle(speed_mps: float, step_time_s: float, leg_length_m: float) -> float:
    """Leg angle (rad) of the neutral point asin(v T / 2L), its argument clipped."""
    return math.asin(max(-MAX_STEP_SINE, min(MAX_STEP_SINE, speed_mps * step_time_s / (2 * leg_length_m))))


class NominalController:
    """Stance/swing state machine, Bezier virtual constraints and joint PD targets."""

    def __init__(self, phys: CassiePhysics, params: ControllerParams | None = None):
        self.phys = phys
        self.p = params or ControllerParams()
        self.kin = {s: LegKinematics(phys, s) for s in SIDES}
        legs = phys.legs
        qpos, la = phys.data.qpos, legs["left"].qadr
        #: Foot-level constant: hip pitch + knee + tarsus + foot at the standing pose.
        self.foot_flat_sum = float(qpos[la["hip-pitch"]] + qpos[la["knee"]]
                                   + qpos[la["tarsus"]] + qpos[la["foot"]])
        # Ankle height above ground when standing (m).
        self.ankle_height0 = 0.5 * (float(phys.foot_position("left")[2]) + float(phys.foot_position("right")[2]))
        self.offsets = {k: 0.0 for k in OFFSET_NAMES}
        self.gait = None
        #: Gait speed (m/s): the command ``vx_des``/``vy_des`` through the rate limiter.
        self.vx_ref = 0.0
        self.vy_ref = 0.0
        #: The commanded speed (m/s), as the regulator and the plant FMU name it.
        self.vx_des = self.vy_des = 0.0
        #: Turning rate of the reference heading (rad/s): the command ``yaw_rate_des`` through its rate limit.
        self.yaw_rate_ref = 0.0
        self.yaw_rate_des = 0.0
        self._gaits = GaitLibrary.uniform(GaitParams())
        self.mode = "stand"
        self.stance = self.p.first_stance
        self.step_index = 0
        self.t_step_start = 0.0
        self.tau = 0.0
        self.vx_step_avg = 0.0
        self.vy_filt = 0.0
        self.vx_filt = 0.0
        self._step_start_xy = phys.pelvis_position()[:2]
        self._swing_start = (0.0, 0.0)
        self._last_t = phys.time_s
        #: Heading held by the hip yaw joints (rad): the pelvis yaw at start.
        self.yaw_ref = phys.heading_yaw()
        self._act_ids = np.array([legs[s].act[j] for s in SIDES for j in MOTOR_JOINTS])
        self._q_idx = np.array([legs[s].qadr[j] for s in SIDES for j in _Q_NAMES])
        self._qd_idx = np.array([legs[s].dadr[j] for s in SIDES for j in MOTOR_JOINTS])
        self._kp = dict(zip(MOTOR_JOINTS, self.p.kp))
        self._kd = dict(zip(MOTOR_JOINTS, self.p.kd))
        #: (side, joint) keys in actuator-array order; default gains per key.
        self._keys = tuple((s, j) for s in SIDES for j in MOTOR_JOINTS)
        self._kp_all = {k: self._kp[k[1]] for k in self._keys}
        self._kd_all = {k: self._kd[k[1]] for k in self._keys}
        self._zeros = {k: 0.0 for k in self._keys}
        self._stance_knee = {s: self.kin[s].knee_for_length(self.p.stance_leg_length_m) for s in SIDES}
        phys.configure_pd_servos()
        self.update()

    # ----------------------------------------------------------- memory
    #: Everything the controller carries from one update to the next (the rest is fixed
    #: at construction from the model and the standing pose); the FMU state holds these.
    MEMORY_FIELDS = ("offsets", "vx_ref", "vy_ref", "vx_des", "vy_des", "yaw_rate_ref", "yaw_rate_des",
                     "mode", "stance", "step_index",
                     "t_step_start", "tau", "vx_step_avg", "vy_filt", "vx_filt",
                     "_step_start_xy", "_swing_start", "_last_t", "yaw_ref")

    #: The controller's modes, in the order it goes through them.
    MODES = ("stand", "shift", "walk")
    #: The largest step_index (the FMU's Integer output, a 32-bit int).
    MAX_STEP_INDEX = 2**31 - 1

    def memory_problems(self, memory: Mapping, time_s: float) -> list[str]:
        """Why ``memory`` is not what :meth:`memory` can have returned at simulated time ``time_s``
        (every problem, each naming the field and its allowed values), or [] if it is.

        Numbers must be finite and at most ``CassiePhysics.MAX_STATE_VALUE`` in magnitude (MuJoCo's
        own divergence bound), the mode and stance one of their values, the step times ordered
        ``0 <= t_step_start <= _last_t <= time_s``, the phase in ``[0, switch_max_tau]``."""
        bound = self.phys.MAX_STATE_VALUE
        if not isinstance(memory, Mapping):
            return [f"controller memory is a {type(memory).__name__}, not a table"]
        problems = [f"controller memory lacks {n}" for n in self.MEMORY_FIELDS if n not in memory]
        problems += [f"controller memory has an unknown field {n!r}" for n in memory if n not in self.MEMORY_FIELDS]
        if problems:
            return problems

        def number(name, value, lo=-bound, hi=bound):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
                problems.append(f"controller {name} = {value!r}: must be a finite number in [{lo:g}, {hi:g}]")
                return False
            return True

        def pair(name, value, lo=-bound, hi=bound):
            if not (isinstance(value, (list, tuple)) and len(value) == 2):
                problems.append(f"controller {name} = {value!r}: must be two numbers")
                return
            for i, v in enumerate(value):
                number(f"{name}[{i}]", v, lo, hi)

        offsets = memory["offsets"]
        if not (isinstance(offsets, Mapping) and set(offsets) == set(OFFSET_NAMES)):
            problems.append(f"controller offsets = {offsets!r}: must have exactly the keys {', '.join(OFFSET_NAMES)}")
        else:
            for k in OFFSET_NAMES:
                number(f"offsets[{k!r}]", offsets[k])
        for name in ("vx_ref", "vy_ref", "vx_des", "vy_des", "yaw_rate_ref", "yaw_rate_des", "vx_step_avg",
                     "vy_filt", "vx_filt", "yaw_ref"):
            number(name, memory[name])
        if memory["mode"] not in self.MODES:
            problems.append(f"controller mode = {memory['mode']!r}: must be one of {', '.join(map(repr, self.MODES))}")
        if memory["stance"] not in SIDES:
            problems.append(f"controller stance = {memory['stance']!r}: must be one of {', '.join(map(repr, SIDES))}")
        step_index = memory["step_index"]
        if isinstance(step_index, bool) or not isinstance(step_index, int) or not 0 <= step_index <= self.MAX_STEP_INDEX:
            problems.append(f"controller step_index = {step_index!r}: must be an int in [0, {self.MAX_STEP_INDEX}]")
        number("tau", memory["tau"], 0.0, self.p.switch_max_tau)
        pair("_step_start_xy", memory["_step_start_xy"])
        pair("_swing_start", memory["_swing_start"], -math.pi, math.pi)  # atan2 angles
        if number("t_step_start", memory["t_step_start"], 0.0) and number("_last_t", memory["_last_t"], 0.0):
            if not memory["t_step_start"] <= memory["_last_t"] <= time_s:
                problems.append(f"controller t_step_start = {memory['t_step_start']!r}, _last_t = "
                                f"{memory['_last_t']!r}: must satisfy 0 <= t_step_start <= _last_t <= the "
                                f"simulated time {time_s!r}")
        return problems

    def memory(self) -> dict:
        """The controller's memory as plain Python values (floats exact, arrays as lists)."""
        out = {}
        for name in self.MEMORY_FIELDS:
            value = getattr(self, name)
            if isinstance(value, np.ndarray):
                value = value.tolist()
            elif isinstance(value, tuple):
                value = list(value)
            elif isinstance(value, dict):
                value = dict(value)
            out[name] = value
        return out

    def restore_memory(self, memory: Mapping) -> None:
        """Set the memory saved by :meth:`memory` (same library of gaits assumed).

        Raises KeyError naming a missing field and ValueError naming every invalid one
        (:meth:`memory_problems`, against the physics' current time), nothing changed; the gait is looked up again for the
        saved gait speed (it is always ``lookup(vx_ref, vy_ref)``).
        """
        missing = [n for n in self.MEMORY_FIELDS if n not in memory]
        if missing:
            raise KeyError(f"controller memory lacks {', '.join(missing)}")
        problems = self.memory_problems(memory, self.phys.time_s)
        if problems:
            raise ValueError("invalid controller memory: " + "; ".join(problems))
        for name in self.MEMORY_FIELDS:
            value = memory[name]
            if name == "_step_start_xy":
                value = np.array(value, dtype=float)
            elif name == "_swing_start":
                value = tuple(float(v) for v in value)
            elif name == "offsets":
                value = {k: float(value[k]) for k in OFFSET_NAMES}
            setattr(self, name, value)
        self.gait = self._gaits.lookup(self.vx_ref, self.vy_ref)

    # ----------------------------------------------------------- interface
    def set_command(self, vx: float, vy: float, gaits, yaw_rate: float = 0.0) -> None:
        """Commanded speed (m/s), the gait library (``lookup(vx, vy) -> GaitParams``)
        and the commanded yaw rate (rad/s, positive turns left).

        The gait follows the command through a rate limiter
        (``ControllerParams.accel_limit_mps2``, ``yaw_accel_limit_radps2``) so walking
        starts from rest smoothly.
        """
        self.vx_des, self.vy_des, self._gaits = float(vx), float(vy), gaits
        self.yaw_rate_des = float(yaw_rate)
        self.gait = None  # force a new lookup (the library may have changed)
        self._refresh_gait(0.0)

    def _refresh_gait(self, dt: float) -> None:
        a = self.p.accel_limit_mps2 * dt
        if self.mode != "walk":
            tx, ty = 0.0, 0.0  # standing/shifting: ramp starts with the first step
        else:
            tx, ty = self.vx_des, self.vy_des
        nx = self.vx_ref + max(-a, min(a, tx - self.vx_ref))
        ny = self.vy_ref + max(-a, min(a, ty - self.vy_ref))
        tw = self.yaw_rate_des if self.mode == "walk" else 0.0
        if tw != self.yaw_rate_ref:
            aw = self.p.yaw_accel_limit_radps2 * dt
            self.yaw_rate_ref += max(-aw, min(aw, tw - self.yaw_rate_ref))
        if nx != self.vx_ref or ny != self.vy_ref or self.gait is None:
            self.vx_ref, self.vy_ref = nx, ny
            self.gait = self._gaits.lookup(nx, ny)

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        for k in offsets:
            if k not in self.offsets:
                raise KeyError(f"unknown offset key {k!r}; allowed: {', '.join(OFFSET_NAMES)}")
        values = {k: float(v) for k, v in offsets.items()}
        bad = [f"offset {k} must be finite, got {v}" for k, v in values.items() if not math.isfinite(v)]
        if bad:  # none set: all or nothing
            raise ValueError("; ".join(bad))
        self.offsets.update(values)

    @property
    def swing(self) -> str:
        return "right" if self.stance == "left" else "left"

    # ------------------------------------------------------------- phase
    def _leg_angles(self, side, yaw):
        """Measured (forward, lateral) absolute leg angles (rad) in the heading frame."""
        phys = self.phys
        v = phys.foot_position(side) - phys.hip_position(side)
        c, s = math.cos(yaw), math.sin(yaw)
        fx, fy = c * v[0] + s * v[1], -s * v[0] + c * v[1]
        return math.atan2(fx, -v[2]), math.atan2(fy, -v[2])

    def _start_step(self, t, yaw, new_stance):
        """End the current step at time ``t`` (s): its average forward speed, a new stance."""
        xy = self.phys.pelvis_position()[:2]
        dt = t - self.t_step_start
        if self.mode == "walk" and dt > MIN_STEP_DURATION_S:
            dx, dy = xy - self._step_start_xy
            self.vx_step_avg = (math.cos(yaw) * dx + math.sin(yaw) * dy) / dt
            self.step_index += 1
        self._step_start_xy = xy
        self.t_step_start = t
        self.stance = new_stance
        self._swing_start = self._leg_angles(self.swing, yaw)

    def _advance_phase(self, t: float, yaw: float) -> None:
        """Stand, shift the weight, then walk: the phase ``tau`` and the stance switches."""
        p = self.p
        if self.mode == "stand" and t >= p.stand_time_s:
            self.mode = "shift"
        if self.mode == "shift" and t >= p.stand_time_s + p.shift_time_s:
            self._start_step(t, yaw, p.first_stance)
            self.mode = "walk"
        if self.mode != "walk":
            self.tau = 0.0
            return
        self.tau = (t - self.t_step_start) / self.gait.step_time_s
        touchdown = False
        if self.tau > p.switch_min_tau:
            # Contact forces only when a touchdown can end the step (saves time).
            fl, fr = self.phys.foot_normal_forces_n()
            swing, stance = (fl, fr) if self.swing == "left" else (fr, fl)
            touchdown = swing > p.touchdown_force_n or (
                swing > p.touchdown_share_min_force_n and swing >= stance)
        if touchdown or self.tau >= p.switch_max_tau:
            self._start_step(t, yaw, self.swing)
            self.tau = 0.0

    # -------------------------------------------------------------- update
    def update(self) -> None:
        """Refresh phase and servo targets from the current state (call every substep block)."""
        sensed, yaw = self._sense()
        self._advance_phase(sensed.t, yaw)
        targets = self._default_targets(sensed)
        if self.mode in ("stand", "shift"):
            self._standing_targets(targets, sensed, yaw)
        else:
            self._walking_targets(targets, sensed)
        self._write_servos(targets)

    def _sense(self) -> tuple[_Sensed, float]:
        """Measure the pelvis and the joints, update the speed filters and the gait."""
        phys, p = self.phys, self.p
        t = phys.time_s
        yaw, pitch, roll, vx_h, vy_h, roll_rate, pitch_rate, yaw_rate = phys.heading_state()
        dt = max(t - self._last_t, 0.0)
        self._last_t = t
        if self.yaw_rate_ref:
            self.yaw_ref = math.remainder(self.yaw_ref + self.yaw_rate_ref * dt, math.tau)
        yaw_err = math.remainder(yaw - self.yaw_ref, math.tau)
        self.vy_filt = _low_pass(self.vy_filt, vy_h, dt, p.vy_filter_tau_s)
        self.vx_filt = _low_pass(self.vx_filt, vx_h, dt, p.vx_filter_tau_s)
        self._refresh_gait(dt)
        qv = phys.data.qpos[self._q_idx].tolist()
        qdv = phys.data.qvel[self._qd_idx].tolist()
        n6, n5 = len(_Q_NAMES), len(MOTOR_JOINTS)
        q = {"left": dict(zip(_Q_NAMES, qv[:n6])), "right": dict(zip(_Q_NAMES, qv[n6:]))}
        qd = {"left": dict(zip(MOTOR_JOINTS, qdv[:n5])), "right": dict(zip(MOTOR_JOINTS, qdv[n5:]))}
        return _Sensed(t, pitch, roll, roll_rate, pitch_rate, yaw_rate, yaw_err, q, qd), yaw

    def _default_targets(self, sensed: _Sensed) -> _Targets:
        """Hold every joint where it is, with the default gains and no feedforward."""
        q = sensed.q
        return _Targets(q={k: q[k[0]][k[1]] for k in self._keys}, qd=dict(self._zeros),
                        ff=dict(self._zeros), kp=dict(self._kp_all), kd=dict(self._kd_all))

    def _level_foot(self, q_leg: dict, pitch: float) -> float:
        """Foot joint target (rad) that keeps the foot level."""
        return self.foot_flat_sum + pitch - q_leg["hip-pitch"] - q_leg["knee"] - q_leg["tarsus"]

    def _stance_targets(self, targets: _Targets, sensed: _Sensed, side: str, share: float,
                        shift_roll: float = 0.0) -> None:
        """Stance leg ``side`` carrying ``share`` of the torso: torso pitch and roll through
        the hip, leg length through the knee, heading through the hip yaw, passive foot."""
        p, gait, offsets = self.p, self.gait, self.offsets
        q, qd, s = sensed.q[side], sensed.qd[side], side
        targets.q[s, "hip-pitch"] = (q["hip-pitch"] - (sensed.pitch - gait.torso_pitch_des_rad)
                                     - offsets["delta_stance_hip_pitch"])
        targets.qd[s, "hip-pitch"] = qd["hip-pitch"] - sensed.pitch_rate
        targets.kp[s, "hip-pitch"] = p.torso_pitch_kp * share
        targets.kd[s, "hip-pitch"] = p.torso_pitch_kd * share
        targets.q[s, "hip-roll"] = q["hip-roll"] + sensed.roll + offsets["delta_stance_hip_roll"] + shift_roll
        targets.qd[s, "hip-roll"] = qd["hip-roll"] + sensed.roll_rate
        targets.kp[s, "hip-roll"] = p.torso_roll_kp * share
        targets.kd[s, "hip-roll"] = p.torso_roll_kd * share
        if share == SINGLE_SUPPORT_SHARE:
            # Gravity feedforward: the pelvis hangs inboard of the stance hip.
            targets.ff[s, "hip-roll"] = p.stance_hip_roll_ff_nm * (1.0 if s == "left" else -1.0)
        targets.q[s, "knee"] = self._stance_knee[s] + offsets["delta_stance_knee"]
        targets.ff[s, "knee"] = p.stance_knee_ff_nm * share
        # Heading hold: hip yaw axes point up, so with the foot fixed the pelvis
        # yaw falls as the hip yaw rises.
        targets.q[s, "hip-yaw"] = q["hip-yaw"] + sensed.yaw_err
        targets.qd[s, "hip-yaw"] = qd["hip-yaw"] + sensed.yaw_rate - self.yaw_rate_ref
        targets.q[s, "foot"] = q["foot"]
        targets.kp[s, "foot"] = 0.0
        targets.kd[s, "foot"] = 0.0

    def _standing_targets(self, targets: _Targets, sensed: _Sensed, yaw: float) -> None:
        """Both legs in stance; the COM held over the feet (forward: foot torques; lateral:
        both hip rolls), shifted over the first stance foot during the weight shift."""
        phys, p = self.phys, self.p
        com = phys.center_of_mass()
        vcom = phys.data.subtree_linvel[phys.pelvis_body]
        feet = 0.5 * (phys.foot_center("left") + phys.foot_center("right"))
        c, s_ = math.cos(yaw), math.sin(yaw)
        ex = c * (com[0] - feet[0]) + s_ * (com[1] - feet[1])
        evx = c * vcom[0] + s_ * vcom[1]
        shift = 0.0
        if self.mode == "shift":
            r = min(1.0, (sensed.t - p.stand_time_s) / max(p.shift_time_s * SHIFT_RAMP_FRACTION,
                                                            MIN_SHIFT_RAMP_S))
            side = 1.0 if p.first_stance == "left" else -1.0
            shift = side * p.shift_distance_m * (3 * r * r - 2 * r * r * r)  # smoothstep
        ey = -s_ * (com[0] - feet[0]) + c * (com[1] - feet[1])
        evy = -s_ * vcom[0] + c * vcom[1]
        # Lateral COM position feedback: both hip rolls decrease to move the pelvis +y.
        shift_roll = -(p.stand_lat_kp * (shift - ey) - p.stand_lat_kd * evy)
        for s in SIDES:
            self._stance_targets(targets, sensed, s, DOUBLE_SUPPORT_SHARE, shift_roll=shift_roll)
            # Foot: level + COM feedback (toe down when COM ahead).
            targets.q[s, "foot"] = self._level_foot(sensed.q[s], sensed.pitch)
            targets.kp[s, "foot"] = self._kp["foot"]
            targets.kd[s, "foot"] = self._kd["foot"]
            targets.ff[s, "foot"] = -(p.stand_com_kp * ex + p.stand_com_kd * evx)

    def _landing_angles(self) -> tuple[float, float]:
        """Where the swing leg lands: (forward, lateral) absolute leg angles (rad)."""
        p, gait, offsets = self.p, self.gait, self.offsets
        step_time_s, leg_length_m = gait.step_time_s, p.stance_leg_length_m
        v_np = self.vx_ref + p.neutral_point_blend * (self.vx_filt - self.vx_ref)
        theta = (_neutral_angle(v_np, step_time_s, leg_length_m) + gait.leg_angle_offset_rad
                 + offsets["delta_swing_hip_pitch"])
        side = 1.0 if self.swing == "left" else -1.0
        phi = (_neutral_angle(self.vy_ref, step_time_s, leg_length_m) + gait.lateral_offset_rad
               + side * gait.step_width_rad + offsets["delta_swing_hip_roll"]
               + p.lateral_speed_gain * (self.vy_filt - self.vy_ref)
               + p.turn_lateral_gain * self.vx_ref * self.yaw_rate_ref)
        return theta, phi

    def _walking_targets(self, targets: _Targets, sensed: _Sensed) -> None:
        """Stance leg as in :meth:`_stance_targets`; the swing leg follows its Bezier
        virtual constraints from lift-off to :meth:`_landing_angles`."""
        phys, p, gait, offsets = self.phys, self.p, self.gait, self.offsets
        sw = self.swing
        self._stance_targets(targets, sensed, self.stance, SINGLE_SUPPORT_SHARE)
        b = bezier(gait.swing_shape, self.tau / gait.swing_end_tau)
        theta_f, phi_f = self._landing_angles()
        theta0, phi0 = self._swing_start
        theta = theta0 + (theta_f - theta0) * b
        phi = phi0 + (phi_f - phi0) * b
        # Swing foot height -> leg length (world-frame target).
        height = bezier(gait.swing_height, self.tau / gait.height_end_tau)
        hip = phys.hip_position(sw)
        gx, gy = self._swing_foot_xy(hip, theta, phi, sensed.yaw_err)
        z_ankle = phys.ground_height_m(gx, gy) + self.ankle_height0 + height
        length = (hip[2] - z_ankle) / max(math.cos(theta) * math.cos(phi), MIN_LEG_COS)
        length = min(max(length, p.swing_leg_min_length_m), p.swing_leg_max_length_m)
        kin = self.kin[sw]
        knee = kin.knee_for_length(length)
        # The knee offset is not compensated at the hip: + extends the shank
        # forward, so the foot lands further forward (and lower/earlier).
        targets.q[sw, "knee"] = knee + offsets["delta_swing_knee"] * b
        targets.q[sw, "hip-pitch"] = theta + sensed.pitch - kin.angle_offset(knee)
        targets.q[sw, "hip-roll"] = phi - sensed.roll
        # The swing foot lands along the reference heading half a step ahead.
        targets.q[sw, "hip-yaw"] = -sensed.yaw_err + 0.5 * self.yaw_rate_ref * gait.step_time_s
        targets.q[sw, "foot"] = self._level_foot(sensed.q[sw], sensed.pitch)

    def _swing_foot_xy(self, hip, theta: float, phi: float, yaw_err: float) -> tuple[float, float]:
        """World (x, y) (m) under the swing foot's target: the hip plus the leg's reach
        along the heading at the target leg angles (the stance leg length as the reach),
        so the foot's height follows the ground where the foot is, not under the hip."""
        yaw = self.yaw_ref + yaw_err
        c, s = math.cos(yaw), math.sin(yaw)
        reach = self.p.stance_leg_length_m
        fx, fy = reach * math.sin(theta), reach * math.sin(phi)
        return hip[0] + c * fx - s * fy, hip[1] + s * fx + c * fy

    def _write_servos(self, targets: _Targets) -> None:
        """Servo gains and commands, one vectorised write each (bias = -kp q - kd qdot)."""
        keys, kp, kd = self._keys, targets.kp, targets.kd
        ctrl = [kp[k] * targets.q[k] + kd[k] * targets.qd[k] + targets.ff[k] for k in keys]
        biasprm = self.phys.model.actuator_biasprm
        biasprm[self._act_ids, 1] = [-kp[k] for k in keys]
        biasprm[self._act_ids, 2] = [-kd[k] for k in keys]
        self.phys.data.ctrl[self._act_ids] = ctrl
        self.targets = targets
