"""Shared by tests/fmu/test_fmu_coexistence.py and tests/fmu/test_fmu_memory.py: builds of the two pythonfmu
FMUs from edited copies of the sources (build.py's own functions, run on the copy), and a host
process that calls fmpy on given .fmu files with its own empty TMPDIR."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from support.paths import MODEL_ENV, REPO_ROOT

#: What build.py needs of the repository: itself, the FMU sources, the plant, the method page.
_TREE = ("build.py", "fmu_src", "plant", "docs/method.md")
_BUILD = "import sys\nfrom pathlib import Path\nimport build\nprint(getattr(build, sys.argv[1])(Path(sys.argv[2])))\n"


def _model_env() -> dict:
    """The model locations as absolute paths (a copy of the repository is not beside shared/)."""
    return {**os.environ, **MODEL_ENV}


def build_edited(tmp: Path, function: str, edits: dict[str, tuple[str, str]]) -> Path:
    """``build.<function>`` (``build_fmu`` or ``build_plant_fmu``) run in a process of its own on a
    copy of the sources in which each file ``edits`` names has its one ``old`` text replaced by
    ``new``; returns the FMU's path (in ``tmp/out``)."""
    tree = tmp / "tree"
    for part in _TREE:
        source = REPO_ROOT / part
        if source.is_dir():
            shutil.copytree(source, tree / part, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            (tree / part).parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, tree / part)
    for name, (old, new) in edits.items():
        text = (tree / name).read_text()
        assert text.count(old) == 1, f"{name}: expected {old!r} once (the test's edit no longer applies)"
        (tree / name).write_text(text.replace(old, new))
    out = tmp / "out"
    out.mkdir()
    proc = subprocess.run([sys.executable, "-c", _BUILD, function, str(out)], cwd=tree, env=_model_env(),
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return Path(proc.stdout.strip().splitlines()[-1])


def run_host(script: str, args, tmp: Path, timeout: float = 900) -> tuple[object, str]:
    """Run ``script`` (Python reading JSON ``args`` on stdin, printing JSON as its last line) in a
    process of its own with TMPDIR an empty folder; the process must exit normally and leave
    nothing in TMPDIR.  Returns (the JSON it printed, its stderr)."""
    tmpdir = tmp / "host_tmp"
    tmpdir.mkdir()
    proc = subprocess.run([sys.executable, "-c", script], input=json.dumps(args), capture_output=True, text=True,
                          env={**_model_env(), "TMPDIR": str(tmpdir)}, timeout=timeout)
    assert proc.returncode == 0, f"the host process died (exit {proc.returncode}):\n{proc.stderr[-4000:]}"
    assert sorted(p.name for p in tmpdir.iterdir()) == [], "left in the temporary folder"
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc.stderr
