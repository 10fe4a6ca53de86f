"""Physics wrapper for the MuJoCo Cassie model (dm_control ``Physics`` style).

Every joint, actuator, body and geom is looked up **by name once** in
:class:`CassiePhysics` (no hard-coded indices, no ``qpos[7:]`` slices); the
accessors below return SI units (m, m/s, rad, rad/s, N) as their names or
docstrings say.

Frames and signs used throughout the plant package
--------------------------------------------------
* World: z up, x forward at start, y to the left.
* Heading (yaw) frame: the world frame rotated about z by the pelvis yaw, so
  ``x`` points where the pelvis faces, projected on the ground.
* ``torso_pitch()``: rotation of the pelvis about the heading-frame +y axis
  (ZYX Euler pitch).  **Positive = nose down** (forward lean).
* ``torso_roll()``: rotation about the pelvis +x axis (ZYX Euler roll).
  **Positive = left side up** (leaning to the right).
* Rates (``torso_pitch_rate()``, ``torso_roll_rate()``) are the pelvis angular
  velocity expressed in the heading frame (y and x component): equal to the
  Euler-angle rates for the small tilts of walking.
* Joint signs on both legs (checked in tests): positive hip pitch / knee moves
  the foot forward (knee positive also lengthens the leg); positive hip roll
  moves the foot toward +y (left) on *both* legs (both axes are +x).

The actuators are re-configured by :meth:`CassiePhysics.configure_pd_servos`
as joint PD servos evaluated by MuJoCo at every 0.5 ms step (see
``plant/controller.py``); the caller's model is copied, never modified.
"""
from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass

import mujoco
import numpy as np

from plant.constants import HOME_KEY, MOTOR_JOINTS, PASSIVE_JOINTS, PELVIS_BODY, SIDES
from plant.errors import ModelError
from plant.terrain import GroundHeight

log = logging.getLogger(__name__)

#: Fall thresholds.  Nominal walking keeps the pelvis 0.85-1.0 m above the ground
#: and within ~0.2 rad of level; 0.55 m means the knees have folded or the robot is
#: down, 0.7 rad (40 deg) of tilt is not recoverable by stepping.
FALL_HEIGHT_M = 0.55
FALL_TILT_RAD = 0.7


@dataclass(frozen=True)
class LegIds:
    """Ids of one leg (all resolved by name)."""

    side: str
    qadr: dict  # joint short name -> qpos address
    dadr: dict  # joint short name -> dof address
    jid: dict  # joint short name -> joint id
    act: dict  # motor joint short name -> actuator id
    hip_pitch_jid: int
    foot_jid: int
    foot_body: int
    foot_geoms: tuple


def quat_to_euler_zyx(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """(yaw, pitch, roll) ZYX Euler angles (rad) of the unit quaternion (w, x, y, z)."""
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (w * y - z * x))))
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    return yaw, pitch, roll


def _id(model, objtype, name):
    i = mujoco.mj_name2id(model, objtype, name)
    if i < 0:
        raise ModelError(f"Cassie model has no {objtype.name.lower()} named {name!r}")
    return i


class CassiePhysics:
    """Named access to a Cassie ``MjModel``/``MjData`` pair.

    Args:
        model: a compiled Cassie model (Menagerie or OSU); it is copied, the
            caller's object is never changed.
    """

    def __init__(self, model: mujoco.MjModel):
        self.model = copy.deepcopy(model)
        self.data = mujoco.MjData(self.model)
        m = self.model
        #: Plant step (s): the model's timestep, 0.5 ms for both Cassie models.
        self.SIM_DT_S = float(m.opt.timestep)
        self.pelvis_body = _id(m, mujoco.mjtObj.mjOBJ_BODY, PELVIS_BODY)
        self.free_qadr, self.free_dadr = self._floating_base_adr(m)
        self.legs = {}
        for s in SIDES:
            qadr, dadr, jid, act = {}, {}, {}, {}
            for j in MOTOR_JOINTS + PASSIVE_JOINTS:
                k = _id(m, mujoco.mjtObj.mjOBJ_JOINT, f"{s}-{j}")
                jid[j] = k
                qadr[j] = int(m.jnt_qposadr[k])
                dadr[j] = int(m.jnt_dofadr[k])
            for j in MOTOR_JOINTS:
                a = _id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{s}-{j}")
                if m.actuator_trnid[a, 0] != jid[j]:
                    raise ModelError(f"actuator {s}-{j} does not drive joint {s}-{j}")
                act[j] = a
            foot_body = _id(m, mujoco.mjtObj.mjOBJ_BODY, f"{s}-foot")
            geoms = tuple(g for g in range(m.ngeom) if m.geom_bodyid[g] == foot_body
                          and (m.geom_contype[g] or m.geom_conaffinity[g]))
            if not geoms:
                raise ModelError(f"{s}-foot has no collision geom")
            self.legs[s] = LegIds(s, qadr, dadr, jid, act, jid["hip-pitch"], jid["foot"],
                                  foot_body, geoms)
        self._foot_geom_side = {g: s for s in SIDES for g in self.legs[s].foot_geoms}
        self._motor_ids = np.array([self.legs[s].act[j] for s in SIDES for j in MOTOR_JOINTS])
        # Original motor limits: peak joint torque = gear * ctrlrange (N m).
        self.torque_limit_nm = {
            (s, j): float(m.actuator_gear[a, 0] * max(abs(m.actuator_ctrlrange[a, 0]),
                                                         abs(m.actuator_ctrlrange[a, 1])))
            for s in SIDES for j, a in self.legs[s].act.items()}
        #: The ground height under a world point (m), see :meth:`ground_height_m`.
        self.ground = GroundHeight(m)
        self._force6 = np.zeros(6)
        self.home_key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, HOME_KEY)
        if self.home_key < 0:
            raise ModelError(f"Cassie model has no {HOME_KEY!r} keyframe; load it with "
                             "plant.model.load_model, which adds one")
        self.reset_standing()

    def _floating_base_adr(self, m):
        """qpos/qvel addresses of the pelvis pose (x, y, z, qw, qx, qy, qz) / twist.

        Menagerie uses one free joint; the OSU model uses three world-axis slide
        joints followed by a ball joint, which has the same qpos/qvel layout (world
        linear velocity, body-frame angular velocity).
        """
        js = [j for j in range(m.njnt) if m.jnt_bodyid[j] == self.pelvis_body]
        T = mujoco.mjtJoint
        if len(js) == 1 and m.jnt_type[js[0]] == T.mjJNT_FREE:
            return int(m.jnt_qposadr[js[0]]), int(m.jnt_dofadr[js[0]])
        if ([m.jnt_type[j] for j in js] == [T.mjJNT_SLIDE] * 3 + [T.mjJNT_BALL]
                and np.allclose(m.jnt_axis[js[:3]], np.eye(3))):
            q0, d0 = int(m.jnt_qposadr[js[0]]), int(m.jnt_dofadr[js[0]])
            if (list(m.jnt_qposadr[js]) == [q0, q0 + 1, q0 + 2, q0 + 3]
                    and list(m.jnt_dofadr[js]) == [d0, d0 + 1, d0 + 2, d0 + 3]):
                return q0, d0
        raise ModelError("the pelvis must float on one free joint or x/y/z slides + a ball joint")

    # ------------------------------------------------------------------ set-up
    def reset_standing(self) -> None:
        """Put the robot at rest in the model's ``home`` standing pose, on the ground under it."""
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        mujoco.mj_resetDataKeyframe(m, d, self.home_key)
        d.qvel[:] = 0.0
        # Terrain: stand on the ground under the pelvis.
        mujoco.mj_kinematics(m, d)
        p = d.xpos[self.pelvis_body]
        d.qpos[self.free_qadr + 2] += self.ground_height_m(p[0], p[1])
        mujoco.mj_forward(m, d)

    def configure_pd_servos(self) -> None:
        """Turn the 10 motors into joint PD servos evaluated by MuJoCo every step.

        Each actuator becomes ``force = ctrl - kp*q - kd*qdot`` (gain 1, affine bias,
        gear 1 so force is the joint torque in N m) with ``forcerange`` equal to the
        original ``gear * ctrlrange``: the controller writes ``ctrl = kp*q_des +
        kd*qdot_des + tau_ff`` and the gains into ``biasprm`` (``-kp``, ``-kd``).
        """
        m = self.model
        for s in SIDES:
            for j, a in self.legs[s].act.items():
                lim = self.torque_limit_nm[(s, j)]
                m.actuator_gear[a, :] = 0.0
                m.actuator_gear[a, 0] = 1.0
                m.actuator_gaintype[a] = mujoco.mjtGain.mjGAIN_FIXED
                m.actuator_biastype[a] = mujoco.mjtBias.mjBIAS_AFFINE
                m.actuator_gainprm[a, :] = 0.0
                m.actuator_gainprm[a, 0] = 1.0
                m.actuator_biasprm[a, :] = 0.0
                m.actuator_ctrllimited[a] = 0
                m.actuator_forcelimited[a] = 1
                m.actuator_forcerange[a] = (-lim, lim)
        # (actuator length/moment are recomputed from the gear at every step; no
        # mj_setConst, which would overwrite the state.)
        self.data.ctrl[:] = 0.0

    # ------------------------------------------------------------------ state
    #: MuJoCo's full integration state: restoring it makes the following steps identical
    #: to never having stopped (time, qpos, qvel, act, warm start, ctrl, applied forces, ...).
    STATE_SPEC = mujoco.mjtState.mjSTATE_INTEGRATION

    def physics_state(self) -> np.ndarray:
        """The integration state followed by the servo gains (``biasprm[:, 1:3]`` of the
        motors, which the controller rewrites at every update), float64."""
        m, d = self.model, self.data
        state = np.empty(mujoco.mj_stateSize(m, self.STATE_SPEC))
        mujoco.mj_getState(m, d, state, self.STATE_SPEC)
        return np.concatenate([state, m.actuator_biasprm[self._motor_ids, 1:3].ravel()])

    def physics_state_size(self) -> int:
        return int(mujoco.mj_stateSize(self.model, self.STATE_SPEC)) + 2 * len(self._motor_ids)

    #: The largest magnitude of a value in a physics state: MuJoCo's own bound (mjMAXVAL), beyond
    #: which its mj_checkPos/mj_checkVel/mj_checkAcc declare the simulation diverged and reset it.
    MAX_STATE_VALUE = float(mujoco.mjMAXVAL)
    #: How far from 1 the norm of a quaternion in a state may be: MuJoCo normalizes quaternions as it
    #: integrates, so a saved one is within a few ulp of unit norm; 1e-6 only leaves room for a state
    #: written by another MuJoCo build.
    QUAT_NORM_TOL = 1e-6

    def _state_parts(self, state: np.ndarray) -> dict[str, np.ndarray]:
        """``state`` (of the right size) split into MuJoCo's components (in mjtState bit order) and the gains."""
        m, parts, at = self.model, {}, 0
        spec = int(self.STATE_SPEC)
        for element in sorted((e for e in mujoco.mjtState.__members__.values()
                               if int(e) & (int(e) - 1) == 0 and int(e) & spec), key=int):
            n = int(mujoco.mj_stateSize(m, element))
            parts[element.name.removeprefix("mjSTATE_").lower()] = state[at:at + n]
            at += n
        parts["servo_gains"] = state[at:]
        return parts

    def physics_state_problems(self, state) -> list[str]:
        """Why ``state`` is not a physics state this model can have reached (every problem, each
        naming the component, the index and the allowed range), or [] if it is one."""
        try:
            state = np.asarray(state, dtype=float)
        except (TypeError, ValueError) as exc:
            return [f"physics state is not an array of numbers ({exc})"]
        if state.shape != (self.physics_state_size(),):
            return [f"physics state has shape {state.shape}, this model needs ({self.physics_state_size()},)"]
        bound, problems = self.MAX_STATE_VALUE, []
        parts = self._state_parts(state)
        for name, values in parts.items():
            bad = np.flatnonzero(~(np.abs(values) <= bound))  # also NaN
            if bad.size:
                problems.append(f"physics {name}[{bad[0]}] = {float(values[bad[0]])!r}: must be finite, in "
                                f"[{-bound:g}, {bound:g}] ({bad.size} such value(s))")
        if not parts["time"][0] >= 0.0:
            problems.append(f"physics time = {float(parts['time'][0])!r}: must be >= 0")
        m = self.model
        free, ball = int(mujoco.mjtJoint.mjJNT_FREE), int(mujoco.mjtJoint.mjJNT_BALL)
        for j in range(m.njnt):
            kind = int(m.jnt_type[j])
            if kind not in (free, ball):
                continue
            at = int(m.jnt_qposadr[j]) + (3 if kind == free else 0)
            qw, qx, qy, qz = parts["qpos"][at:at + 4].tolist()
            norm = math.sqrt(qw * qw + qx * qx + qy * qy + qz * qz)  # fixed order, no BLAS
            if not abs(norm - 1.0) <= self.QUAT_NORM_TOL:
                problems.append(f"physics qpos[{at}:{at + 4}] (quaternion of joint "
                                f"{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or j}) "
                                f"has norm {norm!r}: must be 1 (within {self.QUAT_NORM_TOL:g})")
        if "eq_active" in parts and not np.all((parts["eq_active"] == 0.0) | (parts["eq_active"] == 1.0)):
            problems.append(f"physics eq_active = {parts['eq_active'].tolist()}: each must be 0 or 1")
        gains = parts["servo_gains"]
        if np.any(gains > 0.0):
            problems.append(f"servo gains (-kp, -kd) = {gains.tolist()}: each must be <= 0")
        return problems

    def set_physics_state(self, state) -> None:
        """Restore :meth:`physics_state`; ValueError naming every problem (nothing changed) unless
        it is a state this model can have reached (:meth:`physics_state_problems`).  Derived
        quantities (positions of bodies, contacts) are those of the last step until the next
        step recomputes them, as after any ``mj_step``."""
        problems = self.physics_state_problems(state)
        if problems:
            raise ValueError("invalid physics state: " + "; ".join(problems))
        state = np.asarray(state, dtype=float)
        m, d = self.model, self.data
        n = int(mujoco.mj_stateSize(m, self.STATE_SPEC))
        mujoco.mj_setState(m, d, state[:n], self.STATE_SPEC)
        m.actuator_biasprm[self._motor_ids, 1:3] = state[n:].reshape(-1, 2)

    # -------------------------------------------------------------- accessors
    @property
    def time_s(self) -> float:
        """Simulated time (s)."""
        return float(self.data.time)

    def step(self, n_steps: int = 1) -> None:
        """Advance the plant by ``n_steps`` steps of ``SIM_DT_S``."""
        mujoco.mj_step(self.model, self.data, nstep=int(n_steps))

    def joint_pos_rad(self, side: str, joint: str) -> float:
        """Position of joint ``{side}-{joint}`` (rad)."""
        return float(self.data.qpos[self.legs[side].qadr[joint]])

    def joint_vel_radps(self, side: str, joint: str) -> float:
        """Velocity of joint ``{side}-{joint}`` (rad/s)."""
        return float(self.data.qvel[self.legs[side].dadr[joint]])

    def pelvis_position(self) -> np.ndarray:
        """World position of the pelvis body frame origin (m), shape (3,)."""
        return self.data.qpos[self.free_qadr:self.free_qadr + 3].copy()

    def euler_zyx(self) -> tuple[float, float, float]:
        """Pelvis (yaw, pitch, roll) ZYX Euler angles (rad)."""
        return quat_to_euler_zyx(*self.data.qpos[self.free_qadr + 3:self.free_qadr + 7].tolist())

    def heading_yaw(self) -> float:
        """Pelvis yaw (rad), the rotation of the heading frame about world z."""
        return self.euler_zyx()[0]

    def torso_pitch(self) -> float:
        """Pelvis pitch (rad), positive = nose down."""
        return self.euler_zyx()[1]

    def torso_roll(self) -> float:
        """Pelvis roll (rad), positive = left side up."""
        return self.euler_zyx()[2]

    def heading_state(self) -> tuple:
        """(yaw, pitch, roll, vx, vy, roll_rate, pitch_rate, yaw_rate), Python floats.

        Angles rad (ZYX Euler); vx, vy m/s and the rates rad/s in the heading frame.
        Same values as the individual accessors, computed without numpy temporaries
        (the controller calls this at 1 kHz) and in scalar Python arithmetic in a fixed
        order: every operation rounds once (no FMA contraction) and no BLAS kernel is
        involved, so the bits do not depend on the BLAS kernel or numpy's SIMD dispatch.
        """
        d = self.data
        qa, da = self.free_qadr, self.free_dadr
        yaw, pitch, roll = quat_to_euler_zyx(*d.qpos[qa + 3:qa + 7].tolist())
        v0, v1, _v2, a0, a1, a2 = d.qvel[da:da + 6].tolist()
        r = d.xmat[self.pelvis_body].tolist()
        wx = r[0] * a0 + r[1] * a1 + r[2] * a2
        wy = r[3] * a0 + r[4] * a1 + r[5] * a2
        wz = r[6] * a0 + r[7] * a1 + r[8] * a2
        c, sn = math.cos(yaw), math.sin(yaw)
        return (yaw, pitch, roll, c * v0 + sn * v1, -sn * v0 + c * v1,
                c * wx + sn * wy, -sn * wx + c * wy, wz)

    def pelvis_velocity_heading(self) -> np.ndarray:
        """Pelvis linear velocity in the heading frame (m/s): (forward, left, up)."""
        v = self.data.qvel[self.free_dadr:self.free_dadr + 3]
        yaw = self.heading_yaw()
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])

    def angular_velocity_heading(self) -> np.ndarray:
        """Pelvis angular velocity in the heading frame (rad/s): (roll, pitch, yaw) rates."""
        # The same fixed-order scalar arithmetic as :meth:`heading_state` (no BLAS).
        _, _, _, _, _, roll_rate, pitch_rate, yaw_rate = self.heading_state()
        return np.array([roll_rate, pitch_rate, yaw_rate])

    def torso_pitch_rate(self) -> float:
        """Pitch rate (rad/s), heading-frame y component of the pelvis angular velocity."""
        return float(self.angular_velocity_heading()[1])

    def torso_roll_rate(self) -> float:
        """Roll rate (rad/s), heading-frame x component of the pelvis angular velocity."""
        return float(self.angular_velocity_heading()[0])

    def hip_position(self, side: str) -> np.ndarray:
        """World position of the hip-pitch joint axis point (m)."""
        return self.data.xanchor[self.legs[side].hip_pitch_jid].copy()

    def foot_position(self, side: str) -> np.ndarray:
        """World position of the foot joint (ankle) axis point (m)."""
        return self.data.xanchor[self.legs[side].foot_jid].copy()

    def foot_center(self, side: str) -> np.ndarray:
        """World position of the centre of the foot's contact capsule (m)."""
        return self.data.geom_xpos[self.legs[side].foot_geoms[0]].copy()

    def foot_normal_forces_n(self) -> tuple[float, float]:
        """Contact normal force on the (left, right) foot (N), from all its contacts."""
        d = self.data
        f = [0.0, 0.0]
        n = d.ncon
        if n == 0:
            return 0.0, 0.0
        side_of = self._foot_geom_side
        g1 = d.contact.geom1[:n].tolist()
        g2 = d.contact.geom2[:n].tolist()
        for i in range(n):
            s = side_of.get(g1[i]) or side_of.get(g2[i])
            if s is None:
                continue
            mujoco.mj_contactForce(self.model, d, i, self._force6)
            f[0 if s == "left" else 1] += abs(float(self._force6[0]))
        return f[0], f[1]

    def total_mass_kg(self) -> float:
        """Total robot mass (kg)."""
        return float(np.sum(self.model.body_mass[1:]))

    def center_of_mass(self) -> np.ndarray:
        """World position of the robot's centre of mass (m)."""
        return self.data.subtree_com[self.pelvis_body].copy()

    def set_pelvis_force(self, force_n) -> None:
        """Apply a constant world-frame force (N, shape (3,)) at the pelvis COM until changed."""
        f = np.asarray(force_n, dtype=float).reshape(3)
        if not np.all(np.isfinite(f)):
            raise ValueError(f"force_n must be finite, got {f}")
        self.data.xfrc_applied[self.pelvis_body, :3] = f

    # ------------------------------------------------------------- terrain/fall
    def ground_height_m(self, x: float, y: float) -> float:
        """Height of the ground under the world point (x, y) (m): :class:`plant.terrain.GroundHeight`."""
        return self.ground(x, y)

    def pelvis_height_above_ground_m(self) -> float:
        """Pelvis height above the ground directly under it (m)."""
        p = self.data.qpos[self.free_qadr:self.free_qadr + 3]
        return float(p[2] - self.ground_height_m(p[0], p[1]))

    def fall_reason(self) -> str | None:
        """Why the robot counts as fallen, or None.

        Fallen = pelvis lower than :data:`FALL_HEIGHT_M` above the ground under it,
        or pelvis tilt (angle between pelvis z axis and world z) beyond
        :data:`FALL_TILT_RAD`, or a non-finite state.
        """
        d = self.data
        if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            return "non-finite state"
        h = self.pelvis_height_above_ground_m()
        if h < FALL_HEIGHT_M:
            return f"pelvis height {h:.3f} m < {FALL_HEIGHT_M} m"
        zz = float(d.xmat[self.pelvis_body][8])
        tilt = math.acos(max(-1.0, min(1.0, zz)))
        if tilt > FALL_TILT_RAD:
            return f"pelvis tilt {tilt:.3f} rad > {FALL_TILT_RAD} rad"
        return None

    def fell(self) -> bool:
        """True if :meth:`fall_reason` reports a fall."""
        return self.fall_reason() is not None
