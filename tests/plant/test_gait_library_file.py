"""The gait library is read once, with its module, and a missing or broken one is an error naming
the file, never a fallback to the uncalibrated gait (issue 44).

The plant package is copied into ``tmp_path`` and imported from there in a fresh process, so the
test can delete or break its data file as a host deletes an FMU's extraction folder.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from plant.errors import GaitLibraryError
from plant.gaits import DEFAULT_LIBRARY_PATH, GaitLibrary
from support.paths import REPO_ROOT

PROBE = """
import json, os, sys
from pathlib import Path
from plant.gaits import DEFAULT_LIBRARY_PATH, GaitLibrary
assert Path(DEFAULT_LIBRARY_PATH).is_relative_to(Path.cwd()), DEFAULT_LIBRARY_PATH  # the copy, not the checkout
if sys.argv[1] == "delete":
    os.remove(DEFAULT_LIBRARY_PATH)
try:
    lib = GaitLibrary.default()
except Exception as exc:
    print(json.dumps({"error": type(exc).__name__, "message": str(exc)}))
else:
    print(json.dumps({"vx_grid": lib.vx_grid, "step": lib.lookup(0.5, 0.0).step_time_s}))
"""


def _probe(tmp_path, action: str, data: bytes | None) -> dict:
    shutil.copytree(REPO_ROOT / "plant", tmp_path / "plant", ignore=shutil.ignore_patterns("__pycache__", "native"))
    target = tmp_path / "plant" / "data" / "gait_library.json"
    if data is None:
        target.unlink()
    else:
        target.write_bytes(data)
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run([sys.executable, "-c", PROBE, action], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


def test_library_deleted_after_import_still_serves_the_calibrated_gait(tmp_path):
    committed = GaitLibrary.default()
    got = _probe(tmp_path, "delete", DEFAULT_LIBRARY_PATH.read_bytes())
    assert got == {"vx_grid": list(committed.vx_grid), "step": committed.lookup(0.5, 0.0).step_time_s}


@pytest.mark.parametrize("data, why", [(None, "cannot be read"), (b"{not json", "not a gait library"),
                                       (b'{"vx_grid": [0.0]}', "not a gait library")])
def test_missing_or_broken_library_is_an_error_naming_the_file(tmp_path, data, why):
    got = _probe(tmp_path, "keep", data)
    assert got["error"] == "GaitLibraryError", got
    assert str(tmp_path / "plant" / "data" / "gait_library.json") in got["message"] and why in got["message"], got


def test_load_names_the_file(tmp_path):
    with pytest.raises(GaitLibraryError, match=str(tmp_path / "none.json")):
        GaitLibrary.load(tmp_path / "none.json")
