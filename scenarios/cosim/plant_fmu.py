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
from typing import Any, Mapping

from scenarios.errors import CosimError
from plant.constants import OFFSET_NAMES as OFFSET_NAMES
from fmu_src.plant_fmu.fmu_core import INPUT_NAMES, MODEL_FILES, PLANT_STEP_S, values_from_perturbation
from scenarios.cosim.fmi_host import FmuInstance

#: The native CassiePlant's String parameter holding the height-field file's path
#: (docs/native.md), and the name the master gives the file it writes.
FIELD_PARAMETER = "terrain_field_file"
FIELD_FILE_NAME = "terrain_field.cptf"
REGULATOR_NAMES = ("vx", "vy", "pitch", "roll", "pitch_rate", "roll_rate", "step_index")


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
        super().__init__(fmu_path, instance_name, unpack_dir=unpack_dir)
        self._inputs = {n: 0.0 for n in INPUT_NAMES}
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
        """ctypes arrays for the per-step calls (value references from the model description)."""
        from ctypes import c_double, c_int

        self._in_vrs = self._vr_array([self.vars[n].valueReference for n in INPUT_NAMES])
        self._in_vals = (c_double * len(INPUT_NAMES))()
        fmu = self._fmu
        self._out = []
        for kind, ctype, getter in (("Real", c_double, fmu.fmi2GetReal), ("Integer", c_int, fmu.fmi2GetInteger),
                                    ("Boolean", c_int, fmu.fmi2GetBoolean)):
            names = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type == kind]
            vrs = self._vr_array([self.vars[n].valueReference for n in names])
            self._out.append((f"fmi2Get{kind} (outputs)", getter, names, vrs, (ctype * len(names))()))

    def _read_outputs(self) -> None:
        comp, values = self._fmu.component, {}
        for what, getter, names, vrs, buffer in self._out:
            self._call(what, getter, comp, vrs, len(names), buffer)
            values.update(zip(names, buffer))
        values["fell"] = bool(values["fell"])
        self.out = values

    # ---- the walker's interface
    def set_command(self, vx_des: float, vy_des: float, yaw_rate_des: float = 0.0) -> None:
        self.vx_des, self.vy_des = float(vx_des), float(vy_des)
        self.yaw_rate_des = float(yaw_rate_des)
        self._inputs.update(vx_des=self.vx_des, vy_des=self.vy_des, yaw_rate_des=self.yaw_rate_des)

    def set_offsets(self, offsets: Mapping[str, float]) -> None:
        unknown = [k for k in offsets if k not in OFFSET_NAMES]
        if unknown:
            raise KeyError(f"unknown offset key(s) {unknown}; allowed: {', '.join(OFFSET_NAMES)}")
        self._inputs.update({k: float(v) for k, v in offsets.items()})

    def set_pelvis_force(self, force_n) -> None:
        fx, fy, fz = (float(f) for f in force_n)
        self._inputs.update(push_fx=fx, push_fy=fy, push_fz=fz)

    def advance(self, n_steps: int) -> None:
        h = int(n_steps) * self.SIM_DT_S
        fmu = self._fmu
        self._t = self.time_s
        for i, name in enumerate(INPUT_NAMES):
            self._in_vals[i] = self._inputs[name]
        self._call("fmi2SetReal (inputs)", fmu.fmi2SetReal, fmu.component, self._in_vrs, len(INPUT_NAMES),
                   self._in_vals)
        self._call("fmi2DoStep", fmu.fmi2DoStep, fmu.component, self.time_s, h, 1)
        self.time_s += h
        self._read_outputs()

    def regulator_inputs(self) -> dict:
        out = {n: self.out[n] for n in REGULATOR_NAMES}
        out["step_index"] = int(out["step_index"])
        return out

    def telemetry(self) -> dict:
        o = self.out
        return {"t": o["plant_time"], "pelvis_x": o["pelvis_x"], "pelvis_y": o["pelvis_y"], "pelvis_z": o["pelvis_z"],
                "vx": o["pelvis_vx"], "vy": o["pelvis_vy"], "vx_step_avg": o["vx"], "vy_signal": o["vy"],
                "pitch": o["pitch"], "roll": o["roll"], "stance": float(o["stance"]), "tau": o["gait_phase"],
                "step_index": float(o["step_index"]), "left_foot_force": o["left_foot_force"],
                "right_foot_force": o["right_foot_force"], "vx_des": self.vx_des, "vy_des": self.vy_des,
                "yaw": o["yaw"], "yaw_rate": o["yaw_rate"], "yaw_rate_des": self.yaw_rate_des}

    def fell(self) -> bool:
        return bool(self.out["fell"])

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
