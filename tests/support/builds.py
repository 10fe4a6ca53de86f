"""The FMUs build.py builds, made once per test session (``support.shared.made_once``).

A session whose tests read the whole build (the ``built_all`` fixture: ``build_all``, its FMUs
built in parallel) takes every FMU from that one build, so nothing is compiled twice; a session
that does not (a focused run, e.g. one test file) builds only the FMUs its tests ask for, each
alone.  Which it is is decided once the session has collected its tests (tests/conftest.py).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from support.shared import made_once

#: Whether this session's tests read the whole build (set by tests/conftest.py).
_WHOLE_BUILD = {"used": False}


def use_whole_build(items) -> None:
    """Decide from the collected ``items`` whether the FMUs come from one whole build."""
    _WHOLE_BUILD["used"] = any("built_all" in getattr(item, "fixturenames", ()) for item in items)


def whole_build(tmp_path_factory, build_module) -> tuple[Path, list[Path]]:
    """``build_all`` once per session: its folder and the paths it returned."""
    return made_once(tmp_path_factory, "dist", lambda out: (out, [Path(p) for p in build_module.build_all(out)]))


def built(tmp_path_factory, build_module, key: str, names, make: Callable[[Path], object]):
    """The build products ``names`` (a file name, or {label: file name}) as paths: from the
    session's whole build when it has one, else ``make(folder)`` once per session for ``key``."""
    if _WHOLE_BUILD["used"]:
        dist, _ = whole_build(tmp_path_factory, build_module)
        return {label: dist / name for label, name in names.items()} if isinstance(names, dict) else dist / names
    return made_once(tmp_path_factory, key, make)


def regulator_fmu(tmp_path_factory, build_module) -> Path:
    """``AdaptiveVelocityRegulator.fmu`` (pythonfmu)."""
    return built(tmp_path_factory, build_module, "fmu", f"{build_module.MODEL_IDENTIFIER}.fmu", build_module.build_fmu)


def plant_fmu(tmp_path_factory, build_module) -> Path:
    """``CassiePlant.fmu`` (pythonfmu)."""
    return Path(built(tmp_path_factory, build_module, "plant_fmu", f"{build_module.PLANT_IDENTIFIER}.fmu",
                      build_module.build_plant_fmu))


def by_version(tmp_path_factory, build_module, key: str, name: Callable[[int], str],
               build: Callable[[int, Path], Path]) -> dict[int, Path]:
    """{2: path, 3: path}: one native FMU in both FMI versions."""
    return built(tmp_path_factory, build_module, key, {v: name(v) for v in (2, 3)},
                 lambda out: {v: build(v, out) for v in (2, 3)})


def system(tmp_path_factory, build_module, regulator: Path) -> Path:
    """A folder holding the command source FMU, ``CassieAVR.ssp`` and ``CassieAVR_osp/`` around
    ``regulator`` (build.py's own functions): the whole build's when ``regulator`` is its."""
    if _WHOLE_BUILD["used"]:
        dist, _ = whole_build(tmp_path_factory, build_module)
        if Path(regulator) == dist / f"{build_module.MODEL_IDENTIFIER}.fmu":
            return dist

    def make(out: Path) -> Path:
        plant = plant_fmu(tmp_path_factory, build_module)
        command = build_module.build_command_source(2, out)
        build_module.build_ssp(out, plant, regulator, command)
        build_module.build_osp(out, plant, regulator, command)
        return out
    return made_once(tmp_path_factory, "system", make)
