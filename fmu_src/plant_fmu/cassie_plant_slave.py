"""FMI 2.0 co-simulation slave ``CassiePlant`` (pythonfmu): the MuJoCo Cassie walker.

A thin translator between FMI calls and the plant's pure core (``fmu_src/plant_fmu/fmu_core.py``).
Inside the FMU this module, the core and the plant package travel in
``resources/cassie_plant_lib/`` (``build.py`` copies them with package-relative imports) and
are imported under a name private to the build (``fmu_src/packing/pack.py``): the host's
own ``plant`` package, the regulator FMU's modules and other builds of this FMU never mix with
them (pythonfmu issue #228).  The models are read from each instance's own resources folder; the
gait library was read into memory with the plant package, and an instance checks it has one
when it is created (without one, fmi2Instantiate fails with the error naming the file): nothing
is read later from a folder the host may have deleted since (libcosim deletes an execution's
extraction when the execution ends, while the package loaded from it serves the next one).

Statuses: the FMU's linux64 library is the FMI guard (``fmu_src/regulator_fmu/guard/``, built with this
FMU's variable table and ``AVR_STEP_QUANTUM`` = 0.5 ms): calls the state machine forbids,
sets of outputs or of fixed parameters after initialization, NaN/inf or out-of-range
values, communication steps that are not whole multiples of 0.5 ms or longer than the
maximum step (``AVR_MAX_STEP`` = ``fmu_src.plant_fmu.fmu_core.MAX_STEP_S``), corrupt or foreign
serialized states and ones whose header and blob disagree on the phase or time are
``fmi2Error`` without reaching Python.  pythonfmu reports a
Python exception as ``fmi2Fatal`` only, so this slave never raises on bad input: it logs
the problem with status Error and changes nothing, and the guard answers ``fmi2Error``
for any call that logged an error.  That covers what only Python can check: the
``cassie_model`` name, the plant's own parameter validation (``Perturbation.problems()``: every
problem at once, each naming its field and range) in ``fmi2ExitInitializationMode``,
which then stays in initialization mode, and the contents of an FMU state.

The variables, typed get/set, phases and the checks of a set and of a doStep come from
``fmu_src/fmi/avr_slavebase.py`` (shared with the regulator's slave; inside the FMU, this FMU's
own copy).

FMU state: the regulator's blob format (``fmu_src/fmi/avr_fmustate.py``: every variable
value, the FMI phase and time, CRC-32) with the walker's exact state (MuJoCo's
integration state, servo gains, controller memory) as its core.  As for the regulator,
a state restores only into an instance with the same fixed parameters.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

from pythonfmu.enums import Fmi2Status

from fmu_src.core.avr_errors import StateError
from fmu_src.fmi import avr_fmustate
from fmu_src.fmi.avr_slavebase import STEP_COMPLETE, SpecSlave
from fmu_src.plant_fmu import fmu_core
from plant.gaits import GaitLibrary

#: The folder in ``resources/`` that holds the plant package and the model files.
LIB_DIR = "cassie_plant_lib"


class CassiePlant(SpecSlave):
    """MuJoCo Cassie with its nominal walking controller, started from rest."""

    author = "cassie-avr project"
    description = ("MuJoCo Cassie biped with a nominal HZD-style walking controller (0.5 ms plant step); "
                   "inputs: command, the velocity regulator's joint offsets, a push; outputs: the regulator's "
                   "inputs, telemetry and a fall flag")
    license = "MIT (model files: see resources/cassie_plant_lib/models/*/LICENSE)"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._core = fmu_core
        self._walker = None
        self._gaits = GaitLibrary.default()  # GaitLibraryError (instantiation fails) naming the file
        self._init_variables(self._core.SPECS)

    def _value_problem(self, spec, value) -> str | None:
        if spec.name == "cassie_model":
            return self._core.model_problem(value)
        return super()._value_problem(spec, value)

    # -- life cycle --------------------------------------------------------------------
    def exit_initialization_mode(self):
        """Build the walker; on invalid parameters log every problem and stay in initialization mode."""
        if not self._in_phase("fmi2ExitInitializationMode"):
            return
        try:
            walker = self._start_walker()
        except Exception as exc:  # noqa: BLE001 - reported as fmi2Error, the instance stays usable
            for problem in getattr(exc, "problems", None) or [str(exc)]:
                self._refuse(f"fmi2ExitInitializationMode refused: {problem}")
            return
        self._walker = walker
        self._values.update(self._core.outputs(walker))
        self._phase = STEP_COMPLETE

    def _start_walker(self):
        params = {spec.name: self._values[spec.name] for spec in self._core.PARAM_SPECS}
        return self._core.start(params, Path(self.resources) / LIB_DIR / "models", self._gaits)

    def do_step(self, current_time, step_size):
        problem = self._step_problem(current_time, step_size) or self._core.step_problem(step_size)
        if problem:
            self._refuse(f"fmi2DoStep refused: {problem}")
            return True  # nothing done; the guard reports the logged error as fmi2Error
        inputs = {name: self._values[name] for name in self._core.INPUT_NAMES}
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

    # -- FMU state ---------------------------------------------------------------------
    def _get_fmu_state(self):
        return self._core.encode_fmu_state(self._values, self._phase, self._time_s, self._walker)

    def _set_fmu_state(self, state):
        try:
            if bytes(state[:len(avr_fmustate.REFUSED_STATE)]) == avr_fmustate.REFUSED_STATE:
                raise StateError(bytes(state).decode("utf-8", "replace"))  # only without the guard
            parts, walker = self._restore(bytes(state))
        except Exception as exc:  # noqa: BLE001 - a bad state is refused (fmi2Error), the instance unchanged
            self._refuse(f"fmi2SetFMUstate refused: {exc}")
            return
        self._values, self._phase, self._time_s, self._walker = parts.values, parts.phase, parts.time_s, walker

    def _restore(self, blob: bytes):
        """The state's parts, checked, and a walker in the saved state (the current one if the state
        carries walker bytes and the instance has one; fixed parameters must equal the instance's)."""
        parts = self._core.decode_fmu_state(blob)
        values = self._typed_values(parts.values)
        walker = None
        if parts.core:
            walker = self._walker or self._start_walker()
            self._core.state_from_bytes(walker, parts.core)  # all or nothing
        return dataclasses.replace(parts, values=values), walker

    @staticmethod
    def _fmu_state_from_bytes(state: bytes):
        """The blob itself if its variable table is valid, else ``REFUSED_STATE`` + the reason (which
        the guard reads back and answers with fmi2Error; pythonfmu would turn an exception into
        fmi2Fatal).  pythonfmu calls this on the class, without an instance: the walker state, which
        needs the instance's model, is checked when the state is set (:meth:`_set_fmu_state`, fmi2Error
        too).  The guard has checked the serialized state's CRC-64, GUID, fixed parameters, this blob's
        header and that both say the same phase and time."""
        try:
            blob = bytes(state)
            fmu_core.decode_fmu_state(blob)
        except Exception as exc:  # noqa: BLE001 - nothing may escape to pythonfmu (it would mean fmi2Fatal)
            return avr_fmustate.REFUSED_STATE + f"{type(exc).__name__}: {exc}".encode("utf-8", "replace")
        return blob

