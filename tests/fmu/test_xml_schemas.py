"""Every XML document ``python build.py`` writes, validated against its official schema
(FMI 2.0, FMI 3.0, SSP 1.0, OSP, fmi-ls-ref: where each schema comes from is in
tests/support/xml_schemas.py).

The documents are found by walking the build's output folder (with the OSP folder and the
cross-check tree), into the FMU and SSP archives (and the FMUs inside the SSP): a document
of a new kind, or one missing, fails ``test_the_build_writes_exactly_these_xml_documents``
until it is listed here with its schema.  Each schema is shown to reject a broken copy of the document it checks.

Beyond the schemas (which cannot compare attributes): every FMU's start values lie within
their variables' ``min``/``max``.  The SSP's own rules are tests/ssp/test_ssp_rules.py's.
"""
from __future__ import annotations

import re

import pytest
from lxml import etree

from fmu_src.core.avr_profiles import PROFILES
from support.xml_schemas import (LS_REF_IMPORT_FIX, LS_REF_XSD, kind_of, ls_ref_parser, ls_ref_schema_text, osp_schema_text,
                         problems, xml_documents)

LS_REF_MANIFEST = "extra/org.fmi-standard.fmi-ls-ref/fmi-ls-manifest.xml"
#: The FMUs of the FMI cross-check tree (fmu_src/packing/crosscheck.py).
CROSS_CHECK_FMUS = tuple(f"cross-check/fmus/2.0/cs/{platform}/cassie-avr/0.1.0/AdaptiveVelocityRegulatorNative/"
                         "AdaptiveVelocityRegulatorNative.fmu" for platform in ("linux64", "win64"))
#: Every FMU with a reference experiment (crosscheck.EXPERIMENTS), wherever the build puts it: each carries its
#: reference results (fmi-ls-ref).
EVERY_FMU = ("AdaptiveVelocityRegulator.fmu", "AdaptiveVelocityRegulatorNative_fmi2.fmu",
             "AdaptiveVelocityRegulatorNative_fmi3.fmu", "CassiePlant.fmu", "CommandSource_fmi2.fmu",
             "CommandSource_fmi3.fmu",
             *(f"{system}/{fmu}" for system in ("CassieAVR.ssp/resources", "CassieAVR_osp")
               for fmu in ("AdaptiveVelocityRegulator.fmu", "CassiePlant.fmu", "CommandSource_fmi2.fmu")),
             "CassiePlantNative_fmi2.fmu", "CassiePlantNative_fmi3.fmu",
             *(f"CassieAVRNative.ssp/resources/{fmu}" for fmu in (
                 "AdaptiveVelocityRegulatorNative_fmi2.fmu", "CassiePlantNative_fmi2.fmu", "CommandSource_fmi2.fmu")),
             *CROSS_CHECK_FMUS)
#: Every XML document build.py writes that an official schema describes, with its schema kind.
DOCUMENTS = {
    "AdaptiveVelocityRegulator.fmu/modelDescription.xml": "fmi2-model",
    "AdaptiveVelocityRegulatorNative_fmi2.fmu/modelDescription.xml": "fmi2-model",
    "AdaptiveVelocityRegulatorNative_fmi3.fmu/modelDescription.xml": "fmi3-model",
    "AdaptiveVelocityRegulatorNative_fmi3.fmu/sources/buildDescription.xml": "fmi3-build",
    "CassiePlant.fmu/modelDescription.xml": "fmi2-model",
    "CassieAVR.ssp/SystemStructure.ssd": "ssd",
    "CassieAVR.ssp/resources/avr_nominal.ssv": "ssv",
    "CassieAVR.ssp/resources/plant_nominal.ssv": "ssv",
    "CassieAVR.ssp/resources/AdaptiveVelocityRegulator.fmu/modelDescription.xml": "fmi2-model",
    "CassieAVR.ssp/resources/CassiePlant.fmu/modelDescription.xml": "fmi2-model",
    "CassieAVR_osp/OspSystemStructure.xml": "osp",
    "CassieAVR_osp/AdaptiveVelocityRegulator.fmu/modelDescription.xml": "fmi2-model",
    "CassieAVR_osp/CassiePlant.fmu/modelDescription.xml": "fmi2-model",
    "CommandSource_fmi2.fmu/modelDescription.xml": "fmi2-model",
    "CommandSource_fmi3.fmu/modelDescription.xml": "fmi3-model",
    "CommandSource_fmi3.fmu/sources/buildDescription.xml": "fmi3-build",
    "CassieAVR.ssp/resources/CommandSource_fmi2.fmu/modelDescription.xml": "fmi2-model",
    "CassieAVR_osp/CommandSource_fmi2.fmu/modelDescription.xml": "fmi2-model",
    **{f"{fmu}/modelDescription.xml": "fmi2-model" for fmu in CROSS_CHECK_FMUS},
    "CassiePlantNative_fmi2.fmu/modelDescription.xml": "fmi2-model",
    "CassiePlantNative_fmi3.fmu/modelDescription.xml": "fmi3-model",
    "CassieAVRNative.ssp/SystemStructure.ssd": "ssd",
    "CassieAVRNative.ssp/resources/avr_nominal.ssv": "ssv",
    "CassieAVRNative.ssp/resources/plant_nominal.ssv": "ssv",
    **{f"CassieAVRNative.ssp/resources/{fmu}/modelDescription.xml": "fmi2-model" for fmu in (
        "AdaptiveVelocityRegulatorNative_fmi2.fmu", "CassiePlantNative_fmi2.fmu", "CommandSource_fmi2.fmu")},
    **{f"{fmu}/{LS_REF_MANIFEST}": "fmi-ls-ref" for fmu in EVERY_FMU},
    **{f"profiles/{name}.ssv": "ssv" for name in PROFILES},
}
#: The plant FMU's MuJoCo model files (MJCF: MuJoCo defines no XML schema), wherever the plant FMU is.
MJCF_IN_PLANT = ("resources/cassie_plant_lib/models/menagerie/agility_cassie/cassie.xml",
                 "resources/cassie_plant_lib/models/menagerie/agility_cassie/scene.xml",
                 "resources/cassie_plant_lib/models/osu/cassie.xml")
PLANT_FMUS = ("CassiePlant.fmu", "CassieAVR.ssp/resources/CassiePlant.fmu", "CassieAVR_osp/CassiePlant.fmu")
#: The same model files in the native plant FMUs (resources/models/, no package folder).
MJCF_IN_NATIVE_PLANT = tuple(name.replace("cassie_plant_lib/", "") for name in MJCF_IN_PLANT)
NATIVE_PLANT_FMUS = ("CassiePlantNative_fmi2.fmu", "CassiePlantNative_fmi3.fmu",
                     "CassieAVRNative.ssp/resources/CassiePlantNative_fmi2.fmu")
#: Per schema kind, a break its schema must reject: (attribute, bad value; None removes it) on the
#: first element that has the attribute.
BREAKS = {
    "fmi2-model": ("causality", "sideways"),
    "fmi3-model": ("causality", "sideways"),
    "fmi3-build": ("modelIdentifier", None),
    "ssd": ("kind", "sideways"),
    "ssv": ("value", "fast"),
    "osp": ("stepSize", "fast"),
    "fmi-ls-ref": ("role", "sideways"),
}


@pytest.fixture(scope="module")
def documents(built_all) -> dict[str, bytes]:
    """Every XML document of a full ``build.py`` run (``build_all``) into a fresh folder."""
    return xml_documents(built_all.dist)


def test_the_build_writes_exactly_these_xml_documents(documents):
    with_schema = {label: kind_of(data) for label, data in documents.items() if kind_of(data) is not None}
    assert with_schema == DOCUMENTS
    without = sorted(label for label in documents if label not in with_schema)
    assert without == sorted([f"{fmu}/{name}" for fmu in PLANT_FMUS for name in MJCF_IN_PLANT]
                             + [f"{fmu}/{name}" for fmu in NATIVE_PLANT_FMUS for name in MJCF_IN_NATIVE_PLANT])


def _test_id(label: str) -> str:
    """A label short enough for pytest to show it as the test id (it numbers longer ones)."""
    label = label.replace("extra/org.fmi-standard.fmi-ls-ref/", "fmi-ls-ref:")
    return re.sub(r"^cross-check/fmus/2\.0/cs/(\w+)/cassie-avr/[^/]+/[^/]+/", r"cross-check/\1/", label)


@pytest.mark.parametrize("label", sorted(DOCUMENTS), ids=_test_id)
def test_document_is_valid_against_its_official_schema(documents, label):
    assert label in documents, f"the build wrote no {label}"
    assert problems(DOCUMENTS[label], documents[label]) == []


def _out_of_range(model_description: bytes) -> list[str]:
    """Variables whose start value is outside [min, max] (FMI 2.0 section 2.2.7, FMI 3.0 section 2.4.7.5;
    an FMI 3.0 array's start lists every element)."""
    root = etree.fromstring(model_description)
    out = []
    for variable in root.find("ModelVariables"):
        typed = variable if root.get("fmiVersion").startswith("3.") else next(iter(variable), None)
        if typed is None or typed.get("start") is None or not {"min", "max"} & set(typed.attrib):
            continue
        low, high = float(typed.get("min", "-inf")), float(typed.get("max", "inf"))
        if not all(low <= float(x) <= high for x in typed.get("start").split()):
            out.append(f"{variable.get('name')}: start {typed.get('start')} outside [{low}, {high}]")
    return out


@pytest.mark.parametrize("label", sorted(label for label, kind in DOCUMENTS.items()
                                         if kind.endswith("-model") and label.count("/") == 1))
def test_every_start_value_lies_within_min_and_max(documents, label):
    assert _out_of_range(documents[label]) == []
    if etree.fromstring(documents[label]).xpath("//*[@min]"):  # the command source has no min to fall below
        assert _out_of_range(_broken(documents[label], "min", "1e300")), "a start below min goes unnoticed"


def _broken(data: bytes, attribute: str, bad: str | None) -> bytes:
    root = etree.fromstring(data)
    element = next(e for e in root.iter() if attribute in e.attrib)
    if bad is None:
        del element.attrib[attribute]
    else:
        element.set(attribute, bad)
    return etree.tostring(root)


@pytest.mark.parametrize("kind", sorted(BREAKS))
def test_each_schema_rejects_a_broken_document(documents, kind):
    """The schemas are not vacuous: the first document of each kind, with one attribute broken, fails."""
    label = next(label for label, k in DOCUMENTS.items() if k == kind)
    attribute, bad = BREAKS[kind]
    found = problems(kind, _broken(documents[label], attribute, bad))
    assert found and any(attribute in p for p in found), found


def test_the_osp_schema_is_libcosims_own():
    """The schema read out of libcosimpy's library is OspSystemStructure.xsd for format version 0.1."""
    root = etree.fromstring(osp_schema_text())
    assert root.get("targetNamespace") == "http://opensimulationplatform.com/MSMI/OSPSystemStructure"
    top = root.find("{http://www.w3.org/2001/XMLSchema}element")
    assert top.get("name") == "OspSystemStructure"
    version = top.find(".//{http://www.w3.org/2001/XMLSchema}attribute[@name='version']")
    assert version.get("fixed") == "0.1"


def _git_blob_sha1(data: bytes) -> str:
    import hashlib

    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def test_the_fmi_ls_ref_schema_is_the_releases():
    """The copy is modelica/fmi-ls-ref v1.0.0-beta.1's file byte for byte (its git blob, as the
    README names it), and the one line read differently is the release's invalid import."""
    readme = (LS_REF_XSD.parent / "README.md").read_text()
    blob = _git_blob_sha1(LS_REF_XSD.read_bytes())
    assert blob == "febad9adebb462297c504a0fa9b4735e55bf1273" and blob in readme
    assert _git_blob_sha1((LS_REF_XSD.parent / "LICENSE.txt").read_bytes()) in readme
    wrong, right = LS_REF_IMPORT_FIX
    assert ls_ref_schema_text() == LS_REF_XSD.read_text().replace(wrong, right) != LS_REF_XSD.read_text()
    with pytest.raises(etree.XMLSchemaParseError, match="namespace"):
        etree.XMLSchema(etree.parse(str(LS_REF_XSD), ls_ref_parser()))
