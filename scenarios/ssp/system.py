"""The closed loop as a system of three FMUs: the SSP package and the OSP system structure.

``python build.py`` writes ``dist/CassieAVR.ssp`` and ``dist/CassieAVR_osp/`` from the
built FMUs with the functions here, and ``python -m scenarios export-ssp`` a scenario's
SSP (:mod:`scenarios.ssp.export_ssp`); everything is read from the FMUs' own model
descriptions (names, causality, types, units, start values), so the system always
matches the FMUs it packs:

* components ``plant`` (``CassiePlant.fmu``), ``avr`` (``AdaptiveVelocityRegulator.fmu``)
  and ``command`` (``CommandSource_fmi2.fmu``: the command and the pushes over time, from
  its ``resources/schedule.csv``, see :mod:`fmu_src.command_source.build_command_source`);
* connections name to name: every output of one that is an input of another with the
  same name and type (the plant's ``vx, vy, pitch, roll, pitch_rate, roll_rate,
  step_index`` to the regulator, the regulator's six ``delta_*`` to the plant, the
  command's ``vx_des, vy_des`` to both, its ``yaw_rate_des`` and ``push_fx/fy/fz`` to the
  plant: the regulator has no yaw-rate input, the speeds it regulates are in the heading
  frame whatever the turning rate);
* one parameter-set name, :data:`PARAMETER_SET`, bound to each component that has
  parameters (``resources/<instance>_nominal.ssv``, bare variable names as SSP 1.0 wants
  for a component binding): every parameter of the plant and of the regulator, at its
  start value or the scenario's value.  Only parameters: SSP 1.0 (5.3.4) applies a
  parameter set before initialization, where FMI 2.0 inputs may not be set; the inputs
  are all driven through connections.  One name for all because masters differ in how
  they pick a set: libcosim applies each component's first binding, Ecos applies every
  component's set of the one name given to ``init(parameter_set=...)``; fmpy's
  ``simulate_ssp`` reads no binding (:func:`scenarios.ssp.system_run.ssp_parameter_set`
  hands them over);
* a default experiment (30 s for the nominal system) with a fixed 5 ms step (OSP
  annotation, which libcosim reads).
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Mapping

NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
      "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations"}
OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SYSTEM_NAME = "CassieAVR"
PLANT, REGULATOR, COMMAND = "plant", "avr", "command"
STEP_S = 0.005
STOP_S = 30.0
FMU_MIME = "application/x-fmu-sharedlibrary"
#: The name of every component's parameter set (Ecos: ``init(parameter_set=PARAMETER_SET)``).
PARAMETER_SET = "nominal"


def _q(tag: str) -> str:
    prefix, _, name = tag.partition(":")
    return f"{{{NS[prefix]}}}{name}"


def _md(fmu: Path):
    from fmpy import read_model_description

    return read_model_description(str(fmu))


def components(plant_fmu: Path, regulator_fmu: Path, command_fmu: Path) -> list[tuple[str, Path, object]]:
    """(instance name, FMU file, model description): plant, regulator, command source."""
    return [(name, Path(fmu), _md(fmu)) for name, fmu in
            ((PLANT, plant_fmu), (REGULATOR, regulator_fmu), (COMMAND, command_fmu))]


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


def value_text(kind: str, value: Any) -> str:
    """``value`` as an SSV/SSD attribute of type ``kind`` (Real, Integer, Boolean, String) writes it."""
    if kind == "Boolean":
        return ("true" if value else "false") if isinstance(value, bool) else str(value).lower()
    if kind == "Real":
        return repr(float(value))
    return str(int(value)) if kind == "Integer" else str(value)


def parameter_values(comps, values: Mapping[str, Mapping[str, Any]] | None = None
                     ) -> dict[str, list[tuple[str, str, str]]]:
    """Per instance that has parameters: (variable, type, value as text) for every parameter,
    its start value unless ``values[instance][variable]`` gives another; KeyError naming any
    given name that is not a parameter of that FMU."""
    values = values or {}
    out = {}
    for name, _, md in comps:
        params = {v.name: v for v in md.modelVariables if v.causality == "parameter"}
        given = dict(values.get(name, {}))
        unknown = sorted(set(given) - set(params))
        if unknown:
            raise KeyError(f"{name}: no parameter(s) {', '.join(unknown)} (parameters: {', '.join(params)})")
        if params:
            out[name] = [(v.name, v.type, value_text(v.type, given[v.name]) if v.name in given else v.start)
                         for v in params.values()]
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


def parameter_set(name: str, rows) -> bytes:
    """An SSP 1.0 parameter-values file (``.ssv``): the set ``name`` of ``rows`` (variable, type, value as text)."""
    _register_namespaces()
    root = ET.Element(_q("ssv:ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(root, _q("ssv:Parameters"))
    for var, kind, value in rows:
        ET.SubElement(ET.SubElement(params, _q("ssv:Parameter"), name=var), _q(f"ssv:{kind}"), value=value)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _component(parent, name: str, fmu: Path, md, connected: set[str], units, bound: bool) -> None:
    comp = ET.SubElement(parent, _q("ssd:Component"), name=name, source=f"resources/{fmu.name}", type=FMU_MIME)
    connectors = ET.SubElement(comp, _q("ssd:Connectors"))
    for v in md.modelVariables:  # every output (results show them) and the connected inputs
        if v.causality == "output" or (v.causality == "input" and v.name in connected):
            typed = ET.SubElement(ET.SubElement(connectors, _q("ssd:Connector"), name=v.name, kind=v.causality),
                                  _q(f"ssc:{v.type}"))
            if v.type == "Real" and v.unit in units:
                typed.set("unit", v.unit)
    if bound:
        binding = ET.SubElement(ET.SubElement(comp, _q("ssd:ParameterBindings")), _q("ssd:ParameterBinding"))
        binding.set("source", f"resources/{name}_{PARAMETER_SET}.ssv")


def _register_namespaces() -> None:
    """Write the SSP prefixes (ssd:, ssv:, ...) whatever was serialized before in this process."""
    for prefix, uri in NS.items():
        ET.register_namespace(prefix, uri)


def _ssd(comps, bound: set[str], system_name: str, description: str, stop_s: float) -> bytes:
    _register_namespaces()
    units = _units(comps)
    root = ET.Element(_q("ssd:SystemStructureDescription"), {"version": "1.0", "name": system_name})
    system = ET.SubElement(root, _q("ssd:System"), name=system_name, description=description)
    elements = ET.SubElement(system, _q("ssd:Elements"))
    wires = connections(comps)
    for name, fmu, md in comps:
        _component(elements, name, fmu, md, {var for _, var, end in wires if end == name}, units, name in bound)
    conns = ET.SubElement(system, _q("ssd:Connections"))
    for start, var, end in wires:
        ET.SubElement(conns, _q("ssd:Connection"), startElement=start, startConnector=var, endElement=end,
                      endConnector=var)
    unit_defs = ET.SubElement(root, _q("ssd:Units"))
    for name, exps in units.items():
        ET.SubElement(ET.SubElement(unit_defs, _q("ssc:Unit"), name=name), _q("ssc:BaseUnit"), exps)
    experiment = ET.SubElement(root, _q("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(float(stop_s)))
    annotation = ET.SubElement(ET.SubElement(experiment, _q("ssd:Annotations")), _q("ssc:Annotation"),
                               type="com.opensimulationplatform")
    ET.SubElement(ET.SubElement(annotation, _q("osp:Algorithm")), _q("osp:FixedStepAlgorithm"),
                  baseStepSize=repr(STEP_S))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def ssp_entries(plant_fmu: Path, regulator_fmu: Path, command_fmu: Path, *,
                values: Mapping[str, Mapping[str, Any]] | None = None, system_name: str = SYSTEM_NAME,
                description: str = "MuJoCo Cassie closed around the adaptive velocity regulator, "
                                   "the command and pushes from the command source, name to name",
                stop_s: float = STOP_S) -> dict[str, bytes]:
    """The files of an SSP of the three FMUs by archive name (the caller writes the zip):
    ``values`` {instance: {parameter: value}} on top of the start values; the command and
    pushes are whatever ``command_fmu``'s schedule says."""
    comps = components(plant_fmu, regulator_fmu, command_fmu)
    params = parameter_values(comps, values)
    entries = {"SystemStructure.ssd": _ssd(comps, set(params), system_name, description, stop_s)}
    for name, fmu, _ in comps:
        entries[f"resources/{fmu.name}"] = fmu.read_bytes()
        if name in params:
            entries[f"resources/{name}_{PARAMETER_SET}.ssv"] = parameter_set(PARAMETER_SET, params[name])
    return entries


def osp_system_structure(plant_fmu: Path, regulator_fmu: Path, command_fmu: Path) -> bytes:
    """``OspSystemStructure.xml`` of the nominal system (FMUs expected beside it)."""
    comps = components(plant_fmu, regulator_fmu, command_fmu)
    ET.register_namespace("", OSP_NS)
    root = ET.Element(f"{{{OSP_NS}}}OspSystemStructure", {"version": "0.1"})

    def sub(parent, tag, **attrib):
        return ET.SubElement(parent, f"{{{OSP_NS}}}{tag}", attrib)

    sub(root, "StartTime").text = "0.0"
    sub(root, "BaseStepSize").text = repr(STEP_S)
    sub(root, "Algorithm").text = "fixedStep"
    simulators = sub(root, "Simulators")
    values = parameter_values(comps)
    for name, fmu, _ in comps:
        simulator = sub(simulators, "Simulator", name=name, source=fmu.name, stepSize=repr(STEP_S))
        if values.get(name):
            initial = sub(simulator, "InitialValues")
            for var, kind, value in values[name]:
                sub(sub(initial, "InitialValue", variable=var), kind, value=value)
    conns = sub(root, "Connections")
    for start, var, end in connections(comps):
        conn = sub(conns, "VariableConnection")
        sub(conn, "Variable", simulator=start, name=var)
        sub(conn, "Variable", simulator=end, name=var)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)
