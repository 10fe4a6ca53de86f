"""The RL-HZD baseline: the policy's contract, its file format, and reproducible training."""
import json

import numpy as np
import pytest

from plant.constants import OFFSET_NAMES
from scenarios.cosim import master
from scenarios.results import output
from scenarios.lang import spec
from scenarios.results.metrics import level_errors_vx
from scenarios.rl_hzd import policy as P
from scenarios.rl_hzd import train as T
from fmu_src.core.avr_params import RegulatorInputs


def test_committed_policy_loads_with_its_training_settings():
    doc = json.loads(P.DEFAULT_POLICY.read_text())
    pol = P.load_policy()
    assert pol.weights.shape == (len(OFFSET_NAMES), len(P.FEATURE_NAMES))
    assert np.any(pol.weights != 0.0), "the committed policy must be trained, not zeros"
    for key in ("iterations", "directions", "top", "step_size", "noise", "seed", "wall_s"):
        assert key in doc["training"]
    evals = [r["eval_return"] for r in doc["curve"] if r["eval_return"] is not None]
    assert evals[-1] > evals[0], "training must improve on the untrained (zero) policy"


def test_action_is_held_for_a_walking_step_and_clipped():
    w = np.zeros((6, 9))
    w[0, 0] = 10.0  # error_vx feature (scale 0.5 m/s) -> swing hip pitch, saturates
    pol = P.HzdPolicy(w)
    out1 = pol.step(RegulatorInputs(vx=0.5, vx_des=0.0, step_index=3), 0.01)
    assert out1["delta_swing_hip_pitch"] == P.DELTA_LIMIT_RAD
    out2 = pol.step(RegulatorInputs(vx=0.0, vx_des=0.5, step_index=3), 0.01)
    assert out2 == out1, "held within a step"
    out3 = pol.step(RegulatorInputs(vx=0.0, vx_des=0.5, step_index=4), 0.01)
    assert out3["delta_swing_hip_pitch"] == -P.DELTA_LIMIT_RAD
    assert list(out3) == list(OFFSET_NAMES)


def test_bad_weights_and_foreign_files_are_refused(tmp_path):
    with pytest.raises(ValueError, match="6 x 9"):
        P.HzdPolicy(np.zeros((6, 8)))
    with pytest.raises(ValueError, match="finite"):
        P.HzdPolicy(np.full((6, 9), np.nan))
    path = tmp_path / "p.json"
    P.save_policy(path, np.zeros((6, 9)), {}, [])
    doc = json.loads(path.read_text())
    doc["outputs"] = doc["outputs"][::-1]
    doc["format"] = "other"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as err:
        P.load_policy(path)
    assert "format" in str(err.value) and "outputs" in str(err.value)


def test_training_is_reproducible_from_its_seed():
    """Two short trainings with the same seed give bit-identical weights (real 3 s episodes:
    1.5 s of reward after the stand; the draws and their order do not depend on the length)."""
    s = T.ArsSettings(iterations=1, directions=2, top=1, seed=7, episode_s=3.0)
    w1, curve1, _ = T.train(s, workers=1)
    w2, curve2, _ = T.train(s, workers=2)
    assert np.array_equal(w1, w2) and curve1 == curve2
    assert np.any(w1 != 0.0)


# --------------------------------------------------------------------------- in the master

def test_rl_hzd_is_a_builtin_arm_without_parameters():
    s = spec.load_scenario(spec.SUITE_DIR / "compare_staircase_rl.toml", check_plant=False)
    rl = s.arm("rl_hzd")
    assert rl.controller == "rl_hzd" and rl.overrides == ()
    assert [a.controller for a in s.arms] == ["regulator", "regulator", "rl_hzd"]


def test_rl_hzd_arm_walks_in_the_master_and_writes_beside_the_regulator_arms(tmp_path):
    """A real 6 s closed loop: the policy's six offsets drive the plant; the CSV holds both
    arms (the policy's empty psi cells) and the level errors are per command level."""
    s = spec.override(spec.load_scenario(spec.SUITE_DIR / "compare_staircase_rl.toml"), duration_s=6.0)
    results = master.run_scenario(s, "inprocess", arms=("pd_only", "rl_hzd"))
    rl = results[1]
    assert rl.regulator == "rl_hzd" and "out_psi_x" not in rl.rows.dtype.names
    assert np.any(rl.rows["out_delta_swing_hip_pitch"] != 0.0)
    path = tmp_path / "timeseries.csv"
    output.write_timeseries(path, results)
    header = path.read_text().splitlines()[0].split(",")
    assert "out_psi_x" in header
    last = path.read_text().splitlines()[-1].split(",")
    assert last[0] == "rl_hzd" and last[header.index("out_psi_x")] == ""


def test_level_errors_are_per_command_level_and_none_when_cut_short():
    t = np.arange(0, 10, 0.5)
    rows = np.zeros(len(t), dtype=[("t", float), ("cmd_vx_des", float), ("cmd_vy_des", float),
                                   ("tel_vx_step_avg", float), ("tel_vy_step_avg", float),
                                   ("in_step_index", int)])
    rows["t"] = t
    rows["cmd_vx_des"] = np.where(t < 6, 0.5, 1.0)
    rows["tel_vx_step_avg"] = np.where(t < 6, 0.4, 1.0)
    rows["in_step_index"] = np.arange(len(t))
    levels = level_errors_vx(rows, window_s=2.0)
    assert [lv["vx_des"] for lv in levels] == [0.5, 1.0]
    assert levels[0]["error_vx"] == pytest.approx(0.1)
    assert levels[1]["error_vx"] == pytest.approx(0.0)
    assert level_errors_vx(rows, window_s=2.0, fell=True)[1]["error_vx"] is None


def test_training_flags_out_of_range_are_named_at_once(capsys):
    with pytest.raises(SystemExit) as stop:
        T.main(["--iterations", "0", "--episode-s", "1.0", "--top", "9", "--directions", "8"])
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "--iterations 0: must be >= 1" in err and "--top 9: must be <= --directions 8" in err
    assert "--episode-s 1.0: must be > 1.5 (the reward starts there) and <= 600.0" in err
