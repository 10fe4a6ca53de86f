"""Random FMI call sequences, legal and illegal, against each real regulator FMU in a subprocess.

An independent model of the FMI 2.0 co-simulation state machine (section 4.2.4; for FMI 3.0
the same phases without SetupExperiment), of the FMU's variable table and of its FMU-state
rule (a state is restored only into an instance whose fixed parameters have the values it
was saved with) and of the rules between parameters (``PARAM_REQUIRES``: checked when
initialization ends and on every set while stepping) says which calls are legal.  Property: the process never dies, every legal
call returns OK and no illegal call returns OK.
"""
import json
import math
import os
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS, PARAM_REQUIRES, PARAM_SPECS, requires_problems
from fmu_src.fmi import phase_rules

from support import warm
from support.native_support import DRIVERS, H, REGULATOR_FMUS
from support.paths import SUPPORT_DIR

ERROR = 3

SPECS = {s.name: s for s in (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)}
LIVE = {"instantiated", "initializationMode", "stepComplete", "stepFailed", "terminated"}
FIXED_DEFAULTS = {s.name: s.default for s in PARAM_SPECS if s.variability == "fixed"}
#: The parameters of the rules between parameters, at their defaults.
RULED_DEFAULTS = {name: SPECS[name].default for rule in PARAM_REQUIRES for name in rule}


class FmiModel:
    """What the FMI 2.0 standard and the model description allow, call by call."""

    def __init__(self):
        self.phase = None  # not instantiated
        self.time = 0.0
        self.fixed = dict(FIXED_DEFAULTS)  # current values of the fixed parameters
        self.ruled = dict(RULED_DEFAULTS)  # and of the parameters the rules between parameters read
        self.states = []  # (phase, time, fixed, ruled) per FMUstate index
        self.blobs = []

    def legal(self, op, *args):  # noqa: C901 - one branch per FMI function, as in the standard's table
        p = self.phase
        if op == "instantiate":
            return p is None
        if p is None:
            return None  # not sent: no instance
        if op == "setup":
            return p == "instantiated" and math.isfinite(args[0])
        if op == "enter":
            return p == "instantiated"
        if op == "exit":
            return p == "initializationMode" and not requires_problems(self.ruled)
        if op == "step":
            t, h = args
            return (p == "stepComplete" and math.isfinite(h) and h > 0
                    and abs(t - self.time) <= 1e-9 * max(1.0, abs(self.time)))
        if op == "set":
            name, value = args
            spec = SPECS[name]
            if p not in ("instantiated", "initializationMode", "stepComplete") or spec.causality == "output":
                return False
            if p == "stepComplete" and spec.causality == "parameter" and spec.variability == "fixed":
                return False
            if isinstance(value, float) and not math.isfinite(value):
                return False
            if (spec.min is not None and value < spec.min) or (spec.max is not None and value > spec.max):
                return False
            return not (p == "stepComplete" and name in self.ruled and requires_problems({**self.ruled, name: value}))
        if op == "get":
            return p in ("initializationMode", "stepComplete", "stepFailed", "terminated")
        if op == "terminate":
            return p in ("stepComplete", "stepFailed")
        if op in ("reset", "get_state", "free"):
            return p in LIVE
        if op == "serialize":  # an index the driver has no FMUstate for is not sent
            return (p in LIVE) if 0 <= args[0] < len(self.states) else None
        if op == "set_state":
            if not 0 <= args[0] < len(self.states):
                return None
            return p in LIVE and self.states[args[0]][2] == self.fixed
        if op == "deserialize":  # index -1: garbage bytes, which must be refused
            if args[0] >= len(self.blobs):
                return None
            return p in LIVE and args[0] >= 0 and self.blobs[args[0]][2] == self.fixed
        raise ValueError(op)

    def apply(self, op, *args):
        """Update the model after a call that succeeded."""
        if op == "instantiate":
            self.phase, self.time, self.states, self.blobs = "instantiated", 0.0, [], []
            self.fixed, self.ruled = dict(FIXED_DEFAULTS), dict(RULED_DEFAULTS)
        elif op == "set" and args[0] in self.fixed:
            self.fixed[args[0]] = args[1]
        elif op == "set" and args[0] in self.ruled:
            self.ruled[args[0]] = args[1]
        elif op == "setup":
            self.time = args[0]
        elif op == "enter":
            self.phase = "initializationMode"
        elif op == "exit":
            self.phase = "stepComplete"
        elif op == "step":
            self.time = args[0] + args[1]
        elif op == "terminate":
            self.phase = "terminated"
        elif op == "reset":
            self.phase, self.time, self.fixed, self.ruled = "instantiated", 0.0, dict(FIXED_DEFAULTS), dict(RULED_DEFAULTS)
        elif op == "get_state":
            self.states.append((self.phase, self.time, dict(self.fixed), dict(self.ruled)))
        elif op == "set_state":
            self.phase, self.time, _, ruled = self.states[args[0]]
            self.ruled = dict(ruled)
        elif op == "serialize":
            self.blobs.append(self.states[args[0]])
        elif op == "deserialize":
            self.states.append(self.blobs[args[0]])
        elif op == "free":
            self.phase = None


class Fmi3Model(FmiModel):
    """FMI 3.0 co-simulation without event mode: no SetupExperiment (the start time goes with
    EnterInitializationMode); otherwise the same phases and rules."""

    def legal(self, op, *args):
        if op == "setup":
            return None  # not an FMI 3.0 call: not sent
        return super().legal(op, *args)


MODELS = {2: FmiModel, 3: Fmi3Model}
NAMES = sorted(SPECS)
values = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64), st.integers(-5, 5000),
                   st.sampled_from([0.0, 0.25, 1e-6, 1.0, -1.0]))
calls = st.one_of(
    st.tuples(st.sampled_from(["enter", "exit", "terminate", "reset", "get_state", "free"])),
    st.tuples(st.just("setup"), st.sampled_from([0.0, 0.0, 1.5, math.inf, math.nan])),
    st.tuples(st.just("step"), st.sampled_from([0.0, H, 2 * H, 3 * H, -H]), st.sampled_from([H, 0.0, -H, 0.01])),
    st.tuples(st.just("set"), st.sampled_from(NAMES), values),
    st.tuples(st.just("get"), st.sampled_from(NAMES)),
    st.tuples(st.sampled_from(["set_state", "serialize", "deserialize"]), st.integers(-1, 2)),
)


def _coerce(call):
    """Values of the right FMI type for the variable (an int for Integer, a bool for Boolean)."""
    if call[0] != "set":
        return call
    name, value = call[1], call[2]
    kind = SPECS[name].type
    if kind == "Integer":
        return ("set", name, int(value) if isinstance(value, int) else 3)
    if kind == "Boolean":
        return ("set", name, bool(value == value and value))
    return ("set", name, float(value))


@pytest.fixture(scope="module")
def driver(regulator_fmu):
    """(FMI version, the driver process) on the extracted regulator FMU."""
    proc = subprocess.Popen([sys.executable, str(DRIVERS[regulator_fmu.fmi]), regulator_fmu.dir],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
    yield regulator_fmu.fmi, proc
    proc.stdin.close()
    assert proc.wait(timeout=60) == 0, proc.stderr.read()[-2000:]


def _send(proc, call):
    proc.stdin.write(json.dumps(list(call)) + "\n")
    line = proc.stdout.readline()
    while line and not line.startswith("{"):  # FMU log lines printed by fmpy's default logger
        line = proc.stdout.readline()
    assert line, f"the FMU process died on {call}: exit {proc.poll()}, {proc.stderr.read()[-2000:]}"
    return json.loads(line)


@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(sequence=st.lists(calls, min_size=1, max_size=25))
def test_random_call_sequences_never_crash_and_illegal_calls_are_refused(driver, sequence):
    fmi, proc = driver
    model = MODELS[fmi]()
    for call in [("instantiate",)] + [_coerce(c) for c in sequence] + [("free",)]:
        legal = model.legal(*call)
        if legal is None:
            continue
        answer = _send(proc, call)
        if legal:
            assert answer["status"] == 0, f"FMI {fmi}: legal call {call} answered {answer} in phase {model.phase}"
            model.apply(*call)
        else:
            assert answer["status"] != 0, f"FMI {fmi}: illegal call {call} answered OK in phase {model.phase}"
    assert proc.poll() is None


# ---- every function in every state, against the one table of phase rules ---------------------
#: Functions the FMUs do not provide whatever their state (their model descriptions say so):
#: refused with Error in every state.  The FMU-state functions of an FMU whose model description
#: says canGetAndSetFMUstate="false" join them (_not_provided).
NOT_PROVIDED = {
    2: {"fmi2GetDirectionalDerivative", "fmi2SetRealInputDerivatives", "fmi2GetRealOutputDerivatives",
        "fmi2CancelStep", "fmi2GetStatus", "fmi2GetIntegerStatus", "fmi2GetStringStatus"},
    3: {"fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode", "fmi3GetClock", "fmi3SetClock",
        "fmi3GetNumberOfVariableDependencies", "fmi3GetVariableDependencies", "fmi3GetDirectionalDerivative",
        "fmi3GetAdjointDerivative", "fmi3GetOutputDerivatives", "fmi3EnterEventMode", "fmi3EnterStepMode"},
}
STATE_FUNCTIONS = {2: {"fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate", "fmi2SerializedFMUstateSize",
                       "fmi2SerializeFMUstate", "fmi2DeSerializeFMUstate"},
                   3: {"fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState", "fmi3SerializedFMUStateSize",
                       "fmi3SerializeFMUState", "fmi3DeserializeFMUState"}}
PHASE_MATRIX = SUPPORT_DIR / "fmi" / "phase_matrix.py"
COMMAND_SOURCES = ("command-source-fmi2", "command-source-fmi3")
NATIVE_PLANTS = ("native-plant-fmi2", "native-plant-fmi3")


def _not_provided(fmu_dir, fmi: int) -> set:
    from fmpy import read_model_description

    cs = read_model_description(fmu_dir).coSimulation
    assert not cs.providesDirectionalDerivative and not cs.canInterpolateInputs
    assert not (cs.maxOutputDerivativeOrder or 0)
    return NOT_PROVIDED[fmi] | (set() if cs.canGetAndSetFMUstate else STATE_FUNCTIONS[fmi])


@pytest.fixture(scope="module", params=[*REGULATOR_FMUS, *COMMAND_SOURCES, *NATIVE_PLANTS])
def any_fmu(request, tmp_path_factory, unzip, build_module):
    """(FMI version, extracted folder) of each FMU build.py builds with a C FMI layer: the
    pythonfmu regulator (behind its C guard), the native regulators, the CommandSource FMUs and
    the native CassiePlant FMUs.  (``build_module``: the collection sees that it reads a build,
    whose fixtures it asks for by name.)"""
    kind, fmi = request.param.rsplit("-fmi", 1)
    fmi = int(fmi)
    if kind == "python":
        return fmi, request.getfixturevalue("fmu_dir")
    if os.environ.get("AVR_TEST_FMU"):
        pytest.skip("AVR_TEST_FMU names the one FMU this run tests")
    kinds = {"command-source": "command_sources", "native-plant": "native_plant_fmus"}
    fmu = request.getfixturevalue(kinds.get(kind, "native_fmus"))[fmi]
    return fmi, unzip(fmu, tmp_path_factory.mktemp(request.param) / "unzipped")


def test_every_function_in_every_state_follows_the_phase_rules(any_fmu):
    """Every FMI function the FMU exports, called in every state it can be brought to (real FMU,
    ctypes, its own process): refused for its state exactly where fmu_src/fmi/phase_rules.py's
    table says it is not allowed, never answering OK there, and a function the FMU does not
    provide refused (Error) in every state."""
    fmi, fmu_dir = any_fmu
    proc = warm.run(PHASE_MATRIX, [fmu_dir, fmi], timeout=600)
    assert proc.returncode == 0, f"the host process died (exit {proc.returncode}):\n{proc.stderr[-3000:]}"
    matrix = json.loads(proc.stdout.strip().splitlines()[-1])
    table = phase_rules.FMI2_ALLOWED if fmi == 2 else phase_rules.FMI3_ALLOWED
    not_provided = _not_provided(fmu_dir, fmi)
    assert set(table) <= set(matrix), f"functions of the table the FMU does not export: {set(table) - set(matrix)}"
    wrong = []
    for name, by_state in matrix.items():
        for state, answer in by_state.items():
            if name in not_provided or name not in table:
                if answer["status"] != ERROR:
                    wrong.append(f"{name} in {state}: {answer['status']}, not provided: expected Error")
            elif answer["phase"] != (state not in table[name]):
                wrong.append(f"{name} in {state}: refused for its state {answer['phase']}, the table says allowed "
                             f"{state in table[name]} ({answer['messages']})")
            elif answer["phase"] and answer["status"] != ERROR:
                wrong.append(f"{name} in {state}: refused for its state but answered {answer['status']}")
    assert not wrong, "\n".join(wrong)


# ---- the pythonfmu slaves take their phases from the same table ----------------------------------
SLAVE_CALLS = {"fmi2SetupExperiment": lambda s: s.setup_experiment(0.0),
               "fmi2EnterInitializationMode": lambda s: s.enter_initialization_mode(),
               "fmi2ExitInitializationMode": lambda s: s.exit_initialization_mode(),
               "fmi2Terminate": lambda s: s.terminate(),
               "fmi2DoStep": lambda s: s.do_step(s._time_s, H)}
#: The calls that bring a fresh slave to each of its phases.
SLAVE_ROUTES = {"instantiated": [], "initializationMode": ["fmi2SetupExperiment", "fmi2EnterInitializationMode"],
                "stepComplete": ["fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode"],
                "terminated": ["fmi2SetupExperiment", "fmi2EnterInitializationMode", "fmi2ExitInitializationMode",
                               "fmi2Terminate"]}


def _slave_refuses(call: str, phase: str) -> bool:
    from fmu_src.regulator_fmu.avr_slave import AdaptiveVelocityRegulator, FmiCallError

    slave = AdaptiveVelocityRegulator(instance_name="phases")
    for step in SLAVE_ROUTES[phase]:
        SLAVE_CALLS[step](slave)
    try:
        answer = SLAVE_CALLS[call](slave)
    except FmiCallError as exc:
        assert f"{call} is not allowed in state {phase}" in str(exc)
        return True
    return answer is False  # do_step answers False (and logs why) for a step it does not take


@pytest.mark.parametrize("call", sorted(SLAVE_CALLS))
def test_the_slave_refuses_a_call_exactly_where_the_table_says(call):
    """The regulator slave in process (as on win64, without the C guard): each life-cycle call in
    each of its phases is refused exactly where fmu_src/fmi/phase_rules.py says it is not allowed."""
    for phase in SLAVE_ROUTES:
        assert _slave_refuses(call, phase) == (phase not in phase_rules.FMI2_ALLOWED[call]), phase


def test_the_slave_reads_the_table_not_a_copy(monkeypatch):
    """Change the table and the slave follows: its phase rules are phase_rules.FMI2_ALLOWED itself."""
    assert _slave_refuses("fmi2Terminate", "initializationMode")
    monkeypatch.setitem(phase_rules.FMI2_ALLOWED, "fmi2Terminate",
                        phase_rules.FMI2_ALLOWED["fmi2Terminate"] | {"initializationMode"})
    assert not _slave_refuses("fmi2Terminate", "initializationMode")
