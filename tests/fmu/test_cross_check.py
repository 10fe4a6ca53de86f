"""build.py's reference results: the FMI cross-check vendor tree and the fmi-ls-ref files in each FMU.

Built once (build_all into tmp_path): the tree passes FMPy's own vendor-repository check,
and every FMU of fmus.json, re-simulated by FMPy with the experiment, stimuli and results its
fmi-ls-ref manifest lists, reproduces those results exactly (deterministic fixed-step FMUs,
every input given at every communication point: nothing can legitimately differ on the same
platform).  Each FMU build function adds the reference itself, so an FMU built alone (as a
run builds ``dist/`` on demand) is the same file as build_all's.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_csv, read_model_description, simulate_fmu

from fmu_src.command_source import build_command_source as command_source

from support.plant_fmu_support import built_plant_fmu

LS_REF = "extra/org.fmi-standard.fmi-ls-ref/"
LS_NS = "{http://fmi-standard.org/fmi-ls-manifest}"
#: The release of fmi-ls-ref the manifests follow, and the description its schema fixes.
LS_VERSION = "1.0.0-beta.1"
LS_DESCRIPTION = "Layered Standard providing information on related files included in an FMU."


@pytest.fixture(scope="module")
def dist(built_all) -> Path:
    return built_all.dist


def fmus_of(dist):
    return [dist / e["file"] for e in json.loads((dist / "fmus.json").read_text())["fmus"]]


def test_vendor_tree_passes_fmpy_validation(dist):
    tree = dist / "cross-check"
    proc = subprocess.run([sys.executable, "-m", "fmpy.cross_check.validate_vendor_repo", str(tree)],
                          capture_output=True, text=True)
    assert proc.returncode == 0 and "0 problems found" in proc.stdout, proc.stdout + proc.stderr
    assert "Validated 2 FMUs" in proc.stdout, proc.stdout
    folders = sorted(p.parent.relative_to(tree).as_posix() for p in tree.rglob("*.fmu"))
    assert folders == [f"fmus/2.0/cs/{platform}/cassie-avr/0.1.0/AdaptiveVelocityRegulatorNative"
                       for platform in ("linux64", "win64")]
    for folder in folders:
        model = Path(folder).name
        files = {p.name for p in (tree / folder).iterdir()}
        assert files == {f"{model}.fmu", f"{model}_in.csv", f"{model}_ref.csv", f"{model}_ref.opt", "ReadMe.md",
                         "LICENSE.txt"}
        assert (tree / folder / f"{model}.fmu").read_bytes() == (dist / f"{model}_fmi2.fmu").read_bytes()
        with zipfile.ZipFile(tree / folder / f"{model}.fmu") as archive:  # the FMU's fmi-ls-ref files are the tree's
            for name in (f"{model}_in.csv", f"{model}_ref.csv", f"{model}_ref.opt"):
                assert archive.read(LS_REF + name) == (tree / folder / name).read_bytes(), name
        assert all((tree / folder / name).stat().st_size < 1e6 for name in files)  # the rules' CSV limit


def experiment_of(fmu: Path):
    """The experiment the fmi-ls-ref manifest lists: (options of its ``experiment`` file, stimuli
    bytes, results bytes), each file found by its ``<Related>`` role."""
    with zipfile.ZipFile(fmu) as archive:
        root = ET.fromstring(archive.read(LS_REF + "fmi-ls-manifest.xml"))
        assert (root.get(f"{LS_NS}fmi-ls-name"), root.get(f"{LS_NS}fmi-ls-version"),
                root.get(f"{LS_NS}fmi-ls-description")) == ("org.fmi-standard.fmi-ls-ref", LS_VERSION, LS_DESCRIPTION)
        related = {r.get("role"): r for r in root.findall("Related")}
        assert sorted(related) == ["experiment/validation", "result", "testcase"], fmu.name
        assert all(r.find("Label").get("name") == "experiment:reference" for r in related.values())
        files = {role: archive.read(LS_REF + r.get("source")) for role, r in related.items()}
    options = {}
    for line in files["experiment/validation"].decode().splitlines():  # the cross-check rules' _ref.opt
        key, value = line.split(",")
        options[key.strip()] = float(value)
    assert sorted(options) == ["OutputIntervalLength", "RelTol", "StartTime", "StepSize", "StopTime"], options
    return options, files["testcase"], files["result"]


def test_every_fmu_reproduces_its_reference_results_exactly(dist, unzip, tmp_path):
    for fmu in fmus_of(dist):
        options, stimuli, references = experiment_of(fmu)
        (tmp_path / "in.csv").write_bytes(stimuli)
        (tmp_path / "ref.csv").write_bytes(references)
        ref = read_csv(str(tmp_path / "ref.csv"))
        step = options["StepSize"]
        md = read_model_description(str(fmu))
        outputs = [v.name for v in md.modelVariables if v.causality == "output"]
        assert list(ref.dtype.names) == ["time", *outputs]
        result = simulate_fmu(unzip(fmu, tmp_path / fmu.stem), start_time=options["StartTime"],
                              stop_time=options["StopTime"], output_interval=step,
                              input=read_csv(str(tmp_path / "in.csv")), output=outputs, fmi_type="CoSimulation")
        rows = np.searchsorted(result["time"], ref["time"])
        assert np.array_equal(result["time"][rows], ref["time"]), fmu.name
        for name in outputs:  # exact: the same doubles, not merely close ones
            assert np.array_equal(result[name][rows].astype(float), ref[name].astype(float)), (fmu.name, name)
        if not any(v.causality == "input" for v in md.modelVariables):
            # the CommandSource plays its packed schedule; the nominal one holds a single row
            (_, nominal), = command_source.NOMINAL_ROWS
            assert {n: set(ref[n].astype(float)) for n in outputs} == {n: {nominal[n]} for n in outputs}
            continue
        moving = [n for n in outputs if np.ptp(ref[n].astype(float)) > 0]
        assert len(moving) >= len(outputs) // 2, f"{fmu.name}: a reference where little moves: {moving}"


def test_the_three_regulators_share_one_reference(dist):
    refs = {fmu.name: experiment_of(fmu)[2] for fmu in fmus_of(dist) if "Regulator" in fmu.name}
    assert len(refs) == 3 and len(set(refs.values())) == 1, sorted(refs)


def test_an_fmu_built_alone_is_build_alls(dist, built_fmu, native_fmus, native_plant_fmus, command_sources,
                                         tmp_path_factory, build_module):
    """The FMUs each build function writes (the session's, as a run builds ``dist/`` on demand)
    carry the same reference and are the same files as build_all's."""
    if os.environ.get("AVR_TEST_FMU"):
        pytest.skip("AVR_TEST_FMU: the session's regulator FMU is a given file, not one built here")
    alone = {"AdaptiveVelocityRegulator.fmu": built_fmu, "AdaptiveVelocityRegulatorNative_fmi2.fmu": native_fmus[2],
             "AdaptiveVelocityRegulatorNative_fmi3.fmu": native_fmus[3],
             "CassiePlant.fmu": built_plant_fmu(tmp_path_factory, build_module),
             **{f"CommandSource_fmi{v}.fmu": command_sources[v] for v in (2, 3)},
             **{f"CassiePlantNative_fmi{v}.fmu": native_plant_fmus[v] for v in (2, 3)}}
    assert sorted(alone) == sorted(fmu.name for fmu in fmus_of(dist))
    for name, fmu in alone.items():
        assert experiment_of(Path(fmu))[2] == experiment_of(dist / name)[2], name
        assert Path(fmu).read_bytes() == (dist / name).read_bytes(), name
