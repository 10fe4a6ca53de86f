"""What the project's two pythonfmu slaves share: variables from ``VarSpec`` tables, fast typed
get/set, the FMI 2.0 co-simulation phases and the checks every call makes.

:class:`SpecSlave` declares one FMI variable per ``VarSpec`` (the order of the table is
the value-reference order), keeps every value in ``self._values`` and gives the
get/set functions (one table lookup per value reference: pythonfmu's generic versions
call one closure per variable, and the FMI overhead is most of a regulator step), the
legality of a set (:meth:`SpecSlave.set_problem`, the same rules as the C guard), the
life-cycle calls common to both FMUs and the checks of a doStep's time and step size.
A subclass decides what a refusal does (:meth:`SpecSlave._refuse`): the regulator
raises, the plant only logs (the guard answers fmi2Error for a call that logged an
error).  Each FMU carries its own copy, in the package it imports under a private name.
"""
from __future__ import annotations

import math
import sys

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from fmu_src.core.avr_errors import StateError
from fmu_src.core.avr_specs import PYTHON_TYPES
from fmu_src.fmi.avr_fmustate import PHASES, value_problem
from fmu_src.fmi.phase_rules import FMI2_ALLOWED

#: FMI 2.0 co-simulation phases the slaves track (section 4.2.4; no stepFailed: a refused
#: doStep changes nothing).  Which call is allowed in which is fmu_src/fmi/phase_rules.py's table.
INSTANTIATED, INITIALIZATION_MODE, STEP_COMPLETE, TERMINATED = PHASES
#: The phases a variable may be set in (the same for every type).
_SET_PHASES = FMI2_ALLOWED["fmi2SetReal"]
#: Relative tolerance on "doStep starts where the last step ended": a master that
#: computes t = t0 + k*h differs from (t_prev + h) by a few ulp, far below 1e-9 s.
TIME_MATCH_RTOL = 1e-9

_VARIABLE_CLASSES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CASTS = {**PYTHON_TYPES, "String": str}
_LARGEST = sys.float_info.max


class SpecSlave(Fmi2Slave):
    """A pythonfmu slave whose variables are declared by a ``VarSpec`` table.

    Call :meth:`_init_variables` from ``__init__``.  Subclasses may override
    :meth:`_refuse` (what a refused call does), :meth:`_store` (what setting a value
    also changes) and :meth:`_value_problem` (extra rules for a value).
    """

    def _init_variables(self, specs) -> None:
        self._specs = {spec.name: spec for spec in specs}
        self._values = {spec.name: spec.default for spec in specs}
        self._phase, self._time_s = INSTANTIATED, 0.0
        for spec in specs:
            self.register_variable(self._declare(spec))
        #: value reference -> (name, type) for the fast get/set paths
        self._by_vr = [(var.name, self._specs[var.name].type) for var in self.vars.values()]
        #: value reference -> (name, min, max) of each Real input, for :meth:`set_real`'s fast
        #: path: for a float, ``min <= value <= max`` is exactly :func:`value_problem`'s rule
        #: (the largest finite doubles where the table has no bound, so inf and nan fail).
        #: Empty when a subclass adds rules of its own (:meth:`_value_problem`): every value
        #: then takes the checking path.
        own_rules = type(self)._value_problem is not SpecSlave._value_problem
        self._real_inputs = {} if own_rules else {
            vr: (name, -_LARGEST if spec.min is None else spec.min, _LARGEST if spec.max is None else spec.max)
            for vr, (name, var_type) in enumerate(self._by_vr)
            for spec in [self._specs[name]] if var_type == "Real" and spec.causality == "input"}

    def _declare(self, spec):
        extra = {} if spec.causality == "input" else {"initial": Fmi2Initial.exact}  # FMI: no `initial` on inputs
        return _VARIABLE_CLASSES[spec.type](
            spec.name, causality=getattr(Fmi2Causality, spec.causality),
            variability=getattr(Fmi2Variability, spec.variability), description=spec.fmi_description,
            getter=lambda name=spec.name: self._values[name], **extra)

    def _refuse(self, message: str) -> None:
        """A refused call: logged with status Error (the guard then answers fmi2Error)."""
        self.log(message, Fmi2Status.error)

    # -- getting and setting variables ---------------------------------------------------
    def _names(self, vrs, kind: str) -> list[str]:
        by_vr, names = self._by_vr, []
        for vr in vrs:
            name, var_type = by_vr[vr]
            if var_type != kind:
                raise TypeError(f"Variable with valueReference={vr} ({name}) is not of type {kind}")
            names.append(name)
        return names

    def _get(self, vrs, kind: str) -> list:
        values, cast = self._values, _CASTS[kind]
        return [cast(values[name]) for name in self._names(vrs, kind)]

    def get_real(self, vrs):
        return self._get(vrs, "Real")

    def get_integer(self, vrs):
        return self._get(vrs, "Integer")

    def get_boolean(self, vrs):
        return self._get(vrs, "Boolean")

    def get_string(self, vrs):
        return self._get(vrs, "String")

    def _set_many(self, vrs, values, kind: str) -> None:
        for name, value in zip(self._names(vrs, kind), values):
            self._set(name, value)

    def set_real(self, vrs, values):
        # Fast path, the master's every step: Real inputs only (see _real_inputs), each a
        # float inside its range, not terminated.  Those are exactly the values set_problem
        # allows, so they are stored as the generic path would; anything else, or any
        # doubt, takes the generic path, which checks and refuses value by value.
        if self._phase in _SET_PHASES:
            inputs, accepted = self._real_inputs, []
            for vr, value in zip(vrs, values):
                entry = inputs.get(vr)
                if entry is None or type(value) is not float or not entry[1] <= value <= entry[2]:
                    break
                accepted.append((entry[0], value))
            else:
                for name, value in accepted:
                    self._store(name, value)
                return
        self._set_many(vrs, values, "Real")

    def set_integer(self, vrs, values):
        self._set_many(vrs, values, "Integer")

    def set_boolean(self, vrs, values):
        self._set_many(vrs, values, "Boolean")

    def set_string(self, vrs, values):
        self._set_many(vrs, values, "String")

    def _set(self, name: str, value) -> None:
        problem = self.set_problem(name, value)  # on linux64 the guard checked this already
        if problem is None:
            self._store(name, value)
        else:
            self._refuse(problem)

    def _store(self, name: str, value) -> None:
        self._values[name] = _CASTS[self._specs[name].type](value)

    def set_problem(self, name: str, value) -> str | None:
        """Why setting ``name`` to ``value`` now is illegal, or None if it is allowed."""
        spec = self._specs[name]
        if spec.causality == "output":
            return f"{name} is an output and cannot be set"
        if self._phase not in _SET_PHASES:  # of the slave's phases only terminated
            return f"cannot set {name} after fmi2Terminate"
        if self._phase == STEP_COMPLETE and spec.causality == "parameter" and spec.variability == "fixed":
            return f"{name} is a fixed parameter: set it before fmi2ExitInitializationMode"
        return self._value_problem(spec, value)

    def _value_problem(self, spec, value) -> str | None:
        return value_problem(spec, value)

    # -- life cycle ------------------------------------------------------------------------
    def _phase_problem(self, call: str) -> str | None:
        """Why ``call`` is not allowed in the current phase (FMI2_ALLOWED), or None if it is."""
        allowed = FMI2_ALLOWED[call]
        if self._phase in allowed:
            return None
        return (f"{call} is not allowed in state {self._phase} "
                f"(allowed in: {', '.join(p for p in PHASES if p in allowed)})")

    def _in_phase(self, call: str) -> bool:
        """True if ``call`` is allowed now; else the call is refused (:meth:`_refuse`)."""
        problem = self._phase_problem(call)
        if problem is not None:
            self._refuse(problem)
        return problem is None

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        if not self._in_phase("fmi2SetupExperiment"):
            return
        if math.isfinite(start_time):
            self._time_s = float(start_time)
        else:
            self._refuse(f"startTime = {start_time!r}: must be finite")

    def enter_initialization_mode(self):
        if self._in_phase("fmi2EnterInitializationMode"):
            self._phase = INITIALIZATION_MODE

    def terminate(self):
        if self._in_phase("fmi2Terminate"):
            self._phase = TERMINATED

    def _step_problem(self, current_time, step_size) -> str | None:
        """Why a doStep from ``current_time`` of ``step_size`` is illegal now, or None."""
        if (problem := self._phase_problem("fmi2DoStep")) is not None:
            return problem
        if not (math.isfinite(step_size) and step_size > 0.0):
            return f"communicationStepSize = {step_size!r}: must be a finite number > 0"
        tolerance = TIME_MATCH_RTOL * max(1.0, abs(self._time_s))
        if not (math.isfinite(current_time) and abs(current_time - self._time_s) <= tolerance):
            return (f"currentCommunicationPoint = {current_time!r}: must equal the end of the last step "
                    f"({self._time_s!r}) to within {tolerance:g} s")
        return None

    # -- FMU state -------------------------------------------------------------------------
    def _typed_values(self, values: dict) -> dict:
        """A state's variable values converted to their Python types, after checking that its
        fixed parameters equal this instance's (StateError naming each one that differs)."""
        typed = {name: _CASTS[spec.type](values[name]) for name, spec in self._specs.items()}
        differ = [f"{name} = {typed[name]!r} (this instance: {self._values[name]!r})"
                  for name, spec in self._specs.items()
                  if spec.variability == "fixed" and typed[name] != self._values[name]]
        if differ:
            raise StateError("the state was saved with other fixed parameters: " + ", ".join(differ) +
                             ". Set them to the state's values before restoring it")
        return typed

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return bytes(state)
