"""Compliance of the native FMUs (FMI 2.0 and FMI 3.0) that build.py really builds.

Each test takes ``fmi`` (2 or 3) and the built FMU; the pythonfmu FMU's suite
(tests/test_fmu_compliance.py) checks the same promises, and both can later be
parametrized together.  Calls that could crash run in a subprocess driver
(tests/fmi/driver.py for FMI 2.0, tests/native/driver3.py for FMI 3.0).
"""
import hashlib
import json
import math
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from fmu_src.avr_core import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS
from native_support import (H, MINGW_OBJDUMP, READELF, fmutool, native_fmus, require, unzipped)  # noqa: F401 (fixture)

DRIVERS = {2: Path(__file__).parent / "fmi" / "driver.py", 3: Path(__file__).parent / "native" / "driver3.py"}
OK, ERROR = 0, 3
SPECS = (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)
FMI = pytest.mark.parametrize("fmi", [2, 3])


def run_calls(fmi, fmu, calls):
    """Answers (dicts) to `calls` made in a fresh process; the process must not die."""
    proc = subprocess.run([sys.executable, str(DRIVERS[fmi]), unzipped(fmu), json.dumps(calls)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, f"driver died (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stdout


def statuses(fmi, fmu, calls):
    return [r["status"] for r in run_calls(fmi, fmu, calls)[0]]


def init(fmi):
    return [["instantiate"], ["setup", 0.0], ["enter"], ["exit"]] if fmi == 2 else \
        [["instantiate"], ["enter"], ["exit"]]


# ---- static checks ---------------------------------------------------------------------------
@FMI
def test_fmpy_validation_finds_no_problems(native_fmus, fmi):
    assert validate_fmu(str(native_fmus[fmi])) == []


@FMI
def test_fmutool_check_passes(native_fmus, fmi):
    proc = subprocess.run([str(fmutool()), "-input", str(native_fmus[fmi]), "-check"], capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert f"compliant with FMI-{fmi}.0" in out and f"No semantic error against the FMI-{fmi}" in out, out


@FMI
def test_two_builds_have_the_same_sha256(native_fmus, build_module, tmp_path, fmi):
    again = build_module.build_native_fmu(fmi, tmp_path)
    assert hashlib.sha256(again.read_bytes()).digest() == hashlib.sha256(native_fmus[fmi].read_bytes()).digest()


@FMI
def test_model_description_is_the_variable_table(native_fmus, fmi):
    md = read_model_description(str(native_fmus[fmi]))
    variables = [v for v in md.modelVariables if v.causality != "independent"]
    assert [v.name for v in variables] == [s.name for s in SPECS]
    assert [v.valueReference for v in variables] == list(range(len(SPECS)))  # as the pythonfmu FMU's
    for v, spec in zip(variables, SPECS):
        assert (v.causality, v.variability, v.description) == (spec.causality, spec.variability, spec.description)
        assert (v.min is None) == (spec.min is None) and (v.max is None) == (spec.max is None)
        if spec.min is not None:
            assert float(v.min) == spec.min and float(v.max) == spec.max
        if spec.type == "Boolean":
            assert v.start in ("true", "false") and (v.start == "true") == spec.default
        else:
            assert float(v.start) == spec.default
    units = {v.name: v.unit for v in variables}
    assert units["vx"] == "m/s" and units["pitch"] == "rad" and units["roll_rate"] == "rad/s"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    if fmi == 3:
        [time] = [v for v in md.modelVariables if v.causality == "independent"]
        assert (time.name, time.valueReference, time.unit) == ("time", len(SPECS), "s")
    with zipfile.ZipFile(native_fmus[fmi]) as z:
        names = set(z.namelist())
        doc = z.read("documentation/index.html").decode()
        assert all(info.date_time == (1980, 1, 1, 0, 0, 0) for info in z.infolist())
    assert all(f"<td>{s.name}</td>" in doc for s in SPECS)
    platforms = ("linux64", "win64") if fmi == 2 else ("x86_64-linux", "x86_64-windows")
    assert {f"binaries/{platforms[0]}/AdaptiveVelocityRegulatorNative.so",
            f"binaries/{platforms[1]}/AdaptiveVelocityRegulatorNative.dll"} <= names
    assert {"sources/avr_model.c", "sources/avr_vars.h", f"sources/fmi{fmi}Functions.h"} <= names
    if fmi == 3:
        assert "sources/buildDescription.xml" in names


@FMI
def test_no_python_in_any_binary(native_fmus, fmi, tmp_path):
    with zipfile.ZipFile(native_fmus[fmi]) as z:
        binaries = {n: z.read(n) for n in z.namelist() if n.startswith("binaries/")}
    for name, data in binaries.items():
        assert b"python" not in data.lower() and b"numpy" not in data.lower(), name
        path = tmp_path / Path(name).name
        path.write_bytes(data)
        if name.endswith(".so"):
            out = subprocess.run([str(require(READELF)), "-d", str(path)], capture_output=True, text=True).stdout
            needed = {line.split("[")[1].rstrip("]") for line in out.splitlines() if "(NEEDED)" in line}
            assert needed <= {"libm.so.6", "libc.so.6"}, needed
        else:
            out = subprocess.run([str(require(MINGW_OBJDUMP)), "-p", str(path)], capture_output=True, text=True).stdout
            dlls = {line.split()[-1].lower() for line in out.splitlines() if "DLL Name:" in line}
            assert dlls <= {"kernel32.dll", "msvcrt.dll"}, dlls


def test_build_all_writes_fmus_json_listing_every_fmu_built(build_module, tmp_path):
    built = build_module.build_all(tmp_path)
    paths = [p for p in built if p.suffix == ".fmu"]
    assert {p.name for p in built} - {p.name for p in paths} == {"CassieAVR.ssp", "CassieAVR_osp"}
    listing = json.loads((tmp_path / "fmus.json").read_text())["fmus"]
    assert [e["file"] for e in listing] == [p.name for p in paths] and all(p.is_file() for p in paths)
    assert [(e["fmiVersion"], e["modelIdentifier"], e["implementation"], e["platforms"]) for e in listing] == [
        ("2.0", "AdaptiveVelocityRegulator", "python", ["linux64", "win64"]),
        ("2.0", "AdaptiveVelocityRegulatorNative", "native", ["linux64", "win64"]),
        ("3.0", "AdaptiveVelocityRegulatorNative", "native", ["x86_64-linux", "x86_64-windows"]),
        ("2.0", "CassiePlant", "python", ["linux64"])]
    assert all(e["sha256"] == hashlib.sha256(p.read_bytes()).hexdigest() for e, p in zip(listing, paths))


# ---- the calling sequence ---------------------------------------------------------------------
@FMI
def test_legal_sequence_all_ok(native_fmus, fmi):
    calls = [["instantiate"], ["set", "Kp_x", 0.3], ["set", "n_neurons", 200], ["setup", 0.0], ["enter"],
             ["set", "vx", 0.4], ["get", "delta_swing_hip_pitch"], ["exit"],
             ["step", 0.0, H], ["set", "Kp_x", 0.2], ["set", "vx", 0.6], ["set", "step_index", 1],
             ["step", H, H], ["get", "psi_x"], ["get_state"], ["serialize", 0], ["deserialize", 0],
             ["set_state", 1], ["step", 2 * H, H], ["terminate"], ["get", "delta_swing_knee"],
             ["reset"], ["setup", 0.0], ["enter"], ["exit"], ["step", 0.0, H], ["terminate"], ["free"]]
    assert statuses(fmi, native_fmus[fmi], calls) == [OK] * len(calls)


ILLEGAL = [  # (case, calls after instantiate (None: after initialization), FMI versions)
    ("doStep before initialization", [["step", 0.0, H]], (2, 3)),
    ("doStep in initialization mode", [["setup", 0.0], ["enter"], ["step", 0.0, H]], (2, 3)),
    ("exitInitializationMode twice", None, (2, 3), [["exit"]]),
    ("setupExperiment after initialization", None, (2,), [["setup", 0.0]]),
    ("enterInitializationMode after initialization", None, (2, 3), [["enter"]]),
    ("set an output", None, (2, 3), [["set", "delta_swing_hip_pitch", 0.1]]),
    ("set an output before initialization", [["set", "psi_x", 0.1]], (2, 3)),
    ("set a fixed parameter after initialization", None, (2, 3), [["set", "n_neurons", 10]]),
    ("set the seed after initialization", None, (2, 3), [["set", "seed", 3]]),
    ("doStep after terminate", None, (2, 3), [["step", 0.0, H], ["terminate"], ["step", H, H]]),
    ("set after terminate", None, (2, 3), [["terminate"], ["set", "vx", 0.1]]),
    ("terminate twice", None, (2, 3), [["terminate"], ["terminate"]]),
    ("zero step size", None, (2, 3), [["step", 0.0, 0.0]]),
    ("negative step size", None, (2, 3), [["step", 0.0, -H]]),
    ("step not starting at the current time", None, (2, 3), [["step", 0.0, H], ["step", 3 * H, H]]),
    ("step starting in the past", None, (2, 3), [["step", 0.0, H], ["step", 0.0, H]]),
    ("NaN input", None, (2, 3), [["set", "vx", math.nan]]),
    ("infinite input", None, (2, 3), [["set", "pitch", math.inf]]),
    ("negative step_index", None, (2, 3), [["set", "step_index", -1]]),
    ("parameter above its range", [["set", "psi_limit", 50.0]], (2, 3)),
    ("tunable parameter NaN while stepping", None, (2, 3), [["set", "Kp_x", math.nan]]),
    ("n_neurons zero", [["set", "n_neurons", 0]], (2, 3)),
    ("garbage serialized state", None, (2, 3), [["deserialize", -1]]),
    ("get before initialization", [["get", "vx"]], (2, 3)),
]
CASES = [pytest.param(fmi, case[0], case, id=f"fmi{fmi}-{case[0]}") for case in ILLEGAL for fmi in case[2]]


@pytest.mark.parametrize("fmi, name, case", CASES)
def test_illegal_call_is_refused_and_instance_survives(native_fmus, fmi, name, case):
    calls = [["instantiate"]] + case[1] if case[1] is not None else init(fmi) + case[3]
    calls = [c for c in calls if not (fmi == 3 and c[0] == "setup")]  # FMI 3.0: start time goes with enter
    answers = statuses(fmi, native_fmus[fmi], calls)
    assert answers[:-1] == [OK] * (len(calls) - 1), name
    assert answers[-1] == ERROR, name


@FMI
def test_refused_set_changes_nothing_and_stepping_continues(native_fmus, fmi):
    calls = init(fmi) + [["set", "vx", 0.7], ["set", "vx", math.nan], ["get", "vx"], ["step", 0.0, H],
                         ["set", "Kp_x", 99.0], ["get", "Kp_x"], ["step", H, H], ["terminate"], ["free"]]
    answers, _ = run_calls(fmi, native_fmus[fmi], calls)
    n = len(init(fmi))
    assert [r["status"] for r in answers] == [OK] * (n + 1) + [ERROR, OK, OK, ERROR, OK, OK, OK, OK]
    assert answers[n + 2]["value"] == 0.7  # the NaN was not applied
    assert answers[n + 5]["value"] == {s.name: s for s in PARAM_SPECS}["Kp_x"].default  # nor the bad gain


@FMI
def test_refused_calls_log_the_variable_and_its_range(native_fmus, fmi):
    calls = [["instantiate"], ["set", "psi_limit", 50.0], ["set", "delta_swing_knee", 0.1], ["enter"], ["exit"],
             ["set", "vx", math.nan], ["step", 0.0, -1.0], ["set", "n_neurons", 20000]]
    _, log = run_calls(fmi, native_fmus[fmi], calls)
    spec = {s.name: s for s in PARAM_SPECS}["psi_limit"]
    assert f"psi_limit = 50: out of range [{spec.min:g}, {spec.max:g}]" in log, log
    assert "delta_swing_knee is an output and cannot be set" in log, log
    assert "vx = nan: must be a finite number" in log, log
    assert "communicationStepSize = -1: must be a finite number > 0" in log, log
    assert "n_neurons is a fixed parameter" in log, log


@FMI
def test_wrong_guid_is_refused(native_fmus, fmi):
    md = read_model_description(str(native_fmus[fmi]))
    cls = FMU3Slave if fmi == 3 else FMU2Slave
    fmu = cls(guid="{not-the-guid}", unzipDirectory=unzipped(native_fmus[fmi]),
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="nstantiate"):
        fmu.instantiate()
