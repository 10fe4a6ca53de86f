"""The documented Python entry points of the SSP tools take paths relative to the current folder
(issue 44; the command lines do since issue 20): ``export_ssp``, ``check_ssp``,
``build_container`` (docs/ssp.md: ``build_container(ssp, "CassieAVR_container.fmu")``) and
``run_container``, and the ``export-ssp`` and ``ssp_check`` command lines, each called with relative
paths only, from a temporary working folder, in a fresh process."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

from support.paths import MODEL_ENV
from support.plant_fmu_support import built_plant_fmu, built_system

SCRIPT = """
from pathlib import Path
from scenarios.lang import spec
from scenarios.ssp.export_ssp import export_ssp
from scenarios.ssp.ssp_check import check_ssp
from scenarios.ssp.system_run import build_container, run_container

scenario = spec.override(spec.resolve_targets(["nominal"])[0], duration_s=0.5)
ssp = export_ssp(scenario, "adaptive", "nominal_adaptive.ssp", plant_fmu="fmus/CassiePlant.fmu",
                 regulator_fmu="fmus/AdaptiveVelocityRegulator.fmu", command_fmu="fmus/CommandSource_fmi2.fmu")
assert check_ssp(ssp) == [] and check_ssp("CassieAVR.ssp") == []
for name in ("nominal_adaptive.ssp", "CassieAVR.ssp"):
    fmu = build_container(name, Path(name).stem + "_container.fmu")
    rows = run_container(Path(name).stem + "_container.fmu", 0.5)
    assert fmu.is_file() and len(rows) == 100 and not rows["plant_fell"].any(), name
print("ok")
"""


def test_ssp_python_entry_points_and_commands_take_relative_paths(tmp_path_factory, build_module, built_fmu,
                                                                  tmp_path):
    system = built_system(tmp_path_factory, build_module, built_fmu)
    (tmp_path / "fmus").mkdir()
    shutil.copy(built_fmu, tmp_path / "fmus" / "AdaptiveVelocityRegulator.fmu")
    shutil.copy(built_plant_fmu(tmp_path_factory, build_module), tmp_path / "fmus" / "CassiePlant.fmu")
    shutil.copy(system / "CommandSource_fmi2.fmu", tmp_path / "fmus" / "CommandSource_fmi2.fmu")
    shutil.copy(system / "CassieAVR.ssp", tmp_path / "CassieAVR.ssp")
    (tmp_path / "systemp").mkdir()
    env = {**os.environ, "TMPDIR": str(tmp_path / "systemp"), "MENAGERIE_ROOT": MODEL_ENV["MENAGERIE_ROOT"]}

    def run(*args):
        return subprocess.run([sys.executable, *args], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)

    r = run("-c", SCRIPT)
    assert r.returncode == 0 and r.stdout.splitlines()[-1] == "ok", r.stdout + r.stderr[-2500:]
    for name in ("nominal_adaptive", "CassieAVR"):
        assert (tmp_path / f"{name}_container.fmu").is_file()
    r = run("-m", "scenarios", "export-ssp", "nominal", "--arm", "pd_only", "--out", "pd.ssp",
            "--fmu", "fmus/AdaptiveVelocityRegulator.fmu", "--plant-fmu", "fmus/CassiePlant.fmu", "--command-fmu", "fmus/CommandSource_fmi2.fmu")
    assert r.returncode == 0 and (tmp_path / "pd.ssp").is_file(), r.stderr[-3000:]
    r = run("-m", "scenarios.ssp.ssp_check", "pd.ssp")
    assert r.returncode == 0 and "pd.ssp: 0 problem(s)" in r.stdout, r.stdout + r.stderr
    assert list((tmp_path / "systemp").iterdir()) == []
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("container_")) == []
