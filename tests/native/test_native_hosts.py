"""The native FMUs outside Python: a plain C host, the shipped sources, Windows under Wine,
and the FMU built with AddressSanitizer + UndefinedBehaviorSanitizer.

* (tests/fmu/test_fmu_c_host.py: tests/support/native/fmi2_host.c loads the FMI 2.0 FMU's linux64
  library with an empty environment and matches the numpy core.)
* The FMU's ``sources/`` compile with ``cc`` alone in a clean folder; the library built
  from them gives the same outputs as the shipped one (FMI 2.0 and 3.0).
* (marker ``wine``) the same host cross-compiled with MinGW-w64 runs the win64 library under
  Wine and matches the core.
* (marker ``sanitize``) the FMU library built with -fsanitize=address,undefined runs the
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

from support.native_support import (C_HOST, CC, DRIVERS, FMI2_INCLUDE, MINGW_CC, NATIVE_DIR, WINE, AnySlave, c_host_outputs,
                            c_host_script, compile_c, core_outputs, input_sequence, require, unzipped,
                            wine_env)

PARAMS = {"n_neurons": 500, "seed": 3, "learning_rate": 1e-4, "psi_gain_stance_knee": 0.0}
N_STEPS = 400
#: The cores compute the same bits (no libm function in the numerics, see avr_network)
#: and %.17g round-trips doubles exactly, so the C host's outputs, on Linux and under
#: Wine alike, equal the numpy core's exactly.
TOL = dict(rtol=0, atol=0)
LINUX = {2: "linux64", 3: "x86_64-linux"}


@pytest.fixture(scope="module")
def sequence():
    return input_sequence(N_STEPS, seed=8)


@pytest.fixture(scope="module")
def reference(sequence):
    return core_outputs(sequence, **PARAMS)


def _unzip(fmu, folder: Path) -> Path:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    return folder


@pytest.mark.parametrize("fmi", [2, 3])
def test_sources_in_the_fmu_compile_with_cc_alone_and_match(native_fmus, sequence, tmp_path, fmi):
    unzipped = _unzip(native_fmus[fmi], tmp_path / "fmu")
    clean = tmp_path / "clean"
    shutil.copytree(unzipped / "sources", clean)  # nothing but the FMU's sources
    sources = sorted(p.name for p in clean.glob("*.c"))
    if fmi == 3:  # the build description names the same files
        text = (clean / "buildDescription.xml").read_text()
        assert all(f'name="{name}"' in text for name in sources)
    # no floating-point option: the sources state their contract (tests/support/native/test_native_same_bits.py)
    lib = compile_c(require(CC), sources, clean / "AdaptiveVelocityRegulatorNative.so", "-std=c99", "-O2",
                    "-shared", "-fPIC", "-I.", "-lm", cwd=clean)
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
def test_win64_binary_under_wine_matches_the_core(native_fmus, sequence, reference, tmp_path, tmp_path_factory):
    host = compile_c(require(MINGW_CC), [C_HOST], tmp_path / "fmi2_host.exe", "-std=c99", "-O2",
                     f"-I{FMI2_INCLUDE}", "-static")
    unzipped = _unzip(native_fmus[2], tmp_path / "fmu")
    script = tmp_path / "script.txt"
    script.write_text(c_host_script(native_fmus[2], PARAMS, sequence))
    dll = unzipped / "binaries" / "win64" / "AdaptiveVelocityRegulatorNative.dll"
    env = wine_env(tmp_path_factory)
    guid = read_model_description(str(native_fmus[2])).guid
    proc = subprocess.run([str(require(WINE)), str(host), str(dll), guid, str(script)], env=env, capture_output=True,
                          text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-3000:]
    np.testing.assert_allclose(c_host_outputs(proc.stdout), reference, **TOL)


# ---- AddressSanitizer + UndefinedBehaviorSanitizer ----------------------------------------------------
#: -Wno-error: GCC 12 warns falsely (format-truncation on a checked snprintf) in instrumented -O3 code.
SANITIZE = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g", "-Wno-error")
FUZZ_SEQUENCES = 300


@pytest.fixture(scope="module")
def sanitized_fmus(native_fmus, build_module, tmp_path_factory):
    """Both native FMUs with their Linux library rebuilt from their own sources with the sanitizers."""
    require(CC)
    out = {}
    for fmi, fmu in native_fmus.items():
        tmp = tmp_path_factory.mktemp(f"sanitized{fmi}")
        src = _unzip(fmu, tmp / "unzipped") / "sources"
        lib = build_module.compile_native(src, fmi, "linux", tmp / "AdaptiveVelocityRegulatorNative.so",
                                          extra_flags=SANITIZE)
        assert b"__asan_report" in lib.read_bytes() and b"__ubsan_handle" in lib.read_bytes()  # instrumented
        out[fmi] = tmp / fmu.name
        with zipfile.ZipFile(fmu) as original, zipfile.ZipFile(out[fmi], "w") as copy:
            for info in original.infolist():
                data = lib.read_bytes() if info.filename.startswith(f"binaries/{LINUX[fmi]}/") else \
                    original.read(info)
                copy.writestr(info, data)
    return out


def _sanitizer_env():
    libasan = subprocess.run([str(CC), "-print-file-name=libasan.so"], capture_output=True, text=True).stdout.strip()
    # Python itself is not instrumented and keeps memory until exit: leak checking would report it, not us.
    return {**os.environ, "LD_PRELOAD": libasan, "ASAN_OPTIONS": "detect_leaks=0:halt_on_error=1",
            "UBSAN_OPTIONS": "halt_on_error=1:print_stacktrace=1"}


def _findings(stderr: str) -> int:
    return stderr.count("ERROR: AddressSanitizer") + stderr.count("runtime error:")


def _random_sequences(fmi, rng):
    """Seeded call sequences from the same vocabulary and values as the hypothesis property."""
    from test_fmu_call_sequences import NAMES, _coerce

    specials = [0.0, 0.25, 1e-6, 1.0, -1.0, float("nan"), float("inf"), -float("inf"), 1e300, -5.0, 3000]
    for _ in range(FUZZ_SEQUENCES):
        calls = []
        for _ in range(rng.integers(1, 26)):
            kind = rng.integers(0, 7)
            if kind == 0:
                calls.append((str(rng.choice(["enter", "exit", "terminate", "reset", "get_state", "free"])),))
            elif kind == 1 and fmi == 2:
                calls.append(("setup", float(rng.choice([0.0, 1.5, float("inf"), float("nan")]))))
            elif kind == 2:
                calls.append(("step", float(rng.choice([0.0, 0.005, 0.01, -0.005])),
                              float(rng.choice([0.005, 0.0, -0.005, 0.01]))))
            elif kind in (3, 4):
                calls.append(_coerce(("set", str(rng.choice(NAMES)), specials[rng.integers(len(specials))])))
            elif kind == 5:
                calls.append(("get", str(rng.choice(NAMES))))
            else:
                calls.append((str(rng.choice(["set_state", "serialize", "deserialize"])), int(rng.integers(-1, 3))))
        yield calls


@pytest.mark.sanitize
@pytest.mark.parametrize("fmi", [2, 3])
def test_sanitized_fmu_runs_state_machine_and_fuzz_with_zero_findings(sanitized_fmus, fmi):
    from test_fmu_call_sequences import MODELS
    from test_fmu_compliance import AFTER_INIT, FMI2_ILLEGAL, ILLEGAL, init_calls

    env = _sanitizer_env()
    proc = subprocess.Popen([sys.executable, str(DRIVERS[fmi]), unzipped(sanitized_fmus[fmi])], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1, env=env)

    def send(call):
        proc.stdin.write(json.dumps(list(call)) + "\n")
        line = proc.stdout.readline()
        while line and not line.startswith("{"):
            line = proc.stdout.readline()
        assert line, f"the sanitized FMU process died on {call}:\n{proc.stderr.read()[-4000:]}"
        return json.loads(line)["status"]

    sequences = [([["instantiate"]] + c[1] if c[1] is not AFTER_INIT else init_calls(fmi) + c[2]) + [["free"]]
                 for c in ILLEGAL + (FMI2_ILLEGAL if fmi == 2 else [])]
    sequences += [[["instantiate"]] + [list(c) for c in calls] + [["free"]]
                  for calls in _random_sequences(fmi, np.random.default_rng(2024 + fmi))]
    checked = 0
    for calls in sequences:
        model = MODELS[fmi]()
        for call in calls:
            legal = model.legal(*call)
            if legal is None:
                continue
            status = send(call)
            assert (status == 0) == legal, (fmi, call, status, model.phase)
            if legal:
                model.apply(*call)
            checked += 1
    proc.stdin.close()
    stderr = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and _findings(stderr) == 0, stderr[-4000:]
    run = subprocess.run([sys.executable, str(NATIVE_DIR / "sanitize_run.py"), str(sanitized_fmus[fmi]),
                          str(sanitized_fmus[5 - fmi])], env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and _findings(run.stderr) == 0, run.stderr[-4000:]
    print(f"\nFMI {fmi}.0 sanitized: {checked} calls in {len(sequences)} sequences, {run.stdout.splitlines()[-1]}, "
          f"0 sanitizer findings")
