"""The scenario -> plant mapping: the plant's Perturbation and the compiled model.

Pushes are not part of the plant's ``Perturbation``: the master switches them on and
off itself (``CassieWalker.set_pelvis_force``) on communication-step boundaries.
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pragma: no cover
    import mujoco

    from plant.model import Perturbation
    from scenarios.spec import Scenario

log = logging.getLogger(__name__)

#: Half-size of the terrain square (plant.model.TerrainSpec.size_m) unless the file says.
DEFAULT_TERRAIN_SIZE_M = 20.0


def build_perturbation(scenario: "Scenario", nominal_torso_mass_kg: float | None) -> "Perturbation | None":
    """The plant Perturbation of ``scenario`` (None when the plant is nominal).

    ``torso_added_mass_kg`` needs the model's own torso mass (``nominal_torso_mass_kg``);
    when that is None (validation before loading) the plant's nominal 10.33 kg is used.
    """
    from plant.model import NOMINAL_PELVIS_MASS_KG, Perturbation, TerrainSpec

    mass = scenario.torso_mass_kg
    if scenario.torso_added_mass_kg is not None:
        base = NOMINAL_PELVIS_MASS_KG if nominal_torso_mass_kg is None else nominal_torso_mass_kg
        mass = base + scenario.torso_added_mass_kg
    terrain = None
    if scenario.terrain is not None:
        t = scenario.terrain
        terrain = TerrainSpec(max_height_m=t.max_height_m, max_slope_deg=t.max_slope_deg, seed=t.seed,
                              size_m=t.size_m)
    pert = Perturbation(
        torso_mass_kg=mass,
        torso_com_offset_m=tuple(scenario.torso_com_offset_m),
        joint_damping_scale=scenario.joint_damping_scale,
        terrain=terrain,
    )
    return None if pert.is_nominal else pert


def load_plant_model(scenario: "Scenario") -> tuple["mujoco.MjModel", dict]:
    """Compile the scenario's model with its perturbation; return it and its summary."""
    from plant.model import load_model, model_summary

    nominal_mass = None
    if scenario.torso_added_mass_kg is not None:
        nominal_mass = model_summary(load_model(scenario.model))["pelvis_mass_kg"]
    pert = build_perturbation(scenario, nominal_mass)
    model = load_model(scenario.model, pert)
    summary = model_summary(model)
    log.info("scenario %s: model %s, perturbation %s", scenario.name, scenario.model, pert)
    return model, summary
