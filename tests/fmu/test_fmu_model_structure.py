"""Every FMU's ModelStructure says what the FMU does, measured on the built FMU through fmpy.

For each FMU build.py lists in fmus.json (tests/support/native/test_native_fmu.py pins that list: the
pythonfmu regulator, the native FMI 2.0 and FMI 3.0 regulators, the CassiePlant FMU):

* Outputs (FMI 2.0 ``<Outputs><Unknown dependencies>``, FMI 3.0 ``<Output dependencies>``):
  every output declares ``dependencies``, and they equal the measured direct feedthrough:
  set one input to another in-range value and read every output without a step, after
  initialization and again after some steps (a state that is not the initial one).  An
  output without ``dependencies`` would mean "depends on every input", which makes an SSP
  importer (OMSimulator) see an algebraic loop plant <-> regulator that is not there.
* Initialization (FMI 2.0 section 2.2.8): an output with ``initial="exact"`` holds its start
  value after initialization and no known changes it; an output computed during
  initialization is ``initial="calculated"`` and listed in ``InitialUnknowns``, whose
  ``dependencies`` are the knowns (parameters, inputs) that measurably change it.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from fmu_src.core.avr_specs import PARAM_REQUIRES
from support.plant_fmu_support import built_plant_fmu

FMUS = ("python-fmi2", "native-fmi2", "native-fmi3", "plant-fmi2")
STEP_S = 0.005  # the default experiment's communication step of every FMU
#: Steps taken (with non-default inputs) before the second feedthrough measurement.
WARMUP_STEPS = 20
#: (values set before initialization besides the defaults, the knowns measured there: None =
#: all): knowns that act only in some states are seen too (the plant's terrain parameters
#: shape nothing while the floor is a plane, i.e. terrain_max_height_m = 0).
INIT_BASES = {"plant-fmi2": (({}, None), ({"terrain_max_height_m": 0.1},
                                          ("terrain_max_slope_deg", "terrain_seed", "terrain_size_m")))}


@pytest.fixture(scope="module", params=FMUS)
def fmu(request, tmp_path_factory, build_module, unzip):
    """(the .fmu, its extracted folder) as build.py builds it."""
    if request.param == "python-fmi2":
        path = request.getfixturevalue("built_fmu")
    elif request.param == "plant-fmi2":
        path = built_plant_fmu(tmp_path_factory, build_module)
    else:
        path = request.getfixturevalue("native_fmus")[int(request.param[-1])]
    return request.param, path, unzip(path, tmp_path_factory.mktemp(request.param))


class Instance:
    """One fmpy instance of an FMI 2.0 or 3.0 co-simulation FMU, addressed by variable."""

    def __init__(self, md, unzip_dir, name):
        self.md, self.fmi3 = md, md.fmiVersion.startswith("3")
        cls = FMU3Slave if self.fmi3 else FMU2Slave
        self.fmu = cls(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                       instanceName=name)
        self.fmu.instantiate(loggingOn=False)
        self.t = 0.0

    def _kind(self, var):
        return {"Float64": "Real", "Int32": "Integer"}.get(var.type, var.type)

    def set(self, var, value):
        vr, kind = [var.valueReference], self._kind(var)
        if kind == "Real":
            (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(vr, [float(value)])
        elif kind == "Integer":
            (self.fmu.setInt32 if self.fmi3 else self.fmu.setInteger)(vr, [int(value)])
        elif kind == "Boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        else:
            self.fmu.setString(vr, [value])

    def get(self, var):
        vr, kind = [var.valueReference], self._kind(var)
        if kind == "Real":
            return (self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)(vr)[0]
        if kind == "Integer":
            return (self.fmu.getInt32 if self.fmi3 else self.fmu.getInteger)(vr)[0]
        if kind == "Boolean":
            return bool(self.fmu.getBoolean(vr)[0])
        return self.fmu.getString(vr)[0]

    def init(self):
        if self.fmi3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def step(self):
        self.fmu.doStep(self.t, STEP_S)
        self.t += STEP_S

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def typed_start(var):
    """A variable's start value as the getter returns it."""
    if var.start is None:
        return None
    if var.type == "Boolean":
        return var.start in ("true", "1", True)
    if var.type in ("Integer", "Int32"):
        return int(var.start)
    if var.type == "String":
        return var.start
    return float(var.start)


def other_value(var):
    """A legal value of ``var`` other than its start: a tenth of its range away (towards the
    inside), 0.5 away if unbounded; Integer +1 (or -1 at max), Boolean flipped, String: the
    other enumerated choice the description names."""
    start = typed_start(var)
    if var.type == "Boolean":
        return not start
    if var.type == "String":
        return {"menagerie": "osu", "osu": "menagerie"}[start]
    lo = None if var.min is None else float(var.min)
    hi = None if var.max is None else float(var.max)
    if var.type in ("Integer", "Int32"):
        return start + 1 if hi is None or start + 1 <= hi else start - 1
    delta = 0.5 if lo is None or hi is None else 0.1 * (hi - lo)
    return start + delta if hi is None or start + delta <= hi else start - delta


def declared_structure(fmu_path, md):
    """({output name: dependency names or None if the attribute is absent},
    {initial unknown name: dependency names or None}), read from the XML itself (fmpy's
    reader cannot tell an absent ``dependencies`` from an empty one)."""
    with zipfile.ZipFile(fmu_path) as archive:
        root = ET.fromstring(archive.read("modelDescription.xml"))
    structure = root.find("ModelStructure")
    variables = md.modelVariables
    if md.fmiVersion.startswith("3"):
        by_vr = {v.valueReference: v.name for v in variables}
        lookup = lambda text: by_vr[int(text)]  # noqa: E731
        outputs, initial = structure.findall("Output"), structure.findall("InitialUnknown")
        key = "valueReference"
    else:
        lookup = lambda text: variables[int(text) - 1].name  # noqa: E731
        outputs = structure.findall("Outputs/Unknown")
        initial = structure.findall("InitialUnknowns/Unknown")
        key = "index"

    def read(elements):
        return {lookup(e.get(key)): (None if e.get("dependencies") is None else
                                     {lookup(t) for t in e.get("dependencies").split()}) for e in elements}
    return read(outputs), read(initial)


def measured_feedthrough(md, unzip_dir) -> dict[str, set[str]]:
    """Output name -> the inputs whose change alone (no doStep) changes it; measured after
    initialization and again after ``WARMUP_STEPS`` steps with every input moved."""
    inputs = [v for v in md.modelVariables if v.causality == "input"]
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    found = {o.name: set() for o in outputs}
    inst = Instance(md, unzip_dir, "feedthrough")
    try:
        inst.init()
        for phase in ("initialized", "stepped"):
            if phase == "stepped":
                for var in inputs:
                    inst.set(var, other_value(var))
                for _ in range(WARMUP_STEPS):
                    inst.step()
            for var in inputs:
                before = [inst.get(o) for o in outputs]
                value = inst.get(var)
                inst.set(var, other_value(var) if value == typed_start(var) else typed_start(var))
                after = [inst.get(o) for o in outputs]
                inst.set(var, value)
                for o, a, b in zip(outputs, before, after):
                    if a != b:
                        found[o.name].add(var.name)
    finally:
        inst.free()
    return found


def initialized_outputs(md, unzip_dir, values) -> dict[str, object]:
    inst = Instance(md, unzip_dir, "init")
    try:
        for name, value in values.items():
            inst.set(md_var(md, name), value)
        inst.init()
        return {v.name: inst.get(v) for v in md.modelVariables if v.causality == "output"}
    finally:
        inst.free()


def md_var(md, name):
    return next(v for v in md.modelVariables if v.name == name)


def measured_initial_dependencies(fmu_id, md, unzip_dir):
    """(output name -> knowns that change its value after initialization, the outputs after a
    default initialization).  Knowns: parameters with initial exact (not constants) and
    inputs, each set alone to another value before initialization, over ``INIT_BASES``."""
    knowns = [v for v in md.modelVariables if v.causality in ("input", "parameter")]
    found = {v.name: set() for v in md.modelVariables if v.causality == "output"}
    by_name = {v.name: v for v in md.modelVariables}
    defaults = None
    for base, measure in INIT_BASES.get(fmu_id, (({}, None),)):
        reference = initialized_outputs(md, unzip_dir, base)
        defaults = defaults or reference
        for var in knowns:
            if var.name in base or (measure is not None and var.name not in measure):
                continue
            # A knob that acts only with another (PARAM_REQUIRES) is refused alone: both sides of
            # its comparison set the one it requires.
            needs = {b: other_value(by_name[b]) for a, b in PARAM_REQUIRES if a == var.name and b in by_name}
            against = initialized_outputs(md, unzip_dir, {**base, **needs}) if needs else reference
            changed = initialized_outputs(md, unzip_dir, {**base, **needs, var.name: other_value(var)})
            for name, value in changed.items():
                if value != against[name]:
                    found[name].add(var.name)
    return found, defaults


def test_every_output_declares_its_measured_feedthrough(fmu):
    fmu_id, path, unzip_dir = fmu
    md = read_model_description(str(path))
    outputs, _ = declared_structure(path, md)
    names = {v.name for v in md.modelVariables if v.causality == "output"}
    assert set(outputs) == names, f"{fmu_id}: ModelStructure lists {sorted(outputs)}, the outputs are {sorted(names)}"
    missing = sorted(n for n, deps in outputs.items() if deps is None)
    assert not missing, f"{fmu_id}: outputs without dependencies (= depend on every input): {missing}"
    measured = measured_feedthrough(md, unzip_dir)
    assert outputs == measured, f"{fmu_id}: declared {outputs} != measured {measured}"


def test_initial_unknowns_are_exact(fmu):
    fmu_id, path, unzip_dir = fmu
    md = read_model_description(str(path))
    _, initial = declared_structure(path, md)
    measured, values = measured_initial_dependencies(fmu_id, md, unzip_dir)
    for var in (v for v in md.modelVariables if v.causality == "output"):
        if var.initial in (None, "exact"):
            assert var.name not in initial, f"{fmu_id}: {var.name} is initial exact yet in InitialUnknowns"
            assert values[var.name] == typed_start(var) and not measured[var.name], (
                f"{fmu_id}: {var.name} is initial exact (start {var.start}) but is {values[var.name]} after "
                f"initialization and changes with {sorted(measured[var.name])}: it is calculated")
        else:
            assert var.start is None and var.name in initial, f"{fmu_id}: {var.name} ({var.initial})"
            assert initial[var.name] is not None and measured[var.name] <= initial[var.name], (
                f"{fmu_id}: {var.name} declares initial dependencies {initial[var.name]}, measured "
                f"{measured[var.name]}")
    # One perturbation per known may leave a real dependency unseen for one output (the right
    # foot's force moved with terrain_size_m, the left one's did not): no declared known may be
    # dead for every initial unknown, and none may be missing for any.
    declared = set().union(*(deps for deps in initial.values() if deps))
    seen = set().union(*(measured[name] for name in initial)) if initial else set()
    assert declared == seen, f"{fmu_id}: declared initial dependencies {declared}, measured {seen}"
    calculated = {v.name for v in md.modelVariables if v.causality == "output" and v.initial in ("approx", "calculated")}
    assert set(initial) == calculated, f"{fmu_id}: InitialUnknowns {sorted(initial)} != {sorted(calculated)}"
    assert np.all(np.isfinite([v for v in values.values() if isinstance(v, float)]))
