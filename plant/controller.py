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
  foot height above the ground follows ``GaitParams.swing_height``; both are
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
  (pelvis mass, COM) leaves a steady-state speed error for the regulator.
* Heading hold: the stance hip yaw acts as a PD on the pelvis yaw (reference:
  the yaw at start), the swing hip yaw lands the foot along that heading.
* The gait speed follows the command through a rate limit
  (``accel_limit_mps2``).
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
rates as above.  Because ``fmu_src.avr_core`` samples and holds its lateral PD
once per step (like the longitudinal one), a held lateral term alone was unstable
here too (falls within 8-17 s at Kp_y = 0.3); the nominal controller therefore
closes the lateral sway loop itself, continuously, with the same filtered ``vy``:
landing lateral angle ``+= lateral_speed_gain * (vy - vy_des)`` (0.3 rad per m/s,
proportional only), and the regulator's held lateral PD trims the drift.

All offsets are applied on top of the calibrated gait, so zero offsets at the
commanded speed give (on the nominal model) the commanded speed.

Recommended regulator defaults (measured with this plant and
``fmu_src.avr_core`` with adaptation off): ``Kp_x = 0.10`` rad/(m/s) (0.15 works
too; 0.25 oscillates step to step and falls within 4-12 s), ``Kd_x = 0`` (0.05 is
fine), ``Kp_y = 0.1`` rad/(m/s), ``Kd_y = 0``, torso gains 0 (the stance hip PD
already holds the torso).  These are ``fmu_src.avr_core.RegulatorParams``'
defaults; the gait calibration, the walking tests and the plant benchmark run
that core in-process with ``adaptation_enabled=False`` through
:func:`plant.sim.apply_regulator`.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Mapping

import mujoco
import numpy as np

from plant.cassie import MOTOR_JOINTS, SIDES, CassiePhysics

log = logging.getLogger(__name__)

OFFSET_KEYS = (
    "delta_swing_hip_pitch",
    "delta_swing_knee",
    "delta_swing_hip_roll",
    "delta_stance_hip_roll",
    "delta_stance_hip_pitch",
    "delta_stance_knee",
)


def bezier(coeffs, s: float) -> float:
    """Bezier polynomial ``sum_i a_i C(n,i) s^i (1-s)^(n-i)`` at ``s`` clipped to [0, 1]."""
    s = 0.0 if s < 0.0 else (1.0 if s > 1.0 else s)
    n = len(coeffs) - 1
    t = 1.0 - s
    # de Casteljau: stable and short.
    b = list(coeffs)
    for r in range(1, n + 1):
        for i in range(n - r + 1):
            b[i] = t * b[i] + s * b[i + 1]
    return float(b[0])


@dataclass(frozen=True)
class GaitParams:
    """Gait parameters for one commanded speed (one row of the gait library).

    Angles in rad, lengths in m, times in s.  Forward leg angle is the angle of
    the hip-to-ankle line from vertical in the heading frame, positive forward;
    lateral leg angle likewise, positive toward +y.
    """

    step_time_s: float = 0.4
    #: Landing leg angle = asin(vx_des*T/(2L)) + leg_angle_offset_rad (+ regulator offset).
    leg_angle_offset_rad: float = 0.0
    #: Landing lateral angle = asin(vy_des*T/(2L)) + lateral_offset_rad + side*step_width_rad.
    lateral_offset_rad: float = 0.0
    step_width_rad: float = 0.0
    torso_pitch_des_rad: float = 0.0
    #: Bezier shape (0 -> 1) of the swing angles vs tau/swing_end_tau.
    swing_shape: tuple = (0.0, 0.0, 1.0, 1.0, 1.0)
    swing_end_tau: float = 0.8
    #: Bezier of the swing ankle height above its standing height (m) vs tau/height_end_tau;
    #: ends negative so the foot keeps pressing down until contact (no late touchdown).
    swing_height: tuple = (0.0, 0.2, 0.2, -0.03, -0.03, -0.03)
    height_end_tau: float = 0.85


@dataclass(frozen=True)
class ControllerParams:
    """Parameters of the nominal controller (gains N m/rad and N m s/rad)."""

    #: Joint PD for roll, yaw, pitch, knee, foot (Gong et al. 2019 style).
    kp: tuple = (400.0, 200.0, 500.0, 500.0, 30.0)
    kd: tuple = (10.0, 4.0, 15.0, 15.0, 2.0)
    #: Stance torso PD through hip pitch (pitch) and hip roll (roll).
    torso_pitch_kp: float = 500.0
    torso_pitch_kd: float = 20.0
    torso_roll_kp: float = 300.0
    torso_roll_kd: float = 15.0
    stance_leg_length_m: float = 0.86
    stance_knee_ff_nm: float = 110.0
    #: Single-support hip-roll gravity feedforward (N m; + on the left leg, - on the right).
    stance_hip_roll_ff_nm: float = 50.0
    #: Python layer runs every this many plant steps (4 -> every 2 ms, 500 Hz, at the
    #: 0.5 ms plant step); the joint PD servos run inside MuJoCo at every step.
    control_substeps: int = 4
    #: Phase switching.
    switch_min_tau: float = 0.6
    switch_max_tau: float = 1.1
    touchdown_force_n: float = 200.0
    #: Start-up from rest.
    stand_time_s: float = 0.3
    shift_time_s: float = 0.5
    shift_distance_m: float = 0.06
    first_stance: str = "left"
    #: Standing COM feedback through the foot torques (N m/m, N m s/m, per foot).
    stand_com_kp: float = 600.0
    stand_com_kd: float = 60.0
    #: Standing lateral COM feedback through both hip rolls (rad/m, rad s/m).
    stand_lat_kp: float = 3.0
    stand_lat_kd: float = 0.5
    #: Low-pass time constant of the lateral velocity signal given to the regulator.
    vy_filter_tau_s: float = 0.1
    swing_leg_min_length_m: float = 0.55
    #: Landing leg angle uses the speed v_des + blend*(vx_filt - v_des) in its
    #: neutral-point term asin(v T / 2L): 0 = pure time-based gait (v_des only),
    #: 1 = neutral point of the measured speed (speed-neutral gait, the regulator
    #: supplies the correction).  Proportional only: no integral action.
    neutral_point_blend: float = 1.0
    vx_filter_tau_s: float = 0.05
    #: Lateral landing-angle feedback on the filtered lateral speed error (rad per
    #: m/s), continuous (the foot lands where the latest vy asks): stabilises the
    #: lateral sway; the regulator's held-per-step lateral PD only trims the drift.
    lateral_speed_gain: float = 0.3
    #: Rate limit of the gait speed toward the command (m/s^2).
    accel_limit_mps2: float = 0.5

    def __post_init__(self):
        if not (isinstance(self.control_substeps, int) and self.control_substeps >= 1):
            raise ValueError(f"control_substeps must be an int >= 1, got {self.control_substeps!r}")
        if self.first_stance not in SIDES:
            raise ValueError(f"first_stance must be one of {SIDES}, got {self.first_stance!r}")
    swing_leg_max_length_m: float = 0.93


def _horner(coeffs, x: float) -> float:
    r = 0.0
    for c in coeffs:
        r = r * x + c
    return r


class LegKinematics:
    """Rigid-spring sagittal leg kinematics fitted on the model itself.

    With the shin and heel springs at rest the tarsus follows the knee
    (``tarsus = tarsus_offset - knee``, 0.2269 rad for Cassie); the hip-pitch
    pivot to ankle distance ``L(knee)`` and the angle ``g(knee)`` of that line
    from the thigh's zero are sampled on a grid and fitted by polynomials.
    Absolute leg angle (forward positive) = ``hip_pitch + g(knee) - pelvis_pitch``.
    """

    def __init__(self, phys: CassiePhysics, side: str = "left", tarsus_offset: float | None = None):
        m = phys.model
        d = mujoco.MjData(m)
        d.qpos[:] = phys.data.qpos
        legs = phys.legs[side]
        qa = legs.qadr
        fq = phys.free_qadr
        if tarsus_offset is None:
            tarsus_offset = float(d.qpos[qa["tarsus"]] + d.qpos[qa["knee"]])
        self.tarsus_offset = tarsus_offset
        d.qpos[fq + 3:fq + 7] = [1, 0, 0, 0]
        for j in ("hip-roll", "hip-yaw", "hip-pitch", "shin", "heel-spring"):
            d.qpos[qa[j]] = 0.0
        knees = np.linspace(-2.6, -0.7, 40)
        L, g = [], []
        for kn in knees:
            d.qpos[qa["knee"]] = kn
            d.qpos[qa["tarsus"]] = tarsus_offset - kn
            mujoco.mj_kinematics(m, d)
            v = d.xanchor[legs.foot_jid] - d.xanchor[legs.hip_pitch_jid]
            L.append(math.hypot(v[0], v[2]))
            g.append(math.atan2(v[0], -v[2]))
        # Polynomial coefficients, highest power first, as Python floats (Horner below).
        self._L = tuple(float(c) for c in np.polyfit(knees, L, 5))
        self._g = tuple(float(c) for c in np.polyfit(knees, g, 5))
        self._kn = tuple(float(c) for c in np.polyfit(L, knees, 5))
        self.L_range = (min(L), max(L))
        self.max_fit_error_m = float(np.max(np.abs(np.polyval(self._L, knees) - L)))

    def length(self, knee: float) -> float:
        """Hip-pitch pivot to ankle distance (m) for a knee angle (rad)."""
        return _horner(self._L, knee)

    def angle_offset(self, knee: float) -> float:
        """g(knee) (rad): leg line angle at zero hip pitch and level pelvis."""
        return _horner(self._g, knee)

    def knee_for_length(self, length_m: float) -> float:
        """Knee angle (rad) giving leg length ``length_m`` (clipped to the fitted range)."""
        lo, hi = self.L_range
        return _horner(self._kn, min(max(length_m, lo), hi))


@dataclass
class _Targets:
    q: dict = field(default_factory=dict)
    qd: dict = field(default_factory=dict)
    ff: dict = field(default_factory=dict)
    kp: dict = field(default_factory=dict)
    kd: dict = field(default_factory=dict)


_Q_NAMES = MOTOR_JOINTS + ("tarsus",)


def joint_pd_torque(kp, kd, q_des, qd_des, tau_ff, q, qd, limit):
    """Reference joint PD law (N m) that the MuJoCo servos implement, clipped to +-limit."""
    tau = kp * (q_des - q) + kd * (qd_des - qd) + tau_ff
    return min(max(tau, -limit), limit)


class _Uniform:
    def __init__(self, g):
        self.g = g

    def lookup(self, vx, vy):
        return self.g


class NominalController:
    """Stance/swing state machine, Bezier virtual constraints and joint PD targets."""

    def __init__(self, phys: CassiePhysics, params: ControllerParams | None = None):
        self.phys = phys
        self.p = params or ControllerParams()
        self.kin = {s: LegKinematics(phys, s) for s in SIDES}
        d, legs = phys.data, phys.legs
        la = legs["left"].qadr
        #: Foot-level constant: hip pitch + knee + tarsus + foot at the standing pose.
        self.foot_flat_sum = float(d.qpos[la["hip-pitch"]] + d.qpos[la["knee"]]
                                   + d.qpos[la["tarsus"]] + d.qpos[la["foot"]])
        self.home_q = {s: {j: phys.joint_pos_rad(s, j) for j in MOTOR_JOINTS} for s in SIDES}
        # Ankle height above ground when standing (m).
        self.ankle_height0 = float(np.mean([phys.foot_position(s)[2] for s in SIDES]))
        self.offsets = {k: 0.0 for k in OFFSET_KEYS}
        self.gait = None
        #: Gait speed (m/s): the command through the rate limiter.
        self.vx_des = 0.0
        self.vy_des = 0.0
        self.cmd_vx = self.cmd_vy = 0.0
        self._gaits = _Uniform(GaitParams())
        self.mode = "stand"
        self.stance = self.p.first_stance
        self.step_index = 0
        self.t_step_start = 0.0
        self.tau = 0.0
        self.vx_step_avg = 0.0
        self.vy_step_avg = 0.0
        self.vy_filt = 0.0
        self.vx_filt = 0.0
        self._step_start_xy = phys.pelvis_position()[:2]
        self._swing_start = (0.0, 0.0)
        self._last_t = phys.time_s
        #: Heading held by the hip yaw joints (rad): the pelvis yaw at start.
        self.yaw_ref = phys.heading_yaw()
        legs = phys.legs
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
    MEMORY_FIELDS = ("offsets", "vx_des", "vy_des", "cmd_vx", "cmd_vy", "mode", "stance", "step_index",
                     "t_step_start", "tau", "vx_step_avg", "vy_step_avg", "vy_filt", "vx_filt",
                     "_step_start_xy", "_swing_start", "_last_t", "yaw_ref")

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

        Raises KeyError naming a missing field; the gait is looked up again for the
        saved gait speed (it is always ``lookup(vx_des, vy_des)``).
        """
        missing = [n for n in self.MEMORY_FIELDS if n not in memory]
        if missing:
            raise KeyError(f"controller memory lacks {', '.join(missing)}")
        for name in self.MEMORY_FIELDS:
            value = memory[name]
            if name == "_step_start_xy":
                value = np.array(value, dtype=float)
            elif name == "_swing_start":
                value = tuple(float(v) for v in value)
            elif name == "offsets":
                value = {k: float(value[k]) for k in OFFSET_KEYS}
            setattr(self, name, value)
        self.gait = self._gaits.lookup(self.vx_des, self.vy_des)

    # ----------------------------------------------------------- interface
    def set_command(self, vx: float, vy: float, gaits) -> None:
        """Commanded speed (m/s) and the gait library (``lookup(vx, vy) -> GaitParams``).

        The gait follows the command through a rate limiter
        (``ControllerParams.accel_limit_mps2``) so walking starts from rest smoothly.
        """
        self.cmd_vx, self.cmd_vy, self._gaits = float(vx), float(vy), gaits
        self.gait = None  # force a new lookup (the library may have changed)
        self._refresh_gait(0.0)

    def _refresh_gait(self, dt: float) -> None:
        a = self.p.accel_limit_mps2 * dt
        if self.mode != "walk":
            tx, ty = 0.0, 0.0  # standing/shifting: ramp starts with the first step
        else:
            tx, ty = self.cmd_vx, self.cmd_vy
        nx = self.vx_des + max(-a, min(a, tx - self.vx_des))
        ny = self.vy_des + max(-a, min(a, ty - self.vy_des))
        if nx != self.vx_des or ny != self.vy_des or self.gait is None:
            self.vx_des, self.vy_des = nx, ny
            self.gait = self._gaits.lookup(nx, ny)

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        for k in offsets:
            if k not in self.offsets:
                raise KeyError(f"unknown offset key {k!r}; allowed: {', '.join(OFFSET_KEYS)}")
        for k, v in offsets.items():
            v = float(v)
            if not math.isfinite(v):
                raise ValueError(f"offset {k} must be finite, got {v}")
            self.offsets[k] = v

    @property
    def swing(self) -> str:
        return "right" if self.stance == "left" else "left"

    # ------------------------------------------------------------- helpers
    def _leg_angles(self, side, yaw):
        """Measured (forward, lateral) absolute leg angles (rad) in the heading frame."""
        ph = self.phys
        v = ph.foot_position(side) - ph.hip_position(side)
        c, s = math.cos(yaw), math.sin(yaw)
        fx, fy = c * v[0] + s * v[1], -s * v[0] + c * v[1]
        return math.atan2(fx, -v[2]), math.atan2(fy, -v[2])

    def _start_step(self, t, yaw, new_stance):
        ph = self.phys
        xy = ph.pelvis_position()[:2]
        dt = t - self.t_step_start
        if self.mode == "walk" and dt > 1e-6:
            dx, dy = xy - self._step_start_xy
            c, s = math.cos(yaw), math.sin(yaw)
            self.vx_step_avg = (c * dx + s * dy) / dt
            self.vy_step_avg = (-s * dx + c * dy) / dt
            self.step_index += 1
        self._step_start_xy = xy
        self.t_step_start = t
        self.stance = new_stance
        self._swing_start = self._leg_angles(self.swing, yaw)

    # -------------------------------------------------------------- update
    def update(self) -> None:
        """Refresh phase and servo targets from the current state (call every substep block)."""
        ph, p = self.phys, self.p
        d = ph.data
        t = ph.time_s
        yaw, pitch, roll, vx_h, vy_h, roll_rate, pitch_rate, yaw_rate = ph.heading_state()
        yaw_err = math.remainder(yaw - self.yaw_ref, math.tau)
        dt = max(t - self._last_t, 0.0)
        self._last_t = t
        a = dt / (p.vy_filter_tau_s + dt) if dt > 0 else 0.0
        self.vy_filt += a * (vy_h - self.vy_filt)
        ax = dt / (p.vx_filter_tau_s + dt) if dt > 0 else 0.0
        self.vx_filt += ax * (vx_h - self.vx_filt)

        self._refresh_gait(dt)
        g = self.gait
        # ---------------- phase / mode machine
        if self.mode == "stand" and t >= p.stand_time_s:
            self.mode = "shift"
        if self.mode == "shift" and t >= p.stand_time_s + p.shift_time_s:
            self._start_step(t, yaw, p.first_stance)
            self.mode = "walk"
        if self.mode == "walk":
            T = g.step_time_s
            self.tau = (t - self.t_step_start) / T
            touchdown = False
            if self.tau > p.switch_min_tau:
                # Contact forces only when a touchdown can end the step (saves time).
                fl, fr = ph.foot_normal_forces_n()
                touchdown = (fl if self.swing == "left" else fr) > p.touchdown_force_n
            if touchdown or self.tau >= p.switch_max_tau:
                self._start_step(t, yaw, self.swing)
                self.tau = 0.0
        else:
            self.tau = 0.0

        qv = d.qpos[self._q_idx].tolist()
        qdv = d.qvel[self._qd_idx].tolist()
        n6, n5 = len(_Q_NAMES), len(MOTOR_JOINTS)
        q = {"left": dict(zip(_Q_NAMES, qv[:n6])), "right": dict(zip(_Q_NAMES, qv[n6:]))}
        qd = {"left": dict(zip(MOTOR_JOINTS, qdv[:n5])), "right": dict(zip(MOTOR_JOINTS, qdv[n5:]))}
        T_ = _Targets(q={k: q[k[0]][k[1]] for k in self._keys}, qd=dict(self._zeros),
                      ff=dict(self._zeros), kp=dict(self._kp_all), kd=dict(self._kd_all))
        kp, kd = self._kp, self._kd
        o = self.offsets

        def stance_leg(s, share, shift_roll=0.0):
            # Torso pitch constraint through hip pitch.
            T_.q[s, "hip-pitch"] = q[s]["hip-pitch"] - (pitch - g.torso_pitch_des_rad) - o["delta_stance_hip_pitch"]
            T_.qd[s, "hip-pitch"] = qd[s]["hip-pitch"] - pitch_rate
            T_.kp[s, "hip-pitch"] = p.torso_pitch_kp * share
            T_.kd[s, "hip-pitch"] = p.torso_pitch_kd * share
            T_.q[s, "hip-roll"] = q[s]["hip-roll"] + roll + o["delta_stance_hip_roll"] + shift_roll
            T_.qd[s, "hip-roll"] = qd[s]["hip-roll"] + roll_rate
            T_.kp[s, "hip-roll"] = p.torso_roll_kp * share
            T_.kd[s, "hip-roll"] = p.torso_roll_kd * share
            if share == 1.0:
                # Gravity feedforward: the pelvis hangs inboard of the stance hip.
                T_.ff[s, "hip-roll"] = p.stance_hip_roll_ff_nm * (1.0 if s == "left" else -1.0)
            T_.q[s, "knee"] = self._stance_knee[s] + o["delta_stance_knee"]
            T_.ff[s, "knee"] = p.stance_knee_ff_nm * share
            # Heading hold: hip yaw axes point up, so with the foot fixed the pelvis
            # yaw falls as the hip yaw rises.
            T_.q[s, "hip-yaw"] = q[s]["hip-yaw"] + yaw_err
            T_.qd[s, "hip-yaw"] = qd[s]["hip-yaw"] + yaw_rate
            T_.q[s, "foot"] = q[s]["foot"]
            T_.kp[s, "foot"] = 0.0
            T_.kd[s, "foot"] = 0.0

        if self.mode in ("stand", "shift"):
            com = ph.center_of_mass()
            vcom = d.subtree_linvel[ph.pelvis_body]
            feet = 0.5 * (ph.foot_center("left") + ph.foot_center("right"))
            c, s_ = math.cos(yaw), math.sin(yaw)
            ex = c * (com[0] - feet[0]) + s_ * (com[1] - feet[1])
            evx = c * vcom[0] + s_ * vcom[1]
            shift = 0.0
            if self.mode == "shift":
                r = min(1.0, (t - p.stand_time_s) / max(p.shift_time_s * 0.7, 1e-3))
                side = 1.0 if p.first_stance == "left" else -1.0
                shift = side * p.shift_distance_m * (3 * r * r - 2 * r * r * r)
            ey = -s_ * (com[0] - feet[0]) + c * (com[1] - feet[1])
            evy = -s_ * vcom[0] + c * vcom[1]
            # Lateral COM position feedback: both hip rolls decrease to move the pelvis +y.
            shift_roll = -(p.stand_lat_kp * (shift - ey) - p.stand_lat_kd * evy)
            for s in SIDES:
                stance_leg(s, 0.5, shift_roll=shift_roll)
                # Foot: level + COM feedback (toe down when COM ahead).
                T_.q[s, "foot"] = self.foot_flat_sum + pitch - q[s]["hip-pitch"] - q[s]["knee"] - q[s]["tarsus"]
                T_.kp[s, "foot"] = kp["foot"]
                T_.kd[s, "foot"] = kd["foot"]
                T_.ff[s, "foot"] = -(p.stand_com_kp * ex + p.stand_com_kd * evx)
        else:
            st, sw = self.stance, self.swing
            stance_leg(st, 1.0)
            T = g.step_time_s
            L = p.stance_leg_length_m
            b = bezier(g.swing_shape, self.tau / g.swing_end_tau)
            v_np = self.vx_des + p.neutral_point_blend * (self.vx_filt - self.vx_des)
            th_f = (math.asin(max(-0.5, min(0.5, v_np * T / (2 * L)))) + g.leg_angle_offset_rad
                    + o["delta_swing_hip_pitch"])
            side = 1.0 if sw == "left" else -1.0
            ph_f = (math.asin(max(-0.5, min(0.5, self.vy_des * T / (2 * L)))) + g.lateral_offset_rad
                    + side * g.step_width_rad + o["delta_swing_hip_roll"]
                    + p.lateral_speed_gain * (self.vy_filt - self.vy_des))
            th0, ph0 = self._swing_start
            th = th0 + (th_f - th0) * b
            phi = ph0 + (ph_f - ph0) * b
            # Swing foot height -> leg length (world-frame target).
            h = bezier(g.swing_height, self.tau / g.height_end_tau)
            hip = ph.hip_position(sw)
            ground = ph.ground_height_m(hip[0], hip[1])
            z_ankle = ground + self.ankle_height0 + h
            Ld = (hip[2] - z_ankle) / max(math.cos(th) * math.cos(phi), 0.5)
            Ld = min(max(Ld, p.swing_leg_min_length_m), p.swing_leg_max_length_m)
            kin = self.kin[sw]
            kn = kin.knee_for_length(Ld)
            # The knee offset is not compensated at the hip: + extends the shank
            # forward, so the foot lands further forward (and lower/earlier).
            T_.q[sw, "knee"] = kn + o["delta_swing_knee"] * b
            T_.q[sw, "hip-pitch"] = th + pitch - kin.angle_offset(kn)
            T_.q[sw, "hip-roll"] = phi - roll
            T_.q[sw, "hip-yaw"] = -yaw_err  # swing foot lands along the reference heading
            T_.q[sw, "foot"] = self.foot_flat_sum + pitch - q[sw]["hip-pitch"] - q[sw]["knee"] - q[sw]["tarsus"]

        # ---------------- write servo commands (one vectorised write each)
        keys = self._keys
        Tkp, Tkd, Tq, Tqd, Tff = T_.kp, T_.kd, T_.q, T_.qd, T_.ff
        kps = [-Tkp[k] for k in keys]  # bias = -kp q - kd qdot
        kds = [-Tkd[k] for k in keys]
        ctrl = [Tkp[k] * Tq[k] + Tkd[k] * Tqd[k] + Tff[k] for k in keys]
        m = ph.model
        m.actuator_biasprm[self._act_ids, 1] = kps
        m.actuator_biasprm[self._act_ids, 2] = kds
        d.ctrl[self._act_ids] = ctrl
        self.targets = T_

