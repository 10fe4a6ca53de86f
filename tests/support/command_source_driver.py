"""Drive an unzipped CommandSource FMU (FMI 2.0 or 3.0) through fmpy in its own process
(a crash fails the test that started it, not pytest):

    python command_source_driver.py FMU_DIR FMI_VERSION CALLS_JSON

prints one JSON object: ``results`` (one per call: the FMI status as an int, a value list
for ``get``, ``null`` for an instantiation that returned NULL) and ``log`` (every message
the FMU logged: [status, category, message], the format already applied).

Calls: ["instantiate"] (FMI 3.0: optional keyword flags {"eventModeUsed": true}),
["setup", t0] (FMI 2.0: fmi2SetupExperiment; FMI 3.0: the start time the next "enter"
passes), ["enter"], ["exit"], ["step", t, h], ["get", [vr, ...]], ["set", vr, value],
["terminate"], ["reset"], ["getFMUState"], ["call", name] (a function without arguments
beyond the instance, e.g. fmi3EnterEventMode), ["free"].
"""
from __future__ import annotations

import ctypes
import json
import sys

from fmpy import read_model_description
from fmpy.fmi1 import FMICallException


def text(raw: bytes) -> str:
    """An FMU's log string, which FMI requires to be UTF-8; anything else is shown as such."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return "<not UTF-8> " + raw.decode("utf-8", errors="replace")


def main(fmu_dir: str, version: int, calls: list) -> dict:
    md = read_model_description(fmu_dir)
    log: list = []
    if version == 2:
        from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        from fmpy.logging import addLoggerProxy

        def logger(env, name, status, category, message):
            log.append([status, text(category), text(message)])

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        callbacks.allocateMemory = defaultCallbacks.allocateMemory
        callbacks.freeMemory = defaultCallbacks.freeMemory
        addLoggerProxy(ctypes.byref(callbacks))  # formats the "%s" varargs in C
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="command")
    else:
        from fmpy.fmi3 import FMU3Slave

        def logger(env, status, category, message):
            log.append([status, text(category), text(message)])

        fmu = FMU3Slave(guid=md.guid, unzipDirectory=fmu_dir, modelIdentifier=md.coSimulation.modelIdentifier,
                        instanceName="command")
    start = [0.0]
    results = []

    def instantiate(flags=None):
        try:
            if version == 2:
                fmu.instantiate(callbacks=callbacks)
            else:
                fmu.instantiate(logMessage=logger, **(flags or {}))
        except Exception:  # fmpy raises for a NULL instance
            return None
        return 0

    def run(op, *args):
        if op == "instantiate":
            return instantiate(*args)
        if op == "setup":
            if version == 2:
                fmu.setupExperiment(startTime=args[0])
            else:
                start[0] = args[0]
        elif op == "enter":
            if version == 2:
                fmu.enterInitializationMode()
            else:
                fmu.enterInitializationMode(startTime=start[0])
        elif op == "exit":
            fmu.exitInitializationMode()
        elif op == "step":
            fmu.doStep(args[0], args[1])
        elif op == "get":
            return list(fmu.getReal(args[0]) if version == 2 else fmu.getFloat64(args[0]))
        elif op == "set":
            (fmu.setReal if version == 2 else fmu.setFloat64)([args[0]], [args[1]])
        elif op == "terminate":
            fmu.terminate()
        elif op == "reset":
            fmu.reset()
        elif op == "getFMUState":
            fmu.getFMUstate() if version == 2 else fmu.getFMUState()
        elif op == "call":
            status = getattr(fmu, args[0])(fmu.component)
            return int(status)
        elif op == "free":
            fmu.freeInstance()
        else:
            raise ValueError(f"unknown call {op!r}")
        return 0

    for call in calls:
        try:
            results.append(run(*call))
        except FMICallException as exc:
            results.append(int(exc.status))
    return {"results": results, "log": log}


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]), json.loads(sys.argv[3]))))
