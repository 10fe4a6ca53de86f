"""Call every FMI function an FMU exports in every state the FMU can be brought to, and report
which calls were refused for the state they came in.

Runs in a process of its own (a crash shows as a failed test, not a dead pytest):

    python phase_matrix.py FMU_DIR FMI_VERSION

prints one JSON object {function: {state: {"status": s, "phase": bool, "messages": [...]}}}:
``phase`` is whether the FMU refused the call naming its state ("<function> refused: not allowed
in state ...").  Every function is called through ctypes with its signature from the FMI
standard's own header (fmu_src/fmi/third_party/, read by the conformance
check's ``capi.signatures``), every argument zero or NULL: a call the
state allows then goes on to the argument checks (refused or OK, but never for its state).
A call that may change the state (initialization, terminate, reset) gets an instance of its own.
"""
import ctypes
import json
import re
import sys
from ctypes import POINTER, byref, c_bool, c_char_p, c_double, c_int, c_size_t, c_void_p
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)
from fmpy.logging import addLoggerProxy

from fmu_src.fmi.conformance.capi import signatures

#: Not called: no instance to call them on, or they end it.
SKIPPED = re.compile(r"fmi[23](Instantiate\w*|FreeInstance|GetVersion|GetTypesPlatform)$")
#: Calls that may change the state when allowed: each gets an instance of its own.
MOVERS = {"fmi2EnterInitializationMode", "fmi2ExitInitializationMode", "fmi2Terminate", "fmi2Reset",
          "fmi3EnterInitializationMode", "fmi3ExitInitializationMode", "fmi3Terminate", "fmi3Reset",
          "fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode", "fmi3EnterEventMode", "fmi3EnterStepMode",
          "fmi3EnterContinuousTimeMode"}
#: The path from instantiation to each state: the calls that lead there.
ROUTES = {2: {"instantiated": [], "initializationMode": ["setup", "enter"],
              "stepComplete": ["setup", "enter", "exit"], "terminated": ["setup", "enter", "exit", "terminate"]},
          3: {"Instantiated": [], "InitializationMode": ["enter"], "StepMode": ["enter", "exit"],
              "Terminated": ["enter", "exit", "terminate"]}}


class Fmu:
    def __init__(self, fmu_dir: str, version: int):
        self.dir, self.version = Path(fmu_dir), version
        self.md = read_model_description(fmu_dir)
        identifier = self.md.coSimulation.modelIdentifier
        platform = "linux64" if version == 2 else "x86_64-linux"
        self.lib = ctypes.CDLL(str(self.dir / "binaries" / platform / f"{identifier}.so"))
        self.log = []
        if version == 2:
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            libc = ctypes.CDLL(None)
            libc.calloc.restype, libc.calloc.argtypes = c_void_p, [c_size_t, c_size_t]
            libc.free.argtypes = [c_void_p]
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(libc.calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(libc.free)
            addLoggerProxy(byref(self.callbacks))  # formats the variadic arguments before Python sees them
        else:
            self.log3 = ctypes.CFUNCTYPE(None, c_void_p, c_int, c_char_p, c_char_p)(self._log3)
        self.sig = signatures(version)

    def _log2(self, env, name, status, category, message):
        self.log.append(message.decode("utf-8", "replace"))

    def _log3(self, env, status, category, message):
        self.log.append(message.decode("utf-8", "replace"))

    def function(self, name, argtypes):
        f = self.lib[name]  # a fresh function object: its types are this script's own
        f.argtypes, f.restype = argtypes, c_int
        return f

    def instantiate(self):
        if self.version == 2:
            f = self.lib["fmi2Instantiate"]
            f.restype = c_void_p
            f.argtypes = [c_char_p, c_int, c_char_p, c_char_p, POINTER(fmi2CallbackFunctions), c_int, c_int]
            inst = f(b"matrix", 1, self.md.guid.encode(), (self.dir / "resources").as_uri().encode(),
                     byref(self.callbacks), 0, 0)
        else:
            f = self.lib["fmi3InstantiateCoSimulation"]
            f.restype = c_void_p
            f.argtypes = [c_char_p, c_char_p, c_char_p, c_bool, c_bool, c_bool, c_bool, c_void_p, c_size_t,
                          c_void_p, c_void_p, c_void_p]
            resources = str(self.dir / "resources") + "/"
            inst = f(b"matrix", self.md.instantiationToken.encode(), resources.encode(), False, False, False,
                     False, None, 0, None, ctypes.cast(self.log3, c_void_p), None)
        assert inst, f"instantiation failed: {self.log[-3:]}"
        return inst

    def free(self, inst):
        f = self.lib[f"fmi{self.version}FreeInstance"]
        f.argtypes, f.restype = [c_void_p], None
        f(inst)

    def move(self, inst, step):
        v = self.version
        calls = {"setup": ("fmi2SetupExperiment", [c_void_p, c_int, c_double, c_double, c_int, c_double],
                           (inst, 0, 0.0, 0.0, 0, 0.0)),
                 "enter": (f"fmi{v}EnterInitializationMode", [c_void_p], (inst,)) if v == 2 else
                          ("fmi3EnterInitializationMode", [c_void_p, c_bool, c_double, c_double, c_bool, c_double],
                           (inst, False, 0.0, 0.0, False, 0.0)),
                 "exit": (f"fmi{v}ExitInitializationMode", [c_void_p], (inst,)),
                 "terminate": (f"fmi{v}Terminate", [c_void_p], (inst,))}
        name, argtypes, args = calls[step]
        status = self.function(name, argtypes)(*args)
        assert status == 0, f"{name} on the way to a state answered {status}: {self.log[-3:]}"

    def in_state(self, state):
        inst = self.instantiate()
        for step in ROUTES[self.version][state]:
            self.move(inst, step)
        return inst

    def call(self, inst, name):
        argtypes = self.sig[name]
        unknown = [t for t in argtypes if isinstance(t, str)]
        if unknown:
            raise SystemExit(f"{name}: no ctypes type for {unknown}")
        args = [inst] + [t() if t is not c_void_p else None for t in argtypes[1:]]
        before = len(self.log)
        status = self.function(name, argtypes)(*args)
        messages = self.log[before:]
        phase = any(m.startswith(f"{name} refused: not allowed in state") for m in messages)
        return {"status": status, "phase": phase, "messages": messages}


def main():
    fmu = Fmu(sys.argv[1], int(sys.argv[2]))
    names = sorted(n for n in fmu.sig if not SKIPPED.match(n) and hasattr(fmu.lib, n))
    result = {name: {} for name in names}
    for state in ROUTES[fmu.version]:
        shared = fmu.in_state(state)
        for name in names:
            own = fmu.in_state(state) if name in MOVERS else None
            result[name][state] = fmu.call(own or shared, name)
            if own:
                fmu.free(own)
        fmu.free(shared)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
