"""The co-simulation master: the MuJoCo Cassie plant closed around the regulator.

One loop (:func:`run_arm`) drives the plant and a :class:`RegulatorPath`; two paths
implement that interface with the same data flow:

- :class:`FmuRegulator`: the FMI 2.0 co-simulation FMU through fmpy's ``FMU2Slave``
  (extract, read the model description, instantiate with a logger that collects the
  FMU's messages, set parameters by name with type-correct calls, setupExperiment,
  enter/exit initialization mode, doStep; terminate/freeInstance in ``finally``; any
  non-OK status raises :class:`CosimError` carrying the FMU's log);
- :class:`InProcessRegulator`: the numpy regulator core called directly.

Both give bit-identical trajectories for the same scenario and seed.

Per communication step ``k`` (time ``t = t0 + k*h`` from the integer counter; never
``t += h``): the command schedule and the pushes in force over ``[t, t+h)`` are applied
to the plant (pushes switch on communication-step boundaries only), the plant is
sensed, the regulator steps from ``t`` by ``h`` and its six ``delta_*`` outputs go to
the walker, which then advances ``h / SIM_DT_S`` plant steps. A fall stops the run
(``t_fall_s`` = end of the step in which it was detected).

The result is a numpy structured array, one row per communication step: ``t``,
``cmd_vx_des``, ``cmd_vy_des``, ``push_fx/fy/fz``, ``in_<input>`` (the sensed
regulator inputs), ``out_<output>`` (every FMU output) and ``tel_<key>`` (the
walker's telemetry), all sampled at ``t`` (outputs: computed at ``t``, applied over
the step).
"""
from __future__ import annotations

import abc
import itertools
import logging
import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from scenarios.errors import CosimError, ScenarioError
from scenarios.scenario import Arm, Scenario

log = logging.getLogger(__name__)

#: The regulator outputs that go to the walker (virtual-constraint offsets, rad).
DELTA_NAMES = (
    "delta_swing_hip_pitch", "delta_swing_knee", "delta_swing_hip_roll",
    "delta_stance_hip_roll", "delta_stance_hip_pitch", "delta_stance_knee",
)
#: Regulator inputs sensed on the plant (vx_des/vy_des come from the command schedule).
SENSED_INPUTS = ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index")
REGULATORS = ("fmu", "native", "inprocess")
_FMI_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
_LOG_KEEP = 200

# fmpy's native logger proxy (which formats the FMU's printf-style messages) keeps ONE
# process-wide pointer to the Python logger it forwards to, whichever callbacks struct
# was registered last; a per-instance logger that is garbage-collected leaves it dangling
# and the next FMU message from any instance crashes the process.  So there is one
# logger for the whole process, alive as long as the module, routing messages by
# instance name; names it does not know are printed as fmpy's default logger does.
_LOG_ROUTES: dict[str, list[str]] = {}
_INSTANCE_IDS = itertools.count(1)
_SHARED_CALLBACKS = None


def _route_fmu_message(component, instance_name, status, category, message) -> None:
    label = _FMI_STATUS[status] if 0 <= status < len(_FMI_STATUS) else str(status)
    name = instance_name.decode("utf-8", "replace") if isinstance(instance_name, bytes) else str(instance_name)
    text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
    cat = category.decode("utf-8", "replace") if isinstance(category, bytes) else str(category)
    messages = _LOG_ROUTES.get(name)
    if messages is None:
        log.info("[%s] %s %s: %s", label, name, cat, text)
        return
    messages.append(f"[{label}] {cat}: {text}")
    del messages[:-_LOG_KEEP]


def _shared_callbacks():
    """The process-lifetime fmi2CallbackFunctions with the routing logger."""
    global _SHARED_CALLBACKS
    if _SHARED_CALLBACKS is None:
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(_route_fmu_message)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(byref(callbacks))
        except Exception as exc:  # pragma: no cover - fmpy's native proxy is optional
            log.warning("fmpy logger proxy unavailable (%s): FMU messages are not formatted", exc)
        _SHARED_CALLBACKS = callbacks
    return _SHARED_CALLBACKS


# =========================================================================== regulator paths
class RegulatorPath(abc.ABC):
    """One way of running the regulator; the loop talks to nothing else.

    Life cycle: ``start(parameters, t0, t_stop)`` once, ``step(t, h, inputs)`` per
    communication step (``inputs`` keyed by the FMU input names, Real inputs as float,
    ``step_index`` as int; returns every output by name), ``close()`` always.
    """

    kind: str = ""

    @abc.abstractmethod
    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None: ...

    @abc.abstractmethod
    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]: ...

    @abc.abstractmethod
    def output_names(self) -> tuple[str, ...]: ...

    @abc.abstractmethod
    def close(self) -> None: ...

    def __enter__(self) -> "RegulatorPath":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _core():
    from fmu_src import avr_core

    return avr_core


def _spec_type(spec) -> str:
    kind = str(spec.type).lower()
    return "Boolean" if kind.startswith("bool") else "Integer" if kind.startswith("int") else "Real"


_CASTS: dict[str, Callable[[Any], Any]] = {"Real": float, "Integer": int, "Boolean": bool}


class InProcessRegulator(RegulatorPath):
    """The regulator core called directly, with the FMU's data flow and casts."""

    kind = "inprocess"

    def __init__(self) -> None:
        self._core = _core()
        self._input_types = [(s.name, _CASTS[_spec_type(s)]) for s in self._core.INPUT_SPECS]
        self._outputs = tuple(s.name for s in self._core.OUTPUT_SPECS)
        self._step_fn: Callable[[Any, float], dict] | None = None

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        core = self._core
        types = {s.name: _CASTS[_spec_type(s)] for s in core.PARAM_SPECS}
        unknown = sorted(set(parameters) - set(types))
        if unknown:
            raise CosimError(f"unknown regulator parameter(s): {', '.join(unknown)}")
        values = {s.name: s.default for s in core.PARAM_SPECS}
        values.update(parameters)
        params = core.RegulatorParams(**{n: types[n](v) for n, v in values.items()})
        core.validate_params(params)
        self._step_fn = core.Regulator(params).step

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        reg_in = self._core.RegulatorInputs(**{n: cast(inputs[n]) for n, cast in self._input_types})
        out = self._step_fn(reg_in, float(h))
        return {n: float(out[n]) for n in self._outputs}

    def close(self) -> None:
        self._step_fn = None


class FmuRegulator(RegulatorPath):
    """The FMU through fmpy's FMU2Slave; every FMI call's status is checked."""

    kind = "fmu"

    def __init__(self, fmu_path: str | Path, instance_name: str = "avr", *, unpack_dir: str | Path | None = None) -> None:
        """``unpack_dir``: the folder under which :meth:`start` extracts the FMU (a fresh
        subfolder, removed by :meth:`close`); None: the system temp folder."""
        from fmpy import read_model_description

        self.fmu_path = Path(fmu_path)
        if not self.fmu_path.is_file():
            raise CosimError(f"FMU not found: {self.fmu_path}")
        self.instance_name = f"{instance_name}-{next(_INSTANCE_IDS)}"  # unique: log messages are routed by it
        self.md = read_model_description(str(self.fmu_path))
        if self.md.fmiVersion != "2.0" or self.md.coSimulation is None:
            raise CosimError(f"{self.fmu_path}: not an FMI 2.0 co-simulation FMU")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self._outputs = tuple(v.name for v in self.md.modelVariables if v.causality == "output")
        self.messages: list[str] = []
        self._fmu = None
        self._unpack_dir = unpack_dir
        self._unzip: str | None = None
        self._instantiated = False
        self._initialized = False
        self._t: float | None = None  # the communication point being computed (for messages)

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    # ---- logging and status
    def log_text(self) -> str:
        return "\n".join(self.messages) if self.messages else "(the FMU logged nothing)"

    def _fail(self, what: str, detail: str) -> CosimError:
        if self._t is not None:
            what = f"{what} at t = {self._t!r} s"
        return CosimError(f"{what} failed: {detail}\nFMU log ({self.fmu_path.name}):\n{self.log_text()}")

    def _call(self, what: str, fn, *args):
        from fmpy.fmi1 import FMICallException

        try:
            status = fn(*args)
        except FMICallException as exc:
            raise self._fail(what, str(exc)) from None
        except CosimError:
            raise
        except Exception as exc:  # instantiate raises a bare Exception on NULL
            raise self._fail(what, f"{type(exc).__name__}: {exc}") from None
        if status:  # None (instantiate) or fmi2OK == 0 pass; Warning and worse do not
            raise self._status_error(what, status)
        return status

    def _status_error(self, what: str, status: int) -> CosimError:
        label = _FMI_STATUS[status] if 0 <= status < len(_FMI_STATUS) else str(status)
        return self._fail(what, f"status {label}")

    # ---- life cycle
    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        from ctypes import c_double, c_int

        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        problems = []
        for name, value in parameters.items():
            var = self.vars.get(name)
            if var is None:
                problems.append(f"{name}: the FMU has no such variable")
            elif var.causality != "parameter":
                problems.append(f"{name}: causality {var.causality}, not a parameter")
        if problems:
            raise CosimError("cannot set FMU parameters: " + "; ".join(problems))

        # the folder is ours before anything is extracted: close() removes it whatever fails next
        self._unzip = tempfile.mkdtemp(prefix="fmu-", dir=self._unpack_dir)
        extract(str(self.fmu_path), self._unzip)
        self._callbacks = _shared_callbacks()
        _LOG_ROUTES[self.instance_name] = self.messages
        cwd = os.getcwd()
        try:
            self._fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzip,
                                  modelIdentifier=self.md.coSimulation.modelIdentifier,
                                  instanceName=self.instance_name)
        finally:  # fmpy 0.3 changes into binaries/<platform> to load the library and stays there if that fails
            os.chdir(cwd)
        self._call("fmi2Instantiate", lambda: self._fmu.instantiate(callbacks=self._callbacks, loggingOn=True))
        self._instantiated = True
        comp = self._fmu.component

        # parameters, grouped by type (value references from the model description)
        by_type: dict[str, tuple[list[int], list[Any]]] = {"Real": ([], []), "Integer": ([], []), "Boolean": ([], [])}
        for name, value in parameters.items():
            var = self.vars[name]
            vrs, vals = by_type[var.type]
            vrs.append(var.valueReference)
            vals.append(_CASTS[var.type](value))
        self._set("fmi2SetReal (parameters)", "Real", *by_type["Real"])
        self._set("fmi2SetInteger (parameters)", "Integer", *by_type["Integer"])
        self._set("fmi2SetBoolean (parameters)", "Boolean", *by_type["Boolean"])

        self._call("fmi2SetupExperiment", self._fmu.fmi2SetupExperiment, comp, 0, 0.0, float(t0), 1, float(t_stop))
        self._call("fmi2EnterInitializationMode", self._fmu.fmi2EnterInitializationMode, comp)
        self._call("fmi2ExitInitializationMode", self._fmu.fmi2ExitInitializationMode, comp)
        self._initialized = True

        # preallocated ctypes buffers for the per-step calls
        inputs = [v for v in self.md.modelVariables if v.causality == "input"]
        self._in_real = [v.name for v in inputs if v.type == "Real"]
        self._in_int = [v.name for v in inputs if v.type == "Integer"]
        self._in_bool = [v.name for v in inputs if v.type == "Boolean"]
        if self._in_bool:
            raise CosimError(f"unexpected Boolean inputs: {self._in_bool}")
        self._vr_in_real = self._vr_array([self.vars[n].valueReference for n in self._in_real])
        self._val_in_real = (c_double * len(self._in_real))()
        self._vr_in_int = self._vr_array([self.vars[n].valueReference for n in self._in_int])
        self._val_in_int = (c_int * len(self._in_int))()
        outs = [self.vars[n] for n in self._outputs]
        if any(v.type != "Real" for v in outs):
            raise CosimError("every FMU output must be Real: " + ", ".join(v.name for v in outs if v.type != "Real"))
        self._vr_out = self._vr_array([v.valueReference for v in outs])
        self._val_out = (c_double * len(outs))()
        self._first_step = True
        self._bind_step_calls()

    def _bind_step_calls(self) -> None:
        """The four per-step FMI functions as ctypes prototypes on the loaded library,
        called directly by :meth:`step`, which checks their statuses (fmpy's Python
        wrapper around each call cost about 1.5 us, 5 us a step). :meth:`close` drops
        them before the library is unloaded."""
        from ctypes import CFUNCTYPE, POINTER, c_double, c_int, c_size_t, c_uint, c_void_p

        dll = self._fmu.dll
        reals = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(c_double))
        ints = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(c_int))
        self._set_real = reals(("fmi2SetReal", dll))
        self._get_real = reals(("fmi2GetReal", dll))
        self._set_int = ints(("fmi2SetInteger", dll))
        self._do_step = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)(("fmi2DoStep", dll))

    @staticmethod
    def _vr_array(vrs: list[int]):
        from fmpy.fmi2 import fmi2ValueReference

        return (fmi2ValueReference * len(vrs))(*vrs)

    def _set(self, what: str, kind: str, vrs: list[int], vals: list[Any]) -> None:
        if not vrs:
            return
        from ctypes import c_double, c_int

        arr_vr = self._vr_array(vrs)
        if kind == "Real":
            self._call(what, self._fmu.fmi2SetReal, self._fmu.component, arr_vr, len(vrs), (c_double * len(vals))(*vals))
        elif kind == "Integer":
            self._call(what, self._fmu.fmi2SetInteger, self._fmu.component, arr_vr, len(vrs), (c_int * len(vals))(*vals))
        else:
            self._call(what, self._fmu.fmi2SetBoolean, self._fmu.component, arr_vr, len(vrs),
                       (c_int * len(vals))(*[1 if v else 0 for v in vals]))

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        comp = self._fmu.component
        self._t = t
        vals = self._val_in_real
        for i, n in enumerate(self._in_real):
            vals[i] = float(inputs[n])
        int_changed = self._first_step
        for i, n in enumerate(self._in_int):
            v = int(inputs[n])
            if v != self._val_in_int[i]:
                self._val_in_int[i] = v
                int_changed = True
        try:
            if self._in_real:
                status = self._set_real(comp, self._vr_in_real, len(self._in_real), vals)
                if status:
                    raise self._status_error("fmi2SetReal (inputs)", status)
            if self._in_int and int_changed:  # step_index changes once a walking step: FMU inputs keep their value
                status = self._set_int(comp, self._vr_in_int, len(self._in_int), self._val_in_int)
                if status:
                    raise self._status_error("fmi2SetInteger (inputs)", status)
            self._first_step = False
            status = self._do_step(comp, t, h, 1)
            if status:
                raise self._status_error("fmi2DoStep", status)
            status = self._get_real(comp, self._vr_out, len(self._outputs), self._val_out)
            if status:
                raise self._status_error("fmi2GetReal (outputs)", status)
        except CosimError:
            raise
        except Exception as exc:  # a ctypes argument error: never a traceback without the FMU log
            raise self._fail("FMI call", f"{type(exc).__name__}: {exc}") from None
        return dict(zip(self._outputs, self._val_out))

    def close(self) -> None:
        fmu = self._fmu
        self._fmu = None
        self._set_real = self._get_real = self._set_int = self._do_step = None
        try:
            if fmu is not None and self._instantiated:
                if self._initialized:
                    try:
                        fmu.fmi2Terminate(fmu.component)
                    except Exception as exc:  # keep freeing: the instance must not leak
                        log.warning("fmi2Terminate failed: %s", exc)
                try:
                    fmu.freeInstance()
                except Exception as exc:
                    log.warning("fmi2FreeInstance failed: %s", exc)
        finally:
            self._instantiated = self._initialized = False
            if _LOG_ROUTES.get(self.instance_name) is self.messages:
                del _LOG_ROUTES[self.instance_name]
            if self._unzip is not None:
                shutil.rmtree(self._unzip, ignore_errors=True)
                self._unzip = None


def make_regulator(kind: str, fmu_path: str | Path | None = None, *,
                   unpack_dir: str | Path | None = None) -> RegulatorPath:
    """``unpack_dir``: where an FMU is extracted (see :class:`FmuRegulator`)."""
    if kind in ("fmu", "native"):  # the pythonfmu or the native FMI 2.0 FMU: the same FMI path
        if fmu_path is None:
            raise CosimError(f"the {kind} regulator path needs an FMU file (fmu_path)")
        return FmuRegulator(fmu_path, unpack_dir=unpack_dir)
    if kind == "inprocess":
        return InProcessRegulator()
    raise CosimError(f"regulator = {kind!r}: must be one of {', '.join(REGULATORS)}")


# =========================================================================== the loop
@dataclass(frozen=True, eq=False)
class ArmResult:
    """One arm of one scenario: the trajectory and how the run ended.

    ``timings``: where the arm's time went, seconds (:data:`TIMINGS`); reported in
    summary.json, never part of the trajectory.
    """

    scenario: str
    arm: str
    regulator: str
    model: str
    rows: np.ndarray
    fell: bool
    t_fall_s: float | None
    fall_reason: str | None
    wall_s: float
    model_summary: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    @property
    def sim_s(self) -> float:
        if len(self.rows) == 0:
            return 0.0
        h = float(self.rows["t"][1] - self.rows["t"][0]) if len(self.rows) > 1 else 0.0
        return float(self.rows["t"][-1]) + h


#: The phases :func:`run_arm` times (wall seconds, ``time.perf_counter``), and its CPU time.
TIMINGS = {
    "model_s": "compiling the plant model (0 when it was passed in)",
    "walker_s": "building the walker on it",
    "regulator_start_s": "starting the regulator (FMU: extract, instantiate, initialize)",
    "loop_s": "every communication step, the three below included",
    "regulator_s": "the regulator's steps",
    "plant_s": "the plant's steps (physics and nominal controller)",
    "record_s": "storing each step's row",
    "finish_s": "closing the regulator, building the rows",
    "cpu_s": "CPU time of the process over all of the above",
}


def plant_steps_per_comm(h: float, sim_dt: float) -> int:
    """``h / sim_dt`` as an int; ScenarioError unless it is a whole number >= 1."""
    n = h / sim_dt
    if not (math.isfinite(n) and n >= 1 - 1e-9 and abs(n - round(n)) < 1e-6):
        raise ScenarioError([f"comm_step_s = {h:g}: must be a whole multiple of the plant step {sim_dt:g} s"])
    return int(round(n))


def _row_dtype(outputs: tuple[str, ...], sensed: Mapping[str, Any], telemetry: Mapping[str, Any]) -> np.dtype:
    fields: list[tuple[str, Any]] = [("t", "f8"), ("cmd_vx_des", "f8"), ("cmd_vy_des", "f8"),
                                     ("push_fx", "f8"), ("push_fy", "f8"), ("push_fz", "f8")]
    for n in SENSED_INPUTS:
        fields.append((f"in_{n}", "i8" if n == "step_index" else "f8"))
    fields += [(f"out_{n}", "f8") for n in outputs]
    for k, v in telemetry.items():
        is_int = isinstance(v, (int, np.integer)) and not isinstance(v, bool)
        fields.append((f"tel_{k}", "i8" if is_int else "f8"))
    return np.dtype(fields)


class _Recorder:
    """The rows in a table of doubles preallocated for every step (one store per step),
    turned into the structured array at the end. Integer columns (step counters) are
    whole numbers far below 2**53: a double holds them exactly."""

    def __init__(self, n_steps: int, dtype: np.dtype) -> None:
        self.dtype = dtype
        self.table = np.empty((n_steps, len(dtype.names)))

    def rows(self, n: int) -> np.ndarray:
        rows = np.empty(n, dtype=self.dtype)
        for j, name in enumerate(self.dtype.names):
            rows[name] = self.table[:n, j]
        return rows


@dataclass
class _Steps:
    """What the communication steps of one arm produced (filled in as they run)."""

    recorder: _Recorder | None = None
    done: int = 0
    fell: bool = False
    t_fall: float | None = None
    reason: str | None = None
    timings: dict = field(default_factory=dict)


def run_arm(scenario: Scenario, arm: Arm | str, regulator: RegulatorPath, *,
            progress: Callable[[int], None] | None = None, model=None, model_summary: dict | None = None,
            stop: Callable[[], bool] | None = None,
            plant: Callable[[Scenario, Any], Any] | None = None) -> ArmResult:
    """Run one arm of ``scenario`` closed-loop; return its trajectory (nothing printed).

    ``progress(n)`` is called with the number of communication steps done since the
    last call (for a progress bar). ``model`` may pass an already compiled plant model
    (it is only read: a fresh walker is built on it). ``stop()`` is asked before every
    communication step; when it answers true the run ends with ``KeyboardInterrupt``
    (a cooperative Ctrl-C: raised here, never inside the FMU). The regulator is closed
    whatever happens. ``plant(scenario, model)`` makes the walker instead of
    ``CassieWalker(model)`` (``scenarios.plant_fmu``: the plant FMU); its ``close()``, if
    any, is called at the end. The result's ``timings`` say where the time went
    (:data:`TIMINGS`).
    """
    from plant.sim import CassieWalker

    from scenarios.plantio import load_plant_model

    if isinstance(arm, str):
        arm = scenario.arm(arm)
    cpu0, lap = time.process_time(), time.perf_counter()
    timings = {"model_s": 0.0}
    if model is None:
        model, model_summary = load_plant_model(scenario)
        lap = _lap(timings, "model_s", lap)
    walker = CassieWalker(model) if plant is None else plant(scenario, model)  # its own copy of the model
    n_plant = plant_steps_per_comm(scenario.comm_step_s, float(walker.SIM_DT_S))
    outputs = regulator.output_names()
    missing = [n for n in DELTA_NAMES if n not in outputs]
    if missing:
        raise CosimError(f"the regulator has no output(s) {', '.join(missing)}")
    steps = _Steps()
    wall0 = lap = _lap(timings, "walker_s", lap)
    try:
        regulator.start(arm.overrides_dict(), 0.0, scenario.n_comm_steps * scenario.comm_step_s)
        lap = _lap(timings, "regulator_start_s", lap)
        _run_steps(scenario, arm, walker, regulator, n_plant, steps, progress, stop)
        lap = _lap(timings, "loop_s", lap)
    finally:
        regulator.close()
        if hasattr(walker, "close"):
            walker.close()
    if progress is not None and steps.done % 200:
        progress(steps.done % 200)
    rows = steps.recorder.rows(steps.done) if steps.recorder is not None else np.zeros(0, dtype=[("t", "f8")])
    _lap(timings, "finish_s", lap)
    wall = time.perf_counter() - wall0
    timings.update(steps.timings, cpu_s=time.process_time() - cpu0)
    return ArmResult(scenario=scenario.name, arm=arm.name, regulator=regulator.kind, model=scenario.model,
                     rows=rows, fell=steps.fell, t_fall_s=steps.t_fall, fall_reason=steps.reason, wall_s=wall,
                     model_summary=dict(model_summary or {}), timings=timings)


def _lap(timings: dict[str, float], key: str, since: float) -> float:
    """Add the time since ``since`` to ``timings[key]``; return now."""
    now = time.perf_counter()
    timings[key] = timings.get(key, 0.0) + (now - since)
    return now


def _run_steps(scenario: Scenario, arm: Arm, walker, regulator: RegulatorPath, n_plant: int, steps: _Steps,
               progress: Callable[[int], None] | None, stop: Callable[[], bool] | None) -> None:
    """The communication steps of :func:`run_arm` (see the module docstring), into ``steps``."""
    h, t0, n_steps = scenario.comm_step_s, 0.0, scenario.n_comm_steps
    outputs = regulator.output_names()
    clock = time.perf_counter
    command: tuple[float, float] | None = None
    force = (0.0, 0.0, 0.0)
    table = None
    reg_s = plant_s = record_s = 0.0
    try:
        for k in range(n_steps):
            if stop is not None and stop():
                raise KeyboardInterrupt(f"{scenario.name}/{arm.name} stopped at t = {t0 + k * h:g} s")
            t = t0 + k * h
            cmd = scenario.command_at_step(k)
            if cmd != command:
                walker.set_command(*cmd)
                command = cmd
            f = scenario.push_force_at_step(k)
            if f != force:
                walker.set_pelvis_force(np.array(f, dtype=float))
                force = f
            sensed = walker.regulator_inputs()
            tel = walker.telemetry()
            inputs = {n: sensed[n] for n in SENSED_INPUTS}
            inputs["vx_des"], inputs["vy_des"] = cmd
            c0 = clock()
            out = regulator.step(t, h, inputs)
            c1 = clock()
            walker.set_offsets({n: out[n] for n in DELTA_NAMES})
            if table is None:
                steps.recorder = _Recorder(n_steps, _row_dtype(outputs, sensed, tel))
                table = steps.recorder.table
            c2 = clock()
            table[k] = (t, *cmd, *f, *map(inputs.__getitem__, SENSED_INPUTS), *map(out.__getitem__, outputs),
                        *tel.values())
            c3 = clock()
            walker.advance(n_plant)
            c4 = clock()
            reg_s += c1 - c0
            record_s += c3 - c2
            plant_s += c4 - c3
            steps.done += 1
            if progress is not None and (steps.done % 200 == 0):
                progress(200)
            if walker.fell():
                steps.fell, steps.t_fall = True, t0 + (k + 1) * h
                steps.reason = str(getattr(walker, "fall_reason", "") or "") or None
                log.info("%s/%s: fell at t = %.3f s (%s)", scenario.name, arm.name, steps.t_fall, steps.reason)
                break
    finally:
        steps.timings.update(regulator_s=reg_s, plant_s=plant_s, record_s=record_s)


def run_scenario(scenario: Scenario, regulator: str = "fmu", *, fmu_path: str | Path | None = None,
                 arms: tuple[str, ...] | None = None, progress: Callable[[int], None] | None = None,
                 plant: Callable[[Scenario, Any], Any] | None = None) -> list[ArmResult]:
    """Every arm of ``scenario`` (or those named in ``arms``), each on a fresh plant and regulator."""
    from scenarios.plantio import load_plant_model

    model, summary = load_plant_model(scenario)
    results = []
    for arm in scenario.arms:
        if arms is not None and arm.name not in arms:
            continue
        results.append(run_arm(scenario, arm, make_regulator(regulator, fmu_path), progress=progress,
                               model=model, model_summary=summary, plant=plant))
    return results
