"""The scenario language's robustness fields: floor friction, constant slopes, link masses,
pushes on any body, events during a walk, command ramps, command profiles and seeded
random pushes. Each is validated up front (every problem at once, naming the field and
the allowed range) and reaches the plant."""
from __future__ import annotations

import tomllib

import mujoco
import numpy as np
import pytest

from plant.model import load_model
from scenarios.cosim.master import run_arm
from scenarios.cosim.regulators import make_regulator
from scenarios.errors import ScenarioError
from scenarios.lang import plantio, spec

HEAD = '''name = "x"
duration_s = 4.0
seed = 1
'''
CMD = '''[[command]]
t_s = 0.0
vx_des = 0.5
'''


def parse(text: str, check_plant: bool = True):
    return spec.parse_scenario(tomllib.loads(text), check_plant=check_plant)


def problems_of(text: str, check_plant: bool = True) -> list[str]:
    with pytest.raises(ScenarioError) as exc:
        parse(text, check_plant)
    return exc.value.problems


def has(problems: list[str], *parts: str) -> bool:
    return any(all(p in q for p in parts) for q in problems)


# --------------------------------------------------------------------------- floor friction, slopes
def test_floor_friction_reaches_the_floor_with_priority():
    s = parse(HEAD + "floor_friction = 0.6\n" + CMD)
    assert s.floor_friction == 0.6
    model, _ = plantio.load_plant_model(s)
    floor = np.flatnonzero(model.geom_bodyid == 0)
    assert np.all(model.geom_friction[floor, 0] == 0.6)
    robot = np.flatnonzero(model.geom_bodyid != 0)
    # the floor's friction is the contact's only if it outranks every robot geom
    assert model.geom_priority[floor].min() > model.geom_priority[robot].max()


def test_floor_friction_and_slopes_out_of_range_all_at_once():
    found = problems_of(HEAD + "floor_friction = 2.5\nslope_deg = 20.0\ncross_slope_deg = -16\n" + CMD,
                        check_plant=False)
    assert has(found, "floor_friction=2.5", "(0, 2]")
    assert has(found, "slope_deg=20.0", "[-15, 15] deg")
    assert has(found, "cross_slope_deg=-16", "[-15, 15] deg")


def test_slope_with_terrain_refused():
    found = problems_of(HEAD + "slope_deg = 3.0\n" + CMD + "[terrain]\nmax_height_m = 0.1\nmax_slope_deg = 10.0\n"
                        "seed = 1\n", check_plant=False)
    assert has(found, "give a slope or a terrain, not both")


def test_slope_tilts_the_floor_and_the_ground_height_follows():
    s = parse(HEAD + "slope_deg = 5.0\ncross_slope_deg = -3.0\n" + CMD)
    model, _ = plantio.load_plant_model(s)
    from plant.cassie import CassiePhysics

    ph = CassiePhysics(model)
    for x, y in ((1.0, 0.0), (0.0, 1.0), (2.0, -1.5)):
        want = x * np.tan(np.radians(5.0)) + y * np.tan(np.radians(-3.0))
        assert ph.ground_height_m(x, y) == pytest.approx(want, abs=1e-12)
    # MuJoCo's own contact agrees: a ray straight down from above (x, y) hits the plane there
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    geomid = np.zeros(1, dtype=np.int32)
    dist = mujoco.mj_ray(model, data, np.array([2.0, -1.5, 5.0]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid)
    assert 5.0 - dist == pytest.approx(ph.ground_height_m(2.0, -1.5), abs=1e-9)


# --------------------------------------------------------------------------- link masses
def test_link_masses_by_scale_and_kg():
    s = parse(HEAD + CMD + '[[link_mass]]\nbody = "left-shin"\nscale = 1.5\n'
              '[[link_mass]]\nbody = "right-tarsus"\nmass_kg = 2.0\n')
    nominal = load_model("menagerie")
    model, _ = plantio.load_plant_model(s)
    for body, mass in (("left-shin", 1.5 * nominal.body("left-shin").mass[0]), ("right-tarsus", 2.0)):
        assert model.body(body).mass[0] == pytest.approx(mass, rel=1e-12)
        ratio = mass / nominal.body(body).mass[0]  # the inertia scales with the mass
        np.testing.assert_allclose(model.body(body).inertia, ratio * nominal.body(body).inertia, rtol=1e-12)
    assert model.body("right-shin").mass[0] == nominal.body("right-shin").mass[0]


def test_link_masses_checked_against_the_model_and_ranges():
    found = problems_of(HEAD + CMD + '[[link_mass]]\nbody = "left-wing"\nscale = 1.5\n'
                        '[[link_mass]]\nbody = "left-shin"\nscale = 9.0\n'
                        '[[link_mass]]\nbody = "right-shin"\nscale = 1.0\nmass_kg = 1.0\n')
    assert has(found, "link_mass[2]", "exactly one of scale")
    assert has(found, "link_mass_scale['left-shin']=9.0", "(0, 5]")
    with pytest.raises(ScenarioError) as exc:
        parse(HEAD + CMD + '[[link_mass]]\nbody = "left-wing"\nscale = 1.5\n')
    assert has(exc.value.problems, "link_mass[0].body", "'left-wing'", "no such body", "left-shin")


# --------------------------------------------------------------------------- pushes on any body
def test_push_on_another_body():
    s = parse(HEAD + CMD + '[[push]]\nt_s = 1.0\nforce_n = [20.0, 0.0, 0.0]\nduration_s = 0.1\nbody = "left-tarsus"\n'
              '[[push]]\nt_s = 1.05\nforce_n = [0.0, 10.0, 0.0]\nduration_s = 0.1\n')
    k = round(1.0 / s.comm_step_s)
    assert s.pushed_bodies == ("left-tarsus",)
    assert s.body_forces_at_step(k) == {"left-tarsus": (20.0, 0.0, 0.0)}
    assert s.body_forces_at_step(k + 20) == {}
    # the pelvis' sum holds the pelvis pushes only
    assert s.push_force_at_step(k) == (0.0, 0.0, 0.0)
    assert s.push_force_at_step(k + 10) == (0.0, 10.0, 0.0)
    found = problems_of(HEAD + CMD + '[[push]]\nt_s = 1.0\nforce_n = [1.0, 0.0, 0.0]\nduration_s = 0.1\n'
                        'body = "tail"\n')
    assert has(found, "push[0].body", "'tail'", "no such body")
    assert plantio.plant_fmu_problems(s) and "pelvis only" in plantio.plant_fmu_problems(s)[0]


class Capture:
    """A plant factory for run_arm that keeps the walker it made."""

    def __call__(self, scenario, model):
        from plant.sim import CassieWalker

        self.walker = CassieWalker(model)
        self.forces = []
        inner = self.walker.advance
        body = self.walker.model.body("left-tarsus").id

        def advance(n):
            self.forces.append(self.walker.data.xfrc_applied[body, :3].copy())
            inner(n)
        self.walker.advance = advance
        return self.walker


def test_body_push_and_events_reach_the_running_plant():
    s = parse('''name = "x"
duration_s = 1.0
seed = 1
torso_com_offset_m = [0.01, 0.0, 0.0]
joint_damping_scale = 2.0
[[command]]
t_s = 0.0
vx_des = 0.5
[[push]]
t_s = 0.2
force_n = [5.0, 0.0, 0.0]
duration_s = 0.1
body = "left-tarsus"
[[event]]
t_s = 0.5
torso_mass_kg = 15.0
torso_com_offset_m = [0.03, -0.02, 0.0]
joint_damping_scale = 3.0
floor_friction = 0.7
''')
    start, _ = plantio.load_plant_model(s)
    cap = Capture()
    run_arm(s, "adaptive", make_regulator("inprocess"), plant=cap)
    m = cap.walker.model
    pelvis = m.body("cassie-pelvis").id
    assert m.body_mass[pelvis] == 15.0
    np.testing.assert_allclose(m.body_ipos[pelvis] - start.body_ipos[pelvis], [0.02, -0.02, 0.0], atol=1e-15)
    np.testing.assert_allclose(m.dof_damping, start.dof_damping * 1.5, rtol=1e-12)
    assert np.all(m.geom_friction[m.geom_bodyid == 0, 0] == 0.7)
    pushed = [i for i, f in enumerate(cap.forces) if f[0] != 0.0]
    assert pushed == list(range(40, 60)) and all(cap.forces[i][0] == 5.0 for i in pushed)


def test_events_validated_all_at_once():
    found = problems_of(HEAD + "joint_damping_scale = 0.0\n" + CMD + '''[[event]]
t_s = 2.0
torso_mass_kg = 200.0
[[event]]
t_s = 1.0
floor_friction = 0.0
[[event]]
t_s = 1.5
[[event]]
t_s = 3.0
joint_damping_scale = 2.0
[[event]]
t_s = 5.0
torso_com_offset_m = [0.9, 0.0, 0.0]
''', check_plant=False)
    assert has(found, "event[0]", "torso_mass_kg=200.0", "(0, 100] kg")
    assert has(found, "event[1].t_s", "must be > event[0].t_s")
    assert has(found, "event[1]", "floor_friction=0.0", "(0, 2]")
    assert has(found, "event[2]", "changes nothing")
    assert has(found, "event[3].joint_damping_scale", "non-zero joint_damping_scale")
    assert has(found, "event[4].t_s", "must be < duration_s")
    assert has(found, "event[4]", "torso_com_offset_m[x]=0.9", "[-0.5, 0.5] m")


# --------------------------------------------------------------------------- command ramps and profiles
def test_command_ramp_is_linear_between_points():
    s = parse(HEAD + CMD + "[[command]]\nt_s = 2.0\nvx_des = 1.0\nvy_des = 0.2\nramp = true\n"
              "[[command]]\nt_s = 3.0\nvx_des = 0.0\n")
    h = s.comm_step_s
    assert s.command_at_step(0) == (0.5, 0.0, 0.0)
    vx, vy, _ = s.command_at_step(round(1.0 / h))  # halfway up the ramp
    assert vx == pytest.approx(0.75, abs=1e-12) and vy == pytest.approx(0.1, abs=1e-12)
    assert s.command_at_step(round(2.0 / h)) == (1.0, 0.2, 0.0)
    assert s.command_at_step(round(2.5 / h)) == (1.0, 0.2, 0.0)  # no ramp into the next point: a step
    assert s.command_at_step(round(3.0 / h)) == (0.0, 0.0, 0.0)
    found = problems_of(HEAD + "[[command]]\nt_s = 0.0\nvx_des = 0.5\nramp = true\n"
                        "[[command]]\nt_s = 1.0\nvx_des = 0.5\nramp = 1\n", check_plant=False)
    assert has(found, "command[0].ramp", "no previous point")
    assert has(found, "command[1].ramp = 1", "true or false")


PROFILE = '''[command_profile]
shape = "ramped"
seed = 7
hold_s = 1.0
vx_des = [0.0, 1.0]
vy_des = [-0.2, 0.2]
'''


def test_command_profile_is_seeded_and_in_range():
    s = parse(HEAD + PROFILE)
    assert [c.t_s for c in s.commands] == [0.0, 1.0, 2.0, 3.0]
    assert [c.ramp for c in s.commands] == [False, True, True, True]
    assert all(0.0 <= c.vx_des <= 1.0 and -0.2 <= c.vy_des <= 0.2 for c in s.commands)
    assert parse(HEAD + PROFILE).commands == s.commands
    other = parse(HEAD + PROFILE.replace("seed = 7", "seed = 8"))
    assert other.commands != s.commands
    stepped = parse(HEAD + PROFILE.replace('"ramped"', '"stepped"'))
    assert not any(c.ramp for c in stepped.commands)
    found = problems_of(HEAD + CMD + PROFILE.replace('"ramped"', '"wavy"').replace("[0.0, 1.0]", "[0.0, 3.0]")
                        .replace("hold_s = 1.0", "hold_s = 0.0001"), check_plant=False)
    assert has(found, "give [[command]] or [command_profile], not both")
    assert has(found, "command_profile.shape", "stepped, ramped")
    assert has(found, "command_profile.vx_des", "-2 <= low <= high <= 2")
    assert has(found, "command_profile.hold_s", "whole number of communication steps")


RANDOM_PUSHES = '''[random_pushes]
count = 3
seed = 11
t_s = [1.0, 3.0]
magnitude_n = [15.0, 30.0]
duration_s = 0.1
bodies = ["cassie-pelvis", "left-hip-pitch"]
'''


def test_random_pushes_are_seeded_on_the_grid_and_in_range():
    s = parse(HEAD + CMD + '[[push]]\nt_s = 0.5\nforce_n = [1.0, 0.0, 0.0]\nduration_s = 0.1\n' + RANDOM_PUSHES)
    assert len(s.pushes) == 4 and s.pushes[0].force_n == (1.0, 0.0, 0.0)
    for p in s.pushes[1:]:
        assert 1.0 <= p.t_s <= 3.0 and p.duration_s == 0.1 and p.body in ("cassie-pelvis", "left-hip-pitch")
        assert abs(p.t_s / s.comm_step_s - round(p.t_s / s.comm_step_s)) < 1e-9
        assert 15.0 - 1e-3 <= np.hypot(*p.force_n[:2]) <= 30.0 + 1e-3 and p.force_n[2] == 0.0
    assert parse(HEAD + CMD + RANDOM_PUSHES).pushes == s.pushes[1:]
    found = problems_of(HEAD + CMD + RANDOM_PUSHES.replace("count = 3", "count = 1000")
                        .replace("[1.0, 3.0]", "[1.0, 5.0]").replace("[15.0, 30.0]", "[30.0, 15.0]"),
                        check_plant=False)
    assert has(found, "random_pushes.count = 1000", "<= 100")
    assert has(found, "random_pushes.t_s", "<= 4")
    assert has(found, "random_pushes.magnitude_n", "low <= high")


# --------------------------------------------------------------------------- the plant FMU's parameters
def test_plant_fmu_parameters_carry_friction_slopes_and_link_scales():
    from fmu_src.plant_fmu import fmu_core

    s = parse(HEAD + "floor_friction = 0.7\nslope_deg = -4.0\ncross_slope_deg = 2.0\n" + CMD +
              '[[link_mass]]\nbody = "left-hip-pitch"\nscale = 1.2\n')
    pert = plantio.build_perturbation(s)
    values = fmu_core.values_from_perturbation("menagerie", pert)
    assert values["floor_friction"] == 0.7 and values["floor_slope_deg"] == -4.0
    assert values["floor_cross_slope_deg"] == 2.0 and values["link_mass_scale_left_hip_pitch"] == 1.2
    assert fmu_core.perturbation_from_values(values) == pert
    assert fmu_core.problems(dict(values, floor_friction=3.0, floor_slope_deg=16.0))
    specs = {p.name: p for p in fmu_core.PARAM_SPECS}
    assert (specs["floor_friction"].min, specs["floor_friction"].max) == (0.0, 2.0)
    assert (specs["floor_slope_deg"].min, specs["floor_slope_deg"].max) == (-15.0, 15.0)
    assert not plantio.plant_fmu_problems(s)
    kg = parse(HEAD + CMD + '[[link_mass]]\nbody = "left-hip-pitch"\nmass_kg = 6.0\n[[event]]\nt_s = 1.0\n'
               'floor_friction = 0.5\n')
    found = plantio.plant_fmu_problems(kg)
    assert has(found, "event") and has(found, "link_mass[0].mass_kg")
