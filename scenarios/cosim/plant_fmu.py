"""``--plant fmu``: the CassiePlant FMU in our master, behind the walker's interface.

:class:`FmuPlant` implements :class:`plant.interface.Plant`, what
:func:`scenarios.cosim.master.run_arm` uses of a plant (as :class:`plant.sim.CassieWalker`
does), so the same loop runs the plant in-process or as an FMU
(through fmpy, every status checked, the FMU's messages in the error).  Inputs set
between two ``advance`` calls are held over the next ``fmi2DoStep``; outputs are read
after it.  The same scenario gives the same rows bit for bit with either plant: the
FMU runs the same code at the same plant step, and the master's data flow (sense,
regulate, apply, advance: Gauss-Seidel) does not change.

The scenario's plant (its ``model`` key and perturbation) becomes the FMU's parameters
(``cassie_model``, ``torso_mass_kg``, ...) through
:func:`fmu_src.plant_fmu.fmu_core.values_from_perturbation`; a model given as an MJCF path cannot go
into the FMU (its models travel inside it) and is refused.  The native CassiePlant FMU
cannot generate uneven terrain: for it the height field is written here and handed over
in its ``terrain_field_file`` parameter (:meth:`FmuPlant._with_terrain_field`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

from scenarios.errors import CosimError
from plant.constants import OFFSET_NAMES as OFFSET_NAMES
from plant.interface import inputs_of, signal_pickers, telemetry_of
from fmu_src.plant_fmu.fmu_core import INPUT_NAMES, MODEL_FILES, PLANT_STEP_S, values_from_perturbation
from scenarios.cosim.fmi_host import FmuInstance

#: The native CassiePlant's String parameter holding the height-field file's path
#: (docs/native.md), and the name the master gives the file it writes.
FIELD_PARAMETER = "terrain_field_file"
FIELD_FILE_NAME = "terrain_field.cptf"
#: The FMU output behind each telemetry value (by name in ``TELEMETRY_NAMES``) that is an output
#: of another name; ``vx_des``, ``vy_des`` and ``yaw_rate_des`` are the command the master set.
TELEMETRY_OUTPUTS = {"t": "plant_time", "vx": "pelvis_vx", "vy": "pelvis_vy", "vx_step_avg": "vx",
                     "vy_signal": "vy", "tau": "gait_phase"}


def fmu_parameters(scenario, torso_mass_kg: float | None = None) -> dict:
    """The CassiePlant parameters of ``scenario`` (its model and perturbation).

    ``torso_mass_kg``: the torso mass the plant applied for this scenario (``plant.perturbation.
    torso_mass_kg`` of its compiled model); if None, a ``torso_added_mass_kg`` is added to the
    nominal torso mass of the models the FMU holds (``plant.constants.NOMINAL_TORSO_MASS_KG``).
    """
    import dataclasses

    from plant.constants import NOMINAL_TORSO_MASS_KG
    from plant.perturbation import Perturbation, resolved
    from scenarios.lang.plantio import build_perturbation

    if scenario.model not in MODEL_FILES:
        raise CosimError(f"model = {scenario.model!r}: the CassiePlant FMU holds {', '.join(MODEL_FILES)} only "
                         "(an MJCF path needs --plant inprocess)")
    pert = build_perturbation(scenario)
    if torso_mass_kg is not None:
        pert = dataclasses.replace(pert or Perturbation(), torso_mass_kg=torso_mass_kg, torso_added_mass_kg=None)
    elif pert is not None:
        pert = resolved(pert, NOMINAL_TORSO_MASS_KG)
    return values_from_perturbation(scenario.model, pert)


class FmuPlant(FmuInstance):
    """The CassiePlant FMU as a :class:`plant.interface.Plant` (see the module docstring);
    ``close`` (:class:`FmuInstance`) frees the instance and its extracted folder."""

    kind = "fmu-plant"
    SIM_DT_S = PLANT_STEP_S

    def __init__(self, fmu_path: str | Path, parameters: Mapping[str, Any], instance_name: str = "plant", *,
                 unpack_dir: str | Path | None = None):
        """``unpack_dir``: where the FMU is extracted (a fresh subfolder, removed by ``close``)."""
        from ctypes import c_double

        super().__init__(fmu_path, instance_name, unpack_dir=unpack_dir)
        #: The inputs held over the next doStep (INPUT_NAMES' order), set in place by the setters.
        self._in_vals = (c_double * len(INPUT_NAMES))()
        self._in_at = {n: i for i, n in enumerate(INPUT_NAMES)}
        self._offsets_at = [self._in_at[n] for n in OFFSET_NAMES]
        self.vx_des = self.vy_des = self.yaw_rate_des = 0.0
        self.time_s = 0.0
        self.start(parameters, 0.0, 0.0)

    # ---- life cycle: parameters of every type, outputs of every type
    def start(self, parameters: Mapping[str, Any], t0: float, t_stop: float) -> None:
        unknown = sorted(n for n in parameters if n not in self.vars or self.vars[n].causality != "parameter")
        if unknown:
            raise CosimError(f"CassiePlant has no parameter(s) {', '.join(unknown)}")
        self._instantiate()
        parameters = self._with_terrain_field(parameters)
        fmu = self._fmu
        for name, value in parameters.items():
            var = self.vars[name]
            setter = {"Real": fmu.setReal, "Integer": fmu.setInteger, "Boolean": fmu.setBoolean,
                      "String": fmu.setString}[var.type]
            self._call(f"fmi2Set{var.type} ({name})", setter, [var.valueReference], [value])
        self._initialize(t0, None)  # no stop time: the master decides when to stop
        self.time_s = float(t0)
        self._prepare_buffers()
        self._read_outputs()

    def _with_terrain_field(self, parameters: Mapping[str, Any]) -> Mapping[str, Any]:
        """``parameters`` with ``terrain_field_file`` set, when the FMU takes the terrain as a
        file (the native CassiePlant: it declares that parameter) and the parameters ask for
        terrain (``terrain_max_height_m`` > 0) without naming a file: the field of their
        ``terrain_*`` values (:func:`plant.terrain.write_field`) is written into this
        instance's extracted folder (under ``unpack_dir``: the run's scratch folder), which
        :meth:`close` removes.  Any other FMU or parameter set is returned unchanged."""
        var = self.vars.get(FIELD_PARAMETER)
        if var is None or var.causality != "parameter" or parameters.get(FIELD_PARAMETER):
            return parameters
        from fmu_src.plant_fmu.fmu_core import PARAM_DEFAULTS, perturbation_from_values
        from plant.terrain import write_field

        terrain = perturbation_from_values({**PARAM_DEFAULTS, **parameters}).terrain
        if terrain is None:
            return parameters
        path = write_field(terrain, Path(self._unzip) / FIELD_FILE_NAME)
        return {**parameters, FIELD_PARAMETER: path}

    def _prepare_buffers(self) -> None:
        """The per-step calls bound straight to the library (as the regulator's:
        ``FmuRegulator._bind_step_calls``) on preallocated arrays (value references from the
        model description), and which outputs :meth:`signals` picks."""
        fmu, fmi, comp = self._fmu, self.fmi, self._fmu.component
        vrs = lambda names: self._vr_array([self.vars[n].valueReference for n in names])  # noqa: E731
        self._set_inputs = ("fmi2SetReal (inputs)", fmi.array_function(fmu.dll, "Set", "Real"),
                            fmi.array_args(comp, vrs(INPUT_NAMES), self._in_vals))
        self._do_step, self._do_step_tail, _ = fmi.bind_do_step(fmu.dll)
        self._gets, names = [], []
        for kind in ("Real", "Integer", "Boolean"):
            kind_names = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type == kind]
            values = (fmi.ctypes[kind] * len(kind_names))()
            self._gets.append((f"fmi2Get{kind} (outputs)", fmi.array_function(fmu.dll, "Get", kind),
                               fmi.array_args(comp, vrs(kind_names), values), values))
            names += kind_names
        self._out_names = tuple(names)
        self._head, self._tail = signal_pickers(names, telemetry_from=TELEMETRY_OUTPUTS)
        self._fell_at = names.index("fell")

    def _read_outputs(self) -> None:
        values: list = []
        for what, fn, args, buffer in self._gets:
            self._bound(what, fn, args)
            values += buffer
        self._values = values

    def _drop_bound_calls(self) -> None:
        self._set_inputs = self._do_step = None
        self._gets = []

    @property
    def out(self) -> dict[str, Any]:
        """Every output by name after the last step (``fell`` a bool)."""
        out = dict(zip(self._out_names, self._values))
        out["fell"] = bool(out["fell"])
        return out

    # ---- the walker's interface
    def set_command(self, vx_des: float, vy_des: float, yaw_rate_des: float = 0.0) -> None:
        self.vx_des, self.vy_des = float(vx_des), float(vy_des)
        self.yaw_rate_des = float(yaw_rate_des)
        self._hold({"vx_des": self.vx_des, "vy_des": self.vy_des, "yaw_rate_des": self.yaw_rate_des})

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        unknown = [k for k in offsets if k not in OFFSET_NAMES]
        if unknown:
            raise KeyError(f"unknown offset key(s) {unknown}; allowed: {', '.join(OFFSET_NAMES)}")
        self._hold({k: float(v) for k, v in offsets.items()})

    def set_offset_values(self, values: Sequence[float]) -> None:
        at, held = self._offsets_at, self._in_vals
        if len(values) != len(at):
            raise ValueError(f"{len(values)} offsets given, {len(at)} due ({', '.join(OFFSET_NAMES)})")
        values = [float(v) for v in values]  # all converted before any is held
        for i, v in zip(at, values):
            held[i] = v

    def set_pelvis_force(self, force_n) -> None:
        fx, fy, fz = (float(f) for f in force_n)
        self._hold({"push_fx": fx, "push_fy": fy, "push_fz": fz})

    def _hold(self, values: Mapping[str, float]) -> None:
        """Inputs by name, held over the next doStep."""
        for name, value in values.items():
            self._in_vals[self._in_at[name]] = value

    def advance(self, n_steps: int) -> None:
        h = int(n_steps) * self.SIM_DT_S
        self._t = self.time_s
        self._bound(*self._set_inputs)
        self._bound("fmi2DoStep", self._do_step, (self._fmu.component, self.time_s, h, *self._do_step_tail))
        self.time_s += h
        self._read_outputs()

    def signals(self) -> tuple:
        values = self._values
        return (*self._head(values), self.vx_des, self.vy_des, *self._tail(values), self.yaw_rate_des)

    def regulator_inputs(self) -> dict:
        return inputs_of(self.signals())

    def telemetry(self) -> dict:
        return telemetry_of(self.signals())

    def fell(self) -> bool:
        return bool(self._values[self._fell_at])

    @property
    def fall_reason(self) -> str | None:
        if not self.fell():
            return None
        said = [m for m in self.messages if "CassiePlant fell at t = " in m]  # the FMU logs the reason once
        return said[-1].split(" s: ", 1)[-1] if said else "fell (CassiePlant FMU output)"


def plant_factory(fmu_path: str | Path, unpack_dir: str | Path | None = None):
    """A ``plant(scenario, model)`` for :func:`scenarios.cosim.master.run_arm` that runs the FMU
    (extracted under ``unpack_dir``, the system temp folder if None). ``model`` is the scenario's
    plant compiled with its perturbation: the FMU gets the torso mass the plant applied on it."""
    def make(scenario, model) -> FmuPlant:
        from plant.perturbation import torso_mass_kg

        return FmuPlant(fmu_path, fmu_parameters(scenario, torso_mass_kg(model)), unpack_dir=unpack_dir)
    return make
