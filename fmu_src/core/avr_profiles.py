"""Named profiles: the regulator's parameter sets that ship, declared once.

Each profile lists only the parameters whose value differs from the default (``PARAM_SPECS``),
and is checked against the specs when this module is imported (a value that is illegal, equal
to the default, or that breaks a ``PARAM_REQUIRES`` rule stops the import naming it).
``build.py`` writes each as an SSP 1.0 parameter-values file, ``dist/profiles/NAME.ssv``
(:mod:`scenarios.ssp.profiles`); scenario files, campaign arms and ``python -m scenarios run
--profile NAME`` apply them through :func:`profile_overrides`.
"""
from __future__ import annotations

from fmu_src.core.avr_errors import ParameterError
from fmu_src.core.avr_specs import PARAM_BY_NAME, check_param, requires_problems

__all__ = ["PROFILES", "PROFILE_DESCRIPTIONS", "profile_overrides", "unknown_profile"]

#: name -> {parameter: value}, only what differs from the defaults.
PROFILES: dict[str, dict[str, object]] = {
    # the paper's plain PES rule: no leakage (the one remedy against drift this FMU keeps)
    "paper": {"leakage_per_s": 0.0},
    # the FMU's defaults
    "default": {},
    # the randomized-robots study's shipped design (scenarios/campaigns/robustness_random.toml,
    # variant "ramp")
    "robust": {"command_accel_limit_mps2": 0.5, "learn_settled_steps": 8, "learning_rate": 2e-6,
               "learn_ramp_max_mps2": 0.25},
}

#: name -> one sentence: what the profile is (the FMUs' documentation pages list them).
PROFILE_DESCRIPTIONS = {
    "paper": "the paper's plain learning rule (PES without leakage)",
    "default": "the FMU's defaults (leakage of the weights' unused part at 0.01 /s)",
    "robust": ("the randomized-robots study's design: the command reference at the gait's 0.5 m/s^2, velocity "
               "learning on commands settled over 8 steps or ramping at most 0.25 m/s^2, learning rate 2e-6"),
}


def unknown_profile(name) -> str | None:
    """Why ``name`` is not a profile (naming the allowed ones), or None."""
    if name in PROFILES:
        return None
    return f"profile = {name!r}: unknown (allowed: {', '.join(PROFILES)})"


def profile_overrides(name: str) -> dict[str, object]:
    """The parameter overrides of profile ``name`` (a copy); ParameterError for an unknown name."""
    problem = unknown_profile(name)
    if problem is not None:
        raise ParameterError(problem)
    return dict(PROFILES[name])


def _problems() -> list[str]:
    found = []
    if set(PROFILES) != set(PROFILE_DESCRIPTIONS):
        found.append(f"profiles {sorted(PROFILES)} and descriptions {sorted(PROFILE_DESCRIPTIONS)} differ")
    for name, values in PROFILES.items():
        for key, value in values.items():
            spec = PARAM_BY_NAME.get(key)
            if spec is None:
                found.append(f"profile {name}: {key} is no parameter")
                continue
            normal, problem = check_param(spec, value)
            if problem is not None:
                found.append(f"profile {name}: {problem}")
            elif normal == spec.default and type(normal) is type(spec.default):
                found.append(f"profile {name}: {key} = {value!r} is the default (list only what differs)")
        full = {key: spec.default for key, spec in PARAM_BY_NAME.items()} | values
        found += [f"profile {name}: {problem}" for problem in requires_problems(full)]
    return found


if _problems():  # a declaration error: fail at import, naming every problem
    raise ParameterError(_problems())
