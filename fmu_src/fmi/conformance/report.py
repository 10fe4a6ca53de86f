"""The report: one line per check (status, id, section, message), JUnit XML for CI, JSON for tools."""
from __future__ import annotations

import json
from pathlib import Path

from lxml import etree

from fmu_src.fmi.conformance.checks import BY_ID, Result

LABELS = {"pass": "PASS", "fail": "FAIL", "skip": "SKIP"}


def lines(fmu_name: str, version: int, results: list[Result]) -> list[str]:
    out = [f"{fmu_name} (FMI {version}.0 co-simulation)"]
    for r in results:
        out.append(f"{LABELS[r.status]}  {r.id:<26} [{BY_ID[r.id].section(version)}]"
                   + (f"  {r.message}" if r.message else ""))
    counts = {s: sum(r.status == s for r in results) for s in LABELS}
    out.append(f"{counts['pass']} passed, {counts['fail']} failed, {counts['skip']} skipped")
    return out


def to_json(fmu_name: str, version: int, results: list[Result]) -> dict:
    return {"fmu": fmu_name, "fmiVersion": f"{version}.0", "passed": not any(r.status == "fail" for r in results),
            "checks": [{**r.to_json(), "title": BY_ID[r.id].title, "section": BY_ID[r.id].section(version)}
                       for r in results]}


def junit(fmu_name: str, version: int, results: list[Result]) -> bytes:
    suite = etree.Element("testsuite", name=f"fmi-conformance {fmu_name}", tests=str(len(results)),
                          failures=str(sum(r.status == "fail" for r in results)),
                          skipped=str(sum(r.status == "skip" for r in results)), errors="0")
    for r in results:
        case = etree.SubElement(suite, "testcase", classname=f"{fmu_name}.{BY_ID[r.id].group}", name=r.id)
        if r.status == "fail":
            failure = etree.SubElement(case, "failure", message=r.message[:500])
            failure.text = f"{BY_ID[r.id].section(version)}\n{r.message}\n{json.dumps(r.details)}"
        elif r.status == "skip":
            etree.SubElement(case, "skipped", message=r.message)
    return etree.tostring(suite, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def write(path: Path, data: bytes | str) -> None:
    """Write ``path`` whole or not at all (a temporary file beside it, then renamed)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data if isinstance(data, bytes) else data.encode())
    tmp.replace(path)
