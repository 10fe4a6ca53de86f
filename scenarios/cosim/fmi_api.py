"""What differs between FMI 2.0 and FMI 3.0 co-simulation for the master's host
(:class:`scenarios.cosim.fmi_host.FmuInstance`), and the process's one FMU logger.

One object per FMI version (:data:`FMI_APIS`, by the model description's
``fmiVersion``) says: fmpy's slave class (``FMU2Slave``/``FMU3Slave``), how an instance
is created with the shared logger, the calls that set up the experiment and enter/exit
initialization mode, the names and ctypes of the variable types the host uses, the
array functions (FMI 3.0's take ``nValues`` too) and the doStep function with what it
reports beyond its status (FMI 3.0's out-pointers). The host speaks FMI 2.0's type names
as its vocabulary (``Real``, ``Integer``, ``Boolean``); FMI 3.0's ``Float64``,
``Int32`` and ``Boolean`` map onto them, and variables of other types (FMI 3.0's
independent ``time`` among them, being no input, output or parameter) are never set or
read.
"""
from __future__ import annotations

import logging
import math
import os
from ctypes import CFUNCTYPE, POINTER, byref, c_bool, c_double, c_int, c_int32, c_size_t, c_uint, c_void_p
from typing import Any, Callable

from fmu_src.core.avr_specs import PYTHON_TYPES

log = logging.getLogger("scenarios.cosim.fmi_host")

FMI_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
#: Python type of each of the host's variable kinds (values set by name are cast to it).
#: Python cast per FMI 2.0 type name: the slave's own table (``fmu_src.core.avr_specs``).
FMI_CASTS: dict[str, Callable[[Any], Any]] = PYTHON_TYPES
#: How many of an instance's latest messages are kept for its errors.
LOG_KEEP = 200

# fmpy's native logger proxy (which formats FMI 2.0 FMUs' printf-style messages) keeps ONE
# process-wide pointer to the Python logger it forwards to, whichever callbacks struct
# was registered last; a per-instance logger that is garbage-collected leaves it dangling
# and the next FMU message from any instance crashes the process.  So there is one
# logger per FMI version for the whole process, alive as long as the module, routing
# messages by instance (FMI 2.0: its name; FMI 3.0: its instanceEnvironment, the
# instance's number); instances it does not know are logged here.
_LOG_ROUTES: dict[str, list[str]] = {}
_ENVIRONMENTS: dict[int, str] = {}  # FMI 3.0 instanceEnvironment -> instance name
_SHARED: dict[str, Any] = {}


def status_label(status: int) -> str:
    return FMI_STATUS[status] if 0 <= status < len(FMI_STATUS) else str(status)


def _text(value) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _route_fmu_message(component, instance_name, status, category, message) -> None:
    """The FMI 2.0 logger (and, by name, the FMI 3.0 one): keep the message for its instance."""
    name, text, cat = _text(instance_name), _text(message), _text(category)
    messages = _LOG_ROUTES.get(name)
    if messages is None:
        log.info("[%s] %s %s: %s", status_label(status), name, cat, text)
        return
    messages.append(f"[{status_label(status)}] {cat}: {text}")
    del messages[:-LOG_KEEP]


def _route_fmi3_message(environment, status, category, message) -> None:
    name = _ENVIRONMENTS.get(environment or 0, f"(instanceEnvironment {environment})")
    _route_fmu_message(None, name, status, category, message)


def route_messages(instance_name: str, number: int, messages: list[str]) -> None:
    """Keep the messages of instance ``instance_name`` (number ``number``) in ``messages``."""
    _LOG_ROUTES[instance_name] = messages
    _ENVIRONMENTS[number] = instance_name


def unroute_messages(instance_name: str, number: int, messages: list[str]) -> None:
    if _LOG_ROUTES.get(instance_name) is messages:
        del _LOG_ROUTES[instance_name]
        _ENVIRONMENTS.pop(number, None)


class FmiApi:
    """The version-specific part of the host (see the module docstring)."""

    version = ""
    prefix = ""
    instantiate_name = ""
    #: the host's kinds -> this version's type names, and their ctypes
    type_names: dict[str, str] = {}
    ctypes: dict[str, Any] = {}
    #: array functions take ``nValues`` after the values (FMI 3.0)
    sized = False

    def kind_of(self, type_name: str) -> str | None:
        """The host's kind (``Real``, ``Integer``, ``Boolean``) of a variable type, or None."""
        return next((k for k, t in self.type_names.items() if t == type_name), None)

    def function(self, op: str, kind: str) -> str:
        """The FMI function that gets (``op`` = "Get") or sets values of ``kind``."""
        return f"{self.prefix}{op}{self.type_names[kind]}"

    def array_args(self, component, vrs, values) -> tuple:
        """The arguments of an array function on the arrays ``vrs`` and ``values``."""
        return (component, vrs, len(vrs), values) + ((len(values),) if self.sized else ())

    def array_function(self, dll, op: str, kind: str):
        """:meth:`function` as a ctypes prototype on ``dll`` (for the per-step calls)."""
        extra = (c_size_t,) if self.sized else ()
        proto = CFUNCTYPE(c_int, c_void_p, POINTER(c_uint), c_size_t, POINTER(self.ctypes[kind]), *extra)
        return proto((self.function(op, kind), dll))

    def slave(self, md, unzip: str, instance_name: str):
        raise NotImplementedError

    def instantiate(self, fmu, number: int) -> None:
        """Create the instance with the shared logger; raise if the FMU returns NULL."""
        raise NotImplementedError

    def init_calls(self, fmu, t0: float, t_stop: float | None) -> list[tuple[str, Callable, tuple]]:
        """``(name, function, args)`` of the calls from instantiated to step mode."""
        raise NotImplementedError

    def bind_do_step(self, dll) -> tuple[Callable, tuple, Callable[[float, float], str | None] | None]:
        """doStep as a ctypes prototype, the arguments after ``(instance, t, h)``, and a
        check of what it reported beyond its status (None: nothing to check), which
        returns what is wrong or None."""
        raise NotImplementedError


class Fmi2Api(FmiApi):
    version, prefix, instantiate_name = "2.0", "fmi2", "fmi2Instantiate"
    type_names = {"Real": "Real", "Integer": "Integer", "Boolean": "Boolean"}
    ctypes = {"Real": c_double, "Integer": c_int, "Boolean": c_int}

    def slave(self, md, unzip: str, instance_name: str):
        from fmpy.fmi2 import FMU2Slave

        return FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                         instanceName=instance_name)

    def instantiate(self, fmu, number: int) -> None:
        fmu.instantiate(callbacks=_fmi2_callbacks(), loggingOn=True)

    def init_calls(self, fmu, t0, t_stop):
        comp, defined = fmu.component, t_stop is not None
        return [("fmi2SetupExperiment", fmu.fmi2SetupExperiment,
                 (comp, 0, 0.0, float(t0), int(defined), float(t_stop) if defined else 0.0)),
                ("fmi2EnterInitializationMode", fmu.fmi2EnterInitializationMode, (comp,)),
                ("fmi2ExitInitializationMode", fmu.fmi2ExitInitializationMode, (comp,))]

    def bind_do_step(self, dll):
        do_step = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_int)(("fmi2DoStep", dll))
        return do_step, (1,), None  # noSetFMUStatePriorToCurrentPoint = fmi2True


class Fmi3Api(FmiApi):
    version, prefix, instantiate_name = "3.0", "fmi3", "fmi3InstantiateCoSimulation"
    type_names = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
    ctypes = {"Real": c_double, "Integer": c_int32, "Boolean": c_bool}
    sized = True

    def slave(self, md, unzip: str, instance_name: str):
        from fmpy.fmi3 import FMU3Slave

        return FMU3Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                         instanceName=instance_name)

    def instantiate(self, fmu, number: int) -> None:
        """fmi3InstantiateCoSimulation without event mode, early return or intermediate
        variables; the instance's number is its instanceEnvironment (for the logger)."""
        from fmpy.fmi3 import fmi3IntermediateUpdateCallback, fmi3ValueReference

        resources = os.path.join(fmu.unzipDirectory, "resources") + os.sep
        fmu.component = fmu.fmi3InstantiateCoSimulation(
            fmu.instanceName.encode("utf-8"), fmu.guid.encode("utf-8"), resources.encode("utf-8"),
            False, True, False, False, (fmi3ValueReference * 0)(), 0, c_void_p(number), _fmi3_logger(),
            fmi3IntermediateUpdateCallback())
        if not fmu.component:
            raise RuntimeError("the FMU returned NULL")

    def init_calls(self, fmu, t0, t_stop):
        comp, defined = fmu.component, t_stop is not None
        return [("fmi3EnterInitializationMode", fmu.fmi3EnterInitializationMode,
                 (comp, False, 0.0, float(t0), defined, float(t_stop) if defined else 0.0)),
                ("fmi3ExitInitializationMode", fmu.fmi3ExitInitializationMode, (comp,))]

    def bind_do_step(self, dll):
        flag = POINTER(c_bool)
        do_step = CFUNCTYPE(c_int, c_void_p, c_double, c_double, c_bool, flag, flag, flag,
                            POINTER(c_double))(("fmi3DoStep", dll))
        event, terminate, early, last = c_bool(), c_bool(), c_bool(), c_double()

        def check(t: float, h: float) -> str | None:
            return fmi3_step_problem(t, h, event.value, terminate.value, early.value, last.value)

        return do_step, (True, byref(event), byref(terminate), byref(early), byref(last)), check


def fmi3_step_problem(t: float, h: float, event_handling_needed: bool, terminate_simulation: bool,
                      early_return: bool, last_successful_time: float) -> str | None:
    """What is wrong with what fmi3DoStep from ``t`` by ``h`` reported (status OK), or None.

    Instantiated without event mode and without early return, a step must end at
    ``t + h`` (to the FMUs' own match of communication points: 1e-9 relative, at least
    1e-9 s) and the FMU must not ask to terminate; ``eventHandlingNeeded`` then only says
    that the FMU handled an event inside the step (FMI 3.0: the importer ignores it
    without event mode)."""
    if terminate_simulation:
        return f"the FMU asked to terminate the simulation (terminateSimulation) at t = {last_successful_time!r} s"
    if early_return:
        return f"early return at t = {last_successful_time!r} s, though earlyReturnAllowed = false"
    end = t + h
    if not math.isclose(last_successful_time, end, rel_tol=0.0, abs_tol=1e-9 * max(1.0, abs(end))):
        return f"lastSuccessfulTime = {last_successful_time!r} s, not the step's end {end!r} s"
    if event_handling_needed:
        log.debug("fmi3DoStep at t = %r s: the FMU handled an event inside the step", t)
    return None


FMI_APIS: dict[str, FmiApi] = {api.version: api for api in (Fmi2Api(), Fmi3Api())}


def _fmi2_callbacks():
    """The process-lifetime fmi2CallbackFunctions with the routing logger.

    fmpy's logger proxy (which formats the variadic arguments in C) forwards to one Python
    logger per process, the one registered last: each new instance registers ours again, so
    another user of the proxy in the process (a test host, say) cannot take our messages."""
    from fmpy.fmi2 import fmi2CallbackLoggerTYPE

    if "2.0" not in _SHARED:
        from fmpy import calloc, free
        from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions

        callbacks = fmi2CallbackFunctions()
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        _SHARED["2.0"] = callbacks
        _SHARED["2.0 logger"] = fmi2CallbackLoggerTYPE(_route_fmu_message)
    callbacks = _SHARED["2.0"]
    callbacks.logger = _SHARED["2.0 logger"]
    try:
        from fmpy.logging import addLoggerProxy

        addLoggerProxy(byref(callbacks))
    except Exception as exc:  # pragma: no cover - fmpy's native proxy is optional
        log.warning("fmpy logger proxy unavailable (%s): FMU messages are not formatted", exc)
    return callbacks


def _fmi3_logger():
    """The process-lifetime fmi3LogMessageCallback (FMI 3.0 messages are plain text)."""
    if "3.0" not in _SHARED:
        from fmpy.fmi3 import fmi3LogMessageCallback

        _SHARED["3.0"] = fmi3LogMessageCallback(_route_fmi3_message)
    return _SHARED["3.0"]
