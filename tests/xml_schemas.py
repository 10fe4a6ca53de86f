"""The official XML schemas of every document build.py writes, from the packages that ship them,
and the walk that finds those documents in a build's output folder.

* FMI 2.0 and 3.0 (``modelDescription.xml``, FMI 3.0 ``buildDescription.xml``): fmpy's
  ``fmpy/schema/fmi2`` and ``fmpy/schema/fmi3``;
* SSP 1.0 (``SystemStructure.ssd``, ``*.ssv``): fmpy's ``fmpy/ssp/schema`` (the Modelica
  Association's normative XML Schema 1.0 files, BSD-2-Clause);
* OSP (``OspSystemStructure.xml``): the schema libcosim itself validates the file against.
  libcosim compiles ``data/xsd/OspSystemStructure.xsd`` (open-simulation-platform/libcosim,
  MPL-2.0) into its library as a string, and libcosimpy's wheel ships that library, so the
  schema is read from ``libcosimpy/libcosimc/libcosimc.so``: exactly what the runner that
  reads the file enforces, with no copy to keep in step.
"""
from __future__ import annotations

import io
import re
import zipfile
from functools import cache
from pathlib import Path

from lxml import etree

OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSV_NS = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
#: What a file name must end with to be read as an XML document.
XML_SUFFIXES = (".xml", ".ssd", ".ssv", ".ssm", ".ssb")
#: Archives whose entries are walked too.
ARCHIVE_SUFFIXES = (".fmu", ".ssp")
#: Root elements that no official schema describes: MuJoCo's MJCF model files (MuJoCo
#: defines no XML schema; the plant FMU carries them unchanged and MuJoCo's loader checks
#: them in the plant tests).
NO_SCHEMA_ROOTS = frozenset({"mujoco"})


def _fmpy_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).parent


@cache
def osp_schema_text() -> bytes:
    """``OspSystemStructure.xsd`` as libcosim embeds it (see the module docstring)."""
    import libcosimpy

    library = Path(libcosimpy.__file__).parent / "libcosimc" / "libcosimc.so"
    data = library.read_bytes()
    pattern = rb"<\?xml[^>]*\?>(?:(?!<\?xml).)*?targetNamespace=\"" + re.escape(OSP_NS.encode()) + \
        rb"\".*?</xs:schema>"
    match = re.search(pattern, data, re.S)
    if match is None:
        raise LookupError(f"no XML schema with targetNamespace {OSP_NS} in {library}: libcosimpy no longer embeds "
                          "OspSystemStructure.xsd there; take it from open-simulation-platform/libcosim "
                          "data/xsd/ (MPL-2.0) into tests/third_party/schemas/osp/ instead")
    return match.group(0)


@cache
def schema(kind: str) -> etree.XMLSchema:
    """The XMLSchema for a document kind (the keys of :data:`SCHEMA_FILES` or ``"osp"``)."""
    if kind == "osp":
        return etree.XMLSchema(etree.fromstring(osp_schema_text()))
    return etree.XMLSchema(etree.parse(str(_fmpy_dir() / SCHEMA_FILES[kind])))


SCHEMA_FILES = {
    "fmi2-model": "schema/fmi2/fmi2ModelDescription.xsd",
    "fmi3-model": "schema/fmi3/fmi3ModelDescription.xsd",
    "fmi3-build": "schema/fmi3/fmi3BuildDescription.xsd",
    "ssd": "ssp/schema/SystemStructureDescription.xsd",
    "ssv": "ssp/schema/SystemStructureParameterValues.xsd",
}


def kind_of(data: bytes) -> str | None:
    """The schema kind of an XML document by its root element (None: a root no official schema describes).
    Raises ValueError for a root element nobody here knows."""
    root = etree.fromstring(data)
    tag = etree.QName(root)
    if tag.namespace is None and tag.localname == "fmiModelDescription":
        version = root.get("fmiVersion", "")
        if version == "2.0":
            return "fmi2-model"
        if version.startswith("3."):
            return "fmi3-model"
    if tag.namespace is None and tag.localname == "fmiBuildDescription" and root.get("fmiVersion", "").startswith("3."):
        return "fmi3-build"
    if (tag.namespace, tag.localname) == (SSD_NS, "SystemStructureDescription"):
        return "ssd"
    if (tag.namespace, tag.localname) == (SSV_NS, "ParameterSet"):
        return "ssv"
    if (tag.namespace, tag.localname) == (OSP_NS, "OspSystemStructure"):
        return "osp"
    if tag.namespace is None and tag.localname in NO_SCHEMA_ROOTS:
        return None
    raise ValueError(f"no schema known for root element {tag.text} (fmiVersion {root.get('fmiVersion')!r})")


def problems(kind: str, data: bytes) -> list[str]:
    """Every schema violation of the document ``data`` (empty: valid)."""
    xsd = schema(kind)
    if xsd.validate(etree.fromstring(data)):
        return []
    return [f"line {e.line}: {e.message}" for e in xsd.error_log]


def xml_documents(folder: Path) -> dict[str, bytes]:
    """Every XML document under ``folder``, also inside FMU and SSP archives (and FMUs inside
    an SSP), by a path label such as ``CassieAVR.ssp/resources/CassiePlant.fmu/modelDescription.xml``."""
    out: dict[str, bytes] = {}

    def walk_archive(label: str, data: bytes) -> None:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            for name in archive.namelist():
                if name.endswith(XML_SUFFIXES):
                    out[f"{label}/{name}"] = archive.read(name)
                elif name.endswith(ARCHIVE_SUFFIXES):
                    walk_archive(f"{label}/{name}", archive.read(name))

    for path in sorted(p for p in Path(folder).rglob("*") if p.is_file()):
        label = path.relative_to(folder).as_posix()
        if path.name.endswith(XML_SUFFIXES):
            out[label] = path.read_bytes()
        elif path.name.endswith(ARCHIVE_SUFFIXES):
            walk_archive(label, path.read_bytes())
    return out
