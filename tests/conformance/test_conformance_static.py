"""The static checks of the conformance check (``fmu_src/fmi/conformance/static.py``) on the
native regulators' real model descriptions with one defect written in each: each check finds its
defect, names the variable, and reports every problem at once (in process: no FMU code runs)."""
from __future__ import annotations

import zipfile

import pytest

from fmu_src.fmi.conformance.model import Fmu
from fmu_src.fmi.conformance.static import STATIC_CHECKS


def edited(tmp_path, dist, version: int, *edits) -> Fmu:
    folder = tmp_path / f"fmi{version}"
    with zipfile.ZipFile(dist / f"AdaptiveVelocityRegulatorNative_fmi{version}.fmu") as z:
        z.extractall(folder)
    md = folder / "modelDescription.xml"
    text = md.read_text()
    for old, new in edits:
        assert text.count(old) >= 1, old
        text = text.replace(old, new, 1)
    md.write_text(text)
    return Fmu(folder)


def problems(fmu: Fmu) -> dict:
    return {check: found for check, f in STATIC_CHECKS.items() if (found := f(fmu))}


@pytest.mark.parametrize("version", (2, 3))
def test_the_unchanged_model_descriptions_pass(tmp_path, built_all, version):
    assert problems(edited(tmp_path, built_all.dist, version)) == {}


def test_fmi2_defects_each_found_by_its_check_all_at_once(tmp_path, built_all):
    fmu = edited(tmp_path, built_all.dist, 2,
                 ('causality="input" variability="continuous"', 'causality="input" variability="continuous" '
                                                                'initial="calculated"'),
                 ('unit="rad"', 'unit="furlong"'), ('<Unknown index="44" dependencies=""', '<Unknown index="44" dependencies="0"'))
    found = problems(fmu)
    assert set(found) == {"static.variables", "static.units", "static.model_structure"}, found
    assert found["static.variables"] == [
        "vx: initial='calculated' is not allowed for causality='input', variability='continuous' (no initial "
        "attribute allowed)", "vx: a start value is not allowed with initial='calculated'"]
    assert any("unit 'furlong' is not declared" in p for p in found["static.units"])
    assert any("dependency '0' is not a variable" in p for p in found["static.model_structure"])


def test_fmi3_defects_each_found_by_its_check(tmp_path, built_all):
    fmu = edited(tmp_path, built_all.dist, 3, ('start="1000" min="1"', 'start="0" min="1"'),
                 ('<Output valueReference="43" dependencies=""', '<Output valueReference="43" dependencies="9999"'),
                 ('causality="parameter" variability="tunable"', 'causality="parameter" variability="continuous"'))
    found = problems(fmu)
    assert set(found) == {"static.start_range", "static.model_structure", "static.variables"}, found
    assert found["static.start_range"] == ["n_neurons: start 0 is outside [1, 10000]"]
    assert any("dependency '9999' is not a variable" in p for p in found["static.model_structure"])
    assert any("causality='parameter' with variability='continuous' is not allowed" in p
               for p in found["static.variables"])
