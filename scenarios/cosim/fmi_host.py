"""The FMI co-simulation host under the master: one FMU instance through fmpy.

:class:`FmuInstance` does what every FMU the master runs needs (the regulator FMU in
:mod:`scenarios.cosim.regulators`, FMI 2.0 or 3.0; the CassiePlant FMU in
:mod:`scenarios.cosim.plant_fmu`, FMI 2.0): read the model description, extract into a fresh
folder, instantiate with the process's one logger (the FMU's messages are kept per
instance and go into every error), set values by type, set up the experiment and
enter/exit initialization mode, check every status (anything but OK raises
:class:`CosimError` carrying the FMU's log), and terminate/free/remove the folder in
:meth:`FmuInstance.close` whatever failed. What differs between the FMI versions is in
:mod:`scenarios.cosim.fmi_api`.
"""
from __future__ import annotations

import itertools
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from scenarios.errors import CosimError
from scenarios.cosim.fmi_api import FMI_APIS, FMI_CASTS, route_messages, status_label, unroute_messages

log = logging.getLogger(__name__)

_INSTANCE_IDS = itertools.count(1)


class FmuInstance:
    """One FMI co-simulation FMU instance (see the module docstring)."""

    #: the FMI versions this kind of instance runs
    FMI_VERSIONS: tuple[str, ...] = ("2.0",)

    def __init__(self, fmu_path: str | Path, instance_name: str, *, unpack_dir: str | Path | None = None,
                 fmi_versions: tuple[str, ...] | None = None) -> None:
        """``unpack_dir``: the folder under which the FMU is extracted when it starts (a
        fresh subfolder, removed by :meth:`close`); None: the system temp folder.
        ``fmi_versions``: the FMI versions accepted (default :data:`FMI_VERSIONS`)."""
        from fmpy import read_model_description

        # absolute: fmpy hands the FMU its resources as a file URI, which a relative path has not
        self.fmu_path = Path(fmu_path).absolute()
        if not self.fmu_path.is_file():
            raise CosimError(f"FMU not found: {self.fmu_path}")
        self._number = next(_INSTANCE_IDS)
        self.instance_name = f"{instance_name}-{self._number}"  # unique: log messages are routed by it
        self.md = read_model_description(str(self.fmu_path))
        versions = fmi_versions or self.FMI_VERSIONS
        if self.md.fmiVersion not in versions or self.md.fmiVersion not in FMI_APIS or self.md.coSimulation is None:
            kind = "co-simulation" if self.md.coSimulation is not None else "model exchange only"
            raise CosimError(f"{self.fmu_path}: an FMI {self.md.fmiVersion} FMU ({kind}); this needs an FMI "
                             f"{' or '.join(versions)} co-simulation FMU")
        self.fmi = FMI_APIS[self.md.fmiVersion]
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
        if status:  # None (instantiate) or OK == 0 pass; Warning and worse do not
            raise self._status_error(what, status)
        return status

    def _bound(self, what: str, fn, args: tuple) -> None:
        """A per-step FMI function bound straight to the library (no fmpy wrapper), its status
        checked; a ctypes argument error is a CosimError with the FMU log too."""
        try:
            status = fn(*args)
        except Exception as exc:
            raise self._fail(what, f"{type(exc).__name__}: {exc}") from None
        if status:
            raise self._status_error(what, status)

    def _status_error(self, what: str, status: int) -> CosimError:
        return self._fail(what, f"status {status_label(status)}")

    # ---- life cycle
    def _instantiate(self) -> None:
        """Extract into a fresh folder (ours before anything is extracted: :meth:`close`
        removes it whatever fails next) and instantiate with the shared logger."""
        from fmpy import extract

        # absolute whatever the caller gave: fmpy passes the folder on as a file URI (fmuResourceLocation)
        unpack_dir = None if self._unpack_dir is None else os.path.abspath(self._unpack_dir)
        self._unzip = tempfile.mkdtemp(prefix="fmu-", dir=unpack_dir)
        extract(str(self.fmu_path), self._unzip)
        route_messages(self.instance_name, self._number, self.messages)
        cwd = os.getcwd()
        try:
            self._fmu = self.fmi.slave(self.md, self._unzip, self.instance_name)
        finally:  # fmpy 0.3 changes into binaries/<platform> to load the library and stays there if that fails
            os.chdir(cwd)
        self._call(self.fmi.instantiate_name, self.fmi.instantiate, self._fmu, self._number)
        self._instantiated = True

    def _initialize(self, t0: float, t_stop: float | None) -> None:
        """Set up the experiment (``t_stop`` None: no stop time; no tolerance) and
        enter/exit initialization mode."""
        for what, fn, args in self.fmi.init_calls(self._fmu, t0, t_stop):
            self._call(what, fn, *args)
        self._initialized = True

    def _set(self, what: str, kind: str, vrs: list[int], vals: list[Any]) -> None:
        """One set call of ``kind`` (``Real``, ``Integer``, ``Boolean``) on ``vrs``."""
        if not vrs:
            return
        values = (self.fmi.ctypes[kind] * len(vals))(*(FMI_CASTS[kind](v) for v in vals))
        fn = getattr(self._fmu, self.fmi.function("Set", kind))
        self._call(what, fn, *self.fmi.array_args(self._fmu.component, self._vr_array(vrs), values))

    @staticmethod
    def _vr_array(vrs: list[int]):
        from ctypes import c_uint

        return (c_uint * len(vrs))(*vrs)

    def close(self) -> None:
        fmu = self._fmu
        self._fmu = None
        self._drop_bound_calls()
        try:
            if fmu is not None and self._instantiated:
                if self._initialized:
                    try:
                        getattr(fmu, f"{self.fmi.prefix}Terminate")(fmu.component)
                    except Exception as exc:  # keep freeing: the instance must not leak
                        log.warning("%sTerminate failed: %s", self.fmi.prefix, exc)
                try:
                    fmu.freeInstance()
                except Exception as exc:
                    log.warning("%sFreeInstance failed: %s", self.fmi.prefix, exc)
            elif fmu is not None:  # loaded, not instantiated: unload the library all the same
                fmu.freeLibrary()
        finally:
            self._instantiated = self._initialized = False
            unroute_messages(self.instance_name, self._number, self.messages)
            if self._unzip is not None:
                shutil.rmtree(self._unzip, ignore_errors=True)
                self._unzip = None

    def _drop_bound_calls(self) -> None:
        """Forget anything bound to the FMU's library before it is unloaded (none here)."""
