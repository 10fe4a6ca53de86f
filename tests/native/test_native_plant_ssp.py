"""The Python-free system: CassieAVRNative.ssp (native plant, native regulator, command source)
runs in libcosim, fmpy and Ecos, and gives CassieAVR.ssp's run (pythonfmu plant and regulator)
bit for bit in libcosim; the native plant FMUs' reference results are the pythonfmu plant's.

Both systems are made by build.py's own functions.  The regulators' two cores compute the same
bits (tests/native/test_native_same_bits.py) and so do the plants (tests/native/test_native_plant.py),
so one master running both systems must record the same doubles.
"""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from scenarios.ssp import system, system_run
from support.plant_fmu_support import built_plant_fmu, built_system

#: Simulated seconds per master run: the weight shift and about eight walking steps.
MASTERS_S = 4.0


@pytest.fixture(scope="module")
def systems(tmp_path_factory, build_module, built_fmu, native_plant_fmus, native_fmus):
    """(CassieAVR.ssp, CassieAVRNative.ssp, the native plant FMI 2.0 and 3.0 FMUs, the native regulator):
    the session's FMUs (conftest.py), the native system made of them by build.py's function."""
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.ERROR)
    python_dir = built_system(tmp_path_factory, build_module, built_fmu)
    plants, regulator = [native_plant_fmus[v] for v in (2, 3)], native_fmus[2]
    native = build_module.build_native_ssp(tmp_path_factory.mktemp("native_system"), plants[0], regulator,
                                           python_dir / "CommandSource_fmi2.fmu")
    return python_dir / f"{system.SYSTEM_NAME}.ssp", native, plants, regulator


def _in_fresh_temp(tmp_path, run, *args):
    """``run(*args)`` with the system temp folder pointed at an empty ``tmp_path`` (the masters
    unpack the SSP there); asserts they leave nothing behind."""
    import tempfile

    tmp_path.mkdir(parents=True, exist_ok=True)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("TMPDIR", str(tmp_path))
        mp.setattr(tempfile, "tempdir", str(tmp_path))
        rows = run(*args)
    assert not list(tmp_path.iterdir()), sorted(p.name for p in tmp_path.iterdir())
    return rows


def test_the_native_ssp_holds_no_python(systems):
    _, native, _, _ = systems
    with zipfile.ZipFile(native) as z:
        fmus = sorted(n for n in z.namelist() if n.endswith(".fmu"))
    assert fmus == ["resources/AdaptiveVelocityRegulatorNative_fmi2.fmu", "resources/CassiePlantNative_fmi2.fmu",
                    "resources/CommandSource_fmi2.fmu"]


@pytest.mark.parametrize("master", ["libcosim", "fmpy", "ecos"])
def test_native_ssp_walks_in_each_master(systems, master, tmp_path):
    _, native, _, _ = systems
    run = {"libcosim": system_run.run_libcosim, "fmpy": system_run.run_fmpy, "ecos": system_run.run_ecos}[master]
    rows = _in_fresh_temp(tmp_path / "tmp", run, native, MASTERS_S)
    assert len(rows) == round(MASTERS_S / system.STEP_S)
    assert not rows["plant_fell"].any()
    assert rows["plant_step_index"][-1] >= 8 and rows["plant_pelvis_x"][-1] > 1.0, rows[-1]


def test_native_ssp_is_the_python_ssp_bit_for_bit_in_libcosim(systems, tmp_path):
    python_ssp, native, _, _ = systems
    want = _in_fresh_temp(tmp_path / "a", system_run.run_libcosim, python_ssp, MASTERS_S)
    got = _in_fresh_temp(tmp_path / "b", system_run.run_libcosim, native, MASTERS_S)
    for column in want.dtype.names:
        assert np.array_equal(got[column], want[column]), column


def test_native_plants_reference_results_are_the_pythonfmu_plants(systems, tmp_path_factory, build_module):
    """build.py simulates each FMU with FMPy on the same experiment (fmu_src/packing/crosscheck.py):
    the native plants' results are the pythonfmu plant's, byte for byte."""
    _, _, plants, _ = systems
    python_plant = built_plant_fmu(tmp_path_factory, build_module)
    ref = "extra/org.fmi-standard.fmi-ls-ref/{}_ref.csv"
    with zipfile.ZipFile(python_plant) as z:
        want = z.read(ref.format("CassiePlant"))
    for plant in plants:
        with zipfile.ZipFile(plant) as z:
            assert z.read(ref.format("CassiePlantNative")) == want, plant.name


def test_our_master_runs_a_scenario_on_the_native_plant_as_on_the_pythonfmu_plant(systems, tmp_path_factory,
                                                                                   build_module):
    """``--plant fmu`` with the native plant FMU: mass_20kg's adaptive arm, 4 s, the same rows as
    with the pythonfmu CassiePlant (the master drives any FMU with CassiePlant's variables)."""
    from scenarios.cosim import master
    from scenarios.cosim.plant_fmu import plant_factory
    from scenarios.lang import spec

    _, _, plants, regulator = systems
    scenario = spec.override(spec.resolve_targets(["mass_20kg"])[0], duration_s=MASTERS_S)
    runs = [master.run_scenario(scenario, "fmu", fmu_path=regulator, arms=("adaptive",), plant=plant_factory(p))[0]
            for p in (built_plant_fmu(tmp_path_factory, build_module), plants[0])]
    want, got = (r.rows for r in runs)
    assert len(got) == round(MASTERS_S / 0.005) and not any(r.fell for r in runs)
    for column in want.dtype.names:
        assert np.array_equal(got[column], want[column]), column
