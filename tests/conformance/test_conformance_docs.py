"""docs/conformance.md against the checker: every check with its FMI 2.0.4 section, every option,
and its code blocks run as written (from a folder holding ``dist/``, the session's build, and
``.venv/``, the running interpreter's environment)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from fmu_src.fmi.conformance.checks import CHECKS
from fmu_src.fmi.conformance.cli import parser
from support.paths import REPO_ROOT

PAGE = REPO_ROOT / "docs" / "conformance.md"
SECTION = re.compile(r"\d+(?:\.\d+)+")


def blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```", PAGE.read_text(), re.M | re.S)


def test_every_check_is_documented_with_its_section():
    rows = {m.group(1): m.group(2) for m in re.finditer(r"^\| `([a-z_]+\.[a-z_]+)` \|.*\| ([\d., ]+) \|$",
                                                          PAGE.read_text(), re.M)}
    assert set(rows) == {c.id for c in CHECKS}
    for check in CHECKS:
        assert SECTION.findall(rows[check.id]) == SECTION.findall(check.sections[2].removeprefix("FMI 2.0.4 ")), \
            check.id


def test_every_option_is_documented():
    documented = set(re.findall(r"^\| `(--[a-z-]+)", PAGE.read_text(), re.M))
    options = {o for action in parser()._actions for o in action.option_strings if o.startswith("--") and o != "--help"}
    assert documented == options


def test_code_blocks_run_as_written(tmp_path, built_all):
    (tmp_path / "dist").symlink_to(built_all.dist)
    (tmp_path / ".venv").symlink_to(Path(sys.prefix))
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    shell, python = blocks("sh"), blocks("python")
    assert shell and python
    for block in shell:
        proc = subprocess.run(["bash", "-e", "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, (block, proc.stdout[-2000:], proc.stderr[-2000:])
    assert (tmp_path / "conformance-junit.xml").is_file() and (tmp_path / "conformance.json").is_file()
    for block in python:
        proc = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)
        assert proc.returncode == 0, (block, proc.stderr[-2000:])
