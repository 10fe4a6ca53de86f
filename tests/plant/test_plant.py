"""Fast unit tests of the Cassie plant: name look-ups, accessors, signs, offsets, errors."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from fmu_src.core.avr_core import Regulator
from plant.cassie import FALL_HEIGHT_M, FALL_TILT_RAD, CassiePhysics
from plant.constants import MOTOR_JOINTS, SIDES
from plant.constants import OFFSET_NAMES
from plant.controller_params import ControllerParams
from plant.gaits import GaitParams
from plant.kinematics import LegKinematics
from plant.kinematics import bezier
from plant.gaits import DEFAULT_LIBRARY_PATH, GaitLibrary
from scenarios.gaits.make_gaits import PD_ONLY_PARAMS
from plant.errors import ModelError
from plant.model import load_model, menagerie_xml_path
from plant.sim import CassieWalker
from scenarios.cosim.inprocess import apply_regulator

REG_KEYS = {"vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index"}
TEL_KEYS = {"t", "pelvis_x", "pelvis_y", "pelvis_z", "vx", "vy", "vx_step_avg", "vy_signal",
            "pitch", "roll", "stance", "tau", "step_index", "left_foot_force",
            "right_foot_force", "vx_des", "vy_des", "yaw", "yaw_rate", "yaw_rate_des"}


@pytest.fixture(scope="module")
def model():
    return load_model("menagerie")


@pytest.fixture()
def phys(model):
    return CassiePhysics(model)


def test_ids_by_name_match_model(phys):
    m = phys.model
    for s in SIDES:
        for j in MOTOR_JOINTS:
            assert m.joint(phys.legs[s].jid[j]).name == f"{s}-{j}"
            assert m.actuator(phys.legs[s].act[j]).name == f"{s}-{j}"
        assert m.body(phys.legs[s].foot_body).name == f"{s}-foot"
    assert m.body(phys.pelvis_body).name == "cassie-pelvis"


def test_caller_model_not_modified(model):
    gain = model.actuator_gear.copy()
    CassieWalker(model)
    np.testing.assert_array_equal(model.actuator_gear, gain)


def test_home_pose_accessors(phys):
    assert phys.SIM_DT_S == pytest.approx(0.0005)
    p = phys.pelvis_position()
    assert p[2] == pytest.approx(1.006, abs=1e-3)
    np.testing.assert_allclose(phys.pelvis_velocity_heading(), 0.0, atol=1e-12)
    assert abs(phys.torso_pitch()) < 1e-6 and abs(phys.torso_roll()) < 1e-6
    fl, fr = phys.foot_position("left"), phys.foot_position("right")
    assert fl[1] == pytest.approx(-fr[1], abs=2e-3) and fl[1] > 0.1  # left foot at +y
    # Facts: 33.3 kg in all, pelvis 10.33 kg.
    assert phys.total_mass_kg() == pytest.approx(33.31, abs=0.02)
    assert phys.model.body_mass[phys.pelvis_body] == pytest.approx(10.33)
    com = phys.center_of_mass()
    assert abs(com[1]) < 5e-3 and 0.7 < com[2] < 1.0


def test_osu_model_same_interface():
    ph = CassiePhysics(load_model("osu"))
    assert ph.pelvis_position()[2] == pytest.approx(1.006, abs=2e-3)
    assert ph.total_mass_kg() == pytest.approx(33.31, abs=0.02)


def test_joint_and_angle_signs(model):
    ph = CassiePhysics(model)
    d, m = ph.data, ph.model

    def foot_rel(side):
        mujoco.mj_kinematics(m, d)
        return ph.foot_position(side) - ph.hip_position(side)

    for s in SIDES:
        base = foot_rel(s)
        d.qpos[ph.legs[s].qadr["hip-pitch"]] += 0.1
        assert foot_rel(s)[0] > base[0] + 0.05  # + hip pitch: foot forward
        d.qpos[ph.legs[s].qadr["hip-pitch"]] -= 0.1
        d.qpos[ph.legs[s].qadr["hip-roll"]] += 0.1
        assert foot_rel(s)[1] > base[1] + 0.05  # + hip roll: foot toward +y, both legs
        d.qpos[ph.legs[s].qadr["hip-roll"]] -= 0.1
    # Pitch +: nose down (rotation about +y); roll +: left side up.
    fq = ph.free_qadr
    a = 0.1
    d.qpos[fq + 3:fq + 7] = [math.cos(a / 2), 0, math.sin(a / 2), 0]
    assert ph.torso_pitch() == pytest.approx(a)
    d.qpos[fq + 3:fq + 7] = [math.cos(a / 2), math.sin(a / 2), 0, 0]
    assert ph.torso_roll() == pytest.approx(a)


def test_heading_frame_velocity(phys):
    d = phys.data
    fq, fd = phys.free_qadr, phys.free_dadr
    yaw = math.pi / 2
    d.qpos[fq + 3:fq + 7] = [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
    d.qvel[fd:fd + 3] = [0.0, 0.7, 0.0]  # world +y = heading forward
    mujoco.mj_forward(phys.model, d)
    np.testing.assert_allclose(phys.pelvis_velocity_heading(), [0.7, 0.0, 0.0], atol=1e-9)
    d.qvel[fd + 3:fd + 6] = [0.0, 0.3, 0.0]  # body-frame pitch rate
    mujoco.mj_forward(phys.model, d)
    assert phys.torso_pitch_rate() == pytest.approx(0.3)


def test_fall_detection(phys):
    assert not phys.fell()
    d = phys.data
    d.qpos[phys.free_qadr + 2] = FALL_HEIGHT_M - 0.01
    assert "height" in phys.fall_reason()
    phys.reset_standing()
    a = FALL_TILT_RAD + 0.05
    d.qpos[phys.free_qadr + 3:phys.free_qadr + 7] = [math.cos(a / 2), math.sin(a / 2), 0, 0]
    mujoco.mj_kinematics(phys.model, d)
    assert "tilt" in phys.fall_reason()


def test_leg_kinematics_matches_facts(phys):
    kin = LegKinematics(phys)
    # Facts: knee -1.0/-1.2/-1.6 rad -> 0.912/0.859/0.731 m (rigid springs); fit error < 2 mm.
    for kn, L in ((-1.0, 0.912), (-1.2, 0.859), (-1.6, 0.731)):
        assert kin.length(kn) == pytest.approx(L, abs=3e-3)
        assert kin.knee_for_length(L) == pytest.approx(kn, abs=0.01)


def test_bezier():
    assert bezier((1.0, 2.0), 0.25) == pytest.approx(1.25)
    assert bezier((0.0, 0.0, 1.0, 1.0), 0.0) == 0.0 and bezier((0.0, 0.0, 1.0, 1.0), 2.0) == 1.0


def test_stand_foot_forces_carry_weight(model):
    w = CassieWalker(model)
    w.advance(400)  # 0.2 s standing
    tel = w.telemetry()
    weight = w.physics.total_mass_kg() * 9.81
    # Dynamic settling: within 15 % of the weight, split evenly within 20 %.
    assert tel["left_foot_force"] + tel["right_foot_force"] == pytest.approx(weight, rel=0.15)
    assert tel["left_foot_force"] == pytest.approx(tel["right_foot_force"], rel=0.2)


def test_interface_keys_and_bad_offsets(model):
    w = CassieWalker(model)
    assert set(w.regulator_inputs()) == REG_KEYS
    assert isinstance(w.regulator_inputs()["step_index"], int)
    assert set(w.telemetry()) == TEL_KEYS
    assert all(isinstance(v, float) for v in w.telemetry().values())
    w.set_offsets({k: 0.0 for k in OFFSET_NAMES})
    with pytest.raises(KeyError, match="delta_swing_hip_yaw"):
        w.set_offsets({"delta_swing_hip_yaw": 0.1})
    with pytest.raises(ValueError):
        w.set_offsets({"delta_swing_knee": float("nan")})
    with pytest.raises(ValueError):
        w.advance(-1)


def test_pelvis_force(model):
    w = CassieWalker(model)
    w.set_pelvis_force([30.0, 0.0, 0.0])
    np.testing.assert_allclose(w.data.xfrc_applied[w.physics.pelvis_body, :3], [30, 0, 0])
    w.set_pelvis_force((0, 0, 0))
    assert not w.data.xfrc_applied.any()


def test_advance_counts_substeps_across_calls(model):
    a, b = CassieWalker(model), CassieWalker(model)
    a.advance(101)
    for _ in range(101):
        b.advance(1)
    assert a.time_s == pytest.approx(b.time_s)
    np.testing.assert_allclose(a.data.qpos, b.data.qpos, atol=1e-9)


def _walker_in_walk(model):
    w = CassieWalker(model)
    w.set_command(0.5, 0.0)
    reg = Regulator(PD_ONLY_PARAMS)
    while w.controller.mode != "walk" or w.controller.tau < 0.3:
        apply_regulator(w, reg, 0.01)
        w.advance(20)
    return w


def test_offset_mapping_signs(model):
    """Each offset moves the right joint target of the right leg in the documented direction."""
    w = _walker_in_walk(model)
    c = w.controller
    st, sw = c.stance, c.swing
    c.set_offsets({k: 0.0 for k in OFFSET_NAMES})
    c.update()
    base = dict(c.targets.q)
    d = 0.05
    expect = {  # key: (leg, joint, sign)
        "delta_swing_hip_pitch": (sw, "hip-pitch", +1),
        "delta_swing_knee": (sw, "knee", +1),
        "delta_swing_hip_roll": (sw, "hip-roll", +1),
        "delta_stance_hip_roll": (st, "hip-roll", +1),
        "delta_stance_hip_pitch": (st, "hip-pitch", -1),
        "delta_stance_knee": (st, "knee", +1),
    }
    for key, (leg, joint, sign) in expect.items():
        c.set_offsets({k: (d if k == key else 0.0) for k in OFFSET_NAMES})
        c.update()
        diff = c.targets.q[leg, joint] - base[leg, joint]
        assert sign * diff > 0.2 * d, (key, diff)
        # No other motor target of either leg moves by more than the tied hip pitch/knee.
        for (l2, j2), v in c.targets.q.items():
            if (l2, j2) != (leg, joint) and j2 != "foot":  # foot targets use measured joints
                # The swing knee keeps the foot-height constraint (length = height/cos(angle)),
                # so it (and the hip pitch through the knee) moves a little with the swing
                # angles; everything else is untouched.
                tol = 0.1 * d if (l2, j2) in ((sw, "knee"), (sw, "hip-pitch")) else 1e-9
                assert abs(v - base[l2, j2]) < tol, (key, l2, j2)


def joint_pd_torque(kp, kd, q_des, qd_des, tau_ff, q, qd, limit):
    """Reference joint PD law (N m) that the MuJoCo servos implement, clipped to +-limit."""
    tau = kp * (q_des - q) + kd * (qd_des - qd) + tau_ff
    return min(max(tau, -limit), limit)


def test_servo_matches_reference_pd(model):
    w = _walker_in_walk(model)
    ph = w.physics
    mujoco.mj_forward(ph.model, ph.data)
    for s in SIDES:
        for j in MOTOR_JOINTS:
            a = ph.legs[s].act[j]
            kp, kd = -ph.model.actuator_biasprm[a, 1], -ph.model.actuator_biasprm[a, 2]
            q, qd = ph.joint_pos_rad(s, j), ph.joint_vel_radps(s, j)
            ctrl = ph.data.ctrl[a]
            ref = joint_pd_torque(kp, kd, 0.0, 0.0, ctrl, q, qd, ph.torque_limit_nm[(s, j)])
            assert ph.data.actuator_force[a] == pytest.approx(ref, abs=1e-6)
    # Limits are gear * ctrlrange of the original model (facts: 112.5/112.5/195.2/195.2/45 N m).
    lims = [ph.torque_limit_nm[("left", j)] for j in MOTOR_JOINTS]
    np.testing.assert_allclose(lims, [112.5, 112.5, 195.2, 195.2, 45.0])


def test_gait_library_interpolation(tmp_path):
    g0, g1 = GaitParams(leg_angle_offset_rad=0.0), GaitParams(leg_angle_offset_rad=0.1)
    lib = GaitLibrary((0.0, 1.0), (0.0,), {(0, 0): g0, (1, 0): g1})
    assert lib.lookup(0.25, 0.0).leg_angle_offset_rad == pytest.approx(0.025)
    assert lib.lookup(5.0, 3.0).leg_angle_offset_rad == pytest.approx(0.1)  # clamped
    p = tmp_path / "lib.json"
    lib.save(p)
    assert GaitLibrary.load(p).lookup(0.5, 0.0).leg_angle_offset_rad == pytest.approx(0.05)


def test_committed_gait_library_loads():
    assert DEFAULT_LIBRARY_PATH.exists(), "run python -m scenarios.gaits.make_gaits"
    lib = GaitLibrary.load(DEFAULT_LIBRARY_PATH)
    assert 0.0 in lib.vx_grid and 1.0 in lib.vx_grid and -0.2 in lib.vy_grid and 0.2 in lib.vy_grid


def test_controller_params_frozen():
    p = ControllerParams()
    with pytest.raises(Exception):
        p.kp = (1.0,)


def test_state_machine_phase_and_steps(model):
    """Stand -> shift -> walk; tau in [0, switch_max_tau); stance alternates with k."""
    w = CassieWalker(model)
    w.set_command(0.5, 0.0)
    reg = Regulator(PD_ONLY_PARAMS)
    c, p = w.controller, w.params
    seen_modes, last = [], (None, None)
    while w.time_s < 3.0:
        apply_regulator(w, reg, 0.01)
        w.advance(20)
        if not seen_modes or seen_modes[-1] != c.mode:
            seen_modes.append(c.mode)
        assert 0.0 <= c.tau < p.switch_max_tau
        k, st = c.step_index, c.stance
        if last[0] is not None and k == last[0] + 1:
            assert st != last[1]  # each new step swaps the stance leg
        last = (k, st)
    assert seen_modes == ["stand", "shift", "walk"]
    # Realised steps ~0.3 s (T = 0.4 s nominal, touchdown from tau = 0.6): >= 5 in ~2.2 s.
    assert c.step_index >= 5
    assert w.regulator_inputs()["step_index"] == c.step_index


def test_ground_height_on_terrain_matches_model_module():
    from plant.perturbation import Perturbation
    from plant.terrain import TerrainSpec, terrain_height_at

    m = load_model("menagerie", Perturbation(terrain=TerrainSpec(max_height_m=0.05, max_slope_deg=10.0,
                                                                 seed=3, size_m=5.0)))
    ph = CassiePhysics(m)
    rng = np.random.default_rng(0)  # explicit seed
    for x, y in rng.uniform(-4.5, 4.5, size=(20, 2)):
        assert ph.ground_height_m(x, y) == pytest.approx(terrain_height_at(m, x, y), abs=1e-9)
    # Standing on the flat start patch: pelvis height above ground as on the flat floor.
    assert ph.pelvis_height_above_ground_m() == pytest.approx(1.006, abs=2e-3)


def test_ground_is_the_floor_plane_on_both_models(phys):
    """Without terrain the ground is each model's floor plane (OSU's sits at z = 0 too)."""
    osu = CassiePhysics(load_model("osu"))
    for ph in (phys, osu):
        assert not ph.ground.has_terrain and ph.ground_height_m(3.0, -2.0) == 0.0
    assert osu.pelvis_height_above_ground_m() == pytest.approx(1.006, abs=2e-3)


def test_model_without_home_key_is_refused(model, tmp_path):
    """CassiePhysics stands the robot on the model's ``home`` keyframe (load_model adds it)."""
    spec = mujoco.MjSpec.from_file(str(menagerie_xml_path()))
    spec.delete(spec.key("home"))
    with pytest.raises(ModelError, match="'home' keyframe"):
        CassiePhysics(spec.compile())
