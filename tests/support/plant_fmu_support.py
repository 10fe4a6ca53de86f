"""Shared by tests/fmu/test_plant_fmu.py and tests/ssp/test_ssp.py: the CassiePlant FMU and the
CassieAVR system exactly as build.py builds them, built once per test session into pytest's
temporary folder (``support.builds``), and a small fmpy helper that reports statuses
instead of raising."""
from __future__ import annotations

from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from support import builds


def built_plant_fmu(tmp_path_factory, build_module) -> Path:
    return builds.plant_fmu(tmp_path_factory, build_module)


def built_system(tmp_path_factory, build_module, regulator_fmu) -> Path:
    """A folder holding the command source FMU, CassieAVR.ssp and CassieAVR_osp/ (build.py's own functions)
    around ``regulator_fmu`` (the session's pythonfmu regulator)."""
    return builds.system(tmp_path_factory, build_module, regulator_fmu)


class Plant:
    """fmpy's FMU2Slave on the plant FMU, by variable name."""

    def __init__(self, fmu_dir, name="plant"):
        """``fmu_dir``: the extracted FMU (the tests extract it under their tmp_path)."""
        self.md = read_model_description(str(fmu_dir))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(fmu_dir),
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=False)
        self.t = 0.0

    def set(self, name, value):
        var = self.vars[name]
        {"Real": self.fmu.setReal, "Integer": self.fmu.setInteger, "Boolean": self.fmu.setBoolean,
         "String": self.fmu.setString}[var.type]([var.valueReference], [value])

    def get(self, name):
        var = self.vars[name]
        return {"Real": self.fmu.getReal, "Integer": self.fmu.getInteger, "Boolean": self.fmu.getBoolean,
                "String": self.fmu.getString}[var.type]([var.valueReference])[0]

    def init(self, **values):
        for name, value in values.items():
            self.set(name, value)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        return self

    def step(self, h=0.005, **inputs):
        for name, value in inputs.items():
            self.set(name, value)
        self.fmu.doStep(self.t, h)
        self.t += h
        return self.outputs()

    def outputs(self) -> tuple:
        return tuple(self.get(v.name) for v in self.md.modelVariables if v.causality == "output")

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def status_of(call, *args) -> int:
    """The FMI status of an fmpy call (fmpy raises for Discard and worse)."""
    try:
        call(*args)
    except FMICallException as exc:
        return exc.status
    return 0
