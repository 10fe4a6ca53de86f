"""Scenario files, metrics, report and CLI without simulation (fast).

- every suite file validates; a bad file gives one ScenarioError listing every problem,
  each naming its field; unknown keys get a did-you-mean; comm step not a multiple of
  the plant step; regulator overrides checked against the core's PARAM_SPECS ranges;
- metrics on hand-made structured arrays;
- the report lists every scenario (missing and failed runs too);
- ``python -m scenarios list`` through a subprocess.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from scenarios.errors import ScenarioError
from scenarios import report
from scenarios.lang import spec
from scenarios.results import metrics, output

GOOD = """
name = "tiny"
description = "a test"
duration_s = 2.0
comm_step_s = 0.005
seed = 3
[[command]]
t_s = 0.0
vx_des = 0.5
"""


def parse(text: str, **kw) -> Scenario:
    return spec.parse_scenario(tomllib.loads(text), source="test.toml", **kw)


def problems_of(text: str) -> list[str]:
    with pytest.raises(ScenarioError) as info:
        parse(text)
    return info.value.problems


# --------------------------------------------------------------------------- suite
def test_every_suite_file_validates():
    suite = spec.load_suite()
    names = {s.name for s in suite}
    assert len(suite) == len(spec.suite_files()) >= 15
    for required in ("nominal", "mass_15kg", "mass_20kg", "mass_23kg", "com_fwd_5cm", "com_fwd_10cm",
                     "com_back_10cm", "compare_fixed_speed", "compare_staircase", "diagonal_04_m02",
                     "diagonal_06_01", "push_fwd_30n", "push_back_25n", "terrain_uneven", "redundancy_hip_zero"):
        assert required in names
    for s in suite:
        assert s.claim is not None and s.claim.text and s.claim.checks, s.name
        assert s.duration_s >= 30.0, s.name
        assert s.commands[0].t_s == 0.0
        assert s.n_comm_steps * s.comm_step_s == pytest.approx(s.duration_s)


def test_suite_paper_values():
    by = {s.name: s for s in spec.load_suite()}
    assert [by[f"mass_{m}kg"].torso_mass_kg for m in (15, 20, 23)] == [15.0, 20.0, 23.0]
    assert by["com_back_10cm"].torso_com_offset_m == (-0.1, 0.0, 0.0)
    fixed = by["compare_fixed_speed"]
    assert fixed.torso_added_mass_kg == 5.0 and fixed.torso_com_offset_m == (0.1, 0.0, 0.0)
    assert [a.name for a in fixed.arms] == ["adaptive", "pd_only"]
    assert dict(fixed.arm("pd_only").overrides)["adaptation_enabled"] is False
    assert len({c.vx_des for c in by["compare_staircase"].commands}) >= 3
    assert (by["diagonal_04_m02"].commands[0].vx_des, by["diagonal_04_m02"].commands[0].vy_des) == (0.4, -0.2)
    push = by["push_fwd_30n"].pushes[0]
    assert (push.t_s, push.force_n, push.duration_s) == (2.5, (30.0, 0.0, 0.0), 0.1)
    assert by["push_back_25n"].pushes[0].force_n == (-25.0, 0.0, 0.0)
    terrain = by["terrain_uneven"].terrain
    assert (terrain.max_slope_deg, terrain.max_height_m) == (20.0, 0.4)
    red = by["redundancy_hip_zero"]
    assert dict(red.arm("hip_zero").overrides)["psi_gain_swing_hip_pitch"] == 0.0
    assert "psi_gain_swing_hip_pitch" not in dict(red.arm("adaptive").overrides)


def test_good_file_and_schedule():
    s = parse(GOOD + "\n[[command]]\nt_s = 1.0\nvx_des = 0.2\nvy_des = 0.1\n"
              "[[command]]\nt_s = 1.5\nvx_des = 0.3\nyaw_rate_des = -0.25\n"
              "[[push]]\nt_s = 0.5\nforce_n = [10, 0, 0]\nduration_s = 0.1\n")
    assert s.n_comm_steps == 400
    assert s.command_at_step(0) == (0.5, 0.0, 0.0) and s.command_at_step(199) == (0.5, 0.0, 0.0)
    assert s.command_at_step(200) == (0.2, 0.1, 0.0)  # yaw_rate_des defaults to 0
    assert s.command_at_step(299) == (0.2, 0.1, 0.0) and s.command_at_step(300) == (0.3, 0.0, -0.25)
    assert s.commands[2] == CommandPoint(1.5, 0.3, 0.0, -0.25)
    assert s.push_force_at_step(99) == (0.0, 0.0, 0.0)
    assert s.push_force_at_step(100) == (10.0, 0.0, 0.0) and s.push_force_at_step(119) == (10.0, 0.0, 0.0)
    assert s.push_force_at_step(120) == (0.0, 0.0, 0.0)
    assert [a.name for a in s.arms] == ["adaptive"]
    assert dict(s.arms[0].overrides) == {"seed": 3}  # the top-level seed seeds the regulator


def test_bad_file_lists_every_problem_naming_fields():
    bad = """
name = "Bad Name"
duration_s = -1
comm_step_s = 0.0007
torso_com_offset_m = [0.1, 0.0]
[[command]]
t_s = 0.5
vx_des = 9.0
[[push]]
t_s = 1.0
force_n = [1, 2, 3]
duration_s = 0.1
[[push]]
t_s = 1.0
force_n = [1, 2, 3]
duration_s = -0.1
[regulator]
learning_rate = -5.0
Kp_xx = 1.0
"""
    probs = problems_of(bad)
    text = "\n".join(probs)
    assert "name = 'Bad Name'" in text
    assert "duration_s = -1: must be > 0" in text
    assert any(p.startswith("comm_step_s = 0.0007") and "0.5 ms" in p for p in probs)
    assert any(p.startswith("torso_com_offset_m") for p in probs)
    assert "command[0].vx_des = 9: must be <= 2" in text
    assert any(p.startswith("command[0].t_s") and "t_s = 0" in p for p in probs)
    assert "push[1].duration_s = -0.1: must be > 0" in text
    assert "seed: required" in probs  # seeds are explicit
    assert any(p.startswith("regulator.learning_rate = -5: must be a finite number in [") for p in probs)
    assert any(p.startswith("regulator.Kp_xx") and "did you mean 'Kp_x'" in p for p in probs)
    assert len(probs) >= 9
    with pytest.raises(ScenarioError) as info:
        parse(bad)
    assert str(info.value).startswith("test.toml: ")  # one error, every problem in its message
    assert all(p in str(info.value) for p in probs)


def test_unknown_keys_did_you_mean():
    probs = problems_of("durration_s = 3.0\n" + GOOD + "[[push]]\nt_s = 0.5\nforce = [1, 0, 0]\nduration_s = 0.1\n")
    assert any(p.startswith("durration_s: unknown key") and "did you mean 'duration_s'" in p for p in probs)
    assert any(p.startswith("push[0].force: unknown key") and "'force_n'" in p for p in probs)
    assert any(p.startswith("push[0].force_n: required") for p in probs)


def test_comm_step_must_be_whole_plant_steps():
    probs = problems_of(GOOD.replace("comm_step_s = 0.005", "comm_step_s = 0.0052"))
    assert probs == ["comm_step_s = 0.0052: must be a whole multiple of the plant step 0.5 ms"]
    assert parse(GOOD.replace("comm_step_s = 0.005", "comm_step_s = 0.0005")).n_comm_steps == 4000
    probs = problems_of(GOOD.replace("duration_s = 2.0", "duration_s = 2.0025"))
    assert any(p.startswith("duration_s = 2.0025") for p in probs)


def test_override_out_of_range_and_wrong_type():
    spec_by = {s.name: s for s in PARAM_SPECS}
    lr = spec_by["learning_rate"]
    too_big = (lr.max if lr.max is not None else 1e6) * 10 + 1
    probs = problems_of(GOOD + f"[regulator]\nlearning_rate = {too_big}\nn_neurons = 2.5\nadaptation_enabled = 1\n")
    # the core's own check (params_from_overrides), reported under the scenario's field
    assert any(p.startswith(f"regulator.learning_rate = {too_big:g}: must be a finite number in [") for p in probs)
    assert any(p.startswith("regulator.n_neurons = 2.5: must be an integer in [") for p in probs)
    assert any(p.startswith("regulator.adaptation_enabled = 1: must be a bool") for p in probs)


def test_arms_compare_and_named_arms():
    s = parse('compare = ["adaptive", "pd_only", "hip0"]\n' + GOOD +
              '[regulator]\nlearning_rate = 0.001\n'
              '[[arm]]\nname = "hip0"\nregulator = { psi_gain_swing_hip_pitch = 0.0 }\n')
    arms = {a.name: a.overrides_dict() for a in s.arms}
    assert list(arms) == ["adaptive", "pd_only", "hip0"]
    assert arms["pd_only"] == {"learning_rate": 0.001, "seed": 3, "adaptation_enabled": False}
    assert arms["hip0"] == {"learning_rate": 0.001, "seed": 3, "psi_gain_swing_hip_pitch": 0.0}
    probs = problems_of('compare = ["adaptiv"]\n' + GOOD + '[[arm]]\nname = "x"\nregulator = {}\n'
                        '[[arm]]\nname = "pd_only"\n')
    assert any(p.startswith("compare[0] = 'adaptiv': unknown arm") and "'adaptive'" in p for p in probs)
    assert any("arm 'x' is defined" in p for p in probs)
    assert any(p.startswith("arm[1].name = 'pd_only': is a built-in arm") for p in probs)


def test_claim_checks_validated():
    probs = problems_of(GOOD + '[claim]\ntext = "t"\n[[claim.check]]\narm = "pd_only"\nmetric = "steady_error"\n'
                        'op = "=<"\nvalue = 0.1\nother_arm = "adaptive"\n')
    assert any(p.startswith("claim.check[0].arm = 'pd_only'") for p in probs)
    assert any(p.startswith("claim.check[0].metric = 'steady_error'") for p in probs)
    assert any(p.startswith("claim.check[0].op = '=<'") for p in probs)
    assert any(p.startswith("claim.check[0]: give exactly one of value or other_arm") for p in probs)


def test_perturbation_checked_by_the_plant_and_terrain():
    probs = problems_of("torso_mass_kg = 250.0\njoint_damping_scale = 20.0\n" + GOOD +
                        "[terrain]\nmax_height_m = 0.4\nmax_slope_deg = 50\nseed = 1\n")
    # the ranges are the plant's own (Perturbation / TerrainSpec), checked before any model loads
    assert "perturbation: torso_mass_kg=250.0 is out of range (0, 100] kg (or None)" in probs
    assert any(p.startswith("perturbation: joint_damping_scale=20") and "[0, 10]" in p for p in probs)
    assert any(p.startswith("perturbation: terrain.max_slope_deg=50") and "(0, 45] deg" in p for p in probs)
    probs = problems_of("torso_added_mass_kg = -20.0\ntorso_com_offset_m = [0.6, 0, 0]\n" + GOOD)
    assert any(p.startswith("perturbation: torso_added_mass_kg=-20.0 makes the torso mass") for p in probs)  # < 0 kg
    assert any(p.startswith("perturbation: torso_com_offset_m[x]=0.6") for p in probs)
    probs = problems_of(GOOD + "[terrain]\nmax_slope_deg = 50\nseed = -1\n")  # every problem at once
    assert "terrain.max_height_m: required" in probs
    assert any(p.startswith("perturbation: terrain.max_slope_deg=50") for p in probs)
    assert any(p.startswith("perturbation: terrain.seed=-1") for p in probs)
    assert not any("max_height_m=" in p for p in probs)  # the missing key is reported once


def test_plant_ranges_reported_with_every_other_problem():
    # the plant's ranges are checked while the file is read, not only once it is otherwise valid
    probs = problems_of("torso_mass_kg = 150.0\n" + GOOD.replace('name = "tiny"', 'name = "Bad"'))
    assert any(p.startswith("name = 'Bad'") for p in probs)
    assert any(p.startswith("perturbation: torso_mass_kg=150.0 is out of range (0, 100]") for p in probs)


def test_seed_and_arm_names_checked_once_in_their_place():
    # the top-level seed is the regulator's `seed`: the core's range, named as the file's field
    assert problems_of(GOOD.replace("seed = 3", "seed = 3000000000")) == [
        "seed = 3000000000: must be an integer in [0, 2147483647]"]
    # an [[arm]] with an empty name is an error, not silently dropped
    assert problems_of(GOOD + '[[arm]]\nname = ""\n') == ["arm[0].name = '': must match [a-z0-9][a-z0-9_-]*"]


def test_model_path_and_missing_file(tmp_path):
    probs = problems_of('model = "no/such/model.xml"\n' + GOOD)
    assert any(p.startswith("model = 'no/such/model.xml'") for p in probs)
    xml = tmp_path / "m.xml"
    xml.write_text("<mujoco/>")
    f = tmp_path / "s.toml"
    f.write_text('model = "m.xml"\n' + GOOD)
    assert spec.load_scenario(f, check_plant=False).model == str(xml.resolve())  # relative to the scenario's folder
    with pytest.raises(ScenarioError, match="not the Cassie model"):  # compiled up front: it is no Cassie
        spec.load_scenario(f)
    with pytest.raises(ScenarioError, match="file not found"):
        spec.load_scenario(tmp_path / "none.toml")
    (tmp_path / "broken.toml").write_text("name = ")
    with pytest.raises(ScenarioError, match="TOML syntax error"):
        spec.load_scenario(tmp_path / "broken.toml")


def test_resolve_targets():
    assert [s.name for s in spec.resolve_targets(["nominal"])] == ["nominal"]
    paper = spec.resolve_targets(["paper"])
    assert "nominal" not in {s.name for s in paper} and len(paper) >= 14
    assert len(spec.resolve_targets(["all"])) == len(spec.suite_files())
    with pytest.raises(ScenarioError, match="did you mean 'nominal'"):
        spec.resolve_targets(["nominl"])


def test_a_suite_name_reads_its_own_file_and_all_reads_every_file(tmp_path, monkeypatch):
    """A broken suite file stops ``all`` (named with its problem) but not another scenario
    named on its own; a file whose name is not its stem is refused when named."""
    nominal = (spec.SUITE_DIR / "nominal.toml").read_text()
    (tmp_path / "nominal.toml").write_text(nominal)
    (tmp_path / "broken.toml").write_text(nominal.replace("duration_s = ", "duration_s = -"))
    (tmp_path / "renamed.toml").write_text(nominal)
    monkeypatch.setattr(spec, "SUITE_DIR", tmp_path)
    assert [s.name for s in spec.resolve_targets(["nominal"], check_plant=False)] == ["nominal"]
    with pytest.raises(ScenarioError, match=r"suite: broken\.toml: duration_s") as err:
        spec.resolve_targets(["all"], check_plant=False)
    assert "renamed.toml: name = 'nominal': must equal the file name ('renamed')" in str(err.value)
    with pytest.raises(ScenarioError, match=r"renamed\.toml: name = 'nominal': must equal the file name"):
        spec.resolve_targets(["renamed"], check_plant=False)


# --------------------------------------------------------------------------- metrics
def rows_from(t, vx_avg, vx_des, vy=None, vy_des=None, step_index=None):
    n = len(t)
    dt = np.dtype([("t", "f8"), ("cmd_vx_des", "f8"), ("cmd_vy_des", "f8"), ("in_vx", "f8"), ("in_vy", "f8"),
                   ("in_step_index", "i8"), ("in_pitch", "f8"), ("in_roll", "f8"), ("tel_vx_step_avg", "f8")])
    rows = np.zeros(n, dtype=dt)
    rows["t"] = t
    rows["cmd_vx_des"] = vx_des
    rows["cmd_vy_des"] = 0.0 if vy_des is None else vy_des
    rows["in_vx"] = vx_avg
    rows["tel_vx_step_avg"] = vx_avg
    rows["in_vy"] = 0.0 if vy is None else vy
    rows["in_step_index"] = 0 if step_index is None else step_index
    return rows


def test_steady_state_error_last_5_s():
    t = np.arange(2000) * 0.005  # 10 s
    vx = np.where(t < 5.0, 0.0, 0.45)
    rows = rows_from(t, vx, 0.5)
    assert metrics.steady_state_error(rows, "vx") == pytest.approx(0.05)
    assert metrics.steady_state_error(rows, "vy") == pytest.approx(0.0)
    assert metrics.steady_state_error(rows, "vx", fell=True) is None


def test_convergence_time():
    t = np.arange(2000) * 0.005  # 10 s
    err = np.where(t < 3.0, 0.3, 0.01)
    err[t == 4.0] = 0.06  # one excursion out of the band
    rows = rows_from(t, 0.5 + err, 0.5)
    assert metrics.convergence_time(rows) == pytest.approx(4.005)
    assert metrics.convergence_time(rows, t_from=2.0) == pytest.approx(2.005)
    assert metrics.convergence_time(rows, fell=True) is None
    never = rows_from(t, np.full(2000, 0.7), 0.5)
    assert metrics.convergence_time(never) is None
    late = rows_from(t, np.where(t < 9.5, 0.7, 0.5), 0.5)  # settles 0.5 s before the end
    assert metrics.convergence_time(late) is None
    always = rows_from(t, np.full(2000, 0.52), 0.5)
    assert metrics.convergence_time(always, t_from=2.5) == 0.0


def test_step_average_fallback_for_vy():
    vy = np.array([1.0, 3.0, 10.0, 20.0, 30.0, 5.0])
    steps = np.array([0, 0, 1, 1, 1, 2])
    avg = metrics.step_average(vy, steps)
    assert avg.tolist() == [1.0, 2.0, 2.0, 2.0, 2.0, 20.0]
    rows = rows_from(np.arange(6) * 0.005, 0.5, 0.5, vy=vy, vy_des=0.0, step_index=steps)
    ex, ey = metrics.velocity_errors(rows)
    assert ex.tolist() == [0.0] * 6 and ey.tolist() == avg.tolist()


def test_stride_average_and_lateral_stride_metrics():
    steps = np.array([0, 0, 1, 1, 2, 2, 3, 3])
    step_avg = np.array([0.0, 0.0, 0.2, 0.2, -0.1, -0.1, 0.3, 0.3])
    # before the second completed step: the step average; then the mean of the last two
    assert metrics.stride_average(step_avg, steps).tolist() == pytest.approx(
        [0.0, 0.0, 0.2, 0.2, 0.05, 0.05, 0.1, 0.1])
    # a lateral step average alternating +-0.06 around the 0.1 command with the sway:
    # outside the 0.05 band at every step, but the stride error is 0
    t = np.arange(2000) * 0.005  # 10 s, a step every 0.4 s
    si = (t // 0.4).astype(int)
    vy = 0.1 + np.where(si % 2 == 0, 0.06, -0.06)
    rows = rows_from(t, 0.5, 0.5, vy=vy, vy_des=0.1, step_index=si)
    _, ey = metrics.velocity_errors(rows)
    assert np.all(np.abs(ey[t > 1.0]) > 0.05)
    assert np.all(np.abs(metrics.lateral_stride_error(rows)[t > 1.0]) < 1e-12)
    assert metrics.steady_state_error(rows, "vy") == pytest.approx(0.06)
    assert metrics.steady_state_error(rows, "vy_stride") == pytest.approx(0.0, abs=1e-12)
    # convergence judges the lateral velocity at the stride: settled from the second
    # completed step (t = 0.8 s) on, where the step average never would be
    assert metrics.convergence_time(rows) == pytest.approx(0.8)
    m = metrics.summarize_arm(rows, fell=False, t_fall_s=None)
    assert m["steady_state_error_vy_stride"] == pytest.approx(0.0, abs=1e-12)


def test_run_error_vx_after_startup():
    t = np.arange(2000) * 0.005  # 10 s
    rows = rows_from(t, np.where(t < 5.0, 0.0, np.where(t < 7.5, 0.6, 0.4)), 0.5)
    assert metrics.run_error_vx(rows) == pytest.approx(0.1)  # start-up (error 0.5) excluded
    assert metrics.run_error_vx(rows, startup_s=0.0) == pytest.approx(0.3)
    assert metrics.run_error_vx(rows, fell=True) is None
    assert metrics.run_error_vx(rows, startup_s=20.0) is None


def test_settled_error_vx_counts_rows_where_the_command_has_been_constant_for_2_5_s():
    t = np.arange(4000) * 0.005  # 20 s; commands: 0.5 from 0 s, 1.0 from 10 s, vy_des changes at 15 s
    vx_des = np.where(t < 10.0, 0.5, 1.0)
    vy_des = np.where(t < 15.0, 0.0, 0.1)
    # error 0.3 in each command's first 2.5 s (the transient), 0.02 once settled; 1.0 in start-up
    since = np.where(t < 10.0, t, np.where(t < 15.0, t - 10.0, t - 15.0))
    err = np.where(t < 5.0, 1.0, np.where(since < 2.5, 0.3, 0.02))
    rows = rows_from(t, vx_des + err, vx_des, vy_des=vy_des)
    # counted: [5, 10) (the first command settled since 2.5 s), [12.5, 15), [17.5, 20)
    assert metrics.settled_error_vx(rows) == pytest.approx(0.02)
    # without the start-up cut, the settled part of [2.5, 5) (error 1.0) counts too: 500 of 2500 rows
    assert metrics.settled_error_vx(rows, startup_s=0.0) == pytest.approx((500 * 1.0 + 2000 * 0.02) / 2500)
    assert metrics.settled_error_vx(rows, settle_s=0.0) == pytest.approx(float(np.mean(err[t >= 5.0])))
    assert metrics.settled_error_vx(rows, fell=True) is None
    assert metrics.settled_error_vx(rows, settle_s=10.5) is None  # no command is held 10.5 s
    # a ramp (the command changes every row) never settles
    assert metrics.settled_error_vx(rows_from(t, 0.5, 0.5 + 0.01 * t)) is None
    assert metrics.summarize_arm(rows, fell=False, t_fall_s=None)["settled_error_vx"] == pytest.approx(0.02)


def test_step_alternation():
    t = np.arange(12) * 0.5
    steps = np.arange(12) // 2  # a step change every 2 rows, at t = 1, 2, ..., 5
    psi = np.where(steps % 2 == 0, 0.1, -0.1) + 0.01 * t  # +-0.1 sway on a ramp
    rows = rows_from(t, 0.5, 0.5, step_index=steps)
    import numpy.lib.recfunctions as rfn
    rows = rfn.append_fields(rows, "out_psi_y", psi, usemask=False)
    # values at the changes: -0.09, 0.12, -0.07, 0.14, -0.05: |diffs| 0.21 0.19 0.21 0.19
    assert metrics.step_alternation(rows, "out_psi_y", 0.0, 6.0) == pytest.approx(0.1)
    assert metrics.step_alternation(rows, "out_psi_y", 0.0, 3.0) is None  # two changes only
    assert metrics.step_alternation(rows, "out_psi_x", 0.0, 6.0) is None  # no such column


def test_summarize_and_checks():
    t = np.arange(2000) * 0.005
    rows = rows_from(t, np.full(2000, 0.52), 0.5)
    m = metrics.summarize_arm(rows, fell=False, t_fall_s=None, wall_s=2.5)
    assert m["sim_s"] == pytest.approx(10.0) and m["realtime_factor"] == pytest.approx(4.0)
    assert m["steady_state_error_vx"] == pytest.approx(0.02) and m["convergence_time_s"] == 0.0
    json.dumps(m)
    arms = {"adaptive": m, "pd_only": {**m, "steady_state_error_vx": 0.1}}
    c = metrics.evaluate_check({"arm": "adaptive", "metric": "steady_state_error_vx", "op": "<",
                                "other_arm": "pd_only"}, arms)
    assert c["verdict"] == "pass" and c["rhs"] == 0.1
    c = metrics.evaluate_check({"arm": "adaptive", "metric": "fell", "op": "==", "value": True}, arms)
    assert c["verdict"] == "miss"
    c = metrics.evaluate_check({"arm": "hip", "metric": "fell", "op": "==", "value": False}, arms)
    assert c["verdict"] == "n/a"


# --------------------------------------------------------------------------- report
def test_report_lists_missing_failed_and_ok(tmp_path):
    s = spec.resolve_targets(["nominal"])[0]
    t = np.arange(1000) * 0.005

    class R:  # the shape of master.ArmResult that output needs
        def __init__(self, arm, fell):
            self.arm, self.fell = arm, fell
            self.t_fall_s = 4.0 if fell else None
            self.rows = rows_from(t, np.full(1000, 0.52), 0.5)
            self.wall_s, self.fall_reason, self.model_summary = 1.0, ("pelvis low" if fell else None), {}

    (tmp_path / "nominal").mkdir()
    output.write_results(tmp_path / "nominal", s, "inprocess",
                         [output.ArmOutcome("adaptive", "complete", result=R("adaptive", False)),
                          output.ArmOutcome("pd_only", "failed", error="CosimError: boom")])
    path, problems = report.write_report(tmp_path)
    text = path.read_text()
    assert problems == []
    assert "## nominal" in text and "boom" in text and "failed" in text
    assert "| adaptive |" in text
    assert "**Paper's claim:**" in text and "`adaptive.fell == false`" not in text  # no verdict: incomplete
    assert "**Verdict: n/a**" in text and "incomplete run: pd_only failed" in text
    assert "## mass_15kg" in text and "not run" in text  # suite scenarios without results are listed
    summary = json.loads((tmp_path / "nominal" / "summary.json").read_text())
    for key in ("scenario", "model", "regulator"):
        assert key in summary
    assert summary["status"] == "failed" and summary["error"] == "arm pd_only: CosimError: boom"
    assert summary["arms"]["adaptive"]["status"] == "complete" and summary["arms"]["pd_only"]["status"] == "failed"
    assert summary["verdict"]["overall"] == "n/a"
    for key in ("fell", "t_fall_s", "steady_state_error_vx", "steady_state_error_vy", "convergence_time_s",
                "wall_s", "realtime_factor"):
        assert key in summary["arms"]["adaptive"]
    header = (tmp_path / "nominal" / "timeseries.csv").read_text().splitlines()[0]
    assert header.startswith("arm,t,")

    # arms are written in the scenario's order, whatever order they ended in (--jobs 2)
    (tmp_path / "again").mkdir()
    output.write_results(tmp_path / "again", s, "inprocess",
                         [output.ArmOutcome("pd_only", "complete", result=R("pd_only", False)),
                          output.ArmOutcome("adaptive", "complete", result=R("adaptive", True))])
    arms = [line.split(",", 1)[0] for line in (tmp_path / "again" / "timeseries.csv").read_text().splitlines()[1:]]
    assert arms == ["adaptive"] * 1000 + ["pd_only"] * 1000
    table = output.format_table([summary])
    assert "adaptive" in table and "pd_only" in table  # the failed arm is listed, not hidden


# --------------------------------------------------------------------------- CLI
def test_cli_list_subprocess():
    env = dict(os.environ)
    proc = subprocess.run([sys.executable, "-m", "scenarios", "list"], cwd=REPO_ROOT, env=env,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0].split()[:3] == ["name", "duration_s", "arms"]
    assert any(line.startswith("mass_23kg ") and " 50 " in line for line in lines)
    assert len(lines) == 1 + len(spec.suite_files())


def test_cli_run_rejects_bad_file_before_running(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(GOOD.replace("comm_step_s = 0.005", "comm_step_s = 0.0013"))
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", str(f), "--out", str(tmp_path / "o")],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "comm_step_s = 0.0013" in proc.stderr
    assert not (tmp_path / "o").exists()


# --------------------------------------------------------------------------- properties
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from fmu_src.core.avr_specs import PARAM_SPECS
from scenarios.lang.scenario import CommandPoint, Scenario
from support.paths import REPO_ROOT


@settings(max_examples=60, deadline=None)
@given(errs=st.lists(st.floats(-0.2, 0.2, allow_nan=False), min_size=300, max_size=600),
       t_from=st.floats(0.0, 1.0))
def test_convergence_time_property(errs, t_from):
    """After t_from + result every error is in the band, and the row just before is not (unless 0)."""
    e = np.asarray(errs)
    t = np.arange(len(e)) * 0.005
    rows = rows_from(t, 0.5 + e, 0.5)
    res = metrics.convergence_time(rows, t_from=t_from, min_hold_s=0.0)
    ex, _ = metrics.velocity_errors(rows)
    after = t >= t_from - 1e-9
    if res is None:
        assert np.abs(ex[after][-1]) > metrics.CONVERGENCE_TOL_MPS or not after.any()
        return
    t_c = t_from + res
    inside = t >= t_c - 1e-9
    assert np.all(np.abs(ex[inside]) <= metrics.CONVERGENCE_TOL_MPS)
    if res > 0:
        k = int(np.argmax(inside))
        assert np.abs(ex[k - 1]) > metrics.CONVERGENCE_TOL_MPS


def test_timeseries_csv_round_trips_exactly(tmp_path):
    t = np.arange(50) * 0.005
    rows = rows_from(t, 0.5 + np.sin(t) / 3.0, 0.5, step_index=np.arange(50) // 7)

    class R:
        arm = "adaptive"

    R.rows = rows
    output.write_timeseries(tmp_path / "ts.csv", [R])
    back = np.genfromtxt(tmp_path / "ts.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert set(back["arm"]) == {"adaptive"}
    for name in rows.dtype.names:
        assert np.array_equal(back[name], rows[name]), name


def test_mean_offsets_over_the_last_5_s():
    import numpy.lib.recfunctions as rfn

    t = np.arange(2000) * 0.005  # 10 s
    rows = rows_from(t, np.full(2000, 0.5), 0.5)
    knee = np.where(t < 5.0, 0.0, 0.08)
    rows = rfn.append_fields(rows, ["out_delta_swing_knee", "out_delta_swing_hip_pitch"], [knee, -knee],
                             usemask=False)
    m = metrics.summarize_arm(rows, fell=False, t_fall_s=None)
    assert m["mean_delta_swing_knee_last_s"] == pytest.approx(0.08)
    assert m["mean_delta_swing_hip_pitch_last_s"] == pytest.approx(-0.08)
    assert metrics.summarize_arm(rows_from(t, 0.5, 0.5), fell=False, t_fall_s=None)[
        "mean_delta_swing_knee_last_s"] is None  # no such column: no number invented


def test_report_tables_the_error_per_command_level(tmp_path):
    """A staircase's summary carries ``level_errors_vx``; the report tables it per arm."""
    s = spec.resolve_targets(["compare_staircase"])[0]
    t = np.arange(4000) * 0.005  # 20 s: two 10 s levels
    vx_des = np.where(t < 10.0, 0.2, 0.4)

    class R:
        def __init__(self, arm, vx):
            self.arm, self.fell, self.t_fall_s = arm, False, None
            self.rows = rows_from(t, vx, vx_des)
            self.wall_s, self.fall_reason, self.model_summary = 1.0, None, {}

    (tmp_path / s.name).mkdir()
    output.write_results(tmp_path / s.name, s, "inprocess",
                         [output.ArmOutcome("adaptive", "complete", result=R("adaptive", vx_des + 0.01)),
                          output.ArmOutcome("pd_only", "complete", result=R("pd_only", vx_des + 0.1))])
    levels = json.loads((tmp_path / s.name / "summary.json").read_text())["arms"]["pd_only"]["level_errors_vx"]
    assert [(lv["t_s"], lv["vx_des"]) for lv in levels] == [(0.0, 0.2), (10.0, 0.4)]
    assert levels[1]["error_vx"] == pytest.approx(0.1)
    text = report.write_report(tmp_path)[0].read_text()
    assert "| arm | 0.2 m/s from 0 s | 0.4 m/s from 10 s |" in text
    assert "| adaptive | 0.010 | 0.010 |" in text and "| pd_only | 0.100 | 0.100 |" in text
