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
* A refused ``set`` (or a call in a wrong phase) raises :class:`FmiCallError`.  pythonfmu can only report
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

The variables, typed get/set, phases and the checks of a set and of a doStep come from
:mod:`avr_slavebase`, shared with the plant FMU's slave.  Inside the FMU this module and the
core travel as one package in ``resources/avr_regulator_lib/``, imported under a name private
to the build (``fmu_src/packing/pack.py``), so builds and instances never share code.

Statuses (host sees; linux64 with the guard / pythonfmu's library alone):
    doStep in a wrong phase, non-finite or non-positive step, current time not
    the end of the last step: fmi2Error (guard) / fmi2Discard (slave returns False);
    set of an output, of a fixed parameter after initialization, of anything
    after terminate, a value NaN or outside its declared [min, max] (inputs too):
        fmi2Error (guard) / fmi2Fatal (pythonfmu);
    fmi2ExitInitializationMode with parameters that break a rule between them
    (``avr_specs.PARAM_REQUIRES``: learn_ramp_max_mps2 > 0 requires learn_settled_steps > 0; the
    instance stays in initialization mode), a parameter set while stepping that breaks one:
        fmi2Error (guard, from the slave's logged refusal) / fmi2OK with the refusal logged and
        nothing changed (pythonfmu's library alone cannot return fmi2Error);
    corrupt, truncated, foreign or non-finite state blob, or one saved with other
    fixed parameters: fmi2Error (the guard checks its CRC-64, GUID, time and fixed
    parameters in C, then the slave's verdict) / deserialize OK, then fmi2Fatal
    on fmi2SetFMUstate (pythonfmu).
"""
from __future__ import annotations

from pythonfmu.enums import Fmi2Status

from fmu_src.fmi import avr_fmustate as fmustate
from fmu_src.core.avr_errors import AvrError, StateError
from fmu_src.core.avr_network import build_networks
from fmu_src.core.avr_params import RegulatorInputs, RegulatorParams
from fmu_src.core.avr_regulator import initial_state, step
from fmu_src.fmi.avr_slavebase import STEP_COMPLETE, SpecSlave
from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS, PARAM_SPECS, requires_problems
from fmu_src.core.avr_statebytes import state_from_bytes, state_to_bytes

_ALL_SPECS = (*PARAM_SPECS, *INPUT_SPECS, *OUTPUT_SPECS)
#: What deserializing a refused blob yields (then the reason); see _fmu_state_from_bytes.
REFUSED_STATE = fmustate.REFUSED_STATE


class FmiCallError(AvrError):
    """A call the FMI 2.0 standard forbids in the current phase (or an invalid value)."""


class AdaptiveVelocityRegulator(SpecSlave):
    """Adaptive velocity regulator for 3D bipedal walking (Castillo et al., IROS 2020)."""

    author = "cassie-avr project"
    description = ("Adaptive velocity regulator for bipedal walking: PD foot-placement and torso regulators "
                   "plus online-learning neural networks (delta rule) that output virtual-constraint offsets")
    license = "MIT"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._params = None
        self._networks = None
        self._state = None
        self._init_variables(_ALL_SPECS)
        self._input_names = tuple(spec.name for spec in INPUT_SPECS)

    def _refuse(self, message: str) -> None:
        """pythonfmu reports the exception as fmi2Fatal; on linux64 the guard refused first."""
        super()._refuse(message)
        raise FmiCallError(message)

    def _store(self, name: str, value) -> None:
        super()._store(name, value)
        if self._specs[name].causality == "parameter" and self._phase == STEP_COMPLETE:
            self._params = self._make_params()  # tunable parameter changed while stepping

    def _make_params(self) -> RegulatorParams:
        return RegulatorParams(**{spec.name: self._values[spec.name] for spec in PARAM_SPECS})  # validates

    def _set(self, name: str, value) -> None:
        """The base's set; while stepping, a parameter value that breaks a PARAM_REQUIRES rule is
        refused by logging only (during initialization the rules are checked when it ends: values
        come in any order).  The guard cannot check these rules, so it must not see an exception
        (pythonfmu's fmi2Fatal): it answers fmi2Error for the logged error."""
        if (self._phase == STEP_COMPLETE and self._specs[name].causality == "parameter"
                and self.set_problem(name, value) is None):
            broken = requires_problems({**self._values, name: value})
            if broken:
                SpecSlave._refuse(self, "; ".join(broken))
                return
        super()._set(name, value)

    # -- FMI life cycle -----------------------------------------------------------------
    def exit_initialization_mode(self):
        self._in_phase("fmi2ExitInitializationMode")
        broken = requires_problems(self._values)
        if broken:  # logged, not raised: the guard answers fmi2Error and the instance stays in initialization
            SpecSlave._refuse(self, "fmi2ExitInitializationMode refused: " + "; ".join(broken))
            return
        self._params = self._make_params()
        if self._state is None:  # not already restored from an FMU state blob
            self._networks = build_networks(self._params)
            self._state = initial_state(self._params, self._networks)
        self._phase = STEP_COMPLETE

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

    # -- FMU state ----------------------------------------------------------------------
    def _get_fmu_state(self):
        core = b"" if self._state is None else state_to_bytes(self._state)
        return fmustate.encode(self._values, self._phase, self._time_s, core)

    def _set_fmu_state(self, state):
        parts, params, core_state = _parse_state(state)  # raises StateError naming the problem
        values = self._typed_values(parts.values)  # refuses other fixed parameters
        if core_state is not None:
            networks = build_networks(params) if self._networks_stale(params) else self._networks
        else:
            networks = None
        # everything checked: commit at once
        self._values = values
        self._phase, self._time_s = parts.phase, parts.time_s
        self._params = params if core_state is not None else None
        self._networks, self._state = networks, core_state

    def _networks_stale(self, params) -> bool:
        net = self._networks
        return net is None or (net.n_neurons, net.seed) != (params.n_neurons, params.seed)

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
