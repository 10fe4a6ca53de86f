"""Build ``CommandSource_fmi2.fmu`` / ``CommandSource_fmi3.fmu``: the native FMU that plays a
scenario's command and pushes (``resources/schedule.csv``) into the CassieAVR system.

One C source for both FMI versions (``cmdsrc.c`` + the layer ``cmdsrc_fmi<2|3>.c`` over the FMI
layer the native FMUs share, ``fmu_src/fmi/``: its prologue, generated phase rules and refused
functions),
compiled for the platforms and with the compilers and options of the regulator's native
FMU (:mod:`fmu_src.regulator_fmu.native.build_native`; a platform whose cross compiler is missing is
skipped).  The GUID hashes the model description and the sources, not
``resources/schedule.csv``: :func:`with_schedule` makes a copy with another schedule that is
the same FMU (same binaries, same GUID).

The schedule (:func:`schedule_csv`): a header ``time,vx_des,vy_des,yaw_rate_des,push_fx,push_fy,push_fz``
then one row per change, times strictly increasing from the start time, numbers in C
notation ('.' decimal point).  At time t the outputs hold the last row with time <= t
(relative tolerance 1e-9).
"""
from __future__ import annotations

import hashlib
import html
import io
import shutil
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Iterable, Mapping

from fmu_src.packing import compiler
from fmu_src.packing.archive import PLACEHOLDER_GUID, content_guid, read_entries, write_zip
from fmu_src.regulator_fmu.native import build_native

SRC = Path(__file__).resolve().parent
MODEL_IDENTIFIER = "CommandSource"
#: where the nominal build's reference results live in the FMU (fmi-ls-ref; added by build.py)
REFERENCE_PREFIX = "extra/org.fmi-standard.fmi-ls-ref/"
INSTANCE_NAME = "command"
#: (name, unit, description) in value-reference order: the columns after ``time``.
OUTPUTS = (
    ("vx_des", "m/s", "Commanded forward speed in the heading frame"),
    ("vy_des", "m/s", "Commanded lateral speed in the heading frame"),
    ("yaw_rate_des", "rad/s", "Commanded turning rate (positive turns left)"),
    ("push_fx", "N", "Push on the pelvis, world x"),
    ("push_fy", "N", "Push on the pelvis, world y"),
    ("push_fz", "N", "Push on the pelvis, world z"),
)
NAMES = tuple(name for name, _, _ in OUTPUTS)
HEADER = "time," + ",".join(NAMES)
SCHEDULE = "resources/schedule.csv"
UNITS = {"m/s": {"m": "1", "s": "-1"}, "rad/s": {"rad": "1", "s": "-1"}, "N": {"kg": "1", "m": "1", "s": "-2"}}
#: FMI 3.0's independent variable ``time`` has a unit, which the model description must define.
TIME_UNIT = {"s": {"s": "1"}}
CORE = ("cmdsrc.c",)
API = {2: ("cmdsrc_fmi2.c", "fmi2_common.c"), 3: ("cmdsrc_fmi3.c", "fmi3_common.c")}
HEADERS = ("cmdsrc.h", "fmi_model.h")
GUID_HEADER = "cs_guid.h"
PLATFORMS = build_native.PLATFORMS
DESCRIPTION = ("Plays a schedule of the walking command (vx_des, vy_des, yaw_rate_des) and the pelvis push "
               "(push_fx/fy/fz) from resources/schedule.csv: piecewise constant, the last row at or before t")
VERSION = "0.1.0"
#: A nominal schedule: 0.5 m/s forward from t = 0, no turn, no push.
NOMINAL_ROWS = ((0.0, {"vx_des": 0.5, "vy_des": 0.0, "yaw_rate_des": 0.0, "push_fx": 0.0, "push_fy": 0.0,
                       "push_fz": 0.0}),)


def fmu_name(fmi_version: int) -> str:
    return f"{MODEL_IDENTIFIER}_fmi{fmi_version}.fmu"


def sources(fmi_version: int) -> tuple[str, ...]:
    return CORE + API[fmi_version]


def schedule_csv(rows: Iterable[tuple[float, Mapping[str, float]]]) -> str:
    """The schedule file for ``rows``: (time s, {output: value}); ValueError naming what is wrong."""
    lines, last = [HEADER], None
    for i, (t, values) in enumerate(rows):
        missing = [n for n in NAMES if n not in values]
        if missing:
            raise ValueError(f"schedule row {i} (t = {t!r} s) has no {', '.join(missing)}")
        numbers = [float(t), *(float(values[n]) for n in NAMES)]
        bad = [name for name, x in zip(("time",) + NAMES, numbers) if x != x or x in (float("inf"), float("-inf"))]
        if bad:
            raise ValueError(f"schedule row {i}: {', '.join(bad)} must be finite")
        if last is not None and not numbers[0] > last:
            raise ValueError(f"schedule row {i}: time = {t!r} s must be after the previous row's {last!r} s")
        last = numbers[0]
        lines.append(",".join(repr(x) for x in numbers))
    if len(lines) == 1:
        raise ValueError("a schedule needs at least one row")
    return "\n".join(lines) + "\n"


# ---- model description, documentation, sources ----------------------------------------------
def _md(fmi_version: int, guid: str) -> bytes:
    token = {"guid": guid} if fmi_version == 2 else {"instantiationToken": guid}
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": f"{fmi_version}.0", "modelName": MODEL_IDENTIFIER, **token, "description": DESCRIPTION,
        "author": build_native.describe.AUTHOR, "version": VERSION, "license": build_native.describe.LICENSE,
        "generationTool": "cassie-avr build.py", "variableNamingConvention": "flat"})
    common = {"modelIdentifier": MODEL_IDENTIFIER, "canHandleVariableCommunicationStepSize": "true",
              "canBeInstantiatedOnlyOncePerProcess": "false"}
    if fmi_version == 2:
        cs = ET.SubElement(root, "CoSimulation", common, canNotUseMemoryManagementFunctions="true",
                           canGetAndSetFMUstate="false", canSerializeFMUstate="false")
        files = ET.SubElement(cs, "SourceFiles")
        for name in sources(2):
            ET.SubElement(files, "File", name=name)
    else:
        ET.SubElement(root, "CoSimulation", common, canGetAndSetFMUState="false", canSerializeFMUState="false",
                      hasEventMode="false", providesIntermediateUpdate="false")
    units = ET.SubElement(root, "UnitDefinitions")
    for name, exps in {**UNITS, **(TIME_UNIT if fmi_version == 3 else {})}.items():
        ET.SubElement(ET.SubElement(units, "Unit", name=name), "BaseUnit", exps)
    cats = ET.SubElement(root, "LogCategories")
    ET.SubElement(cats, "Category", name="logStatusError", description="Refused calls and errors (always logged)")
    ET.SubElement(cats, "Category", name="logAll", description="Debug messages (with logging on)")
    ET.SubElement(root, "DefaultExperiment", startTime="0", stepSize="0.005")
    variables = ET.SubElement(root, "ModelVariables")
    for vr, (name, unit, text) in enumerate(OUTPUTS):
        attrs = {"name": name, "valueReference": str(vr), "description": text, "causality": "output",
                 "variability": "discrete", "initial": "calculated"}
        if fmi_version == 2:
            ET.SubElement(ET.SubElement(variables, "ScalarVariable", attrs), "Real", unit=unit)
        else:
            ET.SubElement(variables, "Float64", {**attrs, "unit": unit})
    structure = ET.SubElement(root, "ModelStructure")
    if fmi_version == 2:
        outputs = ET.SubElement(structure, "Outputs")
        for vr in range(len(OUTPUTS)):
            ET.SubElement(outputs, "Unknown", index=str(vr + 1), dependencies="")
        initial = ET.SubElement(structure, "InitialUnknowns")
        for vr in range(len(OUTPUTS)):
            ET.SubElement(initial, "Unknown", index=str(vr + 1), dependencies="")
    else:
        ET.SubElement(variables, "Float64", name="time", valueReference=str(len(OUTPUTS)), causality="independent",
                      variability="continuous", unit="s", description="Simulation time")
        for vr in range(len(OUTPUTS)):
            ET.SubElement(structure, "Output", valueReference=str(vr), dependencies="")
        for vr in range(len(OUTPUTS)):
            ET.SubElement(structure, "InitialUnknown", valueReference=str(vr), dependencies="")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _build_description() -> bytes:
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=MODEL_IDENTIFIER)
    files = ET.SubElement(config, "SourceFileSet", language="C99",
                          compilerOptions=build_native.describe.COMPILER_OPTIONS)
    for name in sources(3):
        ET.SubElement(files, "SourceFile", name=name)
    ET.SubElement(files, "IncludeDirectory", name=".")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _documentation(fmi_version: int) -> bytes:
    rows = "\n".join(f"<tr><td>{vr}</td><td>{n}</td><td>{html.escape(u)}</td><td>{html.escape(t)}</td></tr>"
                     for vr, (n, u, t) in enumerate(OUTPUTS))
    return f"""<!DOCTYPE html>
<html><head><meta charset="utf-8"><title>{MODEL_IDENTIFIER} (FMI {fmi_version}.0)</title></head><body>
<h1>{MODEL_IDENTIFIER} (FMI {fmi_version}.0 co-simulation, native C)</h1>
<p>{html.escape(DESCRIPTION)}.</p>
<h2>The schedule</h2>
<p><code>resources/schedule.csv</code>: a header line <code>{HEADER}</code>, then one row per change (times in s,
strictly increasing; '.' as decimal point; empty lines and lines starting with # are skipped). At time t the
outputs hold the last row whose time is at or before t (relative tolerance 1e-9): a master that hands the outputs
at the communication point t to its other FMUs applies that row over the step [t, t + h). A push of duration d
from t0 is two rows: the force at t0 and its removal at t0 + d. The start time must be at or after the first row.
A missing or malformed schedule fails the instantiation with a message naming the file, the line and the field.</p>
<h2>FMI behaviour</h2>
<p>No inputs and no parameters; outputs change only in doStep (no direct feedthrough). Calls the FMI state
machine forbids, and any set of a variable, are refused with Error and a log message; a refused call changes
nothing. No FMU state, no derivatives.</p>
<h2>Variables</h2>
<table border="1"><tr><th>valueReference</th><th>name</th><th>unit</th><th>description</th></tr>
{rows}
</table></body></html>
""".encode()


def _text_entries(fmi_version: int, guid: str) -> dict[str, bytes]:
    files = {name: build_native.source_file(name, SRC).read_bytes() for name in sources(fmi_version) + HEADERS}
    files.update(build_native.shared_entries(fmi_version))
    files[GUID_HEADER] = (f"/* Generated by build.py: the content-derived GUID of this FMU. */\n"
                          f'#define CS_GUID "{guid}"\n').encode()
    if fmi_version == 3:
        files["buildDescription.xml"] = _build_description()
    entries = {f"sources/{name}": data for name, data in files.items()}
    entries["modelDescription.xml"] = _md(fmi_version, guid)
    entries["documentation/index.html"] = _documentation(fmi_version)
    return entries


def compile_library(src: Path, fmi_version: int, target: str, out: Path, extra_flags=()) -> Path:
    """The library for ``target`` (a target of ``build_native.PLATFORMS``) from the FMU's sources in
    ``src``: the regulator's compilers and options (``extra_flags`` after them, e.g. the tests'
    sanitizers)."""
    name = out.name
    cmd = build_native.compile_command(target, sources(fmi_version), name, extra_flags)
    compiler.run(cmd, "the CommandSource FMU", cwd=src)
    shutil.move(str(src / name), out)
    return out


def fmu_entries(fmi_version: int, schedule: str | None = None) -> dict[str, bytes]:
    """Every file of the FMI ``fmi_version`` CommandSource FMU with ``schedule`` (CSV text;
    default: the nominal 0.5 m/s)."""
    guid = content_guid(hashlib.sha256(f"command source fmi{fmi_version}\0".encode()),
                        _text_entries(fmi_version, PLACEHOLDER_GUID), skip={f"sources/{GUID_HEADER}"})
    entries = _text_entries(fmi_version, guid)
    with tempfile.TemporaryDirectory(prefix="cmdsrc_") as tmp:
        src = Path(tmp) / "src"
        src.mkdir()
        for name, data in entries.items():
            if name.startswith("sources/"):
                (src / name[len("sources/"):]).write_bytes(data)
        for platform, target in build_native.buildable_platforms(fmi_version, fmu_name(fmi_version)).items():
            suffix = build_native.LIBRARY_SUFFIX[target]
            lib = compile_library(src, fmi_version, target, Path(tmp) / f"{MODEL_IDENTIFIER}{suffix}")
            entries[f"binaries/{platform}/{lib.name}"] = lib.read_bytes()
    entries[SCHEDULE] = (schedule or schedule_csv(NOMINAL_ROWS)).encode()
    return entries


def with_schedule(fmu: str | Path, schedule: str, out: str | Path) -> Path:
    """A copy of the built CommandSource FMU ``fmu`` playing ``schedule`` instead (same GUID:
    the schedule is not part of it)."""
    entries = read_entries(Path(fmu))
    if SCHEDULE not in entries or "modelDescription.xml" not in entries:
        raise ValueError(f"{fmu} is not a CommandSource FMU (no {SCHEDULE})")
    root = ET.parse(io.BytesIO(entries["modelDescription.xml"])).getroot()
    if root.get("modelName") != MODEL_IDENTIFIER:
        raise ValueError(f"{fmu} is {root.get('modelName')!r}, not a {MODEL_IDENTIFIER} FMU")
    entries[SCHEDULE] = schedule.encode()
    # the nominal build's reference results (fmi-ls-ref) describe the nominal schedule, not this one
    entries = {name: data for name, data in entries.items() if not name.startswith(REFERENCE_PREFIX)}
    write_zip(entries, Path(out))
    return Path(out)
