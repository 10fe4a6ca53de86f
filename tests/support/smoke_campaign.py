"""The smoke campaign (``scenarios/campaigns/smoke.toml``) on a local Dask cluster of 2 workers,
run once per test session through the real CLI (``made_once``) with its defaults (forked
runs): the run that tests/campaign/test_campaign_dask.py checks in full and that the other
campaign modes (``--no-fork-runs``, one worker, an external scheduler) must reproduce row for row. Read only;
a test that writes beside it works in its own folder.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from support.paths import MODEL_ENV, REPO_ROOT
from support.shared import made_once

SMOKE = REPO_ROOT / "scenarios" / "campaigns" / "smoke.toml"
#: The CLI as an interactive shell starts it: SIGINT at its default (a shell's background
#: job, like a test's, would start it with SIGINT ignored).
CLI = [sys.executable, "-c", "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
       "from scenarios.cli import main; sys.exit(main())", "campaign"]
#: Bound of every campaign the tests run; the smoke tasks take ~3 s each on a busy 2-core machine.
WAIT_S = 180.0


def campaign_env(folder: Path) -> dict[str, str]:
    """The CLI's environment: ``TMPDIR`` a folder that must stay empty (it stands for the system
    temp folder), the Menagerie folder the model loader's default gives."""
    systemp = folder / "systemp"
    systemp.mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(systemp), "MENAGERIE_ROOT": MODEL_ENV["MENAGERIE_ROOT"]}


def run_campaign(args, folder: Path, fmu: Path, timeout: float = WAIT_S) -> subprocess.CompletedProcess:
    """``python -m scenarios campaign ARGS --fmu FMU`` from ``folder``."""
    return subprocess.run(CLI + [str(a) for a in args] + ["--fmu", str(fmu)], capture_output=True, text=True,
                          timeout=timeout, env=campaign_env(folder), cwd=folder)


def campaign_in_process(capsys, *args) -> tuple[int, str, str]:
    """``python -m scenarios campaign ARGS`` in this process: (its exit code, stdout, stderr), the
    output captured by pytest's ``capsys``."""
    from scenarios.cli import main as cli_main

    try:
        rc = cli_main(["campaign", *(str(a) for a in args)])
    except SystemExit as exc:
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def smoke_run(tmp_path_factory, fmu: Path) -> tuple[Path, Path, subprocess.CompletedProcess]:
    """(the folder it ran from, its output folder, the finished CLI process) of the session's
    smoke campaign (its defaults, with its plots)."""
    def make(folder: Path):
        out = folder / "out"
        return folder, out, run_campaign([SMOKE, "--out", out, "--workers", 2], folder, fmu)
    return made_once(tmp_path_factory, "smoke_campaign", make)
