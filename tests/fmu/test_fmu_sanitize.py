"""The FMI tests under AddressSanitizer + UndefinedBehaviorSanitizer, and the fatal path under valgrind.

    pytest -m sanitize tests/fmu/test_fmu_sanitize.py -s     (a few minutes on 2 cores)

``build.py --sanitize`` compiles the guard with ``-fsanitize=address,undefined
-fno-sanitize-recover=all``; the FMU tests (state machine, state integrity with the
bit flips, hostile host inputs, the hypothesis call-sequence fuzz) then run against that
FMU in a pytest subprocess.  How the Python host is set up, and why:

* ``LD_PRELOAD="libasan.so libstdc++.so.6"``: the interpreter is not instrumented, and
  ASan's runtime must be the first library in the process to intercept malloc/free
  before anything else; libstdc++ must be there when ASan starts too, or ASan cannot
  intercept the C++ exceptions pythonfmu throws (it aborts with "CHECK failed:
  real___cxa_throw").  Every process the tests start (the fmpy driver, the ctypes host,
  the C host) inherits it.
* ``ASAN_OPTIONS=detect_leaks=0``: CPython does not free its interned objects, modules and
  arenas at exit, and pythonfmu keeps its interpreter state until exit (and the guard
  deliberately leaks pythonfmu's instance after a Fatal, see fmi2_guard.c), so
  LeakSanitizer would report thousands of blocks that are not bugs; a suppression broad
  enough to silence CPython would also hide the guard's blocks (every guard call has
  libpython frames on its stack).  Use-after-free, double free, overflows and UB are all
  still detected, and abort the process.
* ``log_path``: each report goes to a file in a folder the test counts: a finding is a
  report file, and the run must leave none.

Valgrind (memcheck) then runs the fatal-error cycles (tests/support/fmi/raw_host.py
``fatal_cycles``) against the normal build: pythonfmu's double free after a Python
exception would show as "Invalid read/free" there.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from support.paths import REPO_ROOT, SUPPORT_DIR

pytestmark = pytest.mark.sanitize

UNDER_SANITIZERS = [
    "tests/fmu/test_fmu_compliance.py", "tests/fmu/test_fmu_call_sequences.py", "tests/fmu/test_fmu_state_integrity.py",
    "tests/fmu/test_fmu_host_inputs.py", "tests/fmu/test_fmu_c_host.py", "tests/fmu/test_fmu_forged_states.py",
]


def _preload():
    """LD_PRELOAD for a Python host of the sanitized guard: libasan, then libstdc++ (pythonfmu is
    C++ and throws; ASan intercepts __cxa_throw only if libstdc++ is loaded when ASan starts)."""
    compiler = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if compiler is None:
        pytest.fail("the sanitize tests need gcc (with libasan); .ci/run installs it")
    paths = [subprocess.run([compiler, f"-print-file-name={lib}"], capture_output=True, text=True).stdout.strip()
             for lib in ("libasan.so", "libstdc++.so.6")]
    missing = [p for p in paths if not Path(p).is_file()]
    if missing:
        pytest.fail(f"{compiler} lacks {missing}: apt-get install gcc (it brings libasan8; see .ci/run)")
    return " ".join(paths)


@pytest.fixture(scope="module")
def asan_fmu(build_module, tmp_path_factory):
    return build_module.build_fmu(tmp_path_factory.mktemp("asan_fmu"), sanitize=True)


def test_fmi_tests_and_fuzz_pass_under_asan_and_ubsan_with_zero_findings(asan_fmu, tmp_path):
    reports = tmp_path / "reports"
    reports.mkdir()
    env = dict(os.environ, AVR_TEST_FMU=str(asan_fmu), LD_PRELOAD=_preload(),
               ASAN_OPTIONS=f"detect_leaks=0:halt_on_error=1:log_path={reports}/asan",
               UBSAN_OPTIONS=f"print_stacktrace=1:halt_on_error=1:log_path={reports}/ubsan")
    # the sha256 test builds a normal FMU to compare with: not meaningful against this one; the native
    # FMUs' own sanitizer run is tests/support/native/test_native_hosts.py
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--basetemp={tmp_path / 'bt'}",
           "-k", "not two_builds_have_the_same_sha256 and not native-fmi", *UNDER_SANITIZERS]
    proc = subprocess.run(cmd, cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=3600)
    findings = sorted(p.name for p in reports.iterdir())
    summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ""
    print(f"\nunder ASan+UBSan: {summary}; sanitizer reports: {len(findings)}")
    assert findings == [], "\n\n".join(p.read_text()[:4000] for p in sorted(reports.iterdir()))
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-3000:]
    assert "passed" in summary and "failed" not in summary and "error" not in summary, summary


def test_bit_flips_under_asan_report_their_counts(asan_fmu, tmp_path, unzip, raw_host, monkeypatch):
    """Every single-bit flip of a real state, with the counts printed (for the record)."""
    reports = tmp_path / "reports"
    reports.mkdir()
    monkeypatch.setenv("LD_PRELOAD", _preload())
    monkeypatch.setenv("ASAN_OPTIONS", f"detect_leaks=0:halt_on_error=1:log_path={reports}/asan")
    monkeypatch.setenv("UBSAN_OPTIONS", f"print_stacktrace=1:halt_on_error=1:log_path={reports}/ubsan")
    fmu_dir = unzip(asan_fmu, tmp_path / "fmu")
    every = raw_host(fmu_dir, "bitflip", {"n_neurons": 10})
    sampled = raw_host(fmu_dir, "bitflip", {"n_neurons": 1000, "count": 10_000, "seed": 7})
    findings = sorted(p.name for p in reports.iterdir())
    print(f"\nbit flips under ASan+UBSan: {every['flips']} (every bit of {every['blob_bytes']} bytes) -> "
          f"{every['statuses']}; {sampled['flips']} random of {sampled['blob_bytes']} bytes -> "
          f"{sampled['statuses']}; sanitizer reports: {len(findings)}")
    assert findings == []
    for result in (every, sampled):
        assert result["statuses"] == {"3": result["flips"]} and result["unchanged"] and result["same_future"]


def invalid_accesses(stderr: str) -> list[str]:
    """memcheck's reports of invalid reads, writes and frees, except the dynamic loader's own.

    CPython and ld.so give memcheck noise on this machine (``python -c "import numpy"``
    alone: 1258 errors, uninitialised values in CPython's GC and 4 invalid strncmp reads
    in ld.so's rpath handling), so the exit code says nothing.  A double free, or a use of
    memory freed by one, shows as an "Invalid read/write/free" outside ld.so (pythonfmu
    freeing the slave's objects twice showed as invalid reads in CPython's GC)."""
    blocks, current = [], []
    for line in stderr.splitlines():
        text = line.split("== ", 1)[1] if line.startswith("==") and "== " in line else ""
        if text.strip():
            current.append(text)
        elif current:
            blocks.append(current)
            current = []
    blocks.append(current)
    return ["\n".join(b) for b in blocks if b and b[0].startswith(("Invalid", "Mismatched"))
            and not any("dl-load.c" in line or "dl-deps.c" in line for line in b[1:6])]


def test_fatal_error_cycles_are_clean_under_valgrind(built_fmu, tmp_path, unzip):
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.fail("the sanitize tests need valgrind (apt-get install valgrind; see .ci/run)")
    from test_fmu_state_integrity import inject_fault

    fmu_dir = inject_fault(unzip(built_fmu, tmp_path / "faulty"))
    env = dict(os.environ, PYTHONMALLOC="malloc")  # valgrind sees every Python allocation
    cmd = [valgrind, "--leak-check=no", "--num-callers=40", sys.executable,
           str(SUPPORT_DIR / "fmi" / "raw_host.py"), fmu_dir, "fatal_cycles"]
    proc = subprocess.run(cmd, input='{"cycles": 3}', env=env, capture_output=True, text=True, timeout=1800)
    invalid = invalid_accesses(proc.stderr)
    print(f"\nvalgrind, 3 fatal-error cycles: exit {proc.returncode}, {len(invalid)} invalid accesses")
    assert proc.returncode == 0 and '"cycles"' in proc.stdout, proc.stderr[-6000:]
    assert invalid == [], "\n\n".join(invalid)[:8000]


# ---- the CommandSource FMU (native C, FMI 2.0 and 3.0) under ASan + UBSan ---------------------------
#: -Wno-error: GCC 12 warns falsely (format-truncation on a checked snprintf) in instrumented code.
NATIVE_SANITIZE = ("-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g",
                   "-Wno-error")


@pytest.fixture(scope="module")
def sanitized_command_sources(build_module, tmp_path_factory, unzip):
    """{FMI version: extracted folder} of both CommandSource FMUs as build.py builds them, their Linux
    library rebuilt from the FMU's own sources/ with the sanitizers."""
    from fmu_src.command_source import build_command_source as cs

    out = {}
    for fmi in (2, 3):
        tmp = tmp_path_factory.mktemp(f"command_source_asan{fmi}")
        folder = Path(unzip(build_module.build_command_source(fmi, tmp), tmp / "unzipped"))
        lib = folder / "binaries" / ("linux64" if fmi == 2 else "x86_64-linux") / "CommandSource.so"
        cs.compile_library(folder / "sources", fmi, "linux", tmp / lib.name, extra_flags=NATIVE_SANITIZE)
        assert b"__asan_report" in (tmp / lib.name).read_bytes()  # instrumented
        shutil.copyfile(tmp / lib.name, lib)
        out[fmi] = folder
    return out


@pytest.mark.parametrize("fmi", [2, 3])
def test_command_source_under_asan_and_ubsan_with_zero_findings(sanitized_command_sources, fmi, tmp_path):
    """Every FMI function in every state (tests/support/fmi/phase_matrix.py), 20 instances playing the
    schedule, every illegal call and a malformed schedule (tests/support/native/sanitize_run.py)."""
    reports = tmp_path / "reports"
    reports.mkdir()
    env = dict(os.environ, LD_PRELOAD=_preload(), ASAN_OPTIONS=f"detect_leaks=0:halt_on_error=1:log_path={reports}/asan",
               UBSAN_OPTIONS=f"print_stacktrace=1:halt_on_error=1:log_path={reports}/ubsan")
    folder = str(sanitized_command_sources[fmi])
    runs = [subprocess.run([sys.executable, str(SUPPORT_DIR / "fmi" / "phase_matrix.py"), folder, str(fmi)],
                           env=env, capture_output=True, text=True, timeout=600),
            subprocess.run([sys.executable, str(SUPPORT_DIR / "native" / "sanitize_run.py"), "--command-source",
                            folder, str(fmi)], env=env, capture_output=True, text=True, timeout=1200)]
    findings = sorted(p.name for p in reports.iterdir())
    print(f"\nCommandSource FMI {fmi}.0 under ASan+UBSan: every function in every state, "
          f"{runs[1].stdout.strip().splitlines()[-1] if runs[1].stdout.strip() else '?'}; "
          f"sanitizer reports: {len(findings)}")
    assert findings == [], "\n\n".join(p.read_text()[:4000] for p in sorted(reports.iterdir()))
    for run in runs:
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
