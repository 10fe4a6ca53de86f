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
* fmi-ls-ref (``extra/org.fmi-standard.fmi-ls-ref/fmi-ls-manifest.xml``): no package ships its
  schema, so ``tests/third_party/schemas/fmi-ls-ref/`` holds the release's
  ``fmi3LayeredStandardReferenceManifest.xsd`` unchanged (source, tag and commit in its
  README.md).  The file locates the two FMI 3.0 schemas it builds on by URL
  (modelica/fmi-standard's ``main``); they resolve to fmpy's copies of the same files
  (``fmi3LayeredStandardManifest.xsd``, ``fmi3Annotation.xsd``), never the network.  The
  release brings ``fmi3Annotation.xsd`` in with an ``xs:import`` without a namespace, which
  XML Schema forbids in a schema without a target namespace (libxml2 refuses to compile it);
  ``LS_REF_IMPORT_FIX`` makes it the ``xs:include`` of modelica/fmi-ls-ref commit 596a89d
  (PR #40, the one change of the schema after the release).
"""
from __future__ import annotations

import io
import re
import zipfile
from functools import cache
from pathlib import Path

from lxml import etree

OSP_NS = "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
LS_NS = "http://fmi-standard.org/fmi-ls-manifest"
THIRD_PARTY = Path(__file__).resolve().parents[1] / "third_party" / "schemas"
LS_REF_XSD = THIRD_PARTY / "fmi-ls-ref" / "fmi3LayeredStandardReferenceManifest.xsd"
#: The URL prefix the fmi-ls-ref schema locates the FMI 3.0 schemas by; fmpy ships them in schema/fmi3.
FMI_STANDARD_SCHEMA_URL = "https://raw.githubusercontent.com/modelica/fmi-standard/main/schema/"
#: (the release's line, modelica/fmi-ls-ref commit 596a89d's): see the module docstring.
LS_REF_IMPORT_FIX = (f'<xs:import schemaLocation="{FMI_STANDARD_SCHEMA_URL}fmi3Annotation.xsd"/>',
                     f'<xs:include schemaLocation="{FMI_STANDARD_SCHEMA_URL}fmi3Annotation.xsd"/>')
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


class _FmiStandardSchemas(etree.Resolver):
    """Resolves the FMI 3.0 schemas' URLs (:data:`FMI_STANDARD_SCHEMA_URL`) to fmpy's copies."""

    def resolve(self, url, pubid, context):
        if url.startswith(FMI_STANDARD_SCHEMA_URL):
            local = _fmpy_dir() / "schema" / "fmi3" / url[len(FMI_STANDARD_SCHEMA_URL):]
            if not local.is_file():
                raise LookupError(f"{url}: fmpy ships no {local}")
            return self.resolve_filename(str(local), context)
        return None


def ls_ref_parser() -> etree.XMLParser:
    """An XML parser that reads the FMI 3.0 schemas the fmi-ls-ref schema names from fmpy, never the network."""
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_FmiStandardSchemas())
    return parser


def ls_ref_schema_text() -> str:
    """The fmi-ls-ref release's manifest schema with :data:`LS_REF_IMPORT_FIX` applied."""
    text = LS_REF_XSD.read_text(encoding="utf-8")
    wrong, right = LS_REF_IMPORT_FIX
    if text.count(wrong) != 1:
        raise LookupError(f"{LS_REF_XSD} does not import fmi3Annotation.xsd as the v1.0.0-beta.1 release does "
                          f"({wrong}): a new copy needs LS_REF_IMPORT_FIX revisited")
    return text.replace(wrong, right)


@cache
def schema(kind: str) -> etree.XMLSchema:
    """The XMLSchema for a document kind (the keys of :data:`SCHEMA_FILES`, ``"osp"`` or ``"fmi-ls-ref"``)."""
    if kind == "osp":
        return etree.XMLSchema(etree.fromstring(osp_schema_text()))
    if kind == "fmi-ls-ref":
        text = ls_ref_schema_text().encode()
        return etree.XMLSchema(etree.fromstring(text, ls_ref_parser(), base_url=str(LS_REF_XSD)))
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
    if tag.namespace is None and tag.localname == "fmiReferences" and \
            root.get(f"{{{LS_NS}}}fmi-ls-name") == "org.fmi-standard.fmi-ls-ref":
        return "fmi-ls-ref"
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
