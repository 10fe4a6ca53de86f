"""Closed-loop co-simulation through the REAL built FMU (fmpy) and the in-process core.

Short runs by default (a few simulated seconds each); the whole paper suite is behind
``@pytest.mark.long`` (``pytest -m slow tests/cosim/test_cosim.py``).
"""
from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenarios.errors import CosimError, ScenarioError
from plant.constants import OFFSET_NAMES
from scenarios.cosim import master
from scenarios.lang import spec
from scenarios.cosim.regulators import FmuRegulator
from scenarios.lang.scenario import CommandPoint, Push, Scenario
from support.paths import REPO_ROOT


@pytest.fixture(scope="module")
def fmu_path(built_fmu) -> Path:
    """The FMU exactly as build.py builds it, into a fresh temporary folder (tests/conftest.py)."""
    return Path(built_fmu)


LOGGER_AFTER_MASTER = """
import gc, sys
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from scenarios.cosim.regulators import FmuRegulator
path, unzip = sys.argv[1], sys.argv[2]  # unzip: a folder of the test's own (nothing in the system temp)
for _ in range(2):  # masters come and go; their FMU messages must not leave a dangling logger
    reg = FmuRegulator(path)
    reg.start({}, 0.0, 1.0)
    reg.close()
    del reg
gc.collect()
md = read_model_description(path)
fmu = FMU2Slave(guid="{wrong}", unzipDirectory=str(extract(path, unzip)), modelIdentifier="AdaptiveVelocityRegulator",
                instanceName="after")
try:
    fmu.instantiate()  # logs through fmpy's default callbacks, then fails
except Exception:
    print("refused")
"""


def test_fmu_messages_after_a_master_has_gone_do_not_crash(fmu_path, tmp_path):
    # fmpy's native logger proxy keeps one process-wide logger pointer (see master.py)
    proc = subprocess.run([sys.executable, "-c", LOGGER_AFTER_MASTER, str(fmu_path), str(tmp_path)], capture_output=True,
                          text=True, timeout=120, cwd=REPO_ROOT)
    assert proc.returncode == 0 and "refused" in proc.stdout, (proc.returncode, proc.stderr[-2000:])


def short(name: str, duration_s: float, **changes) -> Scenario:
    s = spec.override(spec.resolve_targets([name])[0], duration_s=duration_s)
    return dataclasses.replace(s, **changes) if changes else s


def test_closed_loop_through_the_fmu(fmu_path):
    s = short("nominal", 3.0)
    (r,) = master.run_scenario(s, "fmu", fmu_path=fmu_path, arms=("adaptive",))
    rows = r.rows
    assert r.regulator == "fmu" and not r.fell, r.fall_reason
    assert len(rows) == 600
    # time from the integer counter: exactly k*h
    assert np.array_equal(rows["t"], np.arange(600) * s.comm_step_s)
    # plant time after step k is (k+1)*h: the walker advanced h/SIM_DT_S steps each time
    assert rows["tel_t"][-1] == pytest.approx(599 * s.comm_step_s, abs=1e-9)
    for name in r.rows.dtype.names:
        if name.startswith("out_"):
            assert np.all(np.isfinite(rows[name])), name
    assert np.all(rows["cmd_vx_des"] == 0.5)
    assert rows["tel_pelvis_x"][-1] > 0.3  # it walked forward
    assert np.any(rows["out_delta_swing_hip_pitch"] != 0.0)  # the regulator acts
    assert r.wall_s > 0 and r.sim_s == pytest.approx(3.0)


def test_fmu_and_inprocess_bit_identical(fmu_path):
    # a perturbed plant, a command change and a push: every branch of the loop
    s = short("compare_fixed_speed", 2.0,
              commands=(CommandPoint(0.0, 0.5, 0.0), CommandPoint(1.0, 0.3, 0.1)),
              pushes=(Push(1.5, (20.0, -5.0, 0.0), 0.1),))
    # learning from the first completed step, so that it acts within these 2 s
    adaptive = s.arm("adaptive")
    s = dataclasses.replace(s, arms=(dataclasses.replace(
        adaptive, overrides=tuple(sorted({**adaptive.overrides_dict(), "learn_from_step": 1}.items()))),))
    (a,) = master.run_scenario(s, "fmu", fmu_path=fmu_path, arms=("adaptive",))
    (b,) = master.run_scenario(s, "inprocess", arms=("adaptive",))
    assert a.rows.dtype == b.rows.dtype
    assert np.array_equal(a.rows, b.rows)
    assert np.any(a.rows["push_fx"] == 20.0) and np.any(a.rows["cmd_vy_des"] == 0.1)
    assert np.any(a.rows["out_psi_x"] != 0.0)  # adaptation really ran


def test_pd_only_arm_differs_and_has_no_psi(fmu_path):
    s = short("compare_fixed_speed", 1.0)
    results = master.run_scenario(s, "fmu", fmu_path=fmu_path)
    assert [r.arm for r in results] == ["adaptive", "pd_only"]
    pd = results[1].rows
    for name in ("out_psi_x", "out_psi_y", "out_psi_pitch", "out_psi_roll"):
        assert np.all(pd[name] == 0.0), name


def test_nan_input_raises_cosim_error_with_the_fmu_log(fmu_path):
    reg = FmuRegulator(fmu_path)
    reg.start({"learning_rate": 0.0005}, 0.0, 1.0)
    good = {"vx": 0.1, "vy": 0.0, "vx_des": 0.5, "vy_des": 0.0, "pitch": 0.0, "roll": 0.0,
            "pitch_rate": 0.0, "roll_rate": 0.0, "step_index": 0}
    try:
        out = reg.step(0.0, 0.005, good)
        assert set(OFFSET_NAMES) <= set(out)
        with pytest.raises(CosimError) as info:
            reg.step(0.005, 0.005, {**good, "vx": math.nan})
    finally:
        reg.close()  # terminate/freeInstance after the failure must not raise
    msg = str(info.value)
    assert "FMU log" in msg
    assert "fmi2" in msg and ("Discard" in msg or "Error" in msg or "error" in msg)
    assert reg.messages, "the logger callback collected nothing"
    assert any("vx" in m or "nan" in m.lower() for m in reg.messages), reg.messages


@pytest.mark.parametrize("kind", ["fmu", "native-fmi2", "native-fmi3", "inprocess"])
def test_step_values_is_step_in_the_masters_order(fmu_path, native_fmus, kind):
    """The master's per-step call (numbers in MASTER_INPUTS' order, outputs in output_names'
    order) gives what ``step`` gives by name, step after step (the FMU keeps its state)."""
    from scenarios.cosim.regulators import MASTER_INPUTS, InProcessRegulator

    def make():
        if kind == "inprocess":
            return InProcessRegulator()
        return FmuRegulator(fmu_path if kind == "fmu" else native_fmus[int(kind[-1])])

    by_name, in_order = make(), make()
    inputs = [{"vx": 0.1 * k, "vy": -0.01, "vx_des": 0.5, "vy_des": 0.1, "pitch": 0.02, "roll": -0.01,
               "pitch_rate": 0.1, "roll_rate": 0.0, "step_index": k // 2} for k in range(6)]
    try:
        for reg in (by_name, in_order):
            reg.start({"learning_rate": 0.0005}, 0.0, 1.0)
        for k, u in enumerate(inputs):
            want = by_name.step(0.005 * k, 0.005, u)
            got = in_order.step_values(0.005 * k, 0.005, [u[n] for n in MASTER_INPUTS])
            assert got == [want[n] for n in by_name.output_names()]
        assert any(v != 0.0 for v in got)
    finally:
        by_name.close()
        in_order.close()


def test_out_of_range_parameter_raises_cosim_error(fmu_path):
    reg = FmuRegulator(fmu_path)
    try:
        with pytest.raises(CosimError) as info:
            reg.start({"learning_rate": -1.0}, 0.0, 1.0)
    finally:
        reg.close()
    assert "learning_rate" in str(info.value)
    with pytest.raises(CosimError, match="no such variable"):
        FmuRegulator(fmu_path).start({"not_a_parameter": 1.0}, 0.0, 1.0)


def test_comm_step_must_be_whole_plant_steps():
    assert master.plant_steps_per_comm(0.005, 0.0005) == 10
    with pytest.raises(ScenarioError, match="whole multiple"):
        master.plant_steps_per_comm(0.0052, 0.0005)
    with pytest.raises(ScenarioError):
        master.plant_steps_per_comm(0.0002, 0.0005)


def test_cli_run_writes_csv_summary_plots(fmu_path, tmp_path):
    scenario = tmp_path / "tiny_push.toml"
    scenario.write_text("""
name = "tiny_push"
description = "2 s with a push, both arms"
duration_s = 2.0
seed = 2
perturbation_t_s = 1.0
compare = ["adaptive", "pd_only"]
[[command]]
t_s = 0.0
vx_des = 0.4
[[push]]
t_s = 1.0
force_n = [25.0, 0.0, 0.0]
duration_s = 0.1
[claim]
text = "it does not fall"
[[claim.check]]
arm = "adaptive"
metric = "fell"
op = "=="
value = false
""")
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", str(scenario), "--out", str(out),
                           "--fmu", str(fmu_path)], cwd=REPO_ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    d = out / "tiny_push"
    summary = json.loads((d / "summary.json").read_text())
    assert summary["scenario"] == "tiny_push" and summary["regulator"] == "fmu"
    assert summary["status"] == "complete"
    assert {n: a["status"] for n, a in summary["arms"].items()} == {"adaptive": "complete", "pd_only": "complete"}
    assert summary["verdict"]["overall"] == "pass"
    for f in ("timeseries.csv", "velocity.png", "psi.png", "torso.png"):
        assert (d / f).stat().st_size > 0, f
    lines = (d / "timeseries.csv").read_text().splitlines()
    assert lines[0].startswith("arm,t,") and len(lines) == 1 + 2 * 400
    assert {ln.split(",", 1)[0] for ln in lines[1:]} == {"adaptive", "pd_only"}
    table = proc.stdout.splitlines()
    assert any(ln.startswith("tiny_push") and " adaptive " in ln for ln in table)
    assert any(ln.startswith("tiny_push") and " pd_only " in ln for ln in table)
    proc = subprocess.run([sys.executable, "-m", "scenarios", "report", str(out)], cwd=REPO_ROOT,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    text = (out / "report.md").read_text()
    assert "## tiny_push" in text and "![tiny_push velocity.png](tiny_push/velocity.png)" in text


@pytest.mark.long
def test_full_paper_suite(tmp_path):
    """Every suite scenario at full length through the FMU (minutes; ``-m long``)."""
    out = tmp_path / "suite"
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", "all", "--out", str(out), "--jobs", "2"],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=7200)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]
    for s in spec.load_suite():
        summary = json.loads((out / s.name / "summary.json").read_text())
        assert summary["status"] == "complete", (s.name, summary.get("error"))
        assert {n: a["status"] for n, a in summary["arms"].items()} == {a.name: "complete" for a in s.arms}


#: A user's session: the pythonfmu regulator FMU run in process, then the default FMU rebuilt
#: because it is older than its sources, then asked for again.
REBUILD_AFTER_LOAD = """
import json, os, sys, zipfile
from pathlib import Path
import fmpy
from scenarios.cosim import fmus
args = json.load(sys.stdin)
fmpy.simulate_fmu(fmpy.extract(args["fmu"], unzipdir=args["unzipped"]), stop_time=0.01)
fmus.DEFAULT_FMU = stale = Path(args["stale"])
path = fmus.ensure_fmu(None)
rebuilt = path == stale and zipfile.is_zipfile(path)
mtime = path.stat().st_mtime
kept = fmus.ensure_fmu(None) == stale and stale.stat().st_mtime == mtime
print(json.dumps({"rebuilt": rebuilt, "kept": kept}))
"""


def test_cli_rebuilds_a_default_fmu_older_than_its_sources_also_after_running_a_pythonfmu_fmu(built_fmu, tmp_path):
    """The rebuild runs in a process of its own: in this one, which has run the pythonfmu FMU (and
    so holds that FMU's copy of pythonfmu, without binaries), pythonfmu could not build."""
    import os

    from support.pythonfmu_support import run_host

    stale = tmp_path / "AdaptiveVelocityRegulator.fmu"
    stale.write_bytes(b"an FMU built from older sources")
    os.utime(stale, (0, 0))  # 1970: older than every source file
    args = {"fmu": str(built_fmu), "unzipped": str(tmp_path / "unzipped"), "stale": str(stale)}
    result, err = run_host(REBUILD_AFTER_LOAD, args, tmp_path)
    assert result == {"rebuilt": True, "kept": True}, err[-2000:]


def test_a_failed_build_names_the_function_and_says_why(tmp_path):
    from fmu_src.core.avr_errors import AvrError
    from scenarios.cosim.fmus import build_in_own_process

    with pytest.raises(AvrError, match=r"build.py's build_native_fmu\(4,\) failed \(exit 1\)") as err:
        build_in_own_process(("build_native_fmu", 4), tmp_path)
    assert "4" in str(err.value).splitlines()[-1]  # the build's own last words
