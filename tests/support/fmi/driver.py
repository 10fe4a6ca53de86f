"""Drive the real FMU through fmpy call by call and report each call's FMI status.

Runs in its own process, so that a crash of the FMU cannot take pytest down.

    python driver.py FMU_DIR             # JSON lines on stdin -> JSON lines on stdout
    python driver.py FMU_DIR CALLS_JSON  # one sequence, prints one JSON list

FMU_DIR is the extracted FMU (the tests extract it under their tmp_path).

A call is a list: ``["instantiate"]``, ``["setup", t0]``, ``["enter"]``, ``["exit"]``,
``["step", t, h]``, ``["set", name, value]``, ``["get", name]``, ``["terminate"]``,
``["reset"]``, ``["get_state"]``, ``["set_state", i]``, ``["serialize", i]``,
``["deserialize", i]`` (i < 0: garbage bytes), ``["free"]``.  The answer per call is
``{"status": 0..4}`` (plus ``"value"`` for get) or ``{"status": "instantiate-failed"}``.
"""
import json
import sys

from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave


class Driver:
    slave_class = FMU2Slave

    def __init__(self, fmu_dir):
        self.md = read_model_description(fmu_dir)
        self.unzip = fmu_dir
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.fmu = None
        self.states = []
        self.blobs = []
        self.count = 0

    def call(self, op, *args):
        try:
            return {"status": 0, **(self._call(op, *args) or {})}
        except FMICallException as exc:
            return {"status": exc.status}

    def _instantiate(self):
        self.count += 1
        self.fmu = self.slave_class(guid=self.md.guid, unzipDirectory=self.unzip,
                                    modelIdentifier=self.md.coSimulation.modelIdentifier,
                                    instanceName=f"driver{self.count}")
        try:
            self.fmu.instantiate(loggingOn=False)
        except Exception:  # fmpy raises a plain Exception when instantiation returns NULL
            self.fmu = None
            return {"status": "instantiate-failed"}
        self.states, self.blobs = [], []
        return None

    def _call(self, op, *args):
        if op == "instantiate":
            return self._instantiate()
        fmu = self.fmu
        if op == "setup":
            fmu.setupExperiment(startTime=args[0])
        elif op == "enter":
            fmu.enterInitializationMode()
        elif op == "exit":
            fmu.exitInitializationMode()
        elif op == "step":
            fmu.doStep(args[0], args[1])
        elif op in ("set", "get"):
            var = self.vars[args[0]]
            vr = [var.valueReference]
            if op == "set":
                value = args[1]
                {"Real": fmu.setReal, "Integer": fmu.setInteger, "Boolean": fmu.setBoolean}[var.type](vr, [value])
                return None
            getter = {"Real": fmu.getReal, "Integer": fmu.getInteger, "Boolean": fmu.getBoolean}[var.type]
            return {"value": getter(vr)[0]}
        elif op == "terminate":
            fmu.terminate()
        elif op == "reset":
            fmu.reset()
        elif op == "get_state":
            self.states.append(fmu.getFMUstate())
            return {"index": len(self.states) - 1}
        elif op == "set_state":
            fmu.setFMUstate(self.states[args[0]])
        elif op == "serialize":
            self.blobs.append(bytes(fmu.serializeFMUstate(self.states[args[0]])))
            return {"index": len(self.blobs) - 1, "size": len(self.blobs[-1])}
        elif op == "deserialize":
            blob = b"\x00garbage" * 8 if args[0] < 0 else self.blobs[args[0]]
            self.states.append(fmu.deSerializeFMUstate(blob))
            return {"index": len(self.states) - 1}
        elif op == "free":
            fmu.freeInstance()
            self.fmu = None
        else:
            raise ValueError(f"unknown op {op!r}")
        return None


def main(driver_class=Driver):
    driver = driver_class(sys.argv[1])
    try:
        if len(sys.argv) > 2:
            print(json.dumps([driver.call(*c) for c in json.loads(sys.argv[2])]), flush=True)
            return
        for line in sys.stdin:
            print(json.dumps(driver.call(*json.loads(line))), flush=True)
    finally:  # a well-behaved host frees what it instantiated
        if driver.fmu is not None:
            driver.fmu.freeInstance()


if __name__ == "__main__":
    main()
