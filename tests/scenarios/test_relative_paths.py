"""Every path a user gives works relative to the current folder, as the README's first line
uses them (``--out runs``): the CLI is run as a real subprocess in a temporary working
folder, and every path on its command line and in its files is relative to that folder
(or, for files that scenario and campaign files name, relative to the file).

The FMUs are build.py's, copied under the working folder so ``--fmu`` can be relative.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from support.plant_fmu_support import built_plant_fmu
from support.scenario_support import scenario_file
from support.paths import REPO_ROOT

OSU_XML = REPO_ROOT.parent / "shared" / "cassie" / "osu" / "cassie.xml"
ARMS = ("adaptive", "pd_only")


@pytest.fixture(scope="module")
def workdir(tmp_path_factory, built_fmu, build_module) -> Path:
    """A working folder holding fmus/ (the regulator and plant FMUs) and scen/ (scenario files)."""
    wd = tmp_path_factory.mktemp("cwd")
    (wd / "fmus").mkdir()
    shutil.copy(built_fmu, wd / "fmus" / "AVR.fmu")
    shutil.copy(built_plant_fmu(tmp_path_factory, build_module), wd / "fmus" / "Plant.fmu")
    (wd / "scen").mkdir()
    scenario_file(wd / "scen", "rel_a", arms=ARMS)
    # the model path is relative to the scenario file's folder
    scenario_file(wd / "scen", "rel_osu", arms=ARMS, model=os.path.relpath(OSU_XML, wd / "scen"))
    return wd


def run_cli(cwd: Path, *argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, MENAGERIE_ROOT=os.path.relpath(REPO_ROOT.parent / "shared" / "cassie" / "menagerie", cwd))
    return subprocess.run([sys.executable, "-m", "scenarios", *argv], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def assert_complete(folder: Path, arms=("adaptive", "pd_only")) -> dict:
    summary = json.loads((folder / "summary.json").read_text())
    assert {a: summary["arms"][a]["status"] for a in arms} == {a: "complete" for a in arms}, summary
    return summary


def test_run_out_fmu_scenario_files_resume_and_report_relative(workdir):
    """`run FILE --out DIR --fmu FMU --jobs 2` with every path relative (the README's first line
    spawns worker processes too), then `--resume` and `report DIR` on the same relative folder."""
    r = run_cli(workdir, "run", "scen/rel_a.toml", "scen/rel_osu.toml", "--out", "runs", "--fmu", "fmus/AVR.fmu",
                "--jobs", "2", "--no-plots")
    assert r.returncode == 0, r.stderr
    assert_complete(workdir / "runs" / "rel_a")
    assert_complete(workdir / "runs" / "rel_osu")

    r = run_cli(workdir, "run", "scen/rel_a.toml", "scen/rel_osu.toml", "--out", "runs", "--fmu", "fmus/AVR.fmu",
                "--resume", "--no-plots")
    assert r.returncode == 0, r.stderr

    r = run_cli(workdir, "report", "runs")
    assert r.returncode == 0, r.stderr
    assert (workdir / "runs" / "report.md").is_file()


@pytest.mark.parametrize("regulator", ["native", "native-fmi3"])
def test_run_native_regulators_relative_out(workdir, regulator, native_fmus):
    """The native FMUs through a relative --fmu and --out."""
    version = 3 if regulator == "native-fmi3" else 2
    local = workdir / "fmus" / f"native{version}.fmu"
    shutil.copy(native_fmus[version], local)
    out = f"runs_{regulator}"
    r = run_cli(workdir, "run", "scen/rel_a.toml", "--out", out, "--regulator", regulator,
                "--fmu", f"fmus/native{version}.fmu", "--no-plots")
    assert r.returncode == 0, r.stderr
    assert_complete(workdir / out / "rel_a")


def test_run_plant_fmu_relative(workdir):
    """--plant fmu with a relative --plant-fmu and --out."""
    r = run_cli(workdir, "run", "scen/rel_a.toml", "--out", "runs_plant", "--fmu", "fmus/AVR.fmu",
                "--plant", "fmu", "--plant-fmu", "fmus/Plant.fmu", "--no-plots")
    assert r.returncode == 0, r.stderr
    assert_complete(workdir / "runs_plant" / "rel_a")


def test_render_relative_out(workdir):
    """--render writes its videos under a relative --out."""
    r = run_cli(workdir, "run", "scen/rel_a.toml", "--out", "runs_render", "--regulator", "inprocess", "--render",
                "--no-plots")
    assert r.returncode == 0, r.stderr
    assert (workdir / "runs_render" / "rel_a" / "adaptive.mp4").stat().st_size > 0
    assert (workdir / "runs_render" / "rel_a" / "pd_only.gif").stat().st_size > 0


def test_validate_relative_files(workdir):
    r = run_cli(workdir, "validate", "scen/rel_a.toml", "scen/rel_osu.toml")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count(": ok") == 2


def test_campaign_relative_file_base_out_and_fmu(workdir):
    """A campaign file given relatively, its base a scenario file relative to it, a relative
    --out and --fmu, on a real local Dask cluster; then --resume on the same relative folder."""
    (workdir / "camp").mkdir(exist_ok=True)
    (workdir / "camp" / "tiny.toml").write_text('''name = "tiny"
description = "two samples from a relative base"
base = "../scen/rel_a.toml"
duration_s = 0.5
compare = ["adaptive"]
samples = 2
seed = 3
task_timeout_s = 300.0

[factors.torso_mass_kg]
dist = "uniform"
low = 10.33
high = 12.0
''')
    r = run_cli(workdir, "campaign", "camp/tiny.toml", "--out", "camp_out", "--fmu", "fmus/AVR.fmu",
                "--workers", "1")
    assert r.returncode == 0, r.stdout + r.stderr
    csv = (workdir / "camp_out" / "campaign.csv").read_text().splitlines()
    assert len(csv) == 1 + 2, csv  # a header and one row per sample x arm
    r = run_cli(workdir, "campaign", "camp/tiny.toml", "--out", "camp_out", "--fmu", "fmus/AVR.fmu",
                "--workers", "1", "--resume")
    assert r.returncode == 0, r.stdout + r.stderr
