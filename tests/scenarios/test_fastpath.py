"""The main job's default path (the native regulator FMU and the C walking controller) gives the
reference path's results (the pythonfmu regulator FMU and the Python controller) byte for byte,
through the real command line and master, and each run's summary.json names the path it took."""
from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from scenarios.run.command import add_arguments
from scenarios.run.options import DEFAULT_CONTROLLER, DEFAULT_REGULATOR, RunOptions
from support.paths import REPO_ROOT

#: Short runs of three suite scenarios: a push (at 2.5 s), uneven terrain, a heavy torso turning.
QUICK = ("push_fwd_30n", "terrain_uneven", "turning_mass_20kg")
QUICK_S = "4"
#: Keys of an arm's summary that measure the run's speed, not its result.
TIMING_KEYS = ("timings", "wall_s", "realtime_factor")


def _run(out: Path, *args) -> None:
    proc = subprocess.run([sys.executable, "-m", "scenarios", "run", *args, "--no-plots", "--out", str(out)],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=3600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _results(summary: dict) -> dict:
    return {arm: {k: v for k, v in entry.items() if k not in TIMING_KEYS} for arm, entry in summary["arms"].items()}


def _compare(fast: Path, ref: Path, names) -> None:
    for name in names:
        a, b = (fast / name / "timeseries.csv").read_bytes(), (ref / name / "timeseries.csv").read_bytes()
        assert a == b, f"{name}: timeseries.csv differs between the default and the reference path"
        sa = json.loads((fast / name / "summary.json").read_text())
        sb = json.loads((ref / name / "summary.json").read_text())
        assert _results(sa) == _results(sb), name
        assert sa["verdict"] == sb["verdict"], name


def test_the_default_path_is_the_native_regulator_and_the_c_controller():
    p = argparse.ArgumentParser()
    add_arguments(p)
    options = RunOptions.from_args(p.parse_args(["all"]))
    assert (options.regulator, options.controller) == (DEFAULT_REGULATOR, DEFAULT_CONTROLLER) == ("native", "native")
    # The CassiePlant FMU carries its own (Python) controller.
    assert RunOptions.from_args(p.parse_args(["all", "--plant", "fmu"])).controller == "python"


def test_default_path_gives_the_reference_path_s_bytes(tmp_path, built_fmu, native_fmus):
    fast, ref = tmp_path / "fast", tmp_path / "ref"
    _run(fast, *QUICK, "--duration", QUICK_S, "--fmu", str(native_fmus[2]))  # --regulator and --controller: defaults
    _run(ref, *QUICK, "--duration", QUICK_S, "--regulator", "fmu", "--fmu", str(built_fmu), "--controller", "python")
    _compare(fast, ref, QUICK)
    for out, regulator, fmu, controller in ((fast, "native", native_fmus[2], "native"),
                                            (ref, "fmu", built_fmu, "python")):
        summary = json.loads((out / QUICK[0] / "summary.json").read_text())
        assert summary["regulator"] == regulator
        assert summary["path"] == {"regulator": regulator, "regulator_fmu": str(Path(fmu).resolve()),
                                   "regulator_fmu_sha256": _sha256(fmu), "plant": "inprocess", "plant_fmu": None,
                                   "plant_fmu_sha256": None, "controller": controller}


@pytest.mark.long
def test_whole_suite_default_path_gives_the_reference_path_s_bytes(tmp_path, built_fmu, native_fmus):
    """Every suite scenario at its full duration, both ways with --jobs 2 (the main job)."""
    from scenarios.lang import spec

    fast, ref = tmp_path / "fast", tmp_path / "ref"
    _run(fast, "all", "--jobs", "2", "--fmu", str(native_fmus[2]))
    _run(ref, "all", "--jobs", "2", "--regulator", "fmu", "--fmu", str(built_fmu), "--controller", "python")
    names = [s.name for s in spec.resolve_targets(["all"])]
    assert len(names) == 21
    _compare(fast, ref, names)
