"""FMI compliance of every regulator FMU build.py really builds (into a temporary folder):
the pythonfmu FMU (FMI 2.0) and the native FMUs (FMI 2.0 and FMI 3.0), each rule written
once and run on each FMU (``regulator_fmu``), plus the checks only one implementation needs.

Calls that could crash run in a subprocess (tests/support/fmi/driver.py, tests/support/native/driver3.py),
so a crash shows as a failed test, not a dead pytest.  FMUs are extracted under tmp_path,
tools are found beside the running interpreter (``venv_tool``).
"""
import hashlib
import json
import math
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu
# Imported here, before any test instantiates the FMU in this process: pythonfmu puts the FMU's
# resources/ (which holds a copy of the pythonfmu package, without its binaries) first on sys.path.
import pythonfmu
from pythonfmu.builder import FmuBuilder

from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS
from fmu_src.packing.archive import ZIP_EPOCH
from support import warm
from support.native_support import DRIVERS, H, AnySlave, fmi2_only, input_sequence

OK, ERROR = 0, 3
SPECS = (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)
PSI_X = [s.name for s in OUTPUT_SPECS].index("psi_x")
#: Where each FMU keeps its binaries (platform folders by FMI version) and its library's suffix.
NATIVE_PLATFORMS = {2: ("linux64", "win64"), 3: ("x86_64-linux", "x86_64-windows")}


def run_calls(fmu, calls):
    """Answers (dicts) to `calls` made in a fresh process on the extracted FMU, and the process's
    stdout (fmpy prints the FMU's log messages there); the process must not die."""
    proc = warm.run(DRIVERS[fmu.fmi], [fmu.dir, json.dumps(calls)], timeout=120)
    assert proc.returncode == 0, f"driver died (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stdout


def statuses(fmu, calls):
    return [r["status"] for r in run_calls(fmu, calls)[0]]


def init_calls(fmi):
    """Instantiate and initialize (FMI 3.0: the start time goes with enterInitializationMode)."""
    return [["instantiate"], ["setup", 0.0], ["enter"], ["exit"]] if fmi == 2 else [["instantiate"], ["enter"], ["exit"]]


def slave(fmu, name="avr") -> AnySlave:
    return AnySlave(fmu.path, name=name, unzip=fmu.dir)


# ---- static checks --------------------------------------------------------------------
def test_fmpy_validation_finds_no_problems(regulator_fmu):
    assert validate_fmu(str(regulator_fmu.path)) == []


def test_fmutool_check_passes(regulator_fmu, venv_tool):
    fmi = regulator_fmu.fmi
    proc = subprocess.run([venv_tool("fmutool"), "-input", str(regulator_fmu.path), "-check"],
                          capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert f"compliant with FMI-{fmi}.0" in out and f"No semantic error against the FMI-{fmi}" in out, out


def test_two_builds_have_the_same_sha256(regulator_fmu, build_module, tmp_path):
    again = regulator_fmu.rebuild(build_module, tmp_path)
    assert hashlib.sha256(again.read_bytes()).hexdigest() == hashlib.sha256(regulator_fmu.path.read_bytes()).hexdigest()


def test_model_description_is_the_variable_table(regulator_fmu):
    md = read_model_description(str(regulator_fmu.path))
    variables = [v for v in md.modelVariables if v.causality != "independent"]
    assert [v.name for v in variables] == [s.name for s in SPECS]  # every declared variable, in declaration order
    assert [v.valueReference for v in variables] == list(range(len(SPECS)))  # the same in every regulator FMU
    for v, spec in zip(variables, SPECS):
        assert (v.causality, v.variability, v.description) == (spec.causality, spec.variability, spec.fmi_description)
        assert (v.min is None) == (spec.min is None) and (v.max is None) == (spec.max is None)
        if spec.min is not None:
            assert float(v.min) == spec.min and float(v.max) == spec.max
        if spec.type == "Boolean":
            assert str(v.start).lower() == str(spec.default).lower()
        else:
            assert float(v.start) == spec.default
    by_name = {v.name: v for v in variables}
    assert {"m/s", "rad", "rad/s"} <= {u.name for u in md.unitDefinitions}
    assert by_name["vx"].unit == "m/s" and by_name["pitch"].unit == "rad" and by_name["roll_rate"].unit == "rad/s"
    assert by_name["delta_swing_knee"].unit == "rad"
    assert by_name["step_index"].variability == "discrete" and by_name["step_index"].type in ("Integer", "Int32")
    assert by_name["n_neurons"].variability == "fixed" and by_name["adaptation_enabled"].variability == "tunable"
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert md.generationDateAndTime is None  # no timestamp: builds are reproducible
    with zipfile.ZipFile(regulator_fmu.path) as z:
        assert all(info.date_time == ZIP_EPOCH for info in z.infolist())
        doc = z.read("documentation/index.html").decode()
    assert all(f"<td>{s.name}</td>" in doc for s in SPECS)


def test_pythonfmu_fmu_ships_its_requirements(built_fmu):
    with zipfile.ZipFile(built_fmu) as z:
        assert z.read("resources/requirements.txt").decode().startswith("numpy")


@pytest.mark.parametrize("fmi", [2, 3])
def test_native_fmu_ships_binaries_and_sources(native_fmus, fmi):
    md = read_model_description(str(native_fmus[fmi]))
    with zipfile.ZipFile(native_fmus[fmi]) as z:
        names = set(z.namelist())
    linux, windows = NATIVE_PLATFORMS[fmi]
    assert {f"binaries/{linux}/AdaptiveVelocityRegulatorNative.so",
            f"binaries/{windows}/AdaptiveVelocityRegulatorNative.dll"} <= names
    assert {"sources/avr_model.c", "sources/avr_vars.h", f"sources/fmi{fmi}Functions.h"} <= names
    if fmi == 3:
        assert "sources/buildDescription.xml" in names
        [time] = [v for v in md.modelVariables if v.causality == "independent"]
        assert (time.name, time.valueReference, time.unit) == ("time", len(SPECS), "s")


def test_module_names_are_unique_to_this_fmu(built_fmu):
    """pythonfmu issue #228: two FMUs whose slave modules share a name collide in one process.  The
    entry module's name carries the hash of the code (tests/fmu/test_fmu_coexistence.py loads builds)."""
    with zipfile.ZipFile(built_fmu) as z:
        assert re.fullmatch(r"avr_slave_[0-9a-f]{16}", z.read("resources/slavemodule.txt").decode())


# ---- the calling sequence (FMI 2.0 section 4.2.4, FMI 3.0 section 4.3) ----------------------
def test_legal_sequence_all_ok(regulator_fmu):
    calls = [["instantiate"], ["set", "Kp_x", 0.3], ["set", "n_neurons", 200], ["setup", 0.0], ["enter"],
             ["set", "vx", 0.4], ["get", "delta_swing_hip_pitch"], ["exit"],
             ["step", 0.0, H], ["set", "Kp_x", 0.2], ["set", "vx", 0.6], ["set", "step_index", 1],
             ["step", H, H], ["get", "psi_x"], ["get_state"], ["serialize", 0], ["deserialize", 0],
             ["set_state", 1], ["step", 2 * H, H], ["terminate"], ["get", "delta_swing_knee"],
             ["reset"], ["setup", 0.0], ["enter"], ["exit"], ["step", 0.0, H], ["terminate"], ["free"]]
    assert statuses(regulator_fmu, calls) == [OK] * len(calls)


AFTER_INIT = None
ILLEGAL = [  # (case, calls after instantiate, or AFTER_INIT and the calls after initialization)
    ("doStep before initialization", [["step", 0.0, H]]),
    ("doStep in initialization mode", [["setup", 0.0], ["enter"], ["step", 0.0, H]]),
    ("exitInitializationMode twice", AFTER_INIT, [["exit"]]),
    ("enterInitializationMode after initialization", AFTER_INIT, [["enter"]]),
    ("set an output", AFTER_INIT, [["set", "delta_swing_hip_pitch", 0.1]]),
    ("set an output before initialization", [["set", "psi_x", 0.1]]),
    ("set a fixed parameter after initialization", AFTER_INIT, [["set", "n_neurons", 10]]),
    ("set the seed after initialization", AFTER_INIT, [["set", "seed", 3]]),
    ("doStep after terminate", AFTER_INIT, [["step", 0.0, H], ["terminate"], ["step", H, H]]),
    ("set after terminate", AFTER_INIT, [["terminate"], ["set", "vx", 0.1]]),
    ("terminate twice", AFTER_INIT, [["terminate"], ["terminate"]]),
    ("zero step size", AFTER_INIT, [["step", 0.0, 0.0]]),
    ("negative step size", AFTER_INIT, [["step", 0.0, -H]]),
    ("step not starting at the current time", AFTER_INIT, [["step", 0.0, H], ["step", 3 * H, H]]),
    ("step starting in the past", AFTER_INIT, [["step", 0.0, H], ["step", 0.0, H]]),
    ("NaN input", AFTER_INIT, [["set", "vx", math.nan]]),
    ("infinite input", AFTER_INIT, [["set", "pitch", math.inf]]),
    ("input above its declared range", AFTER_INIT, [["set", "vx", 1e308]]),
    ("input below its declared range", AFTER_INIT, [["set", "roll_rate", -101.0]]),
    ("negative step_index", AFTER_INIT, [["set", "step_index", -1]]),
    ("parameter above its range", [["set", "psi_limit", 50.0]]),
    ("tunable parameter NaN while stepping", AFTER_INIT, [["set", "Kp_x", math.nan]]),
    ("n_neurons zero", [["set", "n_neurons", 0]]),
    ("garbage serialized state", AFTER_INIT, [["deserialize", -1]]),
    ("get before initialization", [["get", "vx"]]),
]
FMI2_ILLEGAL = [("setupExperiment after initialization", AFTER_INIT, [["setup", 0.0]])]  # no such FMI 3.0 call


def _refused_last(fmu, case):
    """The case's calls all OK but the last, which is refused (Error): the instance survives it."""
    name, calls = case[0], ([["instantiate"]] + case[1] if case[1] is not AFTER_INIT else init_calls(fmu.fmi) + case[2])
    calls = [c for c in calls if not (fmu.fmi == 3 and c[0] == "setup")]  # FMI 3.0: start time goes with enter
    answers = statuses(fmu, calls)
    assert answers[:-1] == [OK] * (len(calls) - 1), name
    assert answers[-1] == ERROR, name


@pytest.mark.parametrize("case", ILLEGAL, ids=[c[0] for c in ILLEGAL])
def test_illegal_call_is_refused_and_instance_survives(regulator_fmu, case):
    _refused_last(regulator_fmu, case)


@fmi2_only
@pytest.mark.parametrize("case", FMI2_ILLEGAL, ids=[c[0] for c in FMI2_ILLEGAL])
def test_illegal_fmi2_call_is_refused_and_instance_survives(regulator_fmu, case):
    _refused_last(regulator_fmu, case)


def test_refused_set_changes_nothing_and_stepping_continues(regulator_fmu):
    init = init_calls(regulator_fmu.fmi)
    calls = init + [["set", "vx", 0.7], ["set", "vx", math.nan], ["get", "vx"], ["step", 0.0, H],
                    ["set", "Kp_x", 99.0], ["get", "Kp_x"], ["step", H, H], ["terminate"], ["free"]]
    answers, _ = run_calls(regulator_fmu, calls)
    n = len(init)
    assert [r["status"] for r in answers] == [OK] * (n + 1) + [ERROR, OK, OK, ERROR, OK, OK, OK, OK]
    assert answers[n + 2]["value"] == 0.7  # the NaN was not applied
    assert answers[n + 5]["value"] == {s.name: s for s in PARAM_SPECS}["Kp_x"].default  # nor the bad gain


def test_refused_calls_log_the_variable_and_its_range(regulator_fmu):
    calls = [["instantiate"], ["set", "psi_limit", 50.0], ["set", "delta_swing_knee", 0.1], ["setup", 0.0],
             ["enter"], ["exit"], ["set", "vx", math.nan], ["set", "vx", 1e308], ["step", 0.0, -1.0],
             ["set", "n_neurons", 20000]]
    _, log = run_calls(regulator_fmu, calls)
    spec = {s.name: s for s in PARAM_SPECS}["psi_limit"]
    assert f"psi_limit = 50: out of range [{spec.min:g}, {spec.max:g}]" in log, log
    assert "delta_swing_knee is an output and cannot be set" in log, log
    assert "vx = nan: must be a finite number in [-10, 10]" in log, log
    assert "vx = 1e+308: out of range [-10, 10]" in log, log
    assert "communicationStepSize = -1: must be a finite number > 0" in log, log
    assert "n_neurons is a fixed parameter" in log, log


def test_wrong_guid_is_refused(regulator_fmu):
    md = read_model_description(str(regulator_fmu.path))
    cls = FMU3Slave if regulator_fmu.fmi == 3 else FMU2Slave
    fmu = cls(guid="{not-the-guid}", unzipDirectory=regulator_fmu.dir,
              modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="nstantiate"):
        fmu.instantiate()


# ---- in-process checks (legal calls only) ------------------------------------------------
def test_reset_returns_the_start_state(regulator_fmu):
    params = {"n_neurons": 300, "learning_rate": 1e-4, "learn_from_step": 0}
    s = slave(regulator_fmu).init(**params)
    seq = input_sequence(50, seed=1)
    first = [s.step(k, u) for k, u in enumerate(seq)]
    s.fmu.terminate()
    s.fmu.reset()
    s.init(**params)
    second = [s.step(k, u) for k, u in enumerate(seq)]
    assert np.array_equal(np.array(first), np.array(second)) and np.any(np.array(first)[:, PSI_X] != 0.0)
    s.close()


def test_state_round_trips_are_bit_exact(regulator_fmu):
    s = slave(regulator_fmu).init(learning_rate=1e-4, learn_from_step=0)  # learns within the 120 calls
    seq = input_sequence(120, seed=2)
    for k, u in enumerate(seq[:60]):
        s.step(k, u)
    state = s.get_state()
    blob = s.serialize(state)
    straight = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    s.set_state(state)  # restore in memory, then continue
    again = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    other = slave(regulator_fmu, name="other").init()  # same fixed parameters (other ones are refused)
    other.set_state(other.deserialize(blob))  # restore the serialized state in a fresh instance
    restored = np.array([other.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    assert np.array_equal(straight, again) and np.array_equal(straight, restored)
    assert np.any(straight[:, PSI_X] != 0.0)  # the state carries learned weights
    assert other.serialize(other.get_state()) == s.serialize(s.get_state())  # same history, same bytes
    assert s.serialize(s.get_state()) != blob  # learning went on
    for each in (s, other):
        each.close()


def test_twenty_instances_in_one_process_are_independent(regulator_fmu):
    params = [{"n_neurons": 200, "seed": i % 2, "learning_rate": 1e-4} for i in range(20)]
    slaves = [slave(regulator_fmu, name=f"i{i}").init(**params[i]) for i in range(20)]
    seqs = [input_sequence(30, seed=100 + i) for i in range(20)]
    interleaved = [[None] * 30 for _ in range(20)]
    for k in range(30):
        for i, s in enumerate(slaves):
            interleaved[i][k] = s.step(k, seqs[i][k])
    for i in (0, 7, 19):  # each equals a run of its own in a fresh instance
        alone = slave(regulator_fmu, name=f"alone{i}").init(**params[i])
        assert np.array_equal(np.array(interleaved[i]), np.array([alone.step(k, u) for k, u in enumerate(seqs[i])]))
        alone.close()
    for s in slaves:
        s.close()


def test_a_state_with_other_fixed_parameters_is_refused_until_they_match(regulator_fmu):
    """A state restores only into an instance with the state's n_neurons and seed (it must never
    bring its own along, silently changing the instance's networks)."""
    from fmpy.fmi1 import FMICallException

    seq = input_sequence(20, seed=4)
    a = slave(regulator_fmu, name="a").init(n_neurons=20, seed=0, learning_rate=1e-3)
    for k, u in enumerate(seq[:10]):
        a.step(k, u)
    blob = a.serialize(a.get_state())
    expected = np.array([a.step(k, u) for k, u in enumerate(seq[10:], start=10)])
    a.close()

    b = slave(regulator_fmu, name="b").init(n_neurons=10, seed=5)
    with pytest.raises(FMICallException):
        b.set_state(b.deserialize(blob))
    b.step(0, seq[0])  # refused, nothing changed: b still steps from its own start
    b.close()

    c = slave(regulator_fmu, name="c").init(n_neurons=20, seed=0)
    c.set_state(c.deserialize(blob))
    np.testing.assert_array_equal([c.step(k, u) for k, u in enumerate(seq[10:], start=10)], expected)
    c.close()


OTHER_SLAVE = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class CounterSlave(Fmi2Slave):
    """A different FMU (its own module name) to load beside the regulator."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.count = 0.0
        self.register_variable(Real("count", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.count += 1.0
        return True
'''


def test_two_different_fmus_in_one_process(fmu_dir, tmp_path, unzip):
    script = tmp_path / "avr_test_counter_slave.py"
    script.write_text(OTHER_SLAVE)
    other_path = FmuBuilder.build_FMU(script, dest=tmp_path)
    md = read_model_description(str(other_path))
    other = FMU2Slave(guid=md.guid, unzipDirectory=unzip(other_path, tmp_path / "counter"),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="counter")
    other.instantiate()
    other.setupExperiment(startTime=0.0)
    other.enterInitializationMode()
    other.exitInitializationMode()
    s = AnySlave(fmu_dir, unzip=fmu_dir).init(n_neurons=100)
    seq = input_sequence(10, seed=5)
    outputs = [s.step(k, u) for k, u in enumerate(seq)]
    for k in range(10):
        other.doStep(k * H, H)
    assert other.getReal([md.modelVariables[0].valueReference]) == [10.0]
    assert np.all(np.isfinite(outputs))
    other.terminate()
    other.freeInstance()
    s.close()


def test_guard_header_matches_model_description(built_fmu):
    root = ET.fromstring(zipfile.ZipFile(built_fmu).read("modelDescription.xml"))
    refs = [int(v.get("valueReference")) for v in root.find("ModelVariables")]
    assert refs == list(range(len(refs)))  # the guard indexes its table by value reference


def test_pythonfmu_exit_use_after_free_is_patched(build_module, built_fmu):
    original = (Path(pythonfmu.__file__).parent / "resources" / "binaries" / "linux64" /
                "libpythonfmu-export.so").read_bytes()
    offset = build_module._elf_symbol_file_offset(original, build_module.EXIT_BUG_SYMBOL)
    patched = build_module.patch_pythonfmu_exit_bug(original)
    assert patched[offset:offset + 5] == build_module.EXIT_BUG_PATCH and len(patched) == len(original)
    assert sum(a != b for a, b in zip(original, patched)) == 1  # one byte: push %rbp -> ret
    assert build_module.patch_pythonfmu_exit_bug(patched) == patched
    with zipfile.ZipFile(built_fmu) as z:
        assert z.read("binaries/linux64/AdaptiveVelocityRegulator_pythonfmu.so") == patched
    broken = original[:offset] + b"\x90" * 5 + original[offset + 5:]
    with pytest.raises(RuntimeError, match="unexpected code"):
        build_module.patch_pythonfmu_exit_bug(broken)
