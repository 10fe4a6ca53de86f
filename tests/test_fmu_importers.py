"""The same input sequence through four importers (and the numpy core in-process).

fmpy FMU2Slave, fmpy simulate_fmu, libcosimpy (Open Simulation Platform, set up from
an OSP system structure file) and an FMU container (fmu-manipulation-toolbox) must
give the core's outputs to 1e-12.  They
are in fact bit-identical (the same float64 code runs), the tolerance only allows
for an importer that routes values through a different float formatting.
"""
import shutil

import numpy as np
import pytest
from fmpy import simulate_fmu

from fmu_src.avr_core import INPUT_SPECS, OUTPUT_SPECS, Regulator, RegulatorInputs, RegulatorParams
from test_fmu_compliance import H, Slave, input_sequence

N_STEPS = 150
PARAMS = {"n_neurons": 400, "seed": 11, "Kp_x": 0.3, "learning_rate": 1e-4}  # a fast learner: Psi visibly moves
OUTPUT_NAMES = [s.name for s in OUTPUT_SPECS]
TOL = dict(rtol=1e-12, atol=1e-12)


@pytest.fixture(scope="module")
def sequence():
    return input_sequence(N_STEPS, seed=21)


@pytest.fixture(scope="module")
def reference(sequence):
    regulator = Regulator(RegulatorParams(**PARAMS))
    out = [regulator.step(RegulatorInputs(**u), H) for u in sequence]
    return np.array([[o[name] for name in OUTPUT_NAMES] for o in out])


def test_reference_actually_learns(reference):
    psi_x = reference[:, OUTPUT_NAMES.index("psi_x")]
    assert psi_x[0] == 0.0 and abs(psi_x[-1]) > 1e-4


def test_fmpy_fmu2slave_matches_core(fmu_dir, sequence, reference):
    s = Slave(fmu_dir).init(**PARAMS)
    out = np.array([s.step(k, u) for k, u in enumerate(sequence)])
    s.fmu.terminate()
    s.fmu.freeInstance()
    np.testing.assert_allclose(out, reference, **TOL)


def test_fmpy_simulate_fmu_matches_core(built_fmu, sequence, reference):
    names = [s.name for s in INPUT_SPECS]
    dtype = [("time", np.float64)] + [(n, np.int32 if n == "step_index" else np.float64) for n in names]
    # fmpy applies the input row whose time is the current communication point; rows at k*H.
    rows = [(k * H, *[u[n] for n in names]) for k, u in enumerate(sequence)]
    signals = np.array(rows, dtype=dtype)
    result = simulate_fmu(str(built_fmu), start_time=0.0, stop_time=N_STEPS * H, step_size=H,
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
    <Simulator name="avr" source="AdaptiveVelocityRegulator.fmu" stepSize="{h}">
      <InitialValues>
{initial}
      </InitialValues>
    </Simulator>
  </Simulators>
</OspSystemStructure>
"""


def test_libcosimpy_matches_core(built_fmu, sequence, reference, tmp_path):
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimManipulator import CosimManipulator
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    shutil.copy(built_fmu, tmp_path / "AdaptiveVelocityRegulator.fmu")
    typed = {"n_neurons": "Integer", "seed": "Integer"}
    initial = "\n".join(
        f'        <InitialValue variable="{k}"><{typed.get(k, "Real")} value="{v!r}"/></InitialValue>'
        for k, v in PARAMS.items())
    (tmp_path / "OspSystemStructure.xml").write_text(OSP_SYSTEM.format(h=H, initial=initial))
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


def test_fmu_container_matches_core(built_fmu, sequence, reference, tmp_path, venv_tool, unzip):
    """Our FMU inside an FMU container (fmu-manipulation-toolbox's fmucontainer), run by fmpy."""
    import subprocess

    shutil.copy(built_fmu, tmp_path / "AdaptiveVelocityRegulator.fmu")
    (tmp_path / "avr_container.csv").write_text("rule;from_fmu;from_port;to_fmu;to_port\n"
                                                 "FMU;AdaptiveVelocityRegulator.fmu;;;\n")
    proc = subprocess.run([venv_tool("fmucontainer"), "-container", f"avr_container.csv:{H}", "-fmu-directory", str(tmp_path)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    container = tmp_path / "avr_container.fmu"
    assert container.is_file(), proc.stdout + proc.stderr
    s = Slave(unzip(container, tmp_path / "container_unzipped"))
    # the container exposes the inputs and outputs, not the parameters: run with the defaults
    s.init()
    regulator = Regulator(RegulatorParams())
    expected = np.array([[o[n] for n in OUTPUT_NAMES]
                         for o in (regulator.step(RegulatorInputs(**u), H) for u in sequence)])
    out = np.array([s.step(k, u) for k, u in enumerate(sequence)])
    s.fmu.terminate()
    s.fmu.freeInstance()
    np.testing.assert_allclose(out, expected, **TOL)
