"""The same input sequence through four importers (and the numpy core in-process), on every
regulator FMU (pythonfmu FMI 2.0, native FMI 2.0 and 3.0).

fmpy FMU2Slave/FMU3Slave, fmpy simulate_fmu, libcosimpy (Open Simulation Platform, set up
from an OSP system structure file; FMI 2.0) and an FMU container (fmu-manipulation-toolbox;
FMI 2.0) must give the core's outputs to 1e-12.  The pythonfmu FMU runs the core's own
float64 code (bit-identical); the native cores differ by summation order only (~1e-16 here);
the tolerance also allows an importer that routes values through a different float formatting.
"""
import shutil

import numpy as np
import pytest
from fmpy import simulate_fmu

from fmu_src.core.avr_specs import INPUT_SPECS
from support.native_support import H, OUTPUT_NAMES, AnySlave, core_outputs, fmi2_only, input_sequence

N_STEPS = 150
# a fast learner from the first step: Psi visibly moves
PARAMS = {"n_neurons": 400, "seed": 11, "Kp_x": 0.3, "learning_rate": 1e-4, "learn_from_step": 1}
TOL = dict(rtol=1e-12, atol=1e-12)


@pytest.fixture(scope="module")
def sequence():
    return input_sequence(N_STEPS, seed=21)


@pytest.fixture(scope="module")
def reference(sequence):
    return core_outputs(sequence, **PARAMS)


def test_reference_actually_learns(reference):
    psi_x = reference[:, OUTPUT_NAMES.index("psi_x")]
    assert psi_x[0] == 0.0 and abs(psi_x[-1]) > 1e-4


def test_fmpy_slave_matches_core(regulator_fmu, sequence, reference):
    s = AnySlave(regulator_fmu.path, unzip=regulator_fmu.dir).init(**PARAMS)
    out = np.array([s.step(k, u) for k, u in enumerate(sequence)])
    s.close()
    np.testing.assert_allclose(out, reference, **TOL)


def test_fmpy_simulate_fmu_matches_core(regulator_fmu, sequence, reference):
    names = [s.name for s in INPUT_SPECS]
    dtype = [("time", np.float64)] + [(n, np.int32 if n == "step_index" else np.float64) for n in names]
    # fmpy applies the input row whose time is the current communication point; rows at k*H.
    rows = [(k * H, *[u[n] for n in names]) for k, u in enumerate(sequence)]
    signals = np.array(rows, dtype=dtype)
    result = simulate_fmu(str(regulator_fmu.path), start_time=0.0, stop_time=N_STEPS * H, step_size=H,
                          output_interval=H, input=signals, start_values=PARAMS, output=OUTPUT_NAMES)
    # result row 0 is the state at t=0 (before any step); row k+1 follows step k
    out = np.array([[row[n] for n in OUTPUT_NAMES] for row in result[1:N_STEPS + 1]])
    np.testing.assert_allclose(out, reference, **TOL)


OSP_SYSTEM = """<?xml version="1.0" encoding="utf-8"?>
<OspSystemStructure xmlns="http://opensimulationplatform.com/MSMI/OSPSystemStructure" version="0.1">
  <StartTime>0.0</StartTime>
  <BaseStepSize>{h}</BaseStepSize>
  <Algorithm>fixedStep</Algorithm>
  <Simulators>
    <Simulator name="avr" source="{fmu}" stepSize="{h}">
      <InitialValues>
{initial}
      </InitialValues>
    </Simulator>
  </Simulators>
</OspSystemStructure>
"""


@fmi2_only
def test_libcosimpy_matches_core(regulator_fmu, sequence, reference, tmp_path):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    shutil.copy(regulator_fmu.path, tmp_path / regulator_fmu.path.name)
    typed = {"n_neurons": "Integer", "seed": "Integer", "learn_from_step": "Integer"}
    initial = "\n".join(
        f'        <InitialValue variable="{k}"><{typed.get(k, "Real")} value="{v!r}"/></InitialValue>'
        for k, v in PARAMS.items())
    (tmp_path / "OspSystemStructure.xml").write_text(OSP_SYSTEM.format(h=H, initial=initial, fmu=regulator_fmu.path.name))
    execution = CosimExecution.from_osp_config_file(osp_path=str(tmp_path))
    index = execution.slave_index_from_instance_name("avr")
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(slave_index=index)}
    manipulator = CosimManipulator.create_override()
    observer = CosimObserver.create_last_value()
    execution.add_manipulator(manipulator=manipulator)
    execution.add_observer(observer=observer)
    reals = [s.name for s in INPUT_SPECS if s.type == "Real"]
    out = []
    for u in sequence:
        manipulator.slave_real_values(index, [vr[n] for n in reals], [u[n] for n in reals])
        manipulator.slave_integer_values(index, [vr["step_index"]], [u["step_index"]])
        assert execution.step()
        out.append(observer.last_real_values(index, [vr[n] for n in OUTPUT_NAMES]))
    np.testing.assert_allclose(np.array(out), reference, **TOL)


@fmi2_only
def test_fmu_container_matches_core(regulator_fmu, sequence, tmp_path, venv_tool, unzip):
    """The FMU inside an FMU container (fmu-manipulation-toolbox's fmucontainer), run by fmpy."""
    import subprocess

    name = regulator_fmu.path.name
    shutil.copy(regulator_fmu.path, tmp_path / name)
    (tmp_path / "avr_container.csv").write_text(f"rule;from_fmu;from_port;to_fmu;to_port\nFMU;{name};;;\n")
    proc = subprocess.run([venv_tool("fmucontainer"), "-container", f"avr_container.csv:{H}", "-fmu-directory",
                           str(tmp_path)], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    container = tmp_path / "avr_container.fmu"
    assert container.is_file(), proc.stdout + proc.stderr
    s = AnySlave(container, unzip=unzip(container, tmp_path / "container_unzipped"))
    s.init()  # the container exposes the inputs and outputs, not the parameters: run with the defaults
    out = np.array([s.step(k, u) for k, u in enumerate(sequence)])
    s.close()
    np.testing.assert_allclose(out, core_outputs(sequence), **TOL)
