"""The native FMUs' XML and documentation, generated from the core's variable tables.

``model_description`` writes ``modelDescription.xml`` for FMI 2.0 or FMI 3.0 from
``PARAM_SPECS``/``INPUT_SPECS``/``OUTPUT_SPECS`` (in value-reference order, as
:func:`fmu_src.regulator_fmu.native.header.all_specs`), ``build_description`` the FMI 3.0
``sources/buildDescription.xml``, and ``documentation`` the HTML page; build.py packs
them with the binaries.  Only units listed in ``units`` are declared (the same
``UNITS`` as the pythonfmu FMU's model description).
"""
from __future__ import annotations

import html
import xml.etree.ElementTree as ET

from fmu_src.packing.describe import xml_value
from fmu_src.packing.method_page import method_html
from fmu_src.packing.parameters import parameters_html
from fmu_src.regulator_fmu.native.header import LOG_CATEGORIES, all_specs

AUTHOR = "cassie-avr project"
VERSION = "0.1.0"
LICENSE = "MIT"
DESCRIPTION = ("Adaptive velocity regulator for bipedal walking (native C implementation): PD foot-placement "
               "and torso regulators plus online-learning neural networks (PES) that output virtual-constraint "
               "offsets")
#: Compiler options of the shipped binaries.  None is needed for the numerics' bits: the sources
#: state their floating-point contract (no FMA contraction, avr_types.h), so any C99 compiler in
#: any mode and at any optimization level gives the same bits; -O3 -fno-trapping-math only let
#: the element-wise loops vectorize (same IEEE operations).  Never -ffast-math (it allows
#: reassociation, which no pragma in the sources can undo).
COMPILER_OPTIONS = "-std=c99 -O3 -fno-trapping-math"
_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}


def _units(root: ET.Element, units: dict) -> None:
    element = ET.SubElement(root, "UnitDefinitions")
    for name, exponents in units.items():
        ET.SubElement(ET.SubElement(element, "Unit", name=name), "BaseUnit", exponents)


def _typed_attributes(spec, units: dict) -> dict:
    attrs = {"start": xml_value(spec.default)}
    if spec.type in ("Real", "Integer"):
        if spec.min is not None:
            attrs["min"] = xml_value(spec.min)
        if spec.max is not None:
            attrs["max"] = xml_value(spec.max)
    if spec.type == "Real" and spec.unit in units:
        attrs["unit"] = spec.unit
    return attrs


def _variable_attributes(spec, vr: int) -> dict:
    attrs = {"name": spec.name, "valueReference": str(vr), "description": spec.fmi_description,
             "causality": spec.causality, "variability": spec.variability}
    if spec.causality != "input":  # FMI: `initial` is not allowed on inputs
        attrs["initial"] = "exact"
    return attrs


def _interface(root: ET.Element, fmi_version: int, model_identifier: str, source_files) -> None:
    common = {"modelIdentifier": model_identifier, "canHandleVariableCommunicationStepSize": "true",
              "canBeInstantiatedOnlyOncePerProcess": "false"}
    if fmi_version == 2:
        cs = ET.SubElement(root, "CoSimulation", common, canInterpolateInputs="false",
                           canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                           canSerializeFMUstate="true", providesDirectionalDerivative="false")
        files = ET.SubElement(cs, "SourceFiles")
        for name in source_files:
            ET.SubElement(files, "File", name=name)
    else:
        ET.SubElement(root, "CoSimulation", common, canGetAndSetFMUState="true", canSerializeFMUState="true",
                      hasEventMode="false", providesIntermediateUpdate="false")


def model_description(fmi_version: int, model_identifier: str, guid: str, source_files, units: dict,
                      default_experiment: dict) -> bytes:
    """``modelDescription.xml`` of the native FMU for ``fmi_version`` 2 or 3."""
    token = {"guid": guid} if fmi_version == 2 else {"instantiationToken": guid}
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": f"{fmi_version}.0", "modelName": model_identifier, **token, "description": DESCRIPTION,
        "author": AUTHOR, "version": VERSION, "license": LICENSE, "generationTool": "cassie-avr build.py",
        "variableNamingConvention": "flat"})
    _interface(root, fmi_version, model_identifier, source_files)
    _units(root, units)
    categories = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES:
        ET.SubElement(categories, "Category", name=name, description=text)
    ET.SubElement(root, "DefaultExperiment", default_experiment)
    variables = ET.SubElement(root, "ModelVariables")
    specs = all_specs()
    for vr, spec in enumerate(specs):
        if fmi_version == 2:
            var = ET.SubElement(variables, "ScalarVariable", _variable_attributes(spec, vr))
            ET.SubElement(var, spec.type, _typed_attributes(spec, units))
        else:
            ET.SubElement(variables, _FMI3_TYPES[spec.type],
                          {**_variable_attributes(spec, vr), **_typed_attributes(spec, units)})
    structure = ET.SubElement(root, "ModelStructure")
    outputs = [(vr, s) for vr, s in enumerate(specs) if s.causality == "output"]
    if fmi_version == 2:
        element = ET.SubElement(structure, "Outputs")
        for vr, _ in outputs:  # no direct feedthrough: outputs change only in doStep
            ET.SubElement(element, "Unknown", index=str(vr + 1), dependencies="")
    else:
        ET.SubElement(variables, "Float64", name="time", valueReference=str(len(specs)), causality="independent",
                      variability="continuous", unit="s", description="Simulation time, s")
        for vr, _ in outputs:
            ET.SubElement(structure, "Output", valueReference=str(vr), dependencies="")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_description(model_identifier: str, source_files) -> bytes:
    """FMI 3.0 ``sources/buildDescription.xml``: compile every listed C file, link libm."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model_identifier,
                           description="Any C99 compiler, any options but fast-math: the sources themselves "
                                       "forbid FMA contraction, so every build gives the shipped binaries' bits")
    files = ET.SubElement(config, "SourceFileSet", language="C99", compilerOptions=COMPILER_OPTIONS)
    for name in source_files:
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(files, "IncludeDirectory", name=".")
    ET.SubElement(config, "Library", name="m", description="the C math library (Linux, macOS)")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def documentation(fmi_version: int, model_identifier: str, platforms) -> str:
    """``documentation/index.html``: the platforms with binaries (``platforms``: (folder, what it
    runs on) pairs), the FMI behaviour, the method (``docs/method.md``) and the variables."""
    specs = all_specs()
    binaries = "".join(f"<li><code>binaries/{html.escape(folder)}/</code>: {html.escape(name)}</li>"
                       for folder, name in platforms)
    aarch64_note = (" FMI 2.0 names no platform folder for Linux aarch64: there, use the FMI 3.0 FMU (which "
                    "carries that binary) or build this one from its sources." if fmi_version == 2 else "")
    rows = "\n".join(
        "<tr>" + "".join(f"<td>{html.escape(str(cell))}</td>" for cell in (
            vr, s.name, s.causality, s.tier or "", s.type, s.variability, s.unit, xml_value(s.default),
            "" if s.min is None else xml_value(s.min), "" if s.max is None else xml_value(s.max), s.fmi_description)) + "</tr>"
        for vr, s in enumerate(specs))
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{model_identifier} (FMI {fmi_version}.0)</title></head><body>
<h1>{model_identifier} (FMI {fmi_version}.0 co-simulation, native C)</h1>
<p>{html.escape(DESCRIPTION)}. No Python is needed.</p>
<h2>Platforms</h2>
<p>This FMU carries binaries for:</p>
<ul>{binaries}</ul>
<p>For any other platform, the C sources in <code>sources/</code> build the library with any C99 compiler
(shipped binaries: <code>{COMPILER_OPTIONS}</code>; no option is needed, only never fast-math). The sources
forbid FMA contraction themselves (<code>#pragma STDC FP_CONTRACT OFF</code> and the GCC and MSVC
equivalents), so a library built from them, in any C mode and at any optimization level, computes the same
bits as the shipped binaries on any CPU whose C compiler evaluates doubles in double precision
(FLT_EVAL_METHOD 0: x86-64, aarch64 and the other 64-bit CPUs; not 32-bit x87 code).{aarch64_note}</p>
<h2>FMI behaviour</h2>
<p>Any communication step &gt; 0 (one regulator call per step whatever its length: no maximum; a step whose
end time overflows is refused). Calls the FMI {fmi_version}.0 state machine forbids, sets of outputs or of
fixed parameters after initialization, NaN/inf values and values outside [min, max], and log categories the
model description does not declare are refused with Error and a log message naming the variable and its range
(or the category); a refused call changes nothing and the instance stays usable.
FMU state can be saved, restored and serialized (all variables, weights and memories; the serialized form carries
the GUID and a CRC-32 and is refused if corrupt or from another FMU, and so is one whose contents no run can
reach: a value out of range, counters beyond what a run counts). Outputs change only in doStep (no direct
feedthrough). Same value references, variables and numerics as the pythonfmu FMU AdaptiveVelocityRegulator.</p>
{method_html()}{parameters_html()}<h2>Variables</h2>
<table border="1"><tr><th>valueReference</th><th>name</th><th>causality</th><th>tier</th><th>type</th><th>variability</th>
<th>unit</th><th>start</th><th>min</th><th>max</th><th>description</th></tr>
{rows}
</table></body></html>
"""
