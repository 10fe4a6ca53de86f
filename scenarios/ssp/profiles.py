"""The named profiles (``fmu_src.core.avr_profiles``) as SSP 1.0 parameter-values files.

``python build.py`` writes ``dist/profiles/NAME.ssv`` for every profile (:func:`write_profiles`):
one ``ssv:ParameterSet`` named after the profile, holding only the parameters whose value
differs from the regulator FMU's start value, typed as the FMU declares them.  An fmpy user
applies one with :func:`read_profile`::

    from fmpy import simulate_fmu
    from scenarios.ssp.profiles import read_profile

    simulate_fmu("dist/AdaptiveVelocityRegulator.fmu", start_values=read_profile("dist/profiles/robust.ssv"))
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from fmu_src.core.avr_errors import ParameterError
from fmu_src.core.avr_params import params_from_overrides
from fmu_src.core.avr_profiles import PROFILES, profile_overrides
from fmu_src.core.avr_specs import PARAM_BY_NAME, PYTHON_TYPES
from scenarios.ssp import system

#: The folder beside the FMUs that holds the profiles.
FOLDER = "profiles"


def profile_ssv(name: str) -> bytes:
    """The ``.ssv`` of profile ``name`` (ParameterError naming the allowed ones if unknown)."""
    rows = [(key, PARAM_BY_NAME[key].type, system.value_text(PARAM_BY_NAME[key].type, value))
            for key, value in profile_overrides(name).items()]
    return system.parameter_set(name, rows)


def write_profiles(out_dir: Path) -> list[Path]:
    """Write ``<out_dir>/profiles/NAME.ssv`` for every profile; their paths."""
    folder = Path(out_dir) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for name in PROFILES:
        path = folder / f"{name}.ssv"
        tmp = path.with_suffix(".ssv.tmp")
        tmp.write_bytes(profile_ssv(name))
        tmp.replace(path)
        paths.append(path)
    return paths


def read_profile(path: str | Path) -> dict[str, object]:
    """The parameter values of a regulator parameter-values file (``.ssv``), typed (float, int,
    bool), usable as ``fmpy.simulate_fmu(start_values=...)``.  Raises ParameterError naming
    every parameter the regulator does not have, every value of the wrong type or out of
    range, and every broken rule between parameters."""
    root = ET.parse(str(path)).getroot()
    values, problems = {}, []
    for param in root.iter(f"{{{system.NS['ssv']}}}Parameter"):
        name = param.get("name")
        (typed,) = list(param)
        kind = typed.tag.rpartition("}")[2]
        spec = PARAM_BY_NAME.get(name)
        if spec is None:
            problems.append(f"{path}: {name}: not a regulator parameter")
        elif kind != spec.type:
            problems.append(f"{path}: {name} is an {spec.type}, the file gives an {kind}")
        else:
            values[name] = _parsed(spec.type, typed.get("value"))
    if problems:
        raise ParameterError(problems)
    params_from_overrides(values)  # every value and rule checked, all problems at once
    return values


def _parsed(kind: str, text: str):
    if kind == "Boolean":
        return text in ("true", "1")
    return PYTHON_TYPES[kind](text)
