"""Our master runs the native FMUs: FMI 2.0 (``--regulator native``) and FMI 3.0
(``--regulator native-fmi3``, fmpy's FMU3Slave): the same closed loop as the numpy core
in-process, bit for bit (the two cores compute the same doubles), and the FMI 3.0 FMU
bit for bit like the FMI 2.0 one (one C core behind both APIs); its errors carry the
FMU's log."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from scenarios.cosim import master
from scenarios.lang import spec
from scenarios.errors import CosimError
from scenarios.cosim.fmi_api import fmi3_step_problem
from scenarios.cosim.regulators import make_regulator
from support.paths import REPO_ROOT

H = 0.005
INPUTS = dict(vx=0.1, vy=0.0, vx_des=0.5, vy_des=0.0, pitch=0.01, roll=0.0, pitch_rate=0.0, roll_rate=0.0,
              step_index=0)


def test_master_native_regulator_matches_the_core_in_process(native_fmus, tmp_path):
    s = spec.override(spec.resolve_targets(["mass_20kg"])[0], duration_s=3.0)
    native = master.run_arm(s, "adaptive", make_regulator("native", native_fmus[2], unpack_dir=tmp_path))
    core = master.run_arm(s, "adaptive", make_regulator("inprocess"))
    assert len(native.rows) == len(core.rows) == 600 and not native.fell
    for name in native.rows.dtype.names:
        np.testing.assert_array_equal(native.rows[name], core.rows[name], err_msg=name)


# nominal/adaptive sets Float64 and Int32 parameters (seed); push_fwd_30n/pd_only a Boolean
# too (adaptation_enabled = false), and 3 s hold its push (2.5-2.6 s)
@pytest.mark.parametrize("name, arm", [("nominal", "adaptive"), ("push_fwd_30n", "pd_only")])
def test_master_native_fmi3_matches_fmi2_and_the_core(native_fmus, tmp_path, name, arm):
    s = spec.override(spec.resolve_targets([name])[0], duration_s=3.0)
    fmi3 = master.run_arm(s, arm, make_regulator("native-fmi3", native_fmus[3], unpack_dir=tmp_path))
    fmi2 = master.run_arm(s, arm, make_regulator("native", native_fmus[2], unpack_dir=tmp_path))
    core = master.run_arm(s, arm, make_regulator("inprocess"))
    assert len(fmi3.rows) == len(core.rows) == 600 and not fmi3.fell
    assert list(tmp_path.iterdir()) == []  # every extracted FMU removed when its arm ended
    if name == "push_fwd_30n":
        assert fmi3.rows["push_fx"].max() == 30.0
    for col in fmi3.rows.dtype.names:
        # the same C core behind FMI 3.0 and FMI 2.0: the FMI 3.0 path must change nothing
        np.testing.assert_array_equal(fmi3.rows[col], fmi2.rows[col], err_msg=col)
        np.testing.assert_array_equal(fmi3.rows[col], core.rows[col], err_msg=col)


def test_native_fmi3_nan_input_is_a_cosim_error_with_the_fmu_log(native_fmus, tmp_path):
    with make_regulator("native-fmi3", native_fmus[3], unpack_dir=tmp_path) as reg:
        reg.start({}, 0.0, 1.0)
        reg.step(0.0, H, INPUTS)
        with pytest.raises(CosimError) as err:
            reg.step(H, H, {**INPUTS, "vx": math.nan})
    text = str(err.value)
    assert "fmi3SetFloat64 (inputs) at t = 0.005 s failed: status Error" in text
    assert "vx = nan: must be a finite number in [-10, 10]" in text  # the FMU's own message, routed to this instance
    assert list(tmp_path.iterdir()) == []  # terminated, freed, its folder removed


@pytest.mark.parametrize("params, call, said", [
    ({"learning_rate": -1.0}, "fmi3SetFloat64 (parameters)", "learning_rate = -1: out of range [0, 0.001]"),
    ({"n_neurons": 0}, "fmi3SetInt32 (parameters)", "n_neurons = 0"),
])
def test_native_fmi3_bad_parameter_is_a_cosim_error_with_the_fmu_log(native_fmus, tmp_path, params, call, said):
    reg = make_regulator("native-fmi3", native_fmus[3], unpack_dir=tmp_path)
    try:
        with pytest.raises(CosimError) as err:
            reg.start(params, 0.0, 1.0)
    finally:
        reg.close()
    assert f"{call} failed" in str(err.value) and said in str(err.value)
    assert list(tmp_path.iterdir()) == []


def test_regulator_kind_and_fmi_version_must_match(native_fmus, tmp_path):
    with pytest.raises(CosimError, match="needs an FMI 3.0 co-simulation FMU"):
        make_regulator("native-fmi3", native_fmus[2])
    with pytest.raises(CosimError, match="needs an FMI 2.0 co-simulation FMU"):
        make_regulator("native", native_fmus[3])


def test_fmi3_step_outcomes_are_checked():
    assert fmi3_step_problem(1.0, H, False, False, False, 1.0 + H) is None
    assert fmi3_step_problem(1.0, H, True, False, False, 1.0 + H) is None  # an event handled inside the step
    assert "terminateSimulation" in fmi3_step_problem(1.0, H, False, True, False, 1.0 + H)
    assert "earlyReturnAllowed = false" in fmi3_step_problem(1.0, H, False, False, True, 1.0 + H / 2)
    assert "not the step's end" in fmi3_step_problem(1.0, H, False, False, False, 1.0)


@pytest.mark.parametrize("regulator, version", [("native", 2), ("native-fmi3", 3)])
def test_cli_runs_the_native_fmus(native_fmus, tmp_path, regulator, version):
    out = tmp_path / "runs"
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", "nominal", "--regulator", regulator,
                           "--fmu", str(native_fmus[version]), "--duration", "1", "--out", str(out)],
                          capture_output=True, text=True, cwd=REPO_ROOT)  # MENAGERIE_ROOT may be relative
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "nominal" / "summary.json").read_text())
    assert summary["regulator"] == regulator and summary["status"] == "complete"


def test_cli_refuses_an_fmu_of_the_other_fmi_version(native_fmus, tmp_path):
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", "nominal", "--regulator", "native-fmi3",
                           "--fmu", str(native_fmus[2]), "--duration", "1", "--out", str(tmp_path / "runs")],
                          capture_output=True, text=True, cwd=REPO_ROOT)
    assert proc.returncode == 2
    assert "an FMI 2.0 FMU; --regulator native-fmi3 runs FMI 3.0 FMUs (use --regulator fmu or native)" in proc.stderr
    assert not (tmp_path / "runs" / "nominal").exists()
