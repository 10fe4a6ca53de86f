"""A plain C host (tests/support/native/fmi2_host.c, no Python of its own) runs each FMI 2.0
regulator FMU, as a non-Python importer would, and matches the numpy core.

* The native FMU needs nothing: the host runs with an empty environment.
* pythonfmu's library takes Python's symbols from the host process: a C host needs
  libpython preloaded (LD_PRELOAD) and PYTHONHOME/PYTHONPATH pointing at an interpreter
  that has numpy.  Without the preload the FMU's guard refuses to instantiate with a
  message that says so, instead of crashing the host.
"""
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from support.native_support import (C_HOST, CC, FMI2_INCLUDE, c_host_outputs, c_host_script, compile_c, core_outputs,
                            fmi2_only, input_sequence, require)

N_STEPS = 200
PARAMS = {"n_neurons": 300, "seed": 5, "learning_rate": 1e-4}
#: %.17g round-trips a double exactly; the native core differs from numpy by summation order
#: (~1e-16): 1e-12 is far above that and far below any real bug.
TOL = dict(rtol=1e-12, atol=1e-12)
#: fmi2Instantiate returned NULL (tests/support/native/fmi2_host.c's exit status)
HOST_INSTANTIATE_FAILED = 4

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a Linux C host")


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    exe = tmp_path_factory.mktemp("c_host") / "fmi2_host"
    return compile_c(require(CC), [C_HOST], exe, "-std=c99", "-O1", f"-I{FMI2_INCLUDE}", "-ldl")


@pytest.fixture(scope="module")
def sequence():
    return input_sequence(N_STEPS, seed=31)


def _run(host, fmu, tmp_path, env, sequence, params):
    from fmpy import read_model_description

    md = read_model_description(fmu.dir)
    script = tmp_path / "script.txt"
    script.write_text(c_host_script(fmu.path, params, sequence))
    library = Path(fmu.dir) / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    env = dict(env, FMI2_HOST_RESOURCES=(Path(fmu.dir) / "resources").as_uri())
    return subprocess.run([str(host), str(library), md.guid, str(script)], env=env, capture_output=True, text=True,
                          timeout=120)


def _python_env(preload: bool) -> dict:
    """What a C host of the pythonfmu FMU needs (with ``preload``), or the environment without PYTHON*."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    if preload:
        libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
        # after whatever is preloaded already (the sanitizer run preloads libasan, which must come first)
        env["LD_PRELOAD"] = " ".join(filter(None, [os.environ.get("LD_PRELOAD"), str(libpython)]))
        env["PYTHONHOME"] = sys.base_prefix
        env["PYTHONPATH"] = str(Path(np.__file__).parents[1])  # where numpy is installed
    return env


@fmi2_only
def test_c_host_runs_the_fmu_and_matches_the_core(host, regulator_fmu, sequence, tmp_path):
    if regulator_fmu.implementation == "python":
        libpython = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("LDLIBRARY") or "")
        if not libpython.is_file() or not sysconfig.get_config_var("Py_ENABLE_SHARED"):
            pytest.skip("this Python has no shared libpython to preload")
        env = _python_env(preload=True)
    else:
        env = {}  # no LD_PRELOAD, no PYTHON*: nothing at all
    proc = _run(host, regulator_fmu, tmp_path, env, sequence, PARAMS)
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_allclose(c_host_outputs(proc.stdout), core_outputs(sequence, **PARAMS), **TOL)


def test_c_host_without_libpython_gets_a_clear_error_not_a_crash(host, fmu_dir, built_fmu, tmp_path):
    from conftest import RegulatorFmu

    fmu = RegulatorFmu("python", 2, built_fmu, fmu_dir)
    proc = _run(host, fmu, tmp_path, _python_env(preload=False), input_sequence(3, seed=1), {})
    assert proc.returncode == HOST_INSTANTIATE_FAILED, (proc.returncode, proc.stderr)
    assert "undefined symbol" in proc.stderr and "LD_PRELOAD" in proc.stderr, proc.stderr
