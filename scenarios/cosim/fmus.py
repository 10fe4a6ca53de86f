"""The FMUs a run uses: the given file, or the default one in ``dist/`` built by
``build.py`` when it is missing, older than its sources (a stale FMU would silently
run old code) or on ``--rebuild-fmu``.  The build runs in a process of its own: pythonfmu's
builder changes ``sys.path`` and ``sys.modules``, and a process that has loaded a pythonfmu FMU
holds that FMU's copy of pythonfmu, which cannot build one."""
from __future__ import annotations

import importlib.util
import logging
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from fmu_src.core.avr_errors import AvrError
from scenarios.errors import CosimError

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulator.fmu"
DEFAULT_NATIVE_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulatorNative_fmi2.fmu"
DEFAULT_NATIVE3_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulatorNative_fmi3.fmu"
DEFAULT_PLANT_FMU = REPO_ROOT / "dist" / "CassiePlant.fmu"

log = logging.getLogger(__name__)


def load_build_module():
    """``build.py`` at the repo root (not ``import build``: PyPA's package clashes)."""
    path = REPO_ROOT / "build.py"
    if not path.is_file():
        raise AvrError(f"cannot build the FMU: {path} does not exist")
    spec = importlib.util.spec_from_file_location("avr_build", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: Runs ``build.py``'s function ``argv[1]`` with the integer arguments ``argv[3:]`` into the folder
#: ``argv[2]`` and prints the path it returns.
_BUILD_SCRIPT = ("import sys\nfrom pathlib import Path\nfrom scenarios.cosim.fmus import load_build_module\n"
                 "print(getattr(load_build_module(), sys.argv[1])(*map(int, sys.argv[3:]), out_dir=Path(sys.argv[2])))\n")


def build_in_own_process(build: tuple, folder: Path) -> Path:
    """``build.py``'s function ``build[0]`` with the arguments ``build[1:]``, building into ``folder``
    in a process of its own; the path it returned.  AvrError with the build's last words if it fails."""
    name, *args = build
    proc = subprocess.run([sys.executable, "-c", _BUILD_SCRIPT, name, str(folder), *map(str, args)],
                          cwd=REPO_ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise AvrError(f"build.py's {name}{tuple(args) if args else '()'} failed (exit {proc.returncode}):\n"
                       f"{proc.stderr[-3000:]}")
    return Path(proc.stdout.strip().splitlines()[-1])


def _built(default: Path, sources: Iterable[Path], build: tuple, rebuild: bool) -> Path:
    """``default``, (re)built by :func:`build_in_own_process` (``build``: build.py's function and
    its arguments) when missing, older than any of ``sources`` or on ``rebuild``."""
    stale = default.is_file() and max(p.stat().st_mtime for p in sources) > default.stat().st_mtime
    if rebuild or stale or not default.is_file():
        log.info("building %s%s", default, " (older than its sources)" if stale else "")
        default.parent.mkdir(parents=True, exist_ok=True)
        return build_in_own_process(build, default.parent)
    return default


@dataclass(frozen=True)
class RegulatorFmu:
    """A ``--regulator`` that runs an FMU: its default file (the module constant named
    ``default_name``), the FMI version it runs and how ``build.py`` builds that file (``build``:
    the function's name and its arguments before the output folder)."""

    default_name: str
    fmi_version: str
    build: tuple
    help: str

    @property
    def default(self) -> Path:
        return globals()[self.default_name]  # looked up when asked: tests point the constant elsewhere


#: The ``--regulator`` choices that run an FMU through fmpy (``inprocess`` runs the core).
REGULATOR_FMUS: dict[str, RegulatorFmu] = {
    "fmu": RegulatorFmu("DEFAULT_FMU", "2.0", ("build_fmu",),
                        "the pythonfmu FMU (FMI 2.0) through fmpy's FMU2Slave"),
    "native": RegulatorFmu("DEFAULT_NATIVE_FMU", "2.0", ("build_native_fmu", 2),
                           "the native (C) FMI 2.0 FMU through fmpy's FMU2Slave"),
    "native-fmi3": RegulatorFmu("DEFAULT_NATIVE3_FMU", "3.0", ("build_native_fmu", 3),
                                "the native (C) FMI 3.0 FMU through fmpy's FMU3Slave"),
}


def fmu_version_problem(regulator: str, fmu: Path) -> str | None:
    """What is wrong with running ``fmu`` as ``--regulator regulator`` (its FMI version), or None."""
    from fmpy import read_model_description

    want = REGULATOR_FMUS[regulator].fmi_version
    try:
        have = read_model_description(str(fmu)).fmiVersion
    except Exception as exc:
        return f"--fmu {fmu}: not a readable FMU ({type(exc).__name__}: {exc})"
    if have != want:
        others = [k for k, r in REGULATOR_FMUS.items() if r.fmi_version == have]
        hint = f" (use --regulator {' or '.join(others)})" if others else ""
        return f"--fmu {fmu}: an FMI {have} FMU; --regulator {regulator} runs FMI {want} FMUs{hint}"
    return None


def regulator_kind(fmu: Path, default: str) -> str:
    """The ``--regulator`` that runs the regulator FMU file ``fmu``: ``native-fmi3`` for an FMI 3.0
    FMU, ``fmu`` for a pythonfmu one (its generationTool), else ``native``; ``default`` when the
    file cannot be read (the options' checks then say why)."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(fmu))
    except Exception:
        return default
    if md.fmiVersion.startswith("3"):
        return "native-fmi3"
    return "fmu" if (md.generationTool or "").startswith("PythonFMU") else "native"


def _role_variables(role: str) -> tuple[str, dict[str, tuple[str, ...]]]:
    """(what the role is, in words; the variables by causality the master sets or reads)."""
    if role == "plant":
        from fmu_src.plant_fmu import fmu_core

        return "the CassiePlant FMU", {"input": fmu_core.INPUT_NAMES,
                                      "output": tuple(s.name for s in fmu_core.OUTPUT_SPECS)}
    from fmu_src.core.avr_specs import INPUT_SPECS
    from plant.constants import OFFSET_NAMES

    return "a regulator FMU (AdaptiveVelocityRegulator)", {"input": tuple(s.name for s in INPUT_SPECS),
                                                           "output": tuple(OFFSET_NAMES)}


def fmu_file_problem(flag: str, fmu: Path | None, role: str | None = None) -> str | None:
    """What is wrong with the FMU file given as ``flag`` (None: not given, nothing): missing, a
    folder, unreadable, or (with ``role``) not a model for that role (:func:`fmu_role_problem`)."""
    if fmu is None:
        return None
    if Path(fmu).is_dir():
        return f"{flag} {fmu}: is a folder, not an FMU file"
    if not Path(fmu).is_file():
        return f"{flag} {fmu}: no such file"
    if role is not None:
        return fmu_role_problem(flag, Path(fmu), role)
    from fmpy import read_model_description

    try:
        read_model_description(str(fmu))
    except Exception as exc:
        return f"{flag} {fmu}: not a readable FMU ({type(exc).__name__}: {exc})"
    return None


def fmu_role_problem(flag: str, fmu: Path, role: str) -> str | None:
    """What is wrong with running ``fmu`` (given as ``flag``) as the ``role`` (``regulator``
    or ``plant``): an unreadable file, or a model without the inputs and outputs the
    master sets and reads for that role (e.g. a CassiePlant FMU given as the regulator)."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(fmu))
    except Exception as exc:
        return f"{flag} {fmu}: not a readable FMU ({type(exc).__name__}: {exc})"
    what, needed = _role_variables(role)
    have = {(v.causality, v.name) for v in md.modelVariables}
    missing = [f"{c} {n}" for c, names in needed.items() for n in names if (c, n) not in have]
    if not missing:
        return None
    other = {"regulator": " (a CassiePlant FMU goes to --plant-fmu)",
             "plant": " (a regulator FMU goes to --fmu)"}[role]
    shown = ", ".join(missing[:4]) + (f" and {len(missing) - 4} more" if len(missing) > 4 else "")
    return (f"{flag} {fmu}: model {md.modelName!r} is not {what}: it has no {shown}; {flag} takes {what}{other}")


def ensure_fmu(fmu: Path | None, *, rebuild: bool = False, regulator: str = "fmu") -> Path:
    """The regulator FMU of ``--regulator regulator`` (:data:`REGULATOR_FMUS`): ``fmu`` if
    given, else its default file in ``dist/``, built from ``fmu_src/`` and ``build.py``."""
    if fmu is not None:
        fmu = Path(fmu)
        if not fmu.is_file():
            raise AvrError(f"--fmu {fmu}: no such file")
        return fmu
    kind = REGULATOR_FMUS[regulator]
    sources = [p for ext in ("py", "c", "h") for p in (REPO_ROOT / "fmu_src").rglob(f"*.{ext}")]
    # docs/method.md: every regulator FMU's documentation page renders it
    return _built(kind.default, sources + [REPO_ROOT / "build.py", REPO_ROOT / "docs" / "method.md"], kind.build, rebuild)


def ensure_plant_fmu(fmu: str | Path | None, *, rebuild: bool = False) -> Path:
    """The CassiePlant FMU: ``fmu`` if given, else ``dist/CassiePlant.fmu``, built from
    ``plant/``, ``fmu_src/`` and ``build.py``."""
    if fmu is not None:
        if not Path(fmu).is_file():
            raise CosimError(f"--plant-fmu {fmu}: no such file")
        return Path(fmu)
    sources = [REPO_ROOT / "build.py", *(REPO_ROOT / "plant").rglob("*.py"), *(REPO_ROOT / "plant" / "data").glob("*"),
               *(REPO_ROOT / "fmu_src").rglob("*.py"), *(REPO_ROOT / "fmu_src").rglob("*.c")]
    return _built(DEFAULT_PLANT_FMU, sources, ("build_plant_fmu",), rebuild)
