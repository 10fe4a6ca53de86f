"""A C host (no Python of its own) runs the FMU, as a non-Python importer would.

pythonfmu's library takes Python's symbols from the host process.  A C host therefore
needs libpython preloaded (LD_PRELOAD) and PYTHONHOME/PYTHONPATH pointing at an
interpreter that has numpy.  Without the preload the FMU's guard refuses to
instantiate with a message that says so, instead of crashing the host.
"""
import math
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from fmu_src.avr_core import OUTPUT_SPECS, Regulator, RegulatorInputs, RegulatorParams

HOST_SOURCE = Path(__file__).parent / "fmi" / "c_host.c"
N_STEPS = 200
H = 0.005

pytestmark = pytest.mark.skipif(shutil.which("cc") is None or not sys.platform.startswith("linux"),
                                reason="needs a C compiler on Linux")


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    exe = tmp_path_factory.mktemp("c_host") / "c_host"
    include = Path(__file__).parents[1] / "fmu_src" / "native" / "third_party" / "fmi2"
    subprocess.run(["cc", "-O1", "-std=c11", f"-I{include}", str(HOST_SOURCE), "-o", str(exe), "-ldl", "-lm"],
                   check=True)
    return exe


@pytest.fixture(scope="module")
def unzipped(fmu_dir):
    return fmu_dir, read_model_description(fmu_dir)


def _env(md, preload):
    vr = {v.name: v.valueReference for v in md.modelVariables}
    names = ["vx", "vx_des", "pitch", "step_index"] + [s.name for s in OUTPUT_SPECS]
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["AVR_VRS"] = ",".join(str(vr[n]) for n in names)
    if preload:
        libpython = Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("LDLIBRARY")
        # after whatever is preloaded already (the sanitizer run preloads libasan, which must come first)
        env["LD_PRELOAD"] = " ".join(filter(None, [os.environ.get("LD_PRELOAD"), str(libpython)]))
        env["PYTHONHOME"] = sys.base_prefix
        env["PYTHONPATH"] = str(Path(np.__file__).parents[1])  # where numpy is installed
    return env


def test_c_host_runs_the_fmu_with_libpython_preloaded(host, unzipped):
    libpython = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("LDLIBRARY") or "")
    if not libpython.is_file() or not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        pytest.skip("this Python has no shared libpython to preload")
    directory, md = unzipped
    proc = subprocess.run([str(host), directory, md.guid, str(N_STEPS)], env=_env(md, preload=True),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    got = np.array([[float(x) for x in line.split()] for line in proc.stdout.splitlines()])
    regulator = Regulator(RegulatorParams())
    expected = []
    for k in range(N_STEPS):
        out = regulator.step(RegulatorInputs(vx=0.5 + 0.3 * math.sin(0.05 * k), vx_des=0.5,
                                             pitch=0.02 * math.cos(0.1 * k), step_index=k // 70), H)
        expected.append([out[s.name] for s in OUTPUT_SPECS])
    # %.17g round-trips a double exactly; C's sin/cos may differ from Python's by an ulp,
    # which the regulator passes on at the 1e-15 level: 1e-12 is far above that, far below any real bug.
    np.testing.assert_allclose(got, np.array(expected), rtol=1e-12, atol=1e-12)


def test_c_host_without_libpython_gets_a_clear_error_not_a_crash(host, unzipped):
    directory, md = unzipped
    proc = subprocess.run([str(host), directory, md.guid, "3"], env=_env(md, preload=False),
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 4, (proc.returncode, proc.stderr)  # fmi2Instantiate returned NULL
    assert "undefined symbol" in proc.stderr and "LD_PRELOAD" in proc.stderr, proc.stderr
