"""The static checks: the model description alone (no FMU code runs).  Each returns the list of
problems it finds, every one at once."""
from __future__ import annotations

import math
from functools import cache
from pathlib import Path

from lxml import etree

from fmu_src.fmi.conformance.model import Fmu, default_initial, number

#: Legal (causality, variability) pairs and the initial values each allows (None: no initial
#: attribute), FMI 2.0 section 2.2.7's tables; FMI 3.0 adds structural parameters.
_OUT_LOCAL = {"constant": {"exact"}, "discrete": {"calculated", "exact", "approx"},
              "continuous": {"calculated", "exact", "approx"}}
LEGAL = {
    ("parameter", "fixed"): {"exact"}, ("parameter", "tunable"): {"exact"},
    ("calculatedParameter", "fixed"): {"calculated", "approx"},
    ("calculatedParameter", "tunable"): {"calculated", "approx"},
    ("input", "discrete"): {None}, ("input", "continuous"): {None},
    **{("output", v): i for v, i in _OUT_LOCAL.items()},
    **{("local", v): i for v, i in _OUT_LOCAL.items()},
    ("local", "fixed"): {"calculated", "approx"}, ("local", "tunable"): {"calculated", "approx"},
    ("independent", "continuous"): {None},
}
LEGAL3 = {**LEGAL, ("structuralParameter", "fixed"): {"exact"}, ("structuralParameter", "tunable"): {"exact"},
          ("input", "discrete"): {None, "exact"}, ("input", "continuous"): {None, "exact"}}
FLOAT_TYPES = {"Real", "Float32", "Float64"}
NUMERIC = FLOAT_TYPES | {"Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64",
                         "Enumeration"}


def _schema_file(version: int) -> Path:
    import fmpy

    return Path(fmpy.__file__).parent / "schema" / f"fmi{version}" / f"fmi{version}ModelDescription.xsd"


@cache
def _schema(version: int) -> etree.XMLSchema:
    return etree.XMLSchema(etree.parse(str(_schema_file(version))))


def schema(fmu: Fmu) -> list[str]:
    """modelDescription.xml against the official schema (the copy fmpy ships)."""
    validator = _schema(fmu.version)
    if validator.validate(fmu.root.getroottree()):
        return []
    return [f"line {e.line}: {e.message}" for e in validator.error_log]


def _scalar_elements(fmu: Fmu):
    """(name, element, type element or None) of every variable, as written in the XML."""
    if fmu.version == 2:
        for sv in fmu.root.iterfind("ModelVariables/ScalarVariable"):
            typed = next((c for c in sv if isinstance(c.tag, str) and c.tag in
                          ("Real", "Integer", "Boolean", "String", "Enumeration")), None)
            yield sv.get("name"), sv, typed
    else:
        for v in fmu.root.find("ModelVariables") if fmu.root.find("ModelVariables") is not None else ():
            if isinstance(v.tag, str):
                yield v.get("name"), v, v


def variables(fmu: Fmu) -> list[str]:
    """Legal causality/variability/initial combinations; start present where required (initial
    exact or approx, inputs), absent where forbidden (initial calculated, independent)."""
    legal = LEGAL if fmu.version == 2 else LEGAL3
    problems = []
    for name, element, typed in _scalar_elements(fmu):
        causality = element.get("causality", "local")
        default_variability = "continuous" if (typed is not None and typed.tag in FLOAT_TYPES) else "discrete"
        variability = element.get("variability", default_variability)
        if fmu.version == 3 and element.tag == "Clock":
            continue
        initial = element.get("initial")
        key = (causality, variability)
        if key not in legal:
            problems.append(f"{name}: causality={causality!r} with variability={variability!r} is not allowed")
            continue
        if initial is not None and initial not in legal[key]:
            allowed = sorted(i for i in legal[key] if i)
            problems.append(f"{name}: initial={initial!r} is not allowed for causality={causality!r}, "
                            f"variability={variability!r} "
                            + (f"(allowed: {', '.join(allowed)})" if allowed else "(no initial attribute allowed)"))
        if typed is not None and typed.tag not in FLOAT_TYPES and variability == "continuous":
            problems.append(f"{name}: a {typed.tag} variable cannot be continuous")
        effective = initial or default_initial(causality, variability)
        has_start = typed is not None and typed.get("start") is not None
        if fmu.version == 3 and typed is not None and typed.find("Start") is not None:
            has_start = True
        if (effective in ("exact", "approx") or causality == "input") and not has_start:
            problems.append(f"{name}: no start value (required for causality={causality!r}, initial={effective!r})")
        if (effective == "calculated" or causality == "independent") and has_start:
            problems.append(f"{name}: a start value is not allowed with "
                            + ("causality='independent'" if causality == "independent" else "initial='calculated'"))
    return problems


def start_range(fmu: Fmu) -> list[str]:
    """Every numeric start value within its variable's [min, max] (the variable's own bounds or
    its declared type's)."""
    problems = []
    for v in fmu.variables:
        if v.type not in NUMERIC or v.start is None or (v.min is None and v.max is None):
            continue
        for text in v.start.split():
            value = number(text)
            if value is None or math.isnan(value):
                problems.append(f"{v.name}: start {text!r} is not a number")
            elif (v.min is not None and value < v.min) or (v.max is not None and value > v.max):
                problems.append(f"{v.name}: start {text} is outside [{v.min:g}, {v.max:g}]".replace("None", "-inf"))
    return problems


def model_structure(fmu: Fmu) -> list[str]:
    """Every output listed once as an output; the initial unknowns exactly those the standard
    lists (outputs with initial approx/calculated, calculated parameters, state derivatives with
    initial approx/calculated); every dependency a valid variable (FMI 2.0: an index into
    ModelVariables, FMI 3.0: a value reference), dependenciesKind as long as dependencies."""
    problems = []
    variables = fmu.variables
    if fmu.version == 2:
        def entries(kind):
            return fmu.root.findall(f"ModelStructure/{kind}/Unknown")

        def key_of(element):
            index = element.get("index")
            if index is None or not index.isdigit() or not 1 <= int(index) <= len(variables):
                problems.append(f"ModelStructure: index {index!r} is not a variable (1..{len(variables)})")
                return None
            return int(index) - 1
        outputs_tag, initial_tag, derivative_tag = "Outputs", "InitialUnknowns", "Derivatives"
        keys = {i: v for i, v in enumerate(variables)}

        def dep_key(text):
            return int(text) - 1 if text.isdigit() and 1 <= int(text) <= len(variables) else None
    else:
        def entries(kind):
            return fmu.root.findall(f"ModelStructure/{kind}")

        by_vr = {v.vr: i for i, v in enumerate(variables)}

        def key_of(element):
            vr = element.get("valueReference")
            if vr is None or not vr.isdigit() or int(vr) not in by_vr:
                problems.append(f"ModelStructure: valueReference {vr!r} is not a variable's")
                return None
            return by_vr[int(vr)]
        outputs_tag, initial_tag, derivative_tag = "Output", "InitialUnknown", "ContinuousStateDerivative"
        keys = {i: v for i, v in enumerate(variables)}

        def dep_key(text):
            return by_vr.get(int(text)) if text.isdigit() else None
    listed = {}
    for kind in (outputs_tag, initial_tag, derivative_tag):
        found = []
        for element in entries(kind):
            key = key_of(element)
            deps = (element.get("dependencies") or "").split()
            for text in deps:
                if dep_key(text) is None:
                    problems.append(f"ModelStructure/{kind} of {keys[key].name if key is not None else '?'}: "
                                    f"dependency {text!r} is not a variable")
            kinds = element.get("dependenciesKind")
            if kinds is not None and len(kinds.split()) != len(deps):
                problems.append(f"ModelStructure/{kind}: dependenciesKind has {len(kinds.split())} entries, "
                                f"dependencies {len(deps)}")
            if key is not None:
                found.append(key)
        listed[kind] = found
    outputs = [i for i, v in keys.items() if v.causality == "output"]
    for i in sorted(set(outputs) - set(listed[outputs_tag])):
        problems.append(f"ModelStructure: output {keys[i].name} is not listed in {outputs_tag}")
    for i in sorted({i for i in listed[outputs_tag] if listed[outputs_tag].count(i) > 1}):
        problems.append(f"ModelStructure: output {keys[i].name} is listed more than once")
    for i in sorted(set(listed[outputs_tag]) - set(outputs)):
        problems.append(f"ModelStructure: {keys[i].name} is listed in {outputs_tag} but its causality is "
                        f"{keys[i].causality!r}")
    derivatives = set(listed[derivative_tag])
    required = {i for i, v in keys.items()
                if (v.causality == "output" or i in derivatives) and v.initial in ("approx", "calculated")
                or v.causality == "calculatedParameter"}
    for i in sorted(required - set(listed[initial_tag])):
        problems.append(f"ModelStructure: {keys[i].name} (causality {keys[i].causality}, initial "
                        f"{keys[i].initial}) is missing from {initial_tag}")
    for i in sorted(set(listed[initial_tag]) - required):
        problems.append(f"ModelStructure: {keys[i].name} is listed in {initial_tag} but is not an initial unknown")
    return problems


def units(fmu: Fmu) -> list[str]:
    """Every unit a variable or type definition names is declared in UnitDefinitions, and every
    display unit among its unit's DisplayUnits."""
    declared = {u.get("name"): {d.get("name") for d in u.iterfind("DisplayUnit")}
                for u in fmu.root.iterfind("UnitDefinitions/Unit")}
    problems = []
    holders = [(f"type {t.get('name')}", t if fmu.version == 3 else next(iter(t), t))
               for t in fmu.root.iterfind("TypeDefinitions/*")]
    holders += [(name, typed) for name, _, typed in _scalar_elements(fmu) if typed is not None]
    for name, element in holders:
        unit, display = element.get("unit"), element.get("displayUnit")
        if unit is not None and unit not in declared:
            problems.append(f"{name}: unit {unit!r} is not declared in UnitDefinitions")
        if display is not None and unit in declared and display not in declared[unit]:
            problems.append(f"{name}: display unit {display!r} is not a DisplayUnit of {unit!r}")
    return problems


#: check id -> function, in the order of checks.CHECKS.
STATIC_CHECKS = {"static.schema": schema, "static.variables": variables, "static.start_range": start_range,
                 "static.model_structure": model_structure, "static.units": units}
