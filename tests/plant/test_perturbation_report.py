"""The plant owns its perturbation: it resolves a mass added to its own torso on the model it
compiles and reports what it applied; no layer above compiles a model to learn a mass."""
from __future__ import annotations

import pytest

import plant.model
from plant.constants import NOMINAL_TORSO_MASS_KG
from plant.errors import PerturbationError
from plant.model import load_model, load_perturbed
from plant.perturbation import Applied, Perturbation, apply_to_compiled, resolved, torso_mass_kg


def test_apply_to_compiled_reports_the_torso_mass_before_and_after():
    model = load_model("menagerie")
    before = torso_mass_kg(model)
    applied = apply_to_compiled(model, Perturbation(torso_added_mass_kg=5.0))
    assert applied == Applied(torso_mass_before_kg=before, torso_mass_after_kg=before + 5.0)
    assert torso_mass_kg(model) == before + 5.0  # exactly the sum: the same bits as an absolute mass
    _, absolute = load_perturbed("menagerie", Perturbation(torso_mass_kg=20.0))
    assert absolute == Applied(torso_mass_before_kg=before, torso_mass_after_kg=20.0)
    assert load_perturbed("menagerie")[1] is None


def test_an_added_mass_is_checked_on_the_model_it_is_added_to():
    model = load_model("menagerie")
    with pytest.raises(PerturbationError, match=r"torso_added_mass_kg=-20.0 makes the torso mass 10.33 \+ -20 = -9.67 kg: "
                                                r"it must be in \(0, 100\] kg"):
        apply_to_compiled(model, Perturbation(torso_added_mass_kg=-20.0))
    assert torso_mass_kg(model) == NOMINAL_TORSO_MASS_KG  # unchanged
    both = Perturbation(torso_mass_kg=20.0, torso_added_mass_kg=5.0).problems()
    assert both == ["torso_mass_kg and torso_added_mass_kg: give one of them, not both"]


def test_resolved_gives_the_absolute_mass_for_consumers_of_absolute_masses():
    p = Perturbation(torso_added_mass_kg=5.0, joint_damping_scale=2.0)
    assert resolved(p, 10.0) == Perturbation(torso_mass_kg=15.0, joint_damping_scale=2.0)
    assert resolved(Perturbation(torso_mass_kg=3.0), 10.0) == Perturbation(torso_mass_kg=3.0)


def test_the_scenario_layer_compiles_an_added_mass_plant_once(monkeypatch):
    """Loading a scenario with ``torso_added_mass_kg`` compiles its model once in a process
    (the base model, which the scenario check shares), not a second time to learn the nominal
    mass nor again for the next arm: each arm's model is a perturbed copy."""
    from scenarios.lang import plantio, spec

    heavy = spec.override(spec.resolve_targets(["compare_staircase"], check_plant=False)[0], duration_s=0.2,
                          check_plant=False)
    assert heavy.torso_added_mass_kg == 5.0 and heavy.terrain is None
    plantio._base_model.cache_clear()
    compiled = []
    real = plant.model._compile
    monkeypatch.setattr(plant.model, "_compile", lambda *a, **k: compiled.append(a[1]) or real(*a, **k))
    model, summary = plantio.load_plant_model(heavy)
    assert compiled == ["menagerie"]
    assert summary["pelvis_mass_kg"] == NOMINAL_TORSO_MASS_KG + 5.0
    again, _ = plantio.load_plant_model(heavy)
    assert compiled == ["menagerie"] and again is not model


def test_the_plant_fmu_gets_the_mass_the_plant_applied():
    from scenarios.cosim.plant_fmu import fmu_parameters
    from scenarios.lang import spec

    heavy = spec.resolve_targets(["compare_staircase"])[0]
    assert fmu_parameters(heavy)["torso_mass_kg"] == NOMINAL_TORSO_MASS_KG + 5.0
    assert fmu_parameters(heavy, 12.5)["torso_mass_kg"] == 12.5
