"""Shared pieces of the regulator-FMU tests (pythonfmu and native alike): an fmpy slave that
speaks FMI 2.0 and FMI 3.0 with variable names, seeded input sequences, the numpy core run on
the same inputs, the subprocess drivers, and C compilation helpers.  The FMUs themselves come
from conftest.py (``built_fmu``, ``native_fmus``, ``regulator_fmu``).
"""
from __future__ import annotations

import itertools
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS
from fmu_src.core.avr_core import Regulator
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams
from support.paths import REPO_ROOT
from support.shared import made_once
H = 0.005  # communication step, s
OUTPUT_NAMES = [s.name for s in OUTPUT_SPECS]
NATIVE_DIR = Path(__file__).parent / "native"
#: The regulator FMUs every compliance rule is checked on (the ids of conftest's ``regulator_fmu``),
#: and those an FMI 2.0-only importer or host takes.
REGULATOR_FMUS = ("python-fmi2", "native-fmi2", "native-fmi3")
FMI2_REGULATOR_FMUS = REGULATOR_FMUS[:2]
#: ``@fmi2_only``: a test taking ``regulator_fmu`` runs on the FMI 2.0 regulator FMUs only.
fmi2_only = pytest.mark.parametrize("regulator_fmu", FMI2_REGULATOR_FMUS, indirect=True)
#: The subprocess drivers (one FMU process per test: a crash fails the test, not pytest), by FMI version.
DRIVERS = {2: Path(__file__).parent / "fmi" / "driver.py", 3: NATIVE_DIR / "driver3.py"}
#: The plain C FMI 2.0 host (tests/support/native/fmi2_host.c) and the FMI 2.0 headers it is compiled with.
C_HOST = NATIVE_DIR / "fmi2_host.c"
FMI2_INCLUDE = REPO_ROOT / "fmu_src" / "fmi" / "third_party" / "fmi2"
#: System compilers and Wine are Debian packages (.ci/run installs them), not Python tools.
CC = Path("/usr/bin/cc")
MINGW_CC = Path("/usr/bin/x86_64-w64-mingw32-gcc")
WINE = Path("/usr/lib/wine/wine64")
READELF = Path("/usr/bin/readelf")
MINGW_OBJDUMP = Path("/usr/bin/x86_64-w64-mingw32-objdump")
#: Linux aarch64: the cross compiler (Debian gcc-aarch64-linux-gnu, with its C library in
#: AARCH64_SYSROOT) and the user-mode emulator that runs its programs here (Debian qemu-user).
AARCH64_CC = Path("/usr/bin/aarch64-linux-gnu-gcc")
AARCH64_SYSROOT = Path("/usr/aarch64-linux-gnu")
QEMU_AARCH64 = Path("/usr/bin/qemu-aarch64")
#: The plain C FMI 3.0 host (tests/support/native/fmi3_host.c, the same scripts as fmi2_host.c) and its headers.
C_HOST3 = NATIVE_DIR / "fmi3_host.c"
FMI3_INCLUDE = FMI2_INCLUDE.parent / "fmi3"


def require(tool: Path) -> Path:
    if not tool.is_file():
        pytest.skip(f"{tool} is not installed (.ci/run installs it)")
    return tool


def wine_env(tmp_path_factory) -> dict[str, str]:
    """The whole environment a Windows program runs in under Wine: Wine's own variables only, and a
    Wine prefix (with its HOME) initialised once per test session (``wineboot``, about 10 s) for
    every Wine test; they run their programs in it, each from its own tmp_path.  TMPDIR is a folder
    of the session's too: the Wine server puts its socket folder (``wine-XXXXXX``) there, which
    it leaves behind."""
    wine = require(WINE)

    def make(folder: Path) -> dict[str, str]:
        (folder / "tmp").mkdir()
        env = {"WINEPREFIX": str(folder / "wineprefix"), "WINEDEBUG": "-all", "HOME": str(folder),
               "WINEDLLOVERRIDES": "mscoree,mshtml=", "PATH": "/usr/bin:/bin", "TMPDIR": str(folder / "tmp")}
        proc = subprocess.run([str(wine), "wineboot", "--init"], env=env, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, proc.stderr[-3000:]
        return env
    return made_once(tmp_path_factory, "wine", make)


def input_sequence(n, seed):
    """A seeded sequence of plausible regulator inputs (a step every 70 calls)."""
    rng = np.random.default_rng(seed)
    seq = []
    for k in range(n):
        seq.append({"vx": float(0.5 + 0.3 * rng.standard_normal()), "vy": float(0.1 * rng.standard_normal()),
                    "vx_des": 0.5, "vy_des": 0.0, "pitch": float(0.05 * rng.standard_normal()),
                    "roll": float(0.05 * rng.standard_normal()), "pitch_rate": float(0.3 * rng.standard_normal()),
                    "roll_rate": float(0.3 * rng.standard_normal()), "step_index": k // 70})
    return seq


#: Where :func:`unzipped` extracts: a folder of this worker's under pytest's temporary folders (set
#: by tests/conftest.py when the session starts). Never beside the FMU: the session's builds are
#: shared by every worker and only read (a test lists what a build holds).
UNZIP_ROOT: dict[str, Path] = {}


def unzipped(fmu_path) -> str:
    """``fmu_path`` extracted into a new folder under :data:`UNZIP_ROOT` (nothing goes to the
    system temp folder or into a shared build)."""
    return extract(str(fmu_path), unzipdir=tempfile.mkdtemp(prefix="unzip_", dir=UNZIP_ROOT["folder"]))


def logged_slave(fmu_path, messages: list, name="avr") -> "AnySlave":
    """An AnySlave whose log messages (text) are appended to ``messages`` (FMI 2.0 or 3.0)."""
    return AnySlave(fmu_path, name=name, messages=messages)


#: Instance numbers of the logged slaves (their FMI 3.0 instanceEnvironment; above the scenarios' own).
_LOGGED_NUMBERS = itertools.count(1_000_000)


def _instantiate_logging(fmu, fmi3: bool, messages: list, number: int) -> None:
    """Instantiate ``fmu`` with the scenarios' process-wide logger routing its messages to
    ``messages``.  Never a logger of its own: fmpy's FMI 2.0 message formatter keeps one global
    pointer to the last logger registered, which would dangle once that logger is collected
    (scenarios/cosim/fmi_api.py explains)."""
    from scenarios.cosim import fmi_api

    fmi_api.route_messages(fmu.instanceName, number, messages)
    fmi_api.FMI_APIS["3.0" if fmi3 else "2.0"].instantiate(fmu, number)


class AnySlave:
    """fmpy's FMU2Slave or FMU3Slave (by the FMU's fmiVersion) addressed by variable name."""

    def __init__(self, fmu_path, name="avr", unzip=None, messages=None):
        """``messages``: a list that gets every log message's text (fmpy prints them otherwise)."""
        number = None if messages is None else next(_LOGGED_NUMBERS)
        if number is not None:
            name = f"{name}-{number}"  # the logger routes by instance name
        self.md = read_model_description(str(fmu_path))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.unzip = unzip or unzipped(fmu_path)
        self.vars = {v.name: v for v in self.md.modelVariables}
        cls = FMU3Slave if self.fmi3 else FMU2Slave
        self.fmu = cls(guid=self.md.guid, unzipDirectory=self.unzip,
                       modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        if messages is None:
            self.fmu.instantiate(loggingOn=False)
        else:
            _instantiate_logging(self.fmu, self.fmi3, messages, number)
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


def c_host_script(fmu, params, sequence) -> str:
    """The script tests/support/native/fmi2_host.c runs: ``params``, then ``sequence`` (dicts of inputs)."""
    md = read_model_description(str(fmu))
    vars_ = {v.name: v for v in md.modelVariables}
    lines = [f"P {vars_[k].valueReference} {vars_[k].type[0]} {float(v)!r}" for k, v in params.items()]
    lines.append("I " + " ".join(str(vars_[s.name].valueReference) for s in INPUT_SPECS))
    lines.append(f"O {len(OUTPUT_NAMES)} " + " ".join(str(vars_[n].valueReference) for n in OUTPUT_NAMES))
    lines += ["S " + " ".join(repr(float(u[s.name])) for s in INPUT_SPECS) for u in sequence]
    return "\n".join(lines) + "\n"


def c_host_outputs(stdout: str) -> np.ndarray:
    """The outputs tests/support/native/fmi2_host.c printed (rows: steps)."""
    return np.array([[float(x) for x in line.split()] for line in stdout.splitlines()])


#: The plain C hosts and their FMI headers, by FMI version.
HOST_SOURCES = {2: (C_HOST, FMI2_INCLUDE), 3: (C_HOST3, FMI3_INCLUDE)}


def compile_host(compiler: Path, fmi: int, out: Path) -> Path:
    """The plain C host for FMI ``fmi``, compiled with ``compiler`` (host or cross).  libm is linked
    in even though the host calls nothing from it: fmpy's CMake build of the sources links no libm
    (it ignores the FMI 3.0 buildDescription's ``<Library name="m"/>``; FMI 2.0 has no place for
    one), so that library takes ``sqrt`` from the process, as it does in every Python host."""
    source, include = HOST_SOURCES[fmi]
    return compile_c(require(compiler), [source], out, "-std=c99", "-O1", f"-I{include}", "-ldl",
                     "-Wl,--no-as-needed", "-lm")


def run_host(host: Path, cpu: str, library: Path, token: str, script: Path) -> str:
    """The host's stdout (one line of outputs per step); aarch64 programs run under qemu-aarch64."""
    cmd = [str(host), str(library), token, str(script)]
    if cpu == "aarch64":
        cmd = [str(require(QEMU_AARCH64)), "-L", str(AARCH64_SYSROOT)] + cmd
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={"PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, f"{' '.join(cmd)} exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    return proc.stdout
