"""Parameters of the nominal walking controller (:class:`plant.controller.NominalController`)."""
from __future__ import annotations

from dataclasses import dataclass

from plant.constants import SIDES


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
    touchdown_force_n: float = 100.0
    #: A swing foot carrying at least this much (N) and at least as much as the stance
    #: foot has also touched down: on an up-slope the swing foot lands early and takes the
    #: weight gradually, below ``touchdown_force_n``; holding the stance until
    #: ``switch_max_tau`` then leaves the torso without its stance leg and it pitches over.
    touchdown_share_min_force_n: float = 50.0
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
    #: Rate limit of the gait speed (``NominalController.vx_ref``/``vy_ref``) toward the command (m/s^2).
    accel_limit_mps2: float = 0.5
    #: Rate limit of the reference heading's turning rate toward the command (rad/s^2).
    yaw_accel_limit_radps2: float = 0.5
    #: Landing lateral angle per unit of centripetal acceleration vx_ref * yaw_rate_ref
    #: (rad per m/s^2): leans the step into the turn so the pelvis keeps no lateral speed.
    turn_lateral_gain: float = -0.13
    swing_leg_max_length_m: float = 0.93

    def __post_init__(self):
        if not (isinstance(self.control_substeps, int) and self.control_substeps >= 1):
            raise ValueError(f"control_substeps must be an int >= 1, got {self.control_substeps!r}")
        if self.first_stance not in SIDES:
            raise ValueError(f"first_stance must be one of {SIDES}, got {self.first_stance!r}")
