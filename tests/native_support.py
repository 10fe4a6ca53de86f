"""Shared pieces of the native-FMU tests: the FMUs build.py really builds (once per
session, into a temporary folder), an fmpy slave that speaks FMI 2.0 and FMI 3.0 with
variable names, the numpy core run on the same inputs, and C compilation helpers.

Written for any of the three FMUs (the slave takes any FMI 2.0 or 3.0 FMU), so the
compliance suite can later be parametrized over the pythonfmu FMU too.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from fmu_src.avr_core import OUTPUT_SPECS, Regulator, RegulatorInputs, RegulatorParams
from test_fmu_compliance import input_sequence  # noqa: F401 (the same seeded inputs as the pythonfmu suite)

H = 0.005  # communication step, s
OUTPUT_NAMES = [s.name for s in OUTPUT_SPECS]
NATIVE_DIR = Path(__file__).parent / "native"
#: System compilers and Wine are Debian packages (.ci/run installs them), not Python tools.
CC = Path("/usr/bin/cc")
MINGW_CC = Path("/usr/bin/x86_64-w64-mingw32-gcc")
WINE = Path("/usr/lib/wine/wine64")
READELF = Path("/usr/bin/readelf")
MINGW_OBJDUMP = Path("/usr/bin/x86_64-w64-mingw32-objdump")


def require(tool: Path) -> Path:
    if not tool.is_file():
        pytest.skip(f"{tool} is not installed (.ci/run installs it)")
    return tool


@pytest.fixture(scope="session")
def native_fmus(tmp_path_factory, build_module):
    """{2: path, 3: path}: both native FMUs exactly as build.py builds them."""
    out = tmp_path_factory.mktemp("native_fmus")
    return {v: build_module.build_native_fmu(v, out) for v in (2, 3)}


def unzipped(fmu_path) -> str:
    """``fmu_path`` extracted into a new folder beside it (the FMUs are built under pytest's
    tmp_path: nothing goes to the system temp folder)."""
    return extract(str(fmu_path), unzipdir=tempfile.mkdtemp(prefix="unzip_", dir=Path(fmu_path).parent))


class AnySlave:
    """fmpy's FMU2Slave or FMU3Slave (by the FMU's fmiVersion) addressed by variable name."""

    def __init__(self, fmu_path, name="avr", unzip=None):
        self.md = read_model_description(str(fmu_path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.unzip = unzip or unzipped(fmu_path)
        self.vars = {v.name: v for v in self.md.modelVariables}
        cls = FMU3Slave if self.fmi3 else FMU2Slave
        self.fmu = cls(guid=self.md.guid, unzipDirectory=self.unzip,
                       modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=False)
        self.out_vrs = [self.vars[n].valueReference for n in OUTPUT_NAMES]

    def init(self, **params):
        for name, value in params.items():
            self.set(name, value)
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def set(self, name, value):
        var = self.vars[name]
        vr = [var.valueReference]
        kind = {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer"}.get(var.type, var.type)
        if kind == "Boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        elif kind == "Integer":
            (self.fmu.setInt32 if self.fmi3 else self.fmu.setInteger)(vr, [int(value)])
        else:
            (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(vr, [float(value)])

    def outputs(self):
        get = self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal
        return np.array(get(self.out_vrs))

    def step(self, k, inputs):
        for name, value in inputs.items():
            self.set(name, value)
        self.fmu.doStep(k * H, H)
        return self.outputs()

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()

    # FMU state, with the version's spelling
    def get_state(self):
        return self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()

    def set_state(self, state):
        (self.fmu.setFMUState if self.fmi3 else self.fmu.setFMUstate)(state)

    def serialize(self, state) -> bytes:
        return bytes((self.fmu.serializeFMUState if self.fmi3 else self.fmu.serializeFMUstate)(state))

    def deserialize(self, blob: bytes):
        return (self.fmu.deserializeFMUState if self.fmi3 else self.fmu.deSerializeFMUstate)(blob)


def core_outputs(sequence, **params) -> np.ndarray:
    """The numpy core's outputs (rows: calls) on ``sequence`` (dicts of inputs)."""
    regulator = Regulator(RegulatorParams(**params))
    return np.array([[o[n] for n in OUTPUT_NAMES]
                     for o in (regulator.step(RegulatorInputs(**u), H) for u in sequence)])


def compile_c(compiler: Path, sources, out: Path, *flags, cwd=None) -> Path:
    """Compile C ``sources`` into ``out``; the test fails with the compiler's message otherwise."""
    cmd = [str(compiler), *flags, *map(str, sources), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr}"
    return out


def fmutool() -> Path:
    """fmutool (fmu-manipulation-toolbox) of the running interpreter's environment."""
    return Path(sys.executable).parent / "fmutool"
