"""The FMUs a run uses: the given file, or the default one in ``dist/`` built by
``build.py`` when it is missing, older than its sources (a stale FMU would silently
run old code) or on ``--rebuild-fmu``."""
from __future__ import annotations

import importlib.util
import logging
from pathlib import Path
from typing import Callable, Iterable

from fmu_src.avr_errors import AvrError
from scenarios.errors import CosimError

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulator.fmu"
DEFAULT_NATIVE_FMU = REPO_ROOT / "dist" / "AdaptiveVelocityRegulatorNative_fmi2.fmu"
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


def _built(default: Path, sources: Iterable[Path], build: Callable[[object, Path], str], rebuild: bool) -> Path:
    """``default``, (re)built by ``build(build_module, folder)`` when missing, older than
    any of ``sources`` or on ``rebuild``."""
    stale = default.is_file() and max(p.stat().st_mtime for p in sources) > default.stat().st_mtime
    if rebuild or stale or not default.is_file():
        log.info("building %s%s", default, " (older than its sources)" if stale else "")
        default.parent.mkdir(parents=True, exist_ok=True)
        return Path(build(load_build_module(), default.parent))
    return default


def ensure_fmu(fmu: Path | None, *, rebuild: bool = False, native: bool = False) -> Path:
    """The regulator FMU: ``fmu`` if given, else the default one (the pythonfmu FMU, or
    with ``native`` the native FMI 2.0 FMU), built from ``fmu_src/`` and ``build.py``."""
    if fmu is not None:
        fmu = Path(fmu)
        if not fmu.is_file():
            raise AvrError(f"--fmu {fmu}: no such file")
        return fmu
    default = DEFAULT_NATIVE_FMU if native else DEFAULT_FMU
    sources = [p for ext in ("py", "c", "h") for p in (REPO_ROOT / "fmu_src").rglob(f"*.{ext}")]
    build = (lambda b, d: b.build_native_fmu(2, d)) if native else (lambda b, d: b.build_fmu(d))
    return _built(default, sources + [REPO_ROOT / "build.py"], build, rebuild)


def ensure_plant_fmu(fmu: str | Path | None, *, rebuild: bool = False) -> Path:
    """The CassiePlant FMU: ``fmu`` if given, else ``dist/CassiePlant.fmu``, built from
    ``plant/``, ``fmu_src/`` and ``build.py``."""
    if fmu is not None:
        if not Path(fmu).is_file():
            raise CosimError(f"--plant-fmu {fmu}: no such file")
        return Path(fmu)
    sources = [REPO_ROOT / "build.py", *(REPO_ROOT / "plant").rglob("*.py"), *(REPO_ROOT / "plant" / "data").glob("*"),
               *(REPO_ROOT / "fmu_src").rglob("*.py"), *(REPO_ROOT / "fmu_src").rglob("*.c")]
    return _built(DEFAULT_PLANT_FMU, sources, lambda b, d: b.build_plant_fmu(d), rebuild)
