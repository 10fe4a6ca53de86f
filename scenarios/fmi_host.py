"""The FMI 2.0 co-simulation host under the master: one FMU instance through fmpy.

:class:`FmuInstance` does what every FMU the master runs needs (the regulator FMU in
:mod:`scenarios.regulators`, the CassiePlant FMU in :mod:`scenarios.plant_fmu`): read the
model description, extract into a fresh folder, instantiate with the process's one
logger (the FMU's messages are kept per instance and go into every error), set
parameters, set up the experiment and enter/exit initialization mode, check every
status (anything but OK raises :class:`CosimError` carrying the FMU's log), and
terminate/free/remove the folder in :meth:`FmuInstance.close` whatever failed.
"""
from __future__ import annotations

import itertools
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from scenarios.errors import CosimError

log = logging.getLogger(__name__)

FMI_STATUS = ("OK", "Warning", "Discard", "Error", "Fatal", "Pending")
#: Python type of each FMI 2.0 variable type (values set by name are cast to it).
FMI_CASTS: dict[str, Callable[[Any], Any]] = {"Real": float, "Integer": int, "Boolean": bool}
#: How many of an instance's latest messages are kept for its errors.
LOG_KEEP = 200

# fmpy's native logger proxy (which formats the FMU's printf-style messages) keeps ONE
# process-wide pointer to the Python logger it forwards to, whichever callbacks struct
# was registered last; a per-instance logger that is garbage-collected leaves it dangling
# and the next FMU message from any instance crashes the process.  So there is one
# logger for the whole process, alive as long as the module, routing messages by
# instance name; names it does not know are printed as fmpy's default logger does.
_LOG_ROUTES: dict[str, list[str]] = {}
_INSTANCE_IDS = itertools.count(1)
_SHARED_CALLBACKS = None


def _route_fmu_message(component, instance_name, status, category, message) -> None:
    label = FMI_STATUS[status] if 0 <= status < len(FMI_STATUS) else str(status)
    name = instance_name.decode("utf-8", "replace") if isinstance(instance_name, bytes) else str(instance_name)
    text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
    cat = category.decode("utf-8", "replace") if isinstance(category, bytes) else str(category)
    messages = _LOG_ROUTES.get(name)
    if messages is None:
        log.info("[%s] %s %s: %s", label, name, cat, text)
        return
    messages.append(f"[{label}] {cat}: {text}")
    del messages[:-LOG_KEEP]


def _shared_callbacks():
    """The process-lifetime fmi2CallbackFunctions with the routing logger."""
    global _SHARED_CALLBACKS
    if _SHARED_CALLBACKS is None:
        from ctypes import byref

        from fmpy import calloc, free
        from fmpy.fmi2 import (fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                               fmi2CallbackLoggerTYPE)

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(_route_fmu_message)
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy

            addLoggerProxy(byref(callbacks))
        except Exception as exc:  # pragma: no cover - fmpy's native proxy is optional
            log.warning("fmpy logger proxy unavailable (%s): FMU messages are not formatted", exc)
        _SHARED_CALLBACKS = callbacks
    return _SHARED_CALLBACKS


def status_label(status: int) -> str:
    return FMI_STATUS[status] if 0 <= status < len(FMI_STATUS) else str(status)


class FmuInstance:
    """One FMI 2.0 co-simulation FMU instance (see the module docstring)."""

    def __init__(self, fmu_path: str | Path, instance_name: str, *, unpack_dir: str | Path | None = None) -> None:
        """``unpack_dir``: the folder under which the FMU is extracted when it starts (a
        fresh subfolder, removed by :meth:`close`); None: the system temp folder."""
        from fmpy import read_model_description

        self.fmu_path = Path(fmu_path)
        if not self.fmu_path.is_file():
            raise CosimError(f"FMU not found: {self.fmu_path}")
        self.instance_name = f"{instance_name}-{next(_INSTANCE_IDS)}"  # unique: log messages are routed by it
        self.md = read_model_description(str(self.fmu_path))
        if self.md.fmiVersion != "2.0" or self.md.coSimulation is None:
            raise CosimError(f"{self.fmu_path}: not an FMI 2.0 co-simulation FMU")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.messages: list[str] = []
        self._fmu = None
        self._unpack_dir = unpack_dir
        self._unzip: str | None = None
        self._instantiated = False
        self._initialized = False
        self._t: float | None = None  # the communication point being computed (for messages)

    # ---- logging and status
    def log_text(self) -> str:
        return "\n".join(self.messages) if self.messages else "(the FMU logged nothing)"

    def _fail(self, what: str, detail: str) -> CosimError:
        if self._t is not None:
            what = f"{what} at t = {self._t!r} s"
        return CosimError(f"{what} failed: {detail}\nFMU log ({self.fmu_path.name}):\n{self.log_text()}")

    def _call(self, what: str, fn, *args):
        from fmpy.fmi1 import FMICallException

        try:
            status = fn(*args)
        except FMICallException as exc:
            raise self._fail(what, str(exc)) from None
        except CosimError:
            raise
        except Exception as exc:  # instantiate raises a bare Exception on NULL
            raise self._fail(what, f"{type(exc).__name__}: {exc}") from None
        if status:  # None (instantiate) or fmi2OK == 0 pass; Warning and worse do not
            raise self._status_error(what, status)
        return status

    def _status_error(self, what: str, status: int) -> CosimError:
        return self._fail(what, f"status {status_label(status)}")

    # ---- life cycle
    def _instantiate(self) -> None:
        """Extract into a fresh folder (ours before anything is extracted: :meth:`close`
        removes it whatever fails next) and instantiate with the shared logger."""
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        self._unzip = tempfile.mkdtemp(prefix="fmu-", dir=self._unpack_dir)
        extract(str(self.fmu_path), self._unzip)
        self._callbacks = _shared_callbacks()
        _LOG_ROUTES[self.instance_name] = self.messages
        cwd = os.getcwd()
        try:
            self._fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._unzip,
                                  modelIdentifier=self.md.coSimulation.modelIdentifier,
                                  instanceName=self.instance_name)
        finally:  # fmpy 0.3 changes into binaries/<platform> to load the library and stays there if that fails
            os.chdir(cwd)
        self._call("fmi2Instantiate", lambda: self._fmu.instantiate(callbacks=self._callbacks, loggingOn=True))
        self._instantiated = True

    def _initialize(self, t0: float, t_stop: float | None) -> None:
        """fmi2SetupExperiment (``t_stop`` None: no stop time) and enter/exit initialization."""
        fmu, comp = self._fmu, self._fmu.component
        stop_defined = t_stop is not None
        self._call("fmi2SetupExperiment", fmu.fmi2SetupExperiment, comp, 0, 0.0, float(t0), int(stop_defined),
                   float(t_stop) if stop_defined else 0.0)
        self._call("fmi2EnterInitializationMode", fmu.fmi2EnterInitializationMode, comp)
        self._call("fmi2ExitInitializationMode", fmu.fmi2ExitInitializationMode, comp)
        self._initialized = True

    @staticmethod
    def _vr_array(vrs: list[int]):
        from fmpy.fmi2 import fmi2ValueReference

        return (fmi2ValueReference * len(vrs))(*vrs)

    def close(self) -> None:
        fmu = self._fmu
        self._fmu = None
        self._drop_bound_calls()
        try:
            if fmu is not None and self._instantiated:
                if self._initialized:
                    try:
                        fmu.fmi2Terminate(fmu.component)
                    except Exception as exc:  # keep freeing: the instance must not leak
                        log.warning("fmi2Terminate failed: %s", exc)
                try:
                    fmu.freeInstance()
                except Exception as exc:
                    log.warning("fmi2FreeInstance failed: %s", exc)
        finally:
            self._instantiated = self._initialized = False
            if _LOG_ROUTES.get(self.instance_name) is self.messages:
                del _LOG_ROUTES[self.instance_name]
            if self._unzip is not None:
                shutil.rmtree(self._unzip, ignore_errors=True)
                self._unzip = None

    def _drop_bound_calls(self) -> None:
        """Forget anything bound to the FMU's library before it is unloaded (none here)."""
