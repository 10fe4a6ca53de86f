"""The regulator paths the master's loop drives: the FMU or the core in-process.

- :class:`FmuRegulator`: the FMI 2.0 co-simulation FMU (the pythonfmu or the native
  one) through :class:`scenarios.fmi_host.FmuInstance`: parameters set by name with
  type-correct calls, the per-step calls bound straight to the library;
- :class:`InProcessRegulator`: the numpy regulator core called directly, with the FMU's
  data flow and casts.

Both give bit-identical trajectories for the same scenario and seed.
"""
from __future__ import annotations

import abc
from pathlib import Path
from typing import Any, Callable, Mapping

from scenarios.errors import CosimError
from scenarios.fmi_host import FMI_CASTS, FmuInstance

REGULATORS = ("fmu", "native", "inprocess")


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


def _fmi_type(spec) -> str:
    kind = str(spec.type).lower()
    return "Boolean" if kind.startswith("bool") else "Integer" if kind.startswith("int") else "Real"


class InProcessRegulator(RegulatorPath):
    """The regulator core called directly, with the FMU's data flow and casts."""

    kind = "inprocess"

    def __init__(self) -> None:
        from fmu_src import avr_core

        self._core = avr_core
        self._input_types = [(s.name, FMI_CASTS[_fmi_type(s)]) for s in self._core.INPUT_SPECS]
        self._outputs = tuple(s.name for s in self._core.OUTPUT_SPECS)
        self._step_fn: Callable[[Any, float], dict] | None = None

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        core = self._core
        types = {s.name: FMI_CASTS[_fmi_type(s)] for s in core.PARAM_SPECS}
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


class FmuRegulator(FmuInstance, RegulatorPath):
    """The FMU through fmpy's FMU2Slave; every FMI call's status is checked."""

    kind = "fmu"

    def __init__(self, fmu_path: str | Path, instance_name: str = "avr", *, unpack_dir: str | Path | None = None) -> None:
        """``unpack_dir``: the folder under which :meth:`start` extracts the FMU (a fresh
        subfolder, removed by :meth:`close`); None: the system temp folder."""
        super().__init__(fmu_path, instance_name, unpack_dir=unpack_dir)
        self._outputs = tuple(v.name for v in self.md.modelVariables if v.causality == "output")

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    # ---- life cycle
    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        self._check_parameter_names(parameters)
        self._instantiate()
        self._set_parameters(parameters)
        self._initialize(t0, t_stop)
        self._prepare_buffers()
        self._first_step = True
        self._bind_step_calls()

    def _check_parameter_names(self, parameters: Mapping[str, Any]) -> None:
        problems = []
        for name in parameters:
            var = self.vars.get(name)
            if var is None:
                problems.append(f"{name}: the FMU has no such variable")
            elif var.causality != "parameter":
                problems.append(f"{name}: causality {var.causality}, not a parameter")
        if problems:
            raise CosimError("cannot set FMU parameters: " + "; ".join(problems))

    def _set_parameters(self, parameters: Mapping[str, Any]) -> None:
        """One fmi2Set call per type (value references from the model description)."""
        by_type: dict[str, tuple[list[int], list[Any]]] = {"Real": ([], []), "Integer": ([], []), "Boolean": ([], [])}
        for name, value in parameters.items():
            var = self.vars[name]
            vrs, vals = by_type[var.type]
            vrs.append(var.valueReference)
            vals.append(FMI_CASTS[var.type](value))
        for kind, (vrs, vals) in by_type.items():
            self._set(f"fmi2Set{kind} (parameters)", kind, vrs, vals)

    def _prepare_buffers(self) -> None:
        """Preallocated ctypes buffers for the per-step calls (Real and Integer inputs, Real outputs)."""
        from ctypes import c_double, c_int

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

    def _drop_bound_calls(self) -> None:
        self._set_real = self._get_real = self._set_int = self._do_step = None


class RlHzdRegulator(RegulatorPath):
    """The fixed RL-HZD policy (:mod:`scenarios.rl_hzd.policy`) in-process: the six offsets."""

    kind = "rl_hzd"

    def __init__(self, policy_path: str | Path | None = None) -> None:
        from plant.constants import OFFSET_NAMES
        from scenarios.rl_hzd.policy import DEFAULT_POLICY

        self._path = Path(policy_path or DEFAULT_POLICY)
        self._outputs = OFFSET_NAMES
        self._policy = None

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        from scenarios.rl_hzd.policy import load_policy

        if parameters:
            raise CosimError(f"the rl_hzd arm takes no regulator parameters, got {', '.join(sorted(parameters))}")
        try:
            self._policy = load_policy(self._path)
        except (OSError, ValueError, KeyError) as exc:
            raise CosimError(f"cannot load the RL-HZD policy {self._path}: {exc}") from exc

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        from fmu_src.avr_core import RegulatorInputs

        return self._policy.step(RegulatorInputs(**inputs), float(h))

    def close(self) -> None:
        self._policy = None


def arm_regulator(arm, kind: str, fmu_path: str | Path | None = None, *,
                  unpack_dir: str | Path | None = None) -> RegulatorPath:
    """The path that drives ``arm``: the RL-HZD policy for an ``rl_hzd`` arm, else
    :func:`make_regulator` of ``kind``."""
    if getattr(arm, "controller", "regulator") == "rl_hzd":
        return RlHzdRegulator()
    return make_regulator(kind, fmu_path, unpack_dir=unpack_dir)


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
