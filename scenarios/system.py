"""The closed loop as a system of two FMUs: the SSP package and the OSP system structure.

``python build.py`` writes ``dist/CassieAVR.ssp`` and ``dist/CassieAVR_osp/`` from the
built FMUs with the functions here; everything is read from the FMUs' own model
descriptions (names, causality, types, units, start values), so the system always
matches the FMUs it packs:

* components ``plant`` (``CassiePlant.fmu``) and ``avr`` (``AdaptiveVelocityRegulator.fmu``);
* connections name to name: every output of one that is an input of the other with the
  same name and type (the plant's ``vx, vy, pitch, roll, pitch_rate, roll_rate,
  step_index`` to the regulator, the regulator's six ``delta_*`` to the plant);
* the nominal case as one parameter-set name, :data:`PARAMETER_SET`, bound to each
  component (``resources/<instance>_nominal.ssv``, bare variable names as SSP 1.0 wants
  for a component binding): the plant's parameters at their start values and the
  command ``vx_des = 0.5 m/s`` on both FMUs (the command is an input of both, set by
  the user, not a connection), ``yaw_rate_des = 0`` on the plant only (the regulator has
  no yaw-rate input: the speeds it regulates are in the heading frame whatever the
  turning rate).  One name for both because masters differ in how they pick a set:
  libcosim applies each component's first binding, Ecos applies every component's
  set of the one name given to ``init(parameter_set=...)``; fmpy's ``simulate_ssp``
  reads no binding (:func:`scenarios.system_run.ssp_parameter_set` hands them over);
* a default experiment of 30 s with a fixed 5 ms step (OSP annotation, which libcosim
  reads).

Neither SSP nor libcosim's SSP reader has a place for inputs that change over time:
:mod:`scenarios.system_run` scripts them (OSP scenario files for libcosim, a CSV
through an FMU container for fmpy).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SYSTEM_NAME = "CassieAVR"
PLANT, REGULATOR = "plant", "avr"
STEP_S = 0.005
STOP_S = 30.0
#: The nominal command, set on every FMU that has the input (yaw_rate_des: the plant only).
NOMINAL_COMMAND = {"vx_des": "0.5", "vy_des": "0.0", "yaw_rate_des": "0.0"}
FMU_MIME = "application/x-fmu-sharedlibrary"
#: The name of the nominal parameter set of every component (Ecos: ``init(parameter_set=PARAMETER_SET)``).
PARAMETER_SET = "nominal"


def _q(tag: str) -> str:
    prefix, _, name = tag.partition(":")
    return f"{{{NS[prefix]}}}{name}"


def _md(fmu: Path):
    from fmpy import read_model_description

    return read_model_description(str(fmu))


def components(plant_fmu: Path, regulator_fmu: Path) -> list[tuple[str, Path, object]]:
    """(instance name, FMU file, model description), plant first."""
    return [(PLANT, Path(plant_fmu), _md(plant_fmu)), (REGULATOR, Path(regulator_fmu), _md(regulator_fmu))]


def connections(comps) -> list[tuple[str, str, str]]:
    """(start instance, variable, end instance) for every same-name, same-type output -> input."""
    out = []
    for a, _, md_a in comps:
        for b, _, md_b in comps:
            if a == b:
                continue
            inputs = {v.name: v.type for v in md_b.modelVariables if v.causality == "input"}
            out += [(a, v.name, b) for v in md_a.modelVariables
                    if v.causality == "output" and inputs.get(v.name) == v.type]
    return out


def nominal_values(comps) -> dict[str, list[tuple[str, str, str]]]:
    """Per instance (variable, type, start value as text): the plant's parameters and the
    command on each FMU that takes it as an input; the regulator's own parameters stay
    at their defaults."""
    out = {}
    for name, _, md in comps:
        variables = {v.name: v for v in md.modelVariables}
        rows = [(v.name, v.type, v.start) for v in md.modelVariables
                if name == PLANT and v.causality == "parameter"]
        rows += [(n, variables[n].type, value) for n, value in NOMINAL_COMMAND.items()
                 if n in variables and variables[n].causality == "input"]
        out[name] = rows
    return out


def _units(comps) -> dict[str, dict[str, str]]:
    units = {}
    for _, _, md in comps:
        for unit in md.unitDefinitions:
            base = unit.baseUnit
            exps = {k: str(getattr(base, k)) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
                    if getattr(base, k, 0)}
            if getattr(base, "factor", 1.0) != 1.0:
                exps["factor"] = repr(base.factor)
            units[unit.name] = exps
    return units


def _ssv(name: str, rows) -> bytes:
    root = ET.Element(_q("ssv:ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(root, _q("ssv:Parameters"))
    for var, kind, value in rows:
        ET.SubElement(ET.SubElement(params, _q("ssv:Parameter"), name=var), _q(f"ssv:{kind}"), value=value)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _component(parent, name: str, fmu: Path, md, connected: set[str], units) -> None:
    comp = ET.SubElement(parent, _q("ssd:Component"), name=name, source=f"resources/{fmu.name}", type=FMU_MIME)
    connectors = ET.SubElement(comp, _q("ssd:Connectors"))
    for v in md.modelVariables:  # every output (results show them) and the connected inputs
        if v.causality == "output" or (v.causality == "input" and v.name in connected):
            typed = ET.SubElement(ET.SubElement(connectors, _q("ssd:Connector"), name=v.name, kind=v.causality),
                                  _q(f"ssc:{v.type}"))
            if v.type == "Real" and v.unit in units:
                typed.set("unit", v.unit)
    binding = ET.SubElement(ET.SubElement(comp, _q("ssd:ParameterBindings")), _q("ssd:ParameterBinding"))
    binding.set("source", f"resources/{name}_nominal.ssv")


def _ssd(comps) -> bytes:
    for prefix, uri in NS.items():
        ET.register_namespace(prefix, uri)
    units = _units(comps)
    root = ET.Element(_q("ssd:SystemStructureDescription"), {"version": "1.0", "name": SYSTEM_NAME})
    system = ET.SubElement(root, _q("ssd:System"), name=SYSTEM_NAME,
                           description="MuJoCo Cassie closed around the adaptive velocity regulator, name to name")
    elements = ET.SubElement(system, _q("ssd:Elements"))
    wires = connections(comps)
    for name, fmu, md in comps:
        _component(elements, name, fmu, md, {var for _, var, end in wires if end == name}, units)
    conns = ET.SubElement(system, _q("ssd:Connections"))
    for start, var, end in wires:
        ET.SubElement(conns, _q("ssd:Connection"), startElement=start, startConnector=var, endElement=end,
                      endConnector=var)
    unit_defs = ET.SubElement(root, _q("ssd:Units"))
    for name, exps in units.items():
        ET.SubElement(ET.SubElement(unit_defs, _q("ssc:Unit"), name=name), _q("ssc:BaseUnit"), exps)
    experiment = ET.SubElement(root, _q("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(STOP_S))
    annotation = ET.SubElement(ET.SubElement(experiment, _q("ssd:Annotations")), _q("ssc:Annotation"),
                               type="com.opensimulationplatform")
    ET.SubElement(ET.SubElement(annotation, _q("osp:Algorithm")), _q("osp:FixedStepAlgorithm"),
                  baseStepSize=repr(STEP_S))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def ssp_entries(plant_fmu: Path, regulator_fmu: Path) -> dict[str, bytes]:
    """The files of ``CassieAVR.ssp`` by archive name (the caller writes the zip)."""
    comps = components(plant_fmu, regulator_fmu)
    entries = {"SystemStructure.ssd": _ssd(comps)}
    for (name, fmu, _), (_, rows) in zip(comps, nominal_values(comps).items()):
        entries[f"resources/{fmu.name}"] = fmu.read_bytes()
        entries[f"resources/{name}_nominal.ssv"] = _ssv(PARAMETER_SET, rows)
    return entries


def osp_system_structure(plant_fmu: Path, regulator_fmu: Path) -> bytes:
    """``OspSystemStructure.xml`` of the same system (FMUs expected beside it)."""
    comps = components(plant_fmu, regulator_fmu)
    ET.register_namespace("", OSP_NS)
    root = ET.Element(f"{{{OSP_NS}}}OspSystemStructure", {"version": "0.1"})

    def sub(parent, tag, **attrib):
        return ET.SubElement(parent, f"{{{OSP_NS}}}{tag}", attrib)

    sub(root, "StartTime").text = "0.0"
    sub(root, "BaseStepSize").text = repr(STEP_S)
    sub(root, "Algorithm").text = "fixedStep"
    simulators = sub(root, "Simulators")
    values = nominal_values(comps)
    for name, fmu, _ in comps:
        initial = sub(sub(simulators, "Simulator", name=name, source=fmu.name, stepSize=repr(STEP_S)),
                      "InitialValues")
        for var, kind, value in values[name]:
            sub(sub(initial, "InitialValue", variable=var), kind, value=value)
    conns = sub(root, "Connections")
    for start, var, end in connections(comps):
        conn = sub(conns, "VariableConnection")
        sub(conn, "Variable", simulator=start, name=var)
        sub(conn, "Variable", simulator=end, name=var)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
