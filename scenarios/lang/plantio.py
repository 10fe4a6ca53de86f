"""The scenario -> plant mapping: the plant's Perturbation and the compiled model.

Pushes are not part of the plant's ``Perturbation``: the master switches them on and
off itself (``CassieWalker.set_pelvis_force``) on communication-step boundaries.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import os
from typing import TYPE_CHECKING, Any

from plant.errors import ModelError

if TYPE_CHECKING:  # pragma: no cover
    import mujoco

    from plant.perturbation import Perturbation
    from scenarios.lang.scenario import Scenario

log = logging.getLogger(__name__)


def build_perturbation(scenario: "Scenario") -> "Perturbation | None":
    """The plant Perturbation of ``scenario`` (None when the plant is nominal). A
    ``torso_added_mass_kg`` goes to the plant as it is: the plant adds it to its own model's
    torso mass (:func:`plant.perturbation.apply_to_compiled`)."""
    t = scenario.terrain
    terrain = None if t is None else dataclasses.asdict(t)  # Terrain's fields are TerrainSpec's
    pert = _perturbation(scenario.torso_mass_kg, scenario.torso_added_mass_kg, scenario.torso_com_offset_m,
                         scenario.joint_damping_scale, terrain, **environment_values(scenario))
    return None if pert.is_nominal else pert


def environment_values(scenario: "Scenario") -> dict[str, Any]:
    """The scenario's floor and link mass values as the plant's Perturbation fields."""
    return {"floor_friction": scenario.floor_friction, "slope_deg": scenario.slope_deg,
            "cross_slope_deg": scenario.cross_slope_deg, "link_masses": scenario.link_masses}


def perturbation_problems(torso_mass_kg: float | None, torso_added_mass_kg: float | None,
                          torso_com_offset_m, joint_damping_scale: float,
                          terrain: dict[str, Any] | None, **environment) -> list[str]:
    """The plant's own problems with these perturbation values (``terrain``: the
    TerrainSpec's fields; ``environment``: :func:`environment_values`), on the plant's
    nominal torso mass."""
    from plant.constants import NOMINAL_TORSO_MASS_KG

    return _perturbation(torso_mass_kg, torso_added_mass_kg, torso_com_offset_m, joint_damping_scale,
                         terrain, **environment).problems(NOMINAL_TORSO_MASS_KG)


def _perturbation(torso_mass_kg, torso_added_mass_kg, torso_com_offset_m, joint_damping_scale, terrain,
                  floor_friction=None, slope_deg=0.0, cross_slope_deg=0.0, link_masses=()) -> "Perturbation":
    """The one place that builds the plant's Perturbation (and TerrainSpec) from scenario values."""
    from plant.perturbation import Perturbation
    from plant.terrain import TerrainSpec

    return Perturbation(
        torso_mass_kg=torso_mass_kg,
        torso_added_mass_kg=torso_added_mass_kg,
        torso_com_offset_m=tuple(torso_com_offset_m),
        joint_damping_scale=joint_damping_scale,
        terrain=None if terrain is None else TerrainSpec(**terrain),
        floor_friction=floor_friction, slope_deg=slope_deg, cross_slope_deg=cross_slope_deg,
        link_mass_scale=tuple((lm.body, lm.scale) for lm in link_masses if lm.scale is not None),
        link_mass_kg=tuple((lm.body, lm.mass_kg) for lm in link_masses if lm.mass_kg is not None),
    )


def check_plant(scenario: "Scenario") -> list[tuple[str, str]]:
    """``(field, problem)`` for everything loading the plant of ``scenario`` would fail on:
    the model must parse safely, compile and be a Cassie (:func:`plant.model.load_model`),
    and the perturbation must be valid on that model (its own torso mass for
    ``torso_added_mass_kg``, which the check's compile reports). The compiled model is cached
    per process."""
    mass, problem = _base_model_check(scenario.model, _file_stamp(scenario.model))
    if problem is not None:
        return [("model", problem)]
    pert = build_perturbation(scenario)
    found = [("perturbation", p) for p in (pert.problems(mass) if pert is not None else [])]
    return found + body_problems(scenario)


def body_problems(scenario: "Scenario") -> list[tuple[str, str]]:
    """``(field, problem)`` for every link mass or push naming a body the scenario's model
    does not have (the compiled model is the cached one of :func:`check_plant`)."""
    named = [(f"link_mass[{i}].body", lm.body) for i, lm in enumerate(scenario.link_masses)]
    named += [(f"push[{i}].body", p.body) for i, p in enumerate(scenario.pushes) if p.body != "cassie-pelvis"]
    if not named:
        return []
    bodies = _model_bodies(scenario.model, _file_stamp(scenario.model))
    if bodies is None:
        return []
    out = []
    for field, body in named:
        if body not in bodies or body in ("world",):
            out.append((field, f"{body!r}: the model has no such body; its bodies: {', '.join(bodies[1:])}"))
        elif field.startswith("link_mass") and body == "cassie-pelvis":
            out.append((field, f"{body!r}: the pelvis mass is torso_mass_kg / torso_added_mass_kg"))
    return out


def _model_bodies(model: str, stamp: tuple | None) -> tuple[str, ...] | None:
    """The body names of ``model`` (world first), or None when it does not load (its own
    problem is reported by :func:`_base_model_check`)."""
    m = _base_model(model, stamp)
    return None if isinstance(m, ModelError) else tuple(m.body(i).name for i in range(m.nbody))


def _file_stamp(model: str) -> tuple | None:
    """What the cached check of ``model`` depends on besides its name: the file's mtime and
    size (the OSU file's for ``osu``), or the Menagerie folder the loader uses."""
    from plant.model import menagerie_root, osu_model_path

    if model == "menagerie":
        root = menagerie_root()
        return ("menagerie", None if root is None else str(root))
    try:
        st = os.stat(osu_model_path() if model == "osu" else model)
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


@functools.lru_cache(maxsize=8)
def _base_model(model: str, stamp: tuple | None) -> "mujoco.MjModel | ModelError":
    """``model`` compiled without a perturbation, once per process and stamp (callers only read
    it), or why it is not a Cassie model that loads."""
    from plant.model import load_model

    try:
        return load_model(model)
    except ModelError as exc:  # the model's problem, reported by _base_model_check
        return exc


def _base_model_check(model: str, stamp: tuple | None) -> tuple[float | None, str | None]:
    """(its torso mass, None) when ``model`` loads as a Cassie, else (None, the reason)."""
    from plant.perturbation import torso_mass_kg

    m = _base_model(model, stamp)
    return (None, str(m)) if isinstance(m, ModelError) else (torso_mass_kg(m), None)


def load_plant_model(scenario: "Scenario", *, shared: bool = False) -> tuple["mujoco.MjModel", dict]:
    """Compile the scenario's model with its perturbation; return it and its summary.

    ``shared``: compiled once per process for each distinct plant (model and
    perturbation) and then shared by every caller, who must only read it (a walker
    works on its own copy): the arms of a run's scenarios on one plant compile it once.
    """
    from plant.model import model_summary

    pert = build_perturbation(scenario)
    stamp = _file_stamp(scenario.model)
    if shared:  # a model that does not load raises its error here, never cached
        model, summary = _shared_model(scenario.model, stamp, pert)
        return model, dict(summary)
    model, applied = _compiled(scenario.model, stamp, pert)
    summary = model_summary(model)
    log.info("scenario %s: model %s, perturbation %s: %s", scenario.name, scenario.model, pert, applied)
    return model, summary


def _compiled(model: str, stamp: tuple | None, pert: "Perturbation | None"):
    """``plant.model.load_perturbed(model, pert)`` from the process's base model
    (:func:`_base_model`, checked): without terrain a perturbed copy of it, with terrain the
    source compiled once with the terrain; the same bytes, one compile less either way."""
    from plant.model import load_perturbed, perturbed_copy, perturbed_with_terrain

    base = _base_model(model, stamp)
    if isinstance(base, ModelError):
        return load_perturbed(model, pert)  # raises the model's error
    if pert is None or pert.terrain is None:
        return perturbed_copy(base, pert, model)
    return perturbed_with_terrain(base, pert, model)


@functools.lru_cache(maxsize=8)
def _shared_model(model: str, stamp: tuple | None, pert: "Perturbation | None") -> tuple["mujoco.MjModel", dict]:
    from plant.model import model_summary

    compiled, applied = _compiled(model, stamp, pert)
    log.info("model %s, perturbation %s: compiled (shared in this process): %s", model, pert, applied)
    return compiled, model_summary(compiled)


# --------------------------------------------------------------------------- the plant FMU's ranges
#: The scenario field each CassiePlant FMU parameter carries (named in problems).
FMU_FIELDS = {"torso_mass_kg": "torso_mass_kg", "joint_damping_scale": "joint_damping_scale",
              **{f"torso_com_offset_{a}_m": f"torso_com_offset_m[{a}]" for a in "xyz"},
              **{f"terrain_{k}": f"terrain.{k}" for k in ("max_height_m", "max_slope_deg", "seed", "size_m")},
              "floor_friction": "floor_friction", "floor_slope_deg": "slope_deg",
              "floor_cross_slope_deg": "cross_slope_deg",
}


def _outside(spec, value) -> bool:
    return (spec.min is not None and value < spec.min) or (spec.max is not None and value > spec.max)


def _range(spec) -> str:
    return f"[{spec.min:g}, {spec.max:g}]" if isinstance(spec.min, float) else f"[{spec.min}, {spec.max}]"


def plant_parameter_problems(torso_mass_kg: float | None, torso_added_mass_kg: float | None,
                             torso_com_offset_m, joint_damping_scale: float,
                             terrain: dict[str, Any] | None, **environment) -> list[tuple[str, Any, str]]:
    """``(field, value, why)`` for every perturbation value outside the range the
    CassiePlant FMU declares for its parameter (``fmu_src.plant_fmu.fmu_core.PARAM_SPECS``, the one
    source of those ranges; on the plant's nominal torso mass). For values the plant's
    own checks (:func:`perturbation_problems`) accept: a scenario valid here runs on
    either plant."""
    from fmu_src.plant_fmu import fmu_core

    from plant.constants import NOMINAL_TORSO_MASS_KG
    from plant.perturbation import resolved

    pert = resolved(_perturbation(torso_mass_kg, torso_added_mass_kg, torso_com_offset_m, joint_damping_scale,
                                  terrain, **environment), NOMINAL_TORSO_MASS_KG)
    values = fmu_core.values_from_perturbation("menagerie", None if pert.is_nominal else pert)
    out: list[tuple[str, Any, str]] = []
    for spec in fmu_core.PARAM_SPECS:
        value = values.get(spec.name)
        if spec.min is not None and value is not None and _outside(spec, value):
            out.append((FMU_FIELDS.get(spec.name, spec.name), value,
                        f"must be in {_range(spec)} (the plant's parameter {spec.name})"))
    return out


def plant_input_problems(scenario: "Scenario") -> list[tuple[str, Any, str]]:
    """``(field, value, why)`` for every command value, and every sum of the pushes in force
    together, outside the range the CassiePlant FMU declares for that input
    (``fmu_src.plant_fmu.fmu_core.INPUT_SPECS``)."""
    from fmu_src.plant_fmu import fmu_core

    inputs = {s.name: s for s in fmu_core.INPUT_SPECS}
    out: list[tuple[str, Any, str]] = []
    for i, point in enumerate(scenario.commands):
        for name in ("vx_des", "vy_des", "yaw_rate_des"):
            spec = inputs.get(name)
            if spec is not None and _outside(spec, getattr(point, name)):
                out.append((f"command[{i}].{name}", getattr(point, name),
                            f"must be in {_range(spec)} (the plant's input {name})"))
    for k in scenario.push_switch_steps:
        for axis, f in zip("xyz", scenario.push_force_at_step(k)):
            spec = inputs.get(f"push_f{axis}")
            if spec is not None and _outside(spec, f):
                out.append((f"push (sum along {axis} at t = {k * scenario.comm_step_s:g} s)", f,
                            f"the pushes in force together must be in {_range(spec)} N (the plant's input "
                            f"push_f{axis})"))
    return out


def plant_fmu_problems(scenario: "Scenario") -> list[str]:
    """Why ``scenario``'s plant cannot be the CassiePlant FMU (``--plant fmu``): a model
    the FMU does not hold, or a value the FMU has no parameter for (it would silently run
    another plant). Its ranges are checked on every scenario (:func:`plant_parameter_problems`,
    :func:`plant_input_problems`)."""
    from fmu_src.plant_fmu import fmu_core

    if scenario.model not in fmu_core.MODEL_FILES:
        return [f"model = {scenario.model!r}: the CassiePlant FMU holds {', '.join(fmu_core.MODEL_FILES)} only; "
                "an MJCF path needs --plant inprocess"]
    found = fmu_unsupported(scenario)
    if found:
        return found
    pert = build_perturbation(scenario)
    if pert is None or pert.terrain is None:
        return []
    from plant.constants import NOMINAL_TORSO_MASS_KG
    from plant.perturbation import resolved

    # the FMU takes the absolute torso mass: an added mass is resolved as fmu_parameters does
    values = fmu_core.values_from_perturbation(scenario.model, resolved(pert, NOMINAL_TORSO_MASS_KG))
    carried = fmu_core.perturbation_from_values(values).terrain
    return [f"terrain.{f.name} = {getattr(pert.terrain, f.name)!r}: the CassiePlant FMU has no parameter for it "
            f"(it uses {getattr(carried, f.name)!r}); --plant inprocess runs it"
            for f in dataclasses.fields(pert.terrain) if getattr(pert.terrain, f.name) != getattr(carried, f.name)]


def fmu_unsupported(scenario: "Scenario") -> list[str]:
    """What of ``scenario`` the CassiePlant FMU has no parameter or input for: events
    during the walk, pushes on bodies other than the pelvis, link masses in kg or on
    links without a ``link_mass_scale_*`` parameter."""
    from fmu_src.plant_fmu import fmu_core

    out = []
    if scenario.events:
        out.append("event: the CassiePlant FMU has no parameters that change during a walk; "
                   "--plant inprocess runs events")
    for i, p in enumerate(scenario.pushes):
        if p.body != "cassie-pelvis":
            out.append(f"push[{i}].body = {p.body!r}: the CassiePlant FMU pushes the pelvis only; "
                       "--plant inprocess runs it")
    for i, lm in enumerate(scenario.link_masses):
        if lm.mass_kg is not None:
            out.append(f"link_mass[{i}].mass_kg: the CassiePlant FMU takes link masses as scale only")
        elif lm.body not in fmu_core.LINK_MASS_BODIES:
            out.append(f"link_mass[{i}].body = {lm.body!r}: the CassiePlant FMU has link_mass_scale_* parameters "
                       f"for {', '.join(fmu_core.LINK_MASS_BODIES)} only")
    return out
