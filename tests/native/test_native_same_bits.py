"""The native FMUs' C sources give the shipped binaries' bits wherever an importer compiles them.

FMI has no place for compiler flags, and importers pass none of ours: fmpy's
``build_platform_binary`` runs CMake with the FMU's source list and the compiler's defaults.
In GCC's GNU modes (``-std=gnu11``, CMake's default ``gnu99``) and with clang, ``a * b + c``
may be contracted into one fused multiply-add, which rounds once instead of twice.  The
sources forbid that themselves (avr_types.h), so here each FMU's ``sources/`` is built by
fmpy's ``build_platform_binary`` with options an importer may well use (``-std=gnu11 -O3
-march=native``; for Linux aarch64 the cross compiler at ``-std=gnu11 -O3``), run through
the plain C host (aarch64 under qemu-aarch64), and its printed outputs must be the shipped
x86-64 binary's, byte for byte (``%.17g`` reads back as the same double): once with the
paper's plain rule, once with every remedy against drift on (leakage, dead-zone, projection).
"""
import os
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.build import build_platform_binary

from support.native_support import AARCH64_CC, CC, c_host_script, compile_host, input_sequence, require, run_host

PARAMS = {"n_neurons": 500, "seed": 3, "learning_rate": 1e-4, "psi_gain_stance_knee": 0.0,
          "learn_from_step": 1, "leakage_per_s": 0.0}  # learning from the first step; the plain rule
#: The same with the remedy against drift on, acting on this sequence: the leak of every weight,
#: with learning on settled commands (slow ramps counting) and the rate-limited command reference.
REMEDIES = {**PARAMS, "leakage_per_s": 0.5, "leakage_mode": 0, "command_accel_limit_mps2": 0.5,
            "learn_settled_steps": 2, "learn_ramp_max_mps2": 0.25}
#: The leak of the part orthogonal to the current rates (leakage_mode 1) with the rate-limited
#: command reference.
KEEP_OUTPUT = {**PARAMS, "leakage_per_s": 0.5, "leakage_mode": 1, "command_accel_limit_mps2": 0.5}
RUNS = {"plain": PARAMS, "remedies": REMEDIES, "keep_output": KEEP_OUTPUT}
N_STEPS = 400
LIBRARY = "AdaptiveVelocityRegulatorNative.so"
SHIPPED = {2: f"binaries/linux64/{LIBRARY}", 3: f"binaries/x86_64-linux/{LIBRARY}"}
CLANG = Path("/usr/bin/clang")
#: build -> (CPU, C compiler, CMAKE_C_FLAGS): what an importer may compile the sources with.
BUILDS = {
    "gcc-gnu11-O3-march=native": ("x86_64", CC, "-std=gnu11 -O3 -march=native"),
    "clang-gnu11-O3-march=native": ("x86_64", CLANG, "-std=gnu11 -O3 -march=native"),
    "aarch64-gcc-gnu11-O3": ("aarch64", AARCH64_CC, "-std=gnu11 -O3"),
}
def build_with_fmpy(fmu: Path, compiler: Path, cpu: str, flags: str, folder: Path, monkeypatch) -> Path:
    """The FMU's ``sources/`` built by fmpy's ``build_platform_binary`` (CMake; ``cmake`` comes
    with fmpy, beside the interpreter) with ``compiler`` and ``flags``; the library's path."""
    unzipped = folder / "fmu"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(unzipped)
    for old in unzipped.glob("binaries/*/*"):
        old.unlink()  # only the library built here may be found below
    options = {"CMAKE_C_COMPILER:FILEPATH": str(require(compiler)), "CMAKE_C_FLAGS:STRING": flags}
    if cpu != "x86_64":
        options.update({"CMAKE_SYSTEM_NAME:STRING": "Linux", "CMAKE_SYSTEM_PROCESSOR:STRING": cpu})
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    build = folder / "build"
    build.mkdir()
    build_platform_binary(unzipped, build, cmake_options=options)
    [library] = unzipped.glob(f"binaries/*/{LIBRARY}")
    return library


@pytest.fixture(scope="module")
def shipped_outputs(native_fmus, tmp_path_factory):
    """{fmi: (instantiation token, {run: (script, the shipped Linux x86-64 binary's outputs
    through the C host)})}, one run per parameter set of ``RUNS``."""
    out = {}
    for fmi, fmu in native_fmus.items():
        tmp = tmp_path_factory.mktemp(f"shipped{fmi}")
        library = tmp / LIBRARY
        with zipfile.ZipFile(fmu) as z:
            library.write_bytes(z.read(SHIPPED[fmi]))
        token = read_model_description(str(fmu)).guid
        host = compile_host(CC, fmi, tmp / "host")
        runs = {}
        for name, params in RUNS.items():
            script = tmp / f"script_{name}.txt"
            script.write_text(c_host_script(fmu, params, input_sequence(N_STEPS, seed=8)))
            runs[name] = (script, run_host(host, "x86_64", library, token, script))
        assert runs["plain"][1] != runs["remedies"][1]  # the remedies act on this sequence
        assert runs["keep_output"][1] not in (runs["plain"][1], runs["remedies"][1])
        out[fmi] = (token, runs)
    return out


@pytest.mark.parametrize("build", list(BUILDS))
@pytest.mark.parametrize("fmi", [2, 3])
def test_sources_built_by_fmpy_give_the_shipped_bits(native_fmus, shipped_outputs, fmi, build, tmp_path,
                                                     monkeypatch):
    cpu, compiler, flags = BUILDS[build]
    library = build_with_fmpy(native_fmus[fmi], compiler, cpu, flags, tmp_path, monkeypatch)
    host = compile_host(CC if cpu == "x86_64" else AARCH64_CC, fmi, tmp_path / "host")
    token, runs = shipped_outputs[fmi]
    for name, (script, expected) in runs.items():
        got = run_host(host, cpu, library, token, script)
        differ = sum(a != b for a, b in zip(got.splitlines(), expected.splitlines()))
        assert len(got.splitlines()) == len(expected.splitlines()) == N_STEPS
        assert got == expected, f"{build}, {name}: {differ} of {N_STEPS} steps differ from the shipped binary"
