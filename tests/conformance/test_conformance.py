"""The FMI conformance check (``python -m fmu_src.fmi.conformance``, ``fmu_src/fmi/conformance/``)
held against the real FMUs both ways: every FMU build.py builds passes every check, and each FMU
of a corpus broken on purpose (the native FMI 2.0 regulator with one source line changed and
recompiled, or its model description edited) fails exactly the check aimed at it, the checker
surviving the crash and the hang it causes.

The command runs in a process of its own, as users run it; ``TMPDIR`` points into ``tmp_path``,
so the archives it extracts never reach the system temp folder.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from lxml import etree

from fmu_src.fmi.conformance.checks import CHECKS
from fmu_src.regulator_fmu.native.build_native import MODEL_IDENTIFIER, compile_native

#: What build_all builds that the checker takes: every FMU in dist/.
DIST_FMUS = ("AdaptiveVelocityRegulator.fmu", "AdaptiveVelocityRegulatorNative_fmi2.fmu",
             "AdaptiveVelocityRegulatorNative_fmi3.fmu", "CassiePlant.fmu", "CassiePlantNative_fmi2.fmu",
             "CassiePlantNative_fmi3.fmu", "CommandSource_fmi2.fmu", "CommandSource_fmi3.fmu")
#: Fewer instantiate/free cycles than the default 20 in the default run (the plant FMU's instances
#: load MuJoCo); the per-cycle bound is the same.
FAST = ("--cycles", "10")


def conformance(tmp_path: Path, *args, timeout=600) -> subprocess.CompletedProcess:
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    return subprocess.run([sys.executable, "-m", "fmu_src.fmi.conformance", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env=env)


def checked(tmp_path: Path, fmu, *args) -> tuple[subprocess.CompletedProcess, dict]:
    out = tmp_path / f"{Path(fmu).name}.json"
    proc = conformance(tmp_path, fmu, "--json", out, *FAST, *args)
    assert out.is_file(), proc.stderr[-2000:]
    return proc, json.loads(out.read_text())


def failed(report: dict) -> dict:
    return {c["id"]: c["message"] for c in report["checks"] if c["status"] == "fail"}


# ---- bad input: exit 2 with one clear line ---------------------------------------------------------
def test_bad_input_exits_2_with_one_line(tmp_path):
    not_zip = tmp_path / "a.fmu"
    not_zip.write_text("text")
    no_md = tmp_path / "b.fmu"
    with zipfile.ZipFile(no_md, "w") as z:
        z.writestr("readme.txt", "x")
    cases = {tmp_path / "missing.fmu": "no such file", not_zip: "not a ZIP archive",
             no_md: "no modelDescription.xml"}
    for path, words in cases.items():
        proc = conformance(tmp_path, path)
        assert proc.returncode == 2 and proc.stdout == "", proc
        assert len(proc.stderr.strip().splitlines()) == 1 and words in proc.stderr, proc.stderr


def test_fmu_without_a_binary_for_this_platform_exits_2(tmp_path, built_all):
    folder = tmp_path / "fmu"
    with zipfile.ZipFile(built_all.dist / "CommandSource_fmi2.fmu") as z:
        z.extractall(folder)
    shutil.rmtree(folder / "binaries" / "linux64")
    proc = conformance(tmp_path, folder)
    assert proc.returncode == 2 and "no binary for this platform: binaries/linux64/CommandSource.so" in proc.stderr


def test_bad_options_exit_2_naming_every_problem_at_once(tmp_path):
    proc = conformance(tmp_path, tmp_path / "x.fmu", "--timeout", "0", "--steps", "2", "--only", "bogus")
    assert proc.returncode == 2
    line = proc.stderr.strip()
    assert len(line.splitlines()) == 1
    for words in ("--timeout 0: allowed range [1, 86400]", "--steps 2: allowed range [3, 100000]",
                  "--only bogus: no such check or group"):
        assert words in line, line


# ---- every FMU build.py builds passes ----------------------------------------------------------
@pytest.mark.parametrize("name", DIST_FMUS)
def test_every_built_fmu_passes_every_check(tmp_path, built_all, name):
    junit = tmp_path / "junit.xml"
    proc, report = checked(tmp_path, built_all.dist / name, "--report", junit)
    assert proc.returncode == 0 and report["passed"], proc.stdout
    assert failed(report) == {}
    assert [c["id"] for c in report["checks"]] == [c.id for c in CHECKS]
    ran = {c["id"] for c in report["checks"] if c["status"] == "pass"}
    assert {"machine.legal_calls", "machine.illegal_calls", "lifecycle.memory", "arguments.null_callbacks"} <= ran
    if "CommandSource" not in name:  # the one FMU without FMU state (canGetAndSetFMUstate false)
        assert {"state.restore", "state.serialize", "state.tampered"} <= ran
    # the text report: one line per check, then the counts
    lines = proc.stdout.splitlines()
    assert len(lines) == len(CHECKS) + 2 and all(re.match(r"(PASS|SKIP)  \S+ +\[FMI [23]\.0", x) for x in lines[1:-1])
    suite = etree.parse(str(junit)).getroot()
    assert suite.tag == "testsuite" and suite.get("tests") == str(len(CHECKS)) and suite.get("failures") == "0"


# ---- the broken corpus: each fails exactly its check --------------------------------------------
def _patched(tmp_path, dist: Path, source: str | None = None, edits=(), xml=None) -> Path:
    """The native FMI 2.0 regulator extracted into tmp_path, with each (old, new) of ``edits``
    applied to ``sources/<source>`` (old must be there exactly once) and the linux64 binary
    recompiled from the sources, or with ``xml(text)`` applied to its model description."""
    folder = tmp_path / "broken"
    with zipfile.ZipFile(dist / "AdaptiveVelocityRegulatorNative_fmi2.fmu") as z:
        z.extractall(folder)
    if source is not None:
        path = folder / "sources" / source
        text = path.read_text()
        for old, new in edits:
            assert text.count(old) == 1, f"{old!r} not once in {source}"
            text = text.replace(old, new)
        path.write_text(text)
        build = tmp_path / "build"
        shutil.copytree(folder / "sources", build)
        compile_native(build, 2, "linux", folder / "binaries" / "linux64" / f"{MODEL_IDENTIFIER}.so")
    if xml is not None:
        md = folder / "modelDescription.xml"
        md.write_text(xml(md.read_text()))
    return folder


def _first_output_removed(text: str) -> str:
    outputs = re.search(r"<Outputs>\s*(<Unknown [^>]*/>)", text)
    return text.replace(outputs.group(1), "", 1)


CORPUS = {
    # fmi2Terminate allowed in the instantiated state too
    "phase rule removed": (dict(source="fmi_phase_rules.h", edits=[("#define FMI_MASK_fmi2Terminate (",
                                                                   "#define FMI_MASK_fmi2Terminate (FMI_INSTANTIATED | ")]),
                           "machine.illegal_calls", "fmi2Terminate"),
    # the CRC-64 of serialized states no longer compared
    "state check disabled": (dict(source="fmi_blob.c", edits=[("if (crc != get_le(p + body, f->crc_bytes)) {",
                                                              "if (crc != get_le(p + body, f->crc_bytes) && 0) {")]),
                             "state.tampered", "accepted"),
    # fmi2Instantiate copies *functions without looking: a segfault on NULL
    "crash on a NULL callback struct": (dict(source="fmi2_common.c",
                                             edits=[("if (functions == NULL) return NULL;", "")]),
                                        "arguments.null_callbacks", "killed by signal SIGSEGV in fmi2Instantiate("),
    # a negative communication step waits forever (for a signal that never comes)
    "hang on a negative step": (dict(source="fmi2_common.c", edits=[
        ("#include <stdlib.h>\n", "#include <stdlib.h>\n#include <unistd.h>\n"),
        ("BEGIN(fmi2DoStep)\n", "BEGIN(fmi2DoStep)\n    while (communicationStepSize < 0) pause();\n")]),
                                "arguments.step_size", "no answer within the time limit"),
    "output missing from ModelStructure": (dict(xml=_first_output_removed), "static.model_structure",
                                           "is not listed in Outputs"),
    "start outside min/max": (dict(xml=lambda t: t.replace('start="0.1" min="-5.0" max="5.0"',
                                                           'start="7.5" min="-5.0" max="5.0"', 1)),
                              "static.start_range", "Kp_x: start 7.5 is outside [-5, 5]"),
}


@pytest.mark.parametrize("case", CORPUS)
def test_each_broken_fmu_fails_exactly_its_check(tmp_path, built_all, case):
    patch, check, words = CORPUS[case]
    folder = _patched(tmp_path, built_all.dist, **patch)
    # a time limit far above a group's time (every group of a check takes ~1.1 s together here),
    # short enough for the hang to cost little
    proc, report = checked(tmp_path, folder, "--timeout", "4")
    assert proc.returncode == 1, proc.stdout
    assert list(failed(report)) == [check], proc.stdout
    assert words in failed(report)[check], failed(report)[check]
    # the rest of the group ran after the crash or hang (in a new process) and passed
    group = [c["status"] for c in report["checks"] if c["id"].split(".")[0] == check.split(".")[0]]
    assert group.count("fail") == 1 and "skip" not in group
