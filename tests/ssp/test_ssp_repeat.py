"""A second and third run of the plant FMU system in one process walks exactly as it would alone.

libcosim and fmpy (issue 44): docs/ssp.md's libcosim loop loads ``CassieAVR.ssp`` again while
the previous execution still lives; that execution, freed when the name is rebound, deletes
its extraction folder, the folder the plant package the next run uses was imported from.  The
plant used to read its gait library from that folder when a walker started and, finding none,
walked on the uncalibrated default gait (the PD-only arm off by up to 0.46 m/s).  The same
happens to any host that creates an instance from a new extraction before it frees the last
one and deletes its folder: the fmpy case below.

Each case runs several executions in one fresh process, alternating two copies of the FMU or
SSP (each extracted on its own) and their parameters, for a few simulated seconds, and compares each
run with the same run alone in another fresh process: bit for bit (one code path, the same
doubles; nothing random).  The uncalibrated gait parts from the calibrated one with the first
step: a walker on the default ``GaitParams()`` leaves the calibrated walker's pelvis x at
t = 0.805 s, right after the 0.8 s stand (measured at 0.5 m/s), and bit for bit a run that
parted cannot come back.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from support.plant_fmu_support import built_plant_fmu, built_system

#: Simulated seconds per run: long enough for the runs to differ (fmpy's torso masses from the
#: start; libcosim's adaptive and PD-only arms part at t = 4.29 s on mass_20kg in our master), and
#: the communication step (docs/ssp.md's 5 ms).
DURATION_S, STEP_S = {"libcosim": 5.0, "fmpy": 3.0}, 0.005
#: libcosim: (SSP copy, adaptation_enabled) per execution: the docs' adaptive-then-PD-only, then adaptive again.
LIBCOSIM_RUNS = (("a", True), ("b", False), ("a", True))
#: fmpy: (FMU copy, torso mass kg) per instance.
FMPY_RUNS = (("a", 10.33), ("b", 20.0), ("a", 10.33))


def _libcosim(runs: list, n: int) -> list:
    """docs/ssp.md's loop: each execution is created while the previous one still lives."""
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    out = []
    for ssp, adaptive in runs:
        execution = CosimExecution.from_ssp_file(ssp)  # the previous execution ends here, after the load
        plant, avr = (execution.slave_index_from_instance_name(name) for name in ("plant", "avr"))
        ref = {i: {v.name.decode(): v.reference for v in execution.slave_variables(i)} for i in (plant, avr)}
        execution.real_initial_value(plant, ref[plant]["torso_mass_kg"], 20.0)
        execution.boolean_initial_value(avr, ref[avr]["adaptation_enabled"], adaptive)
        observer = CosimObserver.create_last_value()
        execution.add_observer(observer)
        refs = [ref[plant][name] for name in ("vx", "pelvis_x", "pelvis_y", "pitch")]
        rows = []
        for _ in range(n):
            assert execution.step()
            rows.append([v.hex() for v in observer.last_real_values(plant, refs)])
        out.append(rows)
    return out


def _fmpy(runs: list, n: int, scratch: str) -> list:
    """A host that extracts each instance's FMU afresh, creates the instance, then frees the
    previous one and deletes that one's folder."""
    from fmpy import extract
    from support.plant_fmu_support import Plant

    out, previous = [], None
    for k, (fmu, torso_mass_kg) in enumerate(runs):
        folder = Path(scratch) / f"x{k}"
        plant = Plant(extract(fmu, unzipdir=str(folder)))
        if previous is not None:
            previous[0].free()
            shutil.rmtree(previous[1])
        previous = plant, folder
        plant.init(torso_mass_kg=torso_mass_kg)
        rows = []
        for _ in range(n):
            plant.step(STEP_S, vx_des=0.5)
            rows.append([float(plant.get(name)).hex() for name in ("vx", "pelvis_x", "pelvis_y", "pitch")])
        out.append(rows)
    previous[0].free()
    return out


def _in_fresh_process(master: str, runs: list, scratch: Path) -> list:
    scratch.mkdir(parents=True)
    proc = subprocess.run([sys.executable, __file__, master, json.dumps(runs), str(scratch)],
                          capture_output=True, text=True, timeout=900, cwd=scratch,
                          env={**os.environ, "TMPDIR": str(scratch),  # libcosim unpacks there
                               "PYTHONPATH": str(Path(__file__).resolve().parents[1])})  # tests/: support.*
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


def _check_each_run_as_alone(master: str, runs: list, tmp_path: Path) -> None:
    together = _in_fresh_process(master, runs, tmp_path / "together")
    assert len(together) == len(runs) and all(len(r) == int(round(DURATION_S[master] / STEP_S)) for r in together)
    alone = {}
    for k, run in enumerate(runs):
        key = json.dumps(run[1:])  # the same parameters give the same run, whichever copy
        if key not in alone:
            (alone[key],) = _in_fresh_process(master, [run], tmp_path / f"alone{k}")
        assert together[k] == alone[key], f"{master} run {k + 1} of {len(runs)} differs from the same run alone"
    # the runs differ (otherwise equality would not tell the gait or the parameters apart)
    assert together[0] != together[1]


@pytest.fixture(scope="module")
def ssp_copies(tmp_path_factory, build_module, built_fmu):
    ssp = built_system(tmp_path_factory, build_module, built_fmu) / "CassieAVR.ssp"
    folder = tmp_path_factory.mktemp("ssp_copies")
    return {name: str(shutil.copy(ssp, folder / f"CassieAVR_{name}.ssp")) for name in ("a", "b")}


def test_libcosim_runs_the_ssp_again_each_run_as_alone(ssp_copies, tmp_path):
    runs = [[ssp_copies[name], adaptive] for name, adaptive in LIBCOSIM_RUNS]
    _check_each_run_as_alone("libcosim", runs, tmp_path)


def test_fmpy_host_instantiates_the_plant_again_each_run_as_alone(tmp_path_factory, build_module, tmp_path):
    fmu = built_plant_fmu(tmp_path_factory, build_module)
    copies = {"a": str(fmu), "b": str(shutil.copy(fmu, tmp_path / "CassiePlant_b.fmu"))}
    runs = [[copies[name], mass] for name, mass in FMPY_RUNS]
    _check_each_run_as_alone("fmpy", runs, tmp_path)


if __name__ == "__main__":
    _master, _runs, _scratch = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3]
    _n = int(round(DURATION_S[_master] / STEP_S))
    print(json.dumps(_libcosim(_runs, _n) if _master == "libcosim" else _fmpy(_runs, _n, _scratch)))
