"""The FMU tests on a bare machine: no project tool on PATH, nothing left in the temp folder.

A representative subset of the FMU tests (build, fmpy and fmutool checks, every importer,
the C host, hostile host inputs, the fatal-error path; on every regulator FMU) runs in a
fresh pytest process with

* ``PATH=/usr/bin:/bin`` only, as ``.ci/run`` gives it on a fresh machine: the tools the
  tests run (fmutool, fmucontainer) must be found beside the interpreter, not on PATH;
* ``TMPDIR`` pointing at an empty folder, and pytest's own ``--basetemp`` elsewhere: any
  file or folder left in TMPDIR afterwards is litter (an FMU extracted with fmpy's default
  ``extract()``, a build folder not removed, ...).
"""
import os
import subprocess
import sys

from plant.model import menagerie_root
from support.paths import REPO_ROOT

SUBSET = [
    "tests/fmu/test_fmu_compliance.py::test_fmpy_validation_finds_no_problems",
    "tests/fmu/test_fmu_compliance.py::test_fmutool_check_passes",
    "tests/fmu/test_fmu_compliance.py::test_legal_sequence_all_ok",
    "tests/fmu/test_fmu_compliance.py::test_state_round_trips_are_bit_exact",
    "tests/fmu/test_fmu_compliance.py::test_two_different_fmus_in_one_process",
    "tests/fmu/test_fmu_compliance.py::test_wrong_guid_is_refused",
    "tests/fmu/test_fmu_importers.py",
    "tests/fmu/test_fmu_c_host.py",
    "tests/fmu/test_fmu_host_inputs.py::test_set_debug_logging_refuses_null_non_utf8_and_unknown_categories",
    "tests/fmu/test_fmu_state_integrity.py::test_after_a_fatal_error_nothing_reaches_pythonfmu_and_free_is_safe",
]


def test_fmu_tests_pass_without_path_and_leave_the_temp_folder_empty(tmp_path):
    tmpdir, basetemp = tmp_path / "tmpdir", tmp_path / "basetemp"
    tmpdir.mkdir()
    env = {"PATH": "/usr/bin:/bin", "HOME": os.environ.get("HOME", str(tmp_path)), "TMPDIR": str(tmpdir)}
    root = menagerie_root()  # the model loader's default when MENAGERIE_ROOT is unset
    if root is not None:
        env["MENAGERIE_ROOT"] = str(root.resolve())
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--basetemp={basetemp}",
                           *SUBSET], cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert " passed" in proc.stdout and "skipped" not in proc.stdout, proc.stdout[-2000:]
    litter = sorted(str(p.relative_to(tmpdir)) for p in tmpdir.iterdir())
    assert litter == [], f"left in TMPDIR: {litter}"
