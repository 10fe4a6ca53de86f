"""One options object for a run (:class:`scenarios.run.options.RunOptions`) and the ``run``
command in the run layer (:mod:`scenarios.run.command`), which the campaigns' fork server
calls without the top command line."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from scenarios.cosim import master
from scenarios.cosim.regulators import InProcessRegulator
from scenarios.lang import spec
from scenarios.run import runner
from scenarios.run.command import add_arguments, main
from scenarios.run.options import RunOptions
from support.scenario_support import scenario_file
from support.paths import REPO_ROOT

def test_every_problem_of_the_options_is_named_at_once(tmp_path):
    bad = RunOptions(targets=("nominal",), regulator="matlab", plant="fmu", jobs=0, render=True,
                     fmu=tmp_path / "missing.fmu", plant_fmu=tmp_path / "nope.fmu", mode="later",
                     exchange="random", controller="cpp")
    found = bad.problems()
    for said in ("--regulator matlab: must be one of fmu, native, native-fmi3, inprocess",
                 "--controller cpp: must be one of python, native",
                 "mode later: must be one of new, overwrite, resume",
                 "exchange random: must be one of gauss-seidel, jacobi", "--jobs 0: must be >= 1",
                 "--render with --plant fmu", f"--fmu {tmp_path / 'missing.fmu'}: no such file",
                 f"--plant-fmu {tmp_path / 'nope.fmu'}: no such file"):
        assert sum(p.startswith(said) for p in found) == 1, (said, found)
    assert len(found) == 8
    assert RunOptions(targets=("nominal",)).problems() == []


def test_the_c_controller_is_refused_up_front_where_it_cannot_run(tmp_path, monkeypatch):
    """With the CassiePlant FMU (its own Python controller), and without a C compiler to build it:
    each named, with the way to the Python controller."""
    import plant.sim

    found = RunOptions(targets=("nominal",), plant="fmu", controller="native").problems()
    assert found == ["--controller native with --plant fmu: the CassiePlant FMU runs its own (Python) controller; "
                     "use --plant inprocess, or --controller python"]
    assert RunOptions(targets=("nominal",), plant="fmu", controller="python").problems() == []
    monkeypatch.setattr(plant.sim, "NATIVE_CACHE", tmp_path / "cache")  # nothing built there
    monkeypatch.setenv("CC", "no-such-compiler")
    monkeypatch.setenv("PATH", str(tmp_path))  # neither cc nor gcc on it
    found = RunOptions(targets=("nominal",)).problems()
    assert len(found) == 1 and found[0].startswith("--controller native: no C compiler (cc or gcc; set CC)")
    assert "choose --controller python" in found[0]
    assert RunOptions(targets=("nominal",), controller="python").problems() == []


def test_the_options_are_built_from_the_command_line_once():
    import argparse

    p = argparse.ArgumentParser()
    add_arguments(p)
    args = p.parse_args(["nominal", "all", "--jobs", "3", "--no-plots", "--resume", "--duration", "2",
                         "--regulator", "inprocess", "--out", "here"])
    assert RunOptions.from_args(args) == RunOptions(targets=("nominal", "all"), duration_s=2.0, out=Path("here"),
                                                    regulator="inprocess", jobs=3, plots=False, mode="resume")


def test_the_runner_runs_an_arm_as_the_options_say():
    """``exchange`` travels from the options to the master: the runner's arm is the master's
    own Jacobi arm, bit for bit, and not its Gauss-Seidel one."""
    s = spec.override(spec.resolve_targets(["nominal"])[0], duration_s=0.3)
    out = runner.run_task(s, "adaptive", RunOptions(regulator="inprocess", exchange="jacobi"), lambda: False)
    assert out.status == "complete", out.error
    jacobi = master.run_arm(s, "adaptive", InProcessRegulator(), exchange="jacobi")
    seidel = master.run_arm(s, "adaptive", InProcessRegulator())
    assert out.result.rows.tobytes() == jacobi.rows.tobytes() != seidel.rows.tobytes()


def test_the_run_command_runs_alone_as_the_fork_server_calls_it(tmp_path, capsys):
    f = scenario_file(tmp_path, "alone", duration_s=0.2)
    assert main([str(f), "--regulator", "inprocess", "--no-plots", "--out", str(tmp_path / "runs")]) == 0
    summary = json.loads((tmp_path / "runs" / "alone" / "summary.json").read_text())
    assert summary["status"] == "complete" and summary["regulator"] == "inprocess"
    assert main([str(f), "--jobs", "0", "--out", str(tmp_path / "other")]) == 2
    assert "--jobs 0: must be >= 1" in capsys.readouterr().err


def test_the_run_layer_and_the_fork_server_do_not_import_the_top_command_line():
    """No circle: the campaign's fork server runs the run layer's command, which imports
    neither the top command line nor the campaigns."""
    code = ("import sys, scenarios.campaign.task, scenarios.campaign.forkrun, scenarios.run.command; "
            "print(sorted(m for m in sys.modules if m == 'scenarios.cli' or m.startswith('scenarios.campaign.cli')))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
