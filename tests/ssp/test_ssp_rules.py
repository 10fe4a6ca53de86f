"""The SSP rules an XML schema cannot state (scenarios/ssp/ssp_check.py), on the CassieAVR.ssp
build.py writes and on broken copies of it, one rule broken at a time.

The built SSP must pass every rule.  Its parameter sets still bind the FMU inputs
``vx_des``, ``vy_des`` (both FMUs) and ``yaw_rate_des`` (the plant), which SSP 1.0 section
5.3.4 does not allow (an FMI 2.0 input has no ``initial``; bindings are applied before
``fmi2EnterInitializationMode``): that check is an expected failure until the command is
fed through a connection, and then flips to a pass (``strict``).

The broken copies keep the real FMUs; each case asserts exactly the problems the break
adds to those of the built SSP.
"""
from __future__ import annotations

import io
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from lxml import etree

from support.plant_fmu_support import built_system
from scenarios.ssp.ssp_check import NS, check_ssp
from support.paths import REPO_ROOT

SSD = "SystemStructure.ssd"
#: The FMU inputs the built SSP's parameter sets bind (the expected failure below).
INPUT_BINDINGS = ("vx_des", "vy_des", "yaw_rate_des")


@pytest.fixture(scope="module")
def ssp(tmp_path_factory, build_module, built_fmu) -> Path:
    return built_system(tmp_path_factory, build_module, built_fmu) / "CassieAVR.ssp"


@pytest.fixture(scope="module")
def baseline(ssp):
    return check_ssp(ssp)


@pytest.fixture(scope="module")
def entries(ssp) -> dict[str, str]:
    """Archive entries by role, read from the SSD: ``plant_fmu``, ``avr_fmu`` (the components' sources)
    and ``plant_ssv`` (the plant's parameter set)."""
    with zipfile.ZipFile(ssp) as archive:
        root = etree.fromstring(archive.read(SSD))
    comps = {c.get("name"): c for c in root.iterfind("ssd:System/ssd:Elements/ssd:Component", NS)}
    return {"plant_fmu": comps["plant"].get("source"), "avr_fmu": comps["avr"].get("source"),
            "plant_ssv": comps["plant"].find("ssd:ParameterBindings/ssd:ParameterBinding", NS).get("source")}


@pytest.mark.parametrize("rule", ["schema", "connector", "range", "connection", "unsupported", "binding"])
def test_the_built_ssp_keeps_the_rule(baseline, rule):
    assert [str(p) for p in baseline if p.rule == rule] == []


# ---- broken copies ---------------------------------------------------------------------------
def _edit_xml(data: bytes, edit) -> bytes:
    root = etree.fromstring(data)
    edit(root)
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8")


def _edit_fmu(data: bytes, edit) -> bytes:
    """The FMU ``data`` with its modelDescription.xml edited."""
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(data)) as src, zipfile.ZipFile(out, "w") as dst:
        for info in src.infolist():
            body = src.read(info)
            dst.writestr(info, _edit_xml(body, edit) if info.filename == "modelDescription.xml" else body)
    return out.getvalue()


def _copy(ssp: Path, dest: Path, edits: dict) -> Path:
    """A copy of ``ssp`` with the entries named in ``edits`` edited in place by the given functions
    of their XML root (of an FMU: of its model description)."""
    with zipfile.ZipFile(ssp) as src, zipfile.ZipFile(dest, "w") as dst:
        assert set(edits) <= set(src.namelist()), set(edits) - set(src.namelist())
        for info in src.infolist():
            body = src.read(info)
            edit = edits.get(info.filename)
            if edit is not None:
                body = (_edit_fmu if info.filename.endswith(".fmu") else _edit_xml)(body, edit)
            dst.writestr(info, body)
    return dest


def _added(baseline, path) -> list[tuple[str, str, str]]:
    return [(p.rule, p.where, p.message) for p in check_ssp(path) if p not in baseline]


def _connector(root, element: str, name: str):
    return root.find(f"ssd:System/ssd:Elements/ssd:Component[@name='{element}']/ssd:Connectors/"
                     f"ssd:Connector[@name='{name}']", NS)


def _retype(connector, kind: str) -> None:
    connector.replace(connector[0], etree.Element(f"{{{NS['ssc']}}}{kind}"))


def _bind(name: str, kind: str, value: str):
    def edit(root):
        param = etree.SubElement(root.find("ssv:Parameters", NS), f"{{{NS['ssv']}}}Parameter", name=name)
        etree.SubElement(param, f"{{{NS['ssv']}}}{kind}", value=value)
    return edit


def _set(path: str, attribute: str, value: str):
    def edit(root):
        root.find(path, NS).set(attribute, value)
    return edit


def _connect(start: str, start_connector: str, end: str, end_connector: str):
    def edit(root):
        etree.SubElement(root.find("ssd:System/ssd:Connections", NS), f"{{{NS['ssd']}}}Connection",
                         startElement=start, startConnector=start_connector, endElement=end,
                         endConnector=end_connector)
    return edit


def _calculated(name: str):
    """The variable without ``initial`` and ``start`` (as FMI 2.0 requires of a calculated one)."""
    def edit(root):
        variable = root.find(f"ModelVariables/ScalarVariable[@name='{name}']")
        del variable.attrib["initial"]
        del variable[0].attrib["start"]
    return edit


def _plant_start(name: str, value: str):
    def edit(root):
        root.find(f"ModelVariables/ScalarVariable[@name='{name}']/Real").set("start", value)
    return edit


CONNECTIONS = "SystemStructure.ssd connection"
CASES = {
    # binding: SSP 1.0 5.3.4
    "binding an input": (
        {"plant_ssv": _bind("delta_swing_knee", "Real", "0.1")},
        [("binding", "{plant_ssv} parameter 'delta_swing_knee'", "an FMI 2.0 input (no initial)")]),
    "binding an output the FMU calculates": (  # no initial on an output: FMI 2.0's default, calculated
        {"plant_fmu": _calculated("yaw"), "plant_ssv": _bind("yaw", "Real", "0.1")},
        [("binding", "{plant_ssv} parameter 'yaw'", "causality 'output', variability 'continuous', "
                                                    "initial 'calculated'")]),
    "binding a name the FMU lacks": (
        {"plant_ssv": _bind("torso_mass", "Real", "12")},
        [("binding", "{plant_ssv} parameter 'torso_mass'", "the FMU has no variable 'torso_mass'")]),
    "binding a value of another type": (
        {"plant_ssv": _bind("terrain_seed", "Real", "1.5")},
        [("binding", "{plant_ssv} parameter 'terrain_seed'", "a value of type Real for 'terrain_seed', a variable of type Integer")]),
    # range: FMI 2.0 2.2.7 (min <= value <= max)
    "a bound value above max": (
        {"plant_ssv": _set("ssv:Parameters/ssv:Parameter[@name='torso_mass_kg']/ssv:Real", "value", "150")},
        [("range", "{plant_ssv} parameter 'torso_mass_kg'", "150 is outside [0.0, 100.0]")]),
    "an FMU start value below min": (
        {"plant_fmu": _plant_start("joint_damping_scale", "-1")},
        [("range", "{plant_fmu} variable 'joint_damping_scale'", "start -1 is outside [0.0, 10.0]")]),
    # connector: SSP 1.0 5.3.1
    "a connector kind other than the causality": (
        {"ssd": lambda r: _connector(r, "plant", "yaw").set("kind", "input")},
        [("connector", "SystemStructure.ssd connector plant.yaw", "kind 'input' but the FMU variable's "
                                                                  "causality is 'output'")]),
    "a connector naming no variable": (
        {"ssd": lambda r: _connector(r, "plant", "yaw").set("name", "heading")},
        [("connector", "SystemStructure.ssd connector plant.heading", "the FMU has no variable of this name")]),
    "a connector type other than the variable's": (
        {"ssd": lambda r: _retype(_connector(r, "plant", "fell"), "Integer")},
        [("connector", "SystemStructure.ssd connector plant.fell", "type Integer but the FMU variable is Boolean")]),
    "a connector unit other than the variable's": (
        {"ssd": lambda r: _connector(r, "plant", "yaw")[0].set("unit", "deg")},
        [("connector", "SystemStructure.ssd connector plant.yaw", "unit 'deg' but the FMU variable's unit is 'rad'")]),
    "a connector unit the SSD does not define": (
        {"ssd": lambda r: _connector(r, "plant", "yaw")[0].set("unit", "furlong")},
        [("connector", "SystemStructure.ssd connector plant.yaw", "unit 'furlong' is not defined in the SSD's Units"),
         ("connector", "SystemStructure.ssd connector plant.yaw", "unit 'furlong' but the FMU variable's unit is "
                                                                  "'rad'")]),
    # connection: SSP 1.0 5.3.2
    "a connection to a missing connector": (
        {"ssd": _connect("plant", "yaw", "avr", "yaw")},
        [("connection", f"{CONNECTIONS} plant.yaw -> avr.yaw", "end 'avr.yaw' is not a connector of element 'avr'")]),
    "a connection from output to output": (
        {"ssd": _connect("plant", "yaw", "avr", "psi_x")},
        [("connection", f"{CONNECTIONS} plant.yaw -> avr.psi_x", "element output to element output is not an "
                                                                  "allowed connection")]),
    "a connection of two types": (
        {"ssd": _connect("plant", "fell", "avr", "vx")},
        [("connection", f"{CONNECTIONS} plant.fell -> avr.vx", "type Boolean to type Real"),
         ("connection", "SystemStructure.ssd connector avr.vx", "2 connections feed this input")]),
    "a connection of two base units": (
        {"ssd": _set("ssd:System/ssd:Connections/ssd:Connection[@startConnector='pitch']", "startConnector",
                     "pelvis_x")},
        [("connection", f"{CONNECTIONS} plant.pelvis_x -> avr.pitch", "unit 'm' to unit 'rad': different base "
                                                                      "units")]),
    # schema: the SSP 1.0 XSDs
    "a connector kind the schema does not know": (
        {"ssd": lambda r: _connector(r, "plant", "yaw").set("kind", "sideways")},
        [("schema", SSD, "'sideways' is not an element of the set"),
         ("connector", "SystemStructure.ssd connector plant.yaw", "kind 'sideways' but the FMU variable's "
                                                                  "causality is 'output'")]),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_checker_reports_each_broken_rule(ssp, baseline, entries, tmp_path, case):
    edits, expected = CASES[case]
    roles = {**entries, "ssd": SSD}
    added = _added(baseline, _copy(ssp, tmp_path / "broken.ssp", {roles[r]: edit for r, edit in edits.items()}))
    assert len(added) == len(expected), added
    for (rule, where, message), (want_rule, want_where, want_text) in zip(added, expected):
        assert (rule, where) == (want_rule, want_where.format(**entries)) and want_text in message, \
            (rule, where, message)


def _without_input_bindings(root):
    params = root.find("ssv:Parameters", NS)
    for name in INPUT_BINDINGS:
        for param in params.findall(f"ssv:Parameter[@name='{name}']", NS):
            params.remove(param)


def test_the_command_line_lists_every_problem_and_exits_1(ssp, entries, tmp_path):
    """The built SSP without its input bindings passes (exit 0); two breaks are both listed (exit 1)."""
    with zipfile.ZipFile(ssp) as archive:
        ssvs = [name for name in archive.namelist() if name.endswith(".ssv")]
    clean = _copy(ssp, tmp_path / "clean.ssp", dict.fromkeys(ssvs, _without_input_bindings))
    broken = _copy(clean, tmp_path / "broken.ssp", {entries["plant_ssv"]: _bind("torso_mass", "Real", "12"),
                                                    SSD: _connect("plant", "yaw", "avr", "psi_x")})
    run = [sys.executable, "-m", "scenarios.ssp.ssp_check"]
    ok = subprocess.run([*run, str(clean)], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert (ok.returncode, ok.stdout) == (0, f"{clean}: 0 problem(s)\n"), ok.stderr
    bad = subprocess.run([*run, str(broken)], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    lines = bad.stdout.splitlines()
    assert bad.returncode == 1 and lines[-1] == f"{broken}: 2 problem(s)", bad.stdout + bad.stderr
    assert lines[0].startswith(f"[binding] {entries['plant_ssv']} parameter 'torso_mass'")
    assert lines[1].startswith("[connection] SystemStructure.ssd connection plant.yaw -> avr.psi_x")
