"""The regulator paths the master's loop drives: the FMU or the core in-process.

- :class:`FmuRegulator`: a co-simulation FMU through :class:`scenarios.cosim.fmi_host.FmuInstance`
  (``--regulator fmu``: the pythonfmu FMU, ``native``: the native FMI 2.0 FMU,
  ``native-fmi3``: the native FMI 3.0 FMU): parameters set by name with type-correct
  calls, the per-step calls bound straight to the library;
- :class:`InProcessRegulator`: the numpy regulator core called directly, with the FMU's
  data flow and casts.

The pythonfmu FMU and the core in-process give bit-identical trajectories for the same
scenario and seed; the native FMUs (C) agree with them to rounding (see
tests/support/native/test_native_master.py).
"""
from __future__ import annotations

import abc
import operator
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from plant.interface import REGULATOR_INPUT_NAMES
from scenarios.errors import CosimError
from scenarios.cosim.fmi_api import FMI_CASTS
from scenarios.cosim.fmi_host import FmuInstance
from scenarios.cosim.fmus import REGULATOR_FMUS

REGULATORS = (*REGULATOR_FMUS, "inprocess")
#: The regulator inputs the master gives, in the order of :meth:`RegulatorPath.step_values`:
#: the plant's sensed inputs (``step_index`` an int), then the command.
MASTER_INPUTS = (*REGULATOR_INPUT_NAMES, "vx_des", "vy_des")


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

    def step_values(self, t: float, h: float, values: Sequence[Any]) -> list[float]:
        """:meth:`step` with the inputs as numbers in :data:`MASTER_INPUTS`' order and the
        outputs in :meth:`output_names`' order (the master's per-step call: no names)."""
        out = self.step(t, h, dict(zip(MASTER_INPUTS, values, strict=True)))
        return [out[n] for n in self.output_names()]

    @abc.abstractmethod
    def close(self) -> None: ...

    def __enter__(self) -> "RegulatorPath":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class InProcessRegulator(RegulatorPath):
    """The regulator core called directly, with the FMU's data flow and casts."""

    kind = "inprocess"

    def __init__(self) -> None:
        from fmu_src.core.avr_params import RegulatorInputs
        from fmu_src.core.avr_specs import INPUT_SPECS, OUTPUT_SPECS

        self._inputs_type = RegulatorInputs
        self._input_types = [(s.name, FMI_CASTS[s.type]) for s in INPUT_SPECS]
        self._outputs = tuple(s.name for s in OUTPUT_SPECS)
        self._step_fn: Callable[[Any, float], dict] | None = None

    def output_names(self) -> tuple[str, ...]:
        return self._outputs

    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        from fmu_src.core.avr_core import Regulator
        from fmu_src.core.avr_params import params_from_overrides
        from fmu_src.core.avr_specs import PARAM_SPECS

        types = {s.name: FMI_CASTS[s.type] for s in PARAM_SPECS}
        unknown = sorted(set(parameters) - set(types))
        if unknown:
            raise CosimError(f"unknown regulator parameter(s): {', '.join(unknown)}")
        # cast as the FMU's setters do, then the core's own defaults and checks
        params = params_from_overrides({n: types[n](v) for n, v in parameters.items()})
        self._step_fn = Regulator(params).step

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        reg_in = self._inputs_type(**{n: cast(inputs[n]) for n, cast in self._input_types})
        out = self._step_fn(reg_in, float(h))
        return {n: float(out[n]) for n in self._outputs}

    def close(self) -> None:
        self._step_fn = None


class FmuRegulator(FmuInstance, RegulatorPath):
    """The FMU through fmpy's FMU2Slave or FMU3Slave; every FMI call's status is checked."""

    kind = "fmu"
    FMI_VERSIONS = ("2.0", "3.0")

    def __init__(self, fmu_path: str | Path, instance_name: str = "avr", *, unpack_dir: str | Path | None = None,
                 fmi_versions: tuple[str, ...] | None = None) -> None:
        """``unpack_dir``: the folder under which :meth:`start` extracts the FMU (a fresh
        subfolder, removed by :meth:`close`); None: the system temp folder.
        ``fmi_versions``: the FMI versions accepted (default: 2.0 and 3.0)."""
        super().__init__(fmu_path, instance_name, unpack_dir=unpack_dir, fmi_versions=fmi_versions)
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
            elif self.fmi.kind_of(var.type) is None:
                problems.append(f"{name}: type {var.type}, not one of {', '.join(self.fmi.type_names.values())}")
        if problems:
            raise CosimError("cannot set FMU parameters: " + "; ".join(problems))

    def _set_parameters(self, parameters: Mapping[str, Any]) -> None:
        """One set call per type (value references from the model description)."""
        by_kind: dict[str, tuple[list[int], list[Any]]] = {k: ([], []) for k in FMI_CASTS}
        for name, value in parameters.items():
            var = self.vars[name]
            vrs, vals = by_kind[self.fmi.kind_of(var.type)]
            vrs.append(var.valueReference)
            vals.append(value)
        for kind, (vrs, vals) in by_kind.items():
            self._set(f"{self.fmi.function('Set', kind)} (parameters)", kind, vrs, vals)

    def _variables(self, causality: str, kind: str) -> list[str]:
        return [v.name for v in self.md.modelVariables
                if v.causality == causality and self.fmi.kind_of(v.type) == kind]

    def _prepare_buffers(self) -> None:
        """Preallocated ctypes buffers for the per-step calls (Real and Integer inputs,
        Real outputs); any other input or output type is refused."""
        kinds = {"input": ("Real", "Integer"), "output": ("Real",)}
        odd = [f"{v.name} ({v.causality} {v.type})" for v in self.md.modelVariables
               if v.causality in kinds and self.fmi.kind_of(v.type) not in kinds[v.causality]]
        if odd:
            raise CosimError("the master passes Real and Integer inputs and Real outputs only: " + ", ".join(odd))
        self._in_real = self._variables("input", "Real")
        self._in_int = self._variables("input", "Integer")
        self._val_in_real = (self.fmi.ctypes["Real"] * len(self._in_real))()
        self._val_in_int = (self.fmi.ctypes["Integer"] * len(self._in_int))()
        self._val_out = (self.fmi.ctypes["Real"] * len(self._outputs))()
        comp, vrs = self._fmu.component, lambda names: self._vr_array([self.vars[n].valueReference for n in names])
        self._args_in_real = self.fmi.array_args(comp, vrs(self._in_real), self._val_in_real)
        self._args_in_int = self.fmi.array_args(comp, vrs(self._in_int), self._val_in_int)
        self._args_out = self.fmi.array_args(comp, vrs(self._outputs), self._val_out)
        given = {n: i for i, n in enumerate(MASTER_INPUTS)}
        if all(n in given for n in (*self._in_real, *self._in_int)):
            self._real_from = _picker([given[n] for n in self._in_real])
            self._int_from = [given[n] for n in self._in_int]
        else:
            self._real_from, self._int_from = None, []

    def _bind_step_calls(self) -> None:
        """The four per-step FMI functions as ctypes prototypes on the loaded library,
        called directly by :meth:`step` on the preallocated arguments through ``FmuInstance._bound``,
        which checks their statuses (fmpy's Python wrapper around each call cost about 1.5 us, 5 us a step).
        :meth:`close` drops them before the library is unloaded."""
        dll, fmi = self._fmu.dll, self.fmi
        self._set_real = fmi.array_function(dll, "Set", "Real")
        self._get_real = fmi.array_function(dll, "Get", "Real")
        self._set_int = fmi.array_function(dll, "Set", "Integer")
        self._do_step, self._do_step_tail, self._check_step = fmi.bind_do_step(dll)
        self._names = {op + kind: f"{fmi.function(op, kind)} ({what})"
                       for op, kind, what in (("Set", "Real", "inputs"), ("Set", "Integer", "inputs"),
                                              ("Get", "Real", "outputs"))}

    def step(self, t: float, h: float, inputs: Mapping[str, Any]) -> dict[str, float]:
        return dict(zip(self._outputs, self._exchange(t, h, [float(inputs[n]) for n in self._in_real],
                                                      [int(inputs[n]) for n in self._in_int])))

    def step_values(self, t: float, h: float, values: Sequence[Any]) -> list[float]:
        if self._real_from is None:  # an FMU with inputs the master does not give: by name (KeyError)
            return super().step_values(t, h, values)
        return self._exchange(t, h, self._real_from(values), [int(values[i]) for i in self._int_from])

    def _exchange(self, t: float, h: float, reals: Sequence[float], ints: Sequence[int]) -> list[float]:
        """Set the Real and Integer inputs (in ``_in_real``/``_in_int``'s order; the Integers only
        when one changed), step, return the Real outputs (in ``_outputs``' order)."""
        self._t = t
        self._val_in_real[:] = reals
        int_changed = self._first_step
        for i, v in enumerate(ints):
            if v != self._val_in_int[i]:
                self._val_in_int[i] = v
                int_changed = True
        if self._in_real:
            self._bound(self._names["SetReal"], self._set_real, self._args_in_real)
        if self._in_int and int_changed:  # step_index changes once a walking step: FMU inputs keep their value
            self._bound(self._names["SetInteger"], self._set_int, self._args_in_int)
        self._first_step = False
        self._bound(f"{self.fmi.prefix}DoStep", self._do_step, (self._fmu.component, t, h, *self._do_step_tail))
        if self._check_step is not None:
            problem = self._check_step(t, h)
            if problem:
                raise self._fail(f"{self.fmi.prefix}DoStep", problem)
        self._bound(self._names["GetReal"], self._get_real, self._args_out)
        return self._val_out[:]

    def _drop_bound_calls(self) -> None:
        self._set_real = self._get_real = self._set_int = self._do_step = self._check_step = None


def _picker(at: list[int]) -> Callable[[Sequence[Any]], Sequence[Any]]:
    """The values at the positions ``at`` of a sequence, as a sequence (however many)."""
    if len(at) >= 2:
        return operator.itemgetter(*at)
    return lambda values: [values[i] for i in at]


class RlHzdRegulator(RegulatorPath):
    """The fixed RL-HZD policy (:mod:`scenarios.rl_hzd.policy`) in-process: the six offsets."""

    kind = "rl_hzd"

    def __init__(self, policy_path: str | Path | None = None) -> None:
        from fmu_src.core.avr_params import RegulatorInputs
        from plant.constants import OFFSET_NAMES
        from scenarios.rl_hzd.policy import DEFAULT_POLICY

        self._inputs = RegulatorInputs
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
        return self._policy.step(self._inputs(**inputs), float(h))

    def close(self) -> None:
        self._policy = None


def arm_regulator(arm, kind: str, fmu_path: str | Path | None = None, *,
                  unpack_dir: str | Path | None = None) -> RegulatorPath:
    """The path that drives ``arm``: the RL-HZD policy for an ``rl_hzd`` arm, else
    :func:`make_regulator` of ``kind``."""
    if arm.controller == "rl_hzd":
        return RlHzdRegulator()
    return make_regulator(kind, fmu_path, unpack_dir=unpack_dir)


def make_regulator(kind: str, fmu_path: str | Path | None = None, *,
                   unpack_dir: str | Path | None = None) -> RegulatorPath:
    """``unpack_dir``: where an FMU is extracted (see :class:`FmuRegulator`)."""
    if kind in REGULATOR_FMUS:  # every FMU the same FMI path, of the kind's FMI version
        if fmu_path is None:
            raise CosimError(f"the {kind} regulator path needs an FMU file (fmu_path)")
        return FmuRegulator(fmu_path, unpack_dir=unpack_dir, fmi_versions=(REGULATOR_FMUS[kind].fmi_version,))
    if kind == "inprocess":
        return InProcessRegulator()
    raise CosimError(f"regulator = {kind!r}: must be one of {', '.join(REGULATORS)}")
