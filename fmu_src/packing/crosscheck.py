"""Reference results: simulated once per build, put inside every FMU (the fmi-ls-ref layered
standard) and written as an FMI cross-check vendor tree.

Each model has one reference experiment (``EXPERIMENTS``): a few seconds at the FMUs'
5 ms communication step, with one input row per communication point (``<Model>_in.csv``),
so an importer never interpolates and every one applies the same doubles; the outputs are
recorded every ``output_every`` steps (``<Model>_ref.csv``).  The results come from a real
simulation of the built FMU with FMPy (``simulate``, in a process of its own: a pythonfmu
FMU loaded into the build process would put its resources first on ``sys.path``).

``add_references`` writes, into each FMU, ``extra/org.fmi-standard.fmi-ls-ref/`` as the
layered standard fmi-ls-ref 1.0.0-beta.1 (modelica/fmi-ls-ref, tag ``v1.0.0-beta.1``) defines
it: ``fmi-ls-manifest.xml``, whose root ``fmiReferences`` lists each related file in a
``<Related>`` element with its MIME type and role, and the files themselves, named and
formatted as the FMI cross-check rules name them (FMI-CROSS-CHECK-RULES.md v4.1, sections
9.1.4-9.1.5): ``<Model>_ref.opt`` (role ``experiment/validation``: start and stop time, step size,
tolerance, output interval), ``<Model>_in.csv`` (role ``testcase``: the experiment's input
signals) and ``<Model>_ref.csv`` (role ``result``: its results); a ``Label`` ties the three to
the one experiment.  The standard leaves an experiment file's format to its MIME type (the
one it names, ``application/x-ma-hs-experiments``, is the separate MA-HS-Experiments
specification, which no fmi-ls-ref release defines a schema for), so the experiment is the
cross-check rules' ``_ref.opt``, and the three files are byte for byte the cross-check
tree's.  ``documentation/fmi-ls-ref.txt`` (the standard recommends one) says what the
experiment is and which deviation to expect.  modelica/Reference-FMUs put their results in
the same folder the same way (``<Related type="text/csv" role="result">``, ``<Model>_out.csv``
of the default experiment, no inputs).  The GUID does not change: it
identifies the model description, sources and binaries, which the reference results are
computed from.

Every FMU build function of build.py calls ``add_reference`` on the FMU it wrote, so an FMU
has its reference whoever builds it (``build_all`` or a run building ``dist/`` on demand).

``write_vendor_tree`` writes ``cross-check/fmus/2.0/cs/<platform>/cassie-avr/<version>/<Model>/``
(FMI-CROSS-CHECK-RULES.md v4.1, section 9.1.4-9.1.5) for every FMU that runs without
additional requirements: the native FMI 2.0 FMU on linux64 and win64.  The pythonfmu FMUs
need a Python installation with numpy (the plant also MuJoCo) on the importing machine,
which rule 9.1.3 excludes; FMI 3.0 has no cross-check tree (the rules know 1.0 and 2.0).

    python -m fmu_src.packing.crosscheck simulate   (reads a JSON request on stdin)
"""
from __future__ import annotations

import json
import logging
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from fmu_src.packing.archive import read_entries, write_zip

log = logging.getLogger(__name__)

LS_REF_DIR = "extra/org.fmi-standard.fmi-ls-ref"
LS_NS = "http://fmi-standard.org/fmi-ls-manifest"
#: The release of fmi-ls-ref followed (modelica/fmi-ls-ref tag v1.0.0-beta.1, commit 70ee1b84).
LS_VERSION = "1.0.0-beta.1"
#: The fixed description the fmi-ls-ref schema requires.
LS_DESCRIPTION = "Layered Standard providing information on related files included in an FMU."
#: The documentation file fmi-ls-ref recommends (section "Documentation").
LS_DOC = "documentation/fmi-ls-ref.txt"
#: The label tying the experiment's three files together.
EXPERIMENT_LABEL = "experiment:reference"
TOOL_NAME = "cassie-avr"
CROSS_CHECK_DIR = "cross-check"
#: Platforms of the cross-check tree, by modelIdentifier: the FMUs that need nothing else to run.
CROSS_CHECK_PLATFORMS = {"AdaptiveVelocityRegulatorNative": ("linux64", "win64")}
#: The band an importer's result is compared with (``RelTol`` of ``_ref.opt``).  The FMUs are
#: fixed-step and deterministic and every input value is given at every communication point,
#: so FMPy on linux64 reproduces the reference bit for bit (tests/fmu/test_cross_check.py); the band
#: leaves room for another platform's libm (exp, log1p) differing in the last bit.
REL_TOL = 1e-6
REPO_ROOT = Path(__file__).resolve().parents[2]
MIT_LICENSE = """MIT License

Copyright (c) cassie-avr project

Permission is hereby granted, free of charge, to any person obtaining a copy of this software and
associated documentation files (the "Software"), to deal in the Software without restriction,
including without limitation the rights to use, copy, modify, merge, publish, distribute,
sublicense, and/or sell copies of the Software, and to permit persons to whom the Software is
furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in all copies or
substantial portions of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT
NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND
NONINFRINGEMENT. IN NO EVENT SHALL THE AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM,
DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT
OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE SOFTWARE.
"""


@dataclass(frozen=True)
class Experiment:
    """One reference experiment: ``steps`` communication steps of ``step_size`` s from 0,
    ``inputs(k)`` the input values at communication point k, the outputs recorded every
    ``output_every`` steps."""

    description: str
    steps: int
    step_size: float
    output_every: int
    inputs: Callable[[int], dict]

    @property
    def stop_time(self) -> float:
        return self.steps * self.step_size


def _regulator_inputs(k: int) -> dict:
    """Walking-like measurements, constant over 0.25 s segments (50 steps, one walking step
    each, step_index counting them): speed below the 0.5 m/s command, then above it."""
    j = k // 50
    return {"vx": round(0.2 + 0.05 * j, 3), "vy": round(0.04 * (-1) ** j, 3), "vx_des": 0.5, "vy_des": 0.0,
            "pitch": round(0.02 - 0.005 * j, 3), "roll": round(0.01 * (-1) ** j, 3),
            "pitch_rate": round(0.1 * ((j % 3) - 1), 3), "roll_rate": round(-0.05 * ((j % 2) * 2 - 1), 3),
            "step_index": j}


def _plant_inputs(k: int) -> dict:
    """Walk in place for 1 s, then command 0.3 m/s forward (no offsets, no push)."""
    return {"vx_des": 0.0 if k < 200 else 0.3}


# 16 walking steps: the networks learn from step 12 on (learn_from_step's default), so the last
# four exercise learning and its outputs.
_REGULATOR = Experiment("4 s of walking-like measurements, a walking step every 0.25 s", 800, 0.005, 10,
                        _regulator_inputs)
EXPERIMENTS = {
    "AdaptiveVelocityRegulator": _REGULATOR,
    "AdaptiveVelocityRegulatorNative": _REGULATOR,
    "CommandSource": Experiment("2 s of the nominal schedule (0.5 m/s, no turn, no push); no inputs", 400, 0.005,
                                10, lambda k: {}),
    "CassiePlant": Experiment("2 s from the home pose: stepping in place, then 0.3 m/s forward", 400, 0.005, 10,
                              _plant_inputs),
}
#: The native plant (C, no Python) has the pythonfmu plant's experiment: the same results, bit for bit.
EXPERIMENTS["CassiePlantNative"] = EXPERIMENTS["CassiePlant"]


def _number(value) -> str:
    """A CSV cell as the cross-check rules want it: C float literals, Booleans as 0/1."""
    if isinstance(value, (bool,)) or type(value).__name__ == "bool_":
        return "1" if value else "0"
    if isinstance(value, float) or type(value).__name__ == "float64":
        return repr(float(value))
    return str(int(value))


def _csv(names, rows) -> bytes:
    lines = [",".join(f'"{n}"' for n in ["time", *names])]
    lines += [",".join(_number(v) for v in row) for row in rows]
    return ("\n".join(lines) + "\n").encode()


def input_csv(experiment: Experiment) -> bytes:
    """``<Model>_in.csv``: one row per communication point, 0 .. stop time."""
    names = list(experiment.inputs(0))
    return _csv(names, [(k * experiment.step_size, *[experiment.inputs(k)[n] for n in names])
                        for k in range(experiment.steps + 1)])


def simulate(fmu: Path, in_csv: Path, experiment: Experiment) -> bytes:
    """``<Model>_ref.csv`` of ``fmu``: FMPy's co-simulation with the inputs of ``in_csv``,
    every output, one row every ``output_every`` steps.  Runs in this process."""
    import numpy as np
    from fmpy import read_csv, read_model_description, simulate_fmu

    md = read_model_description(str(fmu))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    result = simulate_fmu(str(fmu), start_time=0.0, stop_time=experiment.stop_time,
                          output_interval=experiment.step_size, input=read_csv(str(in_csv)), output=outputs,
                          fmi_type="CoSimulation", validate=False)
    if len(result) != experiment.steps + 1:
        raise RuntimeError(f"{fmu.name}: {len(result)} result rows, expected {experiment.steps + 1}")
    rows = [(k * experiment.step_size, *[result[n][k] for n in outputs])
            for k in range(0, experiment.steps + 1, experiment.output_every)]
    if not all(np.isfinite(float(v)) for row in rows for v in row):
        raise RuntimeError(f"{fmu.name}: the reference simulation produced a non-finite value")
    return _csv(outputs, rows)


def _model_identifier(fmu: Path) -> str:
    with zipfile.ZipFile(fmu) as archive:
        return ET.fromstring(archive.read("modelDescription.xml")).find("CoSimulation").get("modelIdentifier")


def reference_results(fmus, work_dir: Path) -> dict[Path, tuple[bytes, bytes]]:
    """{fmu: (_in.csv, _ref.csv)} for every FMU of ``fmus``, simulated in one child process."""
    work_dir = Path(work_dir)
    request = []
    for i, fmu in enumerate(map(Path, fmus)):
        model = _model_identifier(fmu)
        in_path, ref_path = work_dir / f"{i}_in.csv", work_dir / f"{i}_ref.csv"
        in_path.write_bytes(input_csv(EXPERIMENTS[model]))
        request.append({"fmu": str(fmu), "model": model, "in": str(in_path), "ref": str(ref_path)})
    proc = subprocess.run([sys.executable, "-m", "fmu_src.packing.crosscheck", "simulate"],
                          input=json.dumps(request), capture_output=True, text=True, cwd=REPO_ROOT)
    if proc.returncode != 0:
        raise RuntimeError(f"the reference simulation failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
    return {Path(r["fmu"]): (Path(r["in"]).read_bytes(), Path(r["ref"]).read_bytes()) for r in request}


def reference_file_names(model: str) -> dict[str, str]:
    """The experiment's files by role, named as the cross-check rules name them."""
    return {"experiment/validation": f"{model}_ref.opt", "testcase": f"{model}_in.csv", "result": f"{model}_ref.csv"}


def ls_ref_manifest(model: str, experiment: Experiment) -> bytes:
    """``fmi-ls-manifest.xml``: one ``<Related>`` per file of the reference experiment."""
    names = reference_file_names(model)
    ET.register_namespace("fmi-ls", LS_NS)
    root = ET.Element("fmiReferences", {f"{{{LS_NS}}}fmi-ls-name": "org.fmi-standard.fmi-ls-ref",
                                        f"{{{LS_NS}}}fmi-ls-version": LS_VERSION,
                                        f"{{{LS_NS}}}fmi-ls-description": LS_DESCRIPTION})
    related = [
        ("text/plain", "experiment/validation",
         f"Reference experiment ({experiment.description}): FMI cross-check rules options file (StartTime, "
         f"StopTime, StepSize, RelTol, OutputIntervalLength); inputs {names['testcase']}, results {names['result']}"),
        ("text/csv", "testcase", "Input signals of the reference experiment, one row per communication point"),
        ("text/csv", "result", f"Outputs of the reference experiment, every "
         f"{experiment.step_size * experiment.output_every!r} s (FMPy on linux64)"),
    ]
    for mime, role, description in related:
        element = ET.SubElement(root, "Related", type=mime, source=names[role], role=role, description=description)
        ET.SubElement(element, "Label", name=EXPERIMENT_LABEL, description="the files of the reference experiment")
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def ref_opt(experiment: Experiment) -> bytes:
    return (f"StartTime, 0.0\nStopTime, {experiment.stop_time!r}\nStepSize, {experiment.step_size!r}\n"
            f"RelTol, {REL_TOL!r}\nOutputIntervalLength, {experiment.step_size * experiment.output_every!r}\n").encode()


def _experiment_text(model: str, experiment: Experiment) -> str:
    return f"""Reference experiment: {experiment.description}; {experiment.stop_time!r} s, communication step
{experiment.step_size!r} s, one input row per communication point in `{model}_in.csv` (apply
the row of each communication point before its doStep; no interpolation is needed), outputs
every {experiment.step_size * experiment.output_every!r} s in `{model}_ref.csv`, the options in
`{model}_ref.opt`.  The reference was computed with FMPy on linux64 by the project's build
(`python build.py`); FMPy reproduces it bit for bit.  `RelTol` {REL_TOL!r} is the band for
other importers and platforms (another libm may differ in the last bit)."""


def _ls_ref_doc(model: str, experiment: Experiment) -> str:
    return f"""{model}: reference results (fmi-ls-ref {LS_VERSION})

The folder {LS_REF_DIR}/ holds one experiment, listed in its fmi-ls-manifest.xml
and named as the FMI cross-check rules (v4.1, sections 9.1.4-9.1.5) name the files of one:

{_experiment_text(model, experiment)}
"""


def add_references(fmus, work_dir: Path) -> None:
    """Simulate every FMU of ``fmus`` and rewrite it with ``extra/org.fmi-standard.fmi-ls-ref/``
    (manifest, ``_ref.opt``, ``_in.csv``, ``_ref.csv``) and ``documentation/fmi-ls-ref.txt``."""
    results = reference_results(fmus, work_dir)
    for fmu, (in_csv, ref_csv) in results.items():
        model = _model_identifier(fmu)
        experiment = EXPERIMENTS[model]
        names = reference_file_names(model)
        entries = read_entries(fmu)
        entries[f"{LS_REF_DIR}/fmi-ls-manifest.xml"] = ls_ref_manifest(model, experiment)
        entries[f"{LS_REF_DIR}/{names['experiment/validation']}"] = ref_opt(experiment)
        entries[f"{LS_REF_DIR}/{names['testcase']}"] = in_csv
        entries[f"{LS_REF_DIR}/{names['result']}"] = ref_csv
        entries[LS_DOC] = _ls_ref_doc(model, experiment).encode()
        write_zip(entries, fmu)
        log.info("added reference results to %s", fmu)


def add_reference(fmu: Path, *, sanitize: bool = False) -> Path:
    """``fmu`` with its reference results inside (``add_references``); returns ``fmu``.  A
    ``sanitize`` build (tests only) gets none: its guard runs only with libasan preloaded."""
    if sanitize:
        log.info("%s: a sanitize build, no reference results", fmu)
        return Path(fmu)
    with tempfile.TemporaryDirectory(prefix="avr_reference_") as tmp:
        add_references([fmu], Path(tmp))
    return Path(fmu)


def reference_files(fmu: Path) -> dict[str, bytes]:
    """The experiment's files inside ``fmu``, by file name."""
    model = _model_identifier(fmu)
    with zipfile.ZipFile(fmu) as archive:
        names = set(archive.namelist())
        wanted = list(reference_file_names(model).values())
        missing = [n for n in wanted if f"{LS_REF_DIR}/{n}" not in names]
        if missing:
            raise RuntimeError(f"{fmu}: no {', '.join(missing)} in {LS_REF_DIR}/ (a sanitize build has none)")
        return {n: archive.read(f"{LS_REF_DIR}/{n}") for n in wanted}


def _readme(model: str, platform: str, version: str, experiment: Experiment) -> str:
    return f"""# {model} ({TOOL_NAME} {version}, FMI 2.0 co-simulation, {platform})

The adaptive velocity regulator for bipedal walking (Castillo et al., IROS 2020) in C: PD
foot-placement and torso regulators plus online-learning neural networks that output
virtual-constraint offsets.  No Python and no other library is needed (linux64: libc and
libm; win64: kernel32 and msvcrt); the C sources are in the FMU.

{_experiment_text(model, experiment)}
The same three files travel inside the FMU in `{LS_REF_DIR}/` (fmi-ls-ref {LS_VERSION}).

Only this FMU is in the tree: the project's pythonfmu FMUs (AdaptiveVelocityRegulator,
CassiePlant) need a Python 3 installation with numpy (the plant also MuJoCo) on the importing
machine, which the cross-check rules (9.1.3: "without additional requirements") exclude, and
the FMI 3.0 FMU has no place in the cross-check tree (FMI 1.0 and 2.0 only).

License: MIT (`LICENSE.txt`); the FMI headers in `sources/` are BSD-2-Clause (Modelica Association).
"""


def write_vendor_tree(out_dir: Path, fmus, version: str) -> Path:
    """``<out_dir>/cross-check/fmus/2.0/cs/<platform>/cassie-avr/<version>/<Model>/`` for every
    FMI 2.0 FMU of ``fmus`` with platforms in ``CROSS_CHECK_PLATFORMS`` (those it carries binaries
    for), with the reference files inside the FMU; returns the tree's root."""
    import shutil

    root = Path(out_dir) / CROSS_CHECK_DIR
    if root.exists():
        shutil.rmtree(root)
    for fmu in map(Path, fmus):
        with zipfile.ZipFile(fmu) as archive:
            md = ET.fromstring(archive.read("modelDescription.xml"))
            carried = {name.split("/")[1] for name in archive.namelist() if name.startswith("binaries/")}
        model = md.find("CoSimulation").get("modelIdentifier") if md.find("CoSimulation") is not None else None
        if md.get("fmiVersion") != "2.0" or model not in CROSS_CHECK_PLATFORMS:
            continue
        files = reference_files(fmu)
        for platform in [p for p in CROSS_CHECK_PLATFORMS[model] if p in carried]:  # without a cross compiler: not all
            folder = root / "fmus" / "2.0" / "cs" / platform / TOOL_NAME / version / model
            folder.mkdir(parents=True)
            shutil.copyfile(fmu, folder / f"{model}.fmu")
            for name, data in files.items():
                (folder / name).write_bytes(data)
            (folder / "ReadMe.md").write_text(_readme(model, platform, version, EXPERIMENTS[model]))
            (folder / "LICENSE.txt").write_text(MIT_LICENSE)
    return root


def _simulate_request() -> int:
    """The child process of ``reference_results``: simulate each requested FMU."""
    for item in json.loads(sys.stdin.read()):
        Path(item["ref"]).write_bytes(simulate(Path(item["fmu"]), Path(item["in"]), EXPERIMENTS[item["model"]]))
    return 0


if __name__ == "__main__":
    if sys.argv[1:] != ["simulate"]:
        sys.exit(f"usage: python -m {__spec__.name} simulate  (a JSON request on stdin)")
    sys.exit(_simulate_request())
