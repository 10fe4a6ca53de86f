"""A terrain scenario on the native CassiePlant FMU through the real command line: the master
writes the height field the native plant needs (``terrain_field_file``) into the run's scratch
folder, and the run records the pythonfmu CassiePlant FMU's rows byte for byte."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from support.paths import REPO_ROOT
from support.plant_fmu_support import built_plant_fmu

#: Simulated seconds: the weight shift and the first steps on terrain_mass_com's ground.
RUN_S = "3"


def _run(out: Path, plant_fmu: Path, regulator_fmu: Path, tmp: Path) -> subprocess.CompletedProcess:
    """``run terrain_mass_com`` with ``--plant fmu --plant-fmu plant_fmu``, the system temp folder
    pointed at the empty ``tmp`` (the run must write nothing there)."""
    tmp.mkdir()
    env = dict(os.environ, TMPDIR=str(tmp),
               MENAGERIE_ROOT=str(REPO_ROOT.parent / "shared" / "cassie" / "menagerie"))
    return subprocess.run([sys.executable, "-m", "scenarios", "run", "terrain_mass_com", "--duration", RUN_S,
                           "--plant", "fmu", "--plant-fmu", str(plant_fmu), "--regulator", "native",
                           "--fmu", str(regulator_fmu), "--no-plots", "--out", str(out)],
                          cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=1200)


def test_a_terrain_scenario_with_an_added_torso_mass_is_fit_for_the_plant_fmu():
    """terrain_mass_com (terrain and +5 kg on the torso) has nothing the plant FMU cannot carry;
    the added mass is resolved to the absolute torso mass the FMU takes."""
    from scenarios.lang import spec
    from scenarios.lang.plantio import plant_fmu_problems

    assert plant_fmu_problems(spec.resolve_targets(["terrain_mass_com"])[0]) == []


def test_a_terrain_scenario_runs_on_the_native_plant_fmu_as_on_the_pythonfmu_one(tmp_path, tmp_path_factory,
                                                                                   build_module, native_plant_fmus,
                                                                                   native_fmus):
    runs = {}
    for label, plant in (("native", native_plant_fmus[2]), ("python", built_plant_fmu(tmp_path_factory,
                                                                                       build_module))):
        out = tmp_path / label
        proc = _run(out, plant, native_fmus[2], tmp_path / f"tmp_{label}")
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        assert "failed" not in proc.stdout + proc.stderr, proc.stdout[-3000:] + proc.stderr[-3000:]
        assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []  # the scratch folder is gone
        assert list((tmp_path / f"tmp_{label}").iterdir()) == []  # nothing went to the system temp folder
        runs[label] = (out / "terrain_mass_com" / "timeseries.csv").read_bytes()
    assert runs["native"].count(b"\n") > 2 * round(float(RUN_S) / 0.005)  # both arms, every step
    assert runs["native"] == runs["python"]
