"""The FMUs build.py builds, made once per test session (``support.shared.made_once``).

A session whose tests read the whole build (the ``built_all`` fixture) takes every FMU from
that one build, so nothing is compiled twice; a session that does not (a focused run, e.g. one
test file) builds only the FMUs its tests ask for, each alone.  Which it is is decided once the
session has collected its tests (tests/conftest.py), which then starts the whole build at once,
``python build.py`` in a process of its own, while the tests that read no build run: the first
test that reads it waits for it on its lock.
"""
from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable

from support.paths import REPO_ROOT
from support.shared import made_once

#: Whether this session's tests read the whole build (set by tests/conftest.py).
_WHOLE_BUILD = {"used": False}
#: The fixture every build product goes through: a test that uses it (directly or through
#: another fixture) reads a build.
BUILD_FIXTURE = "build_module"
#: Bound of one whole build, s (about 25 s on 2 idle cores).
BUILD_TIMEOUT_S = 1800
#: The build process running now, if any (stopped when the session ends: stop_whole_build).
_RUNNING: dict[str, subprocess.Popen] = {}


def use_whole_build(items) -> bool:
    """Decide from the collected ``items`` whether the FMUs come from one whole build."""
    _WHOLE_BUILD["used"] = any("built_all" in getattr(item, "fixturenames", ()) for item in items)
    return _WHOLE_BUILD["used"]


def whole_build(tmp_path_factory) -> tuple[Path, list[Path]]:
    """``python build.py --out FOLDER`` once per session: the folder and the paths build_all
    returned (the lines build.py prints).  In a process of its own: pythonfmu's builder changes
    ``sys.path``, which must not happen under a test running beside it."""
    return made_once(tmp_path_factory, "dist", _build_all)


def _build_all(out: Path) -> tuple[Path, list[Path]]:
    proc = subprocess.Popen([sys.executable, str(REPO_ROOT / "build.py"), "--out", str(out)], cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _RUNNING["build"] = proc
    try:
        stdout, stderr = proc.communicate(timeout=BUILD_TIMEOUT_S)
    finally:
        _RUNNING.pop("build", None)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if proc.returncode != 0:
        raise RuntimeError(f"python build.py --out {out}: exit {proc.returncode}\n{stderr[-4000:]}")
    return out, [Path(line) for line in stdout.splitlines() if not line.startswith("sha256 ")]


def start_whole_build(tmp_path_factory) -> None:
    """Make the whole build in a background thread (one worker's builds, the others' wait on
    the lock).  A failure is left to the first test that reads the build: it builds again, under
    the lock, and reports it."""
    def run():
        try:
            whole_build(tmp_path_factory)
        except Exception:  # noqa: BLE001 - reported by the test that reads the build
            pass
    threading.Thread(target=run, name="whole-build", daemon=True).start()


def stop_whole_build() -> None:
    """Stop a build still running when the session ends (it was interrupted)."""
    proc = _RUNNING.get("build")
    if proc is not None and proc.poll() is None:
        proc.kill()


def built(tmp_path_factory, build_module, key: str, names, make: Callable[[Path], object]):
    """The build products ``names`` (a file name, or {label: file name}) as paths: from the
    session's whole build when it has one, else ``make(folder)`` once per session for ``key``."""
    if _WHOLE_BUILD["used"]:
        dist, _ = whole_build(tmp_path_factory)
        return {label: dist / name for label, name in names.items()} if isinstance(names, dict) else dist / names
    return made_once(tmp_path_factory, key, make)


def _fresh(function: str) -> Callable[[Path], Path]:
    """``make(folder)``: build.py's ``function`` into ``folder`` in a process of its own, as the CLI
    builds a default FMU (a test worker may have loaded a pythonfmu FMU in process, and then
    cannot build one)."""
    from scenarios.cosim.fmus import build_in_own_process

    return lambda out: build_in_own_process((function,), out)


def regulator_fmu(tmp_path_factory, build_module) -> Path:
    """``AdaptiveVelocityRegulator.fmu`` (pythonfmu)."""
    return built(tmp_path_factory, build_module, "fmu", f"{build_module.MODEL_IDENTIFIER}.fmu", _fresh("build_fmu"))


def plant_fmu(tmp_path_factory, build_module) -> Path:
    """``CassiePlant.fmu`` (pythonfmu)."""
    return Path(built(tmp_path_factory, build_module, "plant_fmu", f"{build_module.PLANT_IDENTIFIER}.fmu",
                      _fresh("build_plant_fmu")))


def by_version(tmp_path_factory, build_module, key: str, name: Callable[[int], str],
               build: Callable[[int, Path], Path]) -> dict[int, Path]:
    """{2: path, 3: path}: one native FMU in both FMI versions."""
    return built(tmp_path_factory, build_module, key, {v: name(v) for v in (2, 3)},
                 lambda out: {v: build(v, out) for v in (2, 3)})


def system(tmp_path_factory, build_module, regulator: Path) -> Path:
    """A folder holding the command source FMU, ``CassieAVR.ssp`` and ``CassieAVR_osp/`` around
    ``regulator`` (build.py's own functions): the whole build's when ``regulator`` is its."""
    if _WHOLE_BUILD["used"]:
        dist, _ = whole_build(tmp_path_factory)
        if Path(regulator) == dist / f"{build_module.MODEL_IDENTIFIER}.fmu":
            return dist

    def make(out: Path) -> Path:
        plant = plant_fmu(tmp_path_factory, build_module)
        command = build_module.build_command_source(2, out)
        build_module.build_ssp(out, plant, regulator, command)
        build_module.build_osp(out, plant, regulator, command)
        return out
    return made_once(tmp_path_factory, "system", make)
