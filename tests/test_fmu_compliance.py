"""FMI 2.0 compliance of the FMU that build.py really builds (into a temporary folder).

Calls that could crash run in a subprocess (tests/fmi/driver.py), so a crash shows
as a failed test, not a dead pytest.  FMUs are extracted under tmp_path (``fmu_dir``,
``unzip``), tools are found beside the running interpreter (``venv_tool``).
"""
import hashlib
import json
import math
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave
from fmpy.validation import validate_fmu
# Imported here, before any test instantiates the FMU in this process: pythonfmu puts the FMU's
# resources/ (which holds a copy of the pythonfmu package, without its binaries) first on sys.path.
import pythonfmu
from pythonfmu.builder import FmuBuilder

from fmu_src.avr_core import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS

DRIVER = Path(__file__).parent / "fmi" / "driver.py"
OK, DISCARD, ERROR, FATAL = 0, 2, 3, 4
H = 0.005  # communication step, s


def run_calls(fmu_dir, calls):
    """Statuses of `calls` made in a fresh process on the extracted FMU; the process must not die."""
    proc = subprocess.run([sys.executable, str(DRIVER), str(fmu_dir), json.dumps(calls)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, f"driver died (exit {proc.returncode}):\n{proc.stderr[-2000:]}"
    return [r["status"] for r in json.loads(proc.stdout.strip().splitlines()[-1])]


INIT = [["instantiate"], ["setup", 0.0], ["enter"], ["exit"]]


# ---- static checks --------------------------------------------------------------------
def test_fmpy_validation_finds_no_problems(built_fmu):
    assert validate_fmu(str(built_fmu)) == []


def test_fmutool_check_passes(built_fmu, venv_tool):
    proc = subprocess.run([venv_tool("fmutool"), "-input", str(built_fmu), "-check"], capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert "compliant with FMI-2.0" in out and "No semantic error" in out, out


def test_two_builds_have_the_same_sha256(built_fmu, build_module, tmp_path):
    again = build_module.build_fmu(tmp_path)
    assert hashlib.sha256(again.read_bytes()).hexdigest() == hashlib.sha256(built_fmu.read_bytes()).hexdigest()


def test_model_description_has_units_ranges_and_content_guid(built_fmu):
    md = read_model_description(str(built_fmu))
    units = {u.name for u in md.unitDefinitions}
    assert {"m/s", "rad", "rad/s"} <= units
    by_name = {v.name: v for v in md.modelVariables}
    assert by_name["vx"].unit == "m/s" and by_name["pitch"].unit == "rad" and by_name["roll_rate"].unit == "rad/s"
    assert by_name["delta_swing_knee"].unit == "rad"
    assert by_name["step_index"].type == "Integer" and by_name["step_index"].variability == "discrete"
    assert by_name["n_neurons"].variability == "fixed" and by_name["adaptation_enabled"].variability == "tunable"
    for spec in (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS):  # every declared variable, in declaration order
        var = by_name[spec.name]
        assert var.causality == spec.causality
        if spec.min is not None:
            assert float(var.min) == spec.min
    assert [v.name for v in md.modelVariables] == [s.name for s in (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)]
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert md.generationDateAndTime is None  # no timestamp: builds are reproducible
    with zipfile.ZipFile(built_fmu) as z:
        names = set(z.namelist())
        assert "documentation/index.html" in names
        assert z.read("resources/requirements.txt").decode().startswith("numpy")
        assert all(info.date_time == (1980, 1, 1, 0, 0, 0) for info in z.infolist())
        doc = z.read("documentation/index.html").decode()
    for spec in PARAM_SPECS:
        assert f"<td>{spec.name}</td>" in doc


def test_module_names_are_unique_to_this_fmu(built_fmu):
    """pythonfmu issue #228: two FMUs whose slave modules share a name collide in one process."""
    with zipfile.ZipFile(built_fmu) as z:
        assert z.read("resources/slavemodule.txt").decode() == "avr_slave"


# ---- the calling sequence (FMI 2.0 section 4.2.4) ------------------------------------------
def test_legal_sequence_all_ok(fmu_dir):
    calls = [["instantiate"], ["set", "Kp_x", 0.3], ["set", "n_neurons", 200], ["setup", 0.0], ["enter"],
             ["set", "vx", 0.4], ["get", "delta_swing_hip_pitch"], ["exit"],
             ["step", 0.0, H], ["set", "Kp_x", 0.2], ["set", "vx", 0.6], ["set", "step_index", 1],
             ["step", H, H], ["get", "psi_x"], ["get_state"], ["serialize", 0], ["deserialize", 0],
             ["set_state", 1], ["step", 2 * H, H], ["terminate"], ["get", "delta_swing_knee"],
             ["reset"], ["setup", 0.0], ["enter"], ["exit"], ["step", 0.0, H], ["terminate"], ["free"]]
    assert run_calls(fmu_dir, calls) == [OK] * len(calls)


@pytest.mark.parametrize("case, calls, expected", [
    ("doStep before initialization", [["instantiate"], ["step", 0.0, H]], ERROR),
    ("doStep in initialization mode", [["instantiate"], ["setup", 0.0], ["enter"], ["step", 0.0, H]], ERROR),
    ("exitInitializationMode twice", INIT + [["exit"]], ERROR),
    ("setupExperiment after initialization", INIT + [["setup", 0.0]], ERROR),
    ("set an output", INIT + [["set", "delta_swing_hip_pitch", 0.1]], ERROR),
    ("set an output before initialization", [["instantiate"], ["set", "psi_x", 0.1]], ERROR),
    ("set a fixed parameter after initialization", INIT + [["set", "n_neurons", 10]], ERROR),
    ("set the seed after initialization", INIT + [["set", "seed", 3]], ERROR),
    ("doStep after terminate", INIT + [["step", 0.0, H], ["terminate"], ["step", H, H]], ERROR),
    ("set after terminate", INIT + [["terminate"], ["set", "vx", 0.1]], ERROR),
    ("terminate twice", INIT + [["terminate"], ["terminate"]], ERROR),
    ("zero step size", INIT + [["step", 0.0, 0.0]], ERROR),
    ("negative step size", INIT + [["step", 0.0, -H]], ERROR),
    ("step not starting at the current time", INIT + [["step", 0.0, H], ["step", 3 * H, H]], ERROR),
    ("step starting in the past", INIT + [["step", 0.0, H], ["step", 0.0, H]], ERROR),
    ("NaN input", INIT + [["set", "vx", math.nan]], ERROR),
    ("infinite input", INIT + [["set", "pitch", math.inf]], ERROR),
    ("input above its declared range", INIT + [["set", "vx", 1e308]], ERROR),
    ("input below its declared range", INIT + [["set", "roll_rate", -101.0]], ERROR),
    ("negative step_index", INIT + [["set", "step_index", -1]], ERROR),
    ("parameter above its range", [["instantiate"], ["set", "psi_limit", 50.0]], ERROR),
    ("tunable parameter NaN while stepping", INIT + [["set", "Kp_x", math.nan]], ERROR),
    ("n_neurons zero", [["instantiate"], ["set", "n_neurons", 0]], ERROR),
    ("garbage serialized state", INIT + [["deserialize", -1]], ERROR),
    ("get before initialization", [["instantiate"], ["get", "vx"]], ERROR),
])
def test_illegal_call_is_refused_and_instance_survives(fmu_dir, case, calls, expected):
    # After the refused call the instance must still work: a legal step from where it was.
    statuses = run_calls(fmu_dir, calls)
    assert statuses[:-1] == [OK] * (len(calls) - 1), case
    assert statuses[-1] == expected, case


def test_refused_set_changes_nothing_and_stepping_continues(fmu_dir):
    calls = INIT + [["set", "vx", 0.7], ["set", "vx", math.nan], ["get", "vx"], ["step", 0.0, H],
                    ["set", "Kp_x", 99.0], ["get", "Kp_x"], ["step", H, H], ["terminate"], ["free"]]
    proc = subprocess.run([sys.executable, str(DRIVER), fmu_dir, json.dumps(calls)], capture_output=True,
                          text=True, timeout=120)
    results = json.loads(proc.stdout.strip().splitlines()[-1])
    assert [r["status"] for r in results] == [OK] * 5 + [ERROR, OK, OK, ERROR, OK, OK, OK, OK]
    assert results[6]["value"] == 0.7  # the NaN was not applied
    assert results[9]["value"] == {s.name: s for s in PARAM_SPECS}["Kp_x"].default  # nor the bad gain


# ---- in-process checks (legal calls only) ------------------------------------------------
class Slave:
    """A thin helper around fmpy's FMU2Slave with names instead of value references."""

    def __init__(self, fmu_dir, name="avr"):
        self.md = read_model_description(str(fmu_dir))
        self.unzip = str(fmu_dir)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=False)

    def init(self, **params):
        for name, value in params.items():
            self.set(name, value)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def set(self, name, value):
        vr = [self.vr[name]]
        if isinstance(value, bool):
            self.fmu.setBoolean(vr, [value])
        elif isinstance(value, int):
            self.fmu.setInteger(vr, [value])
        else:
            self.fmu.setReal(vr, [value])

    def step(self, k, inputs):
        for name, value in inputs.items():
            self.set(name, value)
        self.fmu.doStep(k * H, H)
        return np.array(self.fmu.getReal([self.vr[s.name] for s in OUTPUT_SPECS]))


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


def test_reset_returns_the_start_state(fmu_dir):
    s = Slave(fmu_dir).init(n_neurons=300)
    seq = input_sequence(50, seed=1)
    first = [s.step(k, u) for k, u in enumerate(seq)]
    s.fmu.terminate()
    s.fmu.reset()
    s.init(n_neurons=300)
    second = [s.step(k, u) for k, u in enumerate(seq)]
    assert np.array_equal(np.array(first), np.array(second))
    s.fmu.terminate()
    s.fmu.freeInstance()


def test_state_round_trips_are_bit_exact(fmu_dir):
    s = Slave(fmu_dir).init()
    seq = input_sequence(120, seed=2)
    for k, u in enumerate(seq[:60]):
        s.step(k, u)
    state = s.fmu.getFMUstate()
    blob = s.fmu.serializeFMUstate(state)
    straight = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    s.fmu.setFMUstate(state)  # restore in memory, then continue
    again = np.array([s.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    other = Slave(fmu_dir, name="other").init()  # restore the serialized state in a fresh instance
    other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    restored = np.array([other.step(k, u) for k, u in enumerate(seq[60:], start=60)])
    assert np.array_equal(straight, again) and np.array_equal(straight, restored)
    assert np.any(straight[:, [i for i, o in enumerate(OUTPUT_SPECS) if o.name == "psi_x"][0]] != 0.0)
    assert bytes(s.fmu.serializeFMUstate(s.fmu.getFMUstate())) != bytes(blob)  # learning went on
    for slave in (s, other):
        slave.fmu.terminate()
        slave.fmu.freeInstance()


def test_twenty_instances_in_one_process_are_independent(fmu_dir):
    slaves = [Slave(fmu_dir, name=f"i{i}").init(n_neurons=200, seed=i % 2) for i in range(20)]
    seqs = [input_sequence(30, seed=100 + i) for i in range(20)]
    interleaved = [[None] * 30 for _ in range(20)]
    for k in range(30):
        for i, s in enumerate(slaves):
            interleaved[i][k] = s.step(k, seqs[i][k])
    for i in (0, 7, 19):  # each equals a run of its own in a fresh instance
        alone = Slave(fmu_dir, name=f"alone{i}").init(n_neurons=200, seed=i % 2)
        assert np.array_equal(np.array(interleaved[i]), np.array([alone.step(k, u) for k, u in enumerate(seqs[i])]))
        alone.fmu.freeInstance()
    for s in slaves:
        s.fmu.terminate()
        s.fmu.freeInstance()


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
    s = Slave(fmu_dir).init(n_neurons=100)
    seq = input_sequence(10, seed=5)
    outputs = [s.step(k, u) for k, u in enumerate(seq)]
    for k in range(10):
        other.doStep(k * H, H)
    assert other.getReal([md.modelVariables[0].valueReference]) == [10.0]
    assert np.all(np.isfinite(outputs))
    for fmu in (other, s.fmu):
        fmu.terminate()
        fmu.freeInstance()


def test_refused_calls_log_the_variable_and_its_range(fmu_dir):
    # fmpy's default logger prints FMU messages to stdout; the driver's JSON is the last line.
    calls = [["instantiate"], ["set", "psi_limit", 50.0], ["set", "delta_swing_knee", 0.1], ["setup", 0.0],
             ["enter"], ["exit"], ["set", "vx", math.nan], ["set", "vx", 1e308], ["step", 0.0, -1.0]]
    proc = subprocess.run([sys.executable, str(DRIVER), fmu_dir, json.dumps(calls)], capture_output=True,
                          text=True, timeout=120)
    log = proc.stdout
    spec = {s.name: s for s in PARAM_SPECS}["psi_limit"]
    assert f"psi_limit = 50: out of range [{spec.min:g}, {spec.max:g}]" in log, log
    assert "delta_swing_knee is an output and cannot be set" in log, log
    assert "vx = nan: must be a finite number in [-10, 10]" in log, log
    assert "vx = 1e+308: out of range [-10, 10]" in log, log
    assert "communicationStepSize = -1: must be a finite number > 0" in log, log


def test_guard_refuses_a_wrong_guid(fmu_dir):
    md = read_model_description(fmu_dir)
    fmu = FMU2Slave(guid="{not-the-guid}", unzipDirectory=fmu_dir,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bad")
    with pytest.raises(Exception, match="instantiate"):
        fmu.instantiate()


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
