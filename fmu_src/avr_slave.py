"""FMI 2.0 co-simulation slave ``AdaptiveVelocityRegulator`` (pythonfmu).

A thin translator between FMI calls and the numpy-only regulator core
(:mod:`avr_core`): the variables are declared once, in the order of the core's
``PARAM_SPECS``, ``INPUT_SPECS`` and ``OUTPUT_SPECS`` (that order is the value
reference order), and every numeric decision is the core's.

What this class adds is FMI behaviour that pythonfmu 0.7.0 does not give:

* It tracks the FMI 2.0 co-simulation state (instantiated, initialization mode,
  step complete, terminated) and refuses what the standard forbids there.
* ``do_step`` never lets an exception escape (pythonfmu would turn it into
  ``fmi2Fatal`` and the instance would be unusable): a rejected step returns
  ``False``, which pythonfmu reports as ``fmi2Discard``; the regulator's state is
  left exactly as it was, and the reason is logged.
* A refused ``set`` raises :class:`FmiCallError`.  pythonfmu can only report
  that as ``fmi2Fatal``; the FMU's binary guard (``guard/*.c``, the library the
  host actually loads on linux64) checks the same rules first and answers
  ``fmi2Error`` without calling Python, so on linux64 this path is a second line
  of defence only.
* FMU state: ``_get_fmu_state`` returns one self-describing ``bytes`` blob
  (:mod:`avr_fmustate`: variable values, time, FMI phase and the core's weights
  and memories, with a CRC-32); the same blob is the serialized form, so
  get/set/serialize/deserialize round trips are bit-exact.  Deserializing checks
  the whole blob (checksum, every value's type and range, the core's weights)
  and never raises: a refused blob deserializes to ``REFUSED_STATE`` + the
  reason, which the guard reads back and answers with ``fmi2Error``.  Restoring
  a state whose fixed parameters (``n_neurons``, ``seed``, input scales) differ
  from the instance's current values is refused.

Statuses (host sees; linux64 with the guard / pythonfmu's library alone):
    doStep in a wrong phase, non-finite or non-positive step, current time not
    the end of the last step: fmi2Error (guard) / fmi2Discard (slave returns False);
    set of an output, of a fixed parameter after initialization, of anything
    after terminate, a value NaN or outside its declared [min, max] (inputs too):
        fmi2Error (guard) / fmi2Fatal (pythonfmu);
    corrupt, truncated, foreign or non-finite state blob, or one saved with other
    fixed parameters: fmi2Error (the guard checks its CRC-64, GUID, time and fixed
    parameters in C, then the slave's verdict) / deserialize OK, then fmi2Fatal
    on fmi2SetFMUstate (pythonfmu).
"""
from __future__ import annotations

import math

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.enums import Fmi2Status

try:  # inside the FMU these are top-level modules in resources/
    from . import avr_fmustate as fmustate
    from .avr_core import (FIXED_PARAMS, INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS, RegulatorInputs, RegulatorParams,
                           build_networks, initial_state, state_from_bytes, state_to_bytes, step)
    from .avr_errors import AvrError, StateError
except ImportError:  # pragma: no cover - exercised inside the built FMU
    import avr_fmustate as fmustate
    from avr_core import (FIXED_PARAMS, INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS, RegulatorInputs, RegulatorParams,
                          build_networks, initial_state, state_from_bytes, state_to_bytes, step)
    from avr_errors import AvrError, StateError

# FMI phases tracked by the slave (FMI 2.0 section 4.2.4)
INSTANTIATED, INITIALIZATION_MODE, STEP_COMPLETE, TERMINATED = fmustate.PHASES
_ALL_SPECS = (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)
#: What deserializing a refused blob yields (then the reason, UTF-8); the guard reads it back
#: and answers fmi2Error with the reason (see _fmu_state_from_bytes).
REFUSED_STATE = b"\0AVR-REFUSED\0"

#: Relative tolerance on "doStep starts where the last step ended": a master that
#: computes t = t0 + k*h differs from (t_prev + h) by a few ulp, far below 1e-9 s.
TIME_MATCH_RTOL = 1e-9

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean}
_CAUSALITY = {"parameter": Fmi2Causality.parameter, "input": Fmi2Causality.input, "output": Fmi2Causality.output}
_VARIABILITY = {name: getattr(Fmi2Variability, name) for name in ("fixed", "tunable", "discrete", "continuous")}
_CASTS = {"Real": float, "Integer": int, "Boolean": bool}


class FmiCallError(AvrError):
    """A call the FMI 2.0 standard forbids in the current phase (or an invalid value)."""


class AdaptiveVelocityRegulator(Fmi2Slave):
    """Adaptive velocity regulator for 3D bipedal walking (Castillo et al., IROS 2020)."""

    author = "cassie-avr project"
    description = ("Adaptive velocity regulator for bipedal walking: PD foot-placement and torso regulators "
                   "plus online-learning neural networks (delta rule) that output virtual-constraint offsets")
    license = "MIT"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._specs = {spec.name: spec for spec in _ALL_SPECS}
        self._values = {spec.name: spec.default for spec in self._specs.values()}
        self._phase = INSTANTIATED
        self._time_s = 0.0
        self._params = None
        self._networks = None
        self._state = None
        for spec in _ALL_SPECS:
            self.register_variable(self._declare(spec))
        #: value reference -> (name, type) for the fast get/set paths below
        self._by_vr = [(var.name, self._specs[var.name].type) for var in self.vars.values()]
        self._input_names = tuple(spec.name for spec in INPUT_SPECS)

    # -- declarations -------------------------------------------------------------------
    def _declare(self, spec):
        kind = _TYPES[spec.type]
        extra = {}
        if spec.causality != "input":  # FMI forbids `initial` on inputs
            extra["initial"] = Fmi2Initial.exact
        return kind(spec.name, causality=_CAUSALITY[spec.causality], variability=_VARIABILITY[spec.variability],
                    description=spec.description, getter=lambda name=spec.name: self._values[name], **extra)

    # -- getting and setting variables ---------------------------------------------------------
    # pythonfmu's generic versions call one closure per variable; these do the same checks
    # (type, legality, range) with one table lookup each: the FMI overhead is most of a step.
    def _get(self, vrs, kind: str, cast):
        values, by_vr = self._values, self._by_vr
        out = []
        for vr in vrs:
            name, var_type = by_vr[vr]
            if var_type != kind:
                raise TypeError(f"Variable with valueReference={vr} ({name}) is not of type {kind}")
            out.append(cast(values[name]))
        return out

    def get_real(self, vrs):
        return self._get(vrs, "Real", float)

    def get_integer(self, vrs):
        return self._get(vrs, "Integer", int)

    def get_boolean(self, vrs):
        return self._get(vrs, "Boolean", bool)

    def _set_many(self, vrs, values, kind: str) -> None:
        by_vr = self._by_vr
        names = []
        for vr in vrs:
            name, var_type = by_vr[vr]
            if var_type != kind:
                raise TypeError(f"Variable with valueReference={vr} ({name}) is not of type {kind}")
            names.append(name)
        for name, value in zip(names, values):
            self._set(name, value)

    def set_real(self, vrs, values):
        self._set_many(vrs, values, "Real")

    def set_integer(self, vrs, values):
        self._set_many(vrs, values, "Integer")

    def set_boolean(self, vrs, values):
        self._set_many(vrs, values, "Boolean")

    def _set(self, name: str, value) -> None:
        spec = self._specs[name]
        problem = self.set_problem(name, value)  # the guard checked this already on linux64
        if problem is not None:
            self.log(problem, Fmi2Status.error)
            raise FmiCallError(problem)
        self._values[name] = _CASTS[spec.type](value)
        if spec.causality == "parameter" and self._phase == STEP_COMPLETE:
            self._params = self._make_params()  # tunable parameter changed while stepping

    def set_problem(self, name: str, value) -> str | None:
        """Why setting ``name`` to ``value`` now is illegal, or None if it is allowed."""
        spec = self._specs[name]
        if spec.causality == "output":
            return f"{name} is an output: it cannot be set"
        if self._phase == TERMINATED:
            return f"cannot set {name} after fmi2Terminate"
        if self._phase == STEP_COMPLETE and spec.causality == "parameter" and spec.variability == "fixed":
            return f"{name} is a fixed parameter: it can only be set before fmi2ExitInitializationMode"
        return fmustate.value_problem(spec, value)

    def _make_params(self) -> RegulatorParams:
        return RegulatorParams(**{spec.name: self._values[spec.name] for spec in PARAM_SPECS})  # validates

    # -- FMI life cycle -----------------------------------------------------------------
    def _require(self, call: str, *phases: str) -> None:
        if self._phase not in phases:
            message = f"{call} is not allowed in state {self._phase} (allowed in: {', '.join(phases)})"
            self.log(message, Fmi2Status.error)
            raise FmiCallError(message)

    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._require("fmi2SetupExperiment", INSTANTIATED)
        if not math.isfinite(start_time):
            raise FmiCallError(f"startTime = {start_time!r}: must be finite")
        self._time_s = float(start_time)

    def enter_initialization_mode(self):
        self._require("fmi2EnterInitializationMode", INSTANTIATED)
        self._phase = INITIALIZATION_MODE

    def exit_initialization_mode(self):
        self._require("fmi2ExitInitializationMode", INITIALIZATION_MODE)
        self._params = self._make_params()
        if self._state is None:  # not already restored from an FMU state blob
            self._networks = build_networks(self._params)
            self._state = initial_state(self._params, self._networks)
        self._phase = STEP_COMPLETE

    def terminate(self):
        self._require("fmi2Terminate", STEP_COMPLETE)
        self._phase = TERMINATED

    def do_step(self, current_time, step_size):
        try:
            problem = self._step_problem(current_time, step_size)
            if problem is None:
                values = self._values
                inputs = RegulatorInputs(**{name: values[name] for name in self._input_names})
                new_state, outputs = step(self._state, inputs, float(step_size), self._params, self._networks)
                self._state = new_state
                self._values.update(outputs)
                self._time_s = float(current_time) + float(step_size)
                return True
        except Exception as exc:  # noqa: BLE001 - nothing may escape to pythonfmu (it would mean fmi2Fatal)
            problem = f"doStep rejected: {exc}"
        self.log(problem, Fmi2Status.discard)
        return False

    def _step_problem(self, current_time, step_size) -> str | None:
        if self._phase != STEP_COMPLETE:
            return f"fmi2DoStep is not allowed in state {self._phase} (allowed in: {STEP_COMPLETE})"
        if not (math.isfinite(step_size) and step_size > 0.0):
            return f"communicationStepSize = {step_size!r}: must be a finite number > 0"
        tolerance = TIME_MATCH_RTOL * max(1.0, abs(self._time_s))
        if not (math.isfinite(current_time) and abs(current_time - self._time_s) <= tolerance):
            return (f"currentCommunicationPoint = {current_time!r}: must equal the end of the last step "
                    f"({self._time_s!r}) to within {tolerance:g} s")
        return None

    # -- FMU state ----------------------------------------------------------------------
    def _get_fmu_state(self):
        core = b"" if self._state is None else state_to_bytes(self._state)
        return fmustate.encode(self._values, self._phase, self._time_s, core)

    def _set_fmu_state(self, state):
        parts, params, core_state = _parse_state(state)  # raises StateError naming the problem
        values = parts.values
        differ = [f"{name} = {values[name]!r} (this instance: {self._values[name]!r})"
                  for name in FIXED_PARAMS if values[name] != self._values[name]]
        if differ:
            raise StateError("the state was saved with other fixed parameters: " + ", ".join(differ) +
                             ". Set them to the state's values before restoring it")
        if core_state is not None:
            networks = build_networks(params) if self._networks_stale(params) else self._networks
        else:
            networks = None
        # everything checked: commit at once
        self._values = {name: _CASTS[self._specs[name].type](values[name]) for name in self._specs}
        self._phase, self._time_s = parts.phase, parts.time_s
        self._params = params if core_state is not None else None
        self._networks, self._state = networks, core_state

    def _networks_stale(self, params) -> bool:
        net = self._networks
        return net is None or (net.n_neurons, net.seed) != (params.n_neurons, params.seed)

    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        return bytes(state)

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        """The blob itself if it is a complete, valid state; else ``REFUSED_STATE`` + the reason.

        pythonfmu turns any exception raised here into fmi2Fatal; a refusal returned as data
        lets the guard answer fmi2Error with the reason and leave the instance untouched.
        """
        try:
            _parse_state(state)
        except Exception as exc:  # noqa: BLE001 - nothing may escape to pythonfmu (it would mean fmi2Fatal)
            return REFUSED_STATE + f"{type(exc).__name__}: {exc}".encode("utf-8", "replace")
        return bytes(state)


def _parse_state(blob):
    """Everything in a state blob, checked: (parts, parameters, core state or None)."""
    if bytes(blob[:len(REFUSED_STATE)]) == REFUSED_STATE:  # without the guard, a refused blob can come back
        raise StateError(bytes(blob[len(REFUSED_STATE):]).decode("utf-8", "replace"))
    parts = fmustate.decode(blob, _ALL_SPECS)
    params = RegulatorParams(**{spec.name: parts.values[spec.name] for spec in PARAM_SPECS})  # validates
    core_state = state_from_bytes(parts.core, params) if parts.core else None
    return parts, params, core_state
