"""The pythonfmu FMUs' model description (units, ranges, default experiment, no generation
time) and documentation page, from the variable specs (``VarSpec``-like objects with name,
type, causality, variability, unit, default, min, max, description)."""
from __future__ import annotations

import html
import xml.etree.ElementTree as ET

from fmu_src.packing.archive import PLACEHOLDER_GUID

UNITS = {  # name -> SI base-unit exponents
    "m/s": {"m": "1", "s": "-1"},
    "rad": {"rad": "1"},
    "rad/s": {"rad": "1", "s": "-1"},
    "s": {"s": "1"},
}
DEFAULT_EXPERIMENT = {"startTime": "0", "stopTime": "10", "stepSize": "0.005"}
#: The CassiePlant outputs its initialization computes (the robot placed on the terrain in the
#: home pose), with the knowns each depends on; every other plant output keeps its start value
#: until the first doStep.  tests/fmu/test_fmu_model_structure.py measures both on the built FMU.
PLANT_INITIAL_UNKNOWNS = {
    "pelvis_z": (),  # the home pose's height, whichever model and terrain
    # The contact forces carrying the robot: its model and mass distribution, whether the floor is
    # a plane or the height field (terrain_max_height_m > 0) and the field's sample grid (its
    # spacing follows terrain_size_m).  The robot stands on the field's flat start patch
    # (plant/terrain.py), so the terrain's seed and slope never reach it; a tilted floor, the
    # floor's friction and the leg links' masses (fmu_core.LINK_MASS_BODIES) do.
    **{name: ("cassie_model", "torso_mass_kg", "torso_com_offset_x_m", "torso_com_offset_y_m", "torso_com_offset_z_m",
              "terrain_max_height_m", "terrain_size_m", "floor_friction", "floor_slope_deg", "floor_cross_slope_deg",
              *(f"link_mass_scale_{side}_{link}" for side in ("left", "right")
                for link in ("hip_pitch", "shin", "tarsus")))
       for name in ("left_foot_force", "right_foot_force")},
}


def xml_value(value) -> str:
    """A value as model descriptions write it: booleans as ``true``/``false``, floats round-tripping."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def _schema_order(root: ET.Element, units: ET.Element) -> None:
    """Re-append ``root``'s children in the FMI 2.0 schema order: CoSimulation, UnitDefinitions,
    ..., LogCategories, DefaultExperiment, ModelVariables, ..."""
    children = list(root)
    for child in children:
        root.remove(child)
    for child in children:
        if child.tag == "DefaultExperiment":
            continue
        root.append(child)
        if child.tag == "CoSimulation":
            root.append(units)
        if child.tag == "LogCategories":
            root.append(ET.Element("DefaultExperiment", DEFAULT_EXPERIMENT))


def _unit_definitions(units: dict) -> ET.Element:
    element = ET.Element("UnitDefinitions")
    add_units(element, units)
    return element


def add_units(element: ET.Element, units: dict) -> None:
    """``<Unit name><BaseUnit .../></Unit>`` for every unit of ``units`` (name -> exponents)."""
    for name, exponents in units.items():
        ET.SubElement(ET.SubElement(element, "Unit", name=name), "BaseUnit", exponents)


def _annotate_variables(root: ET.Element, specs, units: dict, ranges: bool = True) -> None:
    """Each variable's unit (if declared in ``units``) and (``ranges``), for Real and Integer, its range."""
    by_name = {spec.name: spec for spec in specs}
    for var in root.find("ModelVariables"):
        spec = by_name[var.get("name")]
        typed = var[0]
        if spec.type == "Real" and spec.unit in units:
            typed.set("unit", spec.unit)
        if ranges and spec.type in ("Real", "Integer"):
            if spec.min is not None:
                typed.set("min", xml_value(spec.min))
            if spec.max is not None:
                typed.set("max", xml_value(spec.max))


def _model_structure(root: ET.Element, initial_unknowns: dict) -> None:
    """The exact ``ModelStructure`` (FMI 2.0 section 2.2.8): every output declares
    ``dependencies=""`` (the slaves compute outputs only in doStep: setting an input changes no
    output before the next step); an output named in ``initial_unknowns`` (name -> the knowns
    it is computed from during initialization) becomes ``initial="calculated"`` without a start
    value and is listed in ``InitialUnknowns`` with those dependencies, in index order."""
    variables = list(root.find("ModelVariables"))
    index = {var.get("name"): str(i) for i, var in enumerate(variables, start=1)}
    unknown = set(initial_unknowns) - {v.get("name") for v in variables if v.get("causality") == "output"}
    if unknown:
        raise ValueError(f"initial_unknowns names no output: {sorted(unknown)}")
    for name in initial_unknowns:
        var = variables[int(index[name]) - 1]
        var.set("initial", "calculated")
        var[0].attrib.pop("start", None)
    old = root.find("ModelStructure")
    if old is not None:
        root.remove(old)
    structure = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(structure, "Outputs")
    for var in variables:
        if var.get("causality") == "output":
            ET.SubElement(outputs, "Unknown", index=index[var.get("name")], dependencies="")
    if initial_unknowns:
        initial = ET.SubElement(structure, "InitialUnknowns")
        for name in sorted(initial_unknowns, key=lambda n: int(index[n])):
            deps = sorted(int(index[known]) for known in initial_unknowns[name])
            ET.SubElement(initial, "Unknown", index=index[name], dependencies=" ".join(map(str, deps)))


def model_description(xml_bytes: bytes, specs, extra_units: dict | None = None,
                      initial_unknowns: dict | None = None) -> ET.ElementTree:
    """pythonfmu's ``modelDescription.xml`` made complete and reproducible: ``UNITS`` (plus
    ``extra_units``), units and ranges from ``specs``, ``DEFAULT_EXPERIMENT``, the exact model
    structure (``_model_structure``; ``initial_unknowns``: the outputs computed during
    initialization, name -> the knowns they depend on), no generation time and a placeholder
    GUID (the content GUID is set once everything else is known)."""
    root = ET.fromstring(xml_bytes)
    root.attrib.pop("generationDateAndTime", None)
    root.set("guid", PLACEHOLDER_GUID)
    units = _unit_definitions(UNITS)
    _schema_order(root, units)
    _annotate_variables(root, specs, UNITS)
    if extra_units:
        add_units(units, extra_units)
        _annotate_variables(root, specs, extra_units, ranges=False)
    _model_structure(root, initial_unknowns or {})
    ET.indent(root)
    return ET.ElementTree(root)


def variables_table(specs) -> str:
    """The HTML table of every variable (the documentation pages' last section); a tier column
    when some variable has a tier (the regulator's parameters)."""
    tiers = any(getattr(s, "tier", None) for s in specs)
    tier = (lambda s: f"<td>{s.tier or ''}</td>") if tiers else (lambda s: "")
    rows = "\n".join(
        f"<tr><td>{s.name}</td><td>{s.causality}</td>{tier(s)}<td>{s.type}</td><td>{s.variability}</td>"
        f"<td>{html.escape(s.unit)}</td><td>{xml_value(s.default)}</td>"
        f"<td>{'' if s.min is None else xml_value(s.min)}</td><td>{'' if s.max is None else xml_value(s.max)}</td>"
        f"<td>{html.escape(s.description)}</td></tr>" for s in specs)
    return f"""<h2>Variables</h2>
<table border="1"><tr><th>name</th><th>causality</th>{'<th>tier</th>' if tiers else ''}<th>type</th><th>variability</th><th>unit</th>
<th>default</th><th>min</th><th>max</th><th>description</th></tr>
{rows}
</table></body></html>
"""
