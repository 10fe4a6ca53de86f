"""FMI 2.0 co-simulation slave ``CassiePlant`` (pythonfmu): the MuJoCo Cassie walker.

A thin translator between FMI calls and the plant's pure core (``plant/fmu_core.py``).
Inside the FMU the core and the plant package travel in ``resources/cassie_plant_lib/``
(``build.py`` copies them with package-relative imports) and are loaded from there under
a module name derived from the resources folder: the host's own ``plant`` package, the
regulator FMU's modules and another copy of this FMU never mix with them (pythonfmu
puts every FMU's ``resources/`` first on ``sys.path``; issue #228 of pythonfmu).

Statuses: the FMU's linux64 library is the FMI guard (``fmu_src/guard/``, built with this
FMU's variable table and ``AVR_STEP_QUANTUM`` = 0.5 ms): calls the state machine forbids,
sets of outputs or of fixed parameters after initialization, NaN/inf or out-of-range
values, communication steps that are not whole multiples of 0.5 ms and corrupt or
foreign serialized states are ``fmi2Error`` without reaching Python.  pythonfmu reports a
Python exception as ``fmi2Fatal`` only, so this slave never raises on bad input: it logs
the problem with status Error and changes nothing, and the guard answers ``fmi2Error``
for any call that logged an error.  That covers what only Python can check: the
``model`` name, the plant's own parameter validation (``Perturbation.problems()``: every
problem at once, each naming its field and range) in ``fmi2ExitInitializationMode``,
which then stays in initialization mode, and the contents of an FMU state.

FMU state: the regulator's blob format (``fmu_src/avr_fmustate.py``: every variable
value, the FMI phase and time, CRC-32) with the walker's exact state (MuJoCo's
integration state, servo gains, controller memory) as its core.  As for the regulator,
a state restores only into an instance with the same fixed parameters.
"""
from __future__ import annotations

import dataclasses
import hashlib
import importlib
import importlib.util
import math
import sys
from pathlib import Path

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

#: The folder in ``resources/`` that holds the plant package and the model files.
LIB_DIR = "cassie_plant_lib"
INSTANTIATED, INITIALIZATION_MODE, STEP_COMPLETE, TERMINATED = (
    "instantiated", "initializationMode", "stepComplete", "terminated")
TIME_MATCH_RTOL = 1e-9
_KINDS = {"Real": (Real, float), "Integer": (Integer, int), "Boolean": (Boolean, bool), "String": (String, str)}


def load_core(resources: str):
    """``plant.fmu_core`` of the copy in ``resources/cassie_plant_lib``, under a private name."""
    root = Path(resources) / LIB_DIR
    name = "_cassie_plant_" + hashlib.sha256(str(root.resolve()).encode()).hexdigest()[:16]
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, root / "__init__.py",
                                                      submodule_search_locations=[str(root)])
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
    return importlib.import_module(name + ".plant.fmu_core")


class CassiePlant(Fmi2Slave):
    """MuJoCo Cassie with its nominal walking controller, started from rest."""

    author = "cassie-avr project"
    description = ("MuJoCo Cassie biped with a nominal HZD-style walking controller (0.5 ms plant step); "
                   "inputs: command, the velocity regulator's joint offsets, a push; outputs: the regulator's "
                   "inputs, telemetry and a fall flag")
    license = "MIT (model files: see resources/cassie_plant_lib/models/*/LICENSE)"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._core = core = load_core(self.resources)
        self._specs = {s.name: s for s in core.SPECS}
        self._values = {s.name: s.default for s in core.SPECS}
        self._phase, self._time_s, self._walker = INSTANTIATED, 0.0, None
        for spec in core.SPECS:
            kind = _KINDS[spec.type][0]
            extra = {} if spec.causality == "input" else {"initial": Fmi2Initial.exact}
            self.register_variable(kind(spec.name, causality=getattr(Fmi2Causality, spec.causality),
                                        variability=getattr(Fmi2Variability, spec.variability),
                                        description=spec.description,
                                        getter=lambda n=spec.name: self._values[n], **extra))
        self._by_vr = [(v.name, self._specs[v.name].type) for v in self.vars.values()]

    def _error(self, message: str) -> None:
        """Log an Error: the guard then answers fmi2Error for the call."""
        self.log(message, Fmi2Status.error)

    # -- variables ---------------------------------------------------------------------
    def _names(self, vrs, kind: str) -> list[str]:
        names = []
        for vr in vrs:
            name, var_type = self._by_vr[vr]
            if var_type != kind:
                raise TypeError(f"valueReference {vr} ({name}) is not a {kind}")
            names.append(name)
        return names

    def _get(self, vrs, kind):
        cast = _KINDS[kind][1]
        return [cast(self._values[n]) for n in self._names(vrs, kind)]

    def get_real(self, vrs):
        return self._get(vrs, "Real")

    def get_integer(self, vrs):
        return self._get(vrs, "Integer")

    def get_boolean(self, vrs):
        return self._get(vrs, "Boolean")

    def get_string(self, vrs):
        return self._get(vrs, "String")

    def _set(self, vrs, values, kind) -> None:
        cast = _KINDS[kind][1]
        for name, value in zip(self._names(vrs, kind), values):
            problem = self.set_problem(name, value)
            if problem:
                self._error(problem)
            else:
                self._values[name] = cast(value)

    def set_real(self, vrs, values):
        self._set(vrs, values, "Real")

    def set_integer(self, vrs, values):
        self._set(vrs, values, "Integer")

    def set_boolean(self, vrs, values):
        self._set(vrs, values, "Boolean")

    def set_string(self, vrs, values):
        self._set(vrs, values, "String")

    def set_problem(self, name: str, value) -> str | None:
        """Why setting ``name`` to ``value`` now is refused, or None (the guard checks the same first)."""
        spec = self._specs[name]
        if spec.causality == "output":
            return f"{name} is an output and cannot be set"
        if self._phase == TERMINATED:
            return f"cannot set {name} after fmi2Terminate"
        if spec.causality == "parameter" and self._phase == STEP_COMPLETE:
            return f"{name} is a fixed parameter: set it before fmi2ExitInitializationMode"
        if name == "model":
            return self._core.model_problem(value)
        if spec.type == "Real" and not math.isfinite(value):
            return f"{name} = {value!r}: must be a finite number in [{spec.min}, {spec.max}]"
        if spec.min is not None and (value < spec.min or value > spec.max):
            return f"{name} = {value!r}: out of range [{spec.min}, {spec.max}]"
        return None

    # -- life cycle --------------------------------------------------------------------
    def _allowed(self, call: str, *phases: str) -> bool:
        if self._phase in phases:
            return True
        self._error(f"{call} is not allowed in state {self._phase} (allowed in: {', '.join(phases)})")
        return False

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if self._allowed("fmi2SetupExperiment", INSTANTIATED):
            self._time_s = float(start_time)

    def enter_initialization_mode(self):
        if self._allowed("fmi2EnterInitializationMode", INSTANTIATED):
            self._phase = INITIALIZATION_MODE

    def exit_initialization_mode(self):
        """Build the walker; on invalid parameters log every problem and stay in initialization mode."""
        if not self._allowed("fmi2ExitInitializationMode", INITIALIZATION_MODE):
            return
        try:
            walker = self._core.start(self._params(), Path(self.resources) / LIB_DIR / "models")
        except Exception as exc:  # noqa: BLE001 - reported as fmi2Error, the instance stays usable
            for problem in getattr(exc, "problems", None) or [str(exc)]:
                self._error(f"fmi2ExitInitializationMode refused: {problem}")
            return
        self._walker = walker
        self._values.update(self._core.outputs(walker))
        self._phase = STEP_COMPLETE

    def _params(self) -> dict:
        return {s.name: self._values[s.name] for s in self._core.PARAM_SPECS}

    def terminate(self):
        if self._allowed("fmi2Terminate", STEP_COMPLETE):
            self._phase = TERMINATED

    def do_step(self, current_time, step_size):
        problem = self._step_problem(current_time, step_size)
        if problem:
            self._error(f"fmi2DoStep refused: {problem}")
            return True  # nothing done; the guard reports the logged error as fmi2Error
        inputs = {n: self._values[n] for n in self._core.INPUT_NAMES}
        try:
            out = self._core.advance(self._walker, inputs, self._core.plant_steps(step_size))
        except Exception as exc:  # noqa: BLE001 - MuJoCo or the controller failed: the step could not be done
            self.log(f"fmi2DoStep could not complete the step at t = {current_time!r} s: {exc!r}", Fmi2Status.discard)
            return False
        if out["fell"] and not self._values["fell"]:
            self.log(f"CassiePlant fell at t = {out['plant_time']:.4f} s: {self._walker.fall_reason}")
        self._values.update(out)
        self._time_s = float(current_time) + float(step_size)
        return True

    def _step_problem(self, current_time, step_size) -> str | None:
        if self._phase != STEP_COMPLETE:
            return f"not allowed in state {self._phase} (allowed in: {STEP_COMPLETE})"
        tolerance = TIME_MATCH_RTOL * max(1.0, abs(self._time_s))
        if not abs(current_time - self._time_s) <= tolerance:
            return (f"currentCommunicationPoint = {current_time!r}: must equal the end of the last step "
                    f"({self._time_s!r})")
        return self._core.step_problem(step_size)

    # -- FMU state ---------------------------------------------------------------------
    def _get_fmu_state(self):
        return self._core.encode_fmu_state(self._values, self._phase, self._time_s, self._walker)

    def _set_fmu_state(self, state):
        try:
            parts, walker = self._restore(bytes(state))
        except Exception as exc:  # noqa: BLE001 - a bad state is refused (fmi2Error), the instance unchanged
            self._error(f"fmi2SetFMUstate refused: {exc}")
            return
        self._values, self._phase, self._time_s, self._walker = parts.values, parts.phase, parts.time_s, walker

    def _restore(self, blob: bytes):
        """The state's parts, checked, and a walker in the saved state (the current one if the state
        carries walker bytes and the instance has one; fixed parameters must equal the instance's)."""
        parts = self._core.decode_fmu_state(blob)
        values = {n: _KINDS[self._specs[n].type][1](v) for n, v in parts.values.items()}
        differ = [f"{n} = {values[n]!r} (this instance: {self._values[n]!r})"
                  for n in self._params() if values[n] != self._values[n]]
        if differ:
            raise ValueError("the state was saved with other fixed parameters: " + ", ".join(differ) +
                             ". Set them to the state's values before restoring it")
        walker = None
        if parts.core:
            walker = self._walker or self._core.start(self._params(), Path(self.resources) / LIB_DIR / "models")
            self._core.state_from_bytes(walker, parts.core)  # all or nothing
        return dataclasses.replace(parts, values=values), walker

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        # The guard has checked the serialized state's CRC-64, GUID, fixed parameters and this blob's
        # header; the contents are checked by _set_fmu_state, which refuses a bad one with fmi2Error.
        return bytes(state)
