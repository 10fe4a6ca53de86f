"""An FMU's binary loaded through ctypes, every function typed from the FMI standard's own header
(``fmu_src/fmi/third_party/fmi<version>/fmi<version>FunctionTypes.h``), every call recorded.

:class:`Binary` gives the two FMI versions one vocabulary (instantiate, initialize, step, get and
set by type, FMU state) so that the checks are written once.  Before each call it hands the
call's text (function and arguments) to ``trace``: the conformance child process writes it out,
so that when the FMU under test crashes or hangs the parent can name the last call made.
"""
from __future__ import annotations

import ctypes
import re
from ctypes import (byref, c_bool, c_char, c_char_p, c_double, c_float, c_int, c_int8, c_int16, c_int32,
                    c_int64, c_size_t, c_uint8, c_uint16, c_uint32, c_uint64, c_void_p)
from pathlib import Path

THIRD_PARTY = Path(__file__).resolve().parents[1] / "third_party"
#: C types of the scalar arguments of the FMI functions (anything with * or [] is a pointer).
SCALARS = {
    "fmi2Component": c_void_p, "fmi2ComponentEnvironment": c_void_p, "fmi2FMUstate": c_void_p,
    "fmi2Real": c_double, "fmi2Integer": c_int32, "fmi2Boolean": c_int, "fmi2ValueReference": c_uint32,
    "fmi2StatusKind": c_int, "fmi2Type": c_int, "fmi2String": c_char_p, "size_t": c_size_t,
    "fmi3Instance": c_void_p, "fmi3InstanceEnvironment": c_void_p, "fmi3FMUState": c_void_p,
    "fmi3LogMessageCallback": c_void_p, "fmi3IntermediateUpdateCallback": c_void_p,
    "fmi3ClockUpdateCallback": c_void_p, "fmi3LockPreemptionCallback": c_void_p,
    "fmi3UnlockPreemptionCallback": c_void_p, "fmi3Float64": c_double, "fmi3Float32": c_float,
    "fmi3Int8": c_int8, "fmi3UInt8": c_uint8, "fmi3Int16": c_int16, "fmi3UInt16": c_uint16, "fmi3Int32": c_int32,
    "fmi3UInt32": c_uint32, "fmi3Int64": c_int64, "fmi3UInt64": c_uint64, "fmi3Boolean": c_bool,
    "fmi3ValueReference": c_uint32, "fmi3String": c_char_p, "fmi3Clock": c_bool, "fmi3DependencyKind": c_int,
    "fmi3IntervalQualifier": c_int,
}
#: Statuses, as both versions number them.
OK, WARNING, DISCARD, ERROR, FATAL = range(5)
STATUS_NAMES = ("OK", "Warning", "Discard", "Error", "Fatal")
#: Variable type (model description) -> ctypes value type, per FMI version.  Binary and Clock
#: variables are not exchanged by the checks (they need sizes or clock semantics).
VALUE_TYPES = {
    2: {"Real": c_double, "Integer": c_int32, "Boolean": c_int, "String": c_char_p, "Enumeration": c_int32},
    3: {"Float64": c_double, "Float32": c_float, "Int8": c_int8, "UInt8": c_uint8, "Int16": c_int16,
        "UInt16": c_uint16, "Int32": c_int32, "UInt32": c_uint32, "Int64": c_int64, "UInt64": c_uint64,
        "Boolean": c_bool, "String": c_char_p, "Enumeration": c_int64},
}
#: The getter/setter suffix of a variable type (FMI 2.0 Enumerations go through Integer, FMI 3.0 through Int64).
ACCESSOR = {2: {"Enumeration": "Integer"}, 3: {"Enumeration": "Int64"}}
#: FMI 3.0 FMU-state functions are spelled "FMUState", FMI 2.0's "FMUstate"; deserialize differs too.
STATE_FUNCTIONS = {
    2: {"get": "fmi2GetFMUstate", "set": "fmi2SetFMUstate", "free": "fmi2FreeFMUstate",
        "size": "fmi2SerializedFMUstateSize", "serialize": "fmi2SerializeFMUstate",
        "deserialize": "fmi2DeSerializeFMUstate"},
    3: {"get": "fmi3GetFMUState", "set": "fmi3SetFMUState", "free": "fmi3FreeFMUState",
        "size": "fmi3SerializedFMUStateSize", "serialize": "fmi3SerializeFMUState",
        "deserialize": "fmi3DeserializeFMUState"},
}


def signatures(version: int) -> dict:
    """{function: [ctypes argument types]} of every function type in fmi<version>FunctionTypes.h
    (a parameter of a type this table does not know is its type's name, a string)."""
    text = (THIRD_PARTY / f"fmi{version}" / f"fmi{version}FunctionTypes.h").read_text()
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    found = {}
    for name, params in re.findall(rf"typedef\s+\w+\s*\*?\s*(fmi{version}\w+)TYPE\s*\(([^;]*?)\)\s*;", text):
        types = []
        for param in (p.strip() for p in params.split(",")):
            if param in ("", "void") or param.startswith("..."):
                continue
            if "*" in param or "[" in param:
                types.append(c_void_p)
                continue
            words = [w for w in param.split() if w != "const"]
            types.append(SCALARS.get(words[0], param))
        found[name] = types
    return found


class Handle(int):
    """An instance pointer: an int to ctypes, hexadecimal in the report."""

    def __repr__(self):
        return f"0x{int(self):x}"


def show(value) -> str:
    """An argument as the report shows it."""
    if value is None:
        return "NULL"
    if isinstance(value, bytes):
        return repr(value.decode("utf-8", "replace")) if len(value) <= 80 else f"<{len(value)} bytes>"
    if isinstance(value, ctypes.Array):
        items = [show(v) for v in value[:6]]
        return "[" + ", ".join(items) + (", ..." if len(value) > 6 else "") + "]"
    if isinstance(value, ctypes._SimpleCData):
        return show(value.value)
    if isinstance(value, (int, float, bool, str)):
        return repr(value)
    referenced = getattr(value, "_obj", None)  # what ctypes.byref points to
    return "&" + type(referenced).__name__ if referenced is not None else type(value).__name__


class Binary:
    """The FMU's shared library for FMI ``version`` (2 or 3), its functions typed, its log kept."""

    def __init__(self, library: Path, version: int, md, resources: Path, trace=lambda text: None):
        self.version, self.md, self.trace = version, md, trace
        self.lib = ctypes.CDLL(str(library))
        self.sig = signatures(version)
        self.resources = resources
        self.log: list[str] = []
        self._functions = {}
        if version == 2:
            from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
            from fmpy.logging import addLoggerProxy

            libc = ctypes.CDLL(None)
            libc.calloc.restype, libc.calloc.argtypes = c_void_p, [c_size_t, c_size_t]
            libc.free.argtypes = [c_void_p]
            self.callbacks = fmi2CallbackFunctions()
            self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log2)
            self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(libc.calloc)
            self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(libc.free)
            addLoggerProxy(byref(self.callbacks))  # formats the variadic arguments before Python sees them
            self.token = md.guid
        else:
            self._logger3 = ctypes.CFUNCTYPE(None, c_void_p, c_int, c_char_p, c_char_p)(self._log3)
            self.token = md.instantiationToken

    def _log2(self, env, name, status, category, message):
        self.log.append((message or b"").decode("utf-8", "replace"))

    def _log3(self, env, status, category, message):
        self.log.append((message or b"").decode("utf-8", "replace"))

    def has(self, name: str) -> bool:
        return hasattr(self.lib, name)

    def function(self, name: str, restype=c_int):
        if name not in self._functions:
            f = self.lib[name]  # a fresh function object: its types are this module's own
            argtypes = self.sig[name]
            unknown = [t for t in argtypes if isinstance(t, str)]
            if unknown:
                raise TypeError(f"{name}: no ctypes type for {unknown}")
            f.argtypes, f.restype = argtypes, restype
            self._functions[name] = f
        return self._functions[name]

    def call(self, name: str, *args, restype=c_int):
        """Call ``name`` with ``args`` after tracing it; returns what it returns."""
        self.trace(f"{name}({', '.join(show(a) for a in args)})")
        return self.function(name, restype)(*args)

    def zero_call(self, inst, name: str):
        """``name`` with every argument after the instance zero or NULL (what a state check sees first)."""
        args = [t() if t is not c_void_p else None for t in self.function(name).argtypes[1:]]
        return self.call(name, inst, *args)

    # ---- life cycle ----------------------------------------------------------------------------
    def instantiate(self, name=b"conformance", token=None, callbacks=True, logger=True):
        """A new instance (None if the FMU refused).  ``callbacks=False``: FMI 2.0 NULL
        ``functions``; ``logger=False``: FMI 3.0 NULL ``logMessage``."""
        token = self.token.encode() if token is None else token
        if self.version == 2:
            uri = self.resources.as_uri().encode()
            return self.handle(self.call("fmi2Instantiate", name, 1, token, uri,
                                         byref(self.callbacks) if callbacks else None, 0, 0, restype=c_void_p))
        path = (str(self.resources) + "/").encode()
        log = ctypes.cast(self._logger3, c_void_p) if logger else None
        return self.handle(self.call("fmi3InstantiateCoSimulation", name, token, path, False, False, False, False,
                                     None, 0, None, log, None, restype=c_void_p))

    @staticmethod
    def handle(pointer):
        """The instance pointer an instantiate function returned (None for NULL)."""
        return None if not pointer else Handle(pointer)

    def free(self, inst):
        self.call(f"fmi{self.version}FreeInstance", inst, restype=None)

    def enter_init(self, inst, start=0.0):
        if self.version == 2:
            return [self.call("fmi2SetupExperiment", inst, 0, 0.0, start, 0, 0.0),
                    self.call("fmi2EnterInitializationMode", inst)]
        return [self.call("fmi3EnterInitializationMode", inst, False, 0.0, start, False, 0.0)]

    def exit_init(self, inst):
        return self.call(f"fmi{self.version}ExitInitializationMode", inst)

    def terminate(self, inst):
        return self.call(f"fmi{self.version}Terminate", inst)

    def reset(self, inst):
        return self.call(f"fmi{self.version}Reset", inst)

    def step(self, inst, t: float, h: float):
        if self.version == 2:
            return self.call("fmi2DoStep", inst, t, h, 1)
        flags = [c_bool() for _ in range(3)]
        last = c_double()
        return self.call("fmi3DoStep", inst, t, h, True, *(byref(f) for f in flags), byref(last))

    # ---- variables -----------------------------------------------------------------------------
    def accessor(self, var_type: str) -> str:
        return ACCESSOR[self.version].get(var_type, var_type)

    def value_type(self, var_type: str):
        return VALUE_TYPES[self.version].get(var_type)

    def get(self, inst, var_type: str, vrs):
        """(status, values) of the variables ``vrs`` of ``var_type``."""
        ctype = self.value_type(var_type)
        refs = (c_uint32 * len(vrs))(*vrs)
        values = (ctype * len(vrs))()
        args = (inst, refs, len(vrs), values) + ((len(vrs),) if self.version == 3 else ())
        status = self.call(f"fmi{self.version}Get{self.accessor(var_type)}", *args)
        return status, list(values)

    def set(self, inst, var_type: str, vrs, values):
        ctype = self.value_type(var_type)
        refs = (c_uint32 * len(vrs))(*vrs)
        array = (ctype * len(vrs))(*values)
        args = (inst, refs, len(vrs), array) + ((len(vrs),) if self.version == 3 else ())
        return self.call(f"fmi{self.version}Set{self.accessor(var_type)}", *args)

    # ---- FMU state ----------------------------------------------------------------------------
    def state_call(self, what: str, *args):
        return self.call(STATE_FUNCTIONS[self.version][what], *args)

    def get_state(self, inst, state=None):
        """(status, state): a new FMU state, or ``state`` updated."""
        state = c_void_p() if state is None else state
        return self.state_call("get", inst, byref(state)), state

    def set_state(self, inst, state):
        return self.state_call("set", inst, state)

    def free_state(self, inst, state):
        return self.state_call("free", inst, byref(state))

    def serialize(self, inst, state):
        """(status, bytes) of ``state``."""
        size = c_size_t()
        status = self.state_call("size", inst, state, byref(size))
        if status != OK:
            return status, b""
        buffer = (c_char * size.value)()
        status = self.state_call("serialize", inst, state, buffer, size.value)
        return status, bytes(buffer)

    def deserialize(self, inst, blob: bytes):
        """(status, state); ``blob`` is copied into a buffer of exactly its length."""
        state = c_void_p()
        buffer = ctypes.create_string_buffer(blob, len(blob)) if blob else (c_char * 1)()
        return self.state_call("deserialize", inst, buffer, len(blob), byref(state)), state

    def messages_since(self, mark: int) -> list[str]:
        return self.log[mark:]

