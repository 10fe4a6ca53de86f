"""The yaw-rate command above the plant: scenario files, the master, the plant FMU, the
metric, summary.json and the report.

``[[command]]`` takes ``yaw_rate_des`` (rad/s, positive turns left, default 0); the master
hands it to the walker (the regulator has no such input: its speeds are in the heading
frame), records it as ``cmd_yaw_rate_des`` and judges the turn with
``steady_state_error_yaw_rate``.
"""
from __future__ import annotations

import copy
import json
import math
import tomllib

import numpy as np
import pytest

from support.plant_fmu_support import built_plant_fmu
from scenarios import report
from scenarios.cosim import master
from scenarios.lang import spec
from scenarios.results import metrics, output, store
from scenarios.campaign.factors import FACTORS
from scenarios.errors import ScenarioError
from scenarios.cosim.plant_fmu import plant_factory
from scenarios.lang.scenario import CommandPoint, Scenario

H = 0.005
TURN = """
name = "turn"
duration_s = 8.0
seed = 1
compare = ["adaptive"]
[[command]]
t_s = 0.0
vx_des = 0.5
yaw_rate_des = 0.3
"""
YAW_RATE = 0.3  # rad/s, the command of TURN
#: |mean yaw rate - command| allowed over the last 3 s of TURN, rad/s.  The heading sways
#: by about +-0.05 rad with every step (the stance hip yaw), so a 3 s window whose two ends
#: fall at different phases of the sway reads up to ~2 * 0.05 / 3 = 0.03 rad/s off from the
#: sway alone; 0.05 rad/s is also issue 11's yaw-rate criterion for the 60 s circle.
YAW_RATE_TOL = 0.05
LAST_S = 3.0


def parse(text: str) -> Scenario:
    return spec.parse_scenario(tomllib.loads(text), source="test.toml")


def mean_yaw_rate(rows: np.ndarray, last_s: float) -> float:
    """The change of the unwrapped heading over the last ``last_s`` of recorded rows, per second."""
    t, yaw = rows["t"], np.unwrap(rows["tel_yaw"])
    first = int(np.searchsorted(t, t[-1] - last_s - 1e-9))
    return float((yaw[-1] - yaw[first]) / (t[-1] - t[first]))


# ---- the scenario file ----------------------------------------------------------------------
def test_yaw_rate_des_is_read_and_defaults_to_zero():
    s = parse(TURN + "[[command]]\nt_s = 4.0\nvx_des = 0.4\n")
    assert s.commands == (CommandPoint(0.0, 0.5, 0.0, YAW_RATE), CommandPoint(4.0, 0.4, 0.0, 0.0))
    assert s.command_at_step(0) == (0.5, 0.0, YAW_RATE) and s.command_at_step(799) == (0.5, 0.0, YAW_RATE)
    assert s.command_at_step(800) == (0.4, 0.0, 0.0)


def test_bad_yaw_rate_des_is_named_with_its_range_every_problem_at_once():
    bad = TURN.replace("yaw_rate_des = 0.3", 'yaw_rate_des = "fast"') + (
        "[[command]]\nt_s = 1.0\nvx_des = 0.5\nyaw_rate_des = 1.5\n"
        "[[command]]\nt_s = 2.0\nvx_des = 9.0\nyaw_rate_des = -3\n"
        "[[command]]\nt_s = 3.0\nvx_des = 0.5\nyaw_rate_des = nan\n")
    with pytest.raises(ScenarioError) as info:
        parse(bad)
    probs = info.value.problems
    assert "command[0].yaw_rate_des = 'fast': must be a number" in probs
    assert "command[1].yaw_rate_des = 1.5: must be <= 1" in probs
    assert "command[2].yaw_rate_des = -3: must be >= -1" in probs
    assert "command[2].vx_des = 9: must be <= 2" in probs  # the other keys' problems come too
    assert any(p.startswith("command[3].yaw_rate_des = nan: must be finite") for p in probs)
    assert len(probs) == 5, probs


def test_the_campaign_factor_sets_the_one_command():
    doc = tomllib.loads(TURN)
    varied = copy.deepcopy(doc)
    assert FACTORS["yaw_rate_des"].apply(varied, -0.4) is None
    assert spec.parse_scenario(varied).command_at_step(0) == (0.5, 0.0, -0.4)
    two = tomllib.loads(TURN + "[[command]]\nt_s = 4.0\nvx_des = 0.4\n")
    assert "exactly one [[command]]" in FACTORS["yaw_rate_des"].apply(two, 0.2)


# ---- the metric on hand-made rows -----------------------------------------------------------
def _turning_rows(rate: float, commanded: float, n: int = 2000, sway: float = 0.0) -> np.ndarray:
    """n steps of 5 ms turning at ``rate`` from a heading of 1.5 rad (wraps through pi),
    plus a yaw sway of amplitude ``sway`` (rad) at a 0.53 s stride, like the walker's."""
    rows = np.zeros(n, dtype=[("t", "f8"), ("cmd_yaw_rate_des", "f8"), ("tel_yaw", "f8")])
    rows["t"] = np.arange(n) * H
    rows["cmd_yaw_rate_des"] = commanded
    heading = 1.5 + rate * rows["t"] + sway * np.sin(2 * math.pi * rows["t"] / 0.53)
    rows["tel_yaw"] = np.remainder(heading + math.pi, 2 * math.pi) - math.pi
    return rows


def test_yaw_rate_error_is_the_heading_rate_against_the_command_over_the_steady_window():
    exact = 1e-9  # the heading is exactly linear in t: only rounding is left
    assert metrics.steady_state_error_yaw_rate(_turning_rows(0.3, 0.3)) == pytest.approx(0.0, abs=exact)
    assert metrics.steady_state_error_yaw_rate(_turning_rows(-0.3, -0.3)) == pytest.approx(0.0, abs=exact)
    assert metrics.steady_state_error_yaw_rate(_turning_rows(0.3, 0.2)) == pytest.approx(0.1, abs=exact)
    assert metrics.steady_state_error_yaw_rate(_turning_rows(0.25, 0.3)) == pytest.approx(0.05, abs=exact)
    assert metrics.steady_state_error_yaw_rate(_turning_rows(0.3, 0.3), fell=True) is None
    # The walker's per-step yaw sway (0.1 rad here, ~0.2 rad peak to peak as measured)
    # must not read as turning: the two ends of a 5 s window alone would give up to
    # 2 * 0.1 / 5 = 0.04 rad/s; the least-squares slope stays within 0.002 rad/s.
    swaying = _turning_rows(0.3, 0.3, sway=0.1)
    assert metrics.steady_state_error_yaw_rate(swaying) <= 0.002
    assert metrics.steady_state_error_yaw_rate(_turning_rows(0.3, 0.3, n=1)) is None  # no window
    no_yaw = np.zeros(10, dtype=[("t", "f8"), ("cmd_yaw_rate_des", "f8")])
    assert metrics.steady_state_error_yaw_rate(no_yaw) is None


# ---- closed loop through the master with the regulator FMU ----------------------------------
@pytest.fixture(scope="module")
def turn_run(built_fmu):
    (result,) = master.run_scenario(parse(TURN), "fmu", fmu_path=built_fmu)
    return result


def test_the_master_turns_the_walker_and_records_the_command(turn_run):
    rows = turn_run.rows
    assert not turn_run.fell
    names = rows.dtype.names
    assert names.index("cmd_yaw_rate_des") == names.index("cmd_vy_des") + 1
    assert np.all(rows["cmd_yaw_rate_des"] == YAW_RATE) and np.all(rows["tel_yaw_rate_des"] == YAW_RATE)
    assert abs(mean_yaw_rate(rows, LAST_S) - YAW_RATE) <= YAW_RATE_TOL, mean_yaw_rate(rows, LAST_S)
    error = metrics.summarize_arm(rows, fell=False, t_fall_s=None)["steady_state_error_yaw_rate"]
    assert error is not None and error <= YAW_RATE_TOL, error


def test_results_carry_the_yaw_rate_csv_summary_and_report(turn_run, tmp_path):
    s = parse(TURN)
    dest = tmp_path / s.name
    dest.mkdir()
    output.write_results(dest, s, "fmu", [output.ArmOutcome("adaptive", "complete", result=turn_run)])
    header = (dest / "timeseries.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["arm", "t", "cmd_vx_des", "cmd_vy_des", "cmd_yaw_rate_des"]
    summary, problems = store.read_summary(dest / "summary.json")
    assert problems == []
    assert summary["commands"] == [[0.0, 0.5, 0.0, YAW_RATE]]
    assert summary["arms"]["adaptive"]["steady_state_error_yaw_rate"] <= YAW_RATE_TOL
    assert "velocity.png" in summary["plots"]
    text = report.write_report(tmp_path)[0].read_text()
    assert "command (0.5, 0) m/s, turning 0.3 rad/s from 0 s" in text and "sse_yaw" in text


def test_a_summary_from_before_the_yaw_rate_reads_as_not_turning():
    s = spec.resolve_targets(["nominal"])[0]
    new = json.loads(json.dumps(output.build_summary(s, "fmu", [])))  # every arm interrupted
    assert output.summary_problems(new) == [] and new["commands"] == [[0.0, 0.5, 0.0, 0.0]]
    old = {**new, "commands": [[0.0, 0.5, 0.0]]}
    assert output.summary_problems(old) == []
    assert store.setup_of(old) == store.setup_of(new)  # --resume keeps it: the same set-up
    bad = {**new, "commands": [[0.0, 0.5]], "arm_names": new["arm_names"]}
    assert any(p.startswith("commands[0] = [0.0, 0.5]: must be a list [t_s, vx_des, vy_des, yaw_rate_des]")
               for p in output.summary_problems(bad))


# ---- the plant FMU turns as the in-process walker does --------------------------------------
def test_the_plant_fmu_turns_bit_for_bit_as_the_walker(tmp_path_factory, build_module):
    plant_fmu = built_plant_fmu(tmp_path_factory, build_module)
    s = spec.override(parse(TURN), duration_s=4.0)
    (with_fmu,) = master.run_scenario(s, "inprocess", plant=plant_factory(plant_fmu))
    (in_process,) = master.run_scenario(s, "inprocess")
    assert with_fmu.rows.dtype == in_process.rows.dtype
    for name in in_process.rows.dtype.names:  # same master, same order: the FMU plant is the plant
        assert np.array_equal(with_fmu.rows[name], in_process.rows[name]), name
    assert np.unwrap(with_fmu.rows["tel_yaw"])[-1] > YAW_RATE  # it turned: ~0.3 rad/s for ~2.5 s
