"""Check an SSP 1.0 archive against its XML schemas and against the rules a schema cannot state.

    python -m scenarios.ssp.ssp_check dist/CassieAVR.ssp

:func:`check_ssp` reads the archive and the FMUs it packs (nothing is extracted to disk)
and returns every problem at once, an empty list when there is none.  Each
:class:`Problem` names its rule:

``schema``
    ``SystemStructure.ssd`` and every ``.ssv`` in the archive against the SSP 1.0 XSDs
    (fmpy ships them: ``fmpy/ssp/schema``).
``binding``
    SSP 1.0 section 5.3.4 (ParameterBindings): a binding is applied before
    ``fmi2EnterInitializationMode``, so it may only set FMU variables with
    ``variability != "constant"`` and ``initial = "exact"`` or ``"approx"`` (given, or by
    FMI 2.0's defaults: a parameter yes, an input never, since an FMI 2.0 input has no
    ``initial``).  The value's type must be the variable's.  A name that no variable
    carries is ignored by importers (5.3.4); it is reported too, as it is always a stale
    or misspelt name.
``connector``
    SSP 1.0 section 5.3.1 (Connectors): a component's connector names a variable of its
    FMU, its ``kind`` is the variable's causality and its type element the variable's
    type; a Real connector's unit is the variable's unit and is defined in the SSD's
    ``Units``.
``range``
    FMI 2.0 section 2.2.7: ``min <= start <= max`` for every variable of every FMU, and
    every bound value within its variable's ``min``/``max``.
``connection``
    SSP 1.0 section 5.3.2 (Connections): both ends exist, the data flow is one of the
    allowed kind pairs (5.3.2.1, e.g. an element's output to an element's input), both
    ends have the same type and units of the same base unit, and no input or parameter
    is fed by more than one connection.
``unsupported``
    What this checker does not cover, reported rather than passed over: FMUs other than
    FMI 2.0, nested systems, parameter mappings, sources outside the archive.
"""
from __future__ import annotations

import io
import math
import sys
import zipfile
from dataclasses import dataclass
from functools import cache
from pathlib import Path

from lxml import etree

SSD_NAME = "SystemStructure.ssd"
NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration", "Binary")
BASE_UNIT_KEYS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
#: FMI 2.0 section 2.2.7: ``initial`` by (causality, variability) when the attribute is absent.
#: Inputs and the independent variable have none (the attribute is not allowed there).
FMI2_DEFAULT_INITIAL = {
    ("parameter", "fixed"): "exact", ("parameter", "tunable"): "exact",
    ("calculatedParameter", "fixed"): "calculated", ("calculatedParameter", "tunable"): "calculated",
    ("output", "constant"): "exact", ("output", "discrete"): "calculated", ("output", "continuous"): "calculated",
    ("local", "constant"): "exact", ("local", "fixed"): "calculated", ("local", "tunable"): "calculated",
    ("local", "discrete"): "calculated", ("local", "continuous"): "calculated",
}
#: SSP 1.0 section 5.3.2.1: the allowed connections as (source owner, kind) -> (destination owner, kind),
#: owner "system" (the enclosing system's connector) or "element" (a connector of one of its elements).
ALLOWED_FLOWS = frozenset({
    (("system", "parameter"), ("system", "calculatedParameter")), (("system", "parameter"), ("system", "output")),
    (("system", "input"), ("system", "output")), (("system", "parameter"), ("element", "parameter")),
    (("system", "parameter"), ("element", "input")), (("system", "parameter"), ("element", "inout")),
    (("system", "input"), ("element", "input")), (("system", "input"), ("element", "inout")),
    (("element", "calculatedParameter"), ("element", "parameter")),
    (("element", "calculatedParameter"), ("element", "input")),
    (("element", "calculatedParameter"), ("element", "inout")), (("element", "output"), ("element", "input")),
    (("element", "output"), ("element", "inout")), (("element", "inout"), ("element", "input")),
    (("element", "calculatedParameter"), ("system", "calculatedParameter")),
    (("element", "calculatedParameter"), ("system", "output")), (("element", "output"), ("system", "output")),
    (("element", "inout"), ("system", "output")),
})
#: Destinations a second inbound connection would make ambiguous (5.3.2.1).
SINGLE_INBOUND = frozenset({("element", "input"), ("element", "inout"), ("element", "parameter"),
                            ("system", "calculatedParameter"), ("system", "output")})


@dataclass(frozen=True)
class Problem:
    """One broken rule: ``rule`` (see the module docstring), ``where`` (file and element), ``message``."""

    rule: str
    where: str
    message: str

    def __str__(self) -> str:
        return f"[{self.rule}] {self.where}: {self.message}"


@dataclass(frozen=True)
class Variable:
    """An FMI 2.0 ScalarVariable as the rules need it (attributes as written, ``initial`` resolved)."""

    name: str
    type: str
    causality: str
    variability: str
    initial: str | None
    start: str | None
    min: float | None
    max: float | None
    unit: str | None


@dataclass(frozen=True)
class Fmu:
    """What the rules read from one FMU's model description."""

    fmi_version: str
    variables: dict[str, Variable]
    units: dict[str, tuple]


@dataclass(frozen=True)
class Connector:
    owner: str  # "system" or "element"
    kind: str
    type: str | None
    unit: str | None


def _q(tag: str) -> str:
    prefix, _, name = tag.partition(":")
    return f"{{{NS[prefix]}}}{name}"


def _base_unit(element) -> tuple:
    """A unit's dimension (exponents of the SI base units and rad), factor and offset left out."""
    base = element.find("BaseUnit") if element.find("BaseUnit") is not None else element.find(_q("ssc:BaseUnit"))
    if base is None:
        return tuple(0 for _ in BASE_UNIT_KEYS)
    return tuple(int(base.get(k, "0")) for k in BASE_UNIT_KEYS)


def _float(text: str | None) -> float | None:
    return None if text is None else float(text)


def read_fmu(data: bytes) -> Fmu:
    """The variables and units of the FMU ``data`` (an FMU archive's bytes), FMI 2.0 attributes as written."""
    with zipfile.ZipFile(io.BytesIO(data)) as archive:
        root = etree.fromstring(archive.read("modelDescription.xml"))
    version = root.get("fmiVersion", "")
    units = {u.get("name"): _base_unit(u) for u in root.iterfind("UnitDefinitions/Unit")}
    if version != "2.0":
        return Fmu(version, {}, units)
    simple_types = {t.get("name"): t[0] for t in root.iterfind("TypeDefinitions/SimpleType") if len(t)}
    variables = {}
    for sv in root.iterfind("ModelVariables/ScalarVariable"):
        typed = next((child for child in sv if child.tag in TYPES), None)
        if typed is None:  # not a valid FMI 2.0 variable: the FMU's schema validation reports it
            continue
        declared = simple_types.get(typed.get("declaredType"))

        def attr(name, typed=typed, declared=declared):
            value = typed.get(name)
            return value if value is not None or declared is None else declared.get(name)

        causality = sv.get("causality", "local")
        variability = sv.get("variability", "continuous")
        initial = sv.get("initial") or FMI2_DEFAULT_INITIAL.get((causality, variability))
        numeric = typed.tag in ("Real", "Integer")
        variables[sv.get("name")] = Variable(
            sv.get("name"), typed.tag, causality, variability, initial, typed.get("start"),
            _float(attr("min")) if numeric else None, _float(attr("max")) if numeric else None,
            attr("unit") if typed.tag == "Real" else None)
    return Fmu(version, variables, units)


@cache
def _schema(name: str) -> etree.XMLSchema:
    import fmpy

    return etree.XMLSchema(etree.parse(str(Path(fmpy.__file__).parent / "ssp" / "schema" / name)))


def _schema_problems(schema_name: str, where: str, root) -> list[Problem]:
    schema = _schema(schema_name)
    if schema.validate(root):
        return []
    return [Problem("schema", where, f"line {e.line}: {e.message}") for e in schema.error_log]


def _in_range(var: Variable, text: str) -> str | None:
    """Why ``text`` is not a value of ``var`` within its min/max, or None."""
    if var.type not in ("Real", "Integer"):
        return None
    try:
        value = float(text) if var.type == "Real" else int(text)
    except ValueError:
        return f"{text!r} is not of type {var.type}"
    bounded = var.min is not None or var.max is not None
    if (bounded and math.isnan(value)) or (var.min is not None and value < var.min) or \
            (var.max is not None and value > var.max):
        return f"{text} is outside [{var.min}, {var.max}]"
    return None


class _Checker:
    def __init__(self, archive: zipfile.ZipFile, ssp_name: str):
        self.archive = archive
        self.ssp = ssp_name
        self.names = set(archive.namelist())
        self.problems: list[Problem] = []
        self.parsed: dict[str, object] = {}

    def add(self, rule: str, where: str, message: str) -> None:
        self.problems.append(Problem(rule, where, message))

    # ---- files -----------------------------------------------------------------------
    def parse(self, name: str, schema_name: str):
        """The XML root of the archive entry ``name`` (None: not XML), its problems reported once."""
        if name not in self.parsed:
            try:
                self.parsed[name] = etree.fromstring(self.archive.read(name))
            except etree.XMLSyntaxError as exc:
                self.parsed[name] = None
                self.add("schema", name, f"not well-formed XML: {exc}")
            else:
                self.problems += _schema_problems(schema_name, name, self.parsed[name])
        return self.parsed[name]

    # ---- components ------------------------------------------------------------------
    def component_fmu(self, comp) -> Fmu | None:
        where = f"{SSD_NAME} component {comp.get('name')!r}"
        source = comp.get("source", "")
        kind = comp.get("type", "application/x-fmu-sharedlibrary")
        if kind != "application/x-fmu-sharedlibrary":
            self.add("unsupported", where, f"type {kind!r}: only FMU components are checked")
            return None
        if source not in self.names:
            self.add("unsupported", where, f"source {source!r} is not a file in the archive")
            return None
        fmu = read_fmu(self.archive.read(source))
        if fmu.fmi_version != "2.0":
            self.add("unsupported", where, f"FMI {fmu.fmi_version} FMU: SSP 1.0 states connector kinds and "
                                           "bindings for FMI 1.0 and 2.0; only FMI 2.0 is checked")
            return None
        for var in fmu.variables.values():
            if var.start is not None and (why := _in_range(var, var.start)):
                self.add("range", f"{source} variable {var.name!r}", f"start {why}")
        return fmu

    def connectors(self, element, owner: str, fmu: Fmu | None, ssd_units: dict) -> dict[str, Connector]:
        out = {}
        name = element.get("name")
        for conn in element.iterfind("ssd:Connectors/ssd:Connector", NS):
            cname, kind = conn.get("name"), conn.get("kind")
            where = f"{SSD_NAME} connector {name}.{cname}"
            typed = next((c for c in conn if etree.QName(c).localname in TYPES), None)
            ctype = None if typed is None else etree.QName(typed).localname
            unit = None if typed is None else typed.get("unit")
            if cname in out:
                self.add("connector", where, "the name is not unique within its element")
            out[cname] = Connector(owner, kind, ctype, unit)
            if unit is not None and unit not in ssd_units:
                self.add("connector", where, f"unit {unit!r} is not defined in the SSD's Units")
            if fmu is None:
                continue
            var = fmu.variables.get(cname)
            if var is None:
                self.add("connector", where, "the FMU has no variable of this name")
                continue
            if kind != var.causality:
                self.add("connector", where, f"kind {kind!r} but the FMU variable's causality is {var.causality!r}")
            if ctype is not None and ctype != var.type:
                self.add("connector", where, f"type {ctype} but the FMU variable is {var.type}")
            if unit is not None and unit != var.unit:
                self.add("connector", where, f"unit {unit!r} but the FMU variable's unit is {var.unit!r}")
        return out

    # ---- parameter bindings -----------------------------------------------------------
    def parameter_sets(self, holder, where: str):
        """(file name for messages, ssv:ParameterSet element, prefix) of each binding of ``holder``."""
        for binding in holder.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
            if binding.find("ssd:ParameterMapping", NS) is not None:
                self.add("unsupported", where, "a parameter mapping: its bindings are not checked")
                continue
            kind = binding.get("type", "application/x-ssp-parameter-set")
            if kind != "application/x-ssp-parameter-set":
                self.add("unsupported", where, f"a binding of type {kind!r} is not checked")
                continue
            prefix = binding.get("prefix", "")
            source = binding.get("source")
            if source is None:
                inline = binding.find("ssd:ParameterValues/ssv:ParameterSet", NS)
                if inline is not None:
                    yield f"{SSD_NAME} ({where}, inline)", inline, prefix
                continue
            if binding.get("sourceBase", "SSD") != "SSD" or source not in self.names:
                self.add("unsupported", where, f"parameter source {source!r} is not a file in the archive")
                continue
            root = self.parse(source, "SystemStructureParameterValues.xsd")
            if root is not None:
                yield source, root, prefix

    def check_value(self, file: str, name: str, fmu: Fmu, var_name: str, value_element) -> None:
        where = f"{file} parameter {name!r}"
        var = fmu.variables.get(var_name)
        if var is None:
            self.add("binding", where, f"the FMU has no variable {var_name!r}: importers ignore the value "
                                       "(SSP 1.0 5.3.4)")
            return
        if var.variability == "constant" or var.initial not in ("exact", "approx"):
            what = (f"an FMI 2.0 {var.causality} (no initial)" if var.initial is None else
                    f"causality {var.causality!r}, variability {var.variability!r}, initial {var.initial!r}")
            self.add("binding", where,
                     f"binds {var_name!r}, {what}: SSP 1.0 5.3.4 applies bindings before "
                     "fmi2EnterInitializationMode, to variables with variability != constant and initial "
                     "exact or approx only")
        kind = etree.QName(value_element).localname
        if kind != var.type:
            self.add("binding", where, f"a value of type {kind} for {var_name!r}, a variable of type {var.type}")
        elif (why := _in_range(var, value_element.get("value", ""))):
            self.add("range", where, f"value for {var_name!r}: {why}")

    def bindings(self, system, components: dict[str, Fmu | None]) -> None:
        for comp in system.iterfind("ssd:Elements/ssd:Component", NS):
            fmu = components.get(comp.get("name"))
            for file, pset, prefix in self.parameter_sets(comp, f"component {comp.get('name')!r}"):
                for param in pset.iterfind("ssv:Parameters/ssv:Parameter", NS):
                    if fmu is not None and len(param):
                        self.check_value(file, param.get("name"), fmu, prefix + param.get("name"), param[0])
        for file, pset, prefix in self.parameter_sets(system, f"system {system.get('name')!r}"):
            for param in pset.iterfind("ssv:Parameters/ssv:Parameter", NS):
                full = prefix + param.get("name")
                element = max((e for e in components if full.startswith(e + ".")), key=len, default=None)
                if element is None:
                    self.add("binding", f"{file} parameter {param.get('name')!r}",
                             f"{full!r} names no element of the system: importers ignore the value (SSP 1.0 5.3.4)")
                elif components[element] is not None and len(param):
                    self.check_value(file, param.get("name"), components[element], full[len(element) + 1:],
                                     param[0])

    # ---- connections -------------------------------------------------------------------
    def connections(self, system, connectors: dict, ssd_units: dict) -> None:
        inbound: dict[tuple, int] = {}
        for conn in system.iterfind("ssd:Connections/ssd:Connection", NS):
            ends = []
            for side in ("start", "end"):
                element, name = conn.get(f"{side}Element"), conn.get(f"{side}Connector")
                label = f"{element}.{name}" if element else name
                found = connectors.get(element, {}).get(name)
                if found is None:
                    self.add("connection", f"{SSD_NAME} connection {self.label(conn)}",
                             f"{side} {label!r} is not a connector of "
                             + (f"element {element!r}" if element else "the system"))
                ends.append((label, found))
            where = f"{SSD_NAME} connection {self.label(conn)}"
            (a_label, a), (b_label, b) = ends
            if a is None or b is None:
                continue
            flows = [(src, dst) for src, dst in ((a, b), (b, a))
                     if ((src.owner, src.kind), (dst.owner, dst.kind)) in ALLOWED_FLOWS]
            if not flows:
                self.add("connection", where, f"{a.owner} {a.kind} to {b.owner} {b.kind} is not an allowed "
                                              "connection (SSP 1.0 5.3.2.1)")
            else:
                dst_label = b_label if flows[0][1] is b else a_label
                key = (dst_label, (flows[0][1].owner, flows[0][1].kind))
                if key[1] in SINGLE_INBOUND:
                    inbound[key] = inbound.get(key, 0) + 1
            if a.type != b.type:
                self.add("connection", where, f"type {a.type} to type {b.type}")
            elif a.unit in ssd_units and b.unit in ssd_units and ssd_units[a.unit] != ssd_units[b.unit]:
                self.add("connection", where, f"unit {a.unit!r} to unit {b.unit!r}: different base units")
        for (label, (_, kind)), count in inbound.items():
            if count > 1:
                self.add("connection", f"{SSD_NAME} connector {label}",
                         f"{count} connections feed this {kind}: the data flow is ambiguous (SSP 1.0 5.3.2.1)")

    @staticmethod
    def label(conn) -> str:
        def end(side):
            element = conn.get(f"{side}Element")
            return f"{element}.{conn.get(side + 'Connector')}" if element else conn.get(f"{side}Connector")

        return f"{end('start')} -> {end('end')}"

    # ---- the whole system ----------------------------------------------------------------
    def run(self) -> list[Problem]:
        if SSD_NAME not in self.names:
            self.add("schema", self.ssp, f"no {SSD_NAME} in the archive")
            return self.problems
        root = self.parse(SSD_NAME, "SystemStructureDescription.xsd")
        system = None if root is None else root.find("ssd:System", NS)
        if system is None:
            return self.problems
        ssd_units = {u.get("name"): _base_unit(u) for u in root.iterfind("ssd:Units/ssc:Unit", NS)}
        if system.find("ssd:Elements/ssd:System", NS) is not None:
            self.add("unsupported", SSD_NAME, "nested systems are not checked")
        components = {comp.get("name"): self.component_fmu(comp)
                      for comp in system.iterfind("ssd:Elements/ssd:Component", NS)}
        connectors = {None: self.connectors(system, "system", None, ssd_units)}
        for comp in system.iterfind("ssd:Elements/ssd:Component", NS):
            connectors[comp.get("name")] = self.connectors(comp, "element", components[comp.get("name")], ssd_units)
        self.bindings(system, components)
        self.connections(system, connectors, ssd_units)
        return self.problems


def check_ssp(path: str | Path) -> list[Problem]:
    """Every problem of the SSP archive ``path`` (see the module docstring): the FMUs' start values,
    the connectors, the parameter bindings, then the connections, each in document order."""
    with zipfile.ZipFile(path) as archive:
        return _Checker(archive, Path(path).name).run()


def main(argv=None) -> int:
    """Exit 0 without problems, 1 with problems (one line each), 2 when FILE is not a readable SSP archive."""
    from scenarios.lang.cmdline import Parser

    parser = Parser(prog="python -m scenarios.ssp.ssp_check",
                    description="Check an SSP 1.0 archive against the SSP schemas and rules")
    parser.add_argument("file", metavar="FILE.ssp")
    path = parser.parse_args(argv).file
    try:
        problems = check_ssp(path)
    except IsADirectoryError:
        print(f"{path}: is a folder, not an SSP archive", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{path}: cannot read: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except zipfile.BadZipFile as exc:
        print(f"{path}: not an SSP archive (a zip file): {exc}", file=sys.stderr)
        return 2
    for problem in problems:
        print(problem)
    print(f"{path}: {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
