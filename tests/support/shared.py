"""Things a test session makes once and every pytest-xdist worker reads: the FMUs build.py
builds, a Wine prefix. The first worker to ask makes it, under a file lock, in a folder of
the session's temporary folder; the others wait on the lock and then read the same folder.
Nothing is shared between sessions (the folder is this session's), nor written to after it is
made: a test that changes an FMU copies it first.
"""
from __future__ import annotations

import fcntl
import os
import pickle
import shutil
from pathlib import Path
from typing import Any, Callable

#: Written last into a shared folder: what ``make`` returned (a folder without it was left
#: half-made by a worker that died, and is made again).
RESULT_NAME = ".made.pickle"


def session_root(tmp_path_factory) -> Path:
    """The folder every worker of this session shares: under pytest-xdist the parent of the
    worker's own base temporary folder (``<basetemp>/popen-gwN``), else the base itself."""
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shared"


def made_once(tmp_path_factory, key: str, make: Callable[[Path], Any]) -> Any:
    """``make(folder)`` run once per test session for ``key`` (a folder name), whichever worker
    asks first; every caller gets what it returned (paths, or a dict of them: picklable)."""
    root = session_root(tmp_path_factory)
    root.mkdir(parents=True, exist_ok=True)
    folder = root / key
    with open(root / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, also if the worker dies
        done = folder / RESULT_NAME
        if not done.is_file():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            made = make(folder)
            tmp = done.with_suffix(".tmp")
            tmp.write_bytes(pickle.dumps(made))
            tmp.rename(done)
        return pickle.loads(done.read_bytes())
