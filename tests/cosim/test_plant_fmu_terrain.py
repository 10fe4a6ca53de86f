"""The plant FMU path on terrain scenarios."""
from __future__ import annotations


def test_a_terrain_scenario_with_an_added_torso_mass_is_fit_for_the_plant_fmu():
    """terrain_mass_com (terrain and +5 kg on the torso) has nothing the plant FMU cannot carry;
    the added mass is resolved to the absolute torso mass the FMU takes."""
    from scenarios.lang import spec
    from scenarios.lang.plantio import plant_fmu_problems

    assert plant_fmu_problems(spec.resolve_targets(["terrain_mass_com"])[0]) == []
